"""A grating layered on its base material without creating energy: per-hit weights of the base's
lobes and of the grating (docs/physics.md section 3.3).

The grating's orders together carry the strip fraction f of the incident power (f = a / D for
LINES, the disks' fill fraction pi a^2 / (2 sqrt 3 D^2) for HEXAGONAL; Parseval, section 3.2), so
the layering takes them out of the surface's budget instead of adding them on top:

- **The zeroth order is the base's specular lobe** (a smooth mirror under a reflection grating,
  smooth glass under a transmission grating): the grating *is* that interface. Its zeroth order
  is the specular continuation, weighted by the zeroth-order efficiency eta_0 = f^2 K (K the
  Harvey-Shack factor of the continuation's direction, 1 without renormalisation), and the
  diffraction of lights leaves the zeroth order out (``PreparedGratings.zeroth_in_base``), so no
  light is counted twice; the other orders come from the diffraction. In the mirror limit
  (a -> D) eta_0 -> 1 and the grating is the plain mirror. A glass base's Fresnel reflection
  under a transmission grating keeps its weight; the refraction is the zeroth transmitted order.
- **Any other base** (Lambertian, rough or layered, a mirror under a transmission grating, glass
  under a reflection grating): the strip fraction f diffracts (all orders, the zeroth included)
  and the base keeps 1 - f of its response: next events, caustic lookups and bounces alike.

The continuation of the zeroth order is a delta lobe where the real order is lambda / (N D)
wide: the same energy, narrower. Approximations, named once in docs/physics.md section 3.3: the
grating's strips reflect (or pass) with reflectance 1 whatever the base colour, so a tinted
mirror tints only the zeroth order; the orders through a glass base are not reduced by its
Fresnel reflection. The grating diffracts the scene's lights, its emissive meshes and the light
pass's records by next events, and everything else (the world on either side, lit surfaces,
glass) by continuing the eye path along a sampled order (LINES gratings, core/gratings/lobe.py,
docs/physics.md section 3.13).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .kernel import harvey_shack_factor, hexagonal_harvey_shack_factor
from ..util.enums import MaterialKind
from .radiance import PreparedGratings, grating_frame

__all__ = ["attach_layering", "strip_fraction", "base_scale", "zeroth_order_efficiency",
           "scale_base", "continue_specular", "active"]

_MIRROR, _DIELECTRIC = int(MaterialKind.MIRROR), int(MaterialKind.DIELECTRIC)


def strip_fraction(g: PreparedGratings) -> np.ndarray:
    """(M,) the fraction of the incident power the grating's orders carry (0 without a grating):
    a / D (LINES) or pi a^2 / (2 sqrt 3 D^2) (HEXAGONAL disks), at most 1."""
    ratio = np.divide(g.slit_width, g.period, out=np.zeros(len(g.period)), where=g.period > 0)
    f = np.where(g.hexagonal, np.pi * ratio**2 / (2 * np.sqrt(3)), ratio)
    return np.where(g.enabled, np.clip(f, 0.0, 1.0), 0.0)


def attach_layering(g: PreparedGratings, kind: np.ndarray, microfacet: np.ndarray | None) -> PreparedGratings:
    """The gratings with ``zeroth_in_base`` set: smooth mirror + reflection grating, smooth glass +
    transmission grating (prepare calls it once the rough-material mask is known)."""
    kind = np.asarray(kind)
    smooth = np.ones(len(kind), bool) if microfacet is None else ~np.asarray(microfacet, bool)
    zeroth = g.enabled & smooth & (((kind == _MIRROR) & ~g.transmission) | ((kind == _DIELECTRIC) & g.transmission))
    return dataclasses.replace(g, zeroth_in_base=zeroth)


def base_scale(g: PreparedGratings) -> np.ndarray:
    """(M,) float32: the weight of the base's response at a grating hit where the grating is not
    the base's specular lobe (1 - f), 1 elsewhere."""
    zeroth = np.zeros(len(g.enabled), bool) if g.zeroth_in_base is None else g.zeroth_in_base
    return np.where(g.enabled & ~zeroth, 1.0 - strip_fraction(g), 1.0).astype(np.float32)


def active(prepared) -> bool:
    """Whether any grating changes a base's weights in this scene."""
    return bool(prepared.gratings.any)


def zeroth_order_efficiency(g: PreparedGratings, mat: int, w_i, t, s, period, wavelength,
                            renormalise: bool = True, bin_width=None) -> np.ndarray:
    """eta_0 = f^2 K: the fraction of the power from w_i (B, 3) the zeroth order carries, per
    sample and wavelength (``wavelength`` (B, K) or (B, 1) nm; ``period`` (B,) nm). LINES: K of
    the finite-N pattern the diffraction evaluates (section 3.2), over the bins of width
    ``bin_width`` around ``wavelength`` when given."""
    f = strip_fraction(g)[mat]
    eta = np.full(np.broadcast_shapes((len(w_i), 1), np.shape(wavelength)), f * f)
    if not renormalise:
        return eta
    w_i = np.asarray(w_i, np.float64)
    alpha = np.sum(w_i * t, axis=1)[:, None]
    beta = np.sum(w_i * s, axis=1)[:, None]
    d = np.asarray(period, np.float64)[:, None]
    ratio = g.slit_width[mat] / g.period[mat]
    if g.hexagonal[mat]:
        return eta * hexagonal_harvey_shack_factor(alpha, beta, wavelength, ratio, d)
    return eta * harvey_shack_factor(alpha, beta, wavelength, ratio, d, n=int(g.slit_count[mat]), bin_width=bin_width)


def scale_base(prepared, rays, hit):
    """The rays at hits with their weight times the base's share (``base_scale``): for the
    Lambertian and microfacet responses (next events, caustic lookups, the bounce)."""
    scale = base_scale(prepared.gratings)[hit.mat]
    if np.all(scale == 1):
        return rays
    n = prepared.grid.n
    if rays.lam is not None:
        return dataclasses.replace(rays, w=(rays.w * scale).astype(np.float32))
    w = (np.broadcast_to(scale[:, None], (len(rays), n)) if rays.w is None else rays.w * scale[:, None])
    return dataclasses.replace(rays, w=np.ascontiguousarray(w, np.float32))


def continue_specular(prepared, out, hit, transmitted, renormalise: bool = True):
    """The rays ``out`` leaving a smooth mirror (``transmitted`` None) or glass (``transmitted``
    (B,) bool) at ``hit``, weighted by the layering: eta_0 of the continuation's direction where
    it is the grating's zeroth order, 1 for the Fresnel reflection under a transmission grating,
    the base's share 1 - f under any other grating."""
    g = prepared.gratings
    if len(out) == 0:
        return out
    mats = hit.mat
    on = g.enabled[mats]
    if not on.any():
        return out
    n = prepared.grid.n
    tr = np.zeros(len(out), bool) if transmitted is None else np.asarray(transmitted, bool)
    zeroth = np.zeros(len(g.enabled), bool) if g.zeroth_in_base is None else g.zeroth_in_base
    # per ray and bin (white) or per ray (mono); start from the base's share
    factor = np.broadcast_to(base_scale(g)[mats][:, None], (len(out), n)).astype(np.float64)
    centres = prepared.grid.wavelengths
    for m in np.unique(mats[on & zeroth[mats]]):  # the few grating materials
        sel = mats == m
        lobe = sel & (tr == bool(g.transmission[m]))  # the zeroth order's lobe
        factor[sel & ~lobe] = 1.0  # glass: the Fresnel reflection under a transmission grating
        idx = np.flatnonzero(lobe)
        if idx.size == 0:
            continue
        h = hit.take(idx)
        t, s = grating_frame(prepared.tri_grating_tangent[h.prim], h.ng, np.full(idx.size, g.cos_rot[m]),
                             np.full(idx.size, g.sin_rot[m]))
        over = prepared.tri_period[h.prim] if len(prepared.tri_period) else np.zeros(idx.size, np.float32)
        period = np.where(over > 0, over, g.period[m])
        # light reaching the viewer along the zeroth order comes from the continuation's direction
        factor[idx] = zeroth_order_efficiency(g, int(m), out.d[idx], t, s, period, centres[None, :], renormalise,
                                              bin_width=np.diff(prepared.grid.bin_edges)[None, :])
    factor = factor.astype(np.float32)
    if out.lam is not None:
        return dataclasses.replace(out, w=(out.w * factor[np.arange(len(out)), out.lam]).astype(np.float32))
    w = factor if out.w is None else out.w * factor
    return dataclasses.replace(out, w=np.ascontiguousarray(w, np.float32))
