"""One frame on a Dask cluster (``dask.distributed``), bit for bit the image one process renders.

``render(scene, settings, client=client)`` (frame.py) prepares the scene here, as a local
render does, and then the scheduler (scheduler.py) runs its units of work through
``DaskExecutor`` on the cluster's workers:

1. The job - the plain scene and settings, the render region, and a digest of this core's
   source - is scattered ONCE to every worker (``client.scatter(..., broadcast=True)``: one copy
   to one worker, then Dask's tree copy between workers). A worker prepares it once (its ray
   caster cannot be pickled) and keeps that preparation for every task of the job, cached by the
   job's token (a content hash of the scene and settings: the next frame of an unchanged scene
   reuses it).
2. Light pass: one task per batch of light paths (light_pass.LightWork; every batch has its own
   random stream). A task traces its batch into a DepositLog - the deposits it would have added
   to the map, in order - and here they are replayed into the LANES lane maps in lane order,
   exactly the additions a local run makes, so the map is identical; the lanes are then summed
   in lane order (light_pass.finish_light_pass). The finished maps are scattered once to every
   worker (only their rows that hold flux: ``pack_map``) and unpacked once per worker.
3. Eye pass: one task per (round, tile) (tiles.EyeWork, each with its own stream), reading the
   scattered job and light maps; a task returns its tile's sums and its non-Direct parts
   already in RGB (and its (P, n) spectral sums only when the job keeps a spectral film: a
   spectral EXR is written), added to the Film here in the local render's order (round by
   round), at most the scheduler's window of tasks ahead of the one the film needs.

Cancel, the time limit, progress and adaptive sampling follow the scheduler's rules, as in a
local render (scheduler.py); the light pass's loop here polls the same control every POLL_S. A
stop cancels the pending tasks. A worker that dies takes its running tasks and the results it held with it; the
scheduler runs them again elsewhere (up to ``distributed.scheduler.allowed-failures`` deaths per
task) and a task that raises is retried ``RETRIES`` times: a rerun draws the same random stream,
so the image does not change.

What crosses the wire is plain - dicts, tuples, NumPy arrays, strings, numbers (``to_wire`` /
``from_wire``) - and the task functions are named by their stable module path
``opal_diffraction.core.render.distributed``, so a client that imported the core under another name (a
Blender extension is ``bl_ext.<repo>.opal_diffraction``) drives workers that ``pip install``-ed
it. Workers must run the same core (checked: the source digest) and the same ray caster backend
(checked), and for bit-identity the same NumPy build on the same kind of CPU.

Dask is optional: this module imports it only inside ``connect``; the executor only calls the
client it is given.
"""

from __future__ import annotations

import hashlib
import importlib
import os
import pickle
import sys
import threading
import time
import uuid
from collections import OrderedDict
from contextlib import contextmanager
from dataclasses import fields, is_dataclass, replace
from types import MappingProxyType

import numpy as np

from ..util.blas_threads import one_blas_thread
from ..sampling.camera import FilterSampler
from ..transport.elements import ElementLayout, IlluminationMap
from ..integrators.eye.eye_pass import EyePass
from ..gratings.records import GratingRecords
from .film import tile_parts_rgb
from ..integrators.light.camera_splat import CameraConnection, CameraSplat, view_key
from ..integrators.light.light_pass import LaneAssembler, LightPassResult, LightWork, finish_light_pass, trace_logged
from .plan import plan_render
from .prepare import prepare
from .scheduler import POLL_S
from ..scene.checks import SceneError
from ..scene.model import Camera, Lights, Materials, Scene
from ..scene.settings import RenderSettings
from .tiles import EyeWork, trace_tile

__all__ = ["DaskExecutor", "connect", "ClusterError", "to_wire", "from_wire", "RETRIES", "LOCAL_PREFIX"]

#: The name workers import this module by, whatever the client's package path.
MODULE = "opal_diffraction.core.render.distributed"
RETRIES = 2          # reruns of a task that raised (a dead worker's tasks are rerun by the scheduler)
WORKER_WAIT_S = 60.0  # how long to wait for a first worker to join the scheduler
REPLICATE_S = 1.0    # seconds between checks for new workers that need the scattered data
LOCAL_PREFIX = "local:"
MAX_CACHED = 2       # prepared jobs a worker keeps (the current frame and the one before)


class ClusterError(SceneError):
    """The cluster cannot render: no dask, no scheduler, no workers, workers running other code."""


#: Workers raise a builtin RuntimeError with this prefix (an exception class of ours might not
#: unpickle on the client); the client turns it into a ClusterError.
_MISMATCH = "opal_diffraction worker mismatch: "


def _result(future):
    """``future.result()``, then the future released (the worker drops the result at once, not
    when a garbage collection finds the future), with a worker's mismatch error as a ClusterError."""
    try:
        return future.result()
    except RuntimeError as e:
        if str(e).startswith(_MISMATCH):
            raise ClusterError(str(e)[len(_MISMATCH):]) from None
        raise
    finally:
        future.release()


# --------------------------------------------------------------------------- the wire format
_WIRE_CLASSES = {c.__name__: c for c in (Scene, Materials, Lights, Camera, RenderSettings, ElementLayout)}


def to_wire(x):
    """``x`` as plain data (dicts, lists, NumPy arrays, str, numbers, None): the dataclasses of
    the scene, the settings and element layouts become tagged dicts, so unpickling needs no module of
    ours. Raises TypeError for anything else that is not plain."""
    if isinstance(x, np.ndarray) or x is None or isinstance(x, (str, bytes, bool, int, float, np.generic)):
        return x
    if is_dataclass(x) and not isinstance(x, type):
        name = type(x).__name__
        if _WIRE_CLASSES.get(name) is not type(x):
            raise TypeError(f"{type(x).__qualname__} cannot be sent to Dask workers")
        return {"__dc__": name, **{f.name: to_wire(getattr(x, f.name)) for f in fields(x)}}
    if isinstance(x, MappingProxyType):
        return {"__ro__": {k: to_wire(v) for k, v in x.items()}}
    if isinstance(x, dict):
        return {k: to_wire(v) for k, v in x.items()}
    if isinstance(x, tuple):
        return {"__t__": [to_wire(v) for v in x]}
    if isinstance(x, list):
        return [to_wire(v) for v in x]
    raise TypeError(f"{type(x).__qualname__} cannot be sent to Dask workers")


def from_wire(x):
    """The inverse of ``to_wire`` (the arrays are not copied)."""
    if isinstance(x, dict):
        if "__dc__" in x:
            cls = _WIRE_CLASSES[x["__dc__"]]
            return cls(**{k: from_wire(v) for k, v in x.items() if k != "__dc__"})
        if "__ro__" in x:
            return MappingProxyType({k: from_wire(v) for k, v in x["__ro__"].items()})
        if "__t__" in x:
            return tuple(from_wire(v) for v in x["__t__"])
        return {k: from_wire(v) for k, v in x.items()}
    if isinstance(x, list):
        return [from_wire(v) for v in x]
    return x


def pack_map(m: IlluminationMap | GratingRecords | None) -> dict | None:
    """An illumination map (or grating records: their sparse lobes) as plain data, only its rows that hold something (a caustic map is
    mostly empty: 6 % of the prism example's rows), exact to the bit (rows are chosen by their
    bits, so even a -0.0 survives)."""
    if m is None:
        return None
    if isinstance(m, GratingRecords):  # sparse already: its occupied lobes, as they are
        return {"layout": to_wire(m.layout), "records": m.arrays()}
    rows = np.flatnonzero(np.any(m.flux.view(np.uint32) != 0, axis=1)).astype(np.int64)
    return {"layout": to_wire(m.layout), "shape": list(m.flux.shape), "rows": rows,
            "flux": np.ascontiguousarray(m.flux[rows])}


def unpack_map(d: dict | None) -> IlluminationMap | GratingRecords | None:
    """The inverse of ``pack_map``."""
    if d is None:
        return None
    if "records" in d:
        return GratingRecords.from_arrays(from_wire(d["layout"]), d["records"])
    flux = np.zeros(tuple(d["shape"]), np.float32)
    flux[d["rows"]] = d["flux"]
    return IlluminationMap(from_wire(d["layout"]), flux)


def _nbytes(x) -> int:
    """Bytes of the arrays and strings in plain data (about its pickled size)."""
    if isinstance(x, np.ndarray):
        return x.nbytes
    if isinstance(x, (str, bytes)):
        return len(x)
    if isinstance(x, dict):
        return sum(_nbytes(v) for v in x.values())
    if isinstance(x, (list, tuple)):
        return sum(_nbytes(v) for v in x)
    return 8


_digest_cache: list[str] = []


def code_digest() -> str:
    """A digest of this core's source files: client and workers must run the same tracer."""
    if not _digest_cache:
        root = os.path.dirname(os.path.abspath(__file__))
        h = hashlib.blake2b(digest_size=16)
        for folder, dirs, files in os.walk(root):
            dirs[:] = sorted(d for d in dirs if not d.startswith((".", "__")))
            for f in sorted(files):
                if f.endswith(".py"):
                    path = os.path.join(folder, f)
                    h.update(os.path.relpath(path, root).replace(os.sep, "/").encode())
                    with open(path, "rb") as fh:
                        h.update(fh.read())
        _digest_cache.append(h.hexdigest())
    return _digest_cache[0]


def make_job(scene: Scene, settings: RenderSettings, region, backend: str, spectral: bool = False) -> dict:
    """What every worker receives once for a frame (plain data; see to_wire). ``spectral``: the
    tile tasks return their spectral sums too (the client's film keeps a spectral image)."""
    scene_w, settings_w = to_wire(scene), to_wire(settings)
    token = hashlib.blake2b(pickle.dumps((scene_w, settings_w, tuple(region)), protocol=5),
                            digest_size=16).hexdigest()
    return {"token": token, "code": code_digest(), "backend": backend, "region": list(region),
            "scene": scene_w, "settings": settings_w, "spectral": bool(spectral)}


# --------------------------------------------------------------------------- on a worker
#: glibc malloc on a worker: Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_=65536, which
#: also switches off glibc's adaptive mmap threshold, so every NumPy temporary above 128 kB is a
#: fresh mmap whose pages fault in zeroed: the tracer ran 2-2.5x slower on a worker than in a
#: plain process (benchmarks/bench_distributed.py). Above this size arrays are still mmapped
#: (and given back when freed), below it the heap reuses them; the heap's top is trimmed past
#: MALLOC_TRIM_BYTES.
MALLOC_MMAP_BYTES = 32 << 20
MALLOC_TRIM_BYTES = 256 << 20
_malloc_tuned: list[bool] = []


def _tune_malloc() -> None:
    """Set this worker process's glibc malloc thresholds once (Linux only; else a no-op)."""
    if _malloc_tuned or not sys.platform.startswith("linux"):
        return
    _malloc_tuned.append(True)
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-3, MALLOC_MMAP_BYTES)  # M_MMAP_THRESHOLD
        libc.mallopt(-1, MALLOC_TRIM_BYTES)  # M_TRIM_THRESHOLD
    except (OSError, AttributeError):  # not glibc (musl, ...): leave it
        pass


class _Frame:
    """A worker's preparation of one job, shared by the job's tasks on that worker."""

    def __init__(self, job: dict):
        _tune_malloc()
        if job["code"] != code_digest():
            raise RuntimeError(f"{_MISMATCH}a worker (pid {os.getpid()}) runs a different opal_diffraction core "
                               "than the client: install the same version on every machine")
        self.prepared = prepare(from_wire(job["scene"]), from_wire(job["settings"]))
        self.plan = plan_render(self.prepared)  # the pass decisions, as the client's plan made them
        if self.prepared.accel.name != job["backend"]:
            raise RuntimeError(f"{_MISMATCH}a worker's ray caster is '{self.prepared.accel.name}', the "
                               f"client's '{job['backend']}': install the same packages (embreex) on every machine")
        self.filt = FilterSampler(self.prepared.settings.filter_width)
        self.eye_work = EyeWork.of(self.prepared, job["region"])
        self._light_work = None
        self._light = (None, None)  # (token, LightPassResult) of the maps last unpacked here

    def light(self, light: dict | None) -> LightPassResult | None:
        """The scattered light-pass maps, unpacked once per worker and bound to this worker's
        preparation (the light pass ran on the client's)."""
        if light is None:
            return None
        token, result = self._light
        if token != light["token"]:
            # the client's camera splat holds for this job's view: the worker needs only its key
            splat = (CameraSplat(view_key(self.prepared.scene.camera, self.prepared.settings.filter_width), None,
                                 bool(light["splat_spectral"])) if light.get("splat") else None)
            result = LightPassResult(unpack_map(light["caustics"]), unpack_map(light["grating_records"]),
                                     MappingProxyType({}), (), False, self.prepared.key, splat)
            self._light = (light["token"], result)
        return result

    @property
    def light_work(self) -> LightWork:
        if self._light_work is None:
            self._light_work = LightWork.of(self.prepared)
        return self._light_work


_frames: OrderedDict[str, _Frame] = OrderedDict()
_frames_lock = threading.Lock()


def _frame(job: dict) -> _Frame:
    """This worker's preparation of ``job``: made by the first task of the job, then reused."""
    with _frames_lock:  # one preparation per worker process, however many threads it runs
        frame = _frames.get(job["token"])
        if frame is None:
            frame = _frames[job["token"]] = _Frame(job)
            while len(_frames) > MAX_CACHED:
                _frames.popitem(last=False)
        _frames.move_to_end(job["token"])
        return frame


@one_blas_thread()  # the worker's threads are the parallelism (core/util/blas_threads.py)
def light_batch_task(job: dict, index: int) -> dict:
    """Trace batch ``index`` of the job's light pass; its deposits in order, and its counts."""
    frame = _frame(job)
    return trace_logged(frame.prepared, frame.light_work, index, frame.plan.splat_bounce, frame.plan.camera_splat)


@one_blas_thread()
def tile_task(job: dict, light: dict | None, r_index: int, t_index: int, pixels=None) -> dict:
    """Trace tile ``t_index`` of round ``r_index`` (only its flat pixel indices ``pixels``, for
    adaptive sampling; None: all), reading the scattered light-pass maps; its sums in RGB, its
    non-Direct parts in RGB, its denoising features (Film.add_converted) and, only when the job
    keeps a spectral film, its (P, n) spectral sums (else None: 12 bytes a pixel cross the wire
    instead of 4 n)."""
    frame = _frame(job)
    eye = EyePass(frame.prepared, frame.light(light), plan=frame.plan)
    tile = trace_tile(eye, frame.filt, frame.eye_work, r_index, t_index, pixels)
    conv = frame.prepared.conv
    return {"rgb": conv.to_rgb(tile.film), "spectral": tile.film if job.get("spectral") else None,
            "parts": tile_parts_rgb(conv, tile), "rays": int(tile.rays), "albedo": tile.albedo,
            "normal": tile.normal, "alpha": tile.alpha}


class _ModuleRef:
    """Pickles as ``importlib.import_module(MODULE)``."""

    def __reduce__(self):
        return importlib.import_module, (MODULE,)


class _Task:
    """A task function of this module, pickled by the stable name MODULE (not by this client's
    package path), so workers resolve it to their own ``opal_diffraction`` install."""

    def __init__(self, name: str):
        self.name = name
        self.__name__ = f"opal-{name}"

    def __call__(self, *args):
        return globals()[self.name](*args)

    def __reduce__(self):
        return getattr, (_ModuleRef(), self.name)


LIGHT_TASK = _Task("light_batch_task")
TILE_TASK = _Task("tile_task")


# --------------------------------------------------------------------------- the client side
@contextmanager
def connect(address: str, timeout: float = 10.0):
    """A ``dask.distributed.Client`` for ``address``: ``'local:N'`` starts a LocalCluster of N
    worker processes with one thread each on this machine (closed on exit); anything else is a
    scheduler address (``tcp://host:8786``). Raises ClusterError with a readable message."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise ClusterError("rendering on a Dask scheduler needs dask: pip install -r requirements-dask.txt "
                           "(or pip install 'opal_diffraction[dask]')") from None
    address = address.strip()
    if address.startswith(LOCAL_PREFIX):
        try:
            n = int(address[len(LOCAL_PREFIX):])
        except ValueError:
            n = 0
        if n < 1:
            raise ClusterError(f"'{address}': write local:N with N >= 1 worker processes")
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None)
        try:
            client = Client(cluster)
        except BaseException:
            cluster.close()
            raise
        try:
            yield client
        finally:
            client.close()
            cluster.close()
        return
    try:
        client = Client(address, timeout=timeout)
    except (OSError, TimeoutError, ValueError) as e:
        raise ClusterError(f"cannot reach the Dask scheduler at '{address}': {e}") from None
    try:
        yield client
    finally:
        client.close()


def _worker_threads(client, should_cancel) -> int:
    """Threads of the workers connected to the scheduler, waiting up to WORKER_WAIT_S for one."""
    t0 = time.perf_counter()
    while True:
        nthreads = client.nthreads()
        if nthreads:
            return sum(nthreads.values())
        if should_cancel and should_cancel():
            return 0
        if time.perf_counter() - t0 > WORKER_WAIT_S:
            raise ClusterError(f"no Dask worker joined the scheduler at {client.scheduler.address} "
                               f"within {WORKER_WAIT_S:.0f} s: start some with 'dask worker {client.scheduler.address}'")
        time.sleep(POLL_S)


class _Replicas:
    """Keeps the scattered job and light maps on every worker: a worker that joins mid-render (a
    dead one's replacement) gets a copy from its peers within REPLICATE_S, rather than with its
    first task, so one more death is less likely to take the last copy."""

    def __init__(self, client):
        self.client, self.futures, self.workers, self.last = client, [], set(client.nthreads()), time.perf_counter()

    def add(self, future) -> None:
        self.futures.append(future)

    def check(self) -> None:
        if time.perf_counter() - self.last < REPLICATE_S or not self.futures:
            return
        self.last = time.perf_counter()
        workers = set(self.client.nthreads())
        if workers - self.workers:
            try:
                self.client.replicate(self.futures)
            except Exception:  # a task that then misses its input reports why
                pass
        self.workers = workers

    def release(self) -> None:
        for f in self.futures:
            f.release()


class _Finished:
    """Wakes the client's loop when a watched future finishes (a done callback sets an event),
    so waiting never raises: a timeout exception's traceback would tie the caller's frames, and
    its callbacks (Blender's engine), into a reference cycle."""

    def __init__(self):
        self.event = threading.Event()

    def watch(self, future):
        future.add_done_callback(self._set)
        return future

    def _set(self, _future) -> None:
        self.event.set()

    def wait(self, pending: dict, timeout: float) -> list:
        """Keys of ``pending`` whose futures have finished, waiting up to ``timeout`` for one."""
        done = [k for k, f in pending.items() if f.done()]
        if not done:
            self.event.wait(timeout)
            self.event.clear()  # before the scan: a future finishing after it sets it again
            done = [k for k, f in pending.items() if f.done()]
        return done


class DaskExecutor:
    """The scheduler's executor on a Dask cluster (core/render/scheduler.py): the job scattered
    once, the light pass as one task per batch, the eye pass as one task per (round, tile).
    ``scene``: the scene as given to ``prepare`` (what the workers prepare again)."""

    def __init__(self, client, scene: Scene):
        self.client, self.scene = client, scene
        self.threads = 1
        self.stats: dict = {"scheduler": str(client.scheduler.address)}
        self._uid = uuid.uuid4().hex[:12]
        self._scattered = _Replicas(client)  # the job and the light-pass maps, released at the end
        self._finished = _Finished()
        self._pending: dict[int, object] = {}
        self._job_f = self._light_f = None
        self._received = 0

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        _cancel(self.client, self._pending)
        self._scattered.release()
        return False

    def start(self, prepared, region, spectral: bool, control) -> bool:
        self.threads = _worker_threads(self.client, control.cancelled)
        if self.threads == 0:  # cancelled while waiting for workers
            return False
        self.stats.update(workers=len(self.client.nthreads()), worker_threads=self.threads)
        job = make_job(self.scene, prepared.settings, region, prepared.accel.name, spectral)
        self.stats["sent_job_bytes"] = _nbytes(job)
        (self._job_f,) = self.client.scatter([job], broadcast=True, hash=False)
        self._scattered.add(self._job_f)
        return True

    def light_pass(self, prepared, plan, control, progress, keep_vertices: int = 0) -> LightPassResult:
        """The light pass on the cluster; it keeps no camera-splat vertices (``keep_vertices`` is
        ignored: the engine keeps nothing between frames rendered on a cluster)."""
        return _light_pass(self.client, self._job_f, prepared, plan, progress, control, self._uid, self.threads,
                           self._scattered)

    def start_eye(self, prepared, plan, light: LightPassResult | None, work: EyeWork) -> None:
        self.stats.update(eye_tasks=0, received_tile_bytes=0)
        if light is None:
            return
        light_w = {"token": self._uid, "caustics": pack_map(light.caustics),
                   "grating_records": pack_map(light.grating_records),
                   "splat": light.splat is not None,
                   "splat_spectral": light.splat is not None and light.splat.spectral}
        self.stats["sent_light_bytes"] = _nbytes(light_w)
        (self._light_f,) = self.client.scatter([light_w], broadcast=True, hash=False)
        self._scattered.add(self._light_f)

    def submit(self, key: int, r_index: int, t_index: int, pixels) -> None:
        self._pending[key] = self._finished.watch(
            self.client.submit(TILE_TASK, self._job_f, self._light_f, r_index, t_index, pixels,
                               key=f"opal-tile-{self._uid}-{r_index}-{t_index}", retries=RETRIES))
        self.stats["eye_tasks"] += 1

    def finished(self, timeout: float) -> list:
        self._scattered.check()
        out = []
        for key in self._finished.wait(self._pending, timeout):
            res = _result(self._pending.pop(key))
            self._received += _nbytes(res)
            out.append((key, res))
        self.stats["received_tile_bytes"] = self._received
        return out

    def add(self, film, tile, samples: int, pixels, half_a: bool, result) -> int:
        x0, y0, x1, y1, _ = tile
        film.add_converted(x0, y0, x1, y1, result["rgb"], result["parts"], samples, result["albedo"],
                           result["normal"], pixels, half_a, result["spectral"], alpha=result.get("alpha"))
        return int(result["rays"])

    def cancel_pending(self) -> None:
        _cancel(self.client, self._pending)

    def note(self) -> str:
        return f", {self.threads} worker thread(s)"


def _cancel(client, pending: dict) -> None:
    """Cancel the tasks still pending (a stop, or an exception on the way out)."""
    if pending:
        try:
            client.cancel(list(pending.values()))
            for f in pending.values():
                f.release()
        except Exception:  # the client is closing (Ctrl-C): its futures go with it
            pass
        pending.clear()


def _light_pass(client, job_f, prepared, plan, progress, control, uid, threads, scattered: _Replicas) -> LightPassResult:
    """The light pass as one task per batch; deposits replayed into the lanes in lane order.
    ``control`` (scheduler.RenderControl) is polled every POLL_S for a cancel and the time limit;
    progress counts the paths added to the lanes (a batch that finished before its lane's
    earlier ones waits), so a cancel right after a report keeps what it reported."""
    t0 = time.perf_counter()
    work = LightWork.of(prepared)
    # the maps and the camera splat, added batch by batch in lane order
    lanes = LaneAssembler(prepared, work, CameraConnection.of(prepared) if plan.camera_splat else None)
    finished = _Finished()
    pending = {j: finished.watch(client.submit(LIGHT_TASK, job_f, j, key=f"opal-light-{uid}-{j}", retries=RETRIES))
               for j in range(len(work.batches))}
    cancelled = timed_out = False
    received = reported = 0
    try:
        while True:
            traced = lanes.drain()  # add what each lane can, in its order
            if progress and traced > reported:  # the paths in the map, as a local light pass reports
                reported = traced
                progress(traced / max(work.total, 1), f"light pass: {traced / 1e6:.2f} M of "
                                                      f"{work.total / 1e6:.2f} M paths on {threads} worker thread(s)")
            if lanes.complete():
                break
            if control.cancelled():
                cancelled = True
                break
            if control.out_of_time():
                timed_out = True  # each lane keeps the prefix it added, as a local lane stops at a batch
                break
            scattered.check()
            done = finished.wait(pending, POLL_S)
            for j in done:
                out = _result(pending.pop(j))
                received += _nbytes(out)
                if out["elements"] != work.layout.total:
                    raise ClusterError("a worker laid out the illumination map differently from the client")
                lanes.add(j, out)
    finally:
        _cancel(client, pending)
    result = finish_light_pass(prepared, work, lanes.maps, lanes.counts, t0, timed_out, cancelled, lanes.splats)
    stats = dict(result.stats, light_tasks=len(work.batches), received_light_bytes=received)
    return replace(result, stats=MappingProxyType(stats))
