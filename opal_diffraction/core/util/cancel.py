"""Cancellation: the exception a cancelled stage raises, and a runner that keeps a long
NumPy-heavy stage responsive to cancel.

``run_cancellable(fn, should_cancel)`` runs ``fn(stopped)`` in a worker thread and polls
``should_cancel`` from the calling thread every POLL_S seconds, so a cancel is honoured within
about POLL_S of the request even while ``fn`` is inside one long vectorised call (NumPy releases
the GIL in its loops). After a cancel ``stopped()`` returns True: ``fn`` checks it between its
stages and gives up early (raising RenderCancelled), so a cancelled worker does not keep the
CPU busy for long; its result is dropped. Code that holds the GIL for long (a C extension's
loop) delays the poll by as long; the Embree backend therefore builds its geometry in chunks.

``StoppableAccel(accel, stopped)`` does the same for a render's ray casting: the eye pass's
units run on an accelerator wrapped so that every ``intersect`` / ``occluded`` call first checks
``stopped()``, so a unit that the scheduler dropped (cancel, time limit) gives up at its next
ray-casting call (every bounce makes one) instead of tracing on in the background; the rays and
their arithmetic are the accelerator's own, so the image is unchanged.
"""

from __future__ import annotations

import threading
import time
from typing import Callable, TypeVar

__all__ = ["RenderCancelled", "OutOfTime", "run_cancellable", "check", "StoppableAccel", "POLL_S"]

T = TypeVar("T")
POLL_S = 0.05


class RenderCancelled(Exception):
    """The user cancelled (Esc in Blender, Ctrl-C, a should_cancel callback returning True)."""


class OutOfTime(RenderCancelled):
    """The render's time limit ran out before it could produce a sample (while preparing)."""


def check(stopped: Callable[[], bool] | None) -> None:
    """Raise RenderCancelled when ``stopped()`` says so (a worker's check between stages)."""
    if stopped is not None and stopped():
        raise RenderCancelled()


def run_cancellable(fn: Callable[[Callable[[], bool]], T], should_cancel: Callable[[], bool] | None,
                    deadline: float | None = None, deadline_armed: threading.Event | None = None) -> T:
    """``fn(stopped)``, or RenderCancelled as soon as ``should_cancel()`` returns True, or
    OutOfTime as soon as ``deadline`` (a time.perf_counter() time) has passed once
    ``deadline_armed`` is set (None: from the start). ``fn`` runs in a worker and the calling
    thread polls every POLL_S, so a long step inside ``fn`` (a ray caster's build) does not
    delay either; ``stopped()`` turns True then, and ``fn`` stops at its next check."""
    if should_cancel is None and deadline is None:
        return fn(lambda: False)
    if should_cancel is not None and should_cancel():
        raise RenderCancelled()
    out: dict = {}
    stop = threading.Event()

    def work():
        try:
            out["value"] = fn(stop.is_set)
        except BaseException as e:  # handed to the caller
            out["error"] = e

    worker = threading.Thread(target=work, name="opal-cancellable", daemon=True)
    worker.start()
    while worker.is_alive():
        worker.join(POLL_S)
        if not worker.is_alive():
            break
        if should_cancel is not None and should_cancel():
            stop.set()
            raise RenderCancelled()
        if deadline is not None and time.perf_counter() > deadline and (
                deadline_armed is None or deadline_armed.is_set()):
            stop.set()
            raise OutOfTime()
    if "error" in out:
        raise out["error"]
    return out["value"]


class StoppableAccel:
    """``accel`` (accel.Accelerator) whose ray casts raise RenderCancelled once ``stopped()``
    says so; everything else is ``accel``'s."""

    def __init__(self, accel, stopped: Callable[[], bool]):
        self._accel = accel
        self._stopped = stopped

    def intersect(self, origins, directions, tmax=None):
        check(self._stopped)
        return self._accel.intersect(origins, directions, tmax)

    def occluded(self, origins, directions, tmax):
        check(self._stopped)
        return self._accel.occluded(origins, directions, tmax)

    def __getattr__(self, name):  # name, triangles, ...: the wrapped accelerator's
        return getattr(self._accel, name)
