"""Small geometry toolbox shared by every module: triangle frames and areas, orthonormal bases.

One place for the few vector formulas the tracer needs again and again (pbrt-v4's
``util/vecmath.h`` plays this role there, ``CoordinateSystem`` among them). Everything is
vectorised over leading axes and computed in float64 unless the caller passes float32.
"""

from __future__ import annotations

import numpy as np

__all__ = ["compact_indices", "group_extrema", "triangle_cross", "triangle_areas", "triangle_normals", "normals_from_cross", "orthonormal_basis", "interpolate_corners", "uv_tangents"]


def compact_indices(ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct non-negative integers in ``ids`` (sorted) and ``ids`` renumbered into them:
    ``np.unique(ids, return_inverse=True)`` (same values, ``ids``' shape) in O(n + range) with
    a mark array instead of an O(n log n) sort (vertex ids of triangles: a small range)."""
    ids = np.asarray(ids)
    if ids.size == 0:
        return np.zeros(0, np.int64), np.zeros(ids.shape, np.int64)
    lo, hi = int(ids.min()), int(ids.max())
    shifted = ids - lo if lo else ids
    mark = np.zeros(hi - lo + 1, bool)
    mark[shifted.ravel()] = True
    rank = np.cumsum(mark, dtype=np.int64) - 1  # the new id of each id present
    return np.flatnonzero(mark) + lo, rank[shifted]


def group_extrema(label: np.ndarray, n_groups: int, values: np.ndarray, ops=(np.minimum, np.maximum)) -> list:
    """Per group, ``op``'s reduction of the rows of ``values`` (N, ...) with that ``label`` (N,)
    in [0, n_groups), for each ufunc in ``ops``: ``np.minimum.at`` / ``np.maximum.at`` on arrays
    filled with +inf / -inf, the same values (min and max are exact in any order), by one
    stable sort of the labels (a radix sort for 16-bit ones) and ``reduceat`` over each group's
    run instead of ufunc.at's per-row scatter. Groups without rows get +inf / -inf."""
    label = np.asarray(label)
    values = np.asarray(values)
    counts = np.bincount(label, minlength=n_groups)
    fill = {np.minimum: np.inf, np.maximum: -np.inf}
    if len(label) == 0 or (counts == 0).any():  # empty groups: reduceat cannot express them
        out = []
        for op in ops:
            acc = np.full((n_groups,) + values.shape[1:], fill[op], np.result_type(values, np.float64))
            op.at(acc, label, values)
            out.append(acc)
        return out
    key = label.astype(np.int16) if n_groups <= np.iinfo(np.int16).max else label
    order = np.argsort(key, kind="stable")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    sorted_values = values[order]
    return [op.reduceat(sorted_values, starts, axis=0).astype(np.result_type(values, np.float64), copy=False)
            for op in ops]


_CROSS_ROWS = 1 << 14  # triangles per chunk of triangle_cross: its temporaries stay in cache


def triangle_cross(vertices, triangles, with_norm: bool = False):
    """(T, 3) float64 ``(v1 - v0) x (v2 - v0)`` per triangle: its normal times twice its area.
    ``with_norm``: also their norms (T,), the values of ``np.linalg.norm(cross, axis=1)``."""
    t = np.asarray(triangles).reshape(-1, 3)
    if len(t) == 0:
        return (np.zeros((0, 3)), np.zeros(0)) if with_norm else np.zeros((0, 3))
    if t.dtype.kind not in "iu":
        t = t.astype(np.int64)
    # the vertices in float64 once (V rows, not 3 T), the edges gathered from them in chunks of
    # triangles, and the cross product written out as np.cross computes it (a1 b2 - a2 b1,
    # ...): the same values; the norm as sqrt((x^2 + y^2) + z^2), np.linalg.norm's order
    v = np.asarray(vertices, np.float64)
    out = np.empty((len(t), 3))
    norm = np.empty(len(t)) if with_norm else None
    for s in range(0, len(t), _CROSS_ROWS):
        tc = t[s:s + _CROSS_ROWS]
        p0 = v[tc[:, 0]]
        a = v[tc[:, 1]]
        a -= p0
        b = v[tc[:, 2]]
        b -= p0
        o = out[s:s + _CROSS_ROWS]
        o[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
        o[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
        o[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
        if with_norm:
            sq = np.multiply(o, o, out=a)
            length = sq[:, 0] + sq[:, 1]
            length += sq[:, 2]
            norm[s:s + _CROSS_ROWS] = np.sqrt(length, out=length)
    return (out, norm) if with_norm else out


def triangle_areas(vertices, triangles) -> np.ndarray:
    """(T,) float64 area of each triangle."""
    return 0.5 * np.linalg.norm(triangle_cross(vertices, triangles), axis=1)


def triangle_normals(vertices, triangles) -> np.ndarray:
    """(T, 3) float64 unit geometric normals (right-handed winding); zero for degenerate triangles."""
    return normals_from_cross(triangle_cross(vertices, triangles))


def normals_from_cross(n: np.ndarray, length: np.ndarray | None = None, in_place: bool = False) -> np.ndarray:
    """(T, 3) float64 unit normals from :func:`triangle_cross`'s products; zero where they are.

    ``length``: (T,) their norms when the caller has them (``np.linalg.norm(n, axis=1)``: the
    same values). ``in_place``: divide ``n`` itself (the caller's products are not kept)."""
    if length is None:
        length = np.linalg.norm(n, axis=1)
    d = np.maximum(length, 1e-30)[:, None]
    return np.divide(n, d, out=n) if in_place else n / d


def orthonormal_basis(axis):
    """Unit vectors (u, v) with (u, v, axis) orthonormal, for unit ``axis`` (..., 3).

    u = axis x a / |axis x a| with a = X unless axis is within ~26 degrees of X (then Y), and
    v = axis x u: continuous except where the choice of a switches, which no caller relies on.
    """
    axis = np.asarray(axis)
    a = np.where(np.abs(axis[..., :1]) < 0.9, np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
    u = np.cross(axis, a)
    u /= np.maximum(np.linalg.norm(u, axis=-1, keepdims=True), 1e-30)
    return u, np.cross(axis, u)


def interpolate_corners(corner_values: np.ndarray, prim: np.ndarray, bu: np.ndarray, bv: np.ndarray) -> np.ndarray:
    """Per-corner data (T, 3, k) at hit points: (1 - u - v) c0 + u c1 + v c2 of triangle ``prim``
    with barycentrics (u, v) as the ray caster reports them (hit = (1-u-v) v0 + u v1 + v v2).
    Returns (B, k) in the dtype of ``corner_values`` (shading normals, UVs, tangents)."""
    c = np.take(corner_values, prim, axis=0)  # (B, 3, k); a row gather (np.take) is faster than c[prim]
    dt = c.dtype
    u = np.asarray(bu, dt)[:, None]
    v = np.asarray(bv, dt)[:, None]
    return (1 - u - v) * c[:, 0] + u * c[:, 1] + v * c[:, 2]


def uv_tangents(vertices, triangles, corner_uvs) -> np.ndarray:
    """Per-corner tangent frames (T, 3, 4) of a mesh from its UVs: the direction of increasing U
    in each triangle's plane (dP/du, made orthogonal to the face normal) and the bitangent sign
    (+1 when dP/dv points along normal x tangent). On flat triangles this is what MikkTSpace
    (Blender's ``calc_tangents``) gives per corner; a triangle with degenerate UVs gets the X axis
    projected onto its plane. For scenes built in code; Blender's exporter reads MikkTSpace
    itself."""
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles, np.int64).reshape(-1, 3)
    uv = np.asarray(corner_uvs, np.float64).reshape(-1, 3, 2)
    p = v[t]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    d1, d2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    ok = np.abs(det) > 1e-20
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)[:, None]
    dpdu = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * inv
    dpdv = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * inv
    n = np.cross(e1, e2)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    dpdu = np.where(ok[:, None], dpdu, np.array([1.0, 0.0, 0.0]))
    tan = dpdu - np.sum(dpdu * n, axis=1, keepdims=True) * n
    ln = np.linalg.norm(tan, axis=1, keepdims=True)
    tan = np.where(ln > 1e-30, tan / np.maximum(ln, 1e-300), 0.0)
    sign = np.where(np.sum(np.cross(n, tan) * dpdv, axis=1) < 0, -1.0, 1.0)
    frame = np.concatenate([tan, sign[:, None]], axis=1).astype(np.float32)
    return np.repeat(frame[:, None, :], 3, axis=1)
