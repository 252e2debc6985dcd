"""One BLAS thread while a render's passes run: the renderer's own threads are its parallelism.

Why: NumPy's OpenBLAS runs every matrix product of more than a few thousand rows on all cores
(the eye pass has many: (B, 3) @ (3,) frames, (B, k) @ (k, n) spectra, (P, n) @ (n, 3) films),
and its worker threads then busy-wait for the next call. Between those calls the passes run
element-wise NumPy in one thread, so the spinning threads burn a second core for nothing:
measured on the Cycles parity scenes (64 x 64, 64 samples, one render thread), the rough metal
sphere took 2.03 CPU s for 1.03 wall s with OpenBLAS's default threads and 0.97 CPU s for
0.96 wall s with one (docs/benchmarks.md, "Cycles parity on an idle machine"). With the
render's tile threads each doing its own products, nothing is lost.

How: ``threadpoolctl.threadpool_limits(1, user_api="blas")`` (the library that finds the BLAS
NumPy is linked to, OpenBLAS, MKL or BLIS, and sets its thread count through its own API; it
restores the previous count on exit). It is a pure-Python dependency bundled with the extension;
without it the limit is skipped (a render is only slower on CPU time, never wrong).

A trap, measured with NumPy 1.26's OpenBLAS 0.3.23: once the main thread has set a thread count,
a count set from another thread is ignored (the main thread's stays). Blender's F12 render job
and the viewport's worker set it from their own threads; if a script has set a count in the
main thread first, that count stays (slower on CPU time only). tests/util/test_blas_threads.py
checks the limit in the thread that renders.
"""

from __future__ import annotations

import contextlib
import threading

__all__ = ["one_blas_thread"]

_lock = threading.Lock()
_depth = 0        # renders inside the limit now (the viewport's and F12's can overlap)
_limiter = None   # the threadpoolctl limiter of the first of them, restored by the last


@contextlib.contextmanager
def one_blas_thread():
    """Run the block with BLAS limited to one thread. Overlapping blocks (in any threads) share
    one limit: the first sets it, the last restores BLAS's previous thread count."""
    global _depth, _limiter
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # not installed: BLAS keeps its threads
        yield
        return
    with _lock:
        if _depth == 0:
            _limiter = threadpool_limits(limits=1, user_api="blas")
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                _limiter.restore_original_limits()
                _limiter = None
