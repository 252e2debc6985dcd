"""Opal domains in the volume: additively weighted 3-D Voronoi cells, each an FCC crystallite with its
own (111) orientation and sphere diameter.

Method (docs/physics.md section 5.4). Precious opal is a mosaic of ordered domains of silica
spheres grown in the volume (Sanders 1964); Yokota et al. (2024, The Visual Computer) model them as
3-D Voronoi cells. Here seeds are drawn uniformly in the object's volume (rejection sampling in
the bounding box with a ray-parity inside test) and a point p belongs to the cell

    argmin_s  |p - seed_s| - weight_s,

the additively weighted Voronoi diagram (Aurenhammer 1987, "Power diagrams", SIAM J. Comput.
16(1); the additive weight grows a cell by that distance towards its neighbours, so a size
distribution of the weights gives a distribution of domain sizes). A surface point takes the
domain of the cell it lies in, so the pattern is a property of the stone, not of its triangles.

Lookup (:meth:`VolumeDomains.lookup`) is exact: per group (one opal object instance) a
``scipy.spatial.cKDTree`` gives each point its k nearest seeds; the weighted argmin among them is
the true one when the k-th distance minus the group's largest weight is not below the best value
found (no farther seed can do better), and the points where that fails are queried again with
k doubled (the last round is the whole group).

Lattice bending (:meth:`VolumeDomains.lattice_axis`; docs/opal.md "Domain curvature"). A
natural domain is not a perfect crystal: its (111) planes bend across it (a "rolling flash"
sweeps over a patch as the stone turns a few degrees; Sanders 1964, Gaillou et al. 2008). Each
domain s gets a constant gradient of its normal, drawn once per scene from a fixed stream:

    a(p) = normalize(a_s + (beta / h) P_s B_s (p - seed_s)),   P_s = I - a_s a_s^T,

B_s a 3 x 3 matrix of independent N(0, 1/3) entries, h the group's mean seed spacing (estimated
from the mean nearest-neighbour distance of its seeds: for uniform seeds E[d_nn] =
Gamma(4/3) (3 / (4 pi))^(1/3) h = 0.5540 h), beta the bend in radians per spacing. For p at
distance r from the seed along any direction, E[tan^2 of the tilt] = (2/3) (beta r / h)^2 (P_s
keeps two of B_s u's three N(0, 1/3) components); at the seed the normal is the cell's own.

Orientations: 'RANDOM' draws the (111) normal uniformly on the sphere; 'LAYERED' uniformly in
the spherical cap of half-angle ``axis_spread_deg`` about ``preferred_axis`` (cos theta uniform
in [cos spread, 1]) - opal grows in layers, so its domains lean towards one axis. Positions,
weights, axes and diameters come from separate streams of ``SeedSequence(seed)``
(docs/physics.md section 9.3).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..util.enums import DomainOrientation

__all__ = [
    "VolumeDomains",
    "DOMAIN_BEND_DEG",
    "NN_PER_SPACING",
    "bragg_domains",
    "inside_mesh",
    "generate_volume_domains",
    "transform_domains",
    "cells_of",
    "ORIENTATIONS",
]

#: Orientation distributions of the (111) normals.
ORIENTATIONS = tuple(m.name for m in DomainOrientation)
#: Nearest seeds a lookup starts with where the weights differ (doubled for the points where
#: they do not decide; measured: 4 is 20-30 % faster than 2 or 8 on the presets' layouts);
#: unweighted cells need the nearest seed only.
_K_START = 4
#: Uniform seeds' mean nearest-neighbour distance in units of the mean spacing (density^(-1/3)):
#: Gamma(4/3) (3 / (4 pi))^(1/3) (Chandrasekhar 1943, Rev. Mod. Phys. 15, eq. 34 in 3-D).
NN_PER_SPACING = 0.5539602785
#: The bend of a domain's (111) planes, degrees per mean domain spacing, that the opal shading
#: uses (docs/opal.md "Domain curvature": a flash rolls across a patch over a few degrees of tilt).
DOMAIN_BEND_DEG = 10.0
#: The fixed stream of the per-domain bending matrices (docs/physics.md section 9.3).
_BEND_STREAM = 0x0BA1


class _Group:
    """One group's seeds with their k-d tree (built once) and largest weight."""

    def __init__(self, seeds, weight):
        from scipy.spatial import cKDTree

        self.seeds = np.asarray(seeds, np.float64).reshape(-1, 3)
        self.weight = np.asarray(weight, np.float64).reshape(-1)
        self.tree = cKDTree(self.seeds) if len(self.seeds) > 1 else None
        self.wmax = float(self.weight.max()) if len(self.weight) else 0.0

    def argmin(self, points, k_start: int = _K_START) -> np.ndarray:
        """Index (B,) of argmin_s |p - s| - w_s for every point; exact (see the module)."""
        n = len(self.seeds)
        out = np.zeros(len(points), np.int64)
        if n <= 1 or len(points) == 0:
            return out
        todo = np.arange(len(points))
        k = 1 if self.wmax == float(self.weight.min()) else min(k_start, n)  # equal weights: the nearest
        while len(todo):
            d, j = self.tree.query(points[todo], k=k)
            d, j = d.reshape(len(todo), k), j.reshape(len(todo), k)
            val = d - self.weight[j]
            best = np.argmin(val, axis=1)
            rows = np.arange(len(todo))
            out[todo] = j[rows, best]
            if k >= n:
                break
            # no seed beyond the k-th can beat the best: its value is at least d_k - max weight
            decided = d[:, -1] - self.wmax >= val[rows, best]
            todo = todo[~decided]
            k = min(2 * k, n)
        return out


def _weighted_argmin(points, seeds, weight, k_start: int = _K_START) -> np.ndarray:
    """Index (B,) into ``seeds`` of argmin_s |p - s| - w_s for every point; exact (see module)."""
    return _Group(seeds, weight).argmin(np.asarray(points, np.float64).reshape(-1, 3), k_start)


@dataclass(frozen=True)
class VolumeDomains:
    """Volume domains of every opal object of a scene, world space.

    ``seeds`` (S, 3) float64 m, ``weight`` (S,) float64 m (additive: a point p belongs to
    argmin_s |p - seed_s| - weight_s within its group), ``axis`` (S, 3) float32 unit (111)
    normals, ``diameter`` (S,) float32 sphere diameter nm, ``group`` (S,) int32 (one group per
    opal object instance), ``tri_group`` (T,) int32: the group whose cells a triangle lies in
    (-1: the triangle has no domains).
    """

    seeds: np.ndarray
    weight: np.ndarray
    axis: np.ndarray
    diameter: np.ndarray
    group: np.ndarray
    tri_group: np.ndarray
    _members: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __len__(self) -> int:
        return len(self.seeds)

    @property
    def groups(self) -> int:
        return int(self.group.max()) + 1 if len(self.group) else 0

    def _of_group(self, g: int):
        """(members (S_g,) global seed indices, _Group), built on first use and kept."""
        entry = self._members.get(g)
        if entry is None:
            m = np.flatnonzero(self.group == g)
            entry = self._members[g] = (m, _Group(self.seeds[m], self.weight[m]))
        return entry

    def cell(self, points, prim) -> np.ndarray:
        """Global seed index (B,) of each point's cell, -1 where its triangle has no domains."""
        p = np.asarray(points, np.float64).reshape(-1, 3)
        prim = np.asarray(prim, np.int64).reshape(-1)
        out = np.full(len(p), -1, np.int64)
        ok = (prim >= 0) & (prim < len(self.tri_group))
        g = np.full(len(p), -1, np.int64)
        g[ok] = self.tri_group[prim[ok]]
        for gi in np.unique(g[g >= 0]).tolist():  # a loop over opal objects (a handful)
            members, grp = self._of_group(gi)
            if len(members) == 0:
                continue
            sel = np.flatnonzero(g == gi)
            out[sel] = members[grp.argmin(p[sel])]
        return out

    def spacing(self, g: int) -> float:
        """Mean seed spacing h of group ``g`` from its mean nearest-neighbour distance (module);
        0 for a group of fewer than two seeds."""
        key = ("h", g)
        if key not in self._members:
            members, grp = self._of_group(g)
            if len(members) < 2:
                self._members[key] = 0.0
            else:
                d, _ = grp.tree.query(grp.seeds, k=2)
                self._members[key] = float(np.mean(d[:, 1])) / NN_PER_SPACING
        return self._members[key]

    def bend_matrices(self) -> np.ndarray:
        """(S, 3, 3) float64: each domain's B_s, independent N(0, 1/3) entries from a fixed stream."""
        b = self._members.get("B")
        if b is None or len(b) != len(self):
            b = self._members["B"] = np.random.default_rng(_BEND_STREAM).normal(0.0, np.sqrt(1.0 / 3.0),
                                                                                (len(self), 3, 3))
        return b

    def lattice_axis(self, points, prim, bend_deg: float):
        """(axis (B, 3) float64 unit, diameter (B,) float32, found (B,) bool): as :meth:`lookup`,
        with each cell's (111) normal bent across the cell by ``bend_deg`` degrees per mean seed
        spacing (module: a(p) = normalize(a_s + (beta / h) P_s B_s (p - seed_s)))."""
        p = np.asarray(points, np.float64).reshape(-1, 3)
        c = self.cell(p, prim)
        found = c >= 0
        axis = np.zeros((len(c), 3), np.float64)
        diameter = np.zeros(len(c), np.float32)
        if not found.any():
            return axis, diameter, found
        cs = c[found]
        a = np.asarray(self.axis, np.float64)[cs]
        a /= np.maximum(np.linalg.norm(a, axis=1), 1e-30)[:, None]
        beta = np.radians(max(float(bend_deg), 0.0))
        if beta > 0:
            h = np.array([self.spacing(int(g)) for g in range(self.groups)])[np.asarray(self.group)[cs]]
            scale = np.where(h > 0, beta / np.where(h > 0, h, 1.0), 0.0)
            t = np.einsum("bij,bj->bi", self.bend_matrices()[cs], p[found] - np.asarray(self.seeds)[cs])
            t -= np.einsum("ij,ij->i", t, a)[:, None] * a  # P_s: tilt only, across the normal
            a = a + scale[:, None] * t
            a /= np.linalg.norm(a, axis=1)[:, None]
        axis[found] = a
        diameter[found] = np.asarray(self.diameter)[cs]
        return axis, diameter, found

    def lookup(self, points, prim):
        """(axis (B, 3) float32, diameter (B,) float32, found (B,) bool) of the cells the points
        lie in; ``prim`` (B,) is each point's triangle (its group). Not found (a triangle
        without domains, or prim -1): axis 0, diameter 0."""
        c = self.cell(points, prim)
        found = c >= 0
        axis = np.zeros((len(c), 3), np.float32)
        diameter = np.zeros(len(c), np.float32)
        axis[found] = self.axis[c[found]]
        diameter[found] = self.diameter[c[found]]
        return axis, diameter, found


def bragg_domains(domains: "VolumeDomains | None", points, prim, tri_normal, default_diameter):
    """The (111) normal and sphere diameter at hit points, for the BRAGG lattice's shading:
    (axis (B, 3) float32 unit, diameter (B,) float32 nm). Inside a volume domain: the cell's
    normal, turned into the hemisphere of the triangle's normal (an axis: n and -n are the same
    planes), and its diameter; elsewhere (no domains for that triangle) one domain whose planes
    are parallel to the face - the triangle's normal ``tri_normal[prim]`` - and
    ``default_diameter`` (the material's, scalar or (B,))."""
    prim = np.asarray(prim, np.int64).reshape(-1)
    nrm = np.asarray(tri_normal, np.float32)[np.clip(prim, 0, max(len(tri_normal) - 1, 0))]
    diameter = np.broadcast_to(np.asarray(default_diameter, np.float32), prim.shape).copy()
    axis = nrm.astype(np.float32, copy=True)
    if domains is None or len(domains) == 0:
        return axis, diameter
    a, d, found = domains.lookup(points, prim)
    flip = np.sum(a * nrm, axis=1) < 0
    a[flip] *= -1.0
    axis[found] = a[found]
    diameter[found] = d[found]
    return axis, diameter


def cells_of(points, seeds, weight) -> np.ndarray:
    """Cell index (B,) of each point among one object's seeds (the weighted argmin)."""
    return _weighted_argmin(np.asarray(points, np.float64).reshape(-1, 3), np.asarray(seeds, np.float64).reshape(-1, 3),
                            np.asarray(weight, np.float64).reshape(-1))


def inside_mesh(points, vertices, triangles) -> np.ndarray:
    """(N,) bool: whether each point is inside the closed mesh (ray parity along a fixed oblique
    direction, every crossing counted by casting again past the last hit)."""
    from ..accel import build_accelerator

    p = np.asarray(points, np.float64).reshape(-1, 3)
    v = np.asarray(vertices, np.float64).reshape(-1, 3)
    t = np.asarray(triangles, np.int64).reshape(-1, 3)
    if len(p) == 0 or len(t) == 0:
        return np.zeros(len(p), bool)
    acc = build_accelerator(v.astype(np.float32), t.astype(np.int32), "auto", threads=1)
    d = np.array([0.3141592, 0.2718281, 0.9101234])  # oblique: no edge or axis-aligned face lies along it
    d /= np.linalg.norm(d)
    extent = float(np.max(np.ptp(v, axis=0))) or 1.0
    eps = 1e-6 * extent
    parity = np.zeros(len(p), bool)
    origin = p.copy()
    live = np.arange(len(p))
    for _ in range(64):  # crossings per ray: a bounded loop over rounds, not over points
        dirs = np.broadcast_to(d, (len(live), 3))
        h = acc.intersect(origin[live].astype(np.float32), dirs.astype(np.float32))
        hit = h.prim >= 0
        parity[live[hit]] ^= True
        origin[live[hit]] += (h.t[hit].astype(np.float64) + eps)[:, None] * d
        live = live[hit]
        if len(live) == 0:
            break
    return parity


def _sample_inside(vertices, triangles, count: int, rng: np.random.Generator) -> np.ndarray:
    v = np.asarray(vertices, np.float64).reshape(-1, 3)
    lo, hi = v.min(axis=0), v.max(axis=0)
    out = []
    have = 0
    rate = 0.5  # fraction inside, refined from each batch (a cabochon fills ~1/3 of its box)
    for _ in range(200):
        n = int(min(max((count - have) / max(rate, 0.02) * 1.2 + 64, 256), 2_000_000))
        cand = lo + (hi - lo) * rng.random((n, 3))
        ins = inside_mesh(cand, v, triangles)
        rate = max(float(ins.mean()), 1e-3)
        out.append(cand[ins])
        have += int(ins.sum())
        if have >= count:
            break
    pts = np.concatenate(out) if out else np.zeros((0, 3))
    if len(pts) < count:
        raise ValueError("could not place the domain seeds inside the mesh: is it closed (a solid)?")
    return pts[:count]


def _unit(v):
    v = np.asarray(v, np.float64)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def _cap_axes(count: int, axis, spread_deg: float, rng: np.random.Generator) -> np.ndarray:
    """Unit vectors uniform in the cap of half-angle ``spread_deg`` about ``axis`` (180: the sphere)."""
    a = _unit(np.asarray(axis, np.float64).reshape(3))
    if not np.linalg.norm(a) > 0:
        a = np.array([0.0, 0.0, 1.0])
    c0 = np.cos(np.radians(min(max(float(spread_deg), 0.0), 180.0)))
    cos_t = 1.0 - rng.random(count) * (1.0 - c0)
    phi = 2.0 * np.pi * rng.random(count)
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t**2))
    ref = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = _unit(np.cross(a, ref))
    e2 = np.cross(a, e1)
    return (cos_t[:, None] * a + (sin_t * np.cos(phi))[:, None] * e1 + (sin_t * np.sin(phi))[:, None] * e2)


def generate_volume_domains(vertices, triangles, count: int, seed: int = 0, size_spread: float = 0.0,
                            orientation: str = "RANDOM", preferred_axis=(0.0, 0.0, 1.0),
                            axis_spread_deg: float = 15.0, diameter_range=(200.0, 330.0)):
    """``count`` volume domains of the closed mesh (vertices (V, 3), triangles (T, 3), any space):
    (seeds (S, 3) float64, weight (S,) float64, axis (S, 3) float32, diameter (S,) float32).

    Seeds uniform in the volume; ``size_spread`` >= 0: the additive weights are uniform in
    [0, size_spread h) with h = (volume / count)^(1/3) the mean seed spacing (0: plain Voronoi
    cells of similar size; 1: sizes vary by about a factor of two); ``orientation`` 'RANDOM' or
    'LAYERED' (within ``axis_spread_deg`` of ``preferred_axis``); diameters uniform in
    ``diameter_range`` nm. Reproducible from ``seed``: positions, weights, axes and diameters
    are separate streams.
    """
    if orientation not in ORIENTATIONS:
        raise ValueError(f"orientation must be one of {ORIENTATIONS}, got {orientation!r}")
    count = max(int(count), 1)
    ss_pos, ss_w, ss_axis, ss_d = np.random.SeedSequence(int(seed)).spawn(4)
    seeds = _sample_inside(vertices, triangles, count, np.random.default_rng(ss_pos))
    v = np.asarray(vertices, np.float64).reshape(-1, 3)
    t = np.asarray(triangles, np.int64).reshape(-1, 3)
    p = v[t]
    volume = abs(float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum()) / 6.0)
    h = (volume / count) ** (1.0 / 3.0)
    weight = max(float(size_spread), 0.0) * h * np.random.default_rng(ss_w).random(count)
    spread = 180.0 if orientation == "RANDOM" else float(axis_spread_deg)
    axis = _cap_axes(count, preferred_axis, spread, np.random.default_rng(ss_axis))
    lo, hi = sorted(float(x) for x in diameter_range)
    diameter = lo + (hi - lo) * np.random.default_rng(ss_d).random(count)
    return seeds, weight, axis.astype(np.float32), diameter.astype(np.float32)


def transform_domains(matrix, seeds, weight, axis):
    """Object-space domains -> world space under the 4x4 ``matrix``: seeds as points, (111)
    normals as normals (inverse transpose, renormalised), weights scaled by |det|^(1/3) (exact for
    a similarity; a non-uniform scale only approximates the object-space cells)."""
    m = np.asarray(matrix, np.float64).reshape(4, 4)
    a = m[:3, :3]
    s = np.asarray(seeds, np.float64).reshape(-1, 3) @ a.T + m[:3, 3]
    det = float(np.linalg.det(a))
    w = np.asarray(weight, np.float64).reshape(-1) * abs(det) ** (1.0 / 3.0)
    nrm = np.linalg.inv(a).T if det != 0 else a
    ax = _unit(np.asarray(axis, np.float64).reshape(-1, 3) @ nrm.T)
    return s, w, ax.astype(np.float32)
