"""The media stage of the eye pass: homogeneous spectral media along the path's segments.

Method (docs/physics.md section 15; core/volumes/): every traced segment is read against the
medium it crossed (``PreparedMedia.segment_medium``: the interior of the closed mesh whose back
face it ends on, else the world's volume). In a medium:

- its emission along the whole segment is added in closed form (L_e (1 - exp(-sigma_t t)) /
  sigma_t per wavelength), whatever the path does next;
- a medium that scatters draws a free-flight distance with spectral MIS over the path's
  wavelengths (core/volumes/tracking.py): a path scattering before the segment's end leaves it
  there (it never reaches the surface) with weight sigma_s T / p(t); the rest reach the end with
  T / P; a medium that only absorbs multiplies the weight by T (Beer-Lambert). Paths past a
  bounce limit (``final``) only gather emission: no scattering, T;
- point and spot lights of radius 0 are also reached from a point of each scattering segment
  drawn towards them by equiangular sampling (core/volumes/tracking.py), its next event weighted
  against the free-flight point's by the balance heuristic;
- at a scattering vertex: one next event per emitter (core/integrators/eye/next_event.py's
  ``light_samples``) weighted by the Henyey-Greenstein phase function and, where phase sampling
  can also find the light, by the power heuristic against it (Veach 1997 section 9.2), its shadow
  ray's transmittance exp(-sigma_t d) per wavelength in the vertex's medium (an unoccluded shadow
  ray crosses no boundary, so one medium holds it); then the path goes on in a direction drawn
  from the phase function (weight 1, its pdf kept for MIS), counted as a volume bounce (Cycles'
  Volume bounces: depth minus the diffuse, glossy and transmission counts; past the limit the
  segment only gathers emission).

Shadow rays from surfaces (next_event.py's hooks) take the world medium's transmittance
(``surface_shadow``). The walker calls ``segment`` through its ``through_media`` hook.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ...lights.sources import POINT, SPOT, is_delta, sample_light_pdf
from ...sampling import footprint
from ...sampling.sampler import SLOT_BOUNCE, SLOT_LIGHT
from ...transport.path_state import MAX_DIFFUSE_VERTICES, Caustic
from ...transport.walker import Rays, light_spectrum_of
from ...volumes.media import PreparedMedia
from ...volumes.phase import hg, sample_hg
from ...volumes.tracking import (equiangular, equiangular_pdf, free_flight, free_flight_pdf, segment_emission,
                                 transmittance)
from .next_event import light_samples, power_heuristic

__all__ = ["MediumStage"]

_F32 = np.float32


class MediumStage:
    """The eye pass's media (``media``: core/volumes/media.PreparedMedia) under the bounce
    limits ``limits`` (total, diffuse, glossy, transmission) and ``volume_bounces``."""

    def __init__(self, prepared, media: PreparedMedia, limits: tuple, volume_bounces: int):
        self.prepared, self.media = prepared, media
        self.limits, self.volume_bounces = limits, int(volume_bounces)
        self.sigma_t = media.sigma_t
        self.sigma_s = media.sigma_s
        self.scatters = media.scatters
        self.emits = media.emits
        self.any_emits = bool(self.emits.any())
        pl = prepared.lights
        # point and spot lights of radius 0: their next events also take equiangular points (MIS)
        self.equi = [li for li in range(len(pl)) if int(pl.kind[li]) in (POINT, SPOT) and is_delta(pl, li)]

    # ------------------------------------------------------------------ shadow rays from surfaces
    def surface_shadow(self, dist) -> np.ndarray | None:
        """(L, n) float32: the world medium's transmittance along shadow rays of lengths ``dist``
        (L,) from surfaces (None: no world medium)."""
        w = self.media.world
        if w < 0:
            return None
        st = np.broadcast_to(self.sigma_t[w], (len(dist), self.sigma_t.shape[1]))
        return transmittance(st, dist).astype(_F32)

    # ------------------------------------------------------------------ the walker's hook
    def segment(self, trace, rays: Rays, h):
        """The segments of ``rays`` to their hits ``h`` (the ray caster's result; prim < 0: a
        miss) through their media: emission added to ``trace.out``, weights times the
        transmittance factors. Returns (the rays going on to their hits, those hits, the rays
        that scattered in a medium with their next events done, or None)."""
        prepared, media = self.prepared, self.media
        prim = np.asarray(h.prim)
        missed = prim < 0
        if len(prepared.tri_material):
            p0 = np.where(missed, 0, prim)
            mat = prepared.tri_material[p0]
            front = np.einsum("ij,ij->i", rays.d, prepared.tri_normal[p0]) < 0
        else:  # no geometry: every segment leaves the scene
            mat, front = np.zeros(len(prim), np.int64), np.zeros(len(prim), bool)
        med = media.segment_medium(mat, front, missed)
        sel = med >= 0
        if not sel.any():
            return rays, h, None
        idx = np.flatnonzero(sel)
        r = rays.take(idx)
        m = med[idx]
        t_end = np.where(missed, np.inf, np.asarray(h.t, np.float64))[idx]
        st = self.sigma_t[m]
        mono = r.lam is not None
        out = trace.out
        if self.any_emits:  # the medium's emission along the whole segment
            em = self.emits[m]
            if em.any():
                k = np.flatnonzero(em)
                re = r.take(k)
                e = segment_emission(st[k], media.emission[m[k]], t_end[k]).astype(_F32)
                contrib = re.w * e[np.arange(len(k)), re.lam] if mono else re.weighted(e)
                out.add_by_vertices(re, contrib)
        n = st.shape[1]
        factor = transmittance(st, t_end)  # (K, n): what absorption-only media and final paths get
        if mono:
            factor = factor[np.arange(len(idx)), r.lam]
        scat = self.scatters[m] & ~r.state.final
        scattered_rows = np.zeros(0, np.int64)
        scattered = None
        if scat.any():
            k = np.flatnonzero(scat)
            rng = trace.rng
            if self.equi:  # the point lights' next events at equiangular points of the segments
                self._equiangular_events(trace, r.take(k), m[k], t_end[k])
            ok, t, f = free_flight(st[k], self.sigma_s[m[k]], t_end[k], rng.random(len(k)), rng.random(len(k)),
                                   r.lam[k] if mono else None)
            factor[k] = f
            if ok.any():
                ks = k[ok]
                scattered_rows = idx[ks]
                rs = r.take(ks)
                w = rs.w * f[ok].astype(_F32) if mono else rs.weighted(f[ok].astype(_F32))
                x = (rs.o.astype(np.float64) + t[ok][:, None] * rs.d).astype(_F32)
                scattered = self._scatter(trace, rs, m[ks], x, w, t[ok], t_end[ks])
        # the rays going on to their hits, weights times their factors
        if mono:
            w_all = np.array(rays.w, _F32, copy=True)
            w_all[idx] *= factor.astype(_F32)
        else:
            w_all = np.array(rays.dense_w(n), _F32, copy=True)
            w_all[idx] *= factor.astype(_F32)
        going = rays.moved(rays.o, rays.d, w_all, depth=rays.depth)
        if len(scattered_rows):
            keep = np.ones(len(rays), bool)
            keep[scattered_rows] = False
            kk = np.flatnonzero(keep)
            going = going.take(kk)
            h = SimpleNamespace(t=np.asarray(h.t).take(kk), prim=prim.take(kk), u=np.asarray(h.u).take(kk),
                                v=np.asarray(h.v).take(kk))
        return going, h, scattered

    # ------------------------------------------------------------------ a scattering vertex
    def _equiangular_events(self, trace, rays: Rays, m: np.ndarray, t_end: np.ndarray) -> None:
        """The point and spot lights' next events from points of the segments drawn towards each
        light (``tracking.equiangular``), weighted against the free-flight points' by the balance
        heuristic: W sigma_s T(t) p(theta) g T_shadow L / p_e(t) x p_e / (p_e + p_d)."""
        prepared, out = self.prepared, trace.out
        pl = prepared.lights
        b = len(rays)
        mono = rays.lam is not None
        n = self.sigma_t.shape[1]
        o, d = rays.o.astype(np.float64), rays.d.astype(np.float64)
        st, ss, g = self.sigma_t[m], self.sigma_s[m], self.media.g[m]
        w = rays.w if mono else rays.dense_w(n)
        nd = rays.state.nd
        for li in self.equi:
            t, p_e = equiangular(o, d, np.broadcast_to(pl.position[li], (b, 3)), t_end, trace.rng.random(b))
            x = (o + t[:, None] * d).astype(_F32)
            wi, dist, gl, _ = sample_light_pdf(pl, li, x, trace.rng)
            p_d = free_flight_pdf(st, t, rays.lam if mono else None)
            ph = hg(np.einsum("ij,ij->i", d, np.asarray(wi, np.float64)), g)
            with np.errstate(divide="ignore", invalid="ignore"):
                scale = np.asarray(gl, np.float64) * ph / (p_e + p_d)  # (1 / p_e) x p_e / (p_e + p_d)
            live = np.flatnonzero((scale > 0) & np.isfinite(scale))
            if live.size == 0:
                continue
            dd = np.asarray(dist, np.float64)[live]
            occ = prepared.accel.occluded(x[live], np.ascontiguousarray(np.asarray(wi, _F32)[live]), dd.astype(_F32))
            out.shadow_rays += len(occ)
            live = live[~occ]
            if live.size == 0:
                continue
            # sigma_s T along the camera side and T along the shadow ray, per wavelength
            tr = ss[live] * transmittance(st[live], t[live] + np.asarray(dist, np.float64)[live])
            spec = pl.spectrum[li]
            if mono:
                lam = rays.lam[live]
                val = w[live] * (scale[live] * tr[np.arange(live.size), lam] * spec[lam]).astype(_F32)
            else:
                val = w[live] * (scale[live, None] * tr * spec).astype(_F32)
            rl = rays.take(live)
            k_nd = nd[live]
            for k in np.unique(k_nd):
                part = k_nd == k
                out.accumulate(rl.take(part), val[part], out.light_film(min(int(k) + 1, 2)))

    def _scatter(self, trace, rays: Rays, m: np.ndarray, x: np.ndarray, w: np.ndarray, t, t_end) -> Rays | None:
        """Next events and the phase-sampled continuation of ``rays`` scattering at ``x`` (B, 3)
        (distance ``t`` along segments of length ``t_end``) in media ``m`` (B,), with throughput
        ``w`` there ((B, n) white, (B,) mono)."""
        prepared, out = self.prepared, trace.out
        b = len(rays)
        mono = rays.lam is not None
        g = self.media.g[m]
        d = rays.d.astype(np.float64)
        st = self.sigma_t[m]
        nd = rays.state.nd
        at = SimpleNamespace(p=x)
        p_d = free_flight_pdf(st, t, rays.lam if mono else None) if self.equi else None
        for li, (wi, dist, gl, spectrum, p_light, pad) in enumerate(light_samples(prepared, at,
                                                                               trace.numbers(rays, SLOT_LIGHT))):
            wi64 = np.asarray(wi, np.float64)
            ph = hg(np.einsum("ij,ij->i", d, wi64), g)
            scale = np.asarray(gl, np.float64) * ph
            if li < len(prepared.lights) and li in self.equi:  # against the equiangular points (balance)
                p_e = equiangular_pdf(rays.o, d, np.broadcast_to(prepared.lights.position[li], (b, 3)), t_end, t)
                with np.errstate(divide="ignore", invalid="ignore"):
                    scale = scale * np.where(p_d > 0, p_d / (p_d + p_e), 0.0)
            if p_light is not None:  # phase sampling can find this light too: the power heuristic
                scale = scale * power_heuristic(p_light, ph.astype(_F32), light_first=True)
            live = np.flatnonzero((scale > 0) & np.isfinite(scale))
            if live.size == 0:
                continue
            dd = np.asarray(dist, np.float64)[live]
            pd = np.asarray(pad, np.float64) if np.ndim(pad) == 0 else np.asarray(pad, np.float64)[live]
            tmax = np.where(np.isinf(dd), np.inf, dd - pd).astype(_F32)
            occ = prepared.accel.occluded(x[live], np.ascontiguousarray(np.asarray(wi, _F32)[live]), tmax)
            out.shadow_rays += len(occ)
            live = live[~occ]
            if live.size == 0:
                continue
            tr = transmittance(st[live], dd[~occ])  # one medium along an unoccluded shadow ray
            rl = rays.take(live)
            spec = light_spectrum_of(spectrum, live, rl)
            if mono:
                val = w[live] * (scale[live] * tr[np.arange(live.size), rl.lam] * spec).astype(_F32)
            else:
                val = w[live] * (scale[live, None] * tr * spec).astype(_F32)
            k_nd = nd[live]
            for k in np.unique(k_nd):  # light after this vertex: the film part of nd + 1 vertices
                part = k_nd == k
                out.accumulate(rl.take(part), val[part], out.light_film(min(int(k) + 1, 2)))
        # the continuation: a direction from the phase function (weight p / pdf = 1)
        u = trace.numbers(rays, SLOT_BOUNCE)
        wi, pdf = sample_hg(d, g, u.random(b), u.random(b))
        cont = rays.moved(x, wi.astype(_F32), w.astype(_F32))
        s = cont.state
        s.nd = np.minimum(s.nd + 1, MAX_DIFFUSE_VERTICES).astype(np.int8)
        s.pdf = pdf.astype(_F32)
        s.caustic = np.full(b, Caustic.NONE)
        s.seen = np.zeros(b, bool)
        volume = cont.depth - s.diffuse - s.glossy - s.transmission  # the volume bounces (section 15.5)
        s.final = (volume > self.volume_bounces) | (cont.depth > self.limits[0])
        if getattr(s, "tbg", None) is not None:  # a scattering ends Film > Transparent Glass's background
            s.tbg = np.zeros(b, bool)
        if getattr(s, "lobe", None) is not None:  # a grating order's path: any path from here on
            s.lobe = np.zeros(b, np.int8)
        if s.rd is not None:
            s.rd = footprint.zero_differentials(b)
        return cont
