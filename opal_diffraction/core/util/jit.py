"""The JIT for the core's compiled kernels (numba), and the switch between them and the NumPy reference.

What: a hot NumPy function of the core (an RGB -> spectrum uplift, a Fresnel term, an environment
lookup) keeps its NumPy lines as the *reference* and gets a compiled twin, a *kernel*, beside it in
the room of its concept. The function itself chooses (``if kernels_enabled(): return kernel(...)``),
so its callers do not change. A kernel loops over rows in one pass instead of NumPy's chain of
temporaries, and runs without the GIL (``nogil``), so render threads run it side by side.

How:
- ``njit`` is ``numba.njit(nogil=True, cache=True, error_model='numpy')`` (NumPy's x / 0 = inf or
  NaN instead of numba's ZeroDivisionError); without numba (not installed, or it fails to import,
  e.g. a NumPy it does not support) it returns the Python function unchanged, and
  ``kernels_enabled()`` is False, so only the reference ever runs (``AVAILABLE``,
  ``UNAVAILABLE_REASON``).
- Compiled kernels are cached on disk in a user cache folder (``cache_dir()``: ``$NUMBA_CACHE_DIR``
  if set, else the platform's user cache, ``.../opal_diffraction/numba-<digest of options and sources>``):
  numba's default, a ``__pycache__`` beside the source, is read-only inside an installed Blender
  extension. NUMBA_CACHE_DIR is read when numba is imported, so it is set here before the import
  (and on numba's config when another add-on imported numba first). The first render after an
  install compiles each kernel once (about a second each); later processes load them from the cache.
- The choice: ``RenderSettings.kernels`` ('auto': the kernels when numba is available; 'numpy': the
  reference) or the environment variable OPAL_KERNELS=numpy (which wins, for whole processes
  such as Dask workers). A render holds its choice with ``kernel_mode(mode)`` for its duration. The
  choice is process-wide, since the render's worker threads (tiles, light-pass lanes) must see it:
  while any render that forces 'numpy' runs, every render in the process uses the reference
  (the reference is never wrong, only slower). ``kernels_path(mode)`` names the path a render
  takes, for its stats line.

The compile stage: numba compiles a kernel when it is first called (about a second each, a few
seconds for all; loading one from the cache takes milliseconds). ``warm_up(run, progress)`` calls
``run`` - core/render/frame.py's render of a built-in tiny scene that takes the kernels' paths -
once per process, before its first render on the kernels, and tells ``progress`` first (the
stage "compiling kernels"), so the first render after an install shows that stage instead of
a render stuck at 0 %; renders that take the reference (kernels 'numpy', OPAL_KERNELS=numpy, no
numba) skip it. ``compile_counts()`` says how many kernels were compiled and how many loaded
from the cache (over every kernel ``njit`` made, ``kernels()``).

Kernels use no ``fastmath``: without it LLVM neither reorders nor contracts (no FMA) floating-point
operations, so a kernel doing the reference's operations in the reference's order and precision
is bit-identical to it; each kernel's test (tests/util/test_kernels.py) says which ones are.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import sys
import tempfile
import threading
import time

__all__ = ["AVAILABLE", "UNAVAILABLE_REASON", "KERNEL_MODES", "KERNELS_ENV", "COMPILE_STAGE", "cache_dir", "njit",
           "kernel_mode", "kernels_enabled", "kernels_path", "kernels", "compile_counts", "warm_up", "warm_up_done"]

#: RenderSettings.kernels: 'auto' (the compiled kernels where numba is available) or 'numpy' (the reference).
KERNEL_MODES = ("auto", "numpy")
#: An environment variable that forces the NumPy reference for the whole process when set to 'numpy'.
KERNELS_ENV = "OPAL_KERNELS"


#: numba.njit's options for every kernel: no GIL, cached on disk, and NumPy's floating-point
#: error model (x / 0 is inf or NaN as in the NumPy reference; numba's default raises ZeroDivisionError).
_OPTIONS = {"nogil": True, "cache": True, "error_model": "numpy"}


def _user_cache_root() -> str:
    """The platform's per-user cache folder (XDG on Linux, Library/Caches on macOS, LOCALAPPDATA on Windows)."""
    if sys.platform == "win32":
        return os.environ.get("LOCALAPPDATA") or os.path.join(os.path.expanduser("~"), "AppData", "Local")
    if sys.platform == "darwin":
        return os.path.join(os.path.expanduser("~"), "Library", "Caches")
    return os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")


def _sources_digest() -> str:
    """A digest of the compile options and of every source file of the core. numba's cache notices
    a changed kernel's own file, but neither changed compile options nor a changed kernel in
    another file that a cached kernel calls (it would load the stale machine code): a folder per
    state of the sources makes every change compile afresh."""
    h = hashlib.sha1(repr(sorted(_OPTIONS.items())).encode())
    core = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    for folder, dirs, files in sorted(os.walk(core)):
        dirs.sort()
        for name in sorted(files):
            if name.endswith(".py"):
                try:
                    with open(os.path.join(folder, name), "rb") as f:
                        h.update(name.encode() + f.read())
                except OSError:
                    continue
    return h.hexdigest()[:12]


def cache_dir() -> str:
    """The writable folder the compiled kernels are cached in (created if missing): NUMBA_CACHE_DIR
    when set, else ``<user cache>/opal_diffraction/numba-<digest>``, else one in the temporary
    folder. ``<digest>``: of the compile options and the core's sources (``_sources_digest``), so
    an update of the extension or an edit never loads another version's kernels."""
    tag = "numba-" + _sources_digest()
    for folder in (os.environ.get("NUMBA_CACHE_DIR"), os.path.join(_user_cache_root(), "opal_diffraction", tag),
                   os.path.join(tempfile.gettempdir(), "opal_diffraction-" + tag)):
        if not folder:
            continue
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError:
            continue
        if os.access(folder, os.W_OK):
            return folder
    return ""  # nowhere writable: numba compiles every process (and warns once)


def _import_numba():
    """(numba module or None, why not). Sets the cache folder before numba reads it."""
    folder = cache_dir()
    if folder and not os.environ.get("NUMBA_CACHE_DIR"):
        os.environ["NUMBA_CACHE_DIR"] = folder
    try:
        import numba
    except Exception as e:  # ImportError, or numba refusing this NumPy (it raises ImportError too)
        return None, f"numba cannot be imported ({type(e).__name__}: {e})"
    if folder and not numba.config.CACHE_DIR:  # numba was imported before us (another add-on)
        numba.config.CACHE_DIR = folder
    return numba, ""


_numba, UNAVAILABLE_REASON = _import_numba()
_kernels: list = []  # every dispatcher njit made, in the order the modules defining them were imported
#: numba imported: the compiled kernels can run.
AVAILABLE = _numba is not None


def njit(fn=None, **options):
    """``numba.njit(nogil=True, cache=True, error_model='numpy', **options)`` of ``fn`` (as ``@njit``
    or ``@njit(...)``); without numba the function itself (never called on the render path then:
    kernels_enabled() is False)."""
    def wrap(f):
        if _numba is None:
            return f
        dispatcher = _numba.njit(**dict(_OPTIONS, **options))(f)
        _kernels.append(dispatcher)
        return dispatcher

    return wrap(fn) if fn is not None else wrap


_lock = threading.Lock()
_numpy_holds = 0  # renders now running that force the NumPy reference


def _env_forces_numpy() -> bool:
    return os.environ.get(KERNELS_ENV, "").strip().lower() == "numpy"


def kernels_path(mode: str = "auto") -> str:
    """The path a render with RenderSettings.kernels = ``mode`` takes: 'numba' (the compiled
    kernels) or 'numpy' (the reference: asked for, OPAL_KERNELS=numpy, or numba unavailable).
    Anything but 'auto' takes the reference (RenderSettings.validate rejects unknown modes)."""
    return "numba" if AVAILABLE and isinstance(mode, str) and mode == "auto" and not _env_forces_numpy() else "numpy"


@contextlib.contextmanager
def kernel_mode(mode: str = "auto"):
    """Hold RenderSettings.kernels = ``mode`` for the block (one render); yields kernels_path(mode).
    Blocks nest and overlap across threads: while one of them forces 'numpy', the reference runs.
    OPAL_KERNELS is read when a block starts: one that starts with it set to 'numpy' forces the
    reference like mode 'numpy', and while blocks are open kernels_enabled() does not read it
    again (it is called thousands of times per render)."""
    global _numpy_holds, _open_blocks
    path = kernels_path(mode)
    forced = path == "numpy"  # asked for, OPAL_KERNELS=numpy now, or no numba
    with _lock:
        _open_blocks += 1
        if forced:
            _numpy_holds += 1
    try:
        yield path
    finally:
        with _lock:
            _open_blocks -= 1
            if forced:
                _numpy_holds -= 1


_open_blocks = 0  # kernel_mode blocks now open (renders running)


def kernels_enabled() -> bool:
    """Whether the compiled kernels run now (numba available, OPAL_KERNELS is not 'numpy' and no
    running render forces the reference). The functions with kernels call this to choose.
    Outside any render (kernel_mode block) OPAL_KERNELS is read on every call; inside, the
    blocks' holds say it (read when each began)."""
    return AVAILABLE and _numpy_holds == 0 and (_open_blocks > 0 or not _env_forces_numpy())


def kernels() -> list:
    """Every kernel ``njit`` compiled-or-will-compile in this process (numba dispatchers; empty without numba)."""
    return list(_kernels)


def compile_counts() -> tuple[int, int]:
    """(compiled, loaded): how many kernel signatures this process compiled and how many it
    loaded from the on-disk cache so far (numba's per-dispatcher cache statistics)."""
    compiled = loaded = 0
    for d in _kernels:
        stats = getattr(d, "stats", None)
        if stats is not None:
            compiled += len(stats.cache_misses)
            loaded += len(stats.cache_hits)
    return compiled, loaded


#: The message of the compile stage, as the render's progress callback receives it.
COMPILE_STAGE = "compiling kernels"
_warm_lock = threading.RLock()  # re-entrant: the warm-up's own render calls warm_up again (a no-op)
_warm = {"started": False, "finished": False, "runner": None}  # runner: the warm-up's worker thread
#: Further warm-ups a render runs only when its scene needs them (``warm_up(stage=...)``), by name.
_stages: dict[str, dict] = {}


def warm_up_done() -> bool:
    """Whether this process has run its warm-up."""
    return _warm["finished"]


def warm_up(run, progress=None, mode: str = "auto", should_cancel=None, stage: str | None = None) -> dict | None:
    """Run ``run()`` once per process, before the first render that takes the kernels (``mode``:
    its RenderSettings.kernels), so the kernels it calls are compiled (or loaded from the cache)
    now; ``progress(0.0, COMPILE_STAGE)`` is called first. Other threads wait for it to finish
    (a render starting meanwhile then finds its kernels ready).

    ``should_cancel()``: the render's cancel check. With one, ``run(stopped)`` runs in a worker
    thread (util/cancel.run_cancellable) while this thread polls the check, so a cancel is
    honoured within cancel.POLL_S even while numba compiles a kernel: RenderCancelled is raised
    here, ``stopped()`` turns True and the warm-up render stops at its next check (the kernel
    being compiled finishes first: numba cannot be interrupted); the stage is not marked done,
    so the next render on the kernels runs it again.

    Returns None when nothing ran (the render takes the reference, or the warm-up already ran),
    else {'compile_s': seconds, 'kernels_compiled': n, 'kernels_loaded': n} (for the render's
    stats; with 'compile_error' when ``run`` raised: the render then goes on, and meets the same
    error itself if it is the kernels').

    ``stage``: a further warm-up of this name, once per process likewise, for kernels only some
    scenes take (core/render/frame.py's rough surfaces); None: the process's first one."""
    _warm = globals()["_warm"] if stage is None else _stages.setdefault(
        stage, {"started": False, "finished": False, "runner": None})
    if _warm["finished"] or kernels_path(mode) != "numba" or not kernels_enabled():
        return None
    if _warm.get("runner") == threading.get_ident():  # the warm-up render's own call (in its worker thread)
        return None
    with _warm_lock:  # another thread's warm-up: wait for it
        if _warm["started"]:  # finished meanwhile, or this thread's own warm-up render
            return None
        _warm["started"] = True
        if progress is not None:
            progress(0.0, COMPILE_STAGE)
        c0, l0 = compile_counts()
        t0 = time.perf_counter()
        out = {}
        done = True
        try:
            if should_cancel is None:
                run()
            else:
                from .cancel import run_cancellable

                def in_worker(stopped):
                    _warm["runner"] = threading.get_ident()
                    try:
                        return run(stopped)
                    finally:
                        _warm["runner"] = None

                run_cancellable(in_worker, should_cancel)
        except BaseException as e:
            from .cancel import RenderCancelled

            if isinstance(e, RenderCancelled):  # cancelled during the stage: the next render runs it
                done = _warm["started"] = False
                raise
            if not isinstance(e, Exception):
                raise
            out["compile_error"] = f"{type(e).__name__}: {e}"  # never the warm-up's fault that the render fails
        finally:
            if done:
                _warm["finished"] = True
        c1, l1 = compile_counts()
        out.update(compile_s=time.perf_counter() - t0, kernels_compiled=c1 - c0, kernels_loaded=l1 - l0)
        return out
