"""Editing a grating field: directions from a vector or an angle, rotation, assignment to selected
faces, periods set or jittered, domains split and merged. Each returns a new array or field;
the faces outside the selection keep their values (Merge: whole domains change)."""

from __future__ import annotations

import numpy as np

from .domains import DomainField, domain_directions, nearest_seed
from .surface import FaceGeometry, project_to_planes, tangent_basis

__all__ = [
    "direction_from_vector",
    "direction_from_angle",
    "direction_angle",
    "rotate_directions",
    "assign_grating",
    "set_period",
    "jitter_period",
    "split_domains",
    "merge_domains",
]


def _mask(selected, n: int) -> np.ndarray:
    m = np.zeros(n, bool) if selected is None else np.asarray(selected, bool).reshape(-1)
    if len(m) != n:
        raise ValueError(f"selection has {len(m)} entries, expected {n}")
    return m


def direction_from_vector(normals, vector) -> np.ndarray:
    """Directions (N, 3) from one vector (a view axis, an edge): projected onto each face."""
    return project_to_planes(np.asarray(vector, np.float64), normals)


def direction_from_angle(normals, angle: float, reference=(1.0, 0.0, 0.0)) -> np.ndarray:
    """Directions at ``angle`` (radians, counter-clockwise about the normal) from ``reference``
    projected onto each face (the face's :func:`tangent_basis` e1)."""
    e1, e2 = tangent_basis(normals, reference)
    return (np.cos(angle) * e1 + np.sin(angle) * e2).astype(np.float32)


def direction_angle(direction, normals, reference=(1.0, 0.0, 0.0)) -> np.ndarray:
    """The angle of each direction about its face normal from the face's reference tangent,
    folded to [0, pi) (a grating's direction is an axis)."""
    e1, e2 = tangent_basis(normals, reference)
    d = np.asarray(direction, np.float64).reshape(-1, 3)
    return np.mod(np.arctan2(np.sum(d * e2, axis=1), np.sum(d * e1, axis=1)), np.pi)


def rotate_directions(direction, normals, selected, angle: float) -> np.ndarray:
    """Directions of the selected faces rotated by ``angle`` about their normals (a copy)."""
    d = np.array(direction, np.float32).reshape(-1, 3)
    m = _mask(selected, len(d))
    if m.any():
        n = np.asarray(normals, np.float64).reshape(-1, 3)[m]
        dm = d[m].astype(np.float64)
        rot = np.cos(angle) * dm + np.sin(angle) * np.cross(n, dm)
        d[m] = project_to_planes(rot, n)
    return d


def assign_grating(field: DomainField, normals, selected, direction=None, period=None,
                   new_domain: bool = True) -> DomainField:
    """The selected faces get ``direction`` ((3,) vector projected onto each face, or (F, 3)
    per face; None keeps theirs), ``period`` (nm; None keeps theirs) and, with ``new_domain``,
    one new domain id (max + 1). Other faces are unchanged. Returns a new field."""
    out = field.copy()
    m = _mask(selected, len(field))
    if not m.any():
        return out
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    if direction is not None:
        dvec = np.asarray(direction, np.float64)
        dvec = dvec[m] if dvec.ndim == 2 and len(dvec) == len(field) else dvec
        out.direction[m] = project_to_planes(dvec, n[m], fallback=field.direction[m])
    if period is not None:
        out.period[m] = np.float32(period)
    if new_domain:
        out.domain[m] = (int(field.domain.max()) + 1) if len(field) else 0
    return out


def set_period(period, selected, value: float) -> np.ndarray:
    """Periods with the selected faces set to ``value`` nm (a copy)."""
    p = np.array(period, np.float32).reshape(-1)
    p[_mask(selected, len(p))] = np.float32(value)
    return p


def jitter_period(period, domain, selected, amount: float, seed: int = 0, per_domain: bool = True,
                  low: float = 1.0, high: float = np.inf) -> np.ndarray:
    """Periods of the selected faces moved by a uniform random offset in [-amount, amount] nm,
    one offset per domain (so domains stay uniform) or per face; clamped to [low, high]."""
    p = np.array(period, np.float32).reshape(-1)
    m = _mask(selected, len(p))
    if not m.any() or amount == 0:
        return p
    rng = np.random.default_rng(int(seed))
    if per_domain:
        dom = np.asarray(domain, np.int64).reshape(-1)
        ids, inv = np.unique(dom[m], return_inverse=True)
        off = (2 * rng.random(len(ids)) - 1) * amount
        delta = off[inv]
    else:
        delta = (2 * rng.random(int(m.sum())) - 1) * amount
    p[m] = np.clip(p[m] + delta, low, high).astype(np.float32)
    return p


def split_domains(field: DomainField, geometry: FaceGeometry, selected, parts: int = 2, seed: int = 0) -> DomainField:
    """Split the selected faces into ``parts`` new domains (Voronoi cells over the selection:
    seeds at area-weighted random selected faces, each face to the nearest seed's centre), each
    with a new random direction; a new domain keeps the period of its seed face. Faces outside
    the selection are unchanged."""
    out = field.copy()
    m = _mask(selected, len(field))
    idx = np.flatnonzero(m)
    if len(idx) == 0:
        return out
    rng = np.random.default_rng(int(seed))
    k = max(1, min(int(parts), len(idx)))
    w = geometry.area[idx]
    prob = w / w.sum() if w.sum() > 0 else None
    seeds = rng.choice(idx, size=k, replace=False, p=prob)
    cell = nearest_seed(geometry.center[idx], geometry.center[seeds])
    used, cell = np.unique(cell, return_inverse=True)
    seeds = seeds[used]
    angles = rng.random(len(seeds)) * np.pi
    base = (int(field.domain.max()) + 1) if len(field) else 0
    out.domain[idx] = base + cell
    out.direction[idx] = domain_directions(geometry.normal[idx], cell, geometry.normal[seeds], angles)
    out.period[idx] = field.period[seeds][cell]
    return out


def merge_domains(field: DomainField, normals, selected, active: int | None = None) -> DomainField:
    """Merge every domain that has a selected face into one: the domain, direction and period of
    the ``active`` face (a face index; default the first selected face). The direction vector of
    the active face is projected onto every merged face. Whole domains change, not only the
    selected faces."""
    out = field.copy()
    m = _mask(selected, len(field))
    if not m.any():
        return out
    a = int(active) if active is not None and 0 <= int(active) < len(field) else int(np.flatnonzero(m)[0])
    doms = np.unique(field.domain[m])
    merged = np.isin(field.domain, doms)
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    out.domain[merged] = field.domain[a]
    out.direction[merged] = project_to_planes(field.direction[a].astype(np.float64), n[merged],
                                              fallback=field.direction[merged])
    out.period[merged] = field.period[a]
    return out
