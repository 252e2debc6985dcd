"""Aiming light paths at the objects that bend light: the casters' bounding spheres, and
unbiased mixture sampling of directions and points towards them.

The light pass (core/integrators/light/, docs/physics.md section 4.1) aims its paths at the
*casters* (mirrors, glass, gratings): their triangles are grouped into connected objects with
bounding spheres (``caster_objects``). From a point or spot light, or a point sampled on an area
light, a direction is drawn in the cone that subtends one object's sphere, the object chosen in
proportion to its cone's solid angle; the pdf of a direction is the mixture
sum_c P_c [w in cone c] / Omega_c, so overlapping cones are accounted for (``sample_cones``,
``sample_towards_casters``). Parallel light (a sun, the world) draws a point on the disk one
object's sphere casts across its direction, with the matching mixture pdf per unit area
(``caster_disk_points``; docs/physics.md sections 7.7, 7.9). core/lights/emission.py builds each
light kind's path starts on these. The three samplers have compiled twins (core/util/jit.py, at
the end), one path per iteration on the random numbers the reference draws, in its order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..util.geometry import compact_indices, group_extrema, orthonormal_basis
from ..util.jit import kernels_enabled, njit

__all__ = ["CasterObjects", "caster_objects", "MAX_OBJECTS", "caster_cones", "sample_cones", "CONE_CHUNK",
           "sample_towards_casters", "caster_disk_points"]

MAX_OBJECTS = 64


@dataclass(frozen=True)
class CasterObjects:
    """Bounding spheres of the connected caster objects: what light paths are aimed at."""

    centre: np.ndarray  # (C, 3)
    radius: np.ndarray  # (C,)

    def __len__(self):
        return len(self.radius)


def caster_objects(vertices, triangles, mask) -> CasterObjects:
    """Bounding spheres of the connected groups of caster triangles (sharing vertex indices).

    Linear in the triangles (connected components of the vertex graph); a mesh whose pieces do
    not share vertices simply makes more, tighter groups. More than MAX_OBJECTS groups are merged
    on a coarse spatial grid so the mixture stays cheap.
    """
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    t = np.asarray(triangles)[np.asarray(mask, bool)]
    if len(t) == 0:
        return CasterObjects(np.zeros((0, 3)), np.zeros(0))
    used, node = compact_indices(t)  # compact the vertex ids of the casters (np.unique's result)
    pts = np.asarray(vertices)[used].astype(np.float64)  # the casters' vertices only, in float64
    extent = float(np.ptp(pts, axis=0).max()) or max(float(np.abs(pts).max()), 1e-30)
    n_nodes = len(used)
    # int32 indices and float64 weights, in CSR: what connected_components converts to otherwise
    rows = np.concatenate([node[:, 0], node[:, 1]]).astype(np.int32)
    cols = np.concatenate([node[:, 1], node[:, 2]]).astype(np.int32)
    graph = csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_nodes, n_nodes))
    n_comp, label = connected_components(graph, directed=False)
    if n_comp > MAX_OBJECTS:  # many separate pieces: group them by a spatial grid instead
        cells = np.floor((pts - pts.min(axis=0)) / (extent / 4 + 1e-12 * extent)).astype(np.int64)
        key = (cells[:, 0] * 5 + cells[:, 1]) * 5 + cells[:, 2]  # cells are 0..4 per axis
        _, label = compact_indices(key)
        n_comp = int(label.max()) + 1
    # per-group bounding box centre and radius, over the group's vertices (O(V) per pass)
    lo, hi = group_extrema(label, n_comp, pts)  # np.minimum.at / np.maximum.at without the scatter
    centre = 0.5 * (lo + hi)
    d2 = np.maximum(group_extrema(label, n_comp, np.sum((pts - centre[label]) ** 2, axis=1), ops=(np.maximum,))[0], 0.0)
    radius = np.sqrt(d2) * (1 + 1e-6) + 1e-9 * extent
    return CasterObjects(centre, radius)


def caster_cones(origin: np.ndarray, objects: CasterObjects):
    """Per (origin, object): unit axis, cos of the half angle, solid angle. origin (B, 3)."""
    to_c = objects.centre[None, :, :] - origin[:, None, :]
    dist = np.linalg.norm(to_c, axis=2)
    inside = dist <= objects.radius[None, :]
    axis = to_c / np.maximum(dist, 1e-30)[..., None]
    sin2 = np.clip((objects.radius[None, :] / np.maximum(dist, 1e-30)) ** 2, 0, 1)
    cos_max = np.where(inside, -1.0, np.sqrt(1 - sin2))
    omega = 2 * np.pi * (1 - cos_max)
    return axis, cos_max, omega


def sample_cones(origin, weights, axis, cos_max, omega, rng, u=None):
    """Directions from ``origin`` (B, 3): choose object c with probability weights (B, C)
    (normalised per row), then uniformly in its cone. Returns (dirs, pdf) with the mixture pdf.
    ``u``: the uniform numbers ((B, 1), (B,), (B,)) to use instead of drawing them from rng."""
    b, c = weights.shape
    uni = (rng.random((b, 1)), rng.random(b), rng.random(b)) if u is None else u
    # one origin for every path (a point light): the mixture, the cones' frames and the pdf's
    # cone tests once per object, not once per path
    shared = all(x.strides[0] == 0 for x in (weights, axis, cos_max, omega))
    if shared and kernels_enabled():  # the compiled twin (below): the same random numbers
        w0 = weights[0]
        prob0 = w0 / max(float(w0.sum()), 1e-300)
        d, pdf = np.empty((b, 3)), np.empty(b)
        _shared_cones_kernel(np.ascontiguousarray(axis[0], np.float64), np.ascontiguousarray(cos_max[0], np.float64),
                             np.ascontiguousarray(omega[0], np.float64), prob0.astype(np.float64),
                             np.ascontiguousarray(uni[0][:, 0]), np.ascontiguousarray(uni[1]),
                             np.ascontiguousarray(uni[2]), d, pdf)
        if c == 1:
            pdf[:] = prob0[0] / max(float(omega[0, 0]), 1e-300)
        return d, pdf
    if shared:
        w0 = weights[0]
        prob0 = w0 / max(float(w0.sum()), 1e-300)
        pick = np.minimum(np.searchsorted(np.cumsum(prob0), uni[0][:, 0], side="left"), c - 1)  # = (u > cdf).sum()
        u0, v0 = orthonormal_basis(axis[0])
        if c == 1:  # one cone: its axis and frame broadcast over the paths
            ax, cm, u, v = axis[0, 0], cos_max[0, 0], u0[0], v0[0]
        else:
            ax, cm, u, v = axis[0][pick], cos_max[0][pick], u0[pick], v0[pick]
        cos_t = 1 - uni[1] * (1 - cm)
        sin_t = np.sqrt(np.maximum(0, 1 - cos_t * cos_t))
        phi = 2 * np.pi * uni[2]
        d = cos_t[:, None] * ax + (sin_t * np.cos(phi))[:, None] * u + (sin_t * np.sin(phi))[:, None] * v
        if c == 1:  # the one cone holds every direction drawn in it
            return d, np.full(b, prob0[0] / max(float(omega[0, 0]), 1e-300))
        inside = d @ axis[0].T >= cos_max[0] - 1e-12
        return d, inside @ (prob0 / np.maximum(omega[0], 1e-300))
    if kernels_enabled():  # the compiled twin (below), as sample_towards_casters' kernel samples
        d, pdf = np.empty((b, 3)), np.empty(b)
        f64 = lambda x: np.ascontiguousarray(x, np.float64)  # noqa: E731
        _cones_kernel(f64(weights), f64(axis), f64(cos_max), f64(omega), f64(uni[0][:, 0]), f64(uni[1]), f64(uni[2]),
                      d, pdf)
        return d, pdf
    prob = weights / np.maximum(weights.sum(axis=1, keepdims=True), 1e-300)
    cdf = np.cumsum(prob, axis=1)
    pick = np.minimum((uni[0] > cdf).sum(axis=1), c - 1)
    rows = np.arange(b)
    ax, cm = axis[rows, pick], cos_max[rows, pick]
    cos_t = 1 - uni[1] * (1 - cm)
    sin_t = np.sqrt(np.maximum(0, 1 - cos_t * cos_t))
    phi = 2 * np.pi * uni[2]
    u, v = orthonormal_basis(ax)
    d = cos_t[:, None] * ax + (sin_t * np.cos(phi))[:, None] * u + (sin_t * np.sin(phi))[:, None] * v
    inside = np.einsum("bcj,bj->bc", axis, d) >= cos_max - 1e-12
    pdf = np.sum(np.where(inside, prob / np.maximum(omega, 1e-300), 0.0), axis=1)
    return d, pdf


#: Paths per chunk where every path has its own origin (area lights, sized lights, emissive
#: meshes): the (paths, objects, 3) cone arrays stay near 6 MB even with MAX_OBJECTS objects.
CONE_CHUNK = 4096


def sample_towards_casters(origin, obj: CasterObjects, rng):
    """``sample_cones`` from per-path origins (B, 3), each path choosing an object by its cone's
    solid angle: in chunks of CONE_CHUNK paths (bounded temporaries), with the random numbers
    drawn for the whole batch first (the same numbers as one unchunked call)."""
    b = len(origin)
    u = (rng.random((b, 1)), rng.random(b), rng.random(b))
    d = np.empty((b, 3))
    pdf = np.empty(b)
    if kernels_enabled():  # the compiled twin (below), one pass over the paths: no chunks needed
        _towards_casters_kernel(np.ascontiguousarray(origin, np.float64), np.ascontiguousarray(obj.centre, np.float64),
                                np.ascontiguousarray(obj.radius, np.float64), u[0][:, 0].copy(), u[1], u[2], d, pdf)
        return d, pdf
    for s in range(0, b, CONE_CHUNK):  # loop over chunks of a batch, not over paths
        sl = slice(s, min(b, s + CONE_CHUNK))
        axis, cos_max, omega = caster_cones(origin[sl], obj)
        d[sl], pdf[sl] = sample_cones(origin[sl], omega, axis, cos_max, omega, None, tuple(x[sl] for x in u))
    return d, pdf


def caster_disk_points(obj: CasterObjects, d: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray]:
    """Points for parallel light along unit directions d (B, 3): an object chosen by the area of
    the disk its bounding sphere casts across d, a uniform point on that disk (in the plane
    through the origin normal to d), and the mixture pdf per unit area over all objects' disks
    (they overlap for some d). The suns' and the world's path starts share it."""
    b = len(d)
    area = np.pi * obj.radius**2
    prob = area / area.sum()
    if kernels_enabled():  # the compiled twin (below): the same random numbers, drawn in the same order
        u0 = rng.random((b, 1))[:, 0].copy()
        u1 = rng.random(b)
        u2 = rng.random(b)
        pts, pdf = np.empty((b, 3)), np.empty(b)
        _disk_points_kernel(np.ascontiguousarray(d, np.float64), np.ascontiguousarray(obj.centre, np.float64),
                            np.ascontiguousarray(obj.radius, np.float64), area, prob, u0, u1, u2, pts, pdf)
        return pts, pdf
    pick = np.minimum((rng.random((b, 1)) > np.cumsum(prob)[None, :]).sum(axis=1), len(obj) - 1)
    r = obj.radius[pick] * np.sqrt(rng.random(b))
    phi = 2 * np.pi * rng.random(b)
    u, v = orthonormal_basis(d)
    c = obj.centre[pick]
    c_plane = c - np.einsum("ij,ij->i", c, d)[:, None] * d
    pts = c_plane + (r * np.cos(phi))[:, None] * u + (r * np.sin(phi))[:, None] * v
    if len(obj) == 1:  # one object: every point drawn lies on its disk
        return pts, np.full(b, 1.0 / area[0])
    # |pts - proj(centre)|^2 = |pts - centre|^2 - ((pts - centre) . d)^2 (pts . d = 0), every object at once
    cd = d @ obj.centre.T  # (B, C)
    dist2 = (np.sum(pts**2, axis=1)[:, None] - 2 * pts @ obj.centre.T + np.sum(obj.centre**2, axis=1)[None, :]
             - cd**2)
    pdf = np.sum(np.where(dist2 <= obj.radius**2 * (1 + 1e-9), prob / area, 0.0), axis=1)
    return pts, pdf


# ------------------------------------------------------------------------------ kernels
# The compiled twins (core/util/jit.py) of the mixture sampling above, one path per iteration
# with the random numbers the reference draws (drawn by the callers, in its order): the same
# formulas in the same order, but sums of three products where the reference has BLAS matmuls
# or einsum (whose order and FMA use are the library's), so they agree to a few ulps
# (tests/lights/test_light_aiming_kernels.py).


@njit
def _basis(ax0, ax1, ax2):
    """orthonormal_basis of one unit axis: (u, v) as six floats."""
    a0, a1 = (1.0, 0.0) if abs(ax0) < 0.9 else (0.0, 1.0)
    # u = axis x a (a2 = 0)
    u0 = ax1 * 0.0 - ax2 * a1
    u1 = ax2 * a0 - ax0 * 0.0
    u2 = ax0 * a1 - ax1 * a0
    nu = max(np.sqrt(u0 * u0 + u1 * u1 + u2 * u2), 1e-30)
    u0, u1, u2 = u0 / nu, u1 / nu, u2 / nu
    return u0, u1, u2, ax1 * u2 - ax2 * u1, ax2 * u0 - ax0 * u2, ax0 * u1 - ax1 * u0


@njit
def _cone_direction(ax, cm, u1, u2, d, i):
    """A direction uniform in the cone (axis ax (3,), cos of its half angle cm) into d[i]."""
    cos_t = 1 - u1 * (1 - cm)
    sin_t = np.sqrt(max(0.0, 1 - cos_t * cos_t))
    phi = 2 * np.pi * u2
    sc, ss = sin_t * np.cos(phi), sin_t * np.sin(phi)
    b0, b1, b2, c0, c1, c2 = _basis(ax[0], ax[1], ax[2])
    d[i, 0] = cos_t * ax[0] + sc * b0 + ss * c0
    d[i, 1] = cos_t * ax[1] + sc * b1 + ss * c1
    d[i, 2] = cos_t * ax[2] + sc * b2 + ss * c2


@njit
def _pick(cdf, u, c):
    """The object whose cdf interval holds u: (u > cdf).sum(), at most c - 1."""
    k = 0
    for m in range(c):
        if u > cdf[m]:
            k += 1
    return min(k, c - 1)


@njit
def _mixture_pdf(axis, cos_max, prob_over_omega, d, i):
    """The mixture pdf of d[i]: sum over the cones holding it of P_c / Omega_c."""
    p = 0.0
    for m in range(len(cos_max)):
        if axis[m, 0] * d[i, 0] + axis[m, 1] * d[i, 1] + axis[m, 2] * d[i, 2] >= cos_max[m] - 1e-12:
            p += prob_over_omega[m]
    return p


@njit
def _shared_cones_kernel(axis, cos_max, omega, prob, u0, u1, u2, d, pdf):
    """sample_cones from one origin: cones (C,) shared by every path."""
    c = len(prob)
    cdf = np.cumsum(prob)
    po = np.empty(c)
    for m in range(c):
        po[m] = prob[m] / max(omega[m], 1e-300)
    for i in range(len(u0)):  # loop over paths
        k = _pick(cdf, u0[i], c)
        _cone_direction(axis[k], cos_max[k], u1[i], u2[i], d, i)
        pdf[i] = _mixture_pdf(axis, cos_max, po, d, i)


@njit
def _towards_casters_kernel(origin, centre, radius, u0, u1, u2, d, pdf):
    """sample_towards_casters: per path, caster_cones from its origin, then sample_cones."""
    c = len(radius)
    axis = np.empty((c, 3))
    cos_max = np.empty(c)
    omega = np.empty(c)
    cdf = np.empty(c)
    po = np.empty(c)
    for i in range(len(origin)):  # loop over paths
        total = 0.0
        for m in range(c):  # the cones of the objects' spheres from this origin
            t0 = centre[m, 0] - origin[i, 0]
            t1 = centre[m, 1] - origin[i, 1]
            t2 = centre[m, 2] - origin[i, 2]
            dist = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
            dd = max(dist, 1e-30)
            axis[m, 0], axis[m, 1], axis[m, 2] = t0 / dd, t1 / dd, t2 / dd
            sin2 = min(max((radius[m] / dd) ** 2, 0.0), 1.0)
            cos_max[m] = -1.0 if dist <= radius[m] else np.sqrt(1 - sin2)
            omega[m] = 2 * np.pi * (1 - cos_max[m])
            total += omega[m]
        _sample_row(omega, total, axis, cos_max, omega, u0[i], u1[i], u2[i], cdf, po, d, pdf, i)


@njit
def _sample_row(weights, total, axis, cos_max, omega, u0, u1, u2, cdf, po, d, pdf, i):
    """One path of sample_cones: object by weights (C,) (their sum ``total``), a direction in its cone."""
    c = len(weights)
    acc = 0.0
    for m in range(c):
        p = weights[m] / max(total, 1e-300)
        acc += p
        cdf[m] = acc
        po[m] = p / max(omega[m], 1e-300)
    k = _pick(cdf, u0, c)
    _cone_direction(axis[k], cos_max[k], u1, u2, d, i)
    pdf[i] = _mixture_pdf(axis, cos_max, po, d, i)


@njit
def _cones_kernel(weights, axis, cos_max, omega, u0, u1, u2, d, pdf):
    """sample_cones with cones per path: weights, cos_max, omega (B, C), axis (B, C, 3)."""
    c = weights.shape[1]
    cdf = np.empty(c)
    po = np.empty(c)
    for i in range(len(u0)):  # loop over paths
        total = 0.0
        for m in range(c):
            total += weights[i, m]
        _sample_row(weights[i], total, axis[i], cos_max[i], omega[i], u0[i], u1[i], u2[i], cdf, po, d, pdf, i)


@njit
def _disk_points_kernel(d, centre, radius, area, prob, u0, u1, u2, pts, pdf):
    """caster_disk_points: per path, an object by disk area, a uniform point on its disk, the mixture pdf."""
    c = len(radius)
    cdf = np.cumsum(prob)
    for i in range(len(d)):  # loop over paths
        k = _pick(cdf, u0[i], c)
        r = radius[k] * np.sqrt(u1[i])
        phi = 2 * np.pi * u2[i]
        b0, b1, b2, c0, c1, c2 = _basis(d[i, 0], d[i, 1], d[i, 2])
        cd = centre[k, 0] * d[i, 0] + centre[k, 1] * d[i, 1] + centre[k, 2] * d[i, 2]
        rc, rs = r * np.cos(phi), r * np.sin(phi)
        pts[i, 0] = (centre[k, 0] - cd * d[i, 0]) + rc * b0 + rs * c0
        pts[i, 1] = (centre[k, 1] - cd * d[i, 1]) + rc * b1 + rs * c1
        pts[i, 2] = (centre[k, 2] - cd * d[i, 2]) + rc * b2 + rs * c2
        if c == 1:  # one object: every point drawn lies on its disk
            pdf[i] = 1.0 / area[0]
            continue
        pp = pts[i, 0] * pts[i, 0] + pts[i, 1] * pts[i, 1] + pts[i, 2] * pts[i, 2]
        p = 0.0
        for m in range(c):
            pc = pts[i, 0] * centre[m, 0] + pts[i, 1] * centre[m, 1] + pts[i, 2] * centre[m, 2]
            cc = centre[m, 0] * centre[m, 0] + centre[m, 1] * centre[m, 1] + centre[m, 2] * centre[m, 2]
            cdm = d[i, 0] * centre[m, 0] + d[i, 1] * centre[m, 1] + d[i, 2] * centre[m, 2]
            if pp - 2 * pc + cc - cdm * cdm <= radius[m] ** 2 * (1 + 1e-9):
                p += prob[m] / area[m]
        pdf[i] = p
