"""Embree 4 ray casting through ``embreex``.

Facts about embreex 4.4.0.post1 this wrapper relies on (checked on this version):

- ``EmbreeScene()`` defaults to ``RTC_SCENE_FLAG_ROBUST`` (watertight on shared vertices).
- ``scene.run`` traces one ray at a time with ``rtcIntersect1``/``rtcOccluded1`` inside a
  ``nogil`` block, so Python threads scale (measured ~2x on 2 cores).  The first call
  commits the scene without a lock, so we commit (trace one ray) in the constructor,
  before any thread can call it.
- ``dists`` (per-ray tfar) is *modified in place* when an array is passed: we always pass a
  fresh copy.  Misses keep their input tfar (we map them to ``inf``) and primID/geomID -1.
- ``tnear`` is hard-wired to 0 and Embree accepts ``tnear <= t <= tfar``: a ray starting
  exactly on a triangle reports ``t = 0``.  To honour the interface (``t > 0``) rays whose
  hit is within ``_nudge(o)`` (a few float32 ulps of the origin's coordinates) are re-cast
  from ``o + nudge*d``; ``occluded`` casts every ray from ``o + nudge*d`` (with tmax reduced
  accordingly).  Hits closer than a few ulps of |origin| are therefore ignored by Embree
  (the NumPy backend keeps any ``t > 0``); callers must offset origins anyway.
- OCCLUDED accepts ``t <= tfar``; we pass ``(tmax - nudge) * (1 - 2**-21)`` to get ``t < tmax``.
- Output ``u``/``v`` follow the Embree convention used by the interface; ``Ng`` is ignored.
- The mesh is copied into Embree's own buffers (float32 vertices, uint32 indices); primIDs
  are indices into the triangles array in input order. The copy and the commit go through
  Embree's C API directly when ``embree_direct.available()`` (embreex's copy loop costs
  ~1.5 us per triangle with the GIL held); the buffers and the BVH are the same.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..util.cancel import check
from ..util.geometry import compact_indices
from . import Hits, _as_rays, _as_tmax, _empty_hits, default_threads, embree_direct

_CHUNK = 1 << 16       # rays per embree call
_GEOMETRY_CHUNK = 1 << 18  # triangles per Embree geometry when a mesh is split
_NUDGE = 2.0 ** -21     # relative (to max |origin coordinate|) start offset (~4 float32 ulps)


def _nudge(o):
    """Per-ray start offset: a few float32 ulps of the largest origin coordinate."""
    a = np.abs(o)
    # column-wise maxima: ~3x faster than a reduction over the short last axis
    m = np.maximum(np.maximum(a[:, 0], a[:, 1]), np.maximum(a[:, 2], np.float32(1e-30)))
    return m * np.float32(_NUDGE)


class EmbreeAccelerator:
    name = "embree"

    def __init__(self, vertices, triangles, threads: int | None = None, stopped=None):
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh

        self.n_triangles = len(triangles)
        self.threads = default_threads() if threads is None else max(1, int(threads))
        self._pool = None
        self._scene = None
        # first triangle of each Embree geometry (geomID), to map (geomID, primID) to our index
        self._geom_start = np.zeros(1, np.int64)
        if self.n_triangles:
            direct = embree_direct.available()
            self._scene = embree_direct.new_scene() if direct else rtcs.EmbreeScene()
            v = np.ascontiguousarray(vertices, np.float32)
            t = np.ascontiguousarray(triangles, np.int32)
            add = embree_direct.add_triangles if direct else TriangleMesh
            if len(t) <= _GEOMETRY_CHUNK:
                add(self._scene, v, t)
            else:
                # the mesh goes in as several geometries of one scene (one BVH over all of
                # them), each with its own compacted vertices, so a cancel poll can run between
                # the pieces (embreex's own copy holds the GIL ~1.5 us per triangle)
                starts = np.arange(0, len(t), _GEOMETRY_CHUNK)
                for s in starts:
                    check(stopped)
                    used, local = compact_indices(t[s:s + _GEOMETRY_CHUNK])
                    local = local.astype(np.int32)
                    add(self._scene, v[used], local)
                self._geom_start = starts.astype(np.int64)
            check(stopped)
            if direct:  # Embree builds the BVH with the GIL released
                embree_direct.commit(self._scene)
            else:  # commit now, single-threaded (embreex commits lazily without a lock)
                self._scene.run(np.zeros((1, 3), np.float32), np.array([[0, 0, 1]], np.float32))

    def _prim_index(self, r) -> np.ndarray:
        """Our triangle index of Embree's hits (-1 for misses)."""
        if len(self._geom_start) == 1:
            return r["primID"]
        geom = r["geomID"]
        return np.where(geom >= 0, self._geom_start[np.maximum(geom, 0)] + r["primID"], -1).astype(np.int32)

    # -- threading ------------------------------------------------------------------------
    def _map(self, fn, n):
        """Run fn(slice) over chunks of n rays, on a thread pool when it pays off."""
        slices = [slice(s, min(n, s + _CHUNK)) for s in range(0, n, _CHUNK)]
        if self.threads > 1 and len(slices) > 1:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(self.threads, thread_name_prefix="opal-embree")
            list(self._pool.map(fn, slices))
        else:
            for sl in slices:
                fn(sl)

    def __del__(self):
        pool = getattr(self, "_pool", None)
        if pool is not None:
            pool.shutdown(wait=False)

    # -- queries ----------------------------------------------------------------------------
    def intersect(self, origins, directions, tmax=None) -> Hits:
        o, d = _as_rays(origins, directions)
        n = len(o)
        tm = _as_tmax(tmax, n)
        if self._scene is None or n == 0:
            return _empty_hits(n)
        t = np.empty(n, np.float32)
        prim = np.empty(n, np.int32)
        u = np.empty(n, np.float32)
        v = np.empty(n, np.float32)
        scene = self._scene

        def work(sl):
            r = scene.run(o[sl], d[sl], dists=tm[sl].copy(), query="INTERSECT", output=1)
            t[sl] = r["tfar"]
            prim[sl] = self._prim_index(r)
            u[sl] = r["u"]
            v[sl] = r["v"]

        self._map(work, n)
        # Hits at (or within a few ulps of) the origin: re-cast from slightly further on.
        with np.errstate(all="ignore"):
            nud = _nudge(o)
            close = np.flatnonzero((prim >= 0) & (t <= nud))
        if len(close):
            with np.errstate(all="ignore"):
                oc = o[close] + d[close] * nud[close, None]
            r = scene.run(oc, np.ascontiguousarray(d[close]),
                          dists=(tm[close] - nud[close]).astype(np.float32), query="INTERSECT", output=1)
            t[close] = r["tfar"] + nud[close]
            prim[close] = self._prim_index(r)
            u[close] = r["u"]
            v[close] = r["v"]
        miss = prim < 0
        t[miss] = np.inf
        u[miss] = 0
        v[miss] = 0
        return Hits(t, prim, u, v)

    def occluded(self, origins, directions, tmax) -> np.ndarray:
        o, d = _as_rays(origins, directions)
        n = len(o)
        tm = _as_tmax(tmax, n)
        if self._scene is None or n == 0:
            return np.zeros(n, bool)
        with np.errstate(all="ignore"):     # NaN/inf rays are simply inactive in Embree
            nud = _nudge(o)
            o2 = o + d * nud[:, None]
            # strict t < tmax (embree accepts t <= tfar, and its t may be an ulp or two off
            # depending on the CPU's code path): shrink by a few ulps; tfar < 0: inactive
            tf = ((tm - nud) * np.float32(1.0 - 2.0 ** -21)).astype(np.float32)
        occ = np.empty(n, np.int32)
        scene = self._scene

        def work(sl):
            occ[sl] = scene.run(o2[sl], d[sl], dists=tf[sl].copy(), query="OCCLUDED")

        self._map(work, n)
        return occ >= 0
