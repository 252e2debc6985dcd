"""The eye pass: a spectral path tracer with the source paper's caustics and diffraction
(the specular transport itself is transport.SpecularWalker).

The source paper's eye pass (Kobayashi & Kawai; docs/physics.md section 4.2), grown into a path
tracer (section 4.5; pbrt-v4's PathIntegrator): at every diffuse (two-sided Lambertian) vertex,
direct light by shadow rays plus the caustic irradiance of the light pass's illumination map,
then a cosine-sampled bounce under Cycles' bounce limits and Russian roulette; at a grating, the
diffraction of every light that reaches it (grating_hits.py) and, along one sampled order, the
path continued to whatever it finds (``_GratingTrace``, docs/physics.md section 3.13); at an emitter and where a ray leaves
the scene, the emitted radiance; at mirrors and glass the path goes on. Paths the light pass
already counted (diffuse <- specular <- emitter) are left out. Every tile writes the films:
Direct (one diffuse vertex), Indirect (more), Caustics, Diffraction and emitted light seen.

The tile tracer is the walker's hooks over named stages of this folder, reading one frozen
``constants.EyeConstants`` built per render and writing one ``tile_output.TileOutput`` per tile;
what a hit's shading leaves for its bounce travels in a ``surface_interaction.HitShading``:

    on_segment, on_miss, on_hit (emitters)   emission.py          emitted light, MIS-weighted
    on_hit (normal maps, BSDF parameters)    surface_interaction.py
    on_hit (lights, meshes, world; caustics) next_event.py        one next-event routine, MIS
    on_hit (gratings)                        grating_hits.py      diffracted light
    (gratings: the order lobe)               _GratingTrace        the path continued along an order
    survives, after_delta, scatter           continuation.py      roulette, BSDF sampling, counts
    dielectric_bounce                        fresnel_split.py     both branches at the first glass
    through_media (every segment)            medium_interaction.py  media: emission, transmittance, scattering
    every stage's film adds                  tile_output.py
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, fields

import numpy as np

from ...transport import wavelengths
from ...sampling import footprint
from ...sampling.sampler import SLOT_LIGHT, SLOT_PARAMS, SLOT_WIDTH, PixelSampler, vertex_pair
from ...gratings import layering as grating_layering
from ...materials.spectra import DIFFUSE
from ...materials.surface import surface_reflectance
from ...transport.path_state import Caustic, PathState
from ...transport.walker import MICROFACET, Hit, Rays, SpecularWalker
from ...sampling.specular_numbers import bounce_choice
from ..light import splat_bounce
from . import emission, fresnel_split
from .constants import EyeConstants, eye_constants
from .continuation import count_delta, lambert_bounce, microfacet_bounce, russian_roulette
from .grating_hits import grating_light
from .next_event import BraggLobeEvents, MicrofacetLobe, caustic_light, lambert_next_events, next_events
from .surface_interaction import HitShading, bend_normals, reflects, surface_lobes
from .tile_output import TileOutput, TileResult

__all__ = ["EyePass", "TileResult"]


class EyePass:
    """Traces tiles of camera samples through a prepared scene (prepare.PreparedScene), with the
    light pass's caustics and grating records (light_pass.LightPassResult; None: no light pass),
    as ``plan`` (render/plan.RenderPlan of ``prepared``) says.

    Stateless between calls, so several threads may trace tiles at once.
    """

    def __init__(self, prepared, light=None, *, plan):
        if light is not None and light.key != prepared.key:
            raise ValueError("the light-pass result belongs to another prepared scene")
        self.prepared = prepared
        self.plan = plan
        self.constants: EyeConstants = eye_constants(prepared, light, plan)  # once per render
        # camera rays carry ray differentials (core/sampling/footprint.py) only to integrate gratings
        self.wants_differentials = self.constants.footprints
        self.any_emissive = bool(prepared.materials.emissive.any())  # else on_hit skips the emission stage

    def trace(self, origins, directions, pix, n_pixels: int, rng: np.random.Generator,
              u_lambda: np.ndarray | None = None, sampler_ids=None,
              differentials: np.ndarray | None = None, tmax: np.ndarray | None = None) -> TileResult:
        """Trace camera rays (one per sample) and return the per-pixel sum of their radiance.

        ``u_lambda`` (B,) in [0, 1): stratified numbers for the SAMPLE wavelength choice
        (uniform random if omitted). ``sampler_ids`` = (pixel ids (B,), sample numbers (B,),
        seed): the path vertices' numbers come from core/sampling/sampler.py's Sobol-Burley points of
        those pixels and samples; None: pseudo-random (``rng``). ``differentials`` (B, 5, 3):
        the rays' differentials per pixel step (``footprint.camera_differentials``), used where
        ``wants_differentials``; None: point samples. ``tmax`` (B,): the camera rays' clip end
        (core/sampling/camera.py camera_rays; None: unbounded).
        """
        if u_lambda is None:
            u_lambda = rng.random(len(pix))
        chunks = wavelengths.split_chunks(self.prepared, len(pix))
        if chunks is not None:  # SPLIT: bounded memory, the batch in pieces (core/transport/wavelengths.py)
            return wavelengths.merge_tiles([self.trace(
                origins[c], directions[c], pix[c], n_pixels, rng, u_lambda[c],
                None if sampler_ids is None else (sampler_ids[0][c], sampler_ids[1][c], sampler_ids[2]),
                None if differentials is None else differentials[c], None if tmax is None else tmax[c]) for c in chunks])
        if sampler_ids is None:
            tr = _TileTrace(self, n_pixels, rng)
            return tr.run(origins, directions, pix, u_lambda, differentials=differentials, tmax=tmax)
        tr = _TileTrace(self, n_pixels, rng, sampler_seed=int(sampler_ids[2]))
        return tr.run(origins, directions, pix, u_lambda, ids=sampler_ids[:2], differentials=differentials, tmax=tmax)

    def trace_escapes(self, origins, directions, rng: np.random.Generator, wavelength_index=None) -> dict:
        """Follow rays through the scene's specular surfaces and report the ones that leave it.

        With ``wavelength_index`` (B,) the rays start monochromatic at those grid indices,
        otherwise white. Returns a dict of arrays over escaping rays: 'origin' (last surface
        point), 'direction', 'weight' ((E, n) white or (E,) mono), 'lam' (or None), 'depth'
        (specular bounces) and 'ray' (index of the starting ray). For tests and tools: the
        directions leaving a prism, a lens, a mirror.
        """
        b = len(origins)
        tr = _TileTrace(self, b, rng, record_escapes=True)
        tr.run(np.asarray(origins, np.float32), np.asarray(directions, np.float32), np.arange(b),
               rng.random(b), wavelength_index)
        e = tr.escapes
        if not e:
            return {"origin": np.zeros((0, 3)), "direction": np.zeros((0, 3)), "weight": np.zeros(0),
                    "lam": None, "depth": np.zeros(0, int), "ray": np.zeros(0, int)}
        cat = lambda k: np.concatenate([x[k] for x in e])  # noqa: E731
        mono = [x for x in e if x["lam"] is not None]
        return {"origin": cat("origin"), "direction": cat("direction"),
                "weight": cat("weight") if len(mono) in (0, len(e)) else None,
                "lam": cat("lam") if len(mono) == len(e) else None, "depth": cat("depth"), "ray": cat("ray")}


@dataclass
class GlassState(PathState):
    """The path state with Cycles' PATH_RAY_TRANSPARENT_BACKGROUND (Film > Transparent with
    Transparent Glass, docs/physics.md section 6.11): ``tbg`` (B,) bool, the path has met only
    smooth refractions since the camera; the world it reaches is transparent."""
    tbg: np.ndarray | None = None


class _TileTrace(SpecularWalker):
    """One tile's trace: the walker's hooks over the stages, with the render's constants
    (``EyeConstants``), the tile's output (``TileOutput``) and its random numbers: the tile's
    stream ``rng`` and, with ``sampler_seed``, core/sampling/sampler.py's points of its pixels and
    samples. ``record_escapes``: keep the rays leaving the scene (``escapes``, trace_escapes)."""

    def __init__(self, eye: EyePass, n_pixels: int, rng: np.random.Generator, sampler_seed: int | None = None,
                 record_escapes: bool = False):
        super().__init__(eye.prepared, rng)
        self.eye = eye
        self.c = eye.constants
        self.sampler_seed = sampler_seed
        self.out = TileOutput(n_pixels, self.n)
        self.escapes = [] if record_escapes else None  # dicts of the rays leaving the scene
        self.any_emissive = eye.any_emissive
        self.transparent = bool(getattr(eye.prepared.settings, "film_transparent", False))
        self.transparent_glass = self.transparent and bool(getattr(eye.prepared.settings, "film_transparent_glass", False))
        self._camera_segment = False  # the next segment traced is the camera rays' (coverage: alpha)
        self._lobe_rng = None  # the grating lobe's own stream (``lobe_rng``), made when first needed
        # Film > Transparent: the materials' Holdout weights (None: no holdout), taken off the
        # alpha of camera rays meeting them (Cycles' integrate_surface_holdout; docs/physics.md 14.8)
        hold = getattr(eye.prepared.materials, "holdout", None)
        self.holdout = hold if self.transparent and hold is not None and (hold > 0).any() else None
        self._holdout_segment = False  # the hits on_hit shades next are the camera rays'
        self._hooks_media = self.c.media is not None  # [volumes] the walker calls through_media

    @property
    def lobe_rng(self) -> np.random.Generator:
        """The random stream of the paths continued along grating orders: spawned from the tile's
        stream's seed (drawing nothing from it), so they leave the tile's other numbers as they were."""
        if self._lobe_rng is None:
            seq = getattr(self.rng.bit_generator, "seed_seq", None)
            self._lobe_rng = (np.random.default_rng(seq.spawn(1)[0]) if isinstance(seq, np.random.SeedSequence)
                              else np.random.default_rng(self.rng.integers(1 << 62)))
        return self._lobe_rng

    def _new_state(self, b: int) -> PathState:
        """The path tracer's per-path state of ``b`` camera paths (core/transport/path_state.py),
        with ray differentials where the render carries them."""
        st = PathState.new(b, differentials=self.c.footprints)
        if not self.transparent_glass:
            return st
        return GlassState(**{f.name: getattr(st, f.name) for f in fields(PathState)}, tbg=np.ones(b, bool))

    def empty_mono(self) -> Rays:
        r = super().empty_mono()
        r.state = self._new_state(0)
        return r

    def run(self, origins, directions, pix, u_lambda, wavelength_index=None, ids=None, differentials=None,
            tmax=None) -> TileResult:
        b = len(pix)
        rays = Rays(origins, directions, pix.astype(np.int64), None, None,
                     np.zeros(b, np.int32), np.asarray(u_lambda, np.float64), self._new_state(b))
        if ids is not None:
            rays.state.pid[:] = ids[0]
            rays.state.sid[:] = ids[1]
        if self.c.footprints and differentials is not None:
            rays.state.rd = np.asarray(differentials, np.float32).reshape(b, 5, 3)
        mono = self.empty_mono()
        if wavelength_index is not None:  # start monochromatic (tools and tests)
            lam = np.broadcast_to(np.asarray(wavelength_index, np.int64), (b,)).copy()
            mono = Rays(rays.o, rays.d, rays.pix, np.ones(b, np.float32), lam, rays.depth, rays.u_lam, rays.state)
            rays = rays.take(np.zeros(b, bool))
        self._camera_segment = True
        self.walk(rays, mono, tmax)
        return self.out.result(self.rays_cast)

    def numbers(self, rays: Rays, slot: int):
        """The random numbers of one decision (``slot``: sampler.SLOT_LIGHT, SLOT_PARAMS or
        SLOT_BOUNCE) at these path vertices: core/sampling/sampler.py's Sobol-Burley points of their
        pixels and samples, a fresh range of dimension pairs per vertex and decision (so no two
        decisions on one path share numbers); the tile's pseudo-random stream without a seed."""
        if self.sampler_seed is None or len(rays) == 0:
            return self.rng
        st = rays.state
        return PixelSampler(self.rng, st.pid, st.sid, vertex_pair(rays.depth, slot), self.sampler_seed,
                            pairs=SLOT_WIDTH[slot])

    # ----------------------------------------------------------------- the walker's hooks
    def on_segment(self, rays: Rays, t: np.ndarray) -> None:
        if self._camera_segment:  # the camera rays: coverage, the film's alpha (Film > Transparent)
            self._camera_segment = False
            self.out.add_alpha(rays.pix, np.isfinite(t))
            self._holdout_segment = self.holdout is not None
        emission.lights_passed(self.c, self.out, rays, t)

    def through_media(self, rays: Rays, h):
        """[volumes] the media along the segments (core/integrators/eye/medium_interaction.py)."""
        return self.c.media.segment(self, rays, h)

    def on_miss(self, rays: Rays) -> None:
        if self.transparent:  # Film > Transparent: the world seen directly is alpha 0, black (Cycles)
            through = rays.depth > 0
            if self.transparent_glass:  # ... and through smooth glass: alpha lowered by the throughput
                glass = through & rays.state.tbg
                if glass.any():
                    g = rays.take(glass)
                    # the mean over the grid of the throughput (a mono ray's one bin: w / n)
                    if g.lam is None:
                        w = g.dense_w(self.n)
                        tput = w.mean(axis=1) if w.ndim == 2 else w
                    else:
                        tput = g.w.astype(np.float64) / self.n
                    self.out.lower_alpha(g.pix, tput)
                    through &= ~glass
            if not through.all():
                rays = rays.take(through)
                if not len(rays):
                    return
        emission.escaped(self.c, self.out, rays, self.escapes)

    def on_hit(self, rays: Rays, hit: Hit, kind: np.ndarray, rng) -> HitShading | None:
        """Emission, then (paths not final) the surface interaction, the opal's lobe, the
        microfacet and Lambertian next events, gratings and caustic lookups; returns what
        ``scatter`` reuses."""
        c, out = self.c, self.out
        prepared = self.prepared
        st = rays.state
        if self._holdout_segment:  # camera rays on a Holdout: its weight off the pixel's alpha
            self._holdout_segment = False
            h = self.holdout[hit.mat]
            first = (h > 0) & (rays.depth == 0)
            if first.any():
                out.lower_alpha(rays.pix[first], h[first])
        if self.any_emissive:
            emits = prepared.materials.emissive.take(hit.mat)
            if np.count_nonzero(emits) and not emission.surface_emission_unit(c, out, rays, hit, emits):
                emission.surface_emitted(c, out, rays.take(emits), hit.take(emits))
        live = ~st.final  # a final segment only gathers emission
        n_live = np.count_nonzero(live)  # (counts cost a fifth of ndarray.any's call on small masks)
        if not n_live:
            return None
        if c.normal_maps:  # bend the shading normal of diffuse hits (core/materials/surface.py); scatter reuses it
            bend = live & ((kind == DIFFUSE) | (kind == MICROFACET))
            if bend.any():
                bend_normals(prepared, hit, bend)
        shading = HitShading()
        if c.bragg is not None:  # the opal lobe, before its body is shaded (core/integrators/bragg_shading.py)
            shading.bragg = self._shade_opal(rays, hit, live, rng)
        if self.any_microfacet:  # rough and layered surfaces: core/materials/bsdf.py, one lobe drawn per hit
            micro = live & self.microfacet[hit.mat]
            if rays.lam is None:  # white rays at a dispersive glass split first; their children shade
                micro &= ~prepared.materials.dispersive[hit.mat]
            if micro.any():
                rm, hm = rays.take(micro), hit.take(micro)
                if c.layers:
                    rm = grating_layering.scale_base(prepared, rm, hm)
                params, mixture = surface_lobes(prepared, c.mixed_layers, rm, hm, self.numbers(rm, SLOT_PARAMS))
                shading.micro = (micro, params, mixture)  # for scatter(): the same lobes for light and bounce
                self._shade_microfacet(rm, hm, params, mixture, rng)
            kind = np.where(micro, -1, kind)  # shaded: not Lambertian below
        full_live = live
        if n_live < len(live):
            idx = live.nonzero()[0]
            rays, hit, kind = rays.take(idx), hit.take(idx), kind.take(idx)
            st = rays.state
        if prepared.gratings.any:
            on_grating = prepared.gratings.enabled[hit.mat]
            if c.scattering is not None:  # diffuse -> grating -> light: the light pass's caustic
                on_grating &= ~(c.scattering[hit.mat] & (st.caustic == Caustic.RECEIVER))
            if on_grating.any():
                rg = rays.take(on_grating)
                grating_light(c, out, rg, hit.take(on_grating), rng, follow=self._follow_grating,
                              events=self._grating_events(rg), lobe_rng=self.lobe_rng, allowed=self._lobe_allowed)
        diffuse = kind == DIFFUSE
        if c.black is not None:  # emission-only surfaces: the denoising features, then nothing
            black = diffuse & c.black[hit.mat]
            if black.any():
                diffuse = diffuse & ~black
                first = black & (st.nd == 0)
                if first.any():
                    out.denoising_features(rays.take(first), hit.take(first), c.albedo_rgb)
        if np.count_nonzero(diffuse):
            rows = diffuse.nonzero()[0]  # the diffuse hits' rows in on_hit's batch
            self._shade_lambert(rays, hit, rows, rows if n_live == len(live) else full_live.nonzero()[0].take(rows),
                                shading, rng)
        return shading

    def survives(self, rays: Rays, rng) -> np.ndarray:
        return russian_roulette(self.c, rays, rng)

    def after_delta(self, rays: Rays, transmitted: np.ndarray) -> Rays:
        if self.transparent_glass:  # a reflection ends the transparent background (Cycles' path_state_next)
            rays.state.tbg = rays.state.tbg & transmitted
        return count_delta(self.c, rays, transmitted)

    def scatter(self, rays: Rays, hit: Hit, kind: np.ndarray, can_bounce: np.ndarray, rng,
                shaded: HitShading | None = None) -> Rays | None:
        """The bounces at non-specular surfaces: rough and layered ones through core/materials/bsdf.py
        (with the lobe on_hit drew, ``shaded``), Lambertian ones by a cosine-weighted direction,
        the opal's lobe continuations."""
        c = self.c
        micro_out = None
        if shaded is not None and shaded.micro is not None:
            micro, params, mixture = shaded.micro
            micro_out = microfacet_bounce(c, rays, hit, micro, params, can_bounce, self.numbers, mixture)
            kind = np.where(micro, -1, kind)
        out = micro_out
        sel = (kind == DIFFUSE) & ~rays.state.final
        if c.black is not None:  # a black surface reflects nothing: the path ends
            sel &= ~c.black[hit.mat]
        if sel.any():
            body = lambert_bounce(c, rays, hit, sel, can_bounce, shaded, self.numbers)
            if body is not None:
                out = body if micro_out is None or not len(micro_out) else Rays.concat(body, micro_out)
        if c.bragg is not None:
            out = c.bragg.continue_paths(c.limits, self.rng, rays, hit, can_bounce, out,
                                         None if shaded is None else shaded.bragg)
        if self.transparent_glass and out is not None and len(out):  # a diffuse or rough bounce: opaque
            out.state.tbg = np.zeros(len(out), bool)
        return out

    def mirror_bounce(self, rays: Rays, hit: Hit) -> Rays:
        out = super().mirror_bounce(rays, hit)  # a grating's zeroth order, or the base's share (section 3.3)
        return grating_layering.continue_specular(self.prepared, out, hit, None) if self.c.layers else out

    def choice_numbers(self, rays: Rays, rng) -> np.ndarray:
        """Smooth glass's reflect / refract choice from the vertex's bounce numbers (stratified
        over the pixel's samples, as Cycles draws its glass closure's choice; core/sampling/specular_numbers.py),
        not the tile's pseudo-random stream: glass_sphere's error at 64 spp 0.0054 -> 0.0038."""
        st = rays.state
        return bounce_choice(st.pid, st.sid, rays.depth, self.sampler_seed, self.rng)

    def dielectric_bounce(self, rays: Rays, hit: Hit, rng, u=None):
        layers = self.c.layers
        if self.c.fresnel_split and self.escapes is None:
            # camera rays take both branches (core/integrators/eye/fresnel_split.py, docs/physics.md section 4.12)
            return fresnel_split.split_first_dielectric(self, rays, hit, rng, u, super().dielectric_bounce)
        out, transmitted = super().dielectric_bounce(rays, hit, rng, u)
        if layers:
            out = grating_layering.continue_specular(self.prepared, out, hit, transmitted)
        return out, transmitted

    def _grating_events(self, rays: Rays):
        """(B,) bool: the grating hits of ``rays`` that diffract the lights, meshes and records
        (None: all of them; ``_GratingTrace`` leaves some to the records)."""
        return None

    def _lobe_allowed(self, rays: Rays, transmitted) -> np.ndarray:
        """(B,) bool: the rays whose order (``transmitted``: crossing the surface, (B,) or scalar)
        the bounce limits let go on: counted as glossy (reflected) or transmission, the walker's
        ``survives`` rule without roulette at the order itself (the continued mono paths are rouletted
        at their later vertices, continuation.russian_roulette)."""
        c = self.c
        st = rays.state
        tr = np.broadcast_to(np.asarray(transmitted, bool), (len(rays),))
        glossy, transmission = st.glossy + ~tr, st.transmission + tr
        return (rays.depth < c.limits[0]) & np.where(tr, transmission <= c.limits[3], glossy <= c.limits[2])

    def _follow_grating(self, rays: Rays, cont) -> None:
        """Trace the paths that leave grating hits of ``rays`` along sampled orders (``cont``:
        gratings.lobe.ContinuedPaths) to their ends in a ``_GratingTrace``, and add everything
        they find to the Diffraction part (docs/physics.md section 3.13). The order is a
        specular-like bounce under the bounce limits (``_lobe_allowed``); its pdf (``cont.pdf``,
        0: none) weighs the emissive meshes the segment meets against the grating's next event."""
        src = rays.take(cont.rows)
        st = src.state
        tr = cont.transmitted
        k = np.flatnonzero(self._lobe_allowed(src, tr))
        if k.size == 0:
            return
        b = k.size
        base = {f.name: getattr(st, f.name) for f in fields(PathState)}
        base = {name: (None if v is None else v[k]) for name, v in base.items()}
        state = LobeState(**base, lobe=np.ones(b, np.int8))
        state.glossy, state.transmission = (st.glossy + ~tr)[k], (st.transmission + tr)[k]
        state.pdf = np.zeros(b, np.float32) if cont.pdf is None else np.asarray(cont.pdf[k], np.float32)
        state.final = np.zeros(b, bool)
        if state.rd is not None:  # a point sample from here on (the order's footprint is not carried)
            state.rd = footprint.zero_differentials(b)
        mono = Rays(cont.origin[k], cont.direction[k], src.pix[k], cont.weight[k], cont.lam[k],
                    (src.depth[k] + 1).astype(np.int32), src.u_lam[k], state)
        child = _GratingTrace(self)
        child.walk(child.empty_white(), mono)
        self.out.shadow_rays += child.out.shadow_rays
        self.rays_cast += child.rays_cast

    # ----------------------------------------------------------------- on_hit's stages
    def _shade_opal(self, rays: Rays, hit: Hit, live: np.ndarray, rng):
        """The opal's Bragg lobe at its hits among ``live``: its next events, then the body's
        share of the throughput (core/integrators/bragg_shading.py); returns the hits' lobes for
        the continuation (None: no opal hit)."""
        c = self.c
        bragg = c.bragg
        sel = bragg.opal_hits(rays, hit, live)
        if not sel.any():
            return None
        r, h = rays.take(sel), hit.take(sel)
        lobe = bragg.lobe(h)
        # a path from a caustic receiver (through mirrors, glass or other opal) to a light via
        # these planes is the light pass's (it scatters off BRAGG planes, scatter_light)
        nee = r.state.caustic == Caustic.NONE if c.caustics_cover_lights else np.ones(len(r), bool)
        if nee.all():
            next_events(c, self.out, r, h, BraggLobeEvents(c, r, h, lobe), rng)
        elif nee.any():
            k = np.flatnonzero(nee)
            rn, hn = r.take(nee), h.take(nee)
            next_events(c, self.out, rn, hn, BraggLobeEvents(c, rn, hn, lobe.take(k)), rng)
        return bragg.body_share(rays, r, h, sel, lobe)

    def _shade_microfacet(self, rays: Rays, hit: Hit, params, mixture, rng):
        """Next-event estimation at rough and layered surfaces (every lobe of a mixture: ``mixture``,
        core/materials/mixtures.py): every light, the emissive meshes
        and the world map, each weighted against BSDF sampling by the power heuristic; and the
        caustic map on a diffuse base (its diffuse lobe, approximately: base colour / pi)."""
        c, out = self.c, self.out
        first = rays.state.nd == 0
        if first.any():
            out.denoising_features(rays.take(first), hit.take(first), c.albedo_rgb)
        for sel, direct in ((first, True), (~first, False)):
            if sel.any():
                r, h = rays.take(sel), hit.take(sel)
                k = np.flatnonzero(sel)
                p = params.take(k) if not sel.all() else params
                mx = None if mixture is None else mixture.take(k)
                next_events(c, out, r, h, MicrofacetLobe(c, r, h, p, mx), self.numbers(r, SLOT_LIGHT),
                            out.film if direct else out.indirect)
        if c.caustic_map is not None:
            base = self.prepared.materials.kind[hit.mat] == DIFFUSE
            if base.any():
                caustic_light(c, out, rays.take(base), hit.take(base), rng)

    def _shade_lambert(self, rays: Rays, hit: Hit, diffuse: np.ndarray, rows: np.ndarray, shading: HitShading, rng):
        """The Lambertian hits at indices ``diffuse`` (rows ``rows`` of on_hit's batch): denoising
        features, the base colour once (kept in ``shading`` for the bounce), next events into
        Direct or Indirect, and the caustic map where the light pass's splats do not already hold it."""
        c, out = self.c, self.out
        prepared = self.prepared
        r, h = rays.take(diffuse), hit.take(diffuse)
        r_full = r
        if c.layers:
            r = grating_layering.scale_base(prepared, r, h)
        first = r.state.nd == 0
        n_first = np.count_nonzero(first)  # (counts cost a fifth of ndarray.any's call on small masks)
        if n_first:
            out.denoising_features(r.take(first), h.take(first), c.albedo_rgb)
        # the base colour once per hit: next events and the bounce (scatter) share it;
        # grey ones as one number per hit (core/integrators/eye/grey_paths.py; next events expand it)
        grey = c.greys.albedo(r, h.mat)
        albedo = surface_reflectance(prepared, h, r.lam) if grey is None else grey
        shading.diffuse = (rows, albedo)
        lit = reflects(c.n, c.probe, albedo)
        n_lit = np.count_nonzero(lit)
        if n_lit < len(lit):  # black (emission-only) surfaces reflect nothing: no next events
            if not n_lit:
                return
            k = lit.nonzero()[0]
            r, h, r_full, albedo, first = r.take(k), h.take(k), r_full.take(k), albedo[k], first[k]
            n_first = np.count_nonzero(first)
        if grey is not None:
            albedo = None  # the next events take the spectra where they need them
        if n_first == len(first):
            lambert_next_events(c, out, r, h, self.numbers(r, SLOT_LIGHT), out.film, albedo)
        else:
            if n_first:
                k = first.nonzero()[0]
                rf = r.take(k)
                lambert_next_events(c, out, rf, h.take(k), self.numbers(rf, SLOT_LIGHT), out.film,
                                    None if albedo is None else albedo[k])
            k = (~first).nonzero()[0]
            rn = r.take(k)
            lambert_next_events(c, out, rn, h.take(k), self.numbers(rn, SLOT_LIGHT), out.indirect,
                                None if albedo is None else albedo[k])
        if c.caustic_map is not None:
            if c.scattering is not None:
                own = c.scattering.take(h.mat)
                if np.count_nonzero(own):  # the map holds the base's share there already
                    caustic_light(c, out, r_full.take(own), h.take(own), rng)
                    r, h = r.take(~own), h.take(~own)
            if c.direct_splat is not None:  # camera -> diffuse: the light pass's splat has it (section 4.9)
                seen = (r.depth == 0) & c.direct_splat.take(h.mat)
                if c.splat_bounce is not None:  # ... and one diffuse bounce on (section 4.11)
                    seen |= splat_bounce.covered(c.splat_bounce, r, h)
                if np.count_nonzero(seen):
                    r, h = r.take(~seen), h.take(~seen)
            caustic_light(c, out, r, h, rng)


@dataclass
class LobeState(PathState):
    """The path state of a path continued along a grating's order (``_GratingTrace``): ``lobe``
    (B,) int8, 1 on the segment leaving the grating, 2 after mirrors and glass only since the
    grating, 0 after a diffuse or rough vertex."""
    lobe: np.ndarray | None = None


class _IntoDiffraction(TileOutput):
    """A ``_GratingTrace``'s output: each film part it writes (direct, indirect, caustics,
    background ...) is the parent tile's Diffraction part itself, so the continued paths add
    there directly (a film per continuation, zeroed and summed, cost the CD studio scene ~45 %)."""

    def __init__(self, parent: TileOutput):
        self._into = parent.diffraction
        super().__init__(parent.n_pixels, parent.n)

    def _new_film(self) -> np.ndarray:
        return self._into


class _GratingTrace(_TileTrace):
    """The paths continued along a grating's sampled orders (docs/physics.md section 3.13), traced
    as the tile's paths are, into their own ``TileOutput`` that the parent adds to its Diffraction
    part. The partition that keeps every light counted once:

    - on the segment leaving the grating (``lobe`` 1) the lights and suns are the grating's next
      events' (grating_hits.grating_light's shadow rays): what the segment meets of them is not
      added; the emissive meshes it meets are, weighted against the grating's next event by the
      power heuristic where its ``PathState.pdf`` (the lobe's, gratings.lobe.lobe_pdf) is > 0;
      the world it reaches is added with weight 1 (the grating does not sample it);
    - after mirrors and glass only (``lobe`` 2), emitters and the world are the light pass's
      grating records' where the light pass ran (light -> mirrors / glass -> grating), else added;
    - another grating met before any diffuse vertex (``lobe`` 1 or 2) diffracts the lights,
      meshes and records only without a light pass: with one, light -> that grating -> ... ->
      the first grating is in the first grating's records (made at every arrival after a
      specular vertex, a diffraction included);
    - after a diffuse or rough vertex (``lobe`` 0) the path is any path: MIS and caustic rules
      as everywhere.
    """

    def __init__(self, parent: _TileTrace):
        super().__init__(parent.eye, parent.out.n_pixels, parent.lobe_rng, sampler_seed=parent.sampler_seed)
        self.out = _IntoDiffraction(parent.out)  # every part it writes is the parent's Diffraction part
        self.transparent = self.transparent_glass = False  # a diffracted path: never the film's background
        self.records = self.c.record_map is not None
        self.emissive = self.any_emissive
        self.any_emissive = False  # on_hit adds the emission itself, by the partition
        self.world_only = dataclasses.replace(self.c, soft_suns=np.zeros(0, np.int64))

    def _new_state(self, b: int) -> PathState:
        st = PathState.new(b, differentials=self.c.footprints)
        return LobeState(**{f.name: getattr(st, f.name) for f in fields(PathState)}, lobe=np.zeros(b, np.int8))

    def empty_white(self) -> Rays:
        return Rays(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32), np.zeros(0, np.int64), None, None,
                    np.zeros(0, np.int32), np.zeros(0), self._new_state(0))

    def _emits(self, rays: Rays) -> np.ndarray:
        """(B,) bool: the rays whose emitters this trace adds (the partition above)."""
        lobe = rays.state.lobe
        return (lobe == 0) if self.records else (lobe != 1)

    def _grating_events(self, rays: Rays):
        # light -> (mirrors, glass, gratings) -> this grating -> ... -> the first grating: with a
        # light pass, the first grating's records hold it (they record every arrival after a
        # specular vertex, a diffraction included)
        return (rays.state.lobe == 0) if self.records else None

    def on_segment(self, rays: Rays, t: np.ndarray) -> None:
        keep = self._emits(rays)
        if keep.all():
            emission.lights_passed(self.c, self.out, rays, t)
        elif keep.any():
            emission.lights_passed(self.c, self.out, rays.take(keep), t[keep])

    def on_miss(self, rays: Rays) -> None:
        full = self._emits(rays)
        if full.any():
            emission.escaped(self.c, self.out, rays.take(full), None)
        world = rays.state.lobe == 1  # the world along the order: no suns (the grating's next events)
        if world.any():
            wr = rays.take(world)
            wr.state.pdf = np.zeros(len(wr), np.float32)  # the grating does not sample the world: weight 1
            emission.escaped(self.world_only, self.out, wr, None)

    def on_hit(self, rays: Rays, hit: Hit, kind: np.ndarray, rng) -> HitShading | None:
        if self.emissive:
            # the meshes met on the segment leaving the grating, where its lobe has a pdf: weighted
            # against the grating's next event by the power heuristic (surface_emitted, section 3.13)
            own = self._emits(rays) | ((rays.state.lobe == 1) & (rays.state.pdf > 0))
            emits = self.prepared.materials.emissive.take(hit.mat) & own
            if np.count_nonzero(emits):
                emission.surface_emitted(self.c, self.out, rays.take(emits), hit.take(emits))
        return super().on_hit(rays, hit, kind, rng)

    def after_delta(self, rays: Rays, transmitted: np.ndarray) -> Rays:
        lobe = rays.state.lobe
        rays.state.lobe = np.where(lobe == 1, np.int8(2), lobe)
        return super().after_delta(rays, transmitted)

    def scatter(self, rays: Rays, hit: Hit, kind: np.ndarray, can_bounce: np.ndarray, rng,
                shaded: HitShading | None = None) -> Rays | None:
        out = super().scatter(rays, hit, kind, can_bounce, rng, shaded)
        if out is not None and len(out):
            out.state.lobe = np.zeros(len(out), np.int8)
        return out
