"""The light pass: paths from the lights through mirrors, glass and gratings, deposited as
caustics and grating records, and connected to the camera; its entry point ``run_light_pass``.

The source paper's bidirectional half (Kobayashi & Kawai; docs/physics.md section 4.1). The
pass is told in four places:

- what it aims at and who receives (core/integrators/light/targets.py: casters, receivers,
  gratings) and how paths are aimed (core/lights/aiming.py: mixtures over the casters'
  bounding spheres);
- where paths start, per light kind, and each emitter's share of the paths by the power it sends
  towards the casters (core/lights/emission.py; docs/physics.md sections 7.7, 7.9);
- one batch of paths walked to its landings (core/integrators/light/walker.py: caustics on diffuse
  surfaces, grating records (docs/physics.md section 3.5), diffracted orders (section 3.10), the
  camera splat (core/integrators/light/camera_splat.py, section 4.9; ``LightPassResult.splat``),
  which the eye pass uses instead of the map where the camera sees such a surface directly);
- here: the work and its lanes. Every batch of paths draws its random numbers from its own
  stream (seed, light pass, emitter, batch), and batches add into the map, so the map does not
  depend on how the work is split. ``LightWork`` is that split: the elements sized for the path
  budget, the batches in order and the LANES fixed lanes they are dealt to; ``run_light_pass``
  runs the lanes on threads and sums them into a ``LightPassResult``. With more threads than
  lanes (and on a Dask worker) a batch deposits into a ``DepositLog`` instead, replayed into its
  lane's maps in the lane's order (``LaneAssembler``), so the map is the same bit for bit
  whatever the thread count or the machines (core/render/distributed.py): every core traces
  batches, while the lanes stay fixed.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor, wait
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from ...util.blas_threads import one_blas_thread
from .camera_splat import CameraConnection, CameraSplat, SplatLog
from .splat_vertices import SplatVertexStore, VertexKeeper
from ...transport.elements import ElementLayout, IlluminationMap
from ...gratings.records import PILOT_STREAM, GratingRecords, record_layout
from ...util.geometry import triangle_areas
from .targets import LightTargets
from .walker import BATCH_PATHS, LightBatch, trace_batch

__all__ = ["LightPassResult", "element_layout", "run_light_pass", "LANES", "LightWork", "DepositLog",
           "LaneAssembler", "trace_logged", "finish_light_pass"]

LANES = 2  # fixed partial maps (so the result does not depend on the thread count)
POLL_S = 0.1  # seconds between progress, cancel and time-limit checks


@dataclass(frozen=True)
class LightPassResult:
    """What the light pass hands to the eye pass; ``key`` is the prepared scene's it belongs to."""

    caustics: IlluminationMap | None          # flux on diffuse elements, or None (no light pass)
    grating_records: GratingRecords | None    # directional flux lobes at grating elements, or None
    stats: Mapping[str, float]                # light_paths, light_deposits, light_rays, elements, light_pass_s
    warnings: tuple[str, ...]
    cancelled: bool
    key: int
    splat: CameraSplat | None = None  # the paths' camera connection (core/integrators/light/camera_splat.py), or None: off
    # the splat's light-path vertices, kept to splat into another view (core/integrators/light/splat_vertices.py),
    # or None: not asked for (run_light_pass's keep_vertices), no splat, or a pass cut short
    vertices: SplatVertexStore | None = None
    # a kept light pass whose splat was made again for another view from ``vertices``
    # (splat_vertices.resplat): that re-splat's stats (resplat_s, resplat_vertices, resplat_bytes,
    # resplat_rays); None: the splat is the light pass's own
    resplat: Mapping[str, float] | None = None

    @property
    def resplatted(self) -> bool:
        """Whether the splat was made again from kept vertices (not traced with the light paths)."""
        return self.resplat is not None

    @classmethod
    def skipped(cls, prepared) -> "LightPassResult":
        return cls(None, None, MappingProxyType({}), (), False, prepared.key)


def element_layout(prepared, n_paths: int, mask, what: str = "caustic") -> tuple[ElementLayout, str]:
    """Elements sized for the path budget: about 16 deposits per element if the paths spread
    over all receiving area (caustics concentrate them, and the eye pass's lookup filters over
    neighbouring elements), capped so each lane's map stays under ~32 M floats (128 MB; the
    LANES partial maps together ~256 MB at most). Returns (layout, warning or "") - the warning
    says when the cap made the user's element size coarser, or when even one element pair per
    triangle is over the cap (then the map is empty: no caustics on those surfaces, said aloud)."""
    v, t = prepared.scene.vertices, prepared.scene.triangles
    mask = np.asarray(mask, bool)
    area = triangle_areas(v, t)  # once: the search below only recounts
    size = float(prepared.settings.element_size or 0.0)
    target = size * size if size > 0 else area[mask].sum() / max(n_paths / 16.0, 1.0)
    cap = 32_000_000 // max(prepared.grid.n, 1)
    if 2 * int(mask.sum()) > cap:
        return (ElementLayout.from_areas(area, np.zeros_like(mask), 1.0),
                f"{int(mask.sum())} receiving triangles are too many for the {what} map ({cap // 2} at most at "
                f"{prepared.grid.n} wavelengths): light through mirrors and glass is not deposited on them "
                "(a coarser wavelength step allows more)")
    asked = target
    while True:
        k = ElementLayout.subdivisions(area, mask, target)
        if int((2 * k * k).sum()) <= cap:
            warning = ""
            if target > asked * 1.01 and size > 0:
                warning = (f"element size {size * 1000:.1f} mm needs more memory than the map allows: "
                           f"using {np.sqrt(target) * 1000:.1f} mm (a coarser wavelength step allows finer)")
            return ElementLayout.from_areas(area, mask, target), warning
        target *= 2.0  # terminates: with k = 1 everywhere the count is 2 * receivers <= cap


def _record_layout(prepared, n_paths: int, mask) -> tuple[ElementLayout, str, dict]:
    """Grating-record elements: of the user's element size if set, else sized by where the
    grating flux lands, from a pilot pass on its own stream (grating_records.record_layout,
    docs/physics.md section 3.5). Returns (layout, warning or "", pilot stats)."""
    if float(prepared.settings.element_size or 0.0) > 0 or n_paths <= 0:
        layout, warning = element_layout(prepared, n_paths, mask, "grating-record")
        return layout, warning, {}

    def trace(light, batch, start, light_paths, illum, records):
        trace_batch(prepared, LightBatch(light, batch, start, light_paths), illum, records, stream=PILOT_STREAM)

    return record_layout(prepared, n_paths, mask, trace, BATCH_PATHS)


@dataclass(frozen=True)
class LightWork:
    """The light pass of one prepared scene cut into batches, and the lanes they are dealt to.

    ``batches`` interleave the lights (ordered by how far into its own light each batch is), so
    a pass stopped early has sampled every light alike; lane k holds batches k, k + LANES, ...
    in that order, and its maps are the batches' deposits added in that order. A pure function
    of the prepared scene and the path count: every machine computes the same one.
    """

    layout: ElementLayout                 # caustic map elements (on diffuse receivers)
    record_layout: ElementLayout | None   # grating record elements, or None without gratings
    warning: str                          # from element_layout, or ""
    batches: tuple[LightBatch, ...]
    total: int                            # paths planned
    record_info: Mapping[str, float] = field(default_factory=dict)  # the record layout's pilot pass

    @classmethod
    def of(cls, prepared, n_paths: int | None = None) -> "LightWork":
        n_paths = int(prepared.settings.light_paths if n_paths is None else n_paths)
        targets: LightTargets = prepared.light_targets
        layout, warning = element_layout(prepared, n_paths, targets.receiver_mask)
        rec_layout, rec_warning, rec_info = (_record_layout(prepared, n_paths, targets.grating_mask)
                                             if targets.grating_mask.any() else (None, "", {}))
        warning = "; ".join(dict.fromkeys(w for w in (warning, rec_warning) if w))
        budgets = targets.budgets  # the lights, then the emissive meshes (index L), the world (L + 1)
        share = budgets / max(budgets.sum(), 1e-300)
        paths_per_light = np.floor(share * n_paths).astype(np.int64)
        jobs = [LightBatch(li, bi, start, int(n_l)) for li, n_l in enumerate(paths_per_light)
                for bi, start in enumerate(range(0, int(n_l), BATCH_PATHS))]
        jobs.sort(key=lambda j: (j.start / max(j.light_paths, 1), j.light))
        return cls(layout, rec_layout, warning, tuple(jobs), int(paths_per_light.sum()), MappingProxyType(rec_info))

    def lane(self, k: int) -> tuple[int, ...]:
        """Indices into ``batches`` of lane k, in the order its maps add them."""
        return tuple(range(k, len(self.batches), LANES))

    def empty_maps(self, n: int) -> tuple[IlluminationMap, GratingRecords | None]:
        """One lane's (caustic map, grating records), zero."""
        return (IlluminationMap.empty(self.layout, n),
                GratingRecords.empty(self.record_layout, n) if self.record_layout else None)


class DepositLog:
    """A sink that records ``deposit`` calls instead of adding them, for ``replay`` into a map:
    the same additions in the same order, so the map is the one direct deposits make."""

    def __init__(self, layout: ElementLayout | None):
        self.layout = layout
        self.calls: list[tuple] = []  # (elements, flux, lam, towards_source, at, basis), in call order

    def deposit(self, elements, flux, lam=None, towards_source=None, at=None, basis=None) -> None:
        if len(elements):
            self.calls.append((elements, flux, lam, towards_source, at, basis))

    def replay(self, target: IlluminationMap) -> None:
        self.replay_calls(self.calls, target)

    @staticmethod
    def replay_calls(calls, target: IlluminationMap) -> None:
        """Add recorded ``calls`` (a DepositLog's ``calls``, e.g. sent back by a worker) to ``target``."""
        for elements, flux, lam, towards_source, at, basis in calls:
            if at is None:  # caustic maps: no points, no directions; perhaps coefficients over basis spectra
                target.deposit(elements, flux, lam, basis=basis)
            else:  # grating records
                target.deposit(elements, flux, lam, towards_source, at=at)


def trace_logged(prepared, work: LightWork, j: int, bounce: bool, splat: bool,
                 connection: CameraConnection | None = None, keep: bool = False) -> dict:
    """Trace batch ``j`` of ``work`` into logs instead of maps: {'illum', 'records' (DepositLog
    calls or None), 'splat' (SplatLog calls or None), 'counts', 'elements', 'vertices' (with
    ``keep`` and a splat: the batch's splat vertices per SPLIT piece, else None)}, what
    ``LaneAssembler.add`` replays (a local worker thread's or a Dask task's result)."""
    illum = DepositLog(work.layout)
    records = DepositLog(work.record_layout) if work.record_layout is not None else None
    splat_log = SplatLog() if splat else None
    vertices = [] if keep and splat else None
    counts = trace_batch(prepared, work.batches[j], illum, records, splat=splat_log, bounce=bounce,
                         connection=connection, keep=vertices)
    return {"illum": illum.calls, "records": None if records is None else records.calls, "counts": counts,
            "elements": work.layout.total, "splat": None if splat_log is None else splat_log.calls,
            "vertices": vertices}


class LaneAssembler:
    """The lanes' maps, counts and camera splats, filled from logged batches (``trace_logged``)
    that may finish in any order: a batch is replayed once every earlier batch of its lane has
    been, so each lane adds its batches in the order direct deposits would (bit for bit).
    ``add`` keeps a finished batch; ``drain`` replays what can be replayed and returns the
    paths now in the maps."""

    def __init__(self, prepared, work: LightWork, connection: CameraConnection | None,
                 keeper: VertexKeeper | None = None):
        self.work = work
        self.keeper = keeper  # the splat vertices kept, lane by lane in order, or None
        self.maps = [work.empty_maps(prepared.grid.n) for _ in range(LANES)]
        self.counts = [dict(paths=0, deposits=0, rays=0) for _ in range(LANES)]
        self.splats = [connection.empty() for _ in range(LANES)] if connection is not None else None
        self.lanes = [work.lane(k) for k in range(LANES)]
        self.position = [0] * LANES  # how many of its batches each lane has added
        self.ready: dict[int, dict] = {}  # finished batches a lane cannot add yet (an earlier one is missing)

    def add(self, j: int, out: dict) -> None:
        if out["elements"] != self.work.layout.total:
            raise ValueError("a batch was laid out differently from the light pass's map")
        self.ready[j] = out

    def drain(self) -> int:
        for k in range(LANES):  # add what each lane can, in its order
            lane = self.lanes[k]
            while self.position[k] < len(lane) and lane[self.position[k]] in self.ready:
                out = self.ready.pop(lane[self.position[k]])
                illum, records = self.maps[k]
                DepositLog.replay_calls(out["illum"], illum)
                if records is not None:
                    DepositLog.replay_calls(out["records"], records)
                if self.splats is not None:
                    for pixels, values in out["splat"] or ():
                        self.splats[k].add(pixels, values)
                for name, value in out["counts"].items():
                    self.counts[k][name] += value
                if self.keeper is not None:
                    self.keeper.add(k, out.get("vertices"), out["counts"]["paths"])
                self.position[k] += 1
        return sum(c["paths"] for c in self.counts)

    def complete(self) -> bool:
        return all(self.position[k] == len(self.lanes[k]) for k in range(LANES))


def finish_light_pass(prepared, work: LightWork, maps, counts, t0: float, timed_out: bool = False,
                      cancelled: bool = False, splats=None, keeper: VertexKeeper | None = None) -> LightPassResult:
    """The LightPassResult of lanes' ``maps`` [(illum, records)], ``counts`` [dict] and camera
    ``splats`` [CameraSplat] (None: off): the lanes summed in lane order, rescaled by planned /
    traced paths after a time limit. ``keeper``: the splat vertices kept (None: none); a pass
    cut short (cancelled, time limit) keeps none."""
    illum, records = maps[0]
    for extra_illum, extra_records in maps[1:]:
        illum += extra_illum
        if records is not None:
            records += extra_records
    splat = None
    if splats:
        splat = splats[0]
        for extra in splats[1:]:
            splat += extra
    total = work.total
    traced = sum(c["paths"] for c in counts)
    warnings = [work.warning] if work.warning else []
    if timed_out and not cancelled:
        if traced and traced < total:
            scale = np.float32(total / traced)
            illum.flux *= scale
            if records is not None:
                records.scale(scale)
            if splat is not None:
                splat.image *= scale
        warnings.append(f"time limit reached during the light pass: caustics from {traced / 1e6:.2f} M of "
                        f"{total / 1e6:.2f} M light paths")
    stats = {"light_paths": traced, "light_deposits": sum(c["deposits"] for c in counts),
             "light_rays": sum(c["rays"] for c in counts), "elements": work.layout.total,
             "light_pass_s": time.perf_counter() - t0}
    if records is not None:
        stats.update(records.stats())
        stats.update(work.record_info)
    if cancelled:
        stats["cancelled"] = True
    vertices = None
    if keeper is not None and not cancelled and not timed_out:
        vertices = keeper.store()
        stats["splat_vertices"] = vertices.vertices
        stats["splat_vertex_bytes"] = vertices.nbytes
    return LightPassResult(illum, records, MappingProxyType(stats), tuple(warnings), cancelled, prepared.key, splat,
                           vertices)


@one_blas_thread()  # the lanes are the parallelism (core/util/blas_threads.py)
def run_light_pass(prepared, n_paths: int | None = None, progress=None, should_cancel=None,
                   deadline: float | None = None, *, plan, keep_vertices: int = 0) -> LightPassResult:
    """Run the light pass over ``prepared`` (``n_paths``: default the settings' light paths) as
    ``plan`` (render/plan.RenderPlan of ``prepared``: its ``camera_splat`` and ``splat_bounce``).
    ``keep_vertices``: where the plan splats, keep the splat's light-path vertices up to that
    many bytes (``LightPassResult.vertices``, for splat_vertices.resplat into another view); 0:
    keep none.

    The batches are dealt to LANES fixed lanes (LightWork: batch j to lane j % LANES), each with
    its own maps, and summed in lane order at the end, so the result does not depend on the
    number of threads: with up to LANES threads each lane deposits directly, with more every
    thread traces batches into logs that the calling thread replays in lane order
    (``_run_logged``). ``progress`` and ``should_cancel``
    are called from the calling thread only (every POLL_S seconds at most; a lane stops at its
    next batch). ``deadline``: a ``time.perf_counter()`` time; the pass stops there and scales
    what it deposited by planned / traced paths (batches of all lights are interleaved, so an
    early stop has traced every light in about the same proportion), with a warning.
    """
    t0 = time.perf_counter()
    work = LightWork.of(prepared, n_paths)
    total = work.total
    keeper = (VertexKeeper(keep_vertices, LANES, total) if plan.camera_splat and keep_vertices > 0 else None)
    if prepared.threads > LANES and len(work.batches) > LANES:
        return _run_logged(prepared, work, plan, progress, should_cancel, deadline, t0, keeper)
    maps = [work.empty_maps(prepared.grid.n) for _ in range(LANES)]
    counts = [dict(paths=0, deposits=0, rays=0) for _ in range(LANES)]
    # the camera splat (core/integrators/light/camera_splat.py), or None: off
    connection = CameraConnection.of(prepared) if plan.camera_splat else None
    splats = [connection.empty() for _ in range(LANES)] if connection is not None else None
    stop = threading.Event()
    cancelled = False

    def run_lane(k):
        illum, records = maps[k]
        for j in work.lane(k):  # bounded memory: fixed batches
            if stop.is_set():
                return
            kept = [] if keeper is not None and keeper.keeping else None
            done = trace_batch(prepared, work.batches[j], illum, records,
                               splat=None if splats is None else splats[k], bounce=plan.splat_bounce,
                               connection=connection, keep=kept)
            for name, value in done.items():
                counts[k][name] += value
            if keeper is not None:
                keeper.add(k, kept, done["paths"])

    threads = max(1, min(LANES, prepared.threads))
    timed_out = False
    with ThreadPoolExecutor(max_workers=threads) as pool:
        futures = [pool.submit(run_lane, k) for k in range(LANES)]
        while True:
            done_set, pending = wait(futures, timeout=POLL_S)
            done = sum(c["paths"] for c in counts)
            if progress:
                progress(done / max(total, 1), f"light pass: {done / 1e6:.2f} M of {total / 1e6:.2f} M paths")
            if not pending:
                break
            if should_cancel and should_cancel():
                stop.set()
                cancelled = True
            if deadline is not None and time.perf_counter() > deadline and not stop.is_set():
                stop.set()
                timed_out = True
        for f in futures:
            f.result()  # re-raise a worker's exception here
    return finish_light_pass(prepared, work, maps, counts, t0, timed_out, cancelled, splats, keeper)


def _run_logged(prepared, work: LightWork, plan, progress, should_cancel, deadline, t0: float,
                keeper: VertexKeeper | None = None) -> LightPassResult:
    """run_light_pass on ``prepared.threads`` > LANES threads: every thread traces whole batches
    into logs (``trace_logged``), submitted in batch order with a bounded number in flight (the
    logs of finished batches wait only for their lane's earlier ones), and the calling thread
    replays them into the lanes in order (``LaneAssembler``): the maps of a direct run, bit for
    bit. A cancel or the time limit stops submitting; each lane keeps the prefix it added, as a
    direct lane stops at its next batch."""
    connection = CameraConnection.of(prepared) if plan.camera_splat else None
    lanes = LaneAssembler(prepared, work, connection, keeper)
    threads = int(prepared.threads)
    ahead = 2 * threads  # batches traced or waiting for their lane at once (bounds the logs' memory)
    total = work.total
    cancelled = timed_out = False
    with ThreadPoolExecutor(max_workers=threads) as pool:
        pending, submitted = {}, 0
        try:
            while True:
                while submitted < len(work.batches) and len(pending) + len(lanes.ready) < ahead:
                    pending[pool.submit(trace_logged, prepared, work, submitted, plan.splat_bounce,
                                        connection is not None, connection,
                                        keeper is not None and keeper.keeping)] = submitted
                    submitted += 1
                done_set, _ = wait(pending, timeout=POLL_S)
                for f in done_set:
                    lanes.add(pending.pop(f), f.result())  # re-raises a worker's exception here
                traced = lanes.drain()
                if progress:
                    progress(traced / max(total, 1), f"light pass: {traced / 1e6:.2f} M of {total / 1e6:.2f} M paths")
                if lanes.complete():
                    break
                if should_cancel and should_cancel():
                    cancelled = True
                    break
                if deadline is not None and time.perf_counter() > deadline:
                    timed_out = True
                    break
        finally:
            for f in pending:
                f.cancel()  # the batches not started; running ones finish and are dropped
    return finish_light_pass(prepared, work, lanes.maps, lanes.counts, t0, timed_out, cancelled, lanes.splats, keeper)
