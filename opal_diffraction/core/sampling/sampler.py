"""Low-discrepancy random numbers per pixel: Owen-scrambled, shuffled Sobol' (0,2)-points.

Method: Burley 2020, "Practical Hash-based Owen Scrambling" (JCGT 9(4)), which Cycles uses as its
default sampler ("Sobol-Burley", intern/cycles/kernel/sample/sobol_burley.h). A pixel's samples
are the points 0, 1, 2, ... of the 2-D Sobol' sequence (van der Corput in x, Sobol's second
dimension in y: a (0,2)-sequence, so the first 2^k points put exactly one point in every
elementary interval of area 2^-k); each pair of dimensions of a path takes its own shuffle of
the sample index and its own nested uniform (Owen) scramble of each coordinate, both keyed by a
hash of (seed, pixel, pair). Every number is therefore uniform on [0, 1) and pairs are
independent of one another across dimensions and pixels, while within one pixel and one pair
the samples stay stratified in 2-D: the error of smooth integrands (soft shadows, sky light on
a diffuse floor, antialiased texture edges) falls faster than random sampling's 1/sqrt(N).
The Owen scramble is Laine & Karras's hash permutation applied to the bit-reversed value (with
Burley's constants): a bit changes only with the bits above it, as nested uniform scrambling
requires (docs/physics.md section 6.5).

Blue-noise dithering (the default, ``blue_noise_numbers``): as Cycles' "Automatic" pattern for
final renders (BLUE_NOISE_PURE, intern/cycles/kernel/sample/pattern.h), every pixel takes a
block of one shared sequence instead of its own: pixel (x, y) numbers its samples from
rank(x, y) L on, with L the render's samples rounded up to a power of two and the same scramble
keys for all pixels (pixel id 0). rank is the pixel's Morton code under a base-4 nested uniform
scramble (Ahmed & Wonka 2020, "Screen-space blue-noise diffusion of Monte Carlo sampling error
via hierarchical ordering of pixels", SIGGRAPH Asia; Vegdahl 2022, Owen-scrambling based
dithered blue noise): each aligned 2^k x 2^k square of pixels gets an aligned block of 4^k L
consecutive sequence indices, which the index shuffle keeps an aligned block, so the square's
samples together are one stratified net and its pixels' errors cancel against each other
(docs/physics.md section 6.6).

``PixelSampler`` offers the one method of ``numpy.random.Generator`` the sampling routines use,
``random(size, dtype)``: each call for the sampler's batch size takes the next dimension (two
consecutive calls form one 2-D pair), any other call falls through to the pseudo-random
generator. Numbers are multiples of 2^-24, so they stay below 1 in float32 as well.

Where the compiled kernels run (core/util/jit.py), ``sobol_owen_2d`` and ``sobol_owen_x`` compute
each point in one pass (key hash, index shuffle, both scrambles) instead of some sixty whole-array
integer operations: integer arithmetic, so the same bits.
"""

from __future__ import annotations

import itertools
from functools import lru_cache

import numpy as np

from ..util.jit import kernels_enabled, njit

__all__ = ["sobol_owen_2d", "sobol_owen_x", "PixelSampler", "CAMERA_PAIRS", "PAIRS_PER_VERTEX", "SLOT_LIGHT", "SLOT_PARAMS",
           "SLOT_BOUNCE", "SLOT_WIDTH", "vertex_pair", "morton2d", "blue_noise_rank", "blue_noise_numbers"]

#: Pairs the camera uses: 0 the pixel position (x, y), 1 the wavelength number (its x).
CAMERA_PAIRS = 2
#: Pairs reserved per path vertex (slots: next-event estimation 0-7, surface parameters 8-9,
#: the bounce 10-15): a vertex never reuses another vertex's or another decision's numbers.
PAIRS_PER_VERTEX = 16
SLOT_LIGHT, SLOT_PARAMS, SLOT_BOUNCE = 0, 8, 10
#: How many pairs each slot may use before its numbers fall back to pseudo-random ones.
SLOT_WIDTH = {SLOT_LIGHT: 8, SLOT_PARAMS: 2, SLOT_BOUNCE: 6}

_U32 = np.uint32


def _reverse_bits(x: np.ndarray) -> np.ndarray:
    """The 32 bits of x in reverse order: neighbouring bits, pairs and nibbles swapped by masks,
    then the four bytes (a few whole-array operations, no table lookups)."""
    x = x.astype(_U32, copy=False)
    x = ((x >> _U32(1)) & _U32(0x55555555)) | ((x & _U32(0x55555555)) << _U32(1))
    x = ((x >> _U32(2)) & _U32(0x33333333)) | ((x & _U32(0x33333333)) << _U32(2))
    x = ((x >> _U32(4)) & _U32(0x0F0F0F0F)) | ((x & _U32(0x0F0F0F0F)) << _U32(4))
    return x.byteswap()


def _superset_parity(index: np.ndarray) -> np.ndarray:
    """Bit j of the result = the parity of the index's set bits i that contain j (i & j == j).

    Sobol's second dimension has direction numbers v_i = v_{i-1} xor (v_{i-1} >> 1), v_0 = 2^31:
    bit 31 - j of v_i is binomial(i, j) mod 2, which is 1 exactly when j's bits are a subset of
    i's (Lucas' theorem). So y(index) = xor of v_i over the index's bits is this word reversed.
    The subset sums over GF(2) take one masked shift-xor per bit of the bit position (5)."""
    w = index.astype(_U32, copy=True)
    for shift, mask in ((1, 0x55555555), (2, 0x33333333), (4, 0x0F0F0F0F), (8, 0x00FF00FF), (16, 0x0000FFFF)):
        w ^= (w >> _U32(shift)) & _U32(mask)
    return w


def _hash(x: np.ndarray) -> np.ndarray:
    """A 32-bit integer finaliser (lowbias32, Wellons 2018): well mixed keys for the scrambles."""
    x = x.astype(_U32, copy=True)
    x ^= x >> _U32(16)
    x *= _U32(0x7FEB352D)
    x ^= x >> _U32(15)
    x *= _U32(0x846CA68B)
    x ^= x >> _U32(16)
    return x


def _laine_karras(x: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """Laine & Karras's hash permutation with Burley's constants: bit i of the result depends on
    bits 0..i of x only (Burley 2020, listing 2)."""
    x = x + seed
    x ^= x * _U32(0x6C50B47C)
    x ^= x * _U32(0xB82F1E52)
    x ^= x * _U32(0xC7AFE638)
    x ^= x * _U32(0x8D22F6E6)
    return x


def _owen(x: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """Nested uniform scramble of 32-bit fixed-point values (Burley 2020, listing 3)."""
    return _reverse_bits(_laine_karras(_reverse_bits(x), seed))


def _sobol_y(index: np.ndarray) -> np.ndarray:
    """Sobol's second dimension of ``index`` (uint32): the reversed superset parities."""
    return _reverse_bits(_superset_parity(index))


def _seed_word(seed: int) -> np.ndarray:
    """(1,) uint32: every 32-bit word of the seed (a render seed can exceed 2^32), each hashed in
    turn. Read-only and kept per seed: every sampler call of a render asks for it."""
    return _seed_word_cached(int(seed))


@lru_cache(maxsize=64)
def _seed_word_cached(seed: int) -> np.ndarray:
    with np.errstate(over="ignore"):
        s = _hash(np.full(1, seed & 0xFFFFFFFF, _U32))
        rest = (int(seed) % (1 << 128)) >> 32  # non-negative: the loop ends
        while rest:
            s = _hash(s ^ np.full(1, rest & 0xFFFFFFFF, _U32))
            rest >>= 32
    s.flags.writeable = False
    return s


def _key(seed: int, pixel: np.ndarray, pair: np.ndarray) -> np.ndarray:
    s = _seed_word(seed)
    with np.errstate(over="ignore"):
        k = _hash(np.asarray(pixel, np.uint64).astype(_U32) ^ s)
        return _hash(k ^ _hash(np.asarray(pair, np.int64).astype(_U32) * _U32(0x9E3779B9)))


def _shuffled(pixel, sample, pair, seed: int):
    """(key, shuffled index) uint32 of (pixel, sample, pair): the pair's own order of the points."""
    sample = np.asarray(sample, np.int64).astype(_U32)
    pair = np.broadcast_to(np.asarray(pair, np.int64), sample.shape)
    with np.errstate(over="ignore"):
        key = _key(seed, np.asarray(pixel), pair)
        return key, _owen(sample, key)


def _scrambled_x(key, index):
    """Sobol's x of the shuffled index, Owen-scrambled: x is the reversed index, so its scramble
    reverse(LK(reverse(x))) needs only the final reversal."""
    return _reverse_bits(_laine_karras(index, _hash(key ^ _U32(0x68BC21EB))))


def sobol_owen_2d(pixel, sample, pair, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The 2-D point of ``sample`` (B,) in pixel ``pixel`` (B,) for dimension pair ``pair``
    (scalar or (B,)): two float64 arrays in [0, 1), multiples of 2^-24."""
    if kernels_enabled():
        points = _points_by_kernel(pixel, sample, pair, seed, True)
        if points is not None:
            return points
    key, index = _shuffled(pixel, sample, pair, seed)
    with np.errstate(over="ignore"):
        x = _scrambled_x(key, index)
        # Sobol's y is reverse(superset parities of the index) (_sobol_y), so its Owen scramble
        # reverse(LK(reverse(y))) is reverse(LK(those parities)): two reversals fewer
        y = _reverse_bits(_laine_karras(_superset_parity(index), _hash(key ^ _U32(0x02E5BE93))))
    scale = 1.0 / (1 << 24)
    return (x >> _U32(8)).astype(np.float64) * scale, (y >> _U32(8)).astype(np.float64) * scale


def morton2d(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(B,) uint32 Morton codes of 16-bit x, y: x's bits at the even positions, y's at the odd."""
    def spread(v):
        v = np.asarray(v).astype(_U32) & _U32(0xFFFF)
        for shift, mask in ((8, 0x00FF00FF), (4, 0x0F0F0F0F), (2, 0x33333333), (1, 0x55555555)):
            v = (v | (v << _U32(shift))) & _U32(mask)
        return v
    return spread(x) | (spread(y) << _U32(1))


#: The 24 permutations of a base-4 digit (rows), for the base-4 scramble.
_PERMS4 = np.array(list(itertools.permutations(range(4))), _U32)


def blue_noise_rank(x: np.ndarray, y: np.ndarray, seed: int, digits: int) -> np.ndarray:
    """(B,) uint32 ranks < 4^digits of pixels (x, y) < 2^digits: their Morton codes under a
    base-4 nested uniform (Owen) scramble. Each base-4 digit, from the top, is permuted by one of
    the 24 permutations, chosen by a hash of the seed, the level and the digits above it (the
    original ones): a bijection of [0, 4^digits) that maps every aligned block of 4^k codes (an
    aligned 2^k x 2^k square of pixels) onto an aligned block of 4^k ranks."""
    code = morton2d(x, y)
    out = np.zeros(code.shape, _U32)
    with np.errstate(over="ignore"):
        s = _hash(np.full(1, int(seed) & 0xFFFFFFFF, _U32) ^ _U32(0xB10E5E)) ^ _U32((int(seed) >> 32) & 0xFFFFFFFF)
        for level in range(digits - 1, -1, -1):  # a loop over the (at most 16) digits
            shift = _U32(2 * level)
            above = code >> shift >> _U32(2)  # the digits above this one
            perm = _hash(_hash(above ^ s) ^ _U32(level * 0x9E3779B9 & 0xFFFFFFFF)) % _U32(24)
            out |= _PERMS4[perm, (code >> shift) & _U32(3)] << shift
    return out


def blue_noise_numbers(x: np.ndarray, y: np.ndarray, width: int, height: int, samples: int, seed: int):
    """The first sample number of each pixel (x, y) of a ``width`` x ``height`` image in the
    shared blue-noise sequence, rank(x, y) L with L = ``samples`` rounded up to a power of two
    (uint32), or None where the blocks would not fit in 2^32 indices (then each pixel keeps its
    own sequence)."""
    digits = max(1, int(max(int(width), int(height)) - 1).bit_length())
    length = 1 << max(0, int(samples) - 1).bit_length()
    if (1 << (2 * digits)) * length > 1 << 32:
        return None
    return blue_noise_rank(x, y, seed, digits) * _U32(length)


def sobol_owen_x(pixel, sample, pair, seed: int) -> np.ndarray:
    """The x coordinate of ``sobol_owen_2d(pixel, sample, pair, seed)`` alone, as float32 in
    [0, 1) (multiples of 2^-24, exact in float32): where a decision needs one number (the glass
    choice, the wavelength), without the y coordinate's work."""
    if kernels_enabled():
        points = _points_by_kernel(pixel, sample, pair, seed, False)
        if points is not None:
            return points[0].astype(np.float32)  # multiples of 2^-24 below 1: exact in float32
    key, index = _shuffled(pixel, sample, pair, seed)
    with np.errstate(over="ignore"):
        x = _scrambled_x(key, index)
    return (x >> _U32(8)).astype(np.float32) * np.float32(1.0 / (1 << 24))


def _points_by_kernel(pixel, sample, pair, seed: int, with_y: bool):
    """(x, y) float64 of sobol_owen_2d by _sobol_owen_kernel (y None without ``with_y``), or None
    for input shapes the NumPy lines handle (anything but (B,) pixels and samples)."""
    pixel, sample = np.asarray(pixel), np.asarray(sample)
    if pixel.ndim != 1 or sample.shape != pixel.shape or pixel.dtype.kind not in "iu" or sample.dtype.kind not in "iu":
        return None
    pair = np.asarray(pair, np.int64)
    if pair.shape not in ((), pixel.shape):
        return None
    x = np.empty(len(pixel))
    y = np.empty(len(pixel) if with_y else 0)
    # a scalar pair as one element (the kernel reads pair[0] for every row): no broadcast view per call
    _sobol_owen_kernel(pixel, sample, pair.reshape(-1), np.uint64(_seed_word(seed)[0]), with_y, x, y)
    return x, (y if with_y else None)


_M32 = np.uint64(0xFFFFFFFF)


@njit
def _hash_word(x):
    """_hash of one 32-bit word held in a uint64."""
    x ^= x >> np.uint64(16)
    x = (x * np.uint64(0x7FEB352D)) & _M32
    x ^= x >> np.uint64(15)
    x = (x * np.uint64(0x846CA68B)) & _M32
    return x ^ (x >> np.uint64(16))


@njit
def _reverse_word(x):
    """_reverse_bits of one 32-bit word held in a uint64."""
    x = ((x >> np.uint64(1)) & np.uint64(0x55555555)) | ((x & np.uint64(0x55555555)) << np.uint64(1))
    x = ((x >> np.uint64(2)) & np.uint64(0x33333333)) | ((x & np.uint64(0x33333333)) << np.uint64(2))
    x = ((x >> np.uint64(4)) & np.uint64(0x0F0F0F0F)) | ((x & np.uint64(0x0F0F0F0F)) << np.uint64(4))
    return (((x & np.uint64(0xFF)) << np.uint64(24)) | ((x & np.uint64(0xFF00)) << np.uint64(8))
            | ((x >> np.uint64(8)) & np.uint64(0xFF00)) | (x >> np.uint64(24)))


@njit
def _laine_karras_word(x, seed):
    """_laine_karras of one 32-bit word held in a uint64."""
    x = (x + seed) & _M32
    x ^= (x * np.uint64(0x6C50B47C)) & _M32
    x ^= (x * np.uint64(0xB82F1E52)) & _M32
    x ^= (x * np.uint64(0xC7AFE638)) & _M32
    x ^= (x * np.uint64(0x8D22F6E6)) & _M32
    return x


@njit
def _sobol_owen_kernel(pixel, sample, pair, seed_word, with_y, x_out, y_out):
    """sobol_owen_2d per point on 32-bit words held in uint64 (every product masked back to 32
    bits, as uint32 arithmetic wraps): the key of (pixel, pair), the shuffled index, then x's
    and (``with_y``) y's Owen scramble, as multiples of 2^-24. The integer inputs (any integer
    type) are cut to their low 32 bits, as the reference's conversions to uint32 cut them."""
    scale = 1.0 / (1 << 24)
    one_pair = pair.shape[0] == 1 and pixel.shape[0] != 1  # one pair for every row
    for b in range(pixel.shape[0]):
        k = _hash_word((np.uint64(pixel[b]) & _M32) ^ seed_word)
        key = _hash_word(k ^ _hash_word((np.uint64(pair[0 if one_pair else b]) * np.uint64(0x9E3779B9)) & _M32))
        index = _reverse_word(_laine_karras_word(_reverse_word(np.uint64(sample[b]) & _M32), key))
        x = _reverse_word(_laine_karras_word(index, _hash_word(key ^ np.uint64(0x68BC21EB))))
        x_out[b] = np.float64(x >> np.uint64(8)) * scale
        if with_y:
            w = index
            w ^= (w >> np.uint64(1)) & np.uint64(0x55555555)
            w ^= (w >> np.uint64(2)) & np.uint64(0x33333333)
            w ^= (w >> np.uint64(4)) & np.uint64(0x0F0F0F0F)
            w ^= (w >> np.uint64(8)) & np.uint64(0x00FF00FF)
            w ^= (w >> np.uint64(16)) & np.uint64(0x0000FFFF)
            y = _reverse_word(_laine_karras_word(w, _hash_word(key ^ np.uint64(0x02E5BE93))))
            y_out[b] = np.float64(y >> np.uint64(8)) * scale


def vertex_pair(depth: np.ndarray, slot: int) -> np.ndarray:
    """The first dimension pair of a decision ``slot`` at path vertices of bounce ``depth``."""
    return CAMERA_PAIRS + np.asarray(depth, np.int64) * PAIRS_PER_VERTEX + slot


class PixelSampler:
    """``random(size, dtype)`` for one batch of path vertices: Sobol-Burley numbers where the
    call asks for one number (or a row of numbers) per vertex, ``rng`` otherwise. ``pixel`` and
    ``sample`` (B,) identify each vertex's pixel and sample; ``pair`` (B,) its first pair."""

    def __init__(self, rng: np.random.Generator, pixel, sample, pair, seed: int, pairs: int = 1 << 30):
        self._rng = rng
        self._left = int(pairs)  # pairs this sampler may still use
        self._pixel = np.asarray(pixel)
        self._sample = np.asarray(sample)
        self._pair = np.asarray(pair, np.int64)
        self._seed = int(seed)
        self._spare = None  # the second coordinate of the current pair

    def __len__(self) -> int:
        return len(self._pixel)

    def _next(self) -> np.ndarray:
        if self._spare is not None:
            out, self._spare = self._spare, None
            self._pair = self._pair + 1
            return out
        out, self._spare = sobol_owen_2d(self._pixel, self._sample, self._pair, self._seed)
        self._left -= 1
        return out

    def random(self, size=None, dtype=np.float64, out=None):
        shape = (size,) if isinstance(size, (int, np.integer)) else (None if size is None else tuple(size))
        if (out is not None or shape is None or len(shape) > 2 or shape[0] != len(self) or len(self) == 0
                or 2 * self._left + (self._spare is not None) < (1 if len(shape) == 1 else shape[1])):
            return self._rng.random(size, dtype, out=out) if out is not None else self._rng.random(size, dtype)
        if len(shape) == 1:
            return self._next().astype(dtype)
        return np.stack([self._next() for _ in range(shape[1])], axis=1).astype(dtype)

    def __getattr__(self, name):  # the rest of the Generator interface: pseudo-random
        return getattr(self._rng, name)
