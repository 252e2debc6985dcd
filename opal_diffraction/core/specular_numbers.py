"""One stratified number per path vertex for the reflect / refract choice at smooth glass.

The eye pass makes the Fresnel choice at a smooth dielectric from the first number of the
vertex's bounce pair (core/sampler.py, SLOT_BOUNCE; docs/physics.md section 6.5): the x
coordinate of the Owen-scrambled, shuffled Sobol' point of (pixel, sample, pair) (Burley 2020,
"Practical Hash-based Owen Scrambling", as Cycles' sobol_burley.h), so a pixel's samples split
between reflection and refraction in proportion to the Fresnel factor with stratified, not
independent, numbers - as Cycles draws its glass closure's choice from its sampler. A glass
vertex makes no other decision, so only x is needed: ``sobol_owen_x`` computes
``sampler.sobol_owen_2d``'s x alone (the same bits), without the y coordinate's work, which
about halves the cost of the choice's numbers.
"""

from __future__ import annotations

import numpy as np

from . import sampler
from .sampler import SLOT_BOUNCE, vertex_pair

__all__ = ["sobol_owen_x", "bounce_choice"]

_U32 = np.uint32
_reverse_bits = sampler._reverse_bits  # the sampler's bit reversal, the same bits


def sobol_owen_x(pixel, sample, pair, seed: int) -> np.ndarray:
    """The x coordinate of ``sampler.sobol_owen_2d(pixel, sample, pair, seed)`` as float32 in
    [0, 1) (multiples of 2^-24, exact in float32)."""
    sample = np.asarray(sample, np.int64).astype(_U32)
    pair = np.broadcast_to(np.asarray(pair, np.int64), sample.shape)
    with np.errstate(over="ignore"):
        key = sampler._key(seed, np.asarray(pixel), pair)
        index = _reverse_bits(sampler._laine_karras(_reverse_bits(sample), key))  # the shuffle
        x = _reverse_bits(sampler._laine_karras(index, sampler._hash(key ^ _U32(0x68BC21EB))))
    return (x >> _U32(8)).astype(np.float32) * np.float32(1.0 / (1 << 24))


def bounce_choice(extra: dict, depth: np.ndarray, seed: int | None, rng: np.random.Generator) -> np.ndarray:
    """The choice's numbers (B,) float32 for path vertices with state ``extra`` (the eye pass's
    'pid', 'sid') at bounce ``depth``: the first number of their SLOT_BOUNCE pair, the same one
    ``PixelSampler.random`` would give; pseudo-random from ``rng`` without a sampler seed."""
    b = len(depth)
    if seed is None or b == 0:
        return rng.random(b, np.float32)
    return sobol_owen_x(extra["pid"], extra["sid"], vertex_pair(depth, SLOT_BOUNCE), seed)
