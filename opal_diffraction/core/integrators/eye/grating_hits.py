"""The gratings stage of the eye pass: light diffracted towards the viewer at a grating hit.

At a hit on a grating layer (docs/physics.md sections 3.1-3.5, 3.11): every light's exact
incident direction by shadow ray (so no noise from the light side), and one point of the
emissive meshes (core/lights/mesh_lights.py's power-proportional sample, as the next events
draw it; section 3.13), diffracted by
core/gratings/radiance.py's kernel into the viewer's direction, over the pixel's footprint where
the rays carry differentials (core/sampling/footprint.py, section 3.7); every directional lobe
of the light pass's grating records (light that reached the grating through mirrors and glass);
and, at LINES gratings, the path continued along one order sampled from the viewer's side
(core/gratings/lobe.py; the eye pass traces it, eye_pass._GratingTrace): the world, lit
surfaces, glass and emissive meshes seen through the orders (sections 3.11, 3.13). The
emissive meshes' next event and the continued path that meets a mesh are weighted by Veach's
power heuristic (the mesh sampler's solid-angle pdf against the lobe's, gratings.lobe.lobe_pdf;
the weighted next event takes point samples of the pattern, as the lobe does). All of it goes
to the Diffraction part of the film.
"""

from __future__ import annotations

import numpy as np

from ...gratings.directions import tangents_at
from ...gratings.radiance import diffracted_radiance, grating_frame
from ...gratings.lobe import WAVELENGTHS, continue_paths, lobe_pdf
from ...materials.spectra import DIELECTRIC
from ...lights.sources import sample_light
from ...sampling import footprint
from ...transport.walker import Hit, Rays

__all__ = ["grating_light", "MIS"]

#: the emissive meshes' next event and the order lobe weighted by the power heuristic (section
#: 3.13); False: the partition that came before (each mesh by the next event alone, the lobe's
#: first segment adding none), kept so the tests can measure what the weighting gains
MIS = True


def grating_light(c, out, rays: Rays, hit: Hit, rng, follow=None, events=None, lobe_rng=None, allowed=None):
    """Light of every light diffracted by the grating layer towards the viewer (exact w_i by
    shadow ray, so no noise from the light side), into the Diffraction part of ``out``; and,
    with ``follow(rays, gratings.lobe.ContinuedPaths)``, the paths that go on along a sampled
    order (LINES gratings: whatever they find arrives diffracted, section 3.13). ``events`` (B,)
    bool: the rays whose lights, meshes and records are diffracted here (None: all; a path
    continued from another grating leaves them to the light pass's records, section 3.13).
    ``lobe_rng``: the continuation's own random stream (None: ``rng``), so the paths it adds do
    not shift the numbers of everything else. ``allowed(rays, transmitted)`` (B,) bool: the rays
    whose continuation ``follow`` traces (the bounce limits; None: all). Where the continuation
    runs, the emissive meshes' next event and the continued path that meets an emitter are
    weighted against each other by the power heuristic (``gratings.lobe.lobe_pdf``, section 3.13)."""
    prepared = c.prepared
    g, lights = prepared.gratings, prepared.lights
    edges = prepared.grid.bin_edges
    for m in np.unique(hit.mat):  # loop over grating materials present (a few)
        sel = hit.mat == m
        r, h = rays.take(sel), hit.take(sel)
        b = len(r)
        ev = None if events is None else np.asarray(events, bool)[sel]
        t, s = grating_frame(tangents_at(prepared.corner_grating_tangent, prepared.tri_grating_tangent, h.prim,
                                         h.bu, h.bv, h.ng), h.ng, np.full(b, g.cos_rot[m]), np.full(b, g.sin_rot[m]))
        over = prepared.tri_period[h.prim] if len(prepared.tri_period) else np.zeros(b, np.float32)
        period = np.where(over > 0, over, g.period[m])
        w_o = -r.d
        lobe = follow is not None and bool(c.lobe_gratings[m])
        # MIS of the emissive meshes between the next event and the lobe (section 3.13): where the
        # lobe continues in air and the next event runs (else each keeps its partition)
        mis = None
        if MIS and lobe and prepared.mesh_lights is not None and prepared.materials.kind[m] != DIELECTRIC:
            mis = np.ones(b, bool) if allowed is None else np.asarray(allowed(r, bool(g.transmission[m])), bool)
            if ev is not None:
                mis &= ev
            if not mis.any():
                mis = None
        white_scale = WAVELENGTHS / prepared.grid.n if r.lam is None else 1.0  # the lobe draws a bin with this probability
        if lobe:  # the grating as a lobe: the path goes on along an order
            cont = continue_paths(prepared, r, h, int(m), t, s, period, rng if lobe_rng is None else lobe_rng)  # (docs/physics.md sections 3.11, 3.13)
            if cont is not None:
                if mis is not None:
                    cont.pdf = _continued_pdf(g, int(m), cont, mis, w_o, t, s, h.ng, period, edges, white_scale)
                follow(r, cont)
        samples = [(li, *sample_light(lights, li, h.p, rng), 0.0, None) for li in range(len(lights))]  # (a handful)
        if prepared.mesh_lights is not None:  # the emissive meshes: one power-proportional point per hit
            wi, dist, gfac, prim, pdf = prepared.mesh_lights.sample(h.p, rng)
            samples.append((prim, wi, dist, gfac, 2 * prepared.tri_offset[prim], pdf))
        for source, wi, dist, gfac, pad, p_light in samples:
            cos_l = np.einsum("ij,ij->i", wi, h.ng)
            valid = (cos_l < 0) if g.transmission[m] else (cos_l > 0)
            valid &= gfac > 0
            if ev is not None:
                valid &= ev
            idx = np.flatnonzero(valid)
            if idx.size == 0:
                continue
            side = np.float32(-1.0 if g.transmission[m] else 1.0)
            eps = h.eps[idx]
            o = h.p[idx] + (side * eps)[:, None] * h.ng[idx]
            end = dist[idx] - 2 * eps - (pad if np.ndim(pad) == 0 else pad[idx])
            tmax = np.where(np.isinf(dist[idx]), np.inf, end).astype(np.float32)
            occ = prepared.accel.occluded(o.astype(np.float32), np.ascontiguousarray(wi[idx], np.float32), tmax)
            out.shadow_rays += len(occ)
            idx = idx[~occ]
            if idx.size == 0:
                continue
            # an emissive mesh weighted against the lobe: point samples of the pattern (the lobe's own
            # integrand, sample by sample; the footprint's box is not what the lobe's samples
            # average, so it would bias the weighted sum), else over the pixel's footprint
            mw = mis[idx] if p_light is not None and mis is not None else np.zeros(len(idx), bool)
            k = np.flatnonzero(mw)
            rad = np.empty((len(idx), len(edges) - 1), np.float32)
            if k.size:
                j = idx[k]
                rad[k] = diffracted_radiance(g, m, w_o[j], wi[j], t[j], s[j], h.ng[j], period[j], edges, rng)
            rest = np.flatnonzero(~mw)
            if rest.size:
                j = idx[rest]
                rad[rest] = diffracted_radiance(g, m, w_o[j], wi[j], t[j], s[j], h.ng[j], period[j], edges, rng,
                                                footprint=_footprint(r, h, j, t, s, wi, dist))
            e = (gfac[idx] * np.abs(cos_l[idx])).astype(np.float32)
            if np.ndim(source) == 0:  # a light: its spectrum
                emitted = lights.spectrum[source][None, :]
            else:  # an emissive triangle's (both sides emit, as the eye pass's next events take them)
                emitted = prepared.materials.emission[prepared.tri_material[source[idx]]]
            spec = rad * e[:, None] * emitted
            if k.size:  # the power heuristic against the lobe's pdf of the same direction and bin
                j = idx[k]
                q = lobe_pdf(g, m, w_o[j], wi[j], t[j], s[j], h.ng[j], period[j], edges) * white_scale
                pl = np.asarray(p_light[j], np.float64)[:, None] ** 2
                spec[k] = spec[k] * (pl / np.maximum(pl + q * q, 1e-300)).astype(np.float32)
            sub = r.take(idx)
            contrib = sub.weighted(spec) if sub.lam is None else sub.w * spec[np.arange(len(idx)), sub.lam]
            out.accumulate(sub, contrib, out.diffraction)
        if c.record_map is not None:
            # light that reached the grating through mirrors and glass: every directional lobe
            # of the light pass's records (grating_records.py, docs/physics.md section 3.5),
            # on the viewer's side (h.ng faces it) for reflection, the far side for transmission
            hit_of, irr, src = c.record_map.lobes(h.prim, h.bu, h.bv, rng, at=h.p)
            cos_l = np.einsum("ij,ij->i", src, h.ng[hit_of])
            keep = (cos_l < 0) if g.transmission[m] else (cos_l > 0)
            if ev is not None:
                keep &= ev[hit_of]
            hit_of, irr, src = hit_of[keep], irr[keep], src[keep]
            chunk = c.record_map.max_pairs
            for c0 in range(0, len(hit_of), chunk):  # (hit, lobe) pairs in bounded chunks
                j, sl = hit_of[c0:c0 + chunk], slice(c0, c0 + chunk)
                rad = diffracted_radiance(g, m, w_o[j], src[sl], t[j], s[j], h.ng[j], period[j], edges, rng,
                                          footprint=_footprint(r, h, j, t, s, src[sl], None, aligned=True))
                spec = rad * irr[sl]
                sub = r.take(j)
                contrib = sub.weighted(spec) if sub.lam is None else sub.w * spec[np.arange(len(j)), sub.lam]
                out.accumulate(sub, contrib, out.diffraction)


def _continued_pdf(g, m: int, cont, mis, w_o, t, s, ng, period, edges, white_scale) -> np.ndarray:
    """(B',) float32: ``lobe_pdf`` of each continued path's direction in its own bin (times the
    probability a white ray draws that bin) where the next event runs (``mis``); 0 elsewhere
    (nothing on that segment is weighted). Point values, as the weighted next event's."""
    out = np.zeros(len(cont.rows), np.float32)
    on = mis[cont.rows]
    for k in np.unique(cont.lam[on]):  # one bin per call (a few dozen at most)
        j = np.flatnonzero(on & (cont.lam == k))
        rows = cont.rows[j]
        q = lobe_pdf(g, m, w_o[rows], cont.direction[j], t[rows], s[rows], ng[rows], period[rows], edges[k:k + 2])
        out[j] = q[:, 0] * white_scale
    return out


def _footprint(rays: Rays, hit: Hit, idx, t, s, wi, dist, aligned: bool = False):
    """(du, dv) of rays[idx]'s pixel footprints at their grating hits (core/sampling/footprint.py), or
    None where the rays carry no differentials. ``aligned``: ``wi`` is already one row per
    entry of ``idx`` (the records' lobes, several per hit), and so is ``dist``."""
    rd = rays.differentials
    if rd is None:
        return None
    return footprint.grating_footprint(rd[idx], rays.o[idx], rays.d[idx], hit.p[idx], hit.ng[idx], t[idx], s[idx],
                                       wi if aligned else wi[idx],
                                       None if dist is None else (dist if aligned else dist[idx]))
