"""The GGX microfacet terms the BSDFs of bsdf.py evaluate: D, Smith's Lambda, and a reflection lobe's f cos and pdf.

Formulas (docs/physics.md section 14): the Trowbridge-Reitz (GGX) normal distribution
D(h) = alpha^2 / (pi ((h_x^2 + h_y^2 + alpha^2 h_z^2)^2)) for local unit half vectors, and the
height-correlated Smith masking-shadowing G2 = 1 / (1 + Lambda(wo) + Lambda(wi)) with
Lambda(w) = (sqrt(1 + alpha^2 tan^2 theta) - 1) / 2 (pbrt-v4, Pharr, Jakob & Humphreys 2023,
section 9.6; Heitz 2014, "Understanding the masking-shadowing function", JCGT 3(2)). A reflection
lobe with F = 1 has f cos = D G2 / (4 cos_o), and visible-normal sampling (Heitz 2018) gives it
the pdf D G1(wo) / (4 cos_o) = D / ((1 + Lambda(wo)) 4 cos_o).

``reflection_terms`` over float32 batches runs a compiled kernel where the kernels run
(core/util/jit.py): the NumPy lines' float32 operations in their order (the half vector's norm
summed x, y, z as np.linalg.norm does), one pass per hit instead of some twenty (B,) and (B, 3)
temporaries; the same bits.
"""

from __future__ import annotations

import numpy as np

from ..util.jit import kernels_enabled, njit

__all__ = ["smith_lambda", "ggx_d", "reflection_terms"]


def smith_lambda(alpha2, w):
    """Smith Lambda of GGX for local directions w (..., 3): 0.5 (sqrt(1 + alpha^2 tan^2) - 1).
    tan^2 from the tangential components (precise near the normal, unlike 1 - cos^2)."""
    s2 = w[..., 0] ** 2 + w[..., 1] ** 2
    z2 = np.maximum(w[..., 2] ** 2, 1e-30)
    return 0.5 * (np.sqrt(1.0 + alpha2 * s2 / z2) - 1.0)


def ggx_d(alpha2, h):
    """GGX D for local unit half vectors (upper hemisphere)."""
    d = h[..., 0] ** 2 + h[..., 1] ** 2 + alpha2 * h[..., 2] ** 2
    return alpha2 / (np.pi * np.maximum(d * d, 1e-38))


def reflection_terms(alpha, wo, wi):
    """D G2 / (4 cos_o) (the f cos of an F = 1 lobe), pdf of VNDF reflection, and wo.h, for
    alpha (B,) and local wo, wi (B, 3)."""
    if kernels_enabled() and all(isinstance(a, np.ndarray) and a.dtype == np.float32 for a in (alpha, wo, wi)) \
            and alpha.ndim == 1 and wo.shape == wi.shape == (len(alpha), 3):
        fc, pdf, cos_oh = (np.empty(len(alpha), np.float32) for _ in range(3))
        _reflection_kernel(alpha, wo, wi, fc, pdf, cos_oh)
        return fc, pdf, cos_oh
    a2 = alpha * alpha
    h = wo + wi
    h /= np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-30)
    d = ggx_d(a2, h)
    lo, li = smith_lambda(a2, wo), smith_lambda(a2, wi)
    mu_o = wo[:, 2]
    fc = d / ((1.0 + lo + li) * 4.0 * mu_o)
    pdf = d / ((1.0 + lo) * 4.0 * mu_o)
    return fc, pdf, np.sum(wo * h, axis=1)


@njit
def _smith_lambda_1(a2, x, y, z):
    """smith_lambda of one direction, in float32 (NaN passes np.maximum's way)."""
    z2 = z * z
    floor = np.float32(1e-30)
    z2 = floor if z2 < floor else z2
    return np.float32(0.5) * (np.sqrt(np.float32(1.0) + a2 * (x * x + y * y) / z2) - np.float32(1.0))


@njit
def _reflection_kernel(alpha, wo, wi, fc, pdf, cos_oh):
    """reflection_terms' NumPy lines per hit, all float32."""
    one, four = np.float32(1.0), np.float32(4.0)
    pi, tiny_norm, tiny_d2 = np.float32(np.pi), np.float32(1e-30), np.float32(1e-38)
    for b in range(alpha.shape[0]):
        a2 = alpha[b] * alpha[b]
        hx, hy, hz = wo[b, 0] + wi[b, 0], wo[b, 1] + wi[b, 1], wo[b, 2] + wi[b, 2]
        norm = np.sqrt(hx * hx + hy * hy + hz * hz)
        norm = tiny_norm if norm < tiny_norm else norm
        hx, hy, hz = hx / norm, hy / norm, hz / norm
        dd = hx * hx + hy * hy + a2 * (hz * hz)
        d2 = dd * dd
        d = a2 / (pi * (tiny_d2 if d2 < tiny_d2 else d2))
        lo = _smith_lambda_1(a2, wo[b, 0], wo[b, 1], wo[b, 2])
        li = _smith_lambda_1(a2, wi[b, 0], wi[b, 1], wi[b, 2])
        mu_o = wo[b, 2]
        fc[b] = d / ((one + lo + li) * four * mu_o)
        pdf[b] = d / ((one + lo) * four * mu_o)
        cos_oh[b] = wo[b, 0] * hx + wo[b, 1] * hy + wo[b, 2] * hz
