"""The light pass's walker: one batch of light paths traced from its emitter to where it lands.

The source paper's bidirectional half (Kobayashi & Kawai; docs/physics.md section 4.1): light
paths carry the whole spectrum from their emitter (core/lights/emission.py), follow specular
reflection and refraction with Fresnel, dispersion and Russian roulette (``LightWalker``, a
transport.SpecularWalker), and where a path that has been specular at least once lands on a
diffuse surface its spectral flux is added to that surface element of the illumination map
(core/transport/elements.py). Where such a path reaches a grating, the grating's element records
the incoming spectral flux by the direction it came from and its wavelength band
(gratings.records.GratingRecords: sparse directional lobes, on elements a pilot pass sizes where
grating flux lands; docs/physics.md section 3.5), for the eye pass to diffract. Line gratings
are casters as well: a path that meets one is diffracted (kind GRATING from ``classify``, the
order sampled by core/gratings/order_sampling.py in ``scatter``) and goes on as a specular path,
so the orders land on diffuse surfaces as caustics (docs/physics.md section 3.10). Direct light
stays the eye pass's job, so a path that reaches a diffuse surface or grating first deposits
nothing: no double counting. The same landings on plain diffuse surfaces are also joined to the
camera and splatted into a film for that view (core/integrators/light/camera_splat.py,
docs/physics.md section 4.9). On smooth-shaded casters the paths bend about the shading normals
(core/transport/walker.py, docs/physics.md section 4.6); deposits and records stay indexed by the
geometric hit (triangle, barycentrics, side).

Every batch of paths (``LightBatch``) draws its random numbers from its own stream (seed, light
pass, emitter, batch), and ``trace_batch`` traces it into any pair of sinks with a ``deposit``
method (a lane's maps, or a DepositLog on a Dask worker: core/integrators/light/light_pass.py).
With SPLIT dispersion a batch is walked in pieces of ``wavelengths.SPLIT_CHUNK_RAYS / n`` white
paths, so the n mono paths each becomes at a dispersive glass stay bounded (docs/physics.md
section 2.6).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...transport import wavelengths
from .camera_splat import CameraConnection, CameraSplat, SplatBatch
from .splat_vertices import RecordingSplatBatch
from . import splat_bounce
from .adjoint_shading import adjoint_factor, dielectric_normal_used
from ...transport.elements import IlluminationMap
from ...gratings.records import GratingRecords
from ...gratings.order_sampling import diffracting, scatter_at_gratings
from ...lights.emission import emit
from ...materials.spectra import DIFFUSE
from ..bragg_shading import BraggShading
from ...transport.walker import GRATING, Hit, Rays, SpecularWalker

__all__ = ["LightWalker", "LightBatch", "trace_batch", "LIGHT_PASS_STREAM", "BATCH_PATHS"]

LIGHT_PASS_STREAM = 2
BATCH_PATHS = 1 << 15
RR_START_DEPTH = 3
RR_SURVIVAL = 0.8


class LightWalker(SpecularWalker):
    """Light paths: deposit at diffuse surfaces after a specular bounce, Russian roulette."""

    #: Veach's adjoint factor at smooth-shaded specular bounces (core/integrators/light/adjoint_shading.py,
    #: docs/physics.md section 4.6); False only to measure what it changes (benchmarks/caustic_ball.py)
    adjoint_shading = True

    def __init__(self, prepared, rng, illum: IlluminationMap, records: GratingRecords | None,
                 splat: SplatBatch | None = None):
        super().__init__(prepared, rng)
        self.illum = illum
        self.records = records
        self.splat = splat  # the camera connection of the landings (core/integrators/light/camera_splat.py), or None
        self.bounces = None  # splat_bounce.BounceLog: the landings continued by a diffuse bounce, or None
        self.deposited = 0
        self.bragg = BraggShading.for_prepared(prepared)  # FCC opal lobes scatter light paths on
        self._held_normal = None  # (rays, hit, specular normal) during a dielectric bounce

    def on_hit(self, rays: Rays, hit: Hit, kind: np.ndarray, rng) -> None:
        if self.records is not None:
            at_grating = self.prepared.gratings.enabled[hit.mat] & (rays.depth >= 1)
            if at_grating.any():
                r, h = rays.take(at_grating), hit.take(at_grating)
                idx, valid = self.records.layout.index(h.prim, h.bu, h.bv, h.front)
                if valid.any():
                    src, at = -r.d[valid], h.p[valid]
                    if r.lam is None:
                        self.records.deposit(idx[valid], r.take(valid).dense_w(self.n), towards_source=src, at=at)
                    else:
                        self.records.deposit(idx[valid], r.w[valid], r.lam[valid], towards_source=src, at=at)
        rows = np.flatnonzero((kind == DIFFUSE) & (rays.depth >= 1))
        if not len(rows):
            return
        if self.splat is not None:  # the same landings, seen by the camera (docs/physics.md section 4.9)
            self.splat.connect(self.prepared, rays, hit, self.n, rows)
            if self.bounces is not None:  # and one diffuse bounce on, to the camera (section 4.11)
                self.bounces.add(self.prepared, rays, hit, rows=rows)
        if isinstance(self.illum, IlluminationMap):  # a lane's map: index and deposit in one call
            take = lambda a: None if a is None else a.take(rows, axis=0)  # noqa: E731
            # the mono weights, the coefficients over the basis, or Rays.dense_w of the landings
            flux = take(rays.w) if rays.w is not None else np.ones((len(rows), self.n), np.float32)
            self.deposited += self.illum.deposit_hits(take(hit.prim), take(hit.bu), take(hit.bv), take(hit.front),
                                                      flux, take(rays.lam), basis=rays.basis)
            return
        r, h = rays.take(rows), hit.take(rows)
        idx, valid = self.illum.layout.index(h.prim, h.bu, h.bv, h.front)
        if not valid.any():
            return
        self.deposited += int(valid.sum())
        if r.lam is None:
            self.illum.deposit(idx[valid], r.dense_w(self.n)[valid] if r.basis is None else r.w[valid], basis=r.basis)
        else:
            self.illum.deposit(idx[valid], r.w[valid], r.lam[valid])

    def mirror_bounce(self, rays: Rays, hit: Hit) -> Rays:
        if self.prepared.corner_normals is None or not self.adjoint_shading or rays.w is None:
            return super().mirror_bounce(rays, hit)
        ns = self.specular_normal(rays, hit)
        self._held_normal = (rays, hit, ns)
        try:
            out = super().mirror_bounce(rays, hit)
        finally:
            self._held_normal = None
        # reflected about the specular normal: |w_l . n_s| = |w_n . n_s| cancel in the factor
        return self._adjoint(out, rays, hit, ns, None)

    def specular_normal(self, rays: Rays, hit: Hit) -> np.ndarray:
        held = self._held_normal  # the bounce's own, computed once for the bounce and its factor
        if held is not None and held[0] is rays and held[1] is hit:
            return held[2]
        return super().specular_normal(rays, hit)

    def dielectric_bounce(self, rays: Rays, hit: Hit, rng, u=None):
        if self.prepared.corner_normals is None or not self.adjoint_shading or rays.w is None:
            return super().dielectric_bounce(rays, hit, rng, u)
        ns = self.specular_normal(rays, hit)
        self._held_normal = (rays, hit, ns)
        try:
            out, transmitted = super().dielectric_bounce(rays, hit, rng, u)
        finally:
            self._held_normal = None
        ior = self.prepared.materials.ior
        n = np.take(ior[:, 0], hit.mat) if rays.lam is None else ior[hit.mat, rays.lam]
        eta = np.where(hit.front, 1.0 / n, n).astype(np.float32)
        used = dielectric_normal_used(rays.d, out.d, hit.ng, ns, eta, transmitted)
        return self._adjoint(out, rays, hit, ns, used), transmitted

    @staticmethod
    def _adjoint(out: Rays, rays: Rays, hit: Hit, ns, used) -> Rays:
        """``out`` with its weights times the adjoint shading-normal factor (adjoint_shading.py)."""
        f = adjoint_factor(rays.d, out.d, hit.ng, ns, used)
        w = out.w * (f[:, None] if out.w.ndim == 2 else f)  # spectra, coefficients or mono weights
        out.w = w.astype(np.float32, copy=False)
        return out

    def classify(self, rays: Rays, hit: Hit, kind: np.ndarray, rng) -> np.ndarray:
        """Paths a grating diffracts (core/gratings/order_sampling.py, docs/physics.md section 3.10) are
        kind GRATING: they neither bounce off the base nor land on it."""
        if not self.prepared.gratings.any:
            return kind
        return np.where(diffracting(self.prepared, hit, kind, rng), GRATING, kind)

    def scatter(self, rays: Rays, hit: Hit, kind: np.ndarray, can_bounce: np.ndarray, rng, shaded=None) -> Rays | None:
        """The orders of the gratings' paths (mono rays; section 3.10): diffracted paths are
        specular ones, so they deposit caustics where they land on diffuse surfaces."""
        if rays.basis is not None and (self.bragg is not None or self.prepared.gratings.any):
            rays = rays.dense()  # the opal lobes and the gratings' orders weigh spectra
        opal = None if self.bragg is None else self.bragg.scatter_light(rays, hit, can_bounce, rng)  # FCC opal lobes
        sel = (kind == GRATING) & can_bounce
        if not sel.any():
            return opal
        orders = scatter_at_gratings(self.prepared, rays.take(sel), hit.take(sel), rng, self.split_white)
        if opal is None or not len(opal):
            return orders
        if orders is None or not len(orders):
            return opal
        if (orders.lam is None) == (opal.lam is None):
            return Rays.concat(opal, orders)
        self.spawn(orders)  # white paths' orders are mono rays: traced with the mono population
        return opal

    def survives(self, rays: Rays, rng) -> np.ndarray:
        ok = rays.depth < self.prepared.settings.max_bounces
        deep = ok & (rays.depth >= RR_START_DEPTH)
        if deep.any():
            # Russian roulette: survivors carry 1 / survival more, so the expectation is unchanged
            killed = deep & (rng.random(len(rays)) >= RR_SURVIVAL)
            ok &= ~killed
            if rays.w is not None:
                w = rays.w.copy()  # a new array: subsets taken earlier may still gather the old one
                w[deep & ~killed] /= np.float32(RR_SURVIVAL)
                rays.w = w
        return ok


@dataclass(frozen=True)
class LightBatch:
    """One batch of light paths: ``paths`` paths of light ``light`` (its ``batch``-th), starting at
    path ``start`` of that light's ``light_paths``; its random stream is
    SeedSequence([seed, LIGHT_PASS_STREAM, light, batch])."""

    light: int
    batch: int
    start: int
    light_paths: int

    @property
    def paths(self) -> int:
        return min(BATCH_PATHS, self.light_paths - self.start)


def trace_batch(prepared, job: LightBatch, illum, records, stream: int = LIGHT_PASS_STREAM, splat=None,
                bounce: bool = False, connection: CameraConnection | None = None, keep: list | None = None) -> dict:
    """Trace one batch of light paths, depositing into ``illum`` and ``records`` (objects with a
    ``layout`` and IlluminationMap's ``deposit``: maps, or DepositLogs; ``records`` None
    without gratings). ``stream``: the random stream id (the records' pilot pass has its own).
    ``splat``: where the batch's camera splats go (an object with CameraSplat's ``add``: a
    lane's film or a camera_splat.SplatLog), or None: no camera connection (the plan's
    ``camera_splat`` off). ``bounce``: with a ``splat``, continue the landings by a diffuse
    bounce (the plan's ``splat_bounce``). ``connection``: ``CameraConnection.of(prepared)`` if the
    caller has it (made once per pass, not per batch). ``keep``: with a ``splat``, a list that
    receives the batch's splat vertices (core/integrators/light/splat_vertices.py), a list of
    SplatVertices per SPLIT piece in the order they were connected; None: none kept. Returns its
    counts: paths, deposits, rays."""
    seed = int(prepared.settings.seed)
    b = job.paths
    rng = np.random.default_rng(np.random.SeedSequence([seed, stream, job.light, job.batch]))
    n = prepared.grid.n
    o, d, coeff, basis = emit(prepared, job.light, b, rng)  # core/lights/emission.py
    live = coeff.max(axis=1) > 0
    w = (coeff[live] / float(job.light_paths)).astype(np.float32)
    if basis is not None and len(basis) >= n:  # no fewer coefficients than samples: plain spectra
        w, basis = (w @ basis).astype(np.float32), None
    m = int(live.sum())
    rays = Rays(o[live].astype(np.float32), d[live].astype(np.float32), np.zeros(m, np.int64),
                w, None, np.zeros(m, np.int32), rng.random(m),
                basis=None if basis is None else np.ascontiguousarray(basis, np.float32))
    if splat is None:
        connection = None
    elif connection is None:
        connection = CameraConnection.of(prepared)
    textured = keep is not None and prepared.textures.uses("color")

    def new_batch():  # a piece's splats (and, asked to keep them, its vertices)
        return SplatBatch(connection) if keep is None else RecordingSplatBatch(connection, textured)

    batch = new_batch() if connection is not None else None
    tr = LightWalker(prepared, rng, illum, records, batch)
    bounce_rng = None
    if batch is not None and bounce:
        tr.bounces = splat_bounce.BounceLog(prepared)
        receivers = tr.bounces.mask  # once per batch, for every piece's log
        # the continued landings (core/integrators/light/splat_bounce.py) draw from a stream of their own, so the
        # map and the direct splats are those of the same seed without them
        bounce_rng = np.random.default_rng(np.random.SeedSequence([seed, stream, job.light, job.batch, 1]))
    # SPLIT: the batch's white paths in pieces (core/wavelengths.split_chunks), so the mono paths
    # they become stay bounded, and each piece's camera splats are summed per pixel before the
    # next piece (a loop over a batch's few pieces, drawing the batch's stream one after another)
    chunks = wavelengths.split_chunks(prepared, m)
    shadow = 0
    for c in [slice(0, m)] if chunks is None else chunks:
        tr.walk(rays if chunks is None else rays.take(np.arange(c.start, c.stop)), tr.empty_mono())
        if tr.bounces is not None:  # the piece's landings, one diffuse bounce on
            tr.rays_cast += splat_bounce.trace_bounces(prepared, tr.bounces, tr.splat, bounce_rng)
            tr.bounces = splat_bounce.BounceLog(prepared, receivers)
        if tr.splat is not None:
            if isinstance(splat, CameraSplat):  # a lane's film: the batch's sums added in one pass
                splat.add_batch(tr.splat)
            else:  # a SplatLog: the (pixels, values) a Dask worker sends back
                splat.add(*tr.splat.finish())
            shadow += tr.splat.shadow_rays
            if keep is not None:
                keep.append(tr.splat.kept)
            tr.splat = new_batch()
    return {"paths": b, "deposits": tr.deposited, "rays": tr.rays_cast + shadow}
