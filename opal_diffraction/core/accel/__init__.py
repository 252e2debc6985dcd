"""Ray casting against a static triangle mesh, behind one small interface.

Backends (all return identical ``Hits`` layouts):

- ``"embree"``: Intel Embree 4 through ``embreex`` (robust/watertight mode), batches split
  across threads (embreex releases the GIL while tracing).
- ``"numpy"``: a pure-NumPy wide BVH (binned-SAH build, vectorised stack traversal,
  watertight float32 triangle test).  Always available.
- ``"brute"``: brute-force float64 oracle, O(rays x triangles); for tests only.

Conventions (all backends):

- ``origins``, ``directions``: (N,3), float32 (float64 accepted and converted); directions
  should be unit length (``t`` is then a distance).
- ``intersect`` returns the closest hit with ``0 < t <= tmax``; misses have ``t = inf``,
  ``prim = -1`` and ``u = v = 0``.  Barycentrics follow Embree: the hit point is
  ``(1-u-v)*v0 + u*v1 + v*v2`` of the triangle ``triangles[prim]``.
- ``occluded`` returns whether any hit with ``0 < t < tmax`` exists.
- No origin offsetting is done here: callers move origins off surfaces themselves.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Protocol

import numpy as np

__all__ = ["Hits", "Accelerator", "build_accelerator", "available_backends"]


@dataclass
class Hits:
    t: np.ndarray     # (N,) float32 distance along the direction; inf for a miss
    prim: np.ndarray  # (N,) int32 triangle index into the builder's triangles; -1 for a miss
    u: np.ndarray     # (N,) float32 barycentric weight of v1
    v: np.ndarray     # (N,) float32 barycentric weight of v2

    def __len__(self) -> int:
        return len(self.t)

    @property
    def hit(self) -> np.ndarray:
        return self.prim >= 0


class Accelerator(Protocol):
    name: str

    def intersect(self, origins, directions, tmax=None) -> Hits: ...

    def occluded(self, origins, directions, tmax) -> np.ndarray: ...


def default_threads() -> int:
    """Threads a backend uses by default: OPAL_ACCEL_THREADS, else the CPUs this process may use."""
    env = os.environ.get("OPAL_ACCEL_THREADS", "").strip()
    if env:
        return max(1, int(env))
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - non-Linux
        return max(1, os.cpu_count() or 1)


def _embree_importable() -> bool:
    try:
        import embreex.rtcore_scene  # noqa: F401
        import embreex.mesh_construction  # noqa: F401
    except Exception:  # ImportError, or a broken shared library
        return False
    return True


def available_backends() -> list[str]:
    """Backends usable on this machine, fastest first ("brute" is always last)."""
    out = ["embree"] if _embree_importable() else []
    return out + ["numpy", "brute"]


def _check_mesh(vertices, triangles):
    v = np.asarray(vertices)
    t = np.asarray(triangles)
    if v.ndim != 2 or v.shape[1] != 3:
        if not (v.size == 0 and t.size == 0):
            raise ValueError(f"vertices must have shape (V, 3), got {v.shape}")
    if t.size == 0:
        return np.asarray(v, np.float32).reshape(-1, 3), np.zeros((0, 3), np.int32)
    if t.ndim != 2 or t.shape[1] != 3:
        raise ValueError(f"triangles must have shape (T, 3), got {t.shape}")
    if not np.issubdtype(t.dtype, np.integer):
        if not np.all(np.equal(np.mod(t, 1), 0)):
            raise ValueError("triangles must hold integer vertex indices")
        t = t.astype(np.int64)
    lo, hi = int(t.min()), int(t.max())  # in the given integer type: no int64 copy of the mesh
    if lo < 0 or hi >= len(v):
        raise ValueError(f"triangle vertex indices must lie in [0, {len(v)}); got [{lo}, {hi}]")
    v = np.asarray(v, np.float32)
    if not np.isfinite(np.min(v)) or not np.isfinite(np.max(v)):  # a NaN or inf propagates
        raise ValueError("vertices must be finite")
    if len(t) >= 2**31 - 1:
        raise ValueError("too many triangles")
    return v, t.astype(np.int32, copy=False)


def build_accelerator(vertices, triangles, backend: str = "auto", threads: int | None = None, stopped=None):
    """Build a ray caster for the mesh ``vertices`` (V,3) / ``triangles`` (T,3).

    ``backend``: "auto" (embree if embreex imports, else numpy; the environment variable
    ``OPAL_ACCEL=embree|numpy|brute`` overrides "auto"), "embree", "numpy" or "brute".
    ``threads``: how many threads one call may split its rays over (default: default_threads();
    1 when the caller already runs calls in parallel). ``stopped()``: polled between the pieces
    of a long build (Embree); True raises cancel.RenderCancelled.
    """
    if not isinstance(backend, str):
        raise ValueError(f"backend must be a string, got {backend!r}")
    b = backend.strip().lower()
    if b == "auto":
        env = os.environ.get("OPAL_ACCEL", "").strip().lower()
        if env and env != "auto":
            if env not in ("embree", "numpy", "brute"):
                raise ValueError(f"OPAL_ACCEL={env!r}: expected 'embree', 'numpy' or 'brute'")
            b = env
        else:
            b = "embree" if _embree_importable() else "numpy"
    if b not in ("embree", "numpy", "brute"):
        raise ValueError(f"unknown ray-casting backend {backend!r}: expected 'auto', 'embree', 'numpy' or 'brute'")
    v, t = _check_mesh(vertices, triangles)
    if b == "embree":
        if not _embree_importable():
            raise ValueError("backend 'embree' requested but embreex cannot be imported (pip install embreex)")
        from .embree_backend import EmbreeAccelerator
        return EmbreeAccelerator(v, t, threads=threads, stopped=stopped)
    if b == "numpy":
        from .numpy_bvh import NumpyBVH
        return NumpyBVH(v, t, threads=threads)
    from .brute_force import BruteForceAccelerator
    return BruteForceAccelerator(v, t)


# -- shared argument handling --------------------------------------------------------------
def _as_rays(origins, directions):
    o = np.ascontiguousarray(origins, dtype=np.float32)
    d = np.ascontiguousarray(directions, dtype=np.float32)
    if o.ndim == 1 and o.shape == (3,):
        o = o.reshape(1, 3)
    if d.ndim == 1 and d.shape == (3,):
        d = d.reshape(1, 3)
    if o.ndim != 2 or o.shape[1] != 3:
        raise ValueError(f"origins must have shape (N, 3), got {o.shape}")
    if d.shape != o.shape:
        raise ValueError(f"directions must have the same shape as origins {o.shape}, got {d.shape}")
    return o, d


def _as_tmax(tmax, n):
    """tmax (None, scalar or (N,)) -> (N,) float32 array, inf for None."""
    if tmax is None:
        return np.full(n, np.inf, np.float32)
    tm = np.asarray(tmax, dtype=np.float32)
    if tm.ndim == 0:
        return np.full(n, tm, np.float32)
    if tm.shape != (n,):
        raise ValueError(f"tmax must be None, a scalar or shape ({n},), got {tm.shape}")
    return np.ascontiguousarray(tm)


def _empty_hits(n):
    return Hits(np.full(n, np.inf, np.float32), np.full(n, -1, np.int32),
                np.zeros(n, np.float32), np.zeros(n, np.float32))
