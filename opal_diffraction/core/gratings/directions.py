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
    p = np.asarray(v)[tris].astype(np.float64, copy=False)  # (T, 3, 3): float32 vertices gathered, then widened
    out = np.empty(tris.shape, np.float64)
    edge = [p[:, (c + 1) % 3] - p[:, c] for c in range(3)]  # corner c's edge to c + 1
    length = [np.linalg.norm(e, axis=1) for e in edge]  # |p_c - p_{c+2}| is edge c + 2's length, exactly
    for c in range(3):  # the three corners
        a = edge[c]
        b = p[:, (c + 2) % 3] - p[:, c]
        cos = np.einsum("ij,ij->i", a, b) / np.maximum(length[c] * length[(c + 2) % 3], 1e-300)
        out[:, c] = np.arccos(np.clip(cos, -1, 1))
    return out


#: The vertex-sum shortcut's margin (degrees): a vertex takes it when every corner's tangent and
#: normal lie within half the crease angle minus this of one reference corner's.
_FAST_MARGIN = 0.5


def _pair_sums(vid, tg, nrm, mat, weight, cos_t, cos_n) -> np.ndarray:
    """Per corner (m, 3): the sum over every corner b at its vertex (in corner order) that
    counts (same material, tangent and normal within the crease angles) of weight_b sign(t.t_b)
    t_b. Inputs per corner; the ordered pairs of corners at one vertex are enumerated."""
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
    ca, cb = order[a], order[b]
    dot_t = np.einsum("ij,ij->i", tg[ca], tg[cb])
    ok = (np.abs(dot_t) >= cos_t) & (mat[ca] == mat[cb])
    ok &= np.einsum("ij,ij->i", nrm[ca], nrm[cb]) >= cos_n
    w = np.where(ok, weight[cb] * np.sign(dot_t), 0.0)
    acc = np.zeros((len(vs), 3))
    for k in range(3):  # components
        acc[:, k] = np.bincount(a, weights=w * tg[cb, k], minlength=len(vs))
    out = np.empty_like(acc)
    out[order] = acc
    return out


def smooth_corner_tangents(vertices, triangles, tri_normal, tri_tangent, tri_material, grating_tri,
                           max_tangent_angle: float = MAX_TANGENT_ANGLE,
                           max_normal_angle: float = MAX_NORMAL_ANGLE) -> np.ndarray | None:
    """Per-corner unit grating tangents (T, 3, 3) float32, sign-aligned with each triangle's own
    ``tri_tangent`` (T, 3) (unit, in the triangle's plane); rows of triangles outside
    ``grating_tri`` (T,) bool repeat their own tangent. None when no triangle is a grating.

    Cost: linear in the grating corners. At a vertex where every corner's tangent lies within
    half the crease angle (less a margin) of one reference corner's, up to sign, and its normal
    likewise, with one material (a smooth surface: nearly every vertex), every pair of corners
    counts and sign(t_a . t_b) = s_a s_b with s = sign(t . t_ref), so corner a's sum is
    s_a sum_b s_b w_b t_b: one bincount over the vertices, added in the same order as the pairs
    (the same values bit for bit: a sign flip is exact; docs/physics.md section 3.12). The other
    vertices enumerate their pairs of corners (about 6 per corner on a regular mesh)."""
    grating_tri = np.asarray(grating_tri, bool)
    if not grating_tri.any() or len(tri_tangent) != len(grating_tri):
        return None
    tri_tangent = np.asarray(tri_tangent)
    # zeros (calloc'd, untouched pages are free), then the rows outside the gratings that have a
    # tangent (prepare leaves theirs zero) repeat it, the grating rows are smoothed (float64 work)
    out = np.zeros((len(grating_tri), 3, 3), np.float32)
    g = np.flatnonzero(grating_tri)
    if np.count_nonzero(tri_tangent) > np.count_nonzero(tri_tangent[g]):  # a tangent outside the gratings
        rest = np.flatnonzero(~grating_tri & np.any(tri_tangent != 0, axis=1))
        out[rest] = tri_tangent[rest][:, None, :]
    tris = np.asarray(triangles, np.int64)[g]
    weight = _corner_angles(vertices, tris).ravel()
    vid = tris.ravel()
    tri_of = np.repeat(np.arange(len(g)), 3)
    tg = np.asarray(tri_tangent)[g].astype(np.float64)[tri_of]  # per corner
    nrm = np.asarray(tri_normal, np.float64)[g][tri_of]
    mat = np.asarray(tri_material)[g][tri_of]
    cos_t, cos_n = np.cos(np.radians(max_tangent_angle)), np.cos(np.radians(max_normal_angle))
    n_v = int(vid.max()) + 1
    slow = np.ones(len(vid), bool)
    acc = np.empty((len(vid), 3))
    half_t, half_n = max_tangent_angle / 2 - _FAST_MARGIN, max_normal_angle / 2 - _FAST_MARGIN
    if half_t > 0 and half_n > 0:
        ref = np.empty(n_v, np.int64)
        ref[vid] = np.arange(len(vid))  # one corner of each vertex (any: the result does not depend on it)
        r = ref[vid]
        d_ref = np.einsum("ij,ij->i", tg, tg[r])
        good = (np.abs(d_ref) >= np.cos(np.radians(half_t))) & (mat == mat[r])
        good &= np.einsum("ij,ij->i", nrm, nrm[r]) >= np.cos(np.radians(half_n))
        bad_vertex = np.zeros(n_v, bool)
        bad_vertex[vid[~good]] = True
        slow = bad_vertex[vid]
        s = np.where(d_ref >= 0, 1.0, -1.0)
        ws = weight * s
        per_vertex = np.empty((n_v, 3))
        for k in range(3):
            per_vertex[:, k] = np.bincount(vid, weights=ws * tg[:, k], minlength=n_v)
        acc = per_vertex[vid]
        acc *= s[:, None]  # the slow corners' rows are overwritten below
    sl = np.flatnonzero(slow)
    if len(sl):
        acc[sl] = _pair_sums(vid[sl], tg[sl], nrm[sl], mat[sl], weight[sl], cos_t, cos_n)
    length = np.linalg.norm(acc, axis=1, keepdims=True)
    acc = np.where(length > 1e-12, acc / np.maximum(length, 1e-300), tg)
    out[g] = acc.reshape(-1, 3, 3)
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
