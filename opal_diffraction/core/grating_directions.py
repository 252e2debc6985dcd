"""Smooth grating directions: the grating vector t-hat interpolated across triangles.

The exporter gives one grating direction per triangle (the UV map's U direction, the object's X
axis or the opal tools' face attribute; ``gratings.triangle_tangents`` projects it onto the
triangle). On a faceted model of a smooth surface - a CD of 256 segments, whose circular tracks
make t-hat radial - that direction jumps by the facet angle (1.4 degrees) at every edge, far
more than the angular width lambda / L of a long track's streak, so the streak follows the
facets. Here, as vertex normals are made from face normals (Phong shading; corner-angle weights
as Thuermer & Wuethrich 1998), each corner gets the corner-angle-weighted mean of the tangents of
the grating triangles around its vertex, and a hit interpolates its triangle's three corner
tangents with the barycentrics and projects the result onto the surface (docs/physics.md
section 3.1).

- A grating is the same for t and -t (P is even in u and in v), so neighbours are sign-aligned
  with the corner's own triangle before averaging.
- Creases keep their jump: a neighbour counts only with the same material, its tangent within
  ``MAX_TANGENT_ANGLE`` and its normal within ``MAX_NORMAL_ANGLE`` of the corner's own (opal
  domains with their own random directions stay distinct).
- The result is continuous across every edge whose two triangles count each other.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MAX_TANGENT_ANGLE", "MAX_NORMAL_ANGLE", "smooth_corner_tangents", "tangents_at"]

#: Neighbouring tangents further apart than this (degrees) are a crease, not smoothed.
MAX_TANGENT_ANGLE = 20.0
#: Neighbouring normals further apart than this (degrees) are a crease, not smoothed.
MAX_NORMAL_ANGLE = 30.0


def _corner_angles(v: np.ndarray, tris: np.ndarray) -> np.ndarray:
    p = v[tris]  # (T, 3, 3)
    out = np.empty(tris.shape, np.float64)
    for c in range(3):  # the three corners
        a = p[:, (c + 1) % 3] - p[:, c]
        b = p[:, (c + 2) % 3] - p[:, c]
        cos = np.einsum("ij,ij->i", a, b) / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300)
        out[:, c] = np.arccos(np.clip(cos, -1, 1))
    return out


def smooth_corner_tangents(vertices, triangles, tri_normal, tri_tangent, tri_material, grating_tri,
                           max_tangent_angle: float = MAX_TANGENT_ANGLE,
                           max_normal_angle: float = MAX_NORMAL_ANGLE) -> np.ndarray | None:
    """Per-corner unit grating tangents (T, 3, 3) float32, sign-aligned with each triangle's own
    ``tri_tangent`` (T, 3) (unit, in the triangle's plane); rows of triangles outside
    ``grating_tri`` (T,) bool repeat their own tangent. None when no triangle is a grating.

    Cost: the pairs of corners sharing a vertex, about 6 per corner on a regular mesh."""
    grating_tri = np.asarray(grating_tri, bool)
    if not grating_tri.any() or len(tri_tangent) != len(grating_tri):
        return None
    # float32 from the start (the float64 rows were cast at the end: the same values), and the
    # float64 work on the grating rows only
    out = np.repeat(np.asarray(tri_tangent)[:, None, :], 3, axis=1).astype(np.float32, copy=False)
    g = np.flatnonzero(grating_tri)
    tris = np.asarray(triangles, np.int64)[g]
    v = np.asarray(vertices, np.float64)
    nrm = np.asarray(tri_normal, np.float64)[g]
    tg = np.asarray(tri_tangent)[g].astype(np.float64)
    mat = np.asarray(tri_material)[g]
    weight = _corner_angles(v, tris).ravel()
    vid = tris.ravel()
    tri_of = np.repeat(np.arange(len(g)), 3)
    order = np.argsort(vid, kind="stable")
    vs = vid[order]
    starts = np.flatnonzero(np.concatenate([[True], vs[1:] != vs[:-1]]))
    sizes = np.diff(np.concatenate([starts, [len(vs)]]))
    group = np.repeat(np.arange(len(starts)), sizes)  # group of each sorted corner
    size_c = sizes[group]
    # all ordered pairs (a, b) of corners at one vertex, a and b positions in the sorted order
    a = np.repeat(np.arange(len(vs)), size_c)
    first = np.repeat(starts[group], size_c)
    b = first + (np.arange(len(a)) - np.repeat(np.cumsum(size_c) - size_c, size_c))
    ta, tb = tri_of[order[a]], tri_of[order[b]]
    dot_t = np.einsum("ij,ij->i", tg[ta], tg[tb])
    ok = (np.abs(dot_t) >= np.cos(np.radians(max_tangent_angle))) & (mat[ta] == mat[tb])
    ok &= np.einsum("ij,ij->i", nrm[ta], nrm[tb]) >= np.cos(np.radians(max_normal_angle))
    w = np.where(ok, weight[order[b]] * np.sign(dot_t), 0.0)
    acc = np.zeros((len(vs), 3))
    for k in range(3):  # components
        acc[:, k] = np.bincount(a, weights=w * tg[tb, k], minlength=len(vs))
    length = np.linalg.norm(acc, axis=1, keepdims=True)
    own = tg[tri_of[order]]
    acc = np.where(length > 1e-12, acc / np.maximum(length, 1e-300), own)
    corner = np.empty((len(vid), 3))
    corner[order] = acc
    out[g] = corner.reshape(-1, 3, 3)
    return out


def tangents_at(corner_tangents: np.ndarray | None, tri_tangent: np.ndarray, prim, bu, bv, normal) -> np.ndarray:
    """Unit grating tangents (B, 3) float32 at hits: the corner tangents of triangle ``prim``
    interpolated with the barycentrics (bu, bv) and projected onto the plane of ``normal``
    (B, 3); the triangle's own tangent where there are none or they cancel."""
    own = np.asarray(tri_tangent)[prim]
    if corner_tangents is None or len(corner_tangents) == 0:
        return own
    c = corner_tangents[prim]
    bu = np.asarray(bu, np.float32)[:, None]
    bv = np.asarray(bv, np.float32)[:, None]
    t = (1 - bu - bv) * c[:, 0] + bu * c[:, 1] + bv * c[:, 2]
    n = np.asarray(normal, np.float32)
    t = t - np.einsum("ij,ij->i", t, n)[:, None] * n
    length = np.linalg.norm(t, axis=1, keepdims=True)
    return np.where(length > 1e-6, t / np.maximum(length, 1e-30), own).astype(np.float32)
