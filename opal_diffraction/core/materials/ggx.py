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
temporaries; the same bits. ``ggx_d_1``, ``smith_lambda_1``, ``reflection_1`` and
``sample_vndf_1`` (Heitz 2018's visible-normal sampling, bsdf._sample_vndf's lines) are the
per-hit float32 pieces bsdf.py's kernels are built from.
"""

from __future__ import annotations

import numpy as np

from ..util.jit import kernels_enabled, njit

__all__ = ["smith_lambda", "ggx_d", "reflection_terms", "ggx_d_1", "reflection_1", "sample_vndf_1", "smith_lambda_1"]


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
def smith_lambda_1(a2, x, y, z):
    """smith_lambda of one direction, in float32 (NaN passes np.maximum's way)."""
    z2 = z * z
    floor = np.float32(1e-30)
    z2 = floor if z2 < floor else z2
    return np.float32(0.5) * (np.sqrt(np.float32(1.0) + a2 * (x * x + y * y) / z2) - np.float32(1.0))


@njit
def ggx_d_1(a2, hx, hy, hz):
    """ggx_d of one half vector, in float32 (NaN passes np.maximum's way)."""
    dd = hx * hx + hy * hy + a2 * (hz * hz)
    d2 = dd * dd
    tiny = np.float32(1e-38)
    return a2 / (np.float32(np.pi) * (tiny if d2 < tiny else d2))


@njit
def reflection_1(alpha, ox, oy, oz, ix, iy, iz):
    """reflection_terms of one pair of local directions: (D G2 / (4 cos_o), pdf, wo.h), float32."""
    one, four, tiny_norm = np.float32(1.0), np.float32(4.0), np.float32(1e-30)
    a2 = alpha * alpha
    hx, hy, hz = ox + ix, oy + iy, oz + iz
    norm = np.sqrt(hx * hx + hy * hy + hz * hz)
    norm = tiny_norm if norm < tiny_norm else norm
    hx, hy, hz = hx / norm, hy / norm, hz / norm
    d = ggx_d_1(a2, hx, hy, hz)
    lo = smith_lambda_1(a2, ox, oy, oz)
    li = smith_lambda_1(a2, ix, iy, iz)
    return d / ((one + lo + li) * four * oz), d / ((one + lo) * four * oz), ox * hx + oy * hy + oz * hz


@njit
def sample_vndf_1(ox, oy, oz, alpha, u1, u2):
    """bsdf._sample_vndf (Heitz 2018) for one local wo, float32 in the reference's order; the sine
    and cosine are libm's (NumPy's own SIMD float32 sin / cos may differ by an ulp)."""
    zero, one, half = np.float32(0.0), np.float32(1.0), np.float32(0.5)
    vx, vy, vz = alpha * ox, alpha * oy, oz
    n = np.sqrt(((zero + vx * vx) + vy * vy) + vz * vz)
    vx, vy, vz = vx / n, vy / n, vz / n
    lensq = vx * vx + vy * vy
    if lensq > np.float32(1e-7):
        inv = one / np.sqrt(lensq)
        t1x, t1y = -vy * inv, vx * inv
    else:
        t1x, t1y = one, zero
    t2x, t2y, t2z = -vz * t1y, vz * t1x, vx * t1y - vy * t1x
    r = np.sqrt(u1)
    phi = np.float32(2.0 * np.pi) * u2
    p1 = r * np.cos(phi)
    p2 = r * np.sin(phi)
    s = half * (one + vz)
    q = one - p1 * p1
    p2 = (one - s) * np.sqrt(zero if q < zero else q) + s * p2
    q = one - p1 * p1 - p2 * p2
    w = np.sqrt(zero if q < zero else q)
    nx = (p1 * t1x + p2 * t2x) + w * vx
    ny = (p1 * t1y + p2 * t2y) + w * vy
    nz = (p1 * zero + p2 * t2z) + w * vz
    hx, hy, hz = alpha * nx, alpha * ny, zero if nz < zero else nz
    hn = np.sqrt(((zero + hx * hx) + hy * hy) + hz * hz)
    tiny = np.float32(1e-30)
    hn = tiny if hn < tiny else hn
    return hx / hn, hy / hn, hz / hn


@njit
def _reflection_kernel(alpha, wo, wi, fc, pdf, cos_oh):
    """reflection_terms' NumPy lines per hit, all float32."""
    for b in range(alpha.shape[0]):
        fc[b], pdf[b], cos_oh[b] = reflection_1(alpha[b], wo[b, 0], wo[b, 1], wo[b, 2], wi[b, 0], wi[b, 1], wi[b, 2])
