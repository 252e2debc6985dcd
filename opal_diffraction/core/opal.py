"""The opal model: a cabochon mesh and grating domains over a surface, as NumPy on mesh arrays.

Sources. The source paper's model (Kobayashi & Kawai; docs/physics.md section 5.1) puts one
diffraction grating on every triangle of the opal mesh, all oriented consistently. Real precious
opal shows patches ("domains") of differently oriented and spaced silica-sphere lattices, the
"harlequin" look; a domain model gives it: Voronoi cells over the surface, each with its own grating direction and
period. The periods come from the silica sphere diameter through the Bragg law of the FCC
(111) planes (Sanders, "Colour of precious opal", Nature 204, 1964, doi:10.1038/2041151a0):

    d111 = sqrt(2/3) D_s,   lambda_B(theta) = 2 d111 sqrt(n_eff^2 - sin^2 theta),
    n_eff^2 = 0.74 n_s^2 + 0.26 n_void^2

(silica n_s = 1.45, air voids: n_eff = 1.3475; D_s = 250 nm gives 550 nm at normal incidence
and 468 nm at 45 degrees). The renderer's gratings are surface gratings, so a domain's period
is the *equivalent* grating period ``period_from_sphere_diameter``: the Bragg wavelength at
normal incidence, which the grating's first order sends where |u| = |(w_o + w_i) . t| = 1
(light and viewer about 30 degrees either side of the normal, across the slits). Spheres of
150-350 nm give periods of 330-770 nm: colour from violet to red, one order at a time.
(That relation is the LINES grating's; a HEXAGONAL lattice's first orders sit at
|q| = 2 lambda / (sqrt 3 D): a known deviation, docs/physics.md section 5.5.)

Everything here is a pure function on arrays (no bpy), so the Blender operators are thin
wrappers and the tests call the logic directly. A surface is given as vertices (V, 3) and
triangles (T, 3), with an optional ``tri_face`` (T,) mapping triangles to polygons (Blender's
loop triangles); per-face data is then per polygon. Per-face grating data is a
:class:`DomainField`: ``domain`` (F,) int32, ``direction`` (F, 3) float32 unit vectors in each
face's plane (object space), ``period`` (F,) float32 nm. A grating's direction is an axis
(t and -t diffract alike), which the preview colours respect.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "N_SILICA",
    "N_VOID",
    "SPHERE_DIAMETER_RANGE",
    "effective_index",
    "d111_spacing",
    "bragg_wavelength",
    "period_from_sphere_diameter",
    "cabochon",
    "FaceGeometry",
    "face_geometry",
    "DomainField",
    "sample_surface_points",
    "nearest_seed",
    "voronoi_domains",
    "tangent_basis",
    "project_to_planes",
    "transport_tangents",
    "domain_directions",
    "aligned_directions",
    "domain_periods",
    "generate_domains",
    "direction_from_vector",
    "direction_from_angle",
    "direction_angle",
    "rotate_directions",
    "assign_grating",
    "set_period",
    "jitter_period",
    "split_domains",
    "merge_domains",
    "preview_colors",
]

#: Refractive index of the silica spheres and of the voids (air) between them
#: (docs/physics.md section 5.3).
N_SILICA = 1.45
N_VOID = 1.0
#: Diameters of the silica spheres of precious opal, nm (docs/physics.md section 5.2).
SPHERE_DIAMETER_RANGE = (150.0, 350.0)
#: Volume fraction of the spheres in an FCC packing (0.74) and of the voids (0.26).
_FILL = 0.74


# ============================================================================ physics (Sanders 1964)
def effective_index(n_sphere: float = N_SILICA, n_void: float = N_VOID) -> float:
    """n_eff = sqrt(0.74 n_s^2 + 0.26 n_void^2): 1.3475 for silica in air."""
    return float(np.sqrt(_FILL * n_sphere**2 + (1.0 - _FILL) * n_void**2))


def d111_spacing(sphere_diameter):
    """Spacing of the FCC (111) planes, d111 = sqrt(2/3) D_s (same unit as D_s)."""
    return np.sqrt(2.0 / 3.0) * np.asarray(sphere_diameter, np.float64)


def bragg_wavelength(sphere_diameter, theta=0.0, n_sphere: float = N_SILICA, n_void: float = N_VOID):
    """First-order Bragg wavelength lambda = 2 d111 sqrt(n_eff^2 - sin^2 theta) (nm for D_s in nm).

    ``theta``: angle of incidence in air (radians) on the (111) planes.
    """
    n2 = effective_index(n_sphere, n_void) ** 2
    return 2.0 * d111_spacing(sphere_diameter) * np.sqrt(n2 - np.sin(np.asarray(theta, np.float64)) ** 2)


def period_from_sphere_diameter(sphere_diameter, n_sphere: float = N_SILICA, n_void: float = N_VOID):
    """The equivalent surface-grating period (nm): the Bragg wavelength at normal incidence.

    The first diffraction order of this grating has the Bragg colour where |u| = 1; smaller |u|
    (closer to the mirror direction) shifts it to the red, larger to the blue.
    """
    return bragg_wavelength(sphere_diameter, 0.0, n_sphere, n_void)


# ============================================================================ cabochon
def cabochon(size_x: float = 0.02, size_y: float = 0.015, height: float = 0.007, rings: int = 24,
             base: bool = True, profile: float = 1.0):
    """An oval dome (half ellipsoid) with a flat base, as (vertices (V, 3), triangles (T, 3)).

    ``size_x`` / ``size_y``: the base's diameters; ``height``: the dome's height (m); ``rings``:
    resolution (the dome has 1 + 3 rings (rings + 1) vertices and 6 rings^2 triangles of
    similar size: ring i has 6 i vertices). ``profile`` shapes the dome: 1 is a half ellipsoid,
    above 1 fuller shoulders, below 1 more pointed. The base (a fan to its centre, facing -Z)
    closes the solid. Triangles wind counter-clockwise seen from outside (normals point out).
    """
    rings = max(int(rings), 1)
    a, b, h = float(size_x) / 2, float(size_y) / 2, float(height)
    verts = [(0.0, 0.0, h)]
    starts = [0]
    for i in range(1, rings + 1):
        theta = 0.5 * np.pi * i / rings  # polar angle: even arc steps over the dome
        r = np.sin(theta)
        z = h * np.cos(theta) ** (1.0 / profile) if i < rings else 0.0
        n = 6 * i
        phi = 2 * np.pi * np.arange(n) / n
        starts.append(len(verts))
        verts.extend(zip(a * r * np.cos(phi), b * r * np.sin(phi), np.full(n, z)))
    tris = []
    for i in range(rings):  # strip between ring i (inner) and ring i + 1 (outer)
        n_in, n_out = max(6 * i, 1), 6 * (i + 1)
        s_in, s_out = starts[i], starts[i + 1]
        j_in = j_out = 0
        while j_in < n_in or j_out < n_out:
            # advance along whichever ring's next vertex comes first in angle
            a_in = (j_in + 1) / n_in if n_in > 1 else 2.0
            a_out = (j_out + 1) / n_out
            if i == 0 or (j_out < n_out and a_out <= a_in):
                tris.append((s_in + j_in % n_in, s_out + j_out % n_out, s_out + (j_out + 1) % n_out))
                j_out += 1
            else:
                tris.append((s_in + j_in % n_in, s_out + j_out % n_out, s_in + (j_in + 1) % n_in))
                j_in += 1
            if i == 0 and j_out >= n_out:
                break
    v = np.asarray(verts, np.float64)
    t = np.asarray(tris, np.int64)
    if base:
        centre = len(v)
        v = np.vstack([v, [[0.0, 0.0, 0.0]]])
        s, n = starts[rings], 6 * rings
        j = np.arange(n)
        t = np.vstack([t, np.stack([np.full(n, centre), s + (j + 1) % n, s + j], axis=1)])
    # outward winding: the dome's triangles face away from the axis / up, the base's down
    p = v[t]
    nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    out = p.mean(axis=1) - np.array([0.0, 0.0, h * 0.25])
    flip = np.sum(nrm * out, axis=1) < 0
    t[flip] = t[flip][:, [0, 2, 1]]
    return v, t.astype(np.int32)


# ============================================================================ surface geometry
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
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
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


# ============================================================================ domains
def sample_surface_points(vertices, triangles, count: int, rng: np.random.Generator):
    """``count`` points uniformly distributed over the surface's area: (points (count, 3), triangle
    index (count,)). Triangles are picked with probability proportional to their area, points
    inside them with the square-root barycentric map."""
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles, np.int64).reshape(-1, 3)
    p = v[t]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
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


# ============================================================================ editing
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


# ============================================================================ preview
def _hsv_to_rgb(h, s, v):
    h = np.mod(np.asarray(h, np.float64), 1.0) * 6.0
    i = np.floor(h).astype(np.int64) % 6
    f = h - np.floor(h)
    s, v = np.broadcast_to(s, h.shape), np.broadcast_to(v, h.shape)
    p, q, t = v * (1 - s), v * (1 - s * f), v * (1 - s * (1 - f))
    table = np.stack([np.stack(c, -1) for c in ((v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v), (v, p, q))])
    return table[i, np.arange(len(h))]


def preview_colors(direction, normals, period, period_range=None, reference=(1.0, 0.0, 0.0)) -> np.ndarray:
    """RGBA (F, 4) float32 in [0, 1]: hue = the direction's angle about the normal (an axis, so
    0 and 180 degrees share a hue), brightness = the period (darkest at the low end of
    ``period_range``, default the periods' own range). Faces without a period (0) are grey."""
    ang = direction_angle(direction, normals, reference)
    p = np.asarray(period, np.float64).reshape(-1)
    valid = p > 0
    if period_range is None:
        lo, hi = (p[valid].min(), p[valid].max()) if valid.any() else (0.0, 1.0)
    else:
        lo, hi = period_range
    x = np.clip((p - lo) / (hi - lo), 0.0, 1.0) if hi > lo else np.full_like(p, 0.5)
    rgb = _hsv_to_rgb(ang / np.pi, 0.85, 0.3 + 0.7 * x)
    rgb[~valid] = 0.5
    out = np.ones((len(p), 4), np.float32)
    out[:, :3] = rgb
    return out
