"""The one scheduler of a render: cancel, time limit, progress and adaptive rounds, for any executor.

A render's work is units with their own random streams: the light pass's batches
(core/integrators/light/light_pass.py, ``LightWork``), then the eye pass's (round, tile) units
(core/render/tiles.py, ``EyeWork``). The image depends only on which units run and on the order
their results enter the film, never on where or when they ran, so this module keeps those rules
in one place and leaves the running to an **executor**:

- ``LocalExecutor``: this process's threads (a pool of ``prepared.threads``), or with one
  thread and nothing to poll (no cancel check, no time limit) the calling thread itself, one
  unit at a time (simpler to profile and debug);
- ``distributed.DaskExecutor``: the workers of a Dask cluster (core/render/distributed.py);
- the rendered viewport's progressive previews (core/render/progressive.py) run the local one
  level after level, under one cancel check.

The rules, the same for every executor:

- **Order.** Units are numbered round-major (unit i is round i // tiles, tile i % tiles) and
  added to the film in that order, whatever order they finish in; at most ``window`` units run
  ahead of the one the film needs next (bounded memory: each holds its tile's sums).
- **Adaptive sampling** (core/render/adaptive.py). A unit's pixels are the tile's active pixels
  when it is submitted (``Film.active_pixels``), so the window never reaches past a tile's
  previous round (it is at most one round of tiles); a tile whose pixels have all converged is
  skipped, and a round in which every tile was skipped ends the render: all pixels converged.
- **Cancel** (``RenderControl.cancelled``) is polled after every unit added and every POLL_S
  seconds while waiting for one; it ends the render at once (the film keeps the units added).
- **Time limit.** Checked on the control's clock after every unit added, at the end of every
  round and every POLL_S seconds while waiting for a unit, in any round: a round stopped midway
  keeps the tiles it added (the per-pixel sample counts say so; a stop in round 0 leaves the
  tiles not yet added without samples). With a time limit round 0 is one sample
  (tiles.EyeWork.of), so the whole image has a sample soon.
- **Latency.** Both act within about POLL_S of the moment, whatever a unit costs: the units in
  flight are dropped, not waited for, and ``cancel_pending`` makes the local executor's running
  units give up at their next ray-casting call (util/cancel.StoppableAccel), so none keeps a
  core busy for long after the render returned. The local light pass is polled the same way
  (``LocalExecutor.light_pass``: a cancel returns at once, its lanes stop at their next batch in
  the background; its time limit still waits for the batches in hand, whose deposits it keeps). A unit is never cut into pieces whose sizes would follow
  the machine's speed: its random numbers are one stream drawn in batch order (the caustic-map
  lookups, Russian roulette, gratings and dispersive splits draw from it, and batch-size
  dependent reductions round differently), so such slices would make the image depend on the
  timing; dropping the unit keeps every image the same bits for a seed and its units.
- **Progress** is reported after every unit added (``RenderControl.report``: increasing, the
  light pass's share first), and reaches 1 when the render ends without a cancel.
- ``on_round(result)`` receives the image after every round that added something, unless the
  render stopped during it.

The clock and the cancel check are injectable (``RenderControl(clock=...)``), so the rules are
tested with a fake clock and fake units of work (tests/render/test_scheduler.py).
"""

from __future__ import annotations

import math
import threading
import time
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Callable, Protocol

from ..integrators.eye.eye_pass import EyePass
from ..integrators.light.light_pass import LightPassResult, run_light_pass
from ..sampling.camera import FilterSampler
from ..util.cancel import RenderCancelled, StoppableAccel, check
from .tiles import EyeWork, is_half_a, trace_tile

__all__ = ["RenderControl", "Executor", "LocalExecutor", "EyePassOutcome", "run_eye_pass", "eye_window",
           "POLL_S", "SKIPPED"]

POLL_S = 0.1  # seconds between cancel checks while waiting for a unit


class RenderControl:
    """Cancel, time limit and progress of one render, measured on ``clock``.

    ``should_cancel()``: polled by ``cancelled``, which stays True once it said so.
    ``time_limit``: seconds from ``started_at`` (a ``clock()`` time; default: now), 0 for none.
    ``progress(fraction, message)``: receives only fractions larger than the last it received.
    ``clock``: seconds as a float (``time.perf_counter``; tests pass a fake)."""

    def __init__(self, should_cancel: Callable[[], bool] | None = None,
                 progress: Callable[[float, str], None] | None = None, time_limit: float = 0.0,
                 started_at: float | None = None, clock: Callable[[], float] = time.perf_counter):
        self.clock = clock
        self.started_at = clock() if started_at is None else float(started_at)
        self.deadline = self.started_at + float(time_limit) if time_limit else None
        self._should_cancel = should_cancel
        self._progress = progress
        self._cancelled = False
        self.reported = -math.inf  # the last fraction passed on

    def cancelled(self) -> bool:
        """Whether the render was asked to stop (polls ``should_cancel``)."""
        if not self._cancelled and self._should_cancel is not None and self._should_cancel():
            self._cancelled = True
        return self._cancelled

    def out_of_time(self) -> bool:
        """Whether the time limit has passed."""
        return self.deadline is not None and self.clock() > self.deadline

    def has_cancel_check(self) -> bool:
        """Whether this render has a cancel check (``should_cancel``)."""
        return self._should_cancel is not None

    def can_stop(self) -> bool:
        """Whether this render may stop early (it has a cancel check or a time limit), so its
        units must run where the scheduler can poll while they do."""
        return self._should_cancel is not None or self.deadline is not None

    def perf_deadline(self) -> float | None:
        """The deadline as a ``time.perf_counter()`` time, for the local light pass, whose lanes
        check it on their own (core/integrators/light/light_pass.py): the time left on this
        control's clock, from now."""
        if self.deadline is None or self.clock is time.perf_counter:
            return self.deadline
        return time.perf_counter() + (self.deadline - self.clock())

    def report(self, fraction: float, message: str) -> None:
        """Pass ``fraction`` (0..1) on to ``progress`` if it is larger than the last one passed."""
        if self._progress is not None and fraction > self.reported:
            self.reported = fraction
            self._progress(fraction, message)

    def stage(self, start: float, end: float) -> Callable[[float, str], None] | None:
        """A progress callback for one stage: its 0..1 maps to ``start``..``end`` of the whole
        (None without a progress callback, so a stage can skip its reports)."""
        if self._progress is None:
            return None
        return lambda f, m: self.report(start + (end - start) * f, m)


class Executor(Protocol):
    """Where a render's units run (LocalExecutor, distributed.DaskExecutor). Used as a context
    manager around one render: leaving it cancels what is pending and releases what it holds."""

    threads: int  # units it runs at once (sets how far ahead the scheduler submits)
    stats: dict   # what it adds to the render's stats

    def start(self, prepared, region, spectral: bool, control: RenderControl) -> bool:
        """Get ready to render ``region`` of ``prepared``; False when cancelled meanwhile."""

    def light_pass(self, prepared, plan, control: RenderControl, progress, keep_vertices: int = 0) -> LightPassResult:
        """Run the light pass as ``plan`` (plan.RenderPlan) says (``progress``: its stage of the
        control's progress, or None; ``keep_vertices``: run_light_pass's, bytes of camera-splat
        vertices to keep for another view, 0: none; an executor may keep none)."""

    def start_eye(self, prepared, plan, light: LightPassResult | None, work: EyeWork) -> None:
        """Get ready to trace ``work``'s units with this light pass, as ``plan`` says."""

    def submit(self, key: int, r_index: int, t_index: int, pixels) -> None:
        """Start unit ``key``: tile ``t_index`` of round ``r_index`` (``pixels``: see trace_tile)."""

    def finished(self, timeout: float) -> list:
        """(key, result) of the submitted units that have finished, waiting up to ``timeout``
        seconds for one."""

    def add(self, film, tile, samples: int, pixels, half_a: bool, result) -> int:
        """Add one unit's ``result`` to ``film`` (Film.add_tile's arguments); its rays."""

    def cancel_pending(self) -> None:
        """Drop the units submitted and not yet returned by ``finished``."""

    def note(self) -> str:
        """A few words for the progress message (where the units run), or ''."""


#: The result of a unit that had nothing to trace (every pixel of its tile has converged).
SKIPPED = None


@dataclass
class EyePassOutcome:
    """How the eye pass ended: ``stop`` is "" (every round ran), "cancel", "time" (the time
    limit) or "converged" (adaptive sampling: no pixel left to sample); ``rays`` traced;
    ``submitted``: units handed to the executor (skipped ones are not)."""

    stop: str
    rays: int
    submitted: int


def eye_window(threads: int, n_tiles: int, adaptive: bool) -> int:
    """Units submitted ahead of the one the film needs next: enough to keep ``threads`` busy;
    with adaptive sampling at most one round of tiles, so a tile's next round is submitted only
    once its previous one is in the film (its pixels follow from it)."""
    window = max(16, 4 * int(threads))
    return min(window, n_tiles) if adaptive else window


def run_eye_pass(work: EyeWork, film, executor: Executor, control: RenderControl, adaptive=None,
                 on_round: Callable[[], None] | None = None, progress_from: float = 0.0,
                 rays_before: int = 0) -> EyePassOutcome:
    """Run ``work``'s units on ``executor`` into ``film`` by the module's rules.

    ``adaptive``: (threshold, min samples) of adaptive sampling (tiles.adaptive_of), or None.
    ``on_round()``: called after every round that added something (unless the render stopped in
    it). Progress goes from ``progress_from`` to 1 over the units, and is 1 at the end unless
    cancelled; ``rays_before`` (the light pass's) is counted in its messages."""
    n_tiles, n_rounds = len(work.tiles), len(work.rounds)
    units = n_tiles * n_rounds
    window = eye_window(executor.threads, n_tiles, adaptive is not None)
    pixels_of: dict[int, object] = {}  # the pixels each unit in flight traces (None: all)
    results: dict[int, object] = {}    # finished units the film cannot add yet
    submitted = cursor = handed = rays = 0
    added_this_round = 0
    stop = ""
    try:
        while cursor < units and not stop:
            while submitted < units and submitted - cursor < window:
                r_index, t_index = divmod(submitted, n_tiles)
                px = film.active_pixels(*work.tiles[t_index][:4])
                pixels_of[submitted] = px
                if px is not None and len(px) == 0:  # converged: nothing to trace
                    results[submitted] = SKIPPED
                else:
                    executor.submit(submitted, r_index, t_index, px)
                    handed += 1
                submitted += 1
            while cursor in results and not stop:  # the film adds units in order
                r_index, t_index = divmod(cursor, n_tiles)
                res, px = results.pop(cursor), pixels_of.pop(cursor)
                cursor += 1
                if res is not SKIPPED:
                    tile = work.tiles[t_index]
                    rays += executor.add(film, tile, work.rounds[r_index], px, is_half_a(r_index), res)
                    if adaptive is not None:
                        film.update_active(*tile[:4], *adaptive)
                    added_this_round += 1
                    control.report(progress_from + (1 - progress_from) * cursor / units,
                                   f"eye pass: round {r_index + 1}/{n_rounds}, {(rays_before + rays) / 1e6:.1f} M "
                                   f"rays{executor.note()}")
                    if control.cancelled():
                        stop = "cancel"
                    elif t_index < n_tiles - 1 and control.out_of_time():
                        stop = "time"  # (after a round's last tile: checked below, after on_round)
                if stop or t_index < n_tiles - 1:
                    continue
                # a round is complete
                if added_this_round == 0:
                    stop = "converged"  # every tile was skipped: so will all later rounds be
                    break
                added_this_round = 0
                if on_round is not None:
                    on_round()
                if r_index + 1 < n_rounds and control.out_of_time():
                    stop = "time"
            if stop or cursor == units or cursor >= submitted:
                continue  # (nothing in flight: everything submitted so far was skipped)
            if control.cancelled():
                stop = "cancel"
                break
            if control.out_of_time():
                stop = "time"  # the units in flight are dropped (their tiles keep what they had)
                break
            for key, res in executor.finished(POLL_S):
                results[key] = res
    finally:
        executor.cancel_pending()
    if stop != "cancel":
        control.report(1.0, "eye pass: done" if stop != "converged" else "eye pass: every pixel has converged")
    return EyePassOutcome(stop, rays, handed)


class LocalExecutor:
    """Units on this process's threads: a pool of ``threads`` (default ``prepared.threads``),
    or with one thread and a render that cannot stop early (RenderControl.can_stop) the calling
    thread itself, one unit each time ``finished`` is called. A render that can stop traces on
    the pool even with one thread, so the scheduler polls while a unit runs; its units cast rays
    through util/cancel.StoppableAccel, so the ones running when ``cancel_pending`` is called
    stop at their next ray cast."""

    def __init__(self, threads: int | None = None):
        self.requested = threads
        self.threads = 1
        self.stats: dict = {}
        self._pool: ThreadPoolExecutor | None = None
        self._pending: dict = {}  # key -> future (a pool) or (r, t, pixels) (the calling thread)
        self._eye = self._filt = self._work = None
        self._pollable = False
        self._stop = threading.Event()  # set by cancel_pending: the running units give up
        self._eye_args = None  # (prepared, light, plan) of the EyePass the first unit builds
        self._eye_lock = threading.Lock()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.cancel_pending()
        if self._pool is not None:
            # not waited for: a dropped unit ends at its next ray cast (cancel_pending), on its own
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
        self._eye = self._eye_args = self._filt = self._work = None
        return False

    def start(self, prepared, region, spectral: bool, control: RenderControl) -> bool:
        self.threads = max(1, int(prepared.threads if self.requested is None else self.requested))
        self._pollable = control.can_stop()
        return True

    def light_pass(self, prepared, plan, control: RenderControl, progress, keep_vertices: int = 0) -> LightPassResult:
        """The light pass (``keep_vertices``: run_light_pass's); with a cancel check it runs in a worker thread polled from here every
        POLL_S, so a cancel returns at once (a cancelled, empty result) while its lanes stop at
        their next batch in the background (a batch can take seconds on a big scene). The
        worker gets plain flags, and the progress is passed on from this thread: the callbacks
        are only ever called from the calling thread (Blender's must)."""
        if not control.has_cancel_check():
            return run_light_pass(prepared, None, progress, control.cancelled, control.perf_deadline(), plan=plan,
                                  keep_vertices=keep_vertices)
        asked = threading.Event()
        latest: list = []  # the worker's last progress report (list appends are atomic)
        out: dict = {}

        def work():
            try:
                out["value"] = run_light_pass(prepared, None, (lambda f, m: latest.append((f, m))) if progress else None,
                                              asked.is_set, control.perf_deadline(), plan=plan,
                                              keep_vertices=keep_vertices)
            except BaseException as e:  # handed to the calling thread
                out["error"] = e

        worker = threading.Thread(target=work, name="opal-light-pass", daemon=True)
        worker.start()
        while worker.is_alive():
            worker.join(POLL_S)
            if latest and progress is not None:
                progress(*latest[-1])
            if worker.is_alive() and control.cancelled():
                asked.set()  # the lanes stop at their next batch; their result is dropped
                # cancelled, and none of its light paths used (stats as a cancelled run_light_pass's)
                return replace(LightPassResult.skipped(prepared), cancelled=True,
                               stats=MappingProxyType({"light_paths": 0, "light_deposits": 0, "light_rays": 0,
                                                       "cancelled": True}))
        if latest and progress is not None:
            progress(*latest[-1])
        if "error" in out:
            raise out["error"]
        return out["value"]

    def start_eye(self, prepared, plan, light, work: EyeWork) -> None:
        on_pool = self.threads > 1 or self._pollable
        self._stop = threading.Event()
        if on_pool:  # units that stop at their next ray cast once dropped (the same rays and bits)
            prepared = replace(prepared, accel=StoppableAccel(prepared.accel, self._stop.is_set))
        # the EyePass (its per-render constants) is built by the first unit, so a render that
        # stops before any (a time limit that ran out in the light pass) does not wait for it
        self._eye, self._eye_args = None, (prepared, light, plan)
        self._filt = FilterSampler(prepared.settings.filter_width)
        self._work = work
        if on_pool and self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=self.threads)

    def _eye_pass(self) -> EyePass:
        with self._eye_lock:
            if self._eye is None:
                if self._eye_args is None:  # the executor was left meanwhile (a dropped unit)
                    raise RenderCancelled()
                prepared, light, plan = self._eye_args
                self._eye = EyePass(prepared, light, plan=plan)
            return self._eye

    def _trace(self, r_index: int, t_index: int, pixels):
        check(self._stop.is_set)  # dropped before it started
        return trace_tile(self._eye_pass(), self._filt, self._work, r_index, t_index, pixels)

    def submit(self, key: int, r_index: int, t_index: int, pixels) -> None:
        if self._pool is not None:
            self._pending[key] = self._pool.submit(self._trace, r_index, t_index, pixels)
        else:  # traced when its result is asked for, in the calling thread
            self._pending[key] = (r_index, t_index, pixels)

    def finished(self, timeout: float) -> list:
        if not self._pending:
            return []
        if self._pool is None:  # the oldest unit, traced now
            key = next(iter(self._pending))
            return [(key, self._trace(*self._pending.pop(key)))]
        done, _ = wait(list(self._pending.values()), timeout=timeout, return_when=FIRST_COMPLETED)
        out = [(k, f) for k, f in self._pending.items() if f in done]
        for k, _f in out:
            del self._pending[k]
        return [(k, f.result()) for k, f in out]  # re-raises a unit's exception here

    def add(self, film, tile, samples: int, pixels, half_a: bool, result) -> int:
        x0, y0, x1, y1, _ = tile
        film.add_tile(x0, y0, x1, y1, result, samples, pixels, half_a)
        return int(result.rays)

    def cancel_pending(self) -> None:
        for f in self._pending.values():
            if self._pool is not None:
                f.cancel()
        if self._pending and self._pool is not None:
            self._stop.set()  # the running ones raise RenderCancelled at their next ray cast (dropped)
        self._pending.clear()

    def note(self) -> str:
        return ""
