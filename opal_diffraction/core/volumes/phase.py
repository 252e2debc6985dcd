"""The Henyey-Greenstein phase function: evaluation and exact inversion sampling
(docs/physics.md section 15.3).

p(cos theta) = (1 - g^2) / (4 pi (1 + g^2 - 2 g cos theta)^(3/2)), with theta the angle between
the propagation directions before and after the scattering (g > 0: forward scattering), as
Cycles' volume_henyey_greenstein (intern/cycles/kernel/closure/volume_henyey_greenstein.h) and
pbrt-v4's HenyeyGreenstein (src/pbrt/util/scattering.h) define it. Sampling inverts the CDF in
cos theta: cos theta = (1 + g^2 - ((1 - g^2) / (1 - g + 2 g u))^2) / (2 g), uniform 1 - 2u
for |g| < 1e-3; the azimuth is uniform.
"""

from __future__ import annotations

import numpy as np

from ..util.geometry import orthonormal_basis

__all__ = ["hg", "sample_hg", "sample_cos"]


def hg(cos_theta, g) -> np.ndarray:
    """The phase function's value (1/sr) at cos theta = d_in . d_out."""
    cos_theta = np.asarray(cos_theta, np.float64)
    g = np.asarray(g, np.float64)
    denom = 1.0 + g * g - 2.0 * g * cos_theta
    return (1.0 - g * g) / (4.0 * np.pi * denom * np.sqrt(np.maximum(denom, 1e-300)))


def sample_cos(g, u) -> np.ndarray:
    """cos theta drawn from the phase function (inverse CDF) for numbers ``u`` in [0, 1)."""
    g = np.broadcast_to(np.asarray(g, np.float64), np.shape(u))
    u = np.asarray(u, np.float64)
    small = np.abs(g) < 1e-3
    gs = np.where(small, 0.5, g)
    k = (1.0 - gs * gs) / (1.0 - gs + 2.0 * gs * u)
    c = (1.0 + gs * gs - k * k) / (2.0 * gs)
    return np.clip(np.where(small, 1.0 - 2.0 * u, c), -1.0, 1.0)


def sample_hg(d, g, u1, u2):
    """New directions (B, 3) float64 about the propagation directions ``d`` (B, 3) and their pdfs
    (B,) (the phase function's value: the sample's weight p / pdf is 1)."""
    d = np.asarray(d, np.float64)
    c = sample_cos(g, u1)
    s = np.sqrt(np.maximum(0.0, 1.0 - c * c))
    phi = 2.0 * np.pi * np.asarray(u2, np.float64)
    u, v = orthonormal_basis(d)
    wi = (s * np.cos(phi))[:, None] * u + (s * np.sin(phi))[:, None] * v + c[:, None] * d
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    return wi, hg(c, g)
