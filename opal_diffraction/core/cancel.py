"""Cancellation: the exception a cancelled stage raises, and a runner that keeps a long
NumPy-heavy stage responsive to cancel.

``run_cancellable(fn, should_cancel)`` runs ``fn`` in a worker thread and polls
``should_cancel`` from the calling thread every POLL_S seconds, so a cancel is honoured within
about POLL_S of the request even while ``fn`` is inside one long vectorised call (NumPy releases
the GIL in its loops). A cancelled worker runs to completion in the background and its result is
dropped. Code that holds the GIL for long (a C extension's loop) delays the poll by as long; the
Embree backend therefore builds its geometry in chunks.
"""

from __future__ import annotations

import threading
from typing import Callable, TypeVar

__all__ = ["RenderCancelled", "run_cancellable", "POLL_S"]

T = TypeVar("T")
POLL_S = 0.05


class RenderCancelled(Exception):
    """The user cancelled (Esc in Blender, Ctrl-C, a should_cancel callback returning True)."""


def run_cancellable(fn: Callable[[], T], should_cancel: Callable[[], bool] | None) -> T:
    """``fn()``, or RenderCancelled as soon as ``should_cancel()`` returns True."""
    if should_cancel is None:
        return fn()
    if should_cancel():
        raise RenderCancelled()
    out: dict = {}

    def work():
        try:
            out["value"] = fn()
        except BaseException as e:  # handed to the caller
            out["error"] = e

    worker = threading.Thread(target=work, name="opal-cancellable", daemon=True)
    worker.start()
    while worker.is_alive():
        worker.join(POLL_S)
        if worker.is_alive() and should_cancel():
            raise RenderCancelled()
    if "error" in out:
        raise out["error"]
    return out["value"]
