"""The eye pass's BRAGG (FCC opal) vertices: next-event estimation of the opal lobe, its
BSDF-sampled continuation, and the body underneath scaled by what the planes did not reflect.

docs/physics.md section 5.8. A material with ``grating = 1, lattice = BRAGG`` is its base (the
body tone: black or white diffuse, clear glass, an orange fire opal) under the lobe of
core/materials/bragg_bsdf.py. At each hit from outside the stone:

- every light (delta lights evaluate the lobe at their direction; sized lights, the emissive
  meshes and the world map are weighted against the lobe's own sampling by the power heuristic,
  Veach 1997 section 9.2), by shadow ray;
- one continuation drawn from the lobe (a glossy bounce), which carries the lobe's pdf for MIS
  where it meets an emitter;
- the ray's throughput for the body is multiplied by 1 - A(wo, lambda), A the lobe's
  directional albedo (``BraggLobe.albedo``): the light the planes sent back does not reach the
  body (the layering rule of Principled's specular layer, docs/physics.md section 14.5).

The eye pass calls :meth:`BraggShading.shade` from ``on_hit`` (before the body is shaded) and
:meth:`BraggShading.continue_paths` from ``scatter``. The domains (``prepared.opal_domains``,
core/opal/ volume domains; absent: one domain whose planes are parallel to each face) give each
hit its (111) axis and sphere diameter.
"""

from __future__ import annotations

import numpy as np

from ..util.enums import Lattice
from ..transport.path_state import MAX_DIFFUSE_VERTICES, Caustic
from ..transport.walker import Rays, light_spectrum_of
from ..opal.bragg import effective_index
from ..materials.bragg_bsdf import BraggLobe, kappa_from_spread
from ..materials.bragg_multilayer import band_table

__all__ = ["BraggShading", "bragg_materials"]

#: The body keeps at least this share of the throughput (1 - albedo is divided out again for the
#: lobe's own continuation, after Russian roulette rescaled the weights).
_MIN_BODY = 1e-3


def _light_weight(p_light, p_lobe) -> np.ndarray:
    """Veach's power heuristic for a light sample against the lobe's sampling (as the eye pass's
    _power_heuristic with light_first; not imported from it: the eye pass imports this module)."""
    a, b = np.asarray(p_light, np.float64), np.asarray(p_lobe, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where(a * a + b * b > 0, a * a / (a * a + b * b), 1.0)
    return np.where(np.isfinite(w), w, 1.0).astype(np.float32)


def bragg_materials(materials) -> np.ndarray:
    """(M,) bool: materials whose grating layer is the BRAGG lattice."""
    return (np.asarray(materials.grating) != 0) & (np.asarray(materials.lattice) == int(Lattice.BRAGG))


class BraggShading:
    """Per-render state of the BRAGG materials: their tables (multilayer.band_table, built once
    per parameter set and process) and per-material parameters; one per tile trace."""

    def __init__(self, prepared):
        m = prepared.scene.materials
        self.prepared = prepared
        self.mask = bragg_materials(m)
        rows = np.flatnonzero(self.mask)
        nm = len(self.mask)
        self.n_eff = np.ones(nm)
        self.kappa = np.ones(nm)
        self.diameter = np.asarray(m.sphere_diameter, np.float64)
        self.table_of = np.zeros(nm, np.int64)
        self.tables = []
        keys = {}
        for i in rows:  # the BRAGG materials (a handful)
            ns, nv, layers = float(m.sphere_ior[i]), float(m.void_ior[i]), int(m.layers[i])
            key = (round(ns, 6), round(nv, 6), layers)
            if key not in keys:
                keys[key] = len(self.tables)
                self.tables.append(band_table(ns, nv, layers))
            self.table_of[i] = keys[key]
            self.n_eff[i] = effective_index(ns, nv)
            self.kappa[i] = kappa_from_spread(float(m.mosaic_spread[i]))
        self.domains = getattr(prepared, "opal_domains", None)
        self.edges = np.asarray(prepared.grid.bin_edges, np.float64)
        self._pending = None

    @classmethod
    def for_prepared(cls, prepared) -> "BraggShading | None":
        m = prepared.scene.materials
        if not len(m) or not bragg_materials(m).any():
            return None
        return cls(prepared)

    # ------------------------------------------------------------------ parameters at hits
    def lobe(self, hit) -> BraggLobe:
        """The lobe at these hits (all BRAGG materials): the domain's axis (oriented to the
        shading normal's side) and diameter, or the face's normal and the material's D_s."""
        mat = hit.mat
        axis = np.asarray(hit.ns, np.float64).copy()
        diameter = self.diameter[mat].copy()
        if self.domains is not None:
            d_axis, d_diam, found = self.domains.lookup(np.asarray(hit.p, np.float64), np.asarray(hit.prim))
            found = np.asarray(found, bool)
            if found.any():
                a = np.asarray(d_axis, np.float64)[found]
                a /= np.maximum(np.linalg.norm(a, axis=1), 1e-30)[:, None]
                flip = np.einsum("ij,ij->i", a, axis[found]) < 0  # planes are an axis: m and -m alike
                a[flip] *= -1
                axis[found] = a
                diameter[found] = np.asarray(d_diam, np.float64)[found]
        return BraggLobe(axis, diameter, self.n_eff[mat], self.kappa[mat], self.tables, self.table_of[mat])

    # ------------------------------------------------------------------ eye pass hooks
    def shade(self, trace, rays, hit, live, rng) -> None:
        """At BRAGG hits among ``live``: next events of the lobe into the film, the lobe kept
        for ``continue_paths``, and ``rays.w`` of those hits scaled by 1 - albedo (the body's
        share). ``trace`` is the eye pass's tile trace."""
        self._pending = None
        sel = live & self.mask[hit.mat] & hit.front
        if rays.lam is None:  # white rays at a dispersive body split first; their mono children shade
            sel &= ~self.prepared.materials.dispersive[hit.mat]
        idx = np.flatnonzero(sel)
        if idx.size == 0:
            return
        r, h = rays.take(sel), hit.take(sel)
        lobe = self.lobe(h)
        # a path from a caustic receiver (through mirrors, glass or other opal) to a light via
        # these planes is the light pass's (it scatters off BRAGG planes, scatter_light)
        nee = r.state.caustic == Caustic.NONE if trace.caustics_cover_lights else np.ones(len(r), bool)
        if nee.all():
            self._next_events(trace, r, h, lobe, rng)
        elif nee.any():
            k = np.flatnonzero(nee)
            self._next_events(trace, r.take(nee), h.take(nee), lobe.take(k), rng)
        wo = -np.asarray(r.d, np.float64)
        body = 1.0 - self._clamped_albedo(lobe, wo, h.ns, r.lam)
        n = len(self.edges) - 1
        w = np.ones((len(rays), n), np.float32) if rays.w is None else rays.w.copy()  # never a shared array
        w[idx] *= body
        rays.w = w
        self._pending = (hit, idx, lobe, body)

    def _clamped_albedo(self, lobe, wo, ns, lam):
        a = lobe.albedo(wo, ns, self.edges, lam)
        return np.minimum(a, np.float32(1.0 - _MIN_BODY))

    def continue_paths(self, trace, rays, hit, can_bounce, out):
        """``out`` (the body's bounces, or None) joined with the lobe's sampled continuations."""
        pending, self._pending = self._pending, None
        if pending is None or pending[0] is not hit:
            return out
        _, idx, lobe, body = pending
        go = (can_bounce[idx] | (rays.depth[idx] >= trace.limits[0])) & ~rays.state.final[idx]
        if not go.any():
            return out
        keep = np.flatnonzero(go)
        idx, lobe, body = idx[keep], lobe.take(keep), body[keep]
        r, h = rays.take(idx), hit.take(idx)
        u = trace.rng.random((len(r), 2))
        wi, weight, pdf, ok = lobe.sample(-np.asarray(r.d, np.float64), np.asarray(h.ns, np.float64), u,
                                          self.edges, r.lam)
        if rays.lam is None:
            ok &= weight.max(axis=1) > 0
        else:
            ok &= weight > 0
        if not ok.any():
            return out
        r, h, wi, weight, pdf, body = r.take(ok), h.take(ok), wi[ok], weight[ok], pdf[ok], body[ok]
        w0 = r.w / body  # the weight before the body's share (with Russian roulette's 1/q)
        o = (h.p + h.eps[:, None] * h.ng).astype(np.float32)
        nxt = r.moved(o, wi, (w0 * weight).astype(np.float32))
        s = nxt.state
        s.nd = np.minimum(s.nd + 1, MAX_DIFFUSE_VERTICES).astype(np.int8)
        s.glossy = s.glossy + 1
        s.pdf = pdf.astype(np.float32)
        # like a specular bounce: after a caustic receiver, a caustic path (the light pass's)
        s.caustic = np.where(s.caustic >= Caustic.RECEIVER, np.int8(Caustic.PATH), np.int8(Caustic.NONE)).astype(np.int8)
        lim = trace.limits
        s.final = ((s.diffuse > lim[1]) | (s.glossy > lim[2]) | (s.transmission > lim[3])
                   | (nxt.depth > lim[0]))
        if out is None or not len(out):
            return nxt
        return Rays.concat(out, nxt)

    def scatter_light(self, rays, hit, can_bounce, rng):
        """The light pass's bounce at BRAGG planes (core/integrators/light/light_pass.py): light arriving from
        outside the stone goes on along a direction drawn from the lobe, its flux times the
        lobe's f cos / pdf (the lobe is reciprocal, so sampling it from the light's side is
        light tracing's own sampling); counted as a specular bounce, so what it lights is a
        caustic. The body's share (1 - albedo) is not taken from the light that enters a clear
        body (docs/physics.md section 12)."""
        sel = self.mask[hit.mat] & hit.front & can_bounce
        if rays.lam is None:
            sel &= ~self.prepared.materials.dispersive[hit.mat]
        if not sel.any():
            return None
        r, h = rays.take(sel), hit.take(sel)
        lobe = self.lobe(h)
        wi, weight, _, ok = lobe.sample(-np.asarray(r.d, np.float64), np.asarray(h.ns, np.float64),
                                        rng.random((len(r), 2)), self.edges, r.lam)
        ok &= (weight.max(axis=1) > 0) if r.lam is None else (weight > 0)
        if not ok.any():
            return None
        r, h, wi, weight = r.take(ok), h.take(ok), wi[ok], weight[ok]
        o = (h.p + h.eps[:, None] * h.ng).astype(np.float32)
        return r.moved(o, wi, r.weighted(weight).astype(np.float32))

    def _next_events(self, trace, rays, hit, lobe, rng) -> None:
        """One sample of every light, of the emissive meshes and of the world map, each by shadow
        ray, the lobe evaluated there (power heuristic against the lobe's sampling where the light
        can also be found by it); into the film part of the path's vertex count + 1."""
        wo = -np.asarray(rays.d, np.float64)
        ns = np.asarray(hit.ns, np.float64)
        samples = trace.light_samples(hit, rng)  # the eye pass's one sample per emitter
        nd = rays.state.nd
        for wi, dist, g, spectrum, p_light, pad in samples:
            f_cos, p_lobe = lobe.evaluate(wo, wi, ns, self.edges, rays.lam)
            scale = np.asarray(g, np.float32)
            if p_light is not None:
                scale = scale * _light_weight(p_light, p_lobe)
            peak = f_cos.max(axis=1) if rays.lam is None else f_cos
            live = np.flatnonzero((scale > 0) & (peak > 0))
            if live.size == 0:
                continue
            live = trace.visible(hit, wi, dist, pad, live)
            if live.size == 0:
                continue
            r = rays.take(live)
            spec = light_spectrum_of(spectrum, live, r)
            if r.lam is None:
                contrib = r.weighted(f_cos[live] * scale[live, None] * spec)
            else:
                contrib = r.w * f_cos[live] * scale[live] * spec
            k_nd = nd[live]
            for k in np.unique(k_nd):  # the path's vertex counts (0, 1, 2+)
                part = k_nd == k
                film = trace._light_film(min(int(k) + 1, 2))
                trace._accumulate(r.take(part), contrib[part], film)
