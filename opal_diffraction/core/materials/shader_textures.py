"""Cycles' procedural textures, vectorised over a batch of points in float32: Perlin noise and its
fractals (the Noise texture), Voronoi (F1, F2, smooth F1, distance to edge), Checker, Gradient
and White Noise (docs/physics.md section 13.6).

The math is ported from Blender's ``intern/cycles/kernel/svm/`` (Apache-2.0): ``noise.h``
(Perlin's improved noise with lookup3 hashes at the lattice corners, the OSL remapping scales,
the 1e5 period), ``fractal_noise.h`` (fBM, multifractal, hetero terrain, hybrid and ridged
multifractal), ``noisetex.h`` (distortion and colour offsets), ``voronoi.h`` (the 3^n / 5^n cell
scans and the fractal wrapper), ``checker.h``, ``gradient.h``, ``white_noise.h``. Cycles' CPU
kernel renders 2-D to 4-D Perlin noise through its SSE / AVX2 code paths, whose operation order
differs from the scalar one; the order here is theirs: ``fade`` is ``(t t)(t (t (6 t - 15) + 10))``
with fused multiply-adds (AVX2 ``madd``, emulated exactly in float64 and rounded once), and the
corner blends run x, then y, then z (4-D: w first, then x, y, z), each ``a + t (b - a)``. Hashes
(:mod:`.shader_hash`) are bit for bit Cycles'; the noise values agree with Cycles to float32
rounding (tests/blender/test_procedural_textures_cycles.py measures it).

Every function takes coordinates as float32 arrays (..., d) and per-point parameters as arrays
broadcastable to the batch (a node input may be driven per hit).
"""

from __future__ import annotations

import itertools

import numpy as np

from ..scene.shader_programs import GRADIENT_TYPES, NOISE_TYPES, VORONOI_FEATURES, VORONOI_METRICS
from ..util.jit import kernels_enabled
from . import shader_hash as H
from .shader_kernels import perlin2_kernel, perlin3_kernel, voronoi_edge_kernel, voronoi_octave_kernel

__all__ = ["brick_texture", "wave_texture", "magic_texture", "perlin", "perlin_reference", "snoise", "noise_texture", "voronoi_texture", "checker_texture", "gradient_texture",
           "white_noise_texture", "NOISE_TYPES", "VORONOI_FEATURES", "VORONOI_METRICS", "GRADIENT_TYPES"]

F = np.float32
_FLT_MAX = F(np.finfo(np.float32).max)


def _f32(x):
    return np.asarray(x, np.float32)


def _madd(a, b, c):
    """a b + c rounded once (a fused multiply-add, as the AVX2 kernel's ``madd``): the float32
    product is exact in float64, so float64's sum rounded to float32 is the fused result but for
    double-rounding ties (vanishingly rare)."""
    return (np.asarray(a, np.float64) * np.asarray(b, np.float64) + np.asarray(c, np.float64)).astype(np.float32)


def _mix(a, b, t):
    return a + t * (b - a)


def _fade_vec(t):
    """SSE/AVX2 ``fade``: (t t)(t b), b = t a + 10, a = 6 t - 15 (fused)."""
    a = _madd(t, F(6), F(-15))
    b = _madd(t, a, F(10))
    return (t * t) * (t * b)


def _fade_scalar(t):
    """Scalar ``fade`` (1-D noise): t t t (t (6 t - 15) + 10)."""
    return t * t * t * (t * (t * F(6) - F(15)) + F(10))


def _floorfrac(x):
    f = np.floor(x)
    return f.astype(np.int32), x - f


def _neg(v, cond):
    return np.where(cond != 0, -v, v)


def _grad1(h, x):
    h = h & 15
    g = (1 + (h & 7)).astype(np.float32)
    return _neg(g, h & 8) * x


def _grad2(h, x, y):
    h = h & 7
    u = np.where(h < 4, x, y)
    v = F(2) * np.where(h < 4, y, x)
    return _neg(u, h & 1) + _neg(v, h & 2)


def _grad3(h, x, y, z):
    h = h & 15
    u = np.where(h < 8, x, y)
    vt = np.where((h == 12) | (h == 14), x, z)
    v = np.where(h < 4, y, vt)
    return _neg(u, h & 1) + _neg(v, h & 2)


def _grad4(h, x, y, z, w):
    h = h & 31
    u = np.where(h < 24, x, y)
    v = np.where(h < 16, y, z)
    s = np.where(h < 8, z, w)
    return _neg(u, h & 1) + _neg(v, h & 2) + _neg(s, h & 4)


_HASH = {1: H.hash_uint, 2: H.hash_uint2, 3: H.hash_uint3, 4: H.hash_uint4}
_GRAD = {1: _grad1, 2: _grad2, 3: _grad3, 4: _grad4}


def perlin(p: np.ndarray) -> np.ndarray:
    """Cycles' ``perlin_1d`` .. ``perlin_4d`` at points p (..., d) float32, d = 1..4 (unscaled).
    2-D and 3-D run the compiled kernels of :mod:`.shader_kernels` when enabled (bit for bit
    this reference)."""
    p = _f32(p)
    d = p.shape[-1]
    if d in (2, 3) and p.size and kernels_enabled():
        flat = p.reshape(-1, d)
        out = np.empty(len(flat), np.float32)
        cols = [np.ascontiguousarray(flat[:, i]) for i in range(d)]
        (perlin2_kernel if d == 2 else perlin3_kernel)(*cols, out)
        return out.reshape(p.shape[:-1])
    return perlin_reference(p)


def perlin_reference(p: np.ndarray) -> np.ndarray:
    """The NumPy reference of :func:`perlin` (what the kernels are tested against)."""
    p = _f32(p)
    d = p.shape[-1]
    cells, fr = _floorfrac(p)
    cells = cells.astype(np.uint32)  # lookup3 takes the ints as uint (two's complement wraps)
    fade = _fade_scalar(fr) if d == 1 else _fade_vec(fr)
    one = np.uint32(1)
    # gradient values at the 2^d corners, keyed by their offsets (o_0, ..., o_{d-1})
    val = {}
    for off in itertools.product((0, 1), repeat=d):
        keys = [cells[..., i] + one if o else cells[..., i] for i, o in enumerate(off)]
        coords = [fr[..., i] - F(1) if o else fr[..., i] for i, o in enumerate(off)]
        val[off] = _GRAD[d](_HASH[d](*keys).astype(np.int64), *coords)
    order = list(range(d)) if d < 4 else [3, 0, 1, 2]  # AVX2 quad_mix blends w first
    for axis in order:
        t = fade[..., axis]
        nxt = {}
        for off, v in val.items():
            if off[axis] == 0:
                hi = off[:axis] + (1,) + off[axis + 1:]
                nxt[off[:axis] + (None,) + off[axis + 1:]] = _mix(v, val[hi], t)
        val = nxt
    (out,) = val.values()
    return out.astype(np.float32)


_SCALE = {1: F(0.25), 2: F(0.6616), 3: F(0.9820), 4: F(0.8344)}


def snoise(p: np.ndarray) -> np.ndarray:
    """Signed noise in about [-1, 1]: ``snoise_Nd`` (fmod by 1e5, then the OSL scale)."""
    p = np.fmod(_f32(p), F(100000.0))
    return (_SCALE[p.shape[-1]] * perlin(p)).astype(np.float32)


def _ival(detail):
    return np.asarray(detail, np.float32).astype(np.int32)  # float_to_int: truncation


def _fbm(p, detail, roughness, lacunarity, normalize):
    n = int(np.max(_ival(detail))) if np.size(detail) else 0
    fscale, amp = F(1), np.ones(p.shape[:-1], np.float32)
    maxamp = np.zeros_like(amp)
    total = np.zeros_like(amp)
    di = np.broadcast_to(_ival(detail), amp.shape)
    lac = np.broadcast_to(_f32(lacunarity), amp.shape)
    fs = np.ones_like(amp)
    for i in range(n + 1):
        on = i <= di
        t = snoise(fs[..., None] * p)
        total = np.where(on, total + t * amp, total)
        maxamp = np.where(on, maxamp + amp, maxamp)
        amp = np.where(on, amp * roughness, amp)
        fs = np.where(on, fs * lac, fs)
    det = np.broadcast_to(_f32(detail), amp.shape)
    rmd = det - np.floor(det)
    t = snoise(fs[..., None] * p)
    sum2 = total + t * amp
    with np.errstate(divide="ignore", invalid="ignore"):
        a = F(0.5) * total / maxamp + F(0.5)
        b = F(0.5) * sum2 / (maxamp + amp) + F(0.5)
    frac = _mix(a, b, rmd) if normalize else _mix(total, sum2, rmd)
    whole = a if normalize else total
    del fscale
    return np.where(rmd != 0, frac, whole).astype(np.float32)


def _multi_fractal(p, detail, roughness, lacunarity):
    shape = p.shape[:-1]
    di = np.broadcast_to(_ival(detail), shape)
    rough = np.broadcast_to(_f32(roughness), shape)
    lac = np.broadcast_to(_f32(lacunarity), shape)
    value, pwr = np.ones(shape, np.float32), np.ones(shape, np.float32)
    for i in range(int(di.max()) + 1 if di.size else 1):
        on = i <= di
        value = np.where(on, value * (pwr * snoise(p) + F(1)), value)
        pwr = np.where(on, pwr * rough, pwr)
        p = np.where(on[..., None], p * lac[..., None], p)
    det = np.broadcast_to(_f32(detail), shape)
    rmd = det - np.floor(det)
    return np.where(rmd != 0, value * (rmd * pwr * snoise(p) + F(1)), value).astype(np.float32)


def _hetero_terrain(p, detail, roughness, lacunarity, offset):
    shape = p.shape[:-1]
    di = np.broadcast_to(_ival(detail), shape)
    rough = np.broadcast_to(_f32(roughness), shape)
    lac = np.broadcast_to(_f32(lacunarity), shape)
    pwr = rough.copy()
    value = offset + snoise(p)
    p = p * lac[..., None]
    for i in range(1, int(di.max()) + 1 if di.size else 1):
        on = i <= di
        inc = (snoise(p) + offset) * pwr * value
        value = np.where(on, value + inc, value)
        pwr = np.where(on, pwr * rough, pwr)
        p = np.where(on[..., None], p * lac[..., None], p)
    det = np.broadcast_to(_f32(detail), shape)
    rmd = det - np.floor(det)
    inc = (snoise(p) + offset) * pwr * value
    return np.where(rmd != 0, value + rmd * inc, value).astype(np.float32)


def _hybrid_multi_fractal(p, detail, roughness, lacunarity, offset, gain):
    shape = p.shape[:-1]
    di = np.broadcast_to(_ival(detail), shape)
    rough = np.broadcast_to(_f32(roughness), shape)
    lac = np.broadcast_to(_f32(lacunarity), shape)
    pwr, value, weight = np.ones(shape, np.float32), np.zeros(shape, np.float32), np.ones(shape, np.float32)
    for i in range(int(di.max()) + 1 if di.size else 1):
        on = (weight > F(0.001)) & (i <= di)
        weight = np.where(on & (weight > 1), F(1), weight)
        signal = (snoise(p) + offset) * pwr
        pwr = np.where(on, pwr * rough, pwr)
        value = np.where(on, value + weight * signal, value)
        weight = np.where(on, weight * (gain * signal), weight)
        p = np.where(on[..., None], p * lac[..., None], p)
    det = np.broadcast_to(_f32(detail), shape)
    rmd = det - np.floor(det)
    last = (rmd != 0) & (weight > F(0.001))
    w = np.where(weight > 1, F(1), weight)
    signal = (snoise(p) + offset) * pwr
    return np.where(last, value + rmd * w * signal, value).astype(np.float32)


def _ridged_multi_fractal(p, detail, roughness, lacunarity, offset, gain):
    shape = p.shape[:-1]
    di = np.broadcast_to(_ival(detail), shape)
    rough = np.broadcast_to(_f32(roughness), shape)
    lac = np.broadcast_to(_f32(lacunarity), shape)
    pwr = rough.copy()
    signal = offset - np.abs(snoise(p))
    signal = signal * signal
    value = signal
    for i in range(1, int(di.max()) + 1 if di.size else 1):
        on = i <= di
        p = np.where(on[..., None], p * lac[..., None], p)
        weight = np.clip(signal * gain, F(0), F(1))
        s = offset - np.abs(snoise(p))
        s = s * s * weight
        value = np.where(on, value + s * pwr, value)
        signal = np.where(on, s, signal)
        pwr = np.where(on, pwr * rough, pwr)
    return value.astype(np.float32)


def _noise_select(p, detail, roughness, lacunarity, offset, gain, kind, normalize):
    if kind == "FBM":
        return _fbm(p, detail, roughness, lacunarity, normalize)
    if kind == "MULTIFRACTAL":
        return _multi_fractal(p, detail, roughness, lacunarity)
    if kind == "HETERO_TERRAIN":
        return _hetero_terrain(p, detail, roughness, lacunarity, offset)
    if kind == "HYBRID_MULTIFRACTAL":
        return _hybrid_multi_fractal(p, detail, roughness, lacunarity, offset, gain)
    if kind == "RIDGED_MULTIFRACTAL":
        return _ridged_multi_fractal(p, detail, roughness, lacunarity, offset, gain)
    raise ValueError(f"unknown noise type {kind!r}")


def _offset(seed: float, d: int) -> np.ndarray:
    """random_floatN_offset(seed): components in [100, 200] from hashes of (seed, i)."""
    s = np.float32(seed)
    if d == 1:
        return np.array([F(100) + H.hash_float_to_float(s) * F(100)], np.float32)
    return np.array([F(100) + H.hash_float2_to_float(s, F(i)) * F(100) for i in range(d)], np.float32)


def noise_texture(vector, w=0.0, scale=5.0, detail=2.0, roughness=0.5, lacunarity=2.0, offset=0.0, gain=1.0,
                  distortion=0.0, dimensions: int = 3, kind: str = "FBM", normalize: bool = True,
                  color: bool = True):
    """Cycles' Noise texture (``svm_node_tex_noise``): (fac (B,), colour (B, 3) or None) at
    ``vector`` (B, 3) and ``w`` (B,) for 1-D / 4-D. Parameters are scalars or (B,) arrays."""
    vector = _f32(vector).reshape(-1, 3)
    b = len(vector)

    def col(x):
        return np.broadcast_to(_f32(x), (b,))

    scale, detail, roughness = col(scale), np.clip(col(detail), F(0), F(15)), np.maximum(col(roughness), F(0))
    lacunarity, offset, gain, distortion = col(lacunarity), col(offset), col(gain), col(distortion)
    vector = vector * scale[:, None]
    w = col(w) * scale
    if dimensions == 1:
        p = w[:, None]
    elif dimensions == 2:
        p = vector[:, :2]
    elif dimensions == 3:
        p = vector
    else:
        p = np.concatenate([vector, w[:, None]], axis=1)
    d = p.shape[1]
    dist = distortion != 0
    if dist.any():
        shift = np.stack([snoise(p + _offset(float(i), d)) * distortion for i in range(d)], axis=1)
        p = np.where(dist[:, None], p + shift, p).astype(np.float32)
    args = (detail, roughness, lacunarity, offset, gain, kind, normalize)
    value = _noise_select(p, *args)
    if not color:
        return value, None
    base = 1 if d == 1 else d  # the colour's seeds follow the distortion's
    rgb = np.stack([value, _noise_select((p + _offset(float(base), d)).astype(np.float32), *args),
                    _noise_select((p + _offset(float(base + 1), d)).astype(np.float32), *args)], axis=1)
    return value, rgb.astype(np.float32)


# ------------------------------------------------------------------------------------ Voronoi
def _vdist(a, b, metric: str, exponent):
    d = a - b
    if metric == "EUCLIDEAN":
        return np.sqrt(np.sum(d * d, axis=-1, dtype=np.float32)) if d.shape[-1] > 1 else np.abs(d[..., 0])
    if metric == "MANHATTAN":
        return np.sum(np.abs(d), axis=-1, dtype=np.float32)
    if metric == "CHEBYCHEV":
        return np.max(np.abs(d), axis=-1)
    e = exponent[..., None] if np.ndim(exponent) else exponent
    return np.power(np.sum(np.power(np.abs(d), e), axis=-1, dtype=np.float32), F(1) / np.asarray(exponent, F))


def _cell_hash(c):
    """Feature point offsets in the integer cell ``c`` (..., d) int32 and the cell's colour: the
    PCG hashes Cycles' Voronoi uses (``hash_int{2,3,4}_to_float{2,3,4}``; 1-D: the float hash of
    the cell, ``hash_float_to_float``)."""
    d = c.shape[-1]
    parts = [c[..., i] for i in range(d)]
    if d == 1:
        f = parts[0].astype(np.float32)
        return H.hash_float_to_float(f)[..., None], H.hash_float_to_float3(f)
    if d == 2:
        return H.hash_int2_to_float2(*parts), H.hash_int2_to_float3(*parts)
    if d == 3:
        h = H.hash_int3_to_float3(*parts)
        return h, h
    return H.hash_int4_to_float4(*parts), H.hash_int4_to_float3(*parts)


def _offsets(d: int, r: int):
    """(integer, float) cell offsets in Cycles' loop order (the first axis fastest)."""
    for off in itertools.product(range(-r, r + 1), repeat=d):
        yield np.array(off[::-1], np.int32), np.array(off[::-1], np.float32)


def _smoothstep(x):
    t = x
    return np.where(x < 0, F(0), np.where(x >= 1, F(1), (F(3) - F(2) * t) * (t * t)))


_KERNEL_METRICS = {"EUCLIDEAN": 0, "MANHATTAN": 1, "CHEBYCHEV": 2}


def _voronoi_octave(coord, feature, metric, randomness, smoothness, exponent):
    if (feature in ("F1", "F2") and metric in _KERNEL_METRICS and coord.shape[-1] in (2, 3) and len(coord)
            and kernels_enabled()):
        coord = np.ascontiguousarray(coord, np.float32)
        dist = np.empty(len(coord), np.float32)
        colour = np.empty((len(coord), 3), np.float32)
        pos = np.zeros(coord.shape, np.float32)
        voronoi_octave_kernel(coord, np.ascontiguousarray(randomness, np.float32), _KERNEL_METRICS[metric],
                              feature == "F2", dist, colour, pos)
        return dist, colour, pos
    return _voronoi_octave_reference(coord, feature, metric, randomness, smoothness, exponent)


def _voronoi_octave_reference(coord, feature, metric, randomness, smoothness, exponent):
    cell = np.floor(coord)
    local = coord - cell
    icell = cell.astype(np.int32)
    shape = coord.shape[:-1]
    d = coord.shape[-1]
    rnd = randomness[..., None]
    if feature == "SMOOTH_F1":
        sdist = np.zeros(shape, np.float32)
        scol = np.zeros(shape + (3,), np.float32)
        spos = np.zeros(coord.shape, np.float32)
        h = np.full(shape, F(-1))
        for ioff, off in _offsets(d, 2):
            hp, hc = _cell_hash(icell + ioff)
            point = off + hp * rnd
            dist = _vdist(point, local, metric, exponent)
            with np.errstate(divide="ignore", invalid="ignore"):
                h = np.where(h == -1, F(1), _smoothstep(F(0.5) + F(0.5) * (sdist - dist) / smoothness))
            corr = smoothness * h * (F(1) - h)
            sdist = _mix(sdist, dist, h) - corr
            corr = corr / (F(1) + F(3) * smoothness)
            scol = _mix(scol, hc, h[..., None]) - corr[..., None]
            spos = _mix(spos, point, h[..., None]) - corr[..., None]
        return sdist, scol, cell + spos
    d1 = np.full(shape, _FLT_MAX)
    d2 = np.full(shape, _FLT_MAX)
    o1 = np.zeros(coord.shape, np.float32)
    o2 = np.zeros(coord.shape, np.float32)
    p1 = np.zeros(coord.shape, np.float32)
    p2 = np.zeros(coord.shape, np.float32)
    for ioff, off in _offsets(d, 1):
        hp, _ = _cell_hash(icell + ioff)
        point = off + hp * rnd
        dist = _vdist(point, local, metric, exponent)
        first = dist < d1
        second = ~first & (dist < d2)
        if feature == "F2":
            d2 = np.where(first, d1, np.where(second, dist, d2))
            o2 = np.where(first[..., None], o1, np.where(second[..., None], off, o2))
            p2 = np.where(first[..., None], p1, np.where(second[..., None], point, p2))
        d1 = np.where(first, dist, d1)
        o1 = np.where(first[..., None], off, o1)
        p1 = np.where(first[..., None], point, p1)
    if feature == "F2":
        d1, o1, p1 = d2, o2, p2
    _, colour = _cell_hash(icell + o1.astype(np.int32))
    return d1, colour, p1 + cell


def _distance_to_edge(coord, randomness):
    if coord.shape[-1] in (2, 3) and len(coord) and kernels_enabled():
        out = np.empty(len(coord), np.float32)
        voronoi_edge_kernel(np.ascontiguousarray(coord, np.float32), np.ascontiguousarray(randomness, np.float32), out)
        return out
    return _distance_to_edge_reference(coord, randomness)


def _distance_to_edge_reference(coord, randomness):
    cell = np.floor(coord)
    local = coord - cell
    icell = cell.astype(np.int32)
    shape = coord.shape[:-1]
    d = coord.shape[-1]
    rnd = randomness[..., None]
    best = np.full(shape, _FLT_MAX)
    closest = np.zeros(coord.shape, np.float32)
    vecs = []
    for ioff, off in _offsets(d, 1):
        hp, _ = _cell_hash(icell + ioff)
        v = off + hp * rnd - local
        vecs.append(v)
        dd = np.sum(v * v, axis=-1, dtype=np.float32)
        better = dd < best
        best = np.where(better, dd, best)
        closest = np.where(better[..., None], v, closest)
    out = np.full(shape, _FLT_MAX)
    for v in vecs:
        perp = v - closest
        pp = np.sum(perp * perp, axis=-1, dtype=np.float32)
        ok = pp > F(0.0001)
        with np.errstate(divide="ignore", invalid="ignore"):
            n = perp / np.sqrt(pp)[..., None]
            e = np.sum(((closest + v) / F(2)) * n, axis=-1, dtype=np.float32)
        out = np.where(ok, np.minimum(out, e), out)
    return out


def voronoi_texture(vector, w=0.0, scale=5.0, detail=0.0, roughness=0.5, lacunarity=2.0, smoothness=1.0,
                    exponent=0.5, randomness=1.0, dimensions: int = 3, feature: str = "F1",
                    metric: str = "EUCLIDEAN", normalize: bool = False):
    """Cycles' Voronoi texture (``svm_node_tex_voronoi`` with ``fractal_voronoi_x_fx`` /
    ``fractal_voronoi_distance_to_edge``): a dict of outputs 'Distance' (B,), 'Color' (B, 3),
    'Position' (B, 3), 'W' (B,) at ``vector`` (B, 3)."""
    vector = _f32(vector).reshape(-1, 3)
    b = len(vector)

    def col(x):
        return np.broadcast_to(_f32(x), (b,)).astype(np.float32)

    scale = col(scale)
    detail = np.clip(col(detail), F(0), F(15))
    roughness = np.clip(col(roughness), F(0), F(1))
    randomness = np.clip(col(randomness), F(0), F(1))
    smoothness = np.clip(col(smoothness) / F(2), F(0), F(0.5))
    lacunarity, exponent = col(lacunarity), col(exponent)
    coord = vector * scale[:, None]
    w = col(w) * scale
    coord = {1: w[:, None], 2: coord[:, :2], 3: coord, 4: np.concatenate([coord, w[:, None]], axis=1)}[dimensions]
    d = coord.shape[1]
    zero = (detail == 0) | (roughness == 0)
    nmax = int(np.ceil(detail.max())) if b else 0
    half = F(0.5) + F(0.5) * randomness
    if feature == "DISTANCE_TO_EDGE":
        maxd = half
        amp, maxamp, sc = np.ones(b, F), maxd.copy(), np.ones(b, F)
        dist = np.full(b, F(8))
        done = np.zeros(b, bool)
        rmd = detail - np.floor(detail)
        for i in range(nmax + 1):
            od = _distance_to_edge(coord * sc[:, None], randomness)
            first = zero & ~done
            dist = np.where(first, od, dist)
            live = ~zero & (i <= np.ceil(detail))
            whole = live & (i <= detail)
            part = live & ~whole & (rmd != 0)
            m_new = _mix(maxamp, maxd / sc, amp)
            d_new = _mix(dist, np.minimum(dist, od / sc), amp)
            maxamp = np.where(whole, m_new, np.where(part, _mix(maxamp, m_new, rmd), maxamp))
            dist = np.where(whole, d_new, np.where(part, _mix(dist, np.minimum(dist, d_new), rmd), dist))
            sc = np.where(whole, sc * lacunarity, sc)
            amp = np.where(whole, amp * roughness, amp)
            done |= zero
        if normalize:
            dist = dist / maxamp
        return {"Distance": dist.astype(F), "Color": np.zeros((b, 3), F), "Position": np.zeros((b, 3), F),
                "W": np.zeros(b, F)}
    if feature not in ("F1", "F2", "SMOOTH_F1"):
        raise ValueError(f"unsupported Voronoi feature {feature!r}")
    corner = np.broadcast_to(half[:, None], (b, d))
    maxd = _vdist(np.zeros((b, d), F), corner, metric, exponent) * (F(2) if feature == "F2" else F(1))
    amp, maxamp, sc = np.ones(b, F), np.zeros(b, F), np.ones(b, F)
    odist, ocol, opos = np.zeros(b, F), np.zeros((b, 3), F), np.zeros((b, 4), F)
    rmd = detail - np.floor(detail)
    done = np.zeros(b, bool)

    def pos4(p):
        if d == 1:
            return np.concatenate([np.zeros((b, 3), F), p], axis=1)
        if d == 2:
            return np.concatenate([p, np.zeros((b, 2), F)], axis=1)
        if d == 3:
            return np.concatenate([p, np.zeros((b, 1), F)], axis=1)
        return p

    smooth_on = smoothness != 0
    for i in range(nmax + 1):
        c = coord * sc[:, None]
        if feature == "SMOOTH_F1":
            sd, scol, sp = _voronoi_octave(c, "SMOOTH_F1", metric, randomness, smoothness, exponent)
            fd, fcol, fp = _voronoi_octave(c, "F1", metric, randomness, smoothness, exponent)
            od = np.where(smooth_on, sd, fd)
            oc = np.where(smooth_on[:, None], scol, fcol)
            op = np.where(smooth_on[:, None], sp, fp)
        else:
            od, oc, op = _voronoi_octave(c, feature, metric, randomness, smoothness, exponent)
        op = pos4(op.astype(F))
        first = zero & ~done
        maxamp = np.where(first, F(1), maxamp)
        odist = np.where(first, od, odist)
        ocol = np.where(first[:, None], oc, ocol)
        opos = np.where(first[:, None], op, opos)
        done |= zero
        live = ~zero & (i <= np.ceil(detail))
        whole = live & (i <= detail)
        part = live & ~whole & (rmd != 0)
        a = amp[:, None]
        new_pos = _mix(opos, op / sc[:, None], a)
        maxamp = np.where(whole, maxamp + amp, np.where(part, _mix(maxamp, maxamp + amp, rmd), maxamp))
        odist = np.where(whole, odist + od * amp, np.where(part, _mix(odist, odist + od * amp, rmd), odist))
        ocol = np.where(whole[:, None], ocol + oc * a,
                        np.where(part[:, None], _mix(ocol, ocol + oc * a, rmd[:, None]), ocol))
        opos = np.where(whole[:, None], new_pos, np.where(part[:, None], _mix(opos, new_pos, rmd[:, None]), opos))
        sc = np.where(whole, sc * lacunarity, sc)
        amp = np.where(whole, amp * roughness, amp)
    if normalize:
        odist = odist / (maxamp * maxd)
        ocol = ocol / maxamp[:, None]
    safe = np.where(scale != 0, scale, F(1))[:, None]
    opos = np.where(scale[:, None] != 0, opos / safe, F(0))  # safe_divide
    return {"Distance": odist.astype(F), "Color": ocol.astype(F), "Position": opos[:, :3].astype(F),
            "W": opos[:, 3].astype(F)}


# ------------------------------------------------------------------------------------ simple textures
def checker_texture(vector, color1, color2, scale=5.0):
    """Cycles' Checker texture (``svm_checker``): (fac (B,), colour (B, 3))."""
    p = _f32(vector).reshape(-1, 3) * np.broadcast_to(_f32(scale), (len(np.reshape(vector, (-1, 3))),))[:, None]
    p = (p + F(0.000001)) * F(0.999999)
    i = np.abs(np.floor(p).astype(np.int32))
    par = i % 2
    f = ((par[:, 0] == par[:, 1]).astype(np.int32) == par[:, 2]).astype(np.float32)
    rgb = np.where(f[:, None] == 1, np.broadcast_to(_f32(color1), p.shape), np.broadcast_to(_f32(color2), p.shape))
    return f, rgb.astype(np.float32)


def gradient_texture(vector, kind: str = "LINEAR"):
    """Cycles' Gradient texture (``svm_gradient``, saturated): (fac (B,), colour (B, 3))."""
    p = _f32(vector).reshape(-1, 3)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    if kind == "LINEAR":
        f = x
    elif kind == "QUADRATIC":
        r = np.maximum(x, F(0))
        f = r * r
    elif kind == "EASING":
        r = np.minimum(np.maximum(x, F(0)), F(1))
        t = r * r
        f = F(3) * t - F(2) * t * r
    elif kind == "DIAGONAL":
        f = (x + y) * F(0.5)
    elif kind == "RADIAL":
        f = np.arctan2(y, x) / F(2 * np.pi) + F(0.5)
    elif kind in ("QUADRATIC_SPHERE", "SPHERICAL"):
        r = np.maximum(F(0.999999) - np.sqrt(x * x + y * y + z * z), F(0))
        f = r * r if kind == "QUADRATIC_SPHERE" else r
    else:
        raise ValueError(f"unknown gradient type {kind!r}")
    f = np.clip(f, F(0), F(1)).astype(np.float32)
    return f, np.repeat(f[:, None], 3, axis=1)


def white_noise_texture(vector, w=0.0, dimensions: int = 3):
    """Cycles' White Noise texture (``svm_node_tex_white_noise``): (value (B,), colour (B, 3)),
    hashes of the coordinates' bits."""
    p = _f32(vector).reshape(-1, 3)
    w = np.broadcast_to(_f32(w), (len(p),)).astype(np.float32)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    if dimensions == 1:
        return H.hash_float_to_float(w), H.hash_float_to_float3(w)
    if dimensions == 2:
        return H.hash_float2_to_float(x, y), H.hash_float2_to_float3(x, y)
    if dimensions == 3:
        return H.hash_float3_to_float(x, y, z), H.hash_float3_to_float3(x, y, z)
    return H.hash_float4_to_float(x, y, z, w), H.hash_float4_to_float3(x, y, z, w)


# ------------------------------------------------------------------------------------ Wave, Magic
_2PI = F(6.2831855)     # M_2PI_F
_PI_2 = F(1.5707964)    # M_PI_2_F


def wave_texture(vector, scale=5.0, distortion=0.0, detail=2.0, detail_scale=1.0, detail_roughness=0.5, phase=0.0,
                 kind: str = "BANDS", bands_direction: str = "X", rings_direction: str = "X",
                 profile: str = "SIN"):
    """Cycles' Wave texture (svm/wave.h ``svm_wave``): (fac (B,), colour (B, 3) = fac grey)."""
    p = _f32(vector).reshape(-1, 3)
    b = len(p)

    def col(x):
        return np.broadcast_to(_f32(x), (b,))

    p = p * col(scale)[:, None]
    p = (p + F(0.000001)) * F(0.999999)
    if kind == "BANDS":
        if bands_direction == "DIAGONAL":
            n = (p[:, 0] + p[:, 1] + p[:, 2]) * F(10)
        else:
            n = p[:, "XYZ".index(bands_direction)] * F(20)
    else:
        rp = p.copy()
        if rings_direction != "SPHERICAL":
            rp[:, "XYZ".index(rings_direction)] = 0
        n = np.sqrt(rp[:, 0] * rp[:, 0] + rp[:, 1] * rp[:, 1] + rp[:, 2] * rp[:, 2]) * F(20)
    n = (n + col(phase)).astype(F)
    dist = col(distortion)
    if np.any(dist != 0):
        fbm = _fbm((p * col(detail_scale)[:, None]).astype(F), col(detail), col(detail_roughness), F(2.0), True)
        n = np.where(dist != 0, n + dist * (fbm * F(2) - F(1)), n).astype(F)
    if profile == "SIN":
        f = F(0.5) + F(0.5) * np.sin(n - _PI_2)
    elif profile == "SAW":
        n = n / _2PI
        f = n - np.floor(n)
    else:
        n = n / _2PI
        f = np.abs(n - np.floor(n + F(0.5))) * F(2)
    f = f.astype(F)
    return f, np.repeat(f[:, None], 3, axis=1)


def magic_texture(vector, scale=5.0, distortion=1.0, depth: int = 2):
    """Cycles' Magic texture (svm/magic.h ``svm_magic``): (fac (B,) = the colour's average,
    colour (B, 3))."""
    p = _f32(vector).reshape(-1, 3)
    b = len(p)
    sc = np.broadcast_to(_f32(scale), (b,))
    d = np.broadcast_to(_f32(distortion), (b,)).astype(F)
    px, py, pz = (np.fmod(p[:, i], _2PI) for i in range(3))
    x = np.sin((px + py + pz) * F(5) * sc)
    y = np.cos((-px + py - pz) * F(5) * sc)
    z = -np.cos((-px - py + pz) * F(5) * sc)
    n = int(depth)
    if n > 0:
        x, y, z = x * d, y * d, z * d
        y = -np.cos(x - y + z) * d
        if n > 1:
            x = np.cos(x - y - z) * d
        if n > 2:
            z = np.sin(-x - y - z) * d
        if n > 3:
            x = -np.cos(-x + y - z) * d
        if n > 4:
            y = -np.sin(-x + y + z) * d
        if n > 5:
            y = -np.cos(-x + y + z) * d
        if n > 6:
            x = np.cos(x + y + z) * d
        if n > 7:
            z = np.sin(x + y - z) * d
        if n > 8:
            x = -np.cos(-x - y + z) * d
        if n > 9:
            y = -np.sin(x - y + z) * d
    dd = d * F(2)
    nz = d != 0
    with np.errstate(divide="ignore", invalid="ignore"):
        x, y, z = (np.where(nz, v / np.where(nz, dd, F(1)), v) for v in (x, y, z))
    rgb = np.stack([F(0.5) - x, F(0.5) - y, F(0.5) - z], axis=1).astype(F)
    return ((rgb[:, 0] + rgb[:, 1] + rgb[:, 2]) * F(1 / 3)).astype(F), rgb


# ------------------------------------------------------------------------------------ Brick
def _brick_noise(n):
    """svm/brick.h ``brick_noise``: Cycles' fast integer noise of uint32 n, in [0, 1)."""
    with np.errstate(over="ignore"):
        n = (n.astype(np.uint32) + np.uint32(1013)) & np.uint32(0x7FFFFFFF)
        n = (n >> np.uint32(13)) ^ n
        nn = (n * (n * n * np.uint32(60493) + np.uint32(19990303)) + np.uint32(1376312589)) & np.uint32(0x7FFFFFFF)
    return F(0.5) * (nn.astype(F) / F(1073741824.0))


def brick_texture(vector, color1, color2, mortar, scale=5.0, mortar_size=0.02, mortar_smooth=0.1, bias=0.0,
                  brick_width=0.5, row_height=0.25, offset_amount=0.5, offset_frequency: int = 2,
                  squash_amount=1.0, squash_frequency: int = 2):
    """Cycles' Brick texture (svm/brick.h ``svm_brick``): (fac (B,) = the mortar, colour (B, 3))."""
    p = _f32(vector).reshape(-1, 3)
    b = len(p)

    def col(x):
        return np.broadcast_to(_f32(x), (b,)).astype(F)

    p = p * col(scale)[:, None]
    msize, msmooth, bias, width, height = col(mortar_size), col(mortar_smooth), col(bias), col(brick_width), col(row_height)
    with np.errstate(divide="ignore", invalid="ignore"):
        rownum = np.floor(p[:, 1] / height).astype(np.int32)
        offset = np.zeros(b, F)
        if offset_frequency and squash_frequency:
            width = np.where(np.fmod(rownum, squash_frequency) != 0, width, width * F(squash_amount)).astype(F)
            offset = np.where(np.fmod(rownum, offset_frequency) != 0, F(0), width * F(offset_amount)).astype(F)
        bricknum = np.floor((p[:, 0] + offset) / width).astype(np.int32)
        x = (p[:, 0] + offset) - width * bricknum.astype(F)
        y = p[:, 1] - height * rownum.astype(F)
    with np.errstate(over="ignore"):
        key = (rownum.astype(np.int64) << 16) + (bricknum.astype(np.int64) & 0xFFFF)
    tint = np.clip(_brick_noise(key.astype(np.uint64).astype(np.uint32)) + bias, F(0), F(1))
    min_dist = np.minimum(np.minimum(x, y), np.minimum(width - x, height - y))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (F(1) - min_dist / msize) / msmooth
    with np.errstate(invalid="ignore", over="ignore"):  # t is inf / NaN only where msmooth is 0 (not used)
        ff = t * t
        smooth = np.where(t <= 0, F(0), np.where(t >= 1, F(1), F(3) * ff - F(2) * ff * t))
    mortar_f = np.where(min_dist >= msize, F(0), np.where(msmooth == 0, F(1), smooth)).astype(F)
    c1 = np.broadcast_to(_f32(color1), (b, 3))
    c2 = np.broadcast_to(_f32(color2), (b, 3))
    cm = np.broadcast_to(_f32(mortar), (b, 3))
    tinted = np.where((mortar_f != 1)[:, None], (F(1) - tint)[:, None] * c1 + tint[:, None] * c2, c1)
    rgb = tinted * (F(1) - mortar_f)[:, None] + cm * mortar_f[:, None]
    return mortar_f, rgb.astype(F)
