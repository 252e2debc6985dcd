"""Tangent geometry on a triangulated surface: per-face centres, normals and areas, tangent bases,
projection onto the faces' planes, and transport of tangents between planes (Rodrigues' rotation).

A surface is vertices (V, 3) and triangles (T, 3) with an optional ``tri_face`` (T,) mapping
triangles to polygons (Blender's loop triangles); per-face data is then per polygon.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..util.geometry import triangle_cross

__all__ = [
    "FaceGeometry",
    "face_geometry",
    "tangent_basis",
    "project_to_planes",
    "transport_tangents",
]


@dataclass
class FaceGeometry:
    """Per-face centre (F, 3), unit normal (F, 3) and area (F,), from a triangulation."""

    center: np.ndarray
    normal: np.ndarray
    area: np.ndarray

    def __len__(self):
        return len(self.area)


def face_geometry(vertices, triangles, tri_face=None, n_faces: int | None = None) -> FaceGeometry:
    """Centres (area-weighted), normals (area-weighted, unit) and areas of the faces.

    Without ``tri_face`` every triangle is a face. A face of zero area gets normal +Z.
    """
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles, np.int64).reshape(-1, 3)
    p = v[t]
    cross = triangle_cross(v, t)
    area = 0.5 * np.linalg.norm(cross, axis=1)
    cen = p.mean(axis=1)
    if tri_face is None:
        nrm, fa, fc = cross, area, cen
    else:
        f = np.asarray(tri_face, np.int64)
        n = int(n_faces) if n_faces is not None else (int(f.max()) + 1 if len(f) else 0)
        fa = np.bincount(f, weights=area, minlength=n)
        nrm = np.stack([np.bincount(f, weights=cross[:, k], minlength=n) for k in range(3)], axis=1)
        wsum = np.stack([np.bincount(f, weights=area * cen[:, k], minlength=n) for k in range(3)], axis=1)
        cnt = np.bincount(f, minlength=n)
        plain = np.stack([np.bincount(f, weights=cen[:, k], minlength=n) for k in range(3)], axis=1)
        fc = np.where(fa[:, None] > 0, wsum / np.maximum(fa, 1e-300)[:, None], plain / np.maximum(cnt, 1)[:, None])
    length = np.linalg.norm(nrm, axis=1)
    ok = length > 0
    unit = np.zeros_like(nrm)
    unit[:, 2] = 1.0
    unit[ok] = nrm[ok] / length[ok, None]
    return FaceGeometry(np.asarray(fc, np.float64), unit, np.asarray(fa, np.float64))


def tangent_basis(normals, reference=(1.0, 0.0, 0.0)):
    """(e1, e2) unit tangents per normal (N, 3): e1 is ``reference`` projected onto the plane
    (falling back to Y, then Z, where it is parallel to the normal), e2 = n x e1."""
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    e1 = np.zeros_like(n)
    todo = np.ones(len(n), bool)
    for cand in (np.asarray(reference, np.float64), np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])):
        proj = cand[None, :] - (n @ cand)[:, None] * n
        length = np.linalg.norm(proj, axis=1)
        ok = todo & (length > 1e-3)
        e1[ok] = proj[ok] / length[ok, None]
        todo &= ~ok
    e2 = np.cross(n, e1)
    return e1, e2


def project_to_planes(vectors, normals, fallback=None) -> np.ndarray:
    """Unit vectors (N, 3) float32: ``vectors`` (3,) or (N, 3) projected onto the planes of
    ``normals``; where a vector is (nearly) parallel to the normal, ``fallback`` (N, 3) is
    projected instead, else the plane's :func:`tangent_basis` e1."""
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    vec = np.broadcast_to(np.asarray(vectors, np.float64), n.shape)
    out = np.zeros_like(n)
    todo = np.ones(len(n), bool)
    cands = [vec] + ([np.broadcast_to(np.asarray(fallback, np.float64), n.shape)] if fallback is not None else [])
    for c in cands:
        proj = c - np.sum(c * n, axis=1, keepdims=True) * n
        length = np.linalg.norm(proj, axis=1)
        ok = todo & (length > 1e-3 * np.maximum(np.linalg.norm(c, axis=1), 1e-30))
        out[ok] = proj[ok] / length[ok, None]
        todo &= ~ok
    if todo.any():
        out[todo] = tangent_basis(n[todo])[0]
    return out.astype(np.float32)


def transport_tangents(vectors, n_from, n_to) -> np.ndarray:
    """Tangent vectors (N, 3) carried from planes of normal ``n_from`` to planes of normal ``n_to``
    by the smallest rotation that takes one normal to the other (Rodrigues:
    R v = v + k x v + k x (k x v) / (1 + c), k = n_from x n_to, c = n_from . n_to), then projected
    and normalised. Where the normals are nearly opposite (over 154 degrees apart) the rotation is ill-defined
    and the vector is projected onto the target plane instead."""
    v = np.broadcast_to(np.asarray(vectors, np.float64), np.shape(n_to)).reshape(-1, 3)
    a = np.broadcast_to(np.asarray(n_from, np.float64), v.shape)
    b = np.asarray(n_to, np.float64).reshape(-1, 3)
    c = np.sum(a * b, axis=1)
    k = np.cross(a, b)
    kv = np.cross(k, v)
    ok = c > -0.9
    rot = v + kv + np.cross(k, kv) / np.where(ok, 1.0 + c, 1.0)[:, None]
    out = np.where(ok[:, None], rot, v)
    return project_to_planes(out, b)
