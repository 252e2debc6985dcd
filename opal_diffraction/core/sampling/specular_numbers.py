"""One stratified number per path vertex for the reflect / refract choice at smooth glass.

The eye pass makes the Fresnel choice at a smooth dielectric from the first number of the
vertex's bounce pair (core/sampling/sampler.py, SLOT_BOUNCE; docs/physics.md section 6.5): the x
coordinate of the Owen-scrambled, shuffled Sobol' point of (pixel, sample, pair) (Burley 2020,
"Practical Hash-based Owen Scrambling", as Cycles' sobol_burley.h), so a pixel's samples split
between reflection and refraction in proportion to the Fresnel factor with stratified, not
independent, numbers - as Cycles draws its glass closure's choice from its sampler. A glass
vertex makes no other decision, so only x is needed: ``sampler.sobol_owen_x`` computes
``sampler.sobol_owen_2d``'s x alone (the same bits), without the y coordinate's work, which
about halves the cost of the choice's numbers.
"""

from __future__ import annotations

import numpy as np

from .sampler import SLOT_BOUNCE, sobol_owen_x, vertex_pair

__all__ = ["bounce_choice"]


def bounce_choice(pid: np.ndarray, sid: np.ndarray, depth: np.ndarray, seed: int | None,
                  rng: np.random.Generator) -> np.ndarray:
    """The choice's numbers (B,) float32 for path vertices of pixels ``pid`` and samples ``sid``
    (the eye pass's PathState.pid, .sid) at bounce ``depth``: the first number of their SLOT_BOUNCE
    pair, the same one ``PixelSampler.random`` would give; pseudo-random from ``rng`` without a
    sampler seed."""
    b = len(depth)
    if seed is None or b == 0:
        return rng.random(b, np.float32)
    return sobol_owen_x(pid, sid, vertex_pair(depth, SLOT_BOUNCE), seed)
