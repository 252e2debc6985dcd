"""The eye pass's BRAGG (FCC opal) vertices: the opal lobe at a hit, its BSDF-sampled
continuation, and the body underneath scaled by what the planes did not reflect.

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

The eye pass (core/integrators/eye/eye_pass.py) selects the hits (:meth:`BraggShading.opal_hits`),
estimates the lobe's next events with its one next-event routine
(core/integrators/eye/next_event.py, the lobe's ``evaluate`` as the BSDF) and scales the body
(:meth:`BraggShading.body_share`) in ``on_hit``, before the body is shaded, and calls
:meth:`BraggShading.continue_paths` from ``scatter`` with what ``body_share`` returned. The domains (``prepared.opal_domains``,
core/opal/ volume domains; absent: one domain whose planes are parallel to each face) give each
hit its (111) axis and sphere diameter; the axis bends across its domain by
``core.opal.volume.DOMAIN_BEND_DEG`` per mean domain spacing (docs/opal.md "Domain curvature").
"""

from __future__ import annotations

import numpy as np

from ..util.enums import Lattice
from ..transport.path_state import MAX_DIFFUSE_VERTICES, Caustic
from ..transport.walker import Rays
from ..opal.bragg import effective_index
from ..opal.volume import DOMAIN_BEND_DEG
from ..materials.bragg_bsdf import BraggLobe, kappa_from_spread
from ..materials.bragg_multilayer import band_table

__all__ = ["BraggShading", "bragg_materials"]

#: The body keeps at least this share of the throughput (1 - albedo is divided out again for the
#: lobe's own continuation, after Russian roulette rescaled the weights).
_MIN_BODY = 1e-3


def bragg_materials(materials) -> np.ndarray:
    """(M,) bool: materials whose grating layer is the BRAGG lattice."""
    return (np.asarray(materials.grating) != 0) & (np.asarray(materials.lattice) == int(Lattice.BRAGG))


class BraggShading:
    """Per-render state of the BRAGG materials: their tables (multilayer.band_table, built once
    per parameter set and process) and per-material parameters; nothing changes while tracing."""

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

    @classmethod
    def for_prepared(cls, prepared) -> "BraggShading | None":
        m = prepared.scene.materials
        if not len(m) or not bragg_materials(m).any():
            return None
        return cls(prepared)

    # ------------------------------------------------------------------ parameters at hits
    def lobe(self, hit) -> BraggLobe:
        """The lobe at these hits (all BRAGG materials): the domain's axis, bent across the domain
        (VolumeDomains.lattice_axis) and oriented to the shading normal's side, and its diameter, or the face's normal and the material's D_s."""
        mat = hit.mat
        axis = np.asarray(hit.ns, np.float64).copy()
        diameter = self.diameter[mat].copy()
        if self.domains is not None:
            d_axis, d_diam, found = self.domains.lattice_axis(np.asarray(hit.p, np.float64), np.asarray(hit.prim),
                                                              DOMAIN_BEND_DEG)
            found = np.asarray(found, bool)
            if found.any():
                a = np.asarray(d_axis, np.float64)[found]
                a /= np.maximum(np.linalg.norm(a, axis=1), 1e-30)[:, None]
                flip = np.einsum("ij,ij->i", a, axis[found]) < 0  # planes are an axis: m and -m alike
                a[flip] *= -1
                axis[found] = a
                diameter[found] = np.asarray(d_diam, np.float64)[found]
        return BraggLobe(axis, diameter, self.n_eff[mat], self.kappa[mat], self.tables, self.table_of[mat])

    # ------------------------------------------------------------------ the eye pass's opal vertices
    def opal_hits(self, rays, hit, live) -> np.ndarray:
        """(B,) bool: the hits among ``live`` on BRAGG planes from outside the stone, where the eye
        pass shades the lobe (white rays at a dispersive body split first; their mono children
        shade)."""
        sel = live & self.mask[hit.mat] & hit.front
        if rays.lam is None:
            sel &= ~self.prepared.materials.dispersive[hit.mat]
        return sel

    def body_share(self, rays, r, h, sel, lobe) -> tuple:
        """Scale ``rays.w`` at the opal hits ``sel`` (B,) bool (``r``, ``h``: those rays and hits,
        ``lobe`` their lobe) by 1 - albedo, the body's share; returns what ``continue_paths``
        needs: (rows, lobe, body share)."""
        idx = np.flatnonzero(sel)
        wo = -np.asarray(r.d, np.float64)
        body = 1.0 - self._clamped_albedo(lobe, wo, h.ns, r.lam)
        n = len(self.edges) - 1
        w = np.ones((len(rays), n), np.float32) if rays.w is None else rays.w.copy()  # never a shared array
        w[idx] *= body
        rays.w = w
        return idx, lobe, body

    def _clamped_albedo(self, lobe, wo, ns, lam):
        a = lobe.albedo(wo, ns, self.edges, lam)
        return np.minimum(a, np.float32(1.0 - _MIN_BODY))

    def continue_paths(self, limits, rng, rays, hit, can_bounce, out, pending):
        """``out`` (the body's bounces, or None) joined with the lobe's sampled continuations of
        the opal hits ``pending`` (``body_share``'s, or None), under the bounce ``limits`` (total,
        diffuse, glossy, transmission); ``rng``: the tile's stream."""
        if pending is None:
            return out
        idx, lobe, body = pending
        go = (can_bounce[idx] | (rays.depth[idx] >= limits[0])) & ~rays.state.final[idx]
        if not go.any():
            return out
        keep = np.flatnonzero(go)
        idx, lobe, body = idx[keep], lobe.take(keep), body[keep]
        r, h = rays.take(idx), hit.take(idx)
        u = rng.random((len(r), 2))
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
        lim = limits
        s.final = ((s.diffuse > lim[1]) | (s.glossy > lim[2]) | (s.transmission > lim[3])
                   | (nxt.depth > lim[0]))
        if out is None or not len(out):
            return nxt
        return Rays.concat(out, nxt)

    def scatter_light(self, rays, hit, can_bounce, rng):
        """The light pass's bounce at BRAGG planes (core/integrators/light/walker.py): light arriving from
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
