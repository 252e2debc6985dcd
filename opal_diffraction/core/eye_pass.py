"""The eye pass: camera rays, direct light at diffuse hits, caustics and diffraction, specular
recursion and dispersion (the transport itself is transport.SpecularWalker).

The source paper's eye pass (Kobayashi & Kawai; docs/physics.md section 4.2). At a diffuse
(two-sided Lambertian) hit: direct light by shadow rays plus the caustic irradiance of the light
pass's illumination map;
at a grating, the diffraction of every light that reaches it (gratings.py); at an emitter, its
radiance; at mirrors and glass the path goes on. Every tile writes three films: what diffuse
surfaces reflect (Direct and Caustics), emitted light seen (world, emitters), and diffraction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import orthonormal_basis
from .gratings import diffracted_radiance, grating_frame
from .lights import sample_light
from .materials import DIFFUSE
from .surface import surface_reflectance
from .transport import Hit, Rays, SpecularWalker

__all__ = ["EyePass", "TileResult"]


@dataclass
class TileResult:
    film: np.ndarray  # (P, n) sum of sample contributions per pixel (everything)
    # the parts of film (P, n) that are not Direct, or None where nothing was written:
    background: np.ndarray | None  # emitted light seen (world, emitters)
    diffraction: np.ndarray | None  # diffracted by gratings
    caustics: np.ndarray | None  # caustic light from the light pass
    rays: int         # rays cast (camera, secondary and shadow)


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
        self.record_map = None if light is None else light.grating_records

    def trace(self, origins, directions, pix, n_pixels: int, rng: np.random.Generator,
              u_lambda: np.ndarray | None = None) -> TileResult:
        """Trace camera rays (one per sample) and return the per-pixel sum of their radiance.

        ``u_lambda`` (B,) in [0, 1): stratified numbers for the SAMPLE wavelength choice
        (uniform random if omitted).
        """
        if u_lambda is None:
            u_lambda = rng.random(len(pix))
        return _TileTrace(self, n_pixels, rng).run(origins, directions, pix, u_lambda)

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
    """The state of one tile's trace: its film accumulators and ray count."""

    def __init__(self, eye: EyePass, n_pixels: int, rng: np.random.Generator):
        super().__init__(eye.prepared, rng)
        self.caustic_map, self.record_map = eye.caustic_map, eye.record_map
        self.world_lights = bool(eye.prepared.world_spectrum.any())
        self._n_pixels = n_pixels
        self._film = self._new_film()  # light reflected by diffuse surfaces from direct lighting
        # the other parts of the film, allocated when first written (most scenes use a few):
        self._parts: dict[str, np.ndarray] = {}  # 'background' (world and emitters seen),
        #                                          'diffraction', 'caustics'
        self.escapes = None  # a list to record rays leaving the scene (trace_escapes)

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

    def run(self, origins, directions, pix, u_lambda, wavelength_index=None) -> TileResult:
        n, b = self.n, len(pix)
        rays = Rays(origins, directions, pix.astype(np.int64), None, None,
                     np.zeros(b, np.int32), np.asarray(u_lambda, np.float64))
        mono = self.empty_mono()
        if wavelength_index is not None:  # start monochromatic (tools and tests)
            lam = np.broadcast_to(np.asarray(wavelength_index, np.int64), (b,)).copy()
            mono = Rays(rays.o, rays.d, rays.pix, np.ones(b, np.float32), lam, rays.depth, rays.u_lam)
            rays = rays.take(np.zeros(b, bool))
        self.walk(rays, mono)
        shape = (self._n_pixels, n)
        total = self._film
        for part in self._parts.values():
            total = total + part
        get = lambda k: self._parts[k].reshape(shape) if k in self._parts else None  # noqa: E731
        return TileResult(total.reshape(shape), get("background"), get("diffraction"), get("caustics"), self._rays)

    # ----------------------------------------------------------------- hooks
    def on_miss(self, rays: Rays) -> None:
        self._add_background(rays)
        if self.escapes is not None:
            self.escapes.append({"origin": rays.o, "direction": rays.d, "weight": rays.dense_w(self.n),
                                 "lam": rays.lam, "depth": rays.depth, "ray": rays.pix})

    def on_hit(self, rays: Rays, hit: Hit, kind: np.ndarray, rng) -> None:
        prepared = self.prepared
        emits = prepared.materials.emissive[hit.mat]
        if emits.any():
            r = rays.take(emits)
            em = prepared.materials.emission[hit.mat[emits]]
            self._accumulate(r, r.weighted(em) if r.lam is None else r.w * em[np.arange(len(r)), r.lam],
                             self._background)
        if prepared.gratings.any:
            on_grating = prepared.gratings.enabled[hit.mat]
            if on_grating.any():
                self._grating_light(rays.take(on_grating), hit.take(on_grating), rng)
        diffuse = kind == DIFFUSE
        if diffuse.any():
            r, h = rays.take(diffuse), hit.take(diffuse)
            self._direct_light(r, h, rng)
            if self.world_lights:
                self._world_light(r, h, rng)
            if self.caustic_map is not None:
                self._caustic_light(r, h, rng)

    # ----------------------------------------------------------------- films
    def _accumulate(self, rays: Rays, contrib, film=None):
        """Add per-ray contributions to their pixels: (B, n) for white rays, (B,) for mono."""
        n = self.n
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

    def _accumulate_factored(self, pix, mat, factors) -> bool:
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
        self._film += (g @ spectra).ravel()
        return True

    def _add_background(self, rays: Rays):
        bg = self.prepared.world_spectrum
        if not bg.any():
            return
        if rays.lam is None and rays.w is None:  # unit weights: count rays per pixel
            counts = np.bincount(rays.pix, minlength=self._n_pixels).astype(np.float32)
            self._background[:] += (counts[:, None] * bg[None, :]).ravel()
            return
        contrib = rays.weighted(np.broadcast_to(bg, (len(rays), self.n)) if rays.lam is None else bg[rays.lam])
        self._accumulate(rays, contrib, self._background)

    # ----------------------------------------------------------------- interactions
    def _direct_light(self, rays: Rays, hit: Hit, rng):
        prepared = self.prepared
        lights = prepared.lights
        nl, b = len(lights), len(rays)
        if nl == 0 or b == 0:
            return
        # One sample per light per ray; all shadow rays in a single any-hit call.
        factors = np.zeros((b, nl), np.float32)
        origins, dirs, tmax, idx = [], [], [], []
        for li in range(nl):  # loop over lights (a handful), not rays
            wi, dist, g = sample_light(lights, li, hit.p, rng)
            cos_s = np.einsum("ij,ij->i", wi, hit.ng)
            f = np.where(cos_s > 0, g * cos_s, np.float32(0.0))
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
        self._rays += len(occ)
        factors.reshape(-1)[np.concatenate(idx)[occ]] = 0.0
        if (rays.lam is None and rays.w is None and not prepared.textures.uses("color")
                and self._accumulate_factored(rays.pix, hit.mat, factors)):
            return
        brdf = surface_reflectance(prepared, hit, rays.lam) * np.float32(1 / np.pi)
        if rays.lam is None:
            irradiance = factors @ lights.spectrum          # (B, L) @ (L, n)
        else:
            irradiance = np.sum(factors * lights.spectrum[:, rays.lam].T, axis=1)
        self._accumulate(rays, rays.weighted(brdf * irradiance))

    def _world_light(self, rays: Rays, hit: Hit, rng):
        """Light from a uniform world reaching diffuse surfaces directly: one cosine-weighted
        shadow ray per hit, so each unoccluded ray adds albedo * L_world (the Lambertian BRDF
        rho / pi times L cos / pdf with pdf = cos / pi) - exact for a constant world, whose
        variance is only the visibility's. (Light from the world through mirrors and glass onto
        diffuse surfaces is a caustic path the light pass does not trace yet.)"""
        prepared = self.prepared
        b = len(rays)
        u1, u2 = rng.random(b, np.float32), rng.random(b, np.float32)
        r, phi = np.sqrt(u1), np.float32(2 * np.pi) * u2
        tu, tv = orthonormal_basis(hit.ng)
        local_z = np.sqrt(np.maximum(np.float32(1) - u1, 0))
        wi = ((r * np.cos(phi))[:, None] * tu + (r * np.sin(phi))[:, None] * tv
              + local_z[:, None] * hit.ng).astype(np.float32)
        o = (hit.p + hit.eps[:, None] * hit.ng).astype(np.float32)
        occ = prepared.accel.occluded(o, wi, np.full(b, np.inf, np.float32))
        self._rays += b
        seen = ~occ
        if not seen.any():
            return
        rr = rays.take(seen)
        bg = prepared.world_spectrum
        albedo = surface_reflectance(prepared, hit.take(seen), rr.lam)
        if rr.lam is None:
            contrib = rr.weighted(albedo * bg[None, :])
        else:
            contrib = rr.w * albedo * bg[rr.lam]
        self._accumulate(rr, contrib)

    def _caustic_light(self, rays: Rays, hit: Hit, rng):
        """Caustic radiance at diffuse hits: the illumination map's irradiance * albedo / pi
        (looked up with a one-element jitter: a box filter over neighbouring elements)."""
        prepared = self.prepared
        irr = self.caustic_map.irradiance(hit.prim, hit.bu, hit.bv, hit.front, rng)
        brdf = prepared.materials.reflectance[hit.mat] * np.float32(1 / np.pi)
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
            t, s = grating_frame(prepared.tri_grating_tangent[h.prim], h.ng, np.full(b, g.cos_rot[m]), np.full(b, g.sin_rot[m]))
            over = prepared.tri_period[h.prim] if len(prepared.tri_period) else np.zeros(b, np.float32)
            period = np.where(over > 0, over, g.period[m])
            w_o = -r.d
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
                self._rays += len(occ)
                idx = idx[~occ]
                if idx.size == 0:
                    continue
                rad = diffracted_radiance(g, m, w_o[idx], wi[idx], t[idx], s[idx], h.ng[idx], period[idx], edges, rng)
                e = (gfac[idx] * np.abs(cos_l[idx])).astype(np.float32)
                spec = rad * e[:, None] * lights.spectrum[li][None, :]
                sub = r.take(idx)
                contrib = sub.weighted(spec) if sub.lam is None else sub.w * spec[np.arange(len(idx)), sub.lam]
                self._accumulate(sub, contrib, self._diffraction)
            if self.record_map is not None:
                # light that reached the grating through mirrors and glass (the light pass's records)
                irr, src, ok = self.record_map.incoming(h.prim, h.bu, h.bv, h.front)
                cos_l = np.einsum("ij,ij->i", src, h.ng)
                ok &= (cos_l < 0) if g.transmission[m] else (cos_l > 0)
                idx = np.flatnonzero(ok)
                if idx.size:
                    rad = diffracted_radiance(g, m, w_o[idx], src[idx], t[idx], s[idx], h.ng[idx], period[idx], edges, rng)
                    spec = rad * irr[idx]
                    sub = r.take(idx)
                    contrib = sub.weighted(spec) if sub.lam is None else sub.w * spec[np.arange(len(idx)), sub.lam]
                    self._accumulate(sub, contrib, self._diffraction)

