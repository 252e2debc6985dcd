"""The eye pass: camera rays, direct light at diffuse hits, specular recursion, dispersion.

The source paper's eye pass (physics.md section 4.2) as a wavefront tracer: all rays of a tile
advance one bounce at a time, in NumPy arrays, with no Python loop per ray or per pixel.

Rays live in two populations:
- *white* rays carry the whole spectrum, a weight array (B, n);
- *mono* rays carry one wavelength sample, a scalar weight (B,) and its index (B,).
A white ray stays white until it meets a dispersive dielectric; there it becomes mono rays:
``SPLIT`` makes one child per wavelength sample with the parent's weight at that wavelength (the
children's weights sum to the parent's: energy is conserved exactly), ``SAMPLE`` makes one child
with wavelength k drawn with probability p_k proportional to the parent's weight and weight
w_k / p_k (an unbiased one-sample estimator of the SPLIT sum, pbrt-v4's TerminateSecondary idea).
Children inherit the parent's hit, so the split costs no extra ray cast.

At a dielectric the reflect / refract choice is sampled with probability equal to the Fresnel
reflectance, so the weight is unchanged (for mono rays the index is the one at their wavelength,
so total internal reflection differs per wavelength). Diffuse surfaces are two-sided Lambertian;
they receive direct light by shadow rays (caustics come from the light pass, not from here).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .gratings import diffracted_radiance, grating_frame
from .lights import sample_light
from .materials import DIELECTRIC, DIFFUSE, MIRROR
from .optics import fresnel_dielectric, reflect, refract

__all__ = ["EyePass", "TileResult"]


@dataclass
class _Rays:
    o: np.ndarray      # (B, 3) float32 origins
    d: np.ndarray      # (B, 3) float32 unit directions
    pix: np.ndarray    # (B,) int64 pixel index within the tile
    w: np.ndarray | None  # (B, n) white or (B,) mono, float32; None: white and all ones (camera rays)
    lam: np.ndarray | None  # (B,) int wavelength index for mono rays, None for white
    depth: np.ndarray  # (B,) int specular bounces so far
    u_lam: np.ndarray  # (B,) float: the sample's stratified number for choosing a wavelength

    def __len__(self):
        return len(self.pix)

    def take(self, mask) -> "_Rays":
        if mask.dtype == bool and len(mask) and mask.all():
            return self
        return _Rays(self.o[mask], self.d[mask], self.pix[mask], None if self.w is None else self.w[mask],
                     None if self.lam is None else self.lam[mask], self.depth[mask], self.u_lam[mask])

    def weighted(self, x):
        """The ray weight times x (x itself for unit-weight camera rays)."""
        return x if self.w is None else self.w * x

    def dense_w(self, n: int) -> np.ndarray:
        return np.ones((len(self), n), np.float32) if self.w is None else self.w

    @staticmethod
    def concat(a: "_Rays", b: "_Rays") -> "_Rays":
        if (a.w is None) != (b.w is None):  # one side has implicit unit weights: make them explicit
            n = (a.w if a.w is not None else b.w).shape[1]
            a, b = replace(a, w=a.dense_w(n)), replace(b, w=b.dense_w(n))
        return _Rays(*(None if x is None else np.concatenate([x, y]) for x, y in
                       zip((a.o, a.d, a.pix, a.w, a.lam, a.depth, a.u_lam),
                           (b.o, b.d, b.pix, b.w, b.lam, b.depth, b.u_lam))))


@dataclass
class _Hit:
    p: np.ndarray     # (B, 3) float32 hit points
    ng: np.ndarray    # (B, 3) float32 geometric normal facing the incoming ray
    cos_i: np.ndarray  # (B,) cosine between -d and ng (>= 0)
    front: np.ndarray  # (B,) bool: the ray arrived on the side the triangle's normal points to
    mat: np.ndarray   # (B,) material index
    eps: np.ndarray   # (B,) float32 self-intersection offset at the hit
    prim: np.ndarray  # (B,) triangle index

    def take(self, mask) -> "_Hit":
        if mask.dtype == bool and len(mask) and mask.all():
            return self
        return _Hit(self.p[mask], self.ng[mask], self.cos_i[mask], self.front[mask], self.mat[mask], self.eps[mask],
                    self.prim[mask])

    @staticmethod
    def concat(a: "_Hit", b: "_Hit") -> "_Hit":
        return _Hit(*(np.concatenate([x, y]) for x, y in
                      zip((a.p, a.ng, a.cos_i, a.front, a.mat, a.eps, a.prim),
                          (b.p, b.ng, b.cos_i, b.front, b.mat, b.eps, b.prim))))


@dataclass
class TileResult:
    film: np.ndarray  # (P, n) float64 sum of sample contributions per pixel (everything)
    background: np.ndarray  # (P, n) the part of film that is emitted light seen (world, emitters), not Direct
    diffraction: np.ndarray  # (P, n) the part of film diffracted by gratings
    rays: int         # rays cast (camera, secondary and shadow)


class EyePass:
    """Traces tiles of camera samples through a prepared scene (see render.RenderContext).

    Stateless between calls, so several threads may trace tiles at once.
    """

    def __init__(self, ctx):
        self.ctx = ctx

    def trace(self, origins, directions, pix, n_pixels: int, rng: np.random.Generator,
              u_lambda: np.ndarray | None = None) -> TileResult:
        """Trace camera rays (one per sample) and return the per-pixel sum of their radiance.

        ``u_lambda`` (B,) in [0, 1): stratified numbers for the SAMPLE wavelength choice
        (uniform random if omitted).
        """
        if u_lambda is None:
            u_lambda = rng.random(len(pix))
        return _TileTrace(self.ctx, n_pixels, rng).run(origins, directions, pix, u_lambda)

    def trace_escapes(self, origins, directions, rng: np.random.Generator, wavelength_index=None) -> dict:
        """Follow rays through the scene's specular surfaces and report the ones that leave it.

        With ``wavelength_index`` (B,) the rays start monochromatic at those grid indices,
        otherwise white. Returns a dict of arrays over escaping rays: 'origin' (last surface
        point), 'direction', 'weight' ((E, n) white or (E,) mono), 'lam' (or None), 'depth'
        (specular bounces) and 'ray' (index of the starting ray). For tests and tools: the
        directions leaving a prism, a lens, a mirror.
        """
        b = len(origins)
        tr = _TileTrace(self.ctx, b, rng)
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


class _TileTrace:
    """The state of one tile's trace: its film accumulator and ray count."""

    def __init__(self, ctx, n_pixels: int, rng: np.random.Generator):
        self.ctx = ctx
        self.n = ctx.grid.n
        self.rng = rng
        self._film = np.zeros(n_pixels * self.n, np.float32)
        self._background = np.zeros(n_pixels * self.n, np.float32)
        self._diffraction = np.zeros(n_pixels * self.n, np.float32)  # emitted light: world and emissive surfaces
        self._n_pixels = n_pixels
        self._rays = 0
        self.escapes = None  # a list to record rays leaving the scene (trace_escapes)

    def run(self, origins, directions, pix, u_lambda, wavelength_index=None) -> TileResult:
        n, b, rng = self.n, len(pix), self.rng
        rays = _Rays(origins, directions, pix.astype(np.int64), None, None,
                     np.zeros(b, np.int32), np.asarray(u_lambda, np.float64))
        mono = _Rays(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32), np.zeros(0, np.int64),
                     np.zeros(0, np.float32), np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros(0))
        if wavelength_index is not None:  # start monochromatic (tools and tests)
            lam = np.broadcast_to(np.asarray(wavelength_index, np.int64), (b,)).copy()
            mono = _Rays(rays.o, rays.d, rays.pix, np.ones(b, np.float32), lam, rays.depth, rays.u_lam)
            rays = rays.take(np.zeros(b, bool))
        while len(rays) or len(mono):
            rays, children, child_hits = self._step(rays, None, rng)
            mono, _, _ = self._step(mono, (children, child_hits), rng)
        shape = (self._n_pixels, n)
        return TileResult((self._film + self._background + self._diffraction).reshape(shape),
                          self._background.reshape(shape), self._diffraction.reshape(shape), self._rays)

    # ----------------------------------------------------------------- one bounce
    def _step(self, rays: _Rays, pending, rng):
        """Advance a population by one interaction; returns (continuing rays, mono children, their hits)."""
        ctx = self.ctx
        hit = None
        if len(rays):
            h = ctx.accel.intersect(rays.o, rays.d)
            self._rays += len(rays)
            missed = h.prim < 0
            if missed.any():
                self._add_background(rays.take(missed))
                if self.escapes is not None:
                    r = rays.take(missed)
                    self.escapes.append({"origin": r.o, "direction": r.d, "weight": r.dense_w(self.n), "lam": r.lam,
                                         "depth": r.depth, "ray": r.pix})
            keep = ~missed
            rays = rays.take(keep)
            hit = self._hit_info(rays, h.t[keep], h.prim[keep])
        if pending is not None and pending[0] is not None and len(pending[0]):
            if hit is None:
                rays, hit = pending
            else:
                rays, hit = _Rays.concat(rays, pending[0]), _Hit.concat(hit, pending[1])
        if hit is None or len(rays) == 0:
            return rays.take(np.zeros(len(rays), bool)), None, None

        emits = ctx.materials.emissive[hit.mat]
        if emits.any():
            r = rays.take(emits)
            em = ctx.materials.emission[hit.mat[emits]]
            self._accumulate(r, r.weighted(em) if r.lam is None else r.w * em[np.arange(len(r)), r.lam],
                             self._background)
        if ctx.gratings.any:
            on_grating = ctx.gratings.enabled[hit.mat]
            if on_grating.any():
                self._grating_light(rays.take(on_grating), hit.take(on_grating), rng)
        kind = ctx.materials.kind[hit.mat]
        diffuse = kind == DIFFUSE
        if diffuse.any():
            self._direct_light(rays.take(diffuse), hit.take(diffuse), rng)

        can_bounce = rays.depth < ctx.settings.max_bounces
        children = child_hits = None
        out = []
        mirror = (kind == MIRROR) & can_bounce
        if mirror.any():
            out.append(self._mirror(rays.take(mirror), hit.take(mirror)))
        diel = (kind == DIELECTRIC) & can_bounce
        if diel.any():
            if rays.lam is None:
                disp = diel & ctx.materials.dispersive[hit.mat]
                if disp.any():
                    children, child_hits = self._split(rays.take(disp), hit.take(disp), rng)
                diel = diel & ~disp
            if diel.any():
                out.append(self._dielectric(rays.take(diel), hit.take(diel), rng))
        if not out:
            return rays.take(np.zeros(len(rays), bool)), children, child_hits
        nxt = out[0]
        for r in out[1:]:
            nxt = _Rays.concat(nxt, r)
        return nxt, children, child_hits

    def _hit_info(self, rays: _Rays, t, prim) -> _Hit:
        ctx = self.ctx
        p = rays.o + t[:, None] * rays.d
        ng = ctx.tri_normal[prim]
        cos = -np.einsum("ij,ij->i", rays.d, ng)
        front = cos > 0
        ng = np.where(front[:, None], ng, -ng)
        return _Hit(p.astype(np.float32, copy=False), ng, np.abs(cos), front, ctx.tri_material[prim],
                    ctx.tri_offset[prim], prim)

    # ----------------------------------------------------------------- spectra helpers
    @staticmethod
    def _per_ray(table, rows, lam):
        """table[rows] (B, n) for white rays, table[rows, lam] (B,) for mono rays."""
        return table[rows] if lam is None else table[rows, lam]

    def _accumulate(self, rays: _Rays, contrib, film=None):
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
        ctx = self.ctx
        b, nl = factors.shape
        ray, light = np.nonzero(factors)
        if ray.size == 0:
            return True
        combo = mat[ray].astype(np.int64) * nl + light
        present = np.bincount(combo, minlength=len(ctx.materials.kind) * nl) > 0  # O(B), no sort
        uniq = np.flatnonzero(present)
        u = (np.cumsum(present) - 1)[combo]
        if len(uniq) * self._n_pixels > b * nl:
            return False
        g = np.bincount(pix[ray] * len(uniq) + u, weights=factors[ray, light],
                        minlength=self._n_pixels * len(uniq)).reshape(self._n_pixels, len(uniq))
        spectra = ctx.materials.reflectance[uniq // nl] * ctx.lights.spectrum[uniq % nl] * np.float32(1 / np.pi)
        self._film += (g @ spectra).ravel()
        return True

    def _add_background(self, rays: _Rays):
        bg = self.ctx.world_spectrum
        if not bg.any():
            return
        if rays.lam is None and rays.w is None:  # unit weights: count rays per pixel
            counts = np.bincount(rays.pix, minlength=self._n_pixels).astype(np.float32)
            self._background += (counts[:, None] * bg[None, :]).ravel()
            return
        contrib = rays.weighted(np.broadcast_to(bg, (len(rays), self.n)) if rays.lam is None else bg[rays.lam])
        self._accumulate(rays, contrib, self._background)

    # ----------------------------------------------------------------- interactions
    def _direct_light(self, rays: _Rays, hit: _Hit, rng):
        ctx = self.ctx
        lights = ctx.lights
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
        occ = ctx.accel.occluded(np.concatenate(origins).astype(np.float32),
                                 np.concatenate(dirs).astype(np.float32),
                                 np.concatenate(tmax).astype(np.float32))
        self._rays += len(occ)
        factors.reshape(-1)[np.concatenate(idx)[occ]] = 0.0
        if rays.lam is None and rays.w is None and self._accumulate_factored(rays.pix, hit.mat, factors):
            return
        brdf = self._per_ray(ctx.materials.reflectance, hit.mat, rays.lam) * np.float32(1 / np.pi)
        if rays.lam is None:
            irradiance = factors @ lights.spectrum          # (B, L) @ (L, n)
        else:
            irradiance = np.sum(factors * lights.spectrum[:, rays.lam].T, axis=1)
        self._accumulate(rays, rays.weighted(brdf * irradiance))

    def _grating_light(self, rays: _Rays, hit: _Hit, rng):
        """Light of every light diffracted by the grating layer towards the viewer (exact w_i by
        shadow ray, so no noise from the light side), into the Diffraction part of the film."""
        ctx = self.ctx
        g, lights = ctx.gratings, ctx.lights
        edges = ctx.grid.bin_edges
        for m in np.unique(hit.mat):  # loop over grating materials present (a few)
            sel = hit.mat == m
            r, h = rays.take(sel), hit.take(sel)
            b = len(r)
            t, s = grating_frame(ctx.tri_grating_tangent[h.prim], h.ng, np.full(b, g.cos_rot[m]), np.full(b, g.sin_rot[m]))
            over = ctx.tri_period[h.prim] if len(ctx.tri_period) else np.zeros(b, np.float32)
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
                occ = ctx.accel.occluded(o.astype(np.float32), np.ascontiguousarray(wi[idx], np.float32), tmax)
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

    def _mirror(self, rays: _Rays, hit: _Hit) -> _Rays:
        ctx = self.ctx
        d = reflect(rays.d, hit.ng)
        o = hit.p + hit.eps[:, None] * hit.ng
        w = rays.weighted(self._per_ray(ctx.materials.reflectance, hit.mat, rays.lam))
        return _Rays(o.astype(np.float32), d.astype(np.float32), rays.pix, w, rays.lam, rays.depth + 1, rays.u_lam)

    def _dielectric(self, rays: _Rays, hit: _Hit, rng) -> _Rays:
        ctx = self.ctx
        lam0 = np.zeros(len(rays), np.int64) if rays.lam is None else rays.lam
        n = ctx.materials.ior[hit.mat, lam0]  # constant over the grid for white rays
        eta = np.where(hit.front, 1.0 / n, n).astype(np.float32)
        fr = fresnel_dielectric(hit.cos_i, eta)
        refl = rng.random(len(rays)) < fr
        t_dir, _ = refract(rays.d, hit.ng, eta)
        d = np.where(refl[:, None], reflect(rays.d, hit.ng), t_dir)
        side = np.where(refl, 1.0, -1.0).astype(np.float32)
        o = hit.p + (hit.eps * side)[:, None] * hit.ng
        w = rays.weighted(self._per_ray(ctx.materials.reflectance, hit.mat, rays.lam))
        return _Rays(o.astype(np.float32), d.astype(np.float32), rays.pix, w, rays.lam, rays.depth + 1, rays.u_lam)

    def _split(self, rays: _Rays, hit: _Hit, rng):
        """White rays at a dispersive interface -> mono rays (SPLIT or SAMPLE), keeping the hit."""
        n, b = self.n, len(rays)
        split = self.ctx.settings.dispersion_sampling == "SPLIT"
        if rays.w is None:  # unit weights: every wavelength alike
            if split:
                parent, lam = np.repeat(np.arange(b), n), np.tile(np.arange(n), b)
                w = np.ones(b * n, np.float32)
            else:
                parent = np.arange(b)
                lam = np.minimum((rays.u_lam * n).astype(np.int64), n - 1)
                w = np.full(b, n, np.float32)
        elif split:
            parent, lam = np.nonzero(rays.w > 0)
            w = rays.w[parent, lam]
        else:
            total = rays.w.sum(axis=1, dtype=np.float64)
            live = total > 0
            cdf = np.cumsum(rays.w[live], axis=1, dtype=np.float64)
            u = rays.u_lam[live] * total[live]  # stratified per pixel
            lam = np.minimum((cdf < u[:, None]).sum(axis=1), n - 1)
            parent = np.flatnonzero(live)
            w = total[live].astype(np.float32)  # w_k / p_k with p_k = w_k / total
        children = _Rays(rays.o[parent], rays.d[parent], rays.pix[parent], w.astype(np.float32),
                         lam.astype(np.int64), rays.depth[parent], rays.u_lam[parent])
        return children, hit.take(parent)
