"""The light paths' adjoint factor for shading normals (docs/physics.md section 4.6).

A BSDF evaluated about an interpolated shading normal n_s is not symmetric: the eye pass
transports radiance with it, and light paths that follow the same specular rule carry flux
through a different operator unless each bounce is multiplied by Veach's adjoint correction
(Veach 1997, section 5.3.2, eq. 5.17; pbrt-v3 ``CorrectShadingNormal``; Mitsuba 3's particle
tracer applies it at every light-path bounce as "Adjoint BSDF for shading normals"):

    f = |w_l . n_s| |w_n . n_g| / (|w_l . n_g| |w_n . n_s|)

with w_l the unit direction back towards the light (minus the arriving ray's direction), w_n the
new direction and n_s the normal the bounce actually used (transport.SpecularWalker's
``specular_normal``: n_s after the reflection fix-up). A reflection about n_s has
|w_l . n_s| = |w_n . n_s|, so f = |w_n . n_g| / |w_l . n_g|. Where the walker refracted about n_g
instead (a refraction about n_s that would not cross) the bounce used n_g and f = 1; so it is on
flat triangles (n_s = n_g).

Without it, the light pass conserved each bounce's flux, but put it where a light tracer of the
eye pass's surface does not: on a coarse smooth-shaded ball the caustic's rim came out too
bright and its centre too dark, a local error that no number of light paths removes
(benchmarks/caustic_ball.py, docs/caustics.md "issue 30").
"""

from __future__ import annotations

import numpy as np

__all__ = ["adjoint_factor", "dielectric_normal_used"]

_TINY = np.float32(1e-7)


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def adjoint_factor(d_in: np.ndarray, d_out: np.ndarray, ng: np.ndarray, ns: np.ndarray,
                   used_ns: np.ndarray | None = None) -> np.ndarray:
    """(B,) float32 factor f above for rays arriving along ``d_in`` and leaving along ``d_out``
    (unit, (B, 3)) at hits with geometric normal ``ng`` and used shading normal ``ns``;
    ``used_ns`` (B,) bool: rows whose bounce used ``ns`` (the others get 1). A row whose
    denominator vanishes (grazing the facet) gets 0: such a light path carries no flux on."""
    num = np.abs(_dot(d_in, ns)) * np.abs(_dot(d_out, ng))
    den = np.abs(_dot(d_in, ng)) * np.abs(_dot(d_out, ns))
    f = np.where(den > _TINY, num / np.maximum(den, _TINY), 0.0).astype(np.float32)
    if used_ns is not None:
        f = np.where(used_ns, f, np.float32(1))
    return f


def dielectric_normal_used(d_in: np.ndarray, d_out: np.ndarray, ng: np.ndarray, ns: np.ndarray, eta: np.ndarray,
                           transmitted: np.ndarray) -> np.ndarray:
    """(B,) bool: the rows of a smooth-dielectric bounce (transport.SpecularWalker's
    ``dielectric_bounce``) that bent about ``ns``: every reflection (the mirror about ns, also
    under total internal reflection) and the refractions whose Snell direction about ns crosses
    the surface (d_t . n_g < 0); the others were refracted about n_g. ``eta``: n_incident /
    n_transmitted per row."""
    cos = -_dot(d_in, ns)
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - eta * eta * np.maximum(0.0, 1.0 - cos * cos)))
    d_t = eta[:, None] * d_in + (eta * cos - cos_t)[:, None] * ns
    crosses = _dot(d_t, ng) < 0
    # a refraction about ns that crossed is the direction the walker took: d_out along d_t
    return ~transmitted | (crosses & (_dot(d_out, d_t) > 0.999))
