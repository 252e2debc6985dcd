"""The eye pass: a spectral path tracer with the source paper's caustics and diffraction
(the specular transport itself is transport.SpecularWalker).

The source paper's eye pass (Kobayashi & Kawai; docs/physics.md section 4.2), grown into a path
tracer (section 4.5; pbrt-v4's PathIntegrator): at every diffuse (two-sided Lambertian) vertex,
direct light by shadow rays plus the caustic irradiance of the light pass's illumination map,
then a cosine-sampled bounce under Cycles' bounce limits and Russian roulette; at a grating, the
diffraction of every light that reaches it (gratings.py); at an emitter and where a ray leaves
the scene, the emitted radiance; at mirrors and glass the path goes on. Paths the light pass
already counted (diffuse <- specular <- emitter) are left out. Every tile writes the films:
Direct (one diffuse vertex), Indirect (more), Caustics, Diffraction and emitted light seen.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...sampling import footprint
from ...transport import wavelengths
from ...gratings.directions import tangents_at
from ...gratings.radiance import diffracted_radiance, grating_frame
from ...sampling.sampler import SLOT_BOUNCE, SLOT_LIGHT, SLOT_PARAMS, SLOT_WIDTH, PixelSampler, vertex_pair
from ...gratings import layering as grating_layering
from ...gratings.order_sampling import scattering_materials
from ...gratings.world import diffracts_world, world_through_grating
from .grey_paths import GreyPaths
from ...lights.sources import (intersect_lights, is_delta, light_pdf, sample_light, sample_light_pdf, sun_radiance)
from ...lights.sources import AREA_DISK, AREA_RECT, POINT, SPOT, SUN
from ...materials.spectra import DIFFUSE
from ...materials.surface import shading_normal, surface_emission, surface_reflectance, surface_roughness
from ...transport.path_state import MAX_DIFFUSE_VERTICES, Caustic, PathState
from ...transport.walker import MICROFACET, Hit, Rays, SpecularWalker, light_spectrum_of, shading_normals
from ...materials import bsdf
from ..bragg_shading import BraggShading
from ..light.camera_splat import direct_materials, usable_splat
from .factored_film import add_scaled_spectra
from ...sampling.specular_numbers import bounce_choice
from . import fresnel_split
from ..light import splat_bounce

__all__ = ["EyePass", "TileResult"]


@dataclass
class TileResult:
    film: np.ndarray  # (P, n) sum of sample contributions per pixel (everything)
    # the parts of film (P, n) that are not Direct, or None where nothing was written:
    background: np.ndarray | None  # emitted light seen (world, emitters), directly or through mirrors and glass
    indirect: np.ndarray | None  # light that reached the eye through two or more diffuse vertices
    diffraction: np.ndarray | None  # diffracted by gratings
    caustics: np.ndarray | None  # caustic light from the light pass
    rays: int         # rays cast (camera, secondary and shadow)
    # denoising features, per-pixel sums over samples (P, 3), as Cycles' Denoising Albedo and
    # Denoising Normal passes: the first diffuse surface's linear RGB albedo times the
    # (grey) throughput of the mirrors and glass before it, and its world-space shading normal
    albedo: np.ndarray | None = None
    normal: np.ndarray | None = None


class EyePass:
    """Traces tiles of camera samples through a prepared scene (prepare.PreparedScene), with the
    light pass's caustics and grating records (light_pass.LightPassResult; None: no light pass).

    Stateless between calls, so several threads may trace tiles at once.
    """

    def __init__(self, prepared, light=None):
        if light is not None and light.key != prepared.key:
            raise ValueError("the light-pass result belongs to another prepared scene")
        self.prepared = prepared
        self.caustic_map = None if light is None else light.caustics
        # the triangles the caustic map holds flux on: the lookup runs only for hits there
        self.caustic_lit = None if self.caustic_map is None else self.caustic_map.lit_triangles()
        self.record_map = None if light is None else light.grating_records
        # (M,) bool: materials whose directly seen caustics the light pass splatted for this
        # camera (core/integrators/light/camera_splat.py, docs/physics.md section 4.9); None: the map everywhere
        self.direct_splat = (None if self.caustic_map is None or usable_splat(prepared, light) is None
                             else direct_materials(prepared))
        # (M,) bool: where the light pass's paths also took a diffuse bounce to the camera
        # (core/integrators/light/splat_bounce.py, docs/physics.md section 4.11); None: no such paths
        self.splat_bounce = (splat_bounce.receivers(prepared) if self.direct_splat is not None
                             and splat_bounce.enabled(prepared) else None)
        # camera rays carry ray differentials (core/sampling/footprint.py) only to integrate gratings
        self.wants_differentials = bool(prepared.gratings.any and getattr(prepared.settings, "grating_footprint", True))
        # (M,) Principled mixes whose layer is drawn per hit (metallic or transmission strictly
        # between 0 and 1); elsewhere the layer is fixed and no number is drawn for it
        mt, tr = np.asarray(prepared.materials.metallic), np.asarray(prepared.materials.transmission)
        self.mixed_layers = ((mt > 0) & (mt < 1)) | ((tr > 0) & (tr < 1))
        self.probe = _probe_wavelength(prepared)  # the black-surface test's wavelength (_TileTrace._reflects)

    def trace(self, origins, directions, pix, n_pixels: int, rng: np.random.Generator,
              u_lambda: np.ndarray | None = None, sampler_ids=None,
              differentials: np.ndarray | None = None) -> TileResult:
        """Trace camera rays (one per sample) and return the per-pixel sum of their radiance.

        ``u_lambda`` (B,) in [0, 1): stratified numbers for the SAMPLE wavelength choice
        (uniform random if omitted). ``sampler_ids`` = (pixel ids (B,), sample numbers (B,),
        seed): the path vertices' numbers come from core/sampling/sampler.py's Sobol-Burley points of
        those pixels and samples; None: pseudo-random (``rng``). ``differentials`` (B, 5, 3):
        the rays' differentials per pixel step (``footprint.camera_differentials``), used where
        ``wants_differentials``; None: point samples.
        """
        if u_lambda is None:
            u_lambda = rng.random(len(pix))
        chunks = wavelengths.split_chunks(self.prepared, len(pix))
        if chunks is not None:  # SPLIT: bounded memory, the batch in pieces (core/transport/wavelengths.py)
            return wavelengths.merge_tiles([self.trace(
                origins[c], directions[c], pix[c], n_pixels, rng, u_lambda[c],
                None if sampler_ids is None else (sampler_ids[0][c], sampler_ids[1][c], sampler_ids[2]),
                None if differentials is None else differentials[c]) for c in chunks])
        tr = _TileTrace(self, n_pixels, rng)
        if sampler_ids is None:
            return tr.run(origins, directions, pix, u_lambda, differentials=differentials)
        tr.sampler_seed = int(sampler_ids[2])
        return tr.run(origins, directions, pix, u_lambda, ids=sampler_ids[:2], differentials=differentials)

    def trace_escapes(self, origins, directions, rng: np.random.Generator, wavelength_index=None) -> dict:
        """Follow rays through the scene's specular surfaces and report the ones that leave it.

        With ``wavelength_index`` (B,) the rays start monochromatic at those grid indices,
        otherwise white. Returns a dict of arrays over escaping rays: 'origin' (last surface
        point), 'direction', 'weight' ((E, n) white or (E,) mono), 'lam' (or None), 'depth'
        (specular bounces) and 'ray' (index of the starting ray). For tests and tools: the
        directions leaving a prism, a lens, a mirror.
        """
        b = len(origins)
        tr = _TileTrace(self, b, rng)
        tr.escapes = []
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


class _TileTrace(SpecularWalker):
    """The state of one tile's trace: its film accumulators, ray count and the path tracer's
    per-path state (``Rays.state``, core/transport/path_state.py)."""

    def __init__(self, eye: EyePass, n_pixels: int, rng: np.random.Generator):
        super().__init__(eye.prepared, rng)
        self.caustic_map, self.record_map = eye.caustic_map, eye.record_map
        self.caustic_lit = eye.caustic_lit
        self.world_gratings = diffracts_world(eye.prepared)
        self.direct_splat = eye.direct_splat
        self.splat_bounce = eye.splat_bounce
        self.sampler_seed = None  # set by EyePass.trace when the tile numbers its samples
        s = eye.prepared.settings
        self.limits = (s.max_bounces, s.diffuse_bounces, s.glossy_bounces, s.transmission_bounces)
        # which emitters' caustic paths (diffuse <- specular... <- emitter) the light pass has
        # already counted: the eye pass leaves those paths out (docs/physics.md section 4.5)
        self.caustics_cover_lights = self.caustic_map is not None
        pl = eye.prepared.lights
        kinds = np.asarray(pl.kind)
        self.delta = np.array([is_delta(pl, i) for i in range(len(pl))], bool)
        # lights a ray can meet: area lights, points and spots with a radius; suns with an angle
        self.hittable = ~self.delta & np.isin(kinds, [POINT, SPOT, AREA_RECT, AREA_DISK])
        self.soft_suns = np.flatnonzero(~self.delta & (kinds == SUN))
        self.mesh_lights = eye.prepared.mesh_lights
        self.normal_maps = eye.prepared.textures.uses("normal")
        self._micro = None  # (hit, mask, SurfaceParams) of the microfacet hits on_hit shaded
        self._albedo_of = None  # (hit, rows, base colours) of the diffuse hits on_hit shaded
        self.bragg = BraggShading.for_prepared(eye.prepared)  # FCC opal lobes (None: no BRAGG material)
        # (M,) black diffuse materials (emission-only surfaces: no base colour, no colour texture,
        # no grating, no microfacet layer): their paths end after the emission (and the first
        # hit's denoising features) without next events, caustic lookups or a bounce
        pm = eye.prepared
        refl = pm.materials.reflectance
        self.black = ((pm.materials.kind == DIFFUSE) & ~pm.microfacet & ~pm.gratings.enabled
                      & (pm.textures.color < 0) & ((refl.max(axis=1) <= 0) if refl.size else True))
        if self.bragg is not None or not self.black.any():
            self.black = None
        # shading normals differ from the geometric ones: directions need both side tests
        self.bent = eye.prepared.corner_normals is not None or self.normal_maps
        self._n_pixels = n_pixels
        self.footprints = eye.wants_differentials  # rays carry differentials (core/sampling/footprint.py)
        self._film = self._new_film()  # light reflected by diffuse surfaces from direct lighting
        # the other parts of the film, allocated when first written (most scenes use a few):
        self._parts: dict[str, np.ndarray] = {}  # 'background' (world and emitters seen),
        #                                          'indirect', 'diffraction', 'caustics'
        self.escapes = None  # a list to record rays leaving the scene (trace_escapes)
        self._albedo = np.zeros((n_pixels, 3), np.float32)
        self._normal = np.zeros((n_pixels, 3), np.float32)
        self._albedo_rgb = np.asarray(eye.prepared.scene.materials.color, np.float32).reshape(-1, 3)
        self.layers = grating_layering.active(eye.prepared)  # gratings take their power from the base (section 3.3)
        # gratings the light pass scatters (section 3.10): the caustic map holds their diffracted
        # light on diffuse surfaces, and at a diffuse base only the base's share already
        pm = eye.prepared
        self.scattering = (scattering_materials(pm.gratings, pm.materials.kind, pm.microfacet)
                           if self.caustic_map is not None and pm.gratings.any else None)
        # grey path weights (core/integrators/eye/grey_paths.py), in the plain path tracer only: gratings, their
        # layers and the opal's lobes read spectral weights
        self.greys = GreyPaths(pm, enabled=not (pm.gratings.any or self.layers or self.bragg is not None))
        self.mixed_layers, self._probe = eye.mixed_layers, eye.probe

    def _reflects(self, albedo: np.ndarray) -> np.ndarray:
        """(B,) bool: base colours (B, n) spectra or (B,) values that are not zero everywhere.
        One column decides where ``_probe_wavelength`` found one (a (B, n) maximum costs about a
        tenth of a textured floor's eye pass)."""
        if albedo.ndim == 1:
            return albedo > 0
        if self._probe is not None and albedo.shape[1] == self.prepared.grid.n:
            return albedo[:, self._probe] > 0
        return albedo.max(axis=1) > 0

    def _new_film(self) -> np.ndarray:
        return np.zeros(self._n_pixels * self.n, np.float32)

    def _part(self, name: str) -> np.ndarray:
        arr = self._parts.get(name)
        if arr is None:
            arr = self._parts[name] = self._new_film()
        return arr

    @property
    def _background(self) -> np.ndarray:
        return self._part("background")

    @property
    def _diffraction(self) -> np.ndarray:
        return self._part("diffraction")

    @property
    def _caustics(self) -> np.ndarray:
        return self._part("caustics")

    def _light_film(self, vertices: int) -> np.ndarray:
        """The film part for light reaching the eye after ``vertices`` diffuse (non-specular)
        vertices: 0 emitted light seen (through mirrors and glass), 1 direct, 2+ indirect."""
        return self._background if vertices == 0 else self._film if vertices == 1 else self._part("indirect")

    def _new_state(self, b: int) -> PathState:
        """The path tracer's per-path state of ``b`` camera paths (core/transport/path_state.py),
        with ray differentials where the tile carries them."""
        return PathState.new(b, differentials=self.footprints)

    def empty_mono(self) -> Rays:
        r = super().empty_mono()
        r.state = self._new_state(0)
        return r

    def run(self, origins, directions, pix, u_lambda, wavelength_index=None, ids=None, differentials=None) -> TileResult:
        n, b = self.n, len(pix)
        rays = Rays(origins, directions, pix.astype(np.int64), None, None,
                     np.zeros(b, np.int32), np.asarray(u_lambda, np.float64), self._new_state(b))
        if ids is not None:
            rays.state.pid[:] = ids[0]
            rays.state.sid[:] = ids[1]
        if self.footprints and differentials is not None:
            rays.state.rd = np.asarray(differentials, np.float32).reshape(b, 5, 3)
        mono = self.empty_mono()
        if wavelength_index is not None:  # start monochromatic (tools and tests)
            lam = np.broadcast_to(np.asarray(wavelength_index, np.int64), (b,)).copy()
            mono = Rays(rays.o, rays.d, rays.pix, np.ones(b, np.float32), lam, rays.depth, rays.u_lam, rays.state)
            rays = rays.take(np.zeros(b, bool))
        self.walk(rays, mono)
        shape = (self._n_pixels, n)
        total = self._film
        for part in self._parts.values():
            total = total + part
        get = lambda k: self._parts[k].reshape(shape) if k in self._parts else None  # noqa: E731
        return TileResult(total.reshape(shape), get("background"), get("indirect"), get("diffraction"),
                          get("caustics"), self.rays_cast, self._albedo, self._normal)

    # ----------------------------------------------------------------- hooks
    def on_segment(self, rays: Rays, t: np.ndarray) -> None:
        """Sized lights a segment passes before it hits anything: their radiance, weighted
        against next-event estimation by the power heuristic (Veach 1997, section 9.2). Lights
        are invisible to camera rays and transparent to paths, as Cycles' default ray
        visibility has them; a caustic path the light pass counted is left out."""
        if not self.hittable.any():
            return
        seen = self._not_covered(rays) & (rays.depth > 0)
        if not seen.any():
            return
        r = rays.take(seen)
        idx, _, scale = intersect_lights(self.prepared.lights, r.o, r.d, t[seen])
        met = idx >= 0
        if not met.any():
            return
        r, idx, scale = r.take(met), idx[met], scale[met]
        p_light = np.zeros(len(r), np.float32)
        for li in np.unique(idx):  # the few lights met
            sel = idx == li
            p_light[sel] = light_pdf(self.prepared.lights, int(li), r.o[sel], r.d[sel])
        scale = scale * _power_heuristic(r.state.pdf, p_light)
        spectrum = self.prepared.lights.spectrum
        radiance = scale[:, None] * spectrum[idx] if r.lam is None else scale * spectrum[idx, r.lam]
        self._add_by_vertices(r, r.weighted(radiance))

    def _not_covered(self, rays: Rays) -> np.ndarray:
        """Rays whose emitter hit is not a caustic path the light pass counted (section 4.5)."""
        if not self.caustics_cover_lights:
            return np.ones(len(rays), bool)
        return rays.state.caustic != Caustic.PATH

    def _numbers(self, rays: Rays, slot: int):
        """The random numbers of one decision (``slot``: sampler.SLOT_LIGHT, SLOT_PARAMS or
        SLOT_BOUNCE) at these path vertices: core/sampling/sampler.py's Sobol-Burley points of their
        pixels and samples, a fresh range of dimension pairs per vertex and decision (so no two
        decisions on one path share numbers); the tile's pseudo-random stream without ids."""
        if self.sampler_seed is None or len(rays) == 0:
            return self.rng
        st = rays.state
        return PixelSampler(self.rng, st.pid, st.sid, vertex_pair(rays.depth, slot), self.sampler_seed,
                            pairs=SLOT_WIDTH[slot])

    def _add_by_vertices(self, rays: Rays, contrib):
        """Accumulate light found at the end of a path segment into the part its diffuse-vertex
        count says (``_light_film``)."""
        nd = rays.state.nd
        if len(nd) and (nd == nd[0]).all():
            self._accumulate(rays, contrib, self._light_film(min(int(nd[0]), 2)))
            return
        for k in np.unique(nd):
            sel = nd == k
            self._accumulate(rays.take(sel), contrib[sel], self._light_film(min(int(k), 2)))

    def on_miss(self, rays: Rays) -> None:
        if len(self.soft_suns):
            seen = self._not_covered(rays) & (rays.depth > 0)
            if seen.any():
                r = rays.take(seen)
                lights = self.prepared.lights
                p_light = sum(light_pdf(lights, int(li), r.o, r.d) for li in self.soft_suns)
                rad = sun_radiance(lights, r.d) * _power_heuristic(r.state.pdf, p_light)[:, None]
                self._add_by_vertices(r, r.weighted(rad) if r.lam is None else r.w * rad[np.arange(len(r)), r.lam])
        st = rays.state
        if self.escapes is not None:
            first = st.nd == 0  # paths that met only mirrors and glass
            r = rays.take(first)
            self.escapes.append({"origin": r.o, "direction": r.d, "weight": r.dense_w(self.n),
                                 "lam": r.lam, "depth": r.depth, "ray": r.pix})
        # the world through glass after a diffuse vertex is a caustic path the light pass
        # counted (it emits from the world too)
        keep = self._not_covered(rays)
        if not keep.all():
            rays = rays.take(keep)
            st = rays.state
        for nd in np.unique(st.nd):
            self._add_background(rays.take(st.nd == nd), self._light_film(min(int(nd), 2)))

    def on_hit(self, rays: Rays, hit: Hit, kind: np.ndarray, rng) -> None:
        prepared = self.prepared
        st = rays.state
        emits = prepared.materials.emissive[hit.mat]
        if emits.any() and not self._emitted_unit(rays, hit, emits):
            self._emitted(rays.take(emits), hit.take(emits))
        live = ~st.final  # a final segment only gathers emission
        if not live.any():
            return
        if self.normal_maps:  # bend the shading normal of diffuse hits (core/materials/surface.py); scatter reuses it
            bend = live & ((kind == DIFFUSE) | (kind == MICROFACET))
            if bend.any():
                ns = hit.ns.copy()
                ns[bend] = shading_normal(prepared, hit.take(bend))
                hit.ns = ns
        if self.bragg is not None:  # the opal lobe, before its body is shaded (core/integrators/bragg_shading.py)
            self.bragg.shade(self, rays, hit, live, rng)
        self._micro = None
        self._albedo_of = None  # (hit, rows, base colours) of the diffuse hits shaded here, for scatter
        if self.any_microfacet:  # rough and layered surfaces: core/materials/bsdf.py, one lobe drawn per hit
            micro = live & self.microfacet[hit.mat]
            if rays.lam is None:  # white rays at a dispersive glass split first; their children shade
                micro &= ~prepared.materials.dispersive[hit.mat]
            if micro.any():
                rm, hm = rays.take(micro), hit.take(micro)
                if self.layers:
                    rm = grating_layering.scale_base(prepared, rm, hm)
                params = self._surface_params(rm, hm, self._numbers(rm, SLOT_PARAMS))
                self._micro = (hit, micro, params)  # for scatter(): the same lobe for light and bounce
                self._shade_microfacet(rm, hm, params, rng)
            kind = np.where(micro, -1, kind)  # shaded: not Lambertian below
        full_hit, full_live = hit, live
        if not live.all():
            rays, hit, kind = rays.take(live), hit.take(live), kind[live]
            st = rays.state
        if prepared.gratings.any:
            on_grating = prepared.gratings.enabled[hit.mat]
            if self.scattering is not None:  # diffuse -> grating -> light: the light pass's caustic
                on_grating &= ~(self.scattering[hit.mat] & (st.caustic == Caustic.RECEIVER))
            if on_grating.any():
                self._grating_light(rays.take(on_grating), hit.take(on_grating), rng)
        diffuse = kind == DIFFUSE
        if self.black is not None:  # emission-only surfaces: the denoising features, then nothing
            black = diffuse & self.black[hit.mat]
            if black.any():
                diffuse = diffuse & ~black
                first = black & (st.nd == 0)
                if first.any():
                    self._denoising_features(rays.take(first), hit.take(first))
        if diffuse.any():
            r, h = rays.take(diffuse), hit.take(diffuse)
            r_full = r
            if self.layers:
                r = grating_layering.scale_base(prepared, r, h)
            first = r.state.nd == 0
            if first.any():
                self._denoising_features(r.take(first), h.take(first))
            # the base colour once per hit: next events and the bounce (scatter) share it;
            # grey ones as one number per hit (core/integrators/eye/grey_paths.py; next events expand it)
            grey = self.greys.albedo(r, h.mat)
            albedo = surface_reflectance(prepared, h, r.lam) if grey is None else grey
            self._albedo_of = (full_hit, np.flatnonzero(full_live)[diffuse], albedo)
            lit = self._reflects(albedo)
            if not lit.all():  # black (emission-only) surfaces reflect nothing: no next events
                r, h, r_full, albedo, first = r.take(lit), h.take(lit), r_full.take(lit), albedo[lit], first[lit]
                if len(r) == 0:
                    return
            if grey is not None:
                albedo = None  # the next events take the spectra where they need them
            if first.all():
                self._next_events(r, h, self._film, albedo)
            else:
                if first.any():
                    self._next_events(r.take(first), h.take(first), self._film,
                                      None if albedo is None else albedo[first])
                self._next_events(r.take(~first), h.take(~first), self._part("indirect"),
                                  None if albedo is None else albedo[~first])
            if self.caustic_map is not None:
                if self.scattering is not None and self.scattering[h.mat].any():
                    own = self.scattering[h.mat]  # the map holds the base's share there already
                    self._caustic_light(r_full.take(own), h.take(own), rng)
                    r, h = r.take(~own), h.take(~own)
                if self.direct_splat is not None:  # camera -> diffuse: the light pass's splat has it (section 4.9)
                    seen = (r.depth == 0) & self.direct_splat[h.mat]
                    if self.splat_bounce is not None:  # ... and one diffuse bounce on (section 4.11)
                        seen |= splat_bounce.covered(self.splat_bounce, r, h)
                    if seen.any():
                        r, h = r.take(~seen), h.take(~seen)
                self._caustic_light(r, h, rng)

    def survives(self, rays: Rays, rng) -> np.ndarray:
        """Specular bounces go on below the total limit and past Russian roulette (after three
        bounces, survival probability = the largest spectral throughput, at most 1, survivors
        reweighted by 1 / that: unbiased; pbrt-v4's rule). Mono rays are not rouletted."""
        ok = (rays.depth < self.limits[0]) & ~rays.state.final
        if rays.lam is None and rays.w is not None:
            deep = ok & (rays.depth >= 3)
            if deep.any():
                # a Fresnel-split child (core/integrators/eye/fresnel_split.py) is rouletted as its unsplit path
                q = np.minimum(rays.w.max(axis=1) / rays.state.split, np.float32(1.0))
                roulette = deep & (q < 1)
                if roulette.any():
                    alive = rng.random(len(rays), np.float32) < q
                    ok &= ~roulette | alive
                    kept = roulette & alive
                    rays.w[kept] /= q[kept, None]
        return ok

    def after_delta(self, rays: Rays, transmitted: np.ndarray) -> Rays:
        """Count a mirror or dielectric bounce (reflection: glossy, refraction: transmission, as
        Cycles counts them) and drop paths over their kind's limit. A specular bounce has no BSDF
        pdf for MIS, and makes a path that left a caustic receiver a caustic path."""
        st = rays.state
        st.glossy = st.glossy + ~transmitted
        st.transmission = st.transmission + transmitted
        st.pdf = np.zeros(len(rays), np.float32)
        st.caustic = np.where(st.caustic == Caustic.RECEIVER, np.int8(Caustic.PATH), st.caustic)
        ok = np.where(transmitted, st.transmission <= self.limits[3], st.glossy <= self.limits[2])
        return rays.take(ok)

    def scatter(self, rays: Rays, hit: Hit, kind: np.ndarray, can_bounce: np.ndarray, rng) -> Rays | None:
        out = self._scatter_body(rays, hit, kind, can_bounce, rng)
        return out if self.bragg is None else self.bragg.continue_paths(self, rays, hit, can_bounce, out)

    def _scatter_body(self, rays: Rays, hit: Hit, kind: np.ndarray, can_bounce: np.ndarray, rng) -> Rays | None:
        """The bounces at non-specular surfaces: rough and layered ones through core/materials/bsdf.py
        (``_scatter_microfacet``, with the lobe on_hit drew), Lambertian ones by a
        cosine-weighted direction (the BRDF's importance sampling, weight = albedo). A path at its diffuse or total bounce limit still takes one
        last, emission-only segment ('final'), so light sources and the world that the next
        event estimation does not sample are still seen once (and MIS stays whole)."""
        st = rays.state
        micro_out = None
        if self._micro is not None and self._micro[0] is hit:
            _, micro, params = self._micro
            self._micro = None
            micro_out = self._scatter_microfacet(rays, hit, micro, params, can_bounce)
            kind = np.where(micro, -1, kind)
        sel = (kind == DIFFUSE) & ~st.final
        if self.black is not None:  # a black surface reflects nothing: the path ends
            sel &= ~self.black[hit.mat]
        if not sel.any():
            return micro_out
        # roulette applies to the bounce; a path that loses it takes no segment at all
        sel &= can_bounce | (rays.depth >= self.limits[0])
        r, h = rays.take(sel), hit.take(sel)
        if len(r) == 0:
            return micro_out
        albedo = self._cached_albedo(hit, sel)
        if albedo is None:
            albedo = self.greys.albedo(r, h.mat)
        if albedo is None:
            albedo = surface_reflectance(self.prepared, h, r.lam)
        # (B,) for white rays: grey base colours, the weight stays one number (core/integrators/eye/grey_paths.py)
        grey = albedo.ndim == 1 and r.lam is None
        if grey and not self.greys.is_grey(r):  # spectral weights: the grey colour as a spectrum
            albedo, grey = albedo[:, None] * self.greys.basis, False
        lit = self._reflects(albedo)
        if not lit.all():  # a zero-weight path (a black surface) ends here
            r, h, albedo = r.take(lit), h.take(lit), albedo[lit]
            if len(r) == 0:
                return micro_out
        wi, cos = bsdf.cosine_hemisphere(h.ns, self._numbers(r, SLOT_BOUNCE))
        if self.bent:  # about ns; a direction below the geometric surface ends the path
            up = np.einsum("ij,ij->i", wi, h.ng) > 0
            if not up.all():
                r, h, wi, cos, albedo = r.take(up), h.take(up), wi[up], cos[up], albedo[up]
        b = len(r)
        o = (h.p + h.eps[:, None] * h.ng).astype(np.float32)
        bump = self._bump(h, wi)
        if np.ndim(bump):
            albedo = albedo * (bump[:, None] if albedo.ndim == 2 else bump)
        if grey:
            out = self.greys.scaled(r, albedo, r.moved(o, wi, None))
        else:
            out = r.moved(o, wi, r.weighted(albedo))
        if self.layers:
            out = grating_layering.scale_base(self.prepared, out, h)
        s = out.state
        s.nd = np.minimum(s.nd + 1, MAX_DIFFUSE_VERTICES).astype(np.int8)
        s.diffuse = s.diffuse + 1
        s.pdf = (cos * np.float32(1 / np.pi)).astype(np.float32)
        s.caustic = np.full(b, Caustic.RECEIVER if self.caustic_map is not None else Caustic.NONE, np.int8)
        s.seen = splat_bounce.mark_bounce(self.splat_bounce, r, h)
        s.final = (s.diffuse > self.limits[1]) | (out.depth > self.limits[0])
        return out if micro_out is None or not len(micro_out) else Rays.concat(out, micro_out)

    def _cached_albedo(self, hit: Hit, sel: np.ndarray):
        """The base colours on_hit computed for the hits ``sel`` of ``hit``, or None when on_hit
        did not shade these hits as diffuse."""
        cached, self._albedo_of = self._albedo_of, None
        if cached is None or cached[0] is not hit:
            return None
        rows, albedo = cached[1], cached[2]
        want = np.flatnonzero(sel)
        if len(want) == len(rows) and np.array_equal(rows, want):  # the usual case: the same hits
            return albedo
        pos = np.searchsorted(rows, want)
        if pos.size and (pos.max() >= len(rows) or not np.array_equal(rows[pos], want)):
            return None  # a hit on_hit did not shade as diffuse
        return albedo[pos]

    def mirror_bounce(self, rays: Rays, hit: Hit) -> Rays:
        out = super().mirror_bounce(rays, hit)  # a grating's zeroth order, or the base's share (section 3.3)
        return grating_layering.continue_specular(self.prepared, out, hit, None) if self.layers else out

    def choice_numbers(self, rays: Rays, rng) -> np.ndarray:
        """Smooth glass's reflect / refract choice from the vertex's bounce numbers (stratified
        over the pixel's samples, as Cycles draws its glass closure's choice; core/sampling/specular_numbers.py),
        not the tile's pseudo-random stream: glass_sphere's error at 64 spp 0.0054 -> 0.0038."""
        st = rays.state
        return bounce_choice(st.pid, st.sid, rays.depth, self.sampler_seed, self.rng)

    def dielectric_bounce(self, rays: Rays, hit: Hit, rng, u=None):
        if fresnel_split.ENABLED and not self.layers and self.escapes is None:
            # camera rays take both branches (core/integrators/eye/fresnel_split.py, docs/physics.md section 4.12)
            return fresnel_split.split_first_dielectric(self, rays, hit, rng, u, super().dielectric_bounce)
        out, transmitted = super().dielectric_bounce(rays, hit, rng, u)
        if self.layers:
            out = grating_layering.continue_specular(self.prepared, out, hit, transmitted)
        return out, transmitted

    # ----------------------------------------------------------------- microfacet surfaces
    def _surface_params(self, rays: Rays, hit: Hit, rng) -> "bsdf.SurfaceParams":
        """core/materials/bsdf.py's parameters of these hits: base colour and roughness per hit (textures),
        the side (entering or leaving glass), one Principled layer drawn per hit where the
        material mixes layers (a pure metal, glass or base takes its one layer: no number)."""
        prepared = self.prepared
        base = surface_reflectance(prepared, hit, rays.lam)
        if rays.lam is not None:
            base = base[:, None]
        u_layer = rng.random(len(rays)) if self.mixed_layers[hit.mat].any() else None
        params = bsdf.params_from_materials(prepared.materials, hit.mat, hit.front, rays.lam, base=base,
                                            roughness=surface_roughness(prepared, hit), u_layer=u_layer)
        return bsdf.with_outgoing(params, -rays.d, hit.ns)  # the next events and the bounce share wo

    def _shade_microfacet(self, rays: Rays, hit: Hit, params, rng):
        """Next-event estimation at rough and layered surfaces: every light, the emissive meshes
        and the world map, each weighted against BSDF sampling by the power heuristic; and the
        caustic map on a diffuse base (its diffuse lobe, approximately: base colour / pi)."""
        first = rays.state.nd == 0
        if first.any():
            self._denoising_features(rays.take(first), hit.take(first))
        for sel, film in ((first, self._film), (~first, None)):
            if sel.any():
                r, h = rays.take(sel), hit.take(sel)
                p = params.take(np.flatnonzero(sel)) if not sel.all() else params
                self._nee_microfacet(r, h, p, self._numbers(r, SLOT_LIGHT),
                                     self._film if film is not None else self._part("indirect"))
        if self.caustic_map is not None:
            base = self.prepared.materials.kind[hit.mat] == DIFFUSE
            if base.any():
                self._caustic_light(rays.take(base), hit.take(base), rng)

    def _nee_microfacet(self, rays: Rays, hit: Hit, params, rng, film, analytic: bool = True):
        """One sample of each light (``analytic``), of the emissive meshes (core/lights/mesh_lights.py:
        power-proportional points) and of the world map (its luminance distribution), each by
        shadow ray and weighted against BSDF sampling by the power heuristic; the BSDF is
        core/materials/bsdf.py's (``params``), with Cycles' bump-terminator term on Lambertian lobes."""
        wo = -rays.d
        samples = self.light_samples(hit, rng, analytic)
        lambert = params.lobe == bsdf.LAMBERT
        for wi, dist, g, spectrum, p_light, pad in samples:
            f_cos, p_bsdf = bsdf.evaluate(params, wo, wi, hit.ns, hit.ng)
            scale = np.asarray(g, np.float32)
            if self.normal_maps and lambert.any():
                scale = scale * np.where(lambert, self._bump(hit, wi), np.float32(1.0))
            if p_light is not None:
                scale = scale * _power_heuristic(p_light, p_bsdf, light_first=True)
            live = np.flatnonzero((scale > 0) & (f_cos.max(axis=1) > 0))
            if live.size == 0:
                continue
            side = np.where(np.einsum("ij,ij->i", wi[live], hit.ng[live]) > 0, 1.0, -1.0).astype(np.float32)
            live = self.visible(hit, wi, dist, pad, live, side)
            if live.size == 0:
                continue
            r = rays.take(live)
            spec = light_spectrum_of(spectrum, live, r)
            val = f_cos[live] * scale[live, None]
            contrib = r.weighted(val * spec) if r.lam is None else r.w * val[:, 0] * spec
            self._accumulate(r, contrib, film)

    def visible(self, hit: Hit, wi, dist, pad, live, side=None) -> np.ndarray:
        """The entries of ``live`` whose shadow ray from the hit along ``wi`` reaches its light
        sample (``dist`` less twice the offset and ``pad``), offset along ng (times ``side``,
        -1 for samples below the surface); counts the rays."""
        eps = hit.eps[live]
        off = eps if side is None else side * eps
        o = (hit.p[live] + off[:, None] * hit.ng[live]).astype(np.float32)
        d = np.asarray(dist, np.float32)[live]
        tmax = np.where(np.isinf(d), np.inf, d - 2 * eps - np.asarray(pad if np.ndim(pad) == 0 else pad[live]))
        occ = self.prepared.accel.occluded(o, np.ascontiguousarray(wi[live], np.float32), tmax.astype(np.float32))
        self.rays_cast += len(occ)
        return live[~occ]

    def light_samples(self, hit: Hit, rng, analytic: bool = True) -> list:
        """One next-event sample per emitter at the hits: every light (``analytic``), the emissive
        meshes (core/lights/mesh_lights.py: power-proportional points) and the world map (its luminance
        distribution). Each is (wi (B, 3), distance (B,), scalar weight (B,), spectrum (n,) or
        (B, n), light pdf (B,) or None for delta lights, shadow-ray end pad)."""
        prepared = self.prepared
        lights = prepared.lights
        b = len(hit.p)
        samples = []
        for li in range(len(lights) if analytic else 0):  # the lights (a handful)
            wi, dist, g, pl = sample_light_pdf(lights, li, hit.p, rng)
            samples.append((np.asarray(wi, np.float32), dist, g, lights.spectrum[li], pl, 0.0))
        if self.mesh_lights is not None:
            wi, dist, g, prim, pdf = self.mesh_lights.sample(hit.p, rng)
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

    def _scatter_microfacet(self, rays: Rays, hit: Hit, micro: np.ndarray, params, can_bounce) -> Rays | None:
        """The bounce at rough and layered surfaces: a direction from core/materials/bsdf.py's sampler,
        counted as Cycles counts it (diffuse, glossy or transmission); a delta event (a layer
        smoother than MIN_ROUGHNESS) continues like a mirror or glass bounce."""
        idx = np.flatnonzero(micro)
        go = can_bounce[idx] | (rays.depth[idx] >= self.limits[0])
        idx, params = idx[go], params.take(np.flatnonzero(go)) if not go.all() else params
        if idx.size == 0:
            return None
        r, h = rays.take(idx), hit.take(idx)
        # the third number (reflect or transmit, coat or base) only where a lobe chooses: one
        # Sobol pair fewer for metals and glossy surfaces
        chooses = np.isin(params.lobe, (bsdf.DIELECTRIC, bsdf.PLASTIC)).any()
        u = self._numbers(r, SLOT_BOUNCE).random((len(r), 3 if chooses else 2), np.float32)
        if not chooses:
            u = np.concatenate([u, np.zeros((len(r), 1), np.float32)], axis=1)
        wi, weight, pdf, flags = bsdf.sample(params, -r.d, h.ns, h.ng, u)
        ok = flags != 0
        if not ok.all():
            r, h, wi, weight, pdf, flags = r.take(ok), h.take(ok), wi[ok], weight[ok], pdf[ok], flags[ok]
        if len(r) == 0:
            return None
        side = np.where(np.einsum("ij,ij->i", wi, h.ng) > 0, 1.0, -1.0).astype(np.float32)
        o = (h.p + (h.eps * side)[:, None] * h.ng).astype(np.float32)
        out = r.moved(o, wi, r.weighted(weight) if r.lam is None else r.w * weight[:, 0])
        if self.layers:
            out = grating_layering.scale_base(self.prepared, out, h)
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
        receiver = diffuse & (self.prepared.materials.kind[h.mat] == DIFFUSE) & (self.caustic_map is not None)
        # a delta event after a receiver makes a caustic path; a diffuse one at a receiver: RECEIVER (1), else NONE
        s.caustic = np.where(singular, np.where(s.caustic == Caustic.RECEIVER, np.int8(Caustic.PATH), s.caustic),
                             receiver.astype(np.int8)).astype(np.int8)
        over = ((s.diffuse > self.limits[1]) | (s.glossy > self.limits[2])
                | (s.transmission > self.limits[3]) | (out.depth > self.limits[0]))
        # over a limit: a delta bounce ends; a scattering one takes its emission-only segment
        keep = ~(over & singular)
        s.final = over & ~singular
        return out.take(keep)

    # ----------------------------------------------------------------- films
    def _denoising_features(self, rays: Rays, hit: Hit):
        """Albedo and normal of the first diffuse surface a sample sees (mono rays count with the
        throughput divided by the wavelength count: their weight is the whole spectrum's)."""
        if rays.w is None:
            grey = np.ones(len(rays), np.float32)
        elif rays.lam is None:
            grey = rays.w.mean(axis=1)
        else:
            grey = rays.w / np.float32(self.n)
        albedo = self._albedo_rgb[hit.mat] * grey[:, None]
        normal = hit.ns
        for arr, val in ((self._albedo, albedo), (self._normal, normal)):
            for c in range(3):
                arr[:, c] += np.bincount(rays.pix, weights=val[:, c], minlength=self._n_pixels).astype(np.float32)

    def _accumulate(self, rays: Rays, contrib, film=None):
        """Add per-ray contributions to their pixels: (B, n) for white rays, (B,) for mono."""
        n = self.n
        if len(rays) == 0:
            return
        film = self._film if film is None else film
        if rays.lam is not None:
            np.add.at(film, rays.pix * n + rays.lam, contrib)
            return
        pix = rays.pix
        if len(pix) > 1 and np.any(pix[1:] < pix[:-1]):
            order = np.argsort(pix, kind="stable")
            pix, contrib = pix[order], contrib[order]
        # rays of a pixel are contiguous: sum each run once, then add the (few) runs to the film
        starts = np.flatnonzero(np.concatenate([[True], pix[1:] != pix[:-1]]))
        sums = np.add.reduceat(contrib, starts, axis=0)
        film.reshape(self._n_pixels, n)[pix[starts]] += sums

    def _accumulate_factored(self, pix, mat, factors, film) -> bool:
        """Direct light of unit-weight white rays without a per-ray spectrum.

        Each such ray adds factor_l * albedo[mat] * light_l(lambda) / pi, a sum over a few
        (material, light) spectra. Sum the scalar factors per pixel and combination first, then
        expand to spectra once per pixel: O(B L + P U n) instead of O(B n). Returns False (and
        does nothing) when the tile holds too many combinations for this to pay off.
        """
        prepared = self.prepared
        b, nl = factors.shape
        ray, light = np.nonzero(factors)
        if ray.size == 0:
            return True
        combo = mat[ray].astype(np.int64) * nl + light
        present = np.bincount(combo, minlength=len(prepared.materials.kind) * nl) > 0  # O(B), no sort
        uniq = np.flatnonzero(present)
        u = (np.cumsum(present) - 1)[combo]
        if len(uniq) * self._n_pixels > b * nl:
            return False
        g = np.bincount(pix[ray] * len(uniq) + u, weights=factors[ray, light],
                        minlength=self._n_pixels * len(uniq)).reshape(self._n_pixels, len(uniq))
        spectra = prepared.materials.reflectance[uniq // nl] * prepared.lights.spectrum[uniq % nl] * np.float32(1 / np.pi)
        film += (g @ spectra).ravel()
        return True

    def _add_background(self, rays: Rays, film):
        env = self.prepared.environment
        if env is not None:  # the world map seen along the escaping rays (docs/physics.md section 7.9)
            if len(rays) == 0:
                return
            spectra = self.prepared.conv.illuminant_from_rgb(env.radiance_rgb(rays.d)).astype(np.float32)
            # a BSDF sample, weighted against the map's next-event estimation (power heuristic)
            spectra *= _power_heuristic(rays.state.pdf, env.pdf(rays.d).astype(np.float32))[:, None]
            contrib = rays.weighted(spectra) if rays.lam is None else rays.w * spectra[np.arange(len(rays)), rays.lam]
            self._accumulate(rays, contrib, film)
            return
        bg = self.prepared.world_spectrum
        if not bg.any() or len(rays) == 0:
            return
        if self.greys.add_constant(film, rays, bg, self._n_pixels):  # grey weights: sums per pixel
            return
        if rays.lam is None and rays.w is None:  # unit weights: count rays per pixel
            counts = np.bincount(rays.pix, minlength=self._n_pixels).astype(np.float32)
            film[:] += (counts[:, None] * bg[None, :]).ravel()
            return
        contrib = rays.weighted(np.broadcast_to(bg, (len(rays), self.n)) if rays.lam is None else bg[rays.lam])
        self._accumulate(rays, contrib, film)

    def _emitted_unit(self, rays: Rays, hit: Hit, emits: np.ndarray) -> bool:
        """``_emitted`` for unit-weight white rays (camera rays, through clear glass and mirrors)
        at untextured emitters with no MIS partner: the emission spectra added per pixel and
        material (core/integrators/eye/factored_film.py), no (B, n) spectrum per ray. False: not applicable,
        nothing added (the general path does it)."""
        if rays.lam is not None or rays.w is not None or self.prepared.textures.uses("emission"):
            return False
        st = rays.state
        sel = emits & self._not_covered(rays)
        if self.mesh_lights is not None and (st.pdf[sel] > 0).any():
            return False  # weighted against the mesh lights' next events: the general path
        idx = np.flatnonzero(sel)
        nd = np.minimum(st.nd[idx], 2)
        groups = [idx] if len(nd) == 0 or (nd == nd[0]).all() else [idx[nd == k] for k in np.unique(nd)]
        table = self.prepared.materials.emission
        for j in groups:
            if len(j) and not add_scaled_spectra(self._light_film(min(int(st.nd[j[0]]), 2)), self._n_pixels,
                                                 rays.pix[j], hit.mat[j], 1.0, table):
                self._emitted(rays.take(j), hit.take(j))
        return True

    def _emitted(self, rays: Rays, hit: Hit):
        """Emission of the surfaces hit (Cycles' units: the material's emission is radiance, seen
        from both sides), weighted against the mesh lights' next-event estimation by the power
        heuristic where a BSDF sample found it; a caustic path the light pass counted is left out."""
        keep = self._not_covered(rays)
        if not keep.all():
            rays, hit = rays.take(keep), hit.take(keep)
        if len(rays) == 0:
            return
        e = surface_emission(self.prepared, hit, rays.lam)
        pdf = rays.state.pdf
        if self.mesh_lights is not None and (pdf > 0).any():
            wgt = _power_heuristic(pdf, self.mesh_lights.pdf(hit.prim, rays.o, hit.p).astype(np.float32))
            e = e * (wgt[:, None] if rays.lam is None else wgt)
        self._add_by_vertices(rays, rays.weighted(e) if rays.lam is None else rays.w * e)

    # ----------------------------------------------------------------- interactions
    def _bump(self, hit: Hit, wi: np.ndarray) -> np.ndarray | float:
        """bump_shadowing for the hits whose material has a normal map (1 elsewhere): light
        (next events) and sampled directions (the bounce's weight) alike, as Cycles applies it
        to diffuse closures; measured against Cycles in tests/blender/test_cycles_parity.py."""
        if not self.normal_maps:
            return np.float32(1.0)
        prepared = self.prepared
        bent = prepared.textures.normal[hit.mat] >= 0
        if not bent.any():
            return np.float32(1.0)
        ni = hit.ng if prepared.corner_normals is None else shading_normals(
            prepared.corner_normals, hit.prim, hit.bu, hit.bv, hit.ng)  # the normal before the map bent it
        return np.where(bent, bump_shadowing(ni, hit.ns, wi), np.float32(1.0))

    def _next_events(self, rays: Rays, hit: Hit, film, albedo=None):
        """Next-event estimation at Lambertian vertices: every light (with the factored fast path
        of ``_direct_light``), then the emissive meshes and the world map (``_nee_lambert``).
        ``albedo``: the hits' base colours (surface_reflectance), computed here if None."""
        rng = self._numbers(rays, SLOT_LIGHT)
        self._direct_light(rays, hit, rng, film, albedo)
        if self.mesh_lights is not None or self.prepared.environment is not None:
            if albedo is None:
                albedo = surface_reflectance(self.prepared, hit, rays.lam)
            self._nee_lambert(rays, hit, albedo, rng, film)

    def _nee_lambert(self, rays: Rays, hit: Hit, albedo, rng, film):
        """``_nee_microfacet``'s emissive-mesh and world-map samples at Lambertian vertices,
        with the lobe written out: f cos = albedo / pi * cos(wi, ns) and pdf = cos / pi where wo
        and wi are above ns and wi above ng (bsdf.evaluate's LAMBERT, without its frames and
        parameter tables), times Cycles' bump-terminator term on normal-mapped hits."""
        wo_up = np.einsum("ij,ij->i", rays.d, hit.ns) < 0  # (on_hit passes lit surfaces only: albedo > 0)
        for wi, dist, g, spectrum, p_light, pad in self.light_samples(hit, rng, analytic=False):
            cos_s = np.einsum("ij,ij->i", wi, hit.ns)
            ok = wo_up & (cos_s > 0) & (np.einsum("ij,ij->i", wi, hit.ng) > 0)
            p_bsdf = np.where(ok, cos_s * np.float32(1 / np.pi), np.float32(0.0)).astype(np.float32)
            scale = np.asarray(g, np.float32) * p_bsdf  # g cos / pi
            if self.normal_maps:
                scale = scale * self._bump(hit, wi)
            scale = scale * _power_heuristic(p_light, p_bsdf, light_first=True)
            live = np.flatnonzero(scale > 0)
            if live.size == 0:
                continue
            live = self.visible(hit, wi, dist, pad, live)
            if live.size == 0:
                continue
            r = rays.take(live)
            spec = light_spectrum_of(spectrum, live, r)
            if r.lam is None:
                contrib = r.weighted(albedo[live] * scale[live, None] * spec)
            else:
                contrib = r.w * albedo[live] * scale[live] * spec
            self._accumulate(r, contrib, film)

    def _direct_light(self, rays: Rays, hit: Hit, rng, film, albedo=None):
        prepared = self.prepared
        lights = prepared.lights
        nl, b = len(lights), len(rays)
        if nl == 0 or b == 0:
            return
        # One sample per light per ray; all shadow rays in a single any-hit call.
        flat = not self.bent
        factors = np.zeros((b, nl), np.float32)
        origins, dirs, tmax, idx = [], [], [], []
        for li in range(nl):  # loop over lights (a handful), not rays
            wi, dist, g, p_light = sample_light_pdf(lights, li, hit.p, rng)
            # shaded with ns; light from below the geometric surface does not reach it (no leaks)
            cos_s = np.einsum("ij,ij->i", wi, hit.ns)
            above = True if flat else np.einsum("ij,ij->i", wi, hit.ng) > 0
            f = np.where((cos_s > 0) & above, g * cos_s * self._bump(hit, wi), np.float32(0.0))
            if p_light is not None:  # a light BSDF sampling can also find: the power heuristic
                f = f * _power_heuristic(p_light, np.maximum(cos_s, 0) * np.float32(1 / np.pi), light_first=True)
            live = np.flatnonzero(f > 0)
            if live.size == 0:
                continue
            eps = hit.eps[live]
            origins.append(hit.p[live] + eps[:, None] * hit.ng[live])
            dirs.append(wi[live])
            tmax.append(np.where(np.isinf(dist[live]), np.inf, dist[live] - 2 * eps))
            idx.append(live * nl + li)
            factors.reshape(-1)[live * nl + li] = f[live]
        if not idx:
            return
        occ = prepared.accel.occluded(np.concatenate(origins).astype(np.float32),
                                 np.concatenate(dirs).astype(np.float32),
                                 np.concatenate(tmax).astype(np.float32))
        self.rays_cast += len(occ)
        factors.reshape(-1)[np.concatenate(idx)[occ]] = 0.0
        if (rays.lam is None and rays.w is None and not prepared.textures.uses("color")
                and self._accumulate_factored(rays.pix, hit.mat, factors, film)):
            return
        brdf = (surface_reflectance(prepared, hit, rays.lam) if albedo is None else albedo) * np.float32(1 / np.pi)
        if rays.lam is None:
            irradiance = factors @ lights.spectrum          # (B, L) @ (L, n)
        else:
            irradiance = np.sum(factors * lights.spectrum[:, rays.lam].T, axis=1)
        self._accumulate(rays, rays.weighted(brdf * irradiance), film)

    def _caustic_light(self, rays: Rays, hit: Hit, rng):
        """Caustic radiance at diffuse hits: the illumination map's irradiance * albedo / pi
        (looked up with a one-element jitter: a box filter over neighbouring elements)."""
        prepared = self.prepared
        lit = self.caustic_lit[hit.prim]
        if not lit.all():
            rays, hit = rays.take(lit), hit.take(lit)
        if not len(rays):
            return
        irr = self.caustic_map.irradiance(hit.prim, hit.bu, hit.bv, hit.front, rng)
        brdf = surface_reflectance(prepared, hit) * np.float32(1 / np.pi)
        radiance = irr * brdf
        contrib = rays.weighted(radiance) if rays.lam is None else rays.w * radiance[np.arange(len(rays)), rays.lam]
        self._accumulate(rays, contrib, self._caustics)

    def _grating_light(self, rays: Rays, hit: Hit, rng):
        """Light of every light diffracted by the grating layer towards the viewer (exact w_i by
        shadow ray, so no noise from the light side), into the Diffraction part of the film."""
        prepared = self.prepared
        g, lights = prepared.gratings, prepared.lights
        edges = prepared.grid.bin_edges
        for m in np.unique(hit.mat):  # loop over grating materials present (a few)
            sel = hit.mat == m
            r, h = rays.take(sel), hit.take(sel)
            b = len(r)
            t, s = grating_frame(tangents_at(prepared.corner_grating_tangent, prepared.tri_grating_tangent, h.prim,
                                             h.bu, h.bv, h.ng), h.ng, np.full(b, g.cos_rot[m]), np.full(b, g.sin_rot[m]))
            over = prepared.tri_period[h.prim] if len(prepared.tri_period) else np.zeros(b, np.float32)
            period = np.where(over > 0, over, g.period[m])
            w_o = -r.d
            if self.world_gratings[m]:  # the world, orders sampled from the viewer (docs/physics.md section 3.11)
                seen = world_through_grating(prepared, r, h, int(m), t, s, period, rng)
                if seen is not None:
                    sub, contrib, casts = seen
                    self.rays_cast += casts
                    self._accumulate(sub, contrib, self._diffraction)
            for li in range(len(lights)):  # loop over lights, not rays
                wi, dist, gfac = sample_light(lights, li, h.p, rng)
                cos_l = np.einsum("ij,ij->i", wi, h.ng)
                valid = (cos_l < 0) if g.transmission[m] else (cos_l > 0)
                valid &= gfac > 0
                idx = np.flatnonzero(valid)
                if idx.size == 0:
                    continue
                side = np.float32(-1.0 if g.transmission[m] else 1.0)
                eps = h.eps[idx]
                o = h.p[idx] + (side * eps)[:, None] * h.ng[idx]
                tmax = np.where(np.isinf(dist[idx]), np.inf, dist[idx] - 2 * eps).astype(np.float32)
                occ = prepared.accel.occluded(o.astype(np.float32), np.ascontiguousarray(wi[idx], np.float32), tmax)
                self.rays_cast += len(occ)
                idx = idx[~occ]
                if idx.size == 0:
                    continue
                rad = diffracted_radiance(g, m, w_o[idx], wi[idx], t[idx], s[idx], h.ng[idx], period[idx], edges, rng,
                                          footprint=_footprint(r, h, idx, t, s, wi, dist))
                e = (gfac[idx] * np.abs(cos_l[idx])).astype(np.float32)
                spec = rad * e[:, None] * lights.spectrum[li][None, :]
                sub = r.take(idx)
                contrib = sub.weighted(spec) if sub.lam is None else sub.w * spec[np.arange(len(idx)), sub.lam]
                self._accumulate(sub, contrib, self._diffraction)
            if self.record_map is not None:
                # light that reached the grating through mirrors and glass: every directional lobe
                # of the light pass's records (grating_records.py, docs/physics.md section 3.5),
                # on the viewer's side (h.ng faces it) for reflection, the far side for transmission
                hit_of, irr, src = self.record_map.lobes(h.prim, h.bu, h.bv, rng, at=h.p)
                cos_l = np.einsum("ij,ij->i", src, h.ng[hit_of])
                keep = (cos_l < 0) if g.transmission[m] else (cos_l > 0)
                hit_of, irr, src = hit_of[keep], irr[keep], src[keep]
                chunk = self.record_map.max_pairs
                for c0 in range(0, len(hit_of), chunk):  # (hit, lobe) pairs in bounded chunks
                    j, sl = hit_of[c0:c0 + chunk], slice(c0, c0 + chunk)
                    rad = diffracted_radiance(g, m, w_o[j], src[sl], t[j], s[j], h.ng[j], period[j], edges, rng,
                                              footprint=_footprint(r, h, j, t, s, src[sl], None, aligned=True))
                    spec = rad * irr[sl]
                    sub = r.take(j)
                    contrib = sub.weighted(spec) if sub.lam is None else sub.w * spec[np.arange(len(j)), sub.lam]
                    self._accumulate(sub, contrib, self._diffraction)


def _probe_wavelength(prepared) -> int | None:
    """A wavelength index j at which every base colour the scene can produce is positive unless
    it is zero at every wavelength, or None. Textures' colours are rgb @ basis with rgb in
    [0, 1] (core/materials/surface.py), so j must have every basis row positive there; every material's
    own reflectance must be positive at j exactly when it is anywhere."""
    refl = np.asarray(prepared.materials.reflectance)
    if refl.ndim != 2 or refl.shape[1] == 0:
        return None
    tx = prepared.textures
    ok = np.ones(refl.shape[1], bool)
    if tx.uses("color"):
        ok &= (np.asarray(tx.reflectance_basis) > 0).all(axis=0)
    ok &= ((refl > 0) == (refl > 0).any(axis=1, keepdims=True)).all(axis=0)
    cols = np.flatnonzero(ok)
    return int(cols[len(cols) // 2]) if len(cols) else None


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


def _footprint(rays: Rays, hit: Hit, idx, t, s, wi, dist, aligned: bool = False):
    """(du, dv) of rays[idx]'s pixel footprints at their grating hits (core/sampling/footprint.py), or
    None where the rays carry no differentials. ``aligned``: ``wi`` is already one row per
    entry of ``idx`` (the records' lobes, several per hit)."""
    rd = rays.differentials
    if rd is None:
        return None
    return footprint.grating_footprint(rd[idx], rays.o[idx], rays.d[idx], hit.p[idx], hit.ng[idx], t[idx], s[idx],
                                       wi if aligned else wi[idx], None if dist is None else dist[idx])


def _power_heuristic(p_this: np.ndarray, p_other: np.ndarray, light_first: bool = False) -> np.ndarray:
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


def bump_shadowing(ni: np.ndarray, ns: np.ndarray, wi: np.ndarray) -> np.ndarray:
    """The bump-terminator shadowing of a diffuse BSDF whose normal a normal map bent from the
    interpolated normal ``ni`` to ``ns``, for light from ``wi`` (Conty Estevez, Lecocq & Stein
    2019, "A Microfacet-Based Shadowing Function to Solve the Bump Terminator Problem", as
    Cycles' ``bump_shadowing_term`` has it): a GGX Smith G1 towards wi with alpha^2 =
    tan^2(angle(ni, ns)) / 8 (at most 1); 0 for light below the interpolated surface."""
    cos_i = np.einsum("ij,ij->i", ni, wi)
    cos_d = np.minimum(np.abs(np.einsum("ij,ij->i", ni, ns)), np.float32(1.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        tan2_d = (1 - cos_d * cos_d) / (cos_d * cos_d)
        alpha2 = np.clip(np.float32(0.125) * tan2_d, 0, 1)
        cos2_i = np.maximum(cos_i * cos_i, np.float32(1e-12))
        tan2_i = (1 - cos2_i) / cos2_i
        g = 2 / (1 + np.sqrt(1 + alpha2 * tan2_i))
    return np.where((cos_i < 0) | (cos_d <= 0), np.float32(0.0), g).astype(np.float32)
