"""Brute-force O(rays x triangles) ray caster: the test oracle.

Every ray is tested against every triangle in float64 with Embree's robust edge-function
("Pluecker") formulation: independent of the NumPy BVH's float32 Woop-style test, and far
more precise than either real backend.  Work is chunked so memory stays bounded (about
``_PAIR_BUDGET`` ray-triangle pairs at a time), but the cost is still rays x triangles:
use it for tests and small scenes only.
"""
from __future__ import annotations

import numpy as np

_PAIR_BUDGET = 1 << 16  # ray-triangle pairs per chunk (float64 temporaries stay in cache)
_EPS64 = float(np.finfo(np.float64).eps)


def pair_hits(origins, directions, v0, v1, v2):
    """All ray-triangle pairs at once (no chunking; callers keep sizes small).

    origins, directions: (N,3); v0, v1, v2: (T,3).  Returns float64 arrays of shape (N,T):

    - ``t``: distance along the ray to the triangle's plane (nan/inf for parallel rays),
    - ``margin``: the smallest normalised barycentric coordinate of the plane hit point
      (>= 0 inside the triangle, < 0 outside; nan for parallel rays or degenerate triangles),
    - ``u``, ``v``: Embree-convention barycentrics (weights of v1 and v2).
    """
    o = np.asarray(origins, np.float64)[:, None, :]
    d = np.asarray(directions, np.float64)[:, None, :]
    a = np.asarray(v0, np.float64)[None, :, :] - o
    b = np.asarray(v1, np.float64)[None, :, :] - o
    c = np.asarray(v2, np.float64)[None, :, :] - o
    with np.errstate(all="ignore"):
        e0, e1, e2 = c - a, a - b, b - c
        U = np.einsum("ntk,ntk->nt", np.cross(e0, c + a), d)
        V = np.einsum("ntk,ntk->nt", np.cross(e1, a + b), d)
        W = np.einsum("ntk,ntk->nt", np.cross(e2, b + c), d)
        uvw = U + V + W
        ng = np.cross(np.asarray(v1, np.float64) - np.asarray(v0, np.float64),
                      np.asarray(v2, np.float64) - np.asarray(v0, np.float64))[None]
        den = np.einsum("ntk,ntk->nt", np.broadcast_to(ng, a.shape), d)
        t = np.einsum("ntk,ntk->nt", a, np.broadcast_to(ng, a.shape)) / den
        u = U / uvw
        v = V / uvw
        margin = np.minimum(np.minimum(u, v), W / uvw)
    return t, margin, u, v


class BruteForceAccelerator:
    """Reference implementation of the Accelerator interface (float64, chunked)."""

    name = "brute"

    def __init__(self, vertices, triangles):
        vertices = np.asarray(vertices, np.float64)
        triangles = np.asarray(triangles, np.int64)
        self.n_triangles = len(triangles)
        tri = vertices[triangles] if len(triangles) else np.zeros((0, 3, 3))
        self._v0 = np.ascontiguousarray(tri[:, 0])
        self._v1 = np.ascontiguousarray(tri[:, 1])
        self._v2 = np.ascontiguousarray(tri[:, 2])
        ng = np.cross(self._v1 - self._v0, self._v2 - self._v0)
        for name, arr in (("_v0", self._v0), ("_v1", self._v1), ("_v2", self._v2), ("_ng", ng)):
            for k, ax in enumerate("xyz"):
                setattr(self, name + ax, np.ascontiguousarray(arr[:, k]))

    # -- core kernel -------------------------------------------------------------------
    def _test(self, o, d, t_lo, t_hi):
        """Closest hit with t_lo < t <= t_hi for a chunk of rays against all triangles."""
        n = len(o)
        best_t = np.full(n, np.inf)
        best_p = np.full(n, -1, np.int64)
        best_u = np.zeros(n)
        best_v = np.zeros(n)
        T = self.n_triangles
        step = max(1, _PAIR_BUDGET // max(n, 1))
        rows = np.arange(n)
        ox, oy, oz = (o[:, k:k + 1] for k in range(3))
        dx, dy, dz = (d[:, k:k + 1] for k in range(3))
        lo = t_lo[:, None]
        hi = t_hi[:, None]
        for s in range(0, T, step):
            sl = slice(s, min(T, s + step))
            ax, ay, az = self._v0x[sl] - ox, self._v0y[sl] - oy, self._v0z[sl] - oz
            bx, by, bz = self._v1x[sl] - ox, self._v1y[sl] - oy, self._v1z[sl] - oz
            cx, cy, cz = self._v2x[sl] - ox, self._v2y[sl] - oy, self._v2z[sl] - oz
            U = _triple_c(cx - ax, cy - ay, cz - az, cx + ax, cy + ay, cz + az, dx, dy, dz)
            V = _triple_c(ax - bx, ay - by, az - bz, ax + bx, ay + by, az + bz, dx, dy, dz)
            W = _triple_c(bx - cx, by - cy, bz - cz, bx + cx, by + cy, bz + cz, dx, dy, dz)
            uvw = U + V + W
            eps = _EPS64 * np.abs(uvw)
            inside = (np.minimum(np.minimum(U, V), W) >= -eps) | (np.maximum(np.maximum(U, V), W) <= eps)
            nx, ny, nz = self._ngx[sl], self._ngy[sl], self._ngz[sl]
            den = nx * dx + ny * dy + nz * dz
            t = (ax * nx + ay * ny + az * nz) / den
            ok = inside & (den != 0) & (t > lo) & (t <= hi)
            t = np.where(ok, t, np.inf)
            j = np.argmin(t, axis=1)
            tj = t[rows, j]
            better = tj < best_t
            if better.any():
                r = rows[better]
                jj = j[better]
                best_t[r] = tj[better]
                best_p[r] = jj + s
                best_u[r] = U[r, jj] / uvw[r, jj]
                best_v[r] = V[r, jj] / uvw[r, jj]
        return best_t, best_p, best_u, best_v

    def _run(self, origins, directions, tmax, strict):
        from . import Hits, _as_rays, _as_tmax

        o, d = _as_rays(origins, directions)
        n = len(o)
        tm = _as_tmax(tmax, n).astype(np.float64)
        if strict:  # occluded(): 0 < t < tmax
            tm = np.nextafter(tm, -np.inf)
        out_t = np.full(n, np.inf)
        out_p = np.full(n, -1, np.int64)
        out_u = np.zeros(n)
        out_v = np.zeros(n)
        if self.n_triangles and n:
            o64 = o.astype(np.float64)
            d64 = d.astype(np.float64)
            chunk = max(1, min(n, _PAIR_BUDGET // max(1, min(self.n_triangles, _PAIR_BUDGET))))
            with np.errstate(all="ignore"):
                for s in range(0, n, chunk):
                    sl = slice(s, min(n, s + chunk))
                    res = self._test(o64[sl], d64[sl], np.zeros(sl.stop - sl.start), tm[sl])
                    out_t[sl], out_p[sl], out_u[sl], out_v[sl] = res
        miss = out_p < 0
        out_u[miss] = 0
        out_v[miss] = 0
        return Hits(out_t.astype(np.float32), out_p.astype(np.int32),
                    out_u.astype(np.float32), out_v.astype(np.float32))

    def intersect(self, origins, directions, tmax=None):
        return self._run(origins, directions, tmax, strict=False)

    def occluded(self, origins, directions, tmax):
        return self._run(origins, directions, tmax, strict=True).prim >= 0


def _triple_c(ex, ey, ez, sx, sy, sz, dx, dy, dz):
    """d . (e x s), component arrays."""
    return dx * (ey * sz - ez * sy) + dy * (ez * sx - ex * sz) + dz * (ex * sy - ey * sx)

