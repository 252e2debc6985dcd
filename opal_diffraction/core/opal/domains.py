"""Grating domains: Voronoi cells over a surface, each with its own grating direction and period.

Real precious opal shows patches ("domains") of differently oriented and spaced silica-sphere
lattices, the "harlequin" look. Seeds are sampled uniformly over the surface's area; each face
belongs to the seed nearest its centre; a domain's direction is tangent to the surface at its
seed and carried to its faces by the smallest rotation (:func:`.surface.transport_tangents`),
its period drawn from a sphere-diameter range through the Bragg law (:mod:`.bragg`). Per-face
grating data is a :class:`DomainField`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..util.geometry import triangle_areas
from .bragg import N_SILICA, N_VOID, period_from_sphere_diameter
from .surface import face_geometry, project_to_planes, tangent_basis, transport_tangents

__all__ = [
    "DomainField",
    "sample_surface_points",
    "nearest_seed",
    "voronoi_domains",
    "domain_directions",
    "aligned_directions",
    "domain_periods",
    "generate_domains",
]


@dataclass
class DomainField:
    """Per-face grating data: domain id (F,) int32, unit direction (F, 3) float32 in the face's
    plane, period (F,) float32 nm."""

    domain: np.ndarray
    direction: np.ndarray
    period: np.ndarray

    def copy(self) -> "DomainField":
        return DomainField(self.domain.copy(), self.direction.copy(), self.period.copy())

    def __len__(self):
        return len(self.domain)


def sample_surface_points(vertices, triangles, count: int, rng: np.random.Generator):
    """``count`` points uniformly distributed over the surface's area: (points (count, 3), triangle
    index (count,)). Triangles are picked with probability proportional to their area, points
    inside them with the square-root barycentric map."""
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles, np.int64).reshape(-1, 3)
    p = v[t]
    area = triangle_areas(v, t)
    total = area.sum()
    if count <= 0 or len(t) == 0 or not total > 0:
        return np.zeros((0, 3)), np.zeros(0, np.int64)
    cdf = np.cumsum(area) / total
    tri = np.minimum(np.searchsorted(cdf, rng.random(count), side="right"), len(t) - 1)
    r1, r2 = rng.random(count), rng.random(count)
    s = np.sqrt(r1)
    pts = (1 - s)[:, None] * p[tri, 0] + (s * (1 - r2))[:, None] * p[tri, 1] + (s * r2)[:, None] * p[tri, 2]
    return pts, tri


def nearest_seed(points, seeds) -> np.ndarray:
    """Index of the nearest seed (Euclidean) for every point (P,)."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    seeds = np.asarray(seeds, np.float64).reshape(-1, 3)
    if len(seeds) == 0:
        return np.zeros(len(points), np.int64)
    try:
        from scipy.spatial import cKDTree

        return cKDTree(seeds).query(points)[1].astype(np.int64)
    except ImportError:  # pragma: no cover - scipy is a dependency; a chunked brute force otherwise
        out = np.empty(len(points), np.int64)
        for i in range(0, len(points), 4096):
            d = ((points[i:i + 4096, None, :] - seeds[None]) ** 2).sum(-1)
            out[i:i + 4096] = np.argmin(d, axis=1)
        return out


def voronoi_domains(centers, seeds) -> np.ndarray:
    """Domain id (F,) int32 of every face: the index of the seed nearest its centre."""
    return nearest_seed(centers, seeds).astype(np.int32)


def domain_directions(normals, domain, domain_normals, angles) -> np.ndarray:
    """One direction per domain, tangent to the surface, consistent within the domain.

    Domain k's direction is the tangent at angle ``angles[k]`` from the tangent basis e1 of its
    reference normal ``domain_normals[k]`` (the normal where its seed lies); every face of the
    domain gets it carried over by the smallest rotation from the reference normal to the
    face's (:func:`transport_tangents`): on a flat domain that is the same vector everywhere, on
    a curved one it turns with the surface (the domain's lattice follows the stone's curvature)
    instead of collapsing where a fixed 3D vector would be nearly normal to the surface.
    """
    dn = np.asarray(domain_normals, np.float64).reshape(-1, 3)
    ang = np.asarray(angles, np.float64)
    e1, e2 = tangent_basis(dn)
    dvec = np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2
    dom = np.asarray(domain, np.int64)
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    return transport_tangents(dvec[dom], dn[dom], n)


def aligned_directions(normals, axis=(1.0, 0.0, 0.0)) -> np.ndarray:
    """The paper's model: every face's direction is ``axis`` projected onto its plane (one
    consistent orientation over the whole mesh)."""
    return project_to_planes(np.asarray(axis, np.float64), normals)


def domain_periods(count: int, rng: np.random.Generator, mode: str = "SPHERES", low: float = 150.0,
                   high: float = 350.0, n_sphere: float = N_SILICA, n_void: float = N_VOID) -> np.ndarray:
    """``count`` periods (nm) drawn uniformly: 'SPHERES' draws the sphere diameter in [low, high]
    nm and converts it (:func:`period_from_sphere_diameter`); 'PERIOD' draws the period itself."""
    lo, hi = sorted((float(low), float(high)))
    x = lo + (hi - lo) * rng.random(int(count))
    if mode == "SPHERES":
        x = period_from_sphere_diameter(x, n_sphere, n_void)
    elif mode != "PERIOD":
        raise ValueError(f"period mode must be 'SPHERES' or 'PERIOD', got {mode!r}")
    return np.asarray(x, np.float32)


def generate_domains(vertices, triangles, count: int, seed: int = 0, tri_face=None, n_faces: int | None = None, *,
                     period_mode: str = "SPHERES", low: float = 150.0, high: float = 350.0,
                     direction_mode: str = "RANDOM", axis=(1.0, 0.0, 0.0), n_sphere: float = N_SILICA,
                     n_void: float = N_VOID, seed_mask=None) -> DomainField:
    """Cover a surface with ``count`` Voronoi grating domains.

    Seeds are sampled on the surface, area-weighted; each face belongs to the seed nearest its
    centre (Euclidean; ids are renumbered 0..K-1 in seed order, K <= count, so every id has at
    least one face). ``direction_mode`` 'RANDOM': each domain a uniformly random direction
    tangent to the surface at its seed, carried to its faces (:func:`domain_directions`);
    'ALIGNED': the paper's model,
    ``axis`` projected onto every face. Periods per domain from :func:`domain_periods`. The
    positions, directions and periods use separate random streams of ``seed``, so changing the
    period range keeps the layout. ``seed_mask`` (F,) bool limits where seeds may lie (e.g. the
    visible dome of a cabochon, not its base); every face is still assigned a domain.
    """
    geo = face_geometry(vertices, triangles, tri_face, n_faces)
    f = len(geo)
    ss_pos, ss_dir, ss_per = np.random.SeedSequence(int(seed)).spawn(3)
    count = max(int(count), 1)
    tris = np.asarray(triangles, np.int64).reshape(-1, 3)
    cand = np.arange(len(tris))
    if seed_mask is not None:
        fmask = np.asarray(seed_mask, bool).reshape(-1)
        tf = np.arange(len(tris)) if tri_face is None else np.asarray(tri_face, np.int64)
        if fmask[tf].any():
            cand = np.flatnonzero(fmask[tf])
    seeds, seed_tri = sample_surface_points(vertices, tris[cand], count, np.random.default_rng(ss_pos))
    seed_tri = cand[seed_tri]
    if len(seeds) == 0:
        return DomainField(np.zeros(f, np.int32), project_to_planes((1.0, 0, 0), geo.normal),
                           np.zeros(f, np.float32))
    raw = voronoi_domains(geo.center, seeds)
    used, domain = np.unique(raw, return_inverse=True)
    domain = domain.astype(np.int32)
    angles = np.random.default_rng(ss_dir).random(count) * np.pi  # an axis: [0, pi) covers all
    periods = domain_periods(count, np.random.default_rng(ss_per), period_mode, low, high, n_sphere, n_void)
    tri_n = face_geometry(vertices, np.asarray(triangles)[seed_tri]).normal if len(seed_tri) else np.zeros((0, 3))
    if direction_mode == "RANDOM":
        direction = domain_directions(geo.normal, domain, tri_n[used], angles[used])
    elif direction_mode == "ALIGNED":
        direction = aligned_directions(geo.normal, axis)
    else:
        raise ValueError(f"direction mode must be 'RANDOM' or 'ALIGNED', got {direction_mode!r}")
    return DomainField(domain, direction, periods[used][domain].astype(np.float32))
