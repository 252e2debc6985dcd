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
  if set, else the platform's user cache, ``.../opal_diffraction/numba-<options digest>``):
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

__all__ = ["AVAILABLE", "UNAVAILABLE_REASON", "KERNEL_MODES", "KERNELS_ENV", "cache_dir", "njit", "kernel_mode",
           "kernels_enabled", "kernels_path"]

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


def cache_dir() -> str:
    """The writable folder the compiled kernels are cached in (created if missing): NUMBA_CACHE_DIR
    when set, else ``<user cache>/opal_diffraction/numba-<options>``, else one in the temporary
    folder. ``<options>`` is a digest of _OPTIONS: numba's cache notices a changed kernel source
    file, not changed compile options, so other options get another folder."""
    tag = "numba-" + hashlib.sha1(repr(sorted(_OPTIONS.items())).encode()).hexdigest()[:8]
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
#: numba imported: the compiled kernels can run.
AVAILABLE = _numba is not None


def njit(fn=None, **options):
    """``numba.njit(nogil=True, cache=True, error_model='numpy', **options)`` of ``fn`` (as ``@njit``
    or ``@njit(...)``); without numba the function itself (never called on the render path then:
    kernels_enabled() is False)."""
    def wrap(f):
        if _numba is None:
            return f
        return _numba.njit(**dict(_OPTIONS, **options))(f)

    return wrap(fn) if fn is not None else wrap


_lock = threading.Lock()
_numpy_holds = 0  # renders now running that force the NumPy reference


def _env_forces_numpy() -> bool:
    return os.environ.get(KERNELS_ENV, "").strip().lower() == "numpy"


def kernels_path(mode: str = "auto") -> str:
    """The path a render with RenderSettings.kernels = ``mode`` takes: 'numba' (the compiled
    kernels) or 'numpy' (the reference: asked for, OPAL_KERNELS=numpy, or numba unavailable).
    Anything but 'auto' takes the reference (RenderSettings.validate rejects unknown modes)."""
    return "numba" if AVAILABLE and mode == "auto" and not _env_forces_numpy() else "numpy"


@contextlib.contextmanager
def kernel_mode(mode: str = "auto"):
    """Hold RenderSettings.kernels = ``mode`` for the block (one render); yields kernels_path(mode).
    Blocks nest and overlap across threads: while one of them forces 'numpy', the reference runs."""
    global _numpy_holds
    path = kernels_path(mode)
    forced = mode != "auto"
    if forced:
        with _lock:
            _numpy_holds += 1
    try:
        yield path
    finally:
        if forced:
            with _lock:
                _numpy_holds -= 1


def kernels_enabled() -> bool:
    """Whether the compiled kernels run now (numba available, OPAL_KERNELS is not 'numpy' and no
    running render forces the reference). The functions with kernels call this to choose."""
    return AVAILABLE and _numpy_holds == 0 and not _env_forces_numpy()
