"""The world seen diffracted by a reflection grating: orders sampled from the viewer's side
(docs/physics.md section 3.11).

Method. A LINES grating sends light arriving from w_src into order m leaving towards w_o when
the tangential direction cosines obey the grating equation (section 3.10),
w_o . t = -(w_src . t) + m lambda / D along t and w_o . s = -(w_src . s) + dv along s. The map
from w_src's direction cosines to w_o's is a translation, so it keeps d(cos) d(cos) = cos theta
d omega: each order carries radiance unchanged, times its power fraction. The radiance towards
w_o from a world of radiance L_world is therefore the sum over the orders that propagate

    L_o(w_o, lambda) = sum_m e_m K(w_src,m) L_world(w_src,m, lambda),

with e_m = (a/D)^2 sinc^2(pi m a / D) (section 3.2) and K the Harvey-Shack factor of the
incident direction w_src,m (1 without renormalisation). Read backwards the grating equation
gives w_src,m from w_o with the same sampler the light pass uses (grating_sampling.sample_orders
with w_o as its "incident" direction: the propagating set and e_m are the same), so one sample
draws m with probability e_m / sum_prop e and weighs L_world by sum_prop e * K(w_src,m). The
slit-length spread along s is sampled as there. A white camera ray first takes WAVELENGTHS
wavelength bins, evenly spaced from its stratified number (each uniform: weight n / WAVELENGTHS),
so each sample is mono.

The layering (section 3.3) says which orders this adds: over a smooth mirror whose zeroth order
is the specular continuation (``PreparedGratings.zeroth_in_base``) the zeroth order is left out
here (the continuation sees the world there already); over any other base every order, the
zeroth included (the base keeps 1 - f of its response). Other lights are not counted twice: the
eye pass's lights and the light pass's records are evaluated by ``diffracted_radiance`` and do
not include the world, and the light pass's world paths reach gratings only through mirrors or
glass. Not covered: transmission gratings over glass (the world behind them needs the ray
continued through the glass) and HEXAGONAL lattices; the diffracted image of other surfaces (only the world is
looked up, an occluded direction adds nothing).

A transmission grating (over a base that is not glass: air on both sides) sees the world behind
it the same way: the orders are sampled towards the far side (``sample_orders`` with
``transmission``; the grating equation's tangential map is the same) and the shadow ray leaves
from the far face (docs/physics.md section 3.11).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .kernel import harvey_shack_factor
from .order_sampling import sample_orders
from ..materials.spectra import DIELECTRIC

__all__ = ["diffracts_world", "world_through_grating", "WAVELENGTHS"]

#: wavelength bins a white camera ray takes at a grating, evenly spaced from its stratified
#: number (each with its own order and shadow ray): 4 cut the colour noise of one by about 2x
WAVELENGTHS = 4
#: the offset added to a sample's stratified wavelength number, so the bin chosen here is not the
#: one a later dispersive split of the same path draws (both stay stratified over the samples)
_LAMBDA_ROTATION = 0.6180339887498949


def diffracts_world(prepared) -> np.ndarray:
    """(M,) bool: the grating materials whose world light this module adds (LINES reflection
    gratings, and LINES transmission gratings whose base is not glass: air on both sides), all
    False when the world is black."""
    g = prepared.gratings
    world = prepared.environment is not None or bool(np.any(prepared.world_spectrum > 0))
    if not world or not g.any:
        return np.zeros(len(g.enabled), bool)
    glass = np.asarray(prepared.materials.kind) == DIELECTRIC
    trans = np.asarray(g.transmission, bool)
    return np.asarray(g.enabled, bool) & ~np.asarray(g.hexagonal, bool) & ~(trans & glass)


def world_through_grating(prepared, rays, hit, mat: int, t, s, period, rng, renormalise: bool = True):
    """The world radiance grating ``mat`` diffracts towards ``rays`` at ``hit`` (one sample each).

    ``t``, ``s`` (B, 3): the grating vector and slit direction at the hits; ``period`` (B,) nm.
    Returns (mono rays: the pixels and the wavelength bins sampled, (B',) contributions, number
    of shadow rays cast), or None when nothing leaves."""
    g = prepared.gratings
    b = len(rays)
    if b == 0:
        return None
    n = prepared.grid.n
    edges = prepared.grid.bin_edges
    if rays.lam is None:  # WAVELENGTHS bins per white ray, stratified over the pixel's samples
        rep = WAVELENGTHS
        each = np.repeat(np.arange(b), rep)
        rays, hit = rays.take(each), hit.take(each)
        t, s, period = t[each], s[each], np.asarray(period)[each]
        b *= rep
        u = (rays.u_lam + _LAMBDA_ROTATION + np.tile(np.arange(rep) / rep, b // rep)) % 1.0
        lam = np.minimum((u * n).astype(np.int64), n - 1)
        scale = np.float32(n / rep)
        w = scale if rays.w is None else rays.w[np.arange(b), lam] * scale
    else:
        lam, w = rays.lam, rays.w
    lam_nm = edges[lam] + rng.random(b) * (edges[lam + 1] - edges[lam])
    ratio = float(g.slit_width[mat] / g.period[mat])
    d = np.asarray(period, np.float64)
    zeroth = g.zeroth_in_base is not None and bool(g.zeroth_in_base[mat])
    trans = bool(g.transmission[mat])  # the world behind the grating: its orders leave the far side
    smp = sample_orders(-rays.d.astype(np.float64), hit.ng, t, s, d, d * ratio, lam_nm, trans, rng,
                        length=g.length[mat], exclude_zeroth=zeroth)
    weight = smp.weight
    src = smp.direction
    if renormalise:
        k = harvey_shack_factor(np.sum(src * t, axis=1), np.sum(src * s, axis=1), lam_nm, ratio, d)
        weight = np.where(weight > 0, weight * k, 0.0)
    live = np.flatnonzero(weight > 0)
    if live.size == 0:
        return None
    side = -1.0 if trans else 1.0
    o = (hit.p[live] + (side * hit.eps[live])[:, None] * hit.ng[live]).astype(np.float32)
    dirs = np.ascontiguousarray(src[live], np.float32)
    occ = prepared.accel.occluded(o, dirs, np.full(live.size, np.inf, np.float32))
    casts = live.size
    live, dirs = live[~occ], dirs[~occ]
    if live.size == 0:
        return None
    env = prepared.environment
    if env is not None:
        radiance = prepared.conv.illuminant_from_rgb(env.radiance_rgb(dirs))[np.arange(live.size), lam[live]]
    else:
        radiance = prepared.world_spectrum[lam[live]]
    contrib = (np.broadcast_to(w, (b,))[live] * weight[live] * radiance).astype(np.float32)
    out = dataclasses.replace(rays.take(live), lam=lam[live], w=None)
    return out, contrib, casts
