"""The BSDF-sampling stage of the eye pass: how a path goes on, and what it counts.

Under Cycles' bounce limits (total, diffuse, glossy, transmission) and Russian roulette after
three bounces (pbrt-v4's rule; docs/physics.md section 4.5): at a Lambertian vertex a
cosine-weighted direction (the BRDF's importance sampling, weight = albedo), at rough and
layered surfaces a direction from core/materials/bsdf.py's sampler, counted as Cycles counts it;
at mirrors and glass (``count_delta``) a glossy or transmission bounce. Each sets the path's
``PathState``: its vertex counts, the BSDF pdf the emission stage's MIS needs, its caustic code
(a path the light pass's caustics cover, section 4.5), and ``final`` - a path at its limit still
takes one emission-only segment, so emitters the next-event stage does not sample are still
seen once (and MIS stays whole).
"""

from __future__ import annotations

import numpy as np

from ...gratings import layering as grating_layering
from ...materials import bsdf
from ...materials.spectra import DIFFUSE
from ...materials.surface import surface_reflectance
from ...sampling.sampler import SLOT_BOUNCE
from ...transport.path_state import MAX_DIFFUSE_VERTICES, Caustic
from ...transport.walker import Hit, Rays
from ..light import splat_bounce
from .surface_interaction import bump, reflects

__all__ = ["russian_roulette", "count_delta", "lambert_bounce", "microfacet_bounce"]


def russian_roulette(c, rays: Rays, rng) -> np.ndarray:
    """Specular bounces go on below the total limit and past Russian roulette (after three
    bounces, survival probability = the largest spectral throughput, at most 1, survivors
    reweighted by 1 / that: unbiased; pbrt-v4's rule). A mono (dispersed) ray's throughput is
    its weight over ``PathState.split``, which its split set to the wavelength pick's factor
    times the white parent's (core/transport/wavelengths.py ``child_split``): it is judged by
    what its white parent would have been, times what it lost since. The reweighted weights are
    a new array (subsets taken earlier may still gather the old one: core/transport/rows.py)."""
    depth = rays.depth
    ok = (depth < c.limits[0]) & ~rays.state.final
    if rays.w is not None:  # camera rays (unit weights, None) are not deep
        deep = ok & (depth >= 3)
        if np.count_nonzero(deep):
            # a Fresnel-split child (core/integrators/eye/fresnel_split.py) is rouletted as its unsplit path
            wmax = rays.w.max(axis=1) if rays.w.ndim == 2 else rays.w
            q = np.minimum(wmax / rays.state.split, np.float32(1.0))
            roulette = deep & (q < 1)
            if np.count_nonzero(roulette):
                alive = rng.random(len(rays), np.float32) < q
                ok &= ~roulette | alive
                kept = roulette & alive
                w = rays.w.copy()
                w[kept] = w[kept] / (q[kept, None] if w.ndim == 2 else q[kept])
                rays.w = w
    return ok


def count_delta(c, rays: Rays, transmitted: np.ndarray) -> Rays:
    """Count a mirror or dielectric bounce (reflection: glossy, refraction: transmission, as
    Cycles counts them) and drop paths over their kind's limit. A specular bounce has no BSDF
    pdf for MIS, and makes a path that left a caustic receiver a caustic path."""
    st = rays.state
    st.glossy = st.glossy + ~transmitted
    st.transmission = st.transmission + transmitted
    st.pdf = np.zeros(len(rays), np.float32)
    st.caustic = np.where(st.caustic == Caustic.RECEIVER, np.int8(Caustic.PATH), st.caustic)
    ok = np.where(transmitted, st.transmission <= c.limits[3], st.glossy <= c.limits[2])
    return rays.take(ok)


def lambert_bounce(c, rays: Rays, hit: Hit, sel: np.ndarray, can_bounce: np.ndarray, shading, numbers) -> Rays | None:
    """The bounces of the Lambertian hits ``sel`` (B,) bool (not final, not black): a
    cosine-weighted direction about ns drawn from ``numbers(rays, slot)`` (the vertices'
    sampler), weight times their base colours (those on_hit computed, ``shading``: a
    surface_interaction.HitShading or None, else looked up); a path that loses roulette takes
    no segment at all, one at its total limit its emission-only one."""
    # roulette applies to the bounce; a path that loses it takes no segment at all
    sel = sel & (can_bounce | (rays.depth >= c.limits[0]))
    k = sel.nonzero()[0]
    if len(k) == 0:
        return None
    r, h = rays.take(k), hit.take(k)
    albedo = None if shading is None else shading.albedo_at(sel)
    if albedo is None:
        albedo = c.greys.albedo(r, h.mat)
    if albedo is None:
        albedo = surface_reflectance(c.prepared, h, r.lam)
    # (B,) for white rays: grey base colours, the weight stays one number (core/integrators/eye/grey_paths.py)
    grey = albedo.ndim == 1 and r.lam is None
    if grey and not c.greys.is_grey(r):  # spectral weights: the grey colour as a spectrum
        albedo, grey = albedo[:, None] * c.greys.basis, False
    lit = reflects(c.n, c.probe, albedo)
    n_lit = np.count_nonzero(lit)  # (counts cost a fifth of ndarray.any's call on small masks)
    if n_lit < len(lit):  # a zero-weight path (a black surface) ends here
        if not n_lit:
            return None
        k = lit.nonzero()[0]
        r, h, albedo = r.take(k), h.take(k), albedo[k]
    wi, cos = bsdf.cosine_hemisphere(h.ns, numbers(r, SLOT_BOUNCE))
    if c.bent:  # about ns; a direction below the geometric surface ends the path
        up = np.einsum("ij,ij->i", wi, h.ng) > 0
        if not up.all():
            r, h, wi, cos, albedo = r.take(up), h.take(up), wi[up], cos[up], albedo[up]
    b = len(r)
    o = (h.p + h.eps[:, None] * h.ng).astype(np.float32)
    bmp = bump(c.prepared, c.normal_maps, h, wi)
    if np.ndim(bmp):
        albedo = albedo * (bmp[:, None] if albedo.ndim == 2 else bmp)
    if grey:
        out = c.greys.scaled(r, albedo, r.moved(o, wi, None))
    else:
        out = r.moved(o, wi, r.weighted(albedo))
    if c.layers:
        out = grating_layering.scale_base(c.prepared, out, h)
    s = out.state
    s.nd = np.minimum(s.nd + 1, MAX_DIFFUSE_VERTICES).astype(np.int8)
    s.diffuse = s.diffuse + 1
    s.pdf = (cos * np.float32(1 / np.pi)).astype(np.float32)
    s.caustic = np.full(b, Caustic.RECEIVER if c.caustic_map is not None else Caustic.NONE)
    s.seen = splat_bounce.mark_bounce(c.splat_bounce, r, h)
    s.final = (s.diffuse > c.limits[1]) | (out.depth > c.limits[0])
    return out


def microfacet_bounce(c, rays: Rays, hit: Hit, micro: np.ndarray, params, can_bounce, numbers,
                      mixture=None) -> Rays | None:
    """The bounce at rough and layered surfaces (the hits ``micro`` (B,) bool, their lobes
    ``params``): a direction from core/materials/bsdf.py's sampler (``numbers(rays, slot)``: the
    vertices' sampler), counted as Cycles counts it (diffuse, glossy or transmission); a delta
    event (a layer smoother than MIN_ROUGHNESS) continues like a mirror or glass bounce. At hits
    whose material mixes layers (``mixture``, core/materials/mixtures.py LobeMixture) the drawn
    lobe's direction is weighed by the whole mixture, f / p with p = sum_i w_i p_i, which is
    also the pdf MIS sees (docs/physics.md section 14.8)."""
    idx = np.flatnonzero(micro)
    go = can_bounce[idx] | (rays.depth[idx] >= c.limits[0])
    if not go.all():
        keep = np.flatnonzero(go)
        params = params.take(keep)
        mixture = None if mixture is None else mixture.take(keep)
    idx = idx[go]
    if idx.size == 0:
        return None
    r, h = rays.take(idx), hit.take(idx)
    # the third number (reflect or transmit, coat or base) only where a lobe chooses: one
    # Sobol pair fewer for metals and glossy surfaces
    chooses = np.isin(params.lobe, (bsdf.DIELECTRIC, bsdf.PLASTIC)).any()
    u = numbers(r, SLOT_BOUNCE).random((len(r), 3 if chooses else 2), np.float32)
    if not chooses:
        u = np.concatenate([u, np.zeros((len(r), 1), np.float32)], axis=1)
    wi, weight, pdf, flags = bsdf.sample(params, -r.d, h.ns, h.ng, u)
    if mixture is not None:  # the whole mixture at the sampled direction (not at delta events)
        f_mix, p_mix = mixture.evaluate(params, -r.d, wi, h.ns, h.ng)
        mixed = np.zeros(len(r), bool)
        mixed[mixture.rows] = True
        mixed &= (flags != 0) & ((flags & bsdf.SINGULAR) == 0) & (p_mix > 0)
        if mixed.any():
            w_mix = f_mix / np.where(mixed, p_mix, np.float32(1.0))[:, None]
            if w_mix.shape[1] != weight.shape[1]:
                weight = np.broadcast_to(weight, w_mix.shape)
            weight = np.where(mixed[:, None], w_mix, weight).astype(np.float32)
            pdf = np.where(mixed, p_mix, pdf).astype(np.float32)
        weight = mixture.scale_singular(weight, flags)  # a delta lobe under a coat: its layer's W / P
    ok = flags != 0
    if not ok.all():
        r, h, wi, weight, pdf, flags = r.take(ok), h.take(ok), wi[ok], weight[ok], pdf[ok], flags[ok]
    if len(r) == 0:
        return None
    side = np.where(np.einsum("ij,ij->i", wi, h.ng) > 0, 1.0, -1.0).astype(np.float32)
    o = (h.p + (h.eps * side)[:, None] * h.ng).astype(np.float32)
    out = r.moved(o, wi, r.weighted(weight) if r.lam is None else r.w * weight[:, 0])
    if c.layers:
        out = grating_layering.scale_base(c.prepared, out, h)
    s = out.state
    singular = (flags & bsdf.SINGULAR) != 0
    diffuse = (flags & bsdf.DIFFUSE_REFLECTION) != 0
    transmitted = (flags & bsdf.TRANSMISSION) != 0
    glossy = ~diffuse & ~transmitted
    s.diffuse = s.diffuse + diffuse
    s.glossy = s.glossy + glossy
    s.transmission = s.transmission + transmitted
    s.nd = np.where(singular, s.nd, np.minimum(s.nd + 1, MAX_DIFFUSE_VERTICES)).astype(np.int8)
    s.pdf = np.where(singular, np.float32(0.0), pdf).astype(np.float32)
    receiver = diffuse & (c.prepared.materials.kind[h.mat] == DIFFUSE) & (c.caustic_map is not None)
    # a delta event after a receiver makes a caustic path; a diffuse one at a receiver: RECEIVER (1), else NONE
    s.caustic = np.where(singular, np.where(s.caustic == Caustic.RECEIVER, np.int8(Caustic.PATH), s.caustic),
                         receiver.astype(np.int8)).astype(np.int8)
    over = ((s.diffuse > c.limits[1]) | (s.glossy > c.limits[2])
            | (s.transmission > c.limits[3]) | (out.depth > c.limits[0]))
    # over a limit: a delta bounce ends; a scattering one takes its emission-only segment
    keep = ~(over & singular)
    s.final = over & ~singular
    return out.take(keep)
