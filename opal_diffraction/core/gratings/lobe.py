"""The grating as a lobe of the eye path: an order sampled from the viewer's side, along which
the path goes on (docs/physics.md sections 3.11, 3.13).

Method. A LINES grating sends light arriving from w_src into order m leaving towards w_o when
the tangential direction cosines obey the grating equation (section 3.10),
eta_o (w_o . t) = -eta_src (w_src . t) + m lambda / D along t and the same with the slit-length
spread dv along s. The map from w_src's (index-scaled) direction cosines to w_o's is a
translation, so it keeps d(cos) d(cos) = cos theta d omega: each order carries radiance
unchanged, times its power fraction. The radiance towards w_o from whatever lies along the
orders (the world, a lit wall, glass and what is behind it) is therefore the sum over the
orders that propagate

    L_o(w_o, lambda) = sum_m e_m K(w_src,m) L_i(w_src,m, lambda),

with e_m = (a/D)^2 sinc^2(pi m a / D) (section 3.2) and K the Harvey-Shack factor of the
incident direction w_src,m. Read backwards the grating equation gives w_src,m from w_o with the
same sampler the light pass uses (order_sampling.sample_orders with w_o as its "incident"
direction: the propagating set and e_m are the same), so one sample draws m with probability
e_m / sum_prop e and carries the weight sum_prop e * K(w_src,m): the estimator of the sum, a
path that continues along w_src,m (``continue_paths``). A white camera ray first takes
WAVELENGTHS wavelength bins, evenly spaced from its stratified number (each uniform: weight
n / WAVELENGTHS), so each continued path is mono.

The layering (section 3.3) says which orders this adds: over a smooth base whose zeroth order
is its specular continuation (``PreparedGratings.zeroth_in_base``: a mirror under a reflection
grating, glass under a transmission grating) the zeroth order is left out here (the
continuation carries it); over any other base every order, the zeroth included (the base
keeps 1 - f of its response). Over glass the orders that cross the surface leave into the glass
(eta_o the glass's index at the path's wavelength; the orders' Fresnel reflection is neglected,
as in section 3.3) and K is the viewer's direction's, with the orders counted on the source's
side (the light pass's K for the reverse path: bounded, sum_prop e K <= a/D).
HEXAGONAL lattices are not continued (their orders are two-dimensional; only their lights are
diffracted).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .kernel import harvey_shack_factor
from .order_sampling import sample_orders
from ..materials.spectra import DIELECTRIC

__all__ = ["lobe_materials", "continue_paths", "ContinuedPaths", "WAVELENGTHS"]

#: wavelength bins a white camera ray takes at a grating, evenly spaced from its stratified
#: number (each with its own order and path): 4 cut the colour noise of one by about 2x
WAVELENGTHS = 4
#: the offset added to a sample's stratified wavelength number, so the bin chosen here is not the
#: one a later dispersive split of the same path draws (both stay stratified over the samples)
_LAMBDA_ROTATION = 0.6180339887498949


def lobe_materials(prepared) -> np.ndarray:
    """(M,) bool: the grating materials whose hits continue the eye path along a sampled order
    (enabled LINES gratings, reflection or transmission, over any base)."""
    g = prepared.gratings
    if not g.any:
        return np.zeros(len(g.enabled), bool)
    return np.asarray(g.enabled, bool) & ~np.asarray(g.hexagonal, bool)


@dataclasses.dataclass
class ContinuedPaths:
    """Mono paths leaving grating hits along sampled orders."""
    rows: np.ndarray         # (B',) int64 the input ray each continues
    origin: np.ndarray       # (B', 3) float32 offset from the hit to the side the order leaves into
    direction: np.ndarray    # (B', 3) float32 unit order directions
    lam: np.ndarray          # (B',) int64 wavelength bins
    weight: np.ndarray       # (B',) float32 the ray's weight in that bin times sum_prop e * K (and n / WAVELENGTHS)
    transmitted: np.ndarray  # (B',) bool the order crossed the surface


def continue_paths(prepared, rays, hit, mat: int, t, s, period, rng, renormalise: bool = True):
    """One order per ray (WAVELENGTHS per white ray) of grating ``mat`` at ``hit``, sampled from
    the viewer's side. ``t``, ``s`` (B, 3): the grating vector and slit direction at the hits;
    ``period`` (B,) nm. Returns ``ContinuedPaths`` (weight-0 samples dropped) or None."""
    g = prepared.gratings
    b = len(rays)
    if b == 0:
        return None
    n = prepared.grid.n
    edges = prepared.grid.bin_edges
    rows = np.arange(b)
    if rays.lam is None:  # WAVELENGTHS bins per white ray, stratified over the pixel's samples
        rep = WAVELENGTHS
        rows = np.repeat(rows, rep)
        u = (rays.u_lam[rows] + _LAMBDA_ROTATION + np.tile(np.arange(rep) / rep, b)) % 1.0
        lam = np.minimum((u * n).astype(np.int64), n - 1)
        scale = np.float32(n / rep)
        w = np.full(len(rows), scale, np.float32) if rays.w is None else rays.dense_w(n)[rows, lam] * scale
    else:
        lam = np.asarray(rays.lam, np.int64)
        w = np.asarray(rays.w, np.float32)
    bb = len(rows)
    ng = hit.ng[rows].astype(np.float64)
    tt, ss = np.asarray(t, np.float64)[rows], np.asarray(s, np.float64)[rows]
    d = np.asarray(period, np.float64)[rows]
    lam_nm = edges[lam] + rng.random(bb) * (edges[lam + 1] - edges[lam])
    ratio = float(g.slit_width[mat] / g.period[mat])
    zeroth = g.zeroth_in_base is not None and bool(g.zeroth_in_base[mat])
    trans = bool(g.transmission[mat])
    eta_view = eta_far = np.ones(bb)
    if prepared.materials.kind[mat] == DIELECTRIC:  # orders into (or out of) the glass base
        ior = prepared.materials.ior[mat, lam].astype(np.float64)
        front = np.asarray(hit.front, bool)[rows]
        eta_view, eta_far = np.where(front, 1.0, ior), np.where(front, ior, 1.0)
    eta_src = eta_far if trans else eta_view
    glass = bool(np.any(eta_src != 1.0) or np.any(eta_view != 1.0))
    # K (section 3.2): in air that of the source direction w_src,m (section 3.11); over glass that
    # of the viewer's direction with the orders counted on the source's side (the light pass's K
    # for light going the other way, sample_orders' renormalise): K of a source inside the glass
    # would count only the few orders that reach the air and grows without bound (4.9 at
    # |n u| = 1.2, D = 740 nm, a = D/2) where the rest is reflected back into the glass
    smp = sample_orders(-rays.d[rows].astype(np.float64), ng, tt, ss, d, d * ratio, lam_nm, trans, rng,
                        eta_i=eta_view, eta_o=eta_src, length=g.length[mat], exclude_zeroth=zeroth,
                        renormalise=renormalise and glass)
    weight = smp.weight
    src = smp.direction
    if renormalise and not glass:
        k = harvey_shack_factor(np.sum(src * tt, axis=1), np.sum(src * ss, axis=1), lam_nm, ratio, d)
        weight = np.where(weight > 0, weight * k, 0.0)
    live = np.flatnonzero(weight > 0)
    if live.size == 0:
        return None
    side = -1.0 if trans else 1.0
    r = rows[live]
    o = (hit.p[r] + (side * hit.eps[r])[:, None] * hit.ng[r]).astype(np.float32)
    out_w = (w[live] * weight[live]).astype(np.float32)
    return ContinuedPaths(r, o, np.ascontiguousarray(src[live], np.float32), lam[live], out_w,
                          np.full(live.size, trans))
