"""The next-event stage of the eye pass: light sampled at a path vertex, by shadow ray, with MIS.

At a diffuse, rough or layered vertex (docs/physics.md section 4.5; pbrt-v4's PathIntegrator
``SampleLd``): one sample of every light, of the emissive meshes (core/lights/mesh_lights.py:
power-proportional points) and of the world map (its luminance distribution), each weighted
against BSDF sampling by Veach's power heuristic (Veach 1997, section 9.2) where BSDF sampling
can also find the emitter, and added to the film if its shadow ray reaches it. ``next_events``
is the one routine for every lobe: Lambertian, core/materials/bsdf.py's microfacet lobes and the
opal's Bragg lobe (core/integrators/bragg_shading.py) differ only in the ``NextEventLobe`` they
pass. The Lambertian vertices' analytic lights take a factored fast path (``direct_light``:
all shadow rays in one call, unit-weight rays summed per (material, light)). The caustic map's
irradiance (the light pass's caustics, section 4.2) is looked up here too (``caustic_light``).

Where the kernels run (core/util/jit.py), ``direct_light``, the Lambertian vertices' meshes and
world map (``lambert_next_events``) and ``caustic_light`` take fused paths (``_direct_fused``,
``_lambert_fused``, ``_caustic_fused``): light samples drawn as before, then per light sample
one kernel for the weights and shadow-ray setup and one for the contribution and the film add
(core/integrators/eye/next_event_kernels.py), the shadow rays still one batched any-hit call; the
NumPy lines stay as the reference, and the fused paths fall back to them for inputs of other forms.
"""

from __future__ import annotations

import numpy as np

from ...lights.sources import sample_light_pdf
from ...materials import bsdf
from ...materials.surface import surface_reflectance
from ...transport.walker import Hit, Rays, light_spectrum_of
from ...util.jit import kernels_enabled
from .next_event_kernels import (NO_F32, NO_F32_2, NO_I64, NO_RGB, caustic_kernel, direct_add, direct_weigh,
                                 lambert_add, lambert_weigh, lobe_add, pixel_order, ray_weights)
from .surface_interaction import bump

__all__ = ["power_heuristic", "power_heuristic_f64", "light_samples", "visible", "next_events", "MicrofacetLobe",
           "LambertLobe", "BraggLobeEvents", "lambert_next_events", "direct_light", "caustic_light"]


def power_heuristic(p_this: np.ndarray, p_other: np.ndarray, light_first: bool = False) -> np.ndarray:
    """Veach's power heuristic (beta = 2) for one sample of each of two strategies: the weight of
    a BSDF sample with pdf ``p_this`` against light sampling's ``p_other`` (``light_first``: the
    arguments are the light sample's pdf and then the BSDF's). A zero pdf for the sample's own
    strategy means a specular or camera ray with no competitor: weight 1."""
    a = np.asarray(p_this, np.float32)
    b = np.asarray(p_other, np.float32)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # pdfs past 1e19: inf, mapped below
        a2, b2 = a * a, b * b
        w = np.where(a2 + b2 > 0, a2 / (a2 + b2), np.float32(1.0))
    if not light_first:
        w = np.where(a > 0, w, np.float32(1.0))
    return np.where(np.isfinite(w), w, np.float32(1.0)).astype(np.float32)


def power_heuristic_f64(p_light, p_lobe) -> np.ndarray:
    """The power heuristic of a light sample against a lobe's sampling, in float64 (the opal
    lobe's pdfs are float64; ``power_heuristic`` with ``light_first`` in float32)."""
    a, b = np.asarray(p_light, np.float64), np.asarray(p_lobe, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where(a * a + b * b > 0, a * a / (a * a + b * b), 1.0)
    return np.where(np.isfinite(w), w, 1.0).astype(np.float32)


class _RowsOf:
    """``table[rows]`` (B, n) without forming it: indexing with the entries a next event keeps
    (``light_spectrum_of``) gathers those rows only."""

    ndim = 2

    def __init__(self, table, rows):
        self.table, self.rows = table, rows

    def __getitem__(self, idx):
        return self.table[self.rows[idx]]

    def __array__(self, dtype=None, copy=None):
        out = self.table[self.rows]
        return out if dtype is None else out.astype(dtype)


def _through_medium(media, r: Rays, contrib, dist):
    """[volumes] ``contrib`` of next events from surfaces times the world medium's transmittance
    along their shadow rays of lengths ``dist`` (medium_interaction.MediumStage.surface_shadow)."""
    tr = media.surface_shadow(dist)
    if tr is None:
        return contrib
    return contrib * (tr if r.lam is None else tr[np.arange(len(r)), r.lam])


def light_samples(prepared, hit: Hit, rng, analytic: bool = True) -> list:
    """One next-event sample per emitter at the hits: every light (``analytic``), the emissive
    meshes (core/lights/mesh_lights.py: power-proportional points) and the world map (its luminance
    distribution). Each is (wi (B, 3), distance (B,), scalar weight (B,), spectrum (n,) or
    (B, n), light pdf (B,) or None for delta lights, shadow-ray end pad)."""
    lights = prepared.lights
    b = len(hit.p)
    samples = []
    for li in range(len(lights) if analytic else 0):  # the lights (a handful)
        wi, dist, g, pl = sample_light_pdf(lights, li, hit.p, rng)
        samples.append((np.asarray(wi, np.float32), dist, g, lights.spectrum[li], pl, 0.0))
    if prepared.mesh_lights is not None:
        wi, dist, g, prim, pdf = prepared.mesh_lights.sample(hit.p, rng)
        em = _RowsOf(prepared.materials.emission, prepared.tri_material[prim])  # gathered for the lit rows only
        samples.append((wi, dist, g, em, pdf, 2 * prepared.tri_offset[prim]))
    if prepared.environment is not None:
        wi, pdf, rgb = prepared.environment.sample(rng.random(b), rng.random(b))
        with np.errstate(divide="ignore"):
            g = np.where(pdf > 0, 1.0 / pdf, 0.0)
        radiance = prepared.conv.illuminant_from_rgb(rgb).astype(np.float32)
        samples.append((wi.astype(np.float32), np.full(b, np.inf, np.float32), g, radiance,
                        pdf.astype(np.float32), 0.0))
    return samples


def visible(prepared, out, hit: Hit, wi, dist, pad, live, side=None) -> np.ndarray:
    """The entries of ``live`` whose shadow ray from the hit along ``wi`` reaches its light
    sample (``dist`` less twice the offset and ``pad``), offset along ng (times ``side``,
    -1 for samples below the surface); counts the rays in ``out`` (a TileOutput)."""
    eps = hit.eps[live]
    off = eps if side is None else side * eps
    o = (hit.p[live] + off[:, None] * hit.ng[live]).astype(np.float32)
    d = np.asarray(dist, np.float32)[live]
    tmax = np.where(np.isinf(d), np.inf, d - 2 * eps - np.asarray(pad if np.ndim(pad) == 0 else pad[live]))
    occ = prepared.accel.occluded(o, np.ascontiguousarray(wi[live], np.float32), tmax.astype(np.float32))
    out.shadow_rays += len(occ)
    return live[~occ]


def next_events(c, out, rays: Rays, hit: Hit, lobe, rng, film=None, analytic: bool = True) -> None:
    """Next-event estimation at ``hit`` for the lobe ``lobe`` (a ``MicrofacetLobe``,
    ``LambertLobe`` or ``BraggLobeEvents``: its evaluate and pdf towards each light sample, the
    MIS weight against its own sampling, its contribution): one sample of each light
    (``analytic``), of the emissive meshes and of the world map (``light_samples``, numbers from
    ``rng``), each kept where the lobe reflects it and its shadow ray reaches the light, added to
    ``film``, or (None) to the film part of each path's vertex count + 1."""
    prepared = c.prepared
    nd = None if film is not None else rays.state.nd
    media = getattr(c, "media", None)  # [volumes] shadow rays through the world's medium (medium_interaction.py)
    fused = (kernels_enabled() and media is None and film is not None and isinstance(lobe, MicrofacetLobe)) \
        and _LobeAdd.of(rays)
    for wi, dist, g, spectrum, p_light, pad in light_samples(prepared, hit, rng, analytic):
        value, scale, live = lobe.weigh(wi, g, p_light)
        if live.size == 0:
            continue
        live = visible(prepared, out, hit, wi, dist, pad, live, lobe.shadow_side(wi, live))
        if live.size == 0:
            continue
        if fused and fused.add(out, film, live, value, scale, spectrum):
            continue
        r = rays.take(live)
        spec = light_spectrum_of(spectrum, live, r)
        contrib = lobe.contribution(r, live, value, scale, spec)
        if media is not None:
            contrib = _through_medium(media, r, contrib, np.asarray(dist)[live])
        if film is not None:
            out.accumulate(r, contrib, film)
            continue
        k_nd = nd[live]
        for k in np.unique(k_nd):  # the path's vertex counts (0, 1, 2+)
            part = k_nd == k
            out.accumulate(r.take(part), contrib[part], out.light_film(min(int(k) + 1, 2)))


class _LobeAdd:
    """next_events' contribution and film add of a MicrofacetLobe's light samples by the
    ``lobe_add`` kernel (no rays.take, no (B, n) contributions); ``of`` is None where the rays'
    weights have another form, ``add`` False (nothing done) for a sample of another form."""

    def __init__(self, rays: Rays, weights):
        self.rays, self.weights = rays, weights
        self.order = pixel_order(rays)
        self.pix = np.asarray(rays.pix, np.int64)
        self.lam = NO_I64 if rays.lam is None else np.asarray(rays.lam, np.int64)

    @classmethod
    def of(cls, rays: Rays):
        weights = ray_weights(rays)
        return None if weights is None else cls(rays, weights)

    def add(self, out, film, live, value, scale, spectrum) -> bool:
        b = len(self.pix)
        if isinstance(spectrum, _RowsOf):
            table, srow = spectrum.table, np.asarray(spectrum.rows, np.int64)
        elif np.ndim(spectrum) == 1:
            table, srow = np.asarray(spectrum)[None, :], np.zeros(b, np.int64)
        else:
            table, srow = spectrum, np.arange(b)
        value = np.asarray(value)
        if (table.dtype != np.float32 or value.dtype != np.float32 or np.asarray(scale).dtype != np.float32 or value.ndim != 2 or len(value) != b
                or value.shape[1] not in (1, out.n) or np.shape(scale) != (b,)):
            return False
        keep = np.zeros(b, bool)
        keep[live] = True
        mode, w2, w1, basis = self.weights
        lobe_add(film, out.n, self.pix, self.order, keep, self.lam, mode, w2, w1, basis, value,
                 np.asarray(scale, np.float32), np.ascontiguousarray(table), srow)
        return True


class MicrofacetLobe:
    """core/materials/bsdf.py's lobes (``params``) at ``hit`` for ``next_events``, with Cycles'
    bump-terminator term on Lambertian lobes; shadow rays leave on the light's side (a light
    behind a rough glass is seen through it). Hits whose material mixes layers (``mixture``, a
    core/materials/mixtures.py LobeMixture) are evaluated over all their lobes: f = sum_i w_i f_i
    and, for MIS, p = sum_i w_i p_i (docs/physics.md section 14.8)."""

    def __init__(self, c, rays: Rays, hit: Hit, params, mixture=None):
        self.prepared, self.normal_maps, self.hit, self.params = c.prepared, c.normal_maps, hit, params
        self.mixture = mixture
        self.wo = -rays.d
        self.lambert = params.lobe == bsdf.LAMBERT

    def weigh(self, wi, g, p_light):
        """(f cos (B, n') of the lobe, scale (B,): the sample's weight times the MIS weight and
        the bump term, the entries that reach the film) for light samples ``wi``."""
        hit = self.hit
        scale = np.asarray(g, np.float32)
        if self.mixture is not None:
            b = bump(self.prepared, self.normal_maps, hit, wi) if self.normal_maps else None
            f_cos, p_bsdf = self.mixture.evaluate(self.params, self.wo, wi, hit.ns, hit.ng, b)
        else:
            f_cos, p_bsdf = bsdf.evaluate(self.params, self.wo, wi, hit.ns, hit.ng)
        if self.mixture is None and self.normal_maps and self.lambert.any():
            scale = scale * np.where(self.lambert, bump(self.prepared, self.normal_maps, hit, wi), np.float32(1.0))
        if p_light is not None:
            scale = scale * power_heuristic(p_light, p_bsdf, light_first=True)
        return f_cos, scale, np.flatnonzero((scale > 0) & (f_cos.max(axis=1) > 0))

    def shadow_side(self, wi, live):
        return np.where(np.einsum("ij,ij->i", wi[live], self.hit.ng[live]) > 0, 1.0, -1.0).astype(np.float32)

    @staticmethod
    def contribution(r: Rays, live, f_cos, scale, spec):
        val = f_cos[live] * scale[live, None]
        return r.weighted(val * spec) if r.lam is None else r.w * val[:, 0] * spec


class LambertLobe:
    """The Lambertian lobe of base colours ``albedo`` at ``hit`` for ``next_events``, written out:
    f cos = albedo / pi * cos(wi, ns) and pdf = cos / pi where wo and wi are above ns and wi above
    ng (bsdf.evaluate's LAMBERT, without its frames and parameter tables), times Cycles'
    bump-terminator term on normal-mapped hits."""

    def __init__(self, c, rays: Rays, hit: Hit, albedo):
        self.prepared, self.normal_maps, self.hit, self.albedo = c.prepared, c.normal_maps, hit, albedo
        self.wo_up = np.einsum("ij,ij->i", rays.d, hit.ns) < 0  # (on_hit passes lit surfaces only: albedo > 0)

    def weigh(self, wi, g, p_light):
        """(the base colours, scale (B,) = g cos / pi times the bump term and the MIS weight, the
        entries that reach the film) for light samples ``wi`` (never delta: meshes, the world)."""
        hit = self.hit
        cos_s = np.einsum("ij,ij->i", wi, hit.ns)
        ok = self.wo_up & (cos_s > 0) & (np.einsum("ij,ij->i", wi, hit.ng) > 0)
        p_bsdf = np.where(ok, cos_s * np.float32(1 / np.pi), np.float32(0.0)).astype(np.float32)
        scale = np.asarray(g, np.float32) * p_bsdf  # g cos / pi
        if self.normal_maps:
            scale = scale * bump(self.prepared, self.normal_maps, hit, wi)
        scale = scale * power_heuristic(p_light, p_bsdf, light_first=True)
        return self.albedo, scale, np.flatnonzero(scale > 0)

    @staticmethod
    def shadow_side(wi, live):
        return None  # above the surface (weigh keeps wi . ng > 0)

    @staticmethod
    def contribution(r: Rays, live, albedo, scale, spec):
        if r.lam is None:
            return r.weighted(albedo[live] * scale[live, None] * spec)
        return r.w * albedo[live] * scale[live] * spec


class BraggLobeEvents:
    """The opal's Bragg lobe (core/materials/bragg_bsdf.py ``BraggLobe``) at ``hit`` for
    ``next_events``, in float64 as the lobe computes (power heuristic against the lobe's
    sampling where the light can also be found by it)."""

    def __init__(self, c, rays: Rays, hit: Hit, lobe):
        self.lobe, self.edges, self.lam = lobe, c.bragg.edges, rays.lam
        self.wo = -np.asarray(rays.d, np.float64)
        self.ns = np.asarray(hit.ns, np.float64)

    def weigh(self, wi, g, p_light):
        f_cos, p_lobe = self.lobe.evaluate(self.wo, wi, self.ns, self.edges, self.lam)
        scale = np.asarray(g, np.float32)
        if p_light is not None:
            scale = scale * power_heuristic_f64(p_light, p_lobe)
        peak = f_cos.max(axis=1) if self.lam is None else f_cos
        return f_cos, scale, np.flatnonzero((scale > 0) & (peak > 0))

    @staticmethod
    def shadow_side(wi, live):
        return None  # from outside the stone, offset along ng

    contribution = staticmethod(LambertLobe.contribution)  # f cos (B, n) or (B,) in the base colours' place


def lambert_next_events(c, out, rays: Rays, hit: Hit, rng, film, albedo=None):
    """Next-event estimation at Lambertian vertices: every light (with the factored fast path
    of ``direct_light``), then the emissive meshes and the world map (``next_events`` with the
    ``LambertLobe``).
    ``albedo``: the hits' base colours (surface_reflectance), computed here if None; ``rng``:
    the vertices' SLOT_LIGHT numbers."""
    direct_light(c, out, rays, hit, rng, film, albedo)
    if c.mesh_lights is not None or c.prepared.environment is not None:
        if kernels_enabled() and getattr(c, "media", None) is None and _lambert_fused(c, out, rays, hit, rng, film, albedo):
            return
        if albedo is None:
            albedo = surface_reflectance(c.prepared, hit, rays.lam)
        next_events(c, out, rays, hit, LambertLobe(c, rays, hit, albedo), rng, film, analytic=False)


def direct_light(c, out, rays: Rays, hit: Hit, rng, film, albedo=None):
    """The analytic lights at Lambertian vertices: one sample per light per ray, all shadow rays
    in a single any-hit call, the power heuristic against cosine sampling for the lights BSDF
    sampling can find; unit-weight white rays on untextured surfaces summed per (material,
    light) (``TileOutput.accumulate_factored``)."""
    prepared = c.prepared
    lights = prepared.lights
    nl, b = len(lights), len(rays)
    if nl == 0 or b == 0:
        return
    media = getattr(c, "media", None)  # [volumes] shadow rays through the world's medium
    if kernels_enabled() and media is None and _direct_fused(c, out, rays, hit, rng, film, albedo):
        return
    # One sample per light per ray; all shadow rays in a single any-hit call.
    flat = not c.bent
    factors = np.zeros((b, nl), np.float32)
    origins, dirs, tmax, idx, dists = [], [], [], [], []
    for li in range(nl):  # loop over lights (a handful), not rays
        wi, dist, g, p_light = sample_light_pdf(lights, li, hit.p, rng)
        # shaded with ns; light from below the geometric surface does not reach it (no leaks)
        cos_s = np.einsum("ij,ij->i", wi, hit.ns)
        above = True if flat else np.einsum("ij,ij->i", wi, hit.ng) > 0
        f = np.where((cos_s > 0) & above, g * cos_s * bump(prepared, c.normal_maps, hit, wi), np.float32(0.0))
        if p_light is not None:  # a light BSDF sampling can also find: the power heuristic
            f = f * power_heuristic(p_light, np.maximum(cos_s, 0) * np.float32(1 / np.pi), light_first=True)
        live = np.flatnonzero(f > 0)
        if live.size == 0:
            continue
        eps = hit.eps[live]
        origins.append(hit.p[live] + eps[:, None] * hit.ng[live])
        dirs.append(wi[live])
        tmax.append(np.where(np.isinf(dist[live]), np.inf, dist[live] - 2 * eps))
        idx.append(live * nl + li)
        dists.append(np.asarray(dist, np.float64)[live])
        factors.reshape(-1)[live * nl + li] = f[live]
    if not idx:
        return
    occ = prepared.accel.occluded(np.concatenate(origins).astype(np.float32),
                                  np.concatenate(dirs).astype(np.float32),
                                  np.concatenate(tmax).astype(np.float32))
    out.shadow_rays += len(occ)
    factors.reshape(-1)[np.concatenate(idx)[occ]] = 0.0
    if media is not None and media.media.world >= 0:  # [volumes] per shadow ray, per wavelength
        flat = np.concatenate(idx)
        tr = media.surface_shadow(np.concatenate(dists))  # (S, n)
        spec = np.zeros((b, prepared.grid.n), np.float32)
        np.add.at(spec, flat // nl, factors.reshape(-1)[flat, None] * tr * lights.spectrum[flat % nl])
        brdf = (surface_reflectance(prepared, hit, rays.lam) if albedo is None else albedo) * np.float32(1 / np.pi)
        irradiance = spec if rays.lam is None else spec[np.arange(b), rays.lam]
        out.accumulate(rays, rays.weighted(brdf * irradiance), film)
        return
    if (rays.lam is None and rays.w is None and not prepared.textures.uses("color")
            and out.accumulate_factored(prepared, rays.pix, hit.mat, factors, film)):
        return
    brdf = (surface_reflectance(prepared, hit, rays.lam) if albedo is None else albedo) * np.float32(1 / np.pi)
    if rays.lam is None:
        irradiance = factors @ lights.spectrum          # (B, L) @ (L, n)
    else:
        irradiance = np.sum(factors * lights.spectrum[:, rays.lam].T, axis=1)
    out.accumulate(rays, rays.weighted(brdf * irradiance), film)


def caustic_light(c, out, rays: Rays, hit: Hit, rng):
    """Caustic radiance at diffuse hits: the illumination map's irradiance * albedo / pi
    (looked up with a one-element jitter: a box filter over neighbouring elements). Where the
    kernels run, one pass (``caustic_kernel``) looks up, weighs and adds to the film."""
    prepared = c.prepared
    if kernels_enabled() and _caustic_fused(c, out, rays, hit, rng):
        return
    lit = c.caustic_lit[hit.prim]
    if not lit.all():
        rays, hit = rays.take(lit), hit.take(lit)
    if not len(rays):
        return
    irr = c.caustic_map.irradiance(hit.prim, hit.bu, hit.bv, hit.front, rng)
    brdf = surface_reflectance(prepared, hit) * np.float32(1 / np.pi)
    radiance = irr * brdf
    contrib = rays.weighted(radiance) if rays.lam is None else rays.w * radiance[np.arange(len(rays)), rays.lam]
    out.accumulate(rays, contrib, out.caustics)


def _caustic_fused(c, out, rays: Rays, hit: Hit, rng) -> bool:
    """caustic_light by caustic_kernel; False (nothing done) where its inputs have another form."""
    weights = ray_weights(rays)
    cmap = c.caustic_map
    if weights is None or cmap.flux.dtype != np.float32:
        return False
    prepared = c.prepared
    lit = c.caustic_lit[hit.prim]
    m = int(np.count_nonzero(lit))
    if m == 0:
        return True
    if prepared.textures.uses("color"):
        sub = hit if m == len(lit) else hit.take(lit)
        albedo = surface_reflectance(prepared, sub)
        arow = np.cumsum(lit) - 1
    else:
        albedo = prepared.materials.reflectance
        arow = np.asarray(hit.mat, np.int64)
    if albedo.dtype != np.float32:  # (the NumPy lines multiply in its precision)
        return False
    r1, r2 = rng.random(m), rng.random(m)  # IlluminationMap.irradiance's numbers, in the same order
    lam = np.zeros(0, np.int64) if rays.lam is None else np.asarray(rays.lam, np.int64)
    mode, w2, w1, basis = weights
    lay = cmap.layout
    caustic_kernel(out.caustics, out.n, np.asarray(rays.pix, np.int64), pixel_order(rays), lam, mode, w2, w1,
                    basis, c.caustic_lit, lay.k, lay.offset, lay.element_area, cmap.flux,
                    np.asarray(hit.prim, np.int64), np.asarray(hit.bu, np.float64), np.asarray(hit.bv, np.float64),
                    np.asarray(hit.front, np.bool_), np.asarray(r1, np.float64), np.asarray(r2, np.float64),
                    np.ascontiguousarray(albedo), arow)
    return True


def _lambert_fused(c, out, rays: Rays, hit: Hit, rng, film, albedo) -> bool:
    """next_events with the LambertLobe for the emissive meshes and the world map (what
    lambert_next_events does after direct_light) by lambert_weigh and lambert_add per light
    sample, the shadow rays still one batched any-hit call; False (nothing done, no numbers
    drawn) where the inputs have another form."""
    prepared = c.prepared
    weights = ray_weights(rays)
    f32 = np.float32
    if (weights is None or film is None or hit.p.dtype != f32 or hit.ns.dtype != f32 or hit.ng.dtype != f32
            or hit.eps.dtype != f32 or rays.d.dtype != f32
            or (prepared.mesh_lights is not None and prepared.materials.emission.dtype != f32)):
        return False
    textured = prepared.textures.uses("color")
    b = len(rays)
    if albedo is None and not textured:
        table = prepared.materials.reflectance
        if table.dtype != f32:
            return False
        alb, arow, fixed = table, np.asarray(hit.mat, np.int64), False
    else:
        if albedo is None:
            albedo = surface_reflectance(prepared, hit, rays.lam)
        if albedo.dtype != f32:
            return False
        fixed = albedo.ndim == 1
        alb, arow = (albedo[:, None] if fixed else albedo), np.arange(b)
    # the samples, drawn in light_samples' order: meshes, then the world
    samples = []
    if prepared.mesh_lights is not None:
        wi, dist, g, prim, pdf = prepared.mesh_lights.sample(hit.p, rng)
        samples.append((wi, dist, g, pdf, 2 * prepared.tri_offset[prim], NO_RGB,
                        prepared.materials.emission, prepared.tri_material[prim]))
    if prepared.environment is not None:
        wi, pdf, rgb = prepared.environment.sample(rng.random(b), rng.random(b))
        with np.errstate(divide="ignore"):
            g = np.where(pdf > 0, 1.0 / pdf, 0.0)
        samples.append((wi.astype(f32), np.full(b, np.inf, f32), g, pdf.astype(f32), np.zeros(b), rgb,
                        NO_F32_2, NO_I64))
    lam = NO_I64 if rays.lam is None else np.asarray(rays.lam, np.int64)
    mode, w2, w1, basis = weights
    order = pixel_order(rays)
    pix = np.asarray(rays.pix, np.int64)
    basis_t = prepared.conv.emission_basis
    for wi, dist, g, pdf, pad, rgb, table, srow in samples:
        bump_v = bump(prepared, c.normal_maps, hit, wi) if c.normal_maps else None
        bump_v = NO_F32 if bump_v is None or np.ndim(bump_v) == 0 else np.ascontiguousarray(bump_v, f32)
        scale = np.empty(b, f32)
        live = np.empty(b, np.int64)
        o = np.empty((b, 3), f32)
        tmax = np.empty(b, f32)
        m = lambert_weigh(np.ascontiguousarray(wi), np.ascontiguousarray(g, f32),
                           np.ascontiguousarray(pdf, f32), rays.d, hit.ns, hit.ng, bump_v, hit.p, hit.eps,
                           np.ascontiguousarray(dist, f32), np.ascontiguousarray(pad), scale, live, o, tmax)
        if m == 0:
            continue
        live = live[:m]
        occ = prepared.accel.occluded(o[:m], np.ascontiguousarray(wi[live], f32), tmax[:m])
        out.shadow_rays += len(occ)
        keep = np.zeros(b, bool)
        keep[live[~occ]] = True
        if not keep.any():
            continue
        rgb = np.ascontiguousarray(rgb) if len(rgb) else rgb
        lambert_add(film, out.n, pix, order, keep, lam, mode, w2, w1, basis, alb, arow, fixed, scale,
                     rgb, basis_t, table, np.asarray(srow, np.int64))
    return True


def _albedo_rows(prepared, rays: Rays, hit: Hit, albedo):
    """(table, rows (B,), fixed column) with the hits' base colours table[rows] (at column lam,
    or column 0 when ``fixed``) for the kernels, without forming them for untextured materials;
    None where they are not float32."""
    if albedo is None and not prepared.textures.uses("color"):
        table = prepared.materials.reflectance
        return (table, np.asarray(hit.mat, np.int64), False) if table.dtype == np.float32 else None
    if albedo is None:
        albedo = surface_reflectance(prepared, hit, rays.lam)
    if albedo.dtype != np.float32:
        return None
    fixed = albedo.ndim == 1
    return (albedo[:, None] if fixed else albedo), np.arange(len(rays)), fixed


def _direct_fused(c, out, rays: Rays, hit: Hit, rng, film, albedo) -> bool:
    """direct_light by direct_weigh (per light) and direct_add, the shadow rays in one any-hit
    call and the factored film add where it applies; False (nothing done, no numbers drawn)
    where the inputs have another form."""
    prepared = c.prepared
    lights = prepared.lights
    weights = ray_weights(rays)
    f32 = np.float32
    if (weights is None or hit.p.dtype != f32 or hit.ns.dtype != f32 or hit.ng.dtype != f32
            or hit.eps.dtype != f32 or lights.spectrum.dtype != f32):
        return False
    nl, b = len(lights), len(rays)
    samples = [sample_light_pdf(lights, li, hit.p, rng) for li in range(nl)]  # the numbers, in light order
    factors = np.zeros((b, nl), f32)
    o, d, tmax = np.empty((b * nl, 3), f32), np.empty((b * nl, 3), f32), np.empty(b * nl, f32)
    idx = np.empty(b * nl, np.int64)
    m = 0
    for li, (wi, dist, g, p_light) in enumerate(samples):
        wi = np.ascontiguousarray(wi, f32)
        bump_v = bump(prepared, c.normal_maps, hit, wi)
        bump_v = NO_F32 if np.ndim(bump_v) == 0 else np.ascontiguousarray(bump_v, f32)
        # g in its own dtype: a spot's cone mask makes it float64, and the NumPy lines multiply in that
        m = direct_weigh(li, wi, np.ascontiguousarray(g),
                          NO_F32 if p_light is None else np.ascontiguousarray(p_light, f32), p_light is not None,
                          np.ascontiguousarray(dist, f32), hit.ns, hit.ng, not c.bent, bump_v, hit.p, hit.eps,
                          factors, o, d, tmax, idx, m)
    if m == 0:
        return True
    occ = prepared.accel.occluded(o[:m], d[:m], tmax[:m])
    out.shadow_rays += len(occ)
    factors.reshape(-1)[idx[:m][occ]] = 0.0
    if (rays.lam is None and rays.w is None and not prepared.textures.uses("color")
            and out.accumulate_factored(prepared, rays.pix, hit.mat, factors, film)):
        return True
    rows = _albedo_rows(prepared, rays, hit, albedo)
    if rows is None:  # (not float32: the NumPy lines' product, after the kernels' factors)
        brdf = (surface_reflectance(prepared, hit, rays.lam) if albedo is None else albedo) * f32(1 / np.pi)
        irradiance = (factors @ lights.spectrum if rays.lam is None
                      else np.sum(factors * lights.spectrum[:, rays.lam].T, axis=1))
        out.accumulate(rays, rays.weighted(brdf * irradiance), film)
        return True
    alb, arow, fixed = rows
    mode, w2, w1, basis = weights
    lam = NO_I64 if rays.lam is None else np.asarray(rays.lam, np.int64)
    direct_add(film, out.n, np.asarray(rays.pix, np.int64), pixel_order(rays), lam, mode, w2, w1, basis,
                alb, arow, fixed, factors, lights.spectrum)
    return True
