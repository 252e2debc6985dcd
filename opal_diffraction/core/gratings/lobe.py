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
incident direction w_src,m. Read backwards the grating equation gives w_src,m from w_o. In air the
path samples the finite-N pattern itself (``sample_finite_pattern``, section 3.13): a point
wavelength in its bin, eta = pi D (w_o + w_src) . t / lambda from the pattern's cumulative power
over the propagating range (kernel.finite_pattern_table: the orders with their finite widths
lambda / (N D), the evanescent ones' tails inside the disk included) and the slit-length spread,
with weight f / p times the finite-N K of w_src: the same integrand as the grating's next
events, so the two can be weighted against each other (``lobe_pdf``: the lobe's solid-angle
density for the power heuristic, docs/physics.md section 3.13). Over glass the infinite-N
sampler of the light pass runs (order_sampling.sample_orders with w_o as its "incident"
direction and refraction: m with probability e_m / sum_prop e, weight sum_prop e * K), with no
MIS. A white camera ray first takes
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

from .kernel import finite_pattern_table, finite_propagating_power, harvey_shack_factor, multislit, sinc2, sinc2_integral
from .order_sampling import SPREAD_LOBES, sample_orders, sample_sinc2
from ..materials.spectra import DIELECTRIC

__all__ = ["lobe_materials", "continue_paths", "ContinuedPaths", "WAVELENGTHS", "sample_finite_pattern",
           "lobe_pdf"]

#: the share of sinc^2(pi x) that ``sample_sinc2``'s table covers (|x| <= SPREAD_LOBES): its density
#: is sinc^2(pi x) / _SPREAD_MASS
_SPREAD_MASS = float(2.0 * sinc2_integral(np.pi * SPREAD_LOBES) / np.pi)

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
    pdf: np.ndarray | None = None  # (B',) float32 the lobe's solid-angle pdf for MIS (``lobe_pdf``; 0: none)


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
    if not glass:  # in air: the finite-N pattern itself (its finite-N K as the next events take it)
        n_slits = int(g.slit_count[mat])
        src, weight = sample_finite_pattern(-rays.d[rows].astype(np.float64), ng, tt, ss, d, ratio, n_slits,
                                            float(g.length[mat]), lam_nm, trans, rng, exclude_zeroth=zeroth)
        if renormalise:
            centre = 0.5 * (edges[lam] + edges[lam + 1])
            k = harvey_shack_factor(np.sum(src * tt, axis=1), np.sum(src * ss, axis=1), centre, ratio, d,
                                    n=n_slits, bin_width=edges[lam + 1] - edges[lam])
            weight = np.where(weight > 0, weight * k, 0.0)
    else:
        smp = sample_orders(-rays.d[rows].astype(np.float64), ng, tt, ss, d, d * ratio, lam_nm, trans, rng,
                            eta_i=eta_view, eta_o=eta_src, length=g.length[mat], exclude_zeroth=zeroth,
                            renormalise=renormalise)
        weight = smp.weight
        src = smp.direction
    live = np.flatnonzero(weight > 0)
    if live.size == 0:
        return None
    side = -1.0 if trans else 1.0
    r = rows[live]
    o = (hit.p[r] + (side * hit.eps[r])[:, None] * hit.ng[r]).astype(np.float32)
    out_w = (w[live] * weight[live]).astype(np.float32)
    return ContinuedPaths(r, o, np.ascontiguousarray(src[live], np.float32), lam[live], out_w,
                          np.full(live.size, trans))


def sample_finite_pattern(w_o, n, t, s, period, ratio: float, slits: int, length: float, lam_nm, transmission: bool,
                          rng, exclude_zeroth: bool = False):
    """Source directions for viewer directions ``w_o`` (B, 3) at a LINES grating in air, drawn
    from its finite-N pattern (docs/physics.md section 3.13): eta = pi D (w_o + w_src) . t / lambda
    from the cumulative power W(eta) of ``kernel.finite_pattern_table`` over the propagating
    range (u in [alpha_o - r, alpha_o + r], r = sqrt(1 - beta_o^2); the |eta| < pi/2 period left
    out with ``exclude_zeroth``), linear between the table's nodes; the spread along s from
    sinc^2 (``sample_sinc2``). ``n`` (B, 3) the normal on the viewer's side, ``period``,
    ``lam_nm`` (B,) nm, ``length`` nm. Returns (directions (B, 3) float64, zero where nothing
    propagates; weights (B,) float64 = f / p, the plain (not renormalised) pattern's kernel
    ratio^2 (N D / lambda) (L / lambda) sinc^2(ratio eta) F_N(eta) sinc^2(pi L v / lambda)
    over the sample's density in (u, v): the propagating power P_N times the point's N-slit
    power over its table interval's mean, ~P_N(w_o))."""
    w_o = np.asarray(w_o, np.float64)
    b = len(w_o)
    d = np.asarray(period, np.float64)
    lam = np.asarray(lam_nm, np.float64)
    alpha, beta = np.einsum("ij,ij->i", w_o, t), np.einsum("ij,ij->i", w_o, s)
    r = np.sqrt(np.maximum(1.0 - beta * beta, 0.0)) * (1 - 1e-12)
    scale = np.pi * d / lam  # eta per unit u
    e_lo, e_hi = (alpha - r) * scale, (alpha + r) * scale
    eta_max = float(np.max(np.maximum(np.abs(e_lo), np.abs(e_hi)))) if b else 1.0
    nodes, w = finite_pattern_table(ratio, slits, eta_max)
    w_lo, w_hi = np.interp(e_lo, nodes, w), np.interp(e_hi, nodes, w)
    if exclude_zeroth:
        z_lo = np.interp(np.clip(-0.5 * np.pi, e_lo, e_hi), nodes, w)
        gap = np.interp(np.clip(0.5 * np.pi, e_lo, e_hi), nodes, w) - z_lo
    else:
        z_lo, gap = w_hi, np.zeros(b)
    mass = w_hi - w_lo - gap
    target = w_lo + rng.random(b) * mass
    target = np.where(target >= z_lo, target + gap, target)  # past the zeroth period
    k = np.clip(np.searchsorted(w, target, side="right") - 1, 0, len(w) - 2)
    dw, de = w[k + 1] - w[k], nodes[k + 1] - nodes[k]
    eta = nodes[k] + np.where(dw > 0, (target - w[k]) / np.where(dw > 0, dw, 1.0), 0.5) * de
    u_src = eta / scale - alpha
    x = sample_sinc2(rng.random(b)) if length > 0 else np.zeros(b)
    v_src = -beta + x * lam / max(length, 1e-300)
    nz2 = 1.0 - u_src * u_src - v_src * v_src
    ok = (mass > 0) & (dw > 0) & (nz2 > 0)
    nz = np.sqrt(np.maximum(nz2, 0.0)) * (-1.0 if transmission else 1.0)
    direction = np.where(ok[:, None], u_src[:, None] * t + v_src[:, None] * s + nz[:, None] * n, 0.0)
    # f / p: the pattern's density dW/deta = ratio^2 (N / pi) sinc^2(ratio eta) F_N(eta) at the point
    # over the sampled density (dW_k / deta_k) / mass; the spread's sinc^2 cancels up to its table's share
    point = ratio * ratio * (slits / np.pi) * sinc2(ratio * eta) * multislit(eta, slits)
    weight = np.where(ok, point * mass * (_SPREAD_MASS if length > 0 else 1.0) * de / np.where(dw > 0, dw, 1.0), 0.0)
    return direction, weight


def lobe_pdf(g, mat: int, w_o, w_src, t, s, normal, period, edges_nm, footprint=None) -> np.ndarray:
    """(B, K) the solid-angle density, per wavelength bin, with which the order lobe (one sample
    per bin) draws w_src (B, 3) from the viewer's direction w_o, for the power heuristic against
    the grating's next events (docs/physics.md section 3.13): the plain pattern's bin mean
    (``radiance.diffracted_radiance(renormalise=False)``, over the pixel's footprint where given,
    centred on the pixel: the same for every sample of a pixel) over the finite-N propagating
    power of w_o's side, P_N(w_o) (less the zeroth order's e_0 where the base carries it), times
    |cos theta_src|. Both sides of the weight (the next event at w_i, the lobe at its sample)
    call this, so their weights sum to one."""
    from .radiance import diffracted_radiance  # (radiance imports nothing of this module)

    edges = np.asarray(edges_nm, np.float64)
    f = diffracted_radiance(g, mat, w_o, w_src, t, s, normal, period, edges, None, renormalise=False,
                            footprint=footprint).astype(np.float64)
    ratio = float(g.slit_width[mat] / g.period[mat])
    d = np.asarray(period, np.float64)[:, None]
    w_o = np.asarray(w_o, np.float64)
    centre = 0.5 * (edges[1:] + edges[:-1])[None, :]
    p_n = finite_propagating_power(np.sum(w_o * t, axis=1)[:, None], np.sum(w_o * s, axis=1)[:, None], centre, ratio,
                                   d, int(g.slit_count[mat]), np.diff(edges)[None, :])
    if g.zeroth_in_base is not None and bool(g.zeroth_in_base[mat]):
        p_n = p_n - ratio * ratio
    cos = np.abs(np.sum(np.asarray(w_src, np.float64) * np.asarray(normal, np.float64), axis=1))[:, None]
    return np.where(p_n > 1e-12, f * cos / np.maximum(p_n, 1e-12), 0.0)
