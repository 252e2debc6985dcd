"""The light pass: paths from the lights through mirrors and glass, deposited as caustics.

The source paper's bidirectional half (Kobayashi & Kawai; docs/physics.md section 4.1): light
paths carry the whole spectrum from each light, are aimed at the objects that can bend light
(mirrors and dielectrics: the *casters*), follow specular reflection and refraction with
Fresnel, dispersion and Russian roulette (transport.SpecularWalker), and where a path that has
been specular at least once lands on a diffuse surface its spectral flux is added to that
surface element of the illumination map (elements.py). Where such a path reaches a grating, the
grating's element records the incoming spectral flux by the direction it came from and its
wavelength band (grating_records.GratingRecords: sparse directional lobes, on elements a pilot
pass sizes where grating flux lands; docs/physics.md section 3.5), for the eye pass to diffract.
Line gratings are casters as well: a path that meets one is diffracted (kind GRATING from
``classify``, the order sampled by core/gratings/order_sampling.py in ``scatter``) and goes on as a
specular path, so the orders land on diffuse surfaces as caustics (docs/physics.md section
3.10). Direct light stays the eye pass's job, so a path that reaches a
diffuse surface or grating first deposits nothing: no double counting. The same landings on plain
diffuse surfaces are also joined to the camera and splatted into a film for that view
(core/integrators/light/camera_splat.py, docs/physics.md section 4.9; ``LightPassResult.splat``), which the eye
pass uses instead of the map where the camera sees such a surface directly. On smooth-shaded casters
the paths bend about the shading normals (transport.py, docs/physics.md section 4.6); deposits
and records stay indexed by the geometric hit (triangle, barycentrics, side).

Aiming (unbiased): casters are grouped into connected objects with bounding spheres. From a
point or spot light, or a point sampled on an area light, a direction is drawn in the cone that
subtends one object's sphere, the object chosen in proportion to its cone's solid angle; the pdf
of a direction is the mixture sum_c P_c [w in cone c] / Omega_c, so overlapping cones are
accounted for. A sun draws a point on the disk one object's sphere casts across its beam, with
the matching mixture pdf per unit area. Lights with a size start on their surface (a sphere) or
in their cone (a sun with an angle), and emissive triangles (mesh_lights.MeshLights) at a point
chosen by area x luminance, each aimed the same way (docs/physics.md section 7.7; the emissive
meshes are one more entry, index L, of the budget). Paths start with weight (emitted radiometric quantity /
pdf / paths of that light), so the map holds flux in W per wavelength sample; lights share the
path budget in proportion to the power they send towards casters. A lamp's or the world's white paths carry
their weight as coefficients over shared spectra (the lamp's spectrum; the map's R, G, B
spectra) until a tint or dispersion needs spectra (transport.Rays.basis, docs/physics.md
section 4.7).

The world (a uniform colour or an environment map, core/lights/environment.py) is one more emitter,
light-pass index L + 1 (after the L lights and the emissive meshes): directions from its distribution, points on the casters'
disks across each direction as for a sun (``_emit_world``, docs/physics.md section 7.9), its
share of the paths by the power it sends through those disks.

Every batch of paths draws its random numbers from its own stream (seed, light pass, light,
batch), and batches add into the map, so the map does not depend on how the work is split.
``LightWork`` is that split: the batches in order and the LANES fixed lanes they are dealt to;
``trace_batch`` traces one batch into any pair of sinks with a ``deposit`` method (the lane's
maps here; a ``DepositLog`` on a Dask worker, replayed into the lane's maps on the client in the
same order, so a distributed map equals this one bit for bit: core/render/distributed.py). With SPLIT
dispersion a batch is walked in pieces of ``wavelengths.SPLIT_CHUNK_RAYS / n`` white paths, so
the n mono paths each becomes at a dispersive glass stay bounded (docs/physics.md section 2.6).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor, wait
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from ...transport import wavelengths
from ...util.blas_threads import one_blas_thread
from .camera_splat import CameraConnection, CameraSplat, SplatBatch
from . import splat_bounce
from ...transport.elements import ElementLayout, IlluminationMap
from ...gratings.records import PILOT_STREAM, GratingRecords, record_layout
from ...util.geometry import compact_indices, group_extrema, orthonormal_basis, triangle_areas
from ...gratings.order_sampling import diffracting, scatter_at_gratings, scattering_materials
from ...lights.sources import AREA_DISK, AREA_RECT, POINT, SPOT, SUN
from ...materials.spectra import DIELECTRIC, DIFFUSE, MIRROR
from ..bragg_shading import BraggShading
from ...transport.walker import GRATING, Hit, Rays, SpecularWalker

__all__ = ["CasterObjects", "caster_objects", "LightTargets", "find_light_targets", "LightPassResult",
           "element_layout", "run_light_pass", "LIGHT_PASS_STREAM", "BATCH_PATHS", "LANES", "LightBatch",
           "LightWork", "trace_batch", "DepositLog", "finish_light_pass"]

LIGHT_PASS_STREAM = 2
BATCH_PATHS = 1 << 15
MAX_OBJECTS = 64
RR_START_DEPTH = 3
RR_SURVIVAL = 0.8
LANES = 2  # fixed partial maps (so the result does not depend on the thread count)
POLL_S = 0.1  # seconds between progress, cancel and time-limit checks


@dataclass(frozen=True)
class CasterObjects:
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


def _cones(origin: np.ndarray, objects: CasterObjects):
    """Per (origin, object): unit axis, cos of the half angle, solid angle. origin (B, 3)."""
    to_c = objects.centre[None, :, :] - origin[:, None, :]
    dist = np.linalg.norm(to_c, axis=2)
    inside = dist <= objects.radius[None, :]
    axis = to_c / np.maximum(dist, 1e-30)[..., None]
    sin2 = np.clip((objects.radius[None, :] / np.maximum(dist, 1e-30)) ** 2, 0, 1)
    cos_max = np.where(inside, -1.0, np.sqrt(1 - sin2))
    omega = 2 * np.pi * (1 - cos_max)
    return axis, cos_max, omega


def _sample_cones(origin, weights, axis, cos_max, omega, rng, u=None):
    """Directions from ``origin`` (B, 3): choose object c with probability weights (B, C)
    (normalised per row), then uniformly in its cone. Returns (dirs, pdf) with the mixture pdf.
    ``u``: the uniform numbers ((B, 1), (B,), (B,)) to use instead of drawing them from rng."""
    b, c = weights.shape
    uni = (rng.random((b, 1)), rng.random(b), rng.random(b)) if u is None else u
    # one origin for every path (a point light): the mixture, the cones' frames and the pdf's
    # cone tests once per object, not once per path
    shared = all(x.strides[0] == 0 for x in (weights, axis, cos_max, omega))
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


def _sample_towards_casters(origin, obj: CasterObjects, rng):
    """``_sample_cones`` from per-path origins (B, 3), each path choosing an object by its cone's
    solid angle: in chunks of CONE_CHUNK paths (bounded temporaries), with the random numbers
    drawn for the whole batch first (the same numbers as one unchunked call)."""
    b = len(origin)
    u = (rng.random((b, 1)), rng.random(b), rng.random(b))
    d = np.empty((b, 3))
    pdf = np.empty(b)
    for s in range(0, b, CONE_CHUNK):  # loop over chunks of a batch, not over paths
        sl = slice(s, min(b, s + CONE_CHUNK))
        axis, cos_max, omega = _cones(origin[sl], obj)
        d[sl], pdf[sl] = _sample_cones(origin[sl], omega, axis, cos_max, omega, None, tuple(x[sl] for x in u))
    return d, pdf


class _LightTrace(SpecularWalker):
    """Light paths: deposit at diffuse surfaces after a specular bounce, Russian roulette."""

    def __init__(self, prepared, rng, illum: IlluminationMap, records: GratingRecords | None,
                 splat: SplatBatch | None = None):
        super().__init__(prepared, rng)
        self.illum = illum
        self.records = records
        self.splat = splat  # the camera connection of the landings (core/integrators/light/camera_splat.py), or None
        self.bounces = None  # core/splat_bounce.BounceLog: the landings continued by a diffuse bounce, or None
        self.deposited = 0
        self.bragg = BraggShading.for_prepared(prepared)  # FCC opal lobes scatter light paths on

    def on_hit(self, rays: Rays, hit: Hit, kind: np.ndarray, rng) -> None:
        if self.records is not None:
            at_grating = self.prepared.gratings.enabled[hit.mat] & (rays.depth >= 1)
            if at_grating.any():
                r, h = rays.take(at_grating), hit.take(at_grating)
                idx, valid = self.records.layout.index(h.prim, h.bu, h.bv, h.front)
                if valid.any():
                    src, at = -r.d[valid], h.p[valid]
                    if r.lam is None:
                        self.records.deposit(idx[valid], r.take(valid).dense_w(self.n), towards_source=src, at=at)
                    else:
                        self.records.deposit(idx[valid], r.w[valid], r.lam[valid], towards_source=src, at=at)
        land = (kind == DIFFUSE) & (rays.depth >= 1)
        if not land.any():
            return
        r, h = rays.take(land), hit.take(land)
        if self.splat is not None:  # the same landings, seen by the camera (docs/physics.md section 4.9)
            self.splat.connect(self.prepared, r, h, self.n)
            if self.bounces is not None:  # and one diffuse bounce on, to the camera (section 4.11)
                self.bounces.add(self.prepared, r, h)
        idx, valid = self.illum.layout.index(h.prim, h.bu, h.bv, h.front)
        if not valid.any():
            return
        self.deposited += int(valid.sum())
        if r.lam is None:
            self.illum.deposit(idx[valid], r.dense_w(self.n)[valid] if r.basis is None else r.w[valid], basis=r.basis)
        else:
            self.illum.deposit(idx[valid], r.w[valid], r.lam[valid])

    def classify(self, rays: Rays, hit: Hit, kind: np.ndarray, rng) -> np.ndarray:
        """Paths a grating diffracts (core/gratings/order_sampling.py, docs/physics.md section 3.10) are
        kind GRATING: they neither bounce off the base nor land on it."""
        if not self.prepared.gratings.any:
            return kind
        return np.where(diffracting(self.prepared, hit, kind, rng), GRATING, kind)

    def scatter(self, rays: Rays, hit: Hit, kind: np.ndarray, can_bounce: np.ndarray, rng, shaded=None) -> Rays | None:
        """The orders of the gratings' paths (mono rays; section 3.10): diffracted paths are
        specular ones, so they deposit caustics where they land on diffuse surfaces."""
        if rays.basis is not None and (self.bragg is not None or self.prepared.gratings.any):
            rays = rays.dense()  # the opal lobes and the gratings' orders weigh spectra
        opal = None if self.bragg is None else self.bragg.scatter_light(rays, hit, can_bounce, rng)  # FCC opal lobes
        sel = (kind == GRATING) & can_bounce
        if not sel.any():
            return opal
        orders = scatter_at_gratings(self.prepared, rays.take(sel), hit.take(sel), rng, self.split_white)
        if opal is None or not len(opal):
            return orders
        if orders is None or not len(orders):
            return opal
        if (orders.lam is None) == (opal.lam is None):
            return Rays.concat(opal, orders)
        self.spawn(orders)  # white paths' orders are mono rays: traced with the mono population
        return opal

    def survives(self, rays: Rays, rng) -> np.ndarray:
        ok = rays.depth < self.prepared.settings.max_bounces
        deep = ok & (rays.depth >= RR_START_DEPTH)
        if deep.any():
            # Russian roulette: survivors carry 1 / survival more, so the expectation is unchanged
            killed = deep & (rng.random(len(rays)) >= RR_SURVIVAL)
            ok &= ~killed
            if rays.w is not None:
                rays.w[deep & ~killed] /= np.float32(RR_SURVIVAL)
        return ok


@dataclass(frozen=True)
class LightTargets:
    """What the light pass aims at and who receives its light (part of the prepared scene)."""

    caster_mask: np.ndarray    # (T,) bool: mirror, glass and grating triangles (light bends or diffracts there)
    receiver_mask: np.ndarray  # (T,) bool: diffuse triangles (caustics land there)
    grating_mask: np.ndarray   # (T,) bool: grating triangles (records land there)
    objects: CasterObjects     # bounding spheres of the connected caster objects
    budget: np.ndarray         # (L,) estimated luminous power each light sends towards the casters
    mesh_budget: float = 0.0   # the same for all emissive triangles together (mesh_lights.MeshLights)
    world_budget: float = 0.0  # the same for the world (uniform or map)

    @property
    def needed(self) -> bool:
        """Some light reaches a caster, and something can receive what comes out of it."""
        return (bool(np.any(self.budget > 0)) or self.mesh_budget > 0 or self.world_budget > 0) and bool(
            self.receiver_mask.any() or self.grating_mask.any())

    @property
    def budgets(self) -> np.ndarray:
        """(L + 2,) the lights' budgets, then the emissive meshes' (light-pass index L) and the
        world's (index L + 1)."""
        return np.append(self.budget, [self.mesh_budget, self.world_budget])


def find_light_targets(vertices, triangles, tri_material, materials, gratings, lights, conv,
                       light_paths: int = 1, mesh_lights=None, world_spectrum=None, microfacet=None) -> LightTargets:
    """The light pass's targets for a scene (prepared materials, gratings, lights, emissive
    meshes, and ``world_spectrum`` (n,) the world's mean radiance, or None: a black world).
    Without light paths or any emitter there is nothing to aim, so the casters are not grouped
    at all. Rough and layered mirrors and glass (``microfacet`` (M,) bool, bsdf.microfacet_materials;
    None: none) are not casters: the eye pass shades them, and a light path ends there. Line
    gratings are casters: their orders go on (docs/physics.md section 3.10)."""
    mk = materials.kind[tri_material] if len(tri_material) else np.zeros(0, np.int32)
    grating = gratings.enabled[tri_material] if len(tri_material) else np.zeros(0, bool)
    caster = np.isin(mk, [MIRROR, DIELECTRIC])
    if microfacet is not None and len(tri_material):
        caster &= ~np.asarray(microfacet)[tri_material]
    if len(tri_material):
        caster |= scattering_materials(gratings, materials.kind, microfacet)[tri_material]
    if getattr(gratings, "bragg", None) is not None and len(tri_material):  # opal flashes light the table
        caster |= gratings.bragg[tri_material]
    world_lum = 0.0 if world_spectrum is None else float(np.asarray(world_spectrum, np.float64) @ conv.cmf_weights[:, 1])
    emitters = len(lights) > 0 or mesh_lights is not None or world_lum > 0
    aimed = caster if light_paths > 0 and emitters else np.zeros_like(caster)
    objects = caster_objects(vertices, triangles, aimed)
    # the world's power through the casters' disks: integral of L over the sphere x sum pi r^2
    world_budget = 4 * np.pi * world_lum * float(np.sum(np.pi * objects.radius**2)) if len(objects) else 0.0
    # a black diffuse surface (an Emission-only material) reflects no caustic: not a receiver
    receiver = mk == DIFFUSE
    if len(tri_material):
        receiver &= (np.asarray(materials.reflectance).max(axis=1) > 0)[tri_material]
    return LightTargets(caster, receiver, grating, objects, _light_budget(lights, objects, conv),
                        _mesh_light_budget(mesh_lights, objects), world_budget)


def _light_budget(lights, obj: CasterObjects, conv) -> np.ndarray:
    """Estimated luminous power each light sends towards the casters (0: none)."""
    out = np.zeros(len(lights))
    if len(obj) == 0:
        return out
    lum = lights.spectrum @ conv.cmf_weights[:, 1].astype(np.float32)
    for li in range(len(lights)):  # loop over lights
        k = int(lights.kind[li])
        if k == SUN:
            out[li] = lum[li] * np.sum(np.pi * obj.radius**2)
            continue
        axis, cos_max, omega = _cones(lights.position[li][None, :], obj)
        omega = omega[0]
        if k == SPOT:  # objects entirely outside the spot's cone get nothing
            ang = np.arccos(np.clip(axis[0] @ lights.direction[li], -1, 1))
            half = np.arccos(np.clip(cos_max, -1, 1))
            omega = np.where(ang - half > np.arccos(lights.cos_half_spot[li]), 0.0, omega)
        if k in (AREA_RECT, AREA_DISK):
            front = (obj.centre - lights.position[li]) @ lights.direction[li] > -obj.radius
            extent = np.hypot(lights.size_u[li], lights.size_v[li])
            omega = np.where(front, omega, 0.0)
            out[li] = lum[li] * lights.area[li] * np.sum(omega) / np.pi if extent > 0 else 0.0
            continue
        out[li] = lum[li] * np.sum(omega)
    return out


@dataclass(frozen=True)
class LightPassResult:
    """What the light pass hands to the eye pass; ``key`` is the prepared scene's it belongs to."""

    caustics: IlluminationMap | None          # flux on diffuse elements, or None (no light pass)
    grating_records: GratingRecords | None    # directional flux lobes at grating elements, or None
    stats: Mapping[str, float]                # light_paths, light_deposits, light_rays, elements, light_pass_s
    warnings: tuple[str, ...]
    cancelled: bool
    key: int
    splat: CameraSplat | None = None  # the paths' camera connection (core/integrators/light/camera_splat.py), or None: off

    @classmethod
    def skipped(cls, prepared) -> "LightPassResult":
        return cls(None, None, MappingProxyType({}), (), False, prepared.key)


def element_layout(prepared, n_paths: int, mask, what: str = "caustic") -> tuple[ElementLayout, str]:
    """Elements sized for the path budget: about 16 deposits per element if the paths spread
    over all receiving area (caustics concentrate them, and the eye pass's lookup filters over
    neighbouring elements), capped so each lane's map stays under ~32 M floats (128 MB; the
    LANES partial maps together ~256 MB at most). Returns (layout, warning or "") - the warning
    says when the cap made the user's element size coarser, or when even one element pair per
    triangle is over the cap (then the map is empty: no caustics on those surfaces, said aloud)."""
    v, t = prepared.scene.vertices, prepared.scene.triangles
    mask = np.asarray(mask, bool)
    area = triangle_areas(v, t)  # once: the search below only recounts
    size = float(prepared.settings.element_size or 0.0)
    target = size * size if size > 0 else area[mask].sum() / max(n_paths / 16.0, 1.0)
    cap = 32_000_000 // max(prepared.grid.n, 1)
    if 2 * int(mask.sum()) > cap:
        return (ElementLayout.from_areas(area, np.zeros_like(mask), 1.0),
                f"{int(mask.sum())} receiving triangles are too many for the {what} map ({cap // 2} at most at "
                f"{prepared.grid.n} wavelengths): light through mirrors and glass is not deposited on them "
                "(a coarser wavelength step allows more)")
    asked = target
    while True:
        k = ElementLayout.subdivisions(area, mask, target)
        if int((2 * k * k).sum()) <= cap:
            warning = ""
            if target > asked * 1.01 and size > 0:
                warning = (f"element size {size * 1000:.1f} mm needs more memory than the map allows: "
                           f"using {np.sqrt(target) * 1000:.1f} mm (a coarser wavelength step allows finer)")
            return ElementLayout.from_areas(area, mask, target), warning
        target *= 2.0  # terminates: with k = 1 everywhere the count is 2 * receivers <= cap


def _record_layout(prepared, n_paths: int, mask) -> tuple[ElementLayout, str, dict]:
    """Grating-record elements: of the user's element size if set, else sized by where the
    grating flux lands, from a pilot pass on its own stream (grating_records.record_layout,
    docs/physics.md section 3.5). Returns (layout, warning or "", pilot stats)."""
    if float(prepared.settings.element_size or 0.0) > 0 or n_paths <= 0:
        layout, warning = element_layout(prepared, n_paths, mask, "grating-record")
        return layout, warning, {}

    def trace(light, batch, start, light_paths, illum, records):
        trace_batch(prepared, LightBatch(light, batch, start, light_paths), illum, records, stream=PILOT_STREAM)

    return record_layout(prepared, n_paths, mask, trace, BATCH_PATHS)


@dataclass(frozen=True)
class LightBatch:
    """One batch of light paths: ``paths`` paths of light ``light`` (its ``batch``-th), starting at
    path ``start`` of that light's ``light_paths``; its random stream is
    SeedSequence([seed, LIGHT_PASS_STREAM, light, batch])."""

    light: int
    batch: int
    start: int
    light_paths: int

    @property
    def paths(self) -> int:
        return min(BATCH_PATHS, self.light_paths - self.start)


@dataclass(frozen=True)
class LightWork:
    """The light pass of one prepared scene cut into batches, and the lanes they are dealt to.

    ``batches`` interleave the lights (ordered by how far into its own light each batch is), so
    a pass stopped early has sampled every light alike; lane k holds batches k, k + LANES, ...
    in that order, and its maps are the batches' deposits added in that order. A pure function
    of the prepared scene and the path count: every machine computes the same one.
    """

    layout: ElementLayout                 # caustic map elements (on diffuse receivers)
    record_layout: ElementLayout | None   # grating record elements, or None without gratings
    warning: str                          # from element_layout, or ""
    batches: tuple[LightBatch, ...]
    total: int                            # paths planned
    record_info: Mapping[str, float] = field(default_factory=dict)  # the record layout's pilot pass

    @classmethod
    def of(cls, prepared, n_paths: int | None = None) -> "LightWork":
        n_paths = int(prepared.settings.light_paths if n_paths is None else n_paths)
        targets: LightTargets = prepared.light_targets
        layout, warning = element_layout(prepared, n_paths, targets.receiver_mask)
        rec_layout, rec_warning, rec_info = (_record_layout(prepared, n_paths, targets.grating_mask)
                                             if targets.grating_mask.any() else (None, "", {}))
        warning = "; ".join(dict.fromkeys(w for w in (warning, rec_warning) if w))
        budgets = targets.budgets  # the lights, then the emissive meshes (index L), the world (L + 1)
        share = budgets / max(budgets.sum(), 1e-300)
        paths_per_light = np.floor(share * n_paths).astype(np.int64)
        jobs = [LightBatch(li, bi, start, int(n_l)) for li, n_l in enumerate(paths_per_light)
                for bi, start in enumerate(range(0, int(n_l), BATCH_PATHS))]
        jobs.sort(key=lambda j: (j.start / max(j.light_paths, 1), j.light))
        return cls(layout, rec_layout, warning, tuple(jobs), int(paths_per_light.sum()), MappingProxyType(rec_info))

    def lane(self, k: int) -> tuple[int, ...]:
        """Indices into ``batches`` of lane k, in the order its maps add them."""
        return tuple(range(k, len(self.batches), LANES))

    def empty_maps(self, n: int) -> tuple[IlluminationMap, GratingRecords | None]:
        """One lane's (caustic map, grating records), zero."""
        return (IlluminationMap.empty(self.layout, n),
                GratingRecords.empty(self.record_layout, n) if self.record_layout else None)


def trace_batch(prepared, job: LightBatch, illum, records, stream: int = LIGHT_PASS_STREAM, splat=None) -> dict:
    """Trace one batch of light paths, depositing into ``illum`` and ``records`` (objects with a
    ``layout`` and IlluminationMap's ``deposit``: maps, or DepositLogs; ``records`` None
    without gratings). ``stream``: the random stream id (the records' pilot pass has its own).
    ``splat``: where the batch's camera splats go (an object with CameraSplat's ``add``: a
    lane's film or a camera_splat.SplatLog), or None: no camera connection.
    Returns its counts: paths, deposits, rays."""
    seed = int(prepared.settings.seed)
    b = job.paths
    rng = np.random.default_rng(np.random.SeedSequence([seed, stream, job.light, job.batch]))
    n = prepared.grid.n
    if job.light == len(prepared.lights):  # the emissive meshes: a spectrum per path
        o, d, coeff = _emit_mesh(prepared, b, rng)
        basis = None
    elif job.light > len(prepared.lights):  # the world: coefficients over its basis spectra
        o, d, coeff, basis = _emit_world(prepared, b, rng)
    else:  # a light: a scalar per path times the light's spectrum
        o, d, weight = _emit(prepared, job.light, b, rng)
        coeff, basis = weight[:, None], prepared.lights.spectrum[job.light][None, :]
    live = coeff.max(axis=1) > 0
    w = (coeff[live] / float(job.light_paths)).astype(np.float32)
    if basis is not None and len(basis) >= n:  # no fewer coefficients than samples: plain spectra
        w, basis = (w @ basis).astype(np.float32), None
    m = int(live.sum())
    rays = Rays(o[live].astype(np.float32), d[live].astype(np.float32), np.zeros(m, np.int64),
                w, None, np.zeros(m, np.int32), rng.random(m),
                basis=None if basis is None else np.ascontiguousarray(basis, np.float32))
    connection = CameraConnection.of(prepared) if splat is not None else None
    batch = SplatBatch(connection) if connection is not None else None
    tr = _LightTrace(prepared, rng, illum, records, batch)
    bounce_rng = None
    if batch is not None and splat_bounce.enabled(prepared):
        tr.bounces = splat_bounce.BounceLog(prepared)
        # the continued landings (core/integrators/light/splat_bounce.py) draw from a stream of their own, so the
        # map and the direct splats are those of the same seed without them
        bounce_rng = np.random.default_rng(np.random.SeedSequence([seed, stream, job.light, job.batch, 1]))
    # SPLIT: the batch's white paths in pieces (core/wavelengths.split_chunks), so the mono paths
    # they become stay bounded, and each piece's camera splats are summed per pixel before the
    # next piece (a loop over a batch's few pieces, drawing the batch's stream one after another)
    chunks = wavelengths.split_chunks(prepared, m)
    shadow = 0
    for c in [slice(0, m)] if chunks is None else chunks:
        tr.walk(rays if chunks is None else rays.take(np.arange(c.start, c.stop)), tr.empty_mono())
        if tr.bounces is not None:  # the piece's landings, one diffuse bounce on
            tr.rays_cast += splat_bounce.trace_bounces(prepared, tr.bounces, tr.splat, bounce_rng)
            tr.bounces = splat_bounce.BounceLog(prepared)
        if tr.splat is not None:
            splat.add(*tr.splat.finish())
            shadow += tr.splat.shadow_rays
            tr.splat = SplatBatch(connection)
    return {"paths": b, "deposits": tr.deposited, "rays": tr.rays_cast + shadow}


class DepositLog:
    """A sink that records ``deposit`` calls instead of adding them, for ``replay`` into a map:
    the same additions in the same order, so the map is the one direct deposits make."""

    def __init__(self, layout: ElementLayout | None):
        self.layout = layout
        self.calls: list[tuple] = []  # (elements, flux, lam, towards_source, at, basis), in call order

    def deposit(self, elements, flux, lam=None, towards_source=None, at=None, basis=None) -> None:
        if len(elements):
            self.calls.append((elements, flux, lam, towards_source, at, basis))

    def replay(self, target: IlluminationMap) -> None:
        self.replay_calls(self.calls, target)

    @staticmethod
    def replay_calls(calls, target: IlluminationMap) -> None:
        """Add recorded ``calls`` (a DepositLog's ``calls``, e.g. sent back by a worker) to ``target``."""
        for elements, flux, lam, towards_source, at, basis in calls:
            if at is None:  # caustic maps: no points, no directions; perhaps coefficients over basis spectra
                target.deposit(elements, flux, lam, basis=basis)
            else:  # grating records
                target.deposit(elements, flux, lam, towards_source, at=at)


def finish_light_pass(prepared, work: LightWork, maps, counts, t0: float, timed_out: bool = False,
                      cancelled: bool = False, splats=None) -> LightPassResult:
    """The LightPassResult of lanes' ``maps`` [(illum, records)], ``counts`` [dict] and camera
    ``splats`` [CameraSplat] (None: off): the lanes summed in lane order, rescaled by planned /
    traced paths after a time limit."""
    illum, records = maps[0]
    for extra_illum, extra_records in maps[1:]:
        illum += extra_illum
        if records is not None:
            records += extra_records
    splat = None
    if splats:
        splat = splats[0]
        for extra in splats[1:]:
            splat += extra
    total = work.total
    traced = sum(c["paths"] for c in counts)
    warnings = [work.warning] if work.warning else []
    if timed_out and not cancelled:
        if traced and traced < total:
            scale = np.float32(total / traced)
            illum.flux *= scale
            if records is not None:
                records.scale(scale)
            if splat is not None:
                splat.image *= scale
        warnings.append(f"time limit reached during the light pass: caustics from {traced / 1e6:.2f} M of "
                        f"{total / 1e6:.2f} M light paths")
    stats = {"light_paths": traced, "light_deposits": sum(c["deposits"] for c in counts),
             "light_rays": sum(c["rays"] for c in counts), "elements": work.layout.total,
             "light_pass_s": time.perf_counter() - t0}
    if records is not None:
        stats.update(records.stats())
        stats.update(work.record_info)
    if cancelled:
        stats["cancelled"] = True
    return LightPassResult(illum, records, MappingProxyType(stats), tuple(warnings), cancelled, prepared.key, splat)


@one_blas_thread()  # the lanes are the parallelism (core/util/blas_threads.py)
def run_light_pass(prepared, n_paths: int | None = None, progress=None, should_cancel=None,
                   deadline: float | None = None) -> LightPassResult:
    """Run the light pass over ``prepared`` (``n_paths``: default the settings' light paths).

    The batches are dealt to LANES fixed lanes (LightWork: batch j to lane j % LANES), each with
    its own maps, run on up to ``prepared.threads`` threads and summed in lane order at the end,
    so the result does not depend on the number of threads. ``progress`` and ``should_cancel``
    are called from the calling thread only (every POLL_S seconds at most; a lane stops at its
    next batch). ``deadline``: a ``time.perf_counter()`` time; the pass stops there and scales
    what it deposited by planned / traced paths (batches of all lights are interleaved, so an
    early stop has traced every light in about the same proportion), with a warning.
    """
    t0 = time.perf_counter()
    work = LightWork.of(prepared, n_paths)
    total = work.total
    maps = [work.empty_maps(prepared.grid.n) for _ in range(LANES)]
    counts = [dict(paths=0, deposits=0, rays=0) for _ in range(LANES)]
    connection = CameraConnection.of(prepared)  # the camera splat (core/integrators/light/camera_splat.py), or None: off
    splats = [connection.empty() for _ in range(LANES)] if connection is not None else None
    stop = threading.Event()
    cancelled = False

    def run_lane(k):
        illum, records = maps[k]
        for j in work.lane(k):  # bounded memory: fixed batches
            if stop.is_set():
                return
            done = trace_batch(prepared, work.batches[j], illum, records,
                               splat=None if splats is None else splats[k])
            for name, value in done.items():
                counts[k][name] += value

    threads = max(1, min(LANES, prepared.threads))
    timed_out = False
    with ThreadPoolExecutor(max_workers=threads) as pool:
        futures = [pool.submit(run_lane, k) for k in range(LANES)]
        while True:
            done_set, pending = wait(futures, timeout=POLL_S)
            done = sum(c["paths"] for c in counts)
            if progress:
                progress(done / max(total, 1), f"light pass: {done / 1e6:.2f} M of {total / 1e6:.2f} M paths")
            if not pending:
                break
            if should_cancel and should_cancel():
                stop.set()
                cancelled = True
            if deadline is not None and time.perf_counter() > deadline and not stop.is_set():
                stop.set()
                timed_out = True
        for f in futures:
            f.result()  # re-raise a worker's exception here
    return finish_light_pass(prepared, work, maps, counts, t0, timed_out, cancelled, splats)


def _emit(prepared, li: int, b: int, rng):
    """b path starts from light li: origins, unit directions, scalar weights (1 / pdf, times
    the geometric terms; the light's spectrum is applied by the caller)."""
    lights, obj = prepared.lights, prepared.light_targets.objects
    k = int(lights.kind[li])
    if k == SUN and lights.sun_half[li] > 0:
        return _emit_sun_cone(prepared, li, b, rng)
    if k in (POINT, SPOT) and lights.radius[li] > 0:
        return _emit_sized_point(prepared, li, b, rng)
    if k == SUN:
        d = np.broadcast_to(lights.direction[li], (b, 3))
        pts, pdf = _caster_disk_points(obj, d, rng)
        return pts - _far_distance(prepared) * d, d.copy(), np.where(pdf > 0, 1.0 / np.maximum(pdf, 1e-300), 0.0)
    if k in (POINT, SPOT):
        origin = np.broadcast_to(lights.position[li], (b, 3))
        axis, cos_max, omega = _cones(lights.position[li][None, :], obj)
        axis, cos_max, omega = (np.broadcast_to(x, (b,) + x.shape[1:]) for x in (axis, cos_max, omega))
        d, pdf = _sample_cones(origin, omega, axis, cos_max, omega, rng)
        weight = 1.0 / np.maximum(pdf, 1e-300)  # intensity (in the spectrum) / pdf
        if k == SPOT:
            from ...lights.sources import _smoothstep

            cos_axis = d @ lights.direction[li]
            ch, sm = lights.cos_half_spot[li], lights.spot_smooth[li]
            cone = (cos_axis > ch).astype(np.float64)
            if sm > 0:
                cone = cone * _smoothstep((cos_axis - ch) / sm)
            weight = weight * cone
        return np.array(origin), d, weight
    # area lights: a uniform point on the emitter, then a direction towards an object
    r1, r2 = rng.random(b), rng.random(b)
    if k == AREA_RECT:
        a, c = (r1 - 0.5) * lights.size_u[li], (r2 - 0.5) * lights.size_v[li]
    else:
        rad, phi = np.sqrt(r1), 2 * np.pi * r2
        a, c = 0.5 * lights.size_u[li] * rad * np.cos(phi), 0.5 * lights.size_v[li] * rad * np.sin(phi)
    origin = lights.position[li] + a[:, None] * lights.axis_u[li] + c[:, None] * lights.axis_v[li]
    d, pdf = _sample_towards_casters(origin, obj, rng)
    cos_l = d @ lights.direction[li]
    # radiance (in the spectrum) * cos * area / pdf(direction)   (pdf of the point: 1 / area)
    weight = np.where(cos_l > 0, cos_l * lights.area[li] / np.maximum(pdf, 1e-300), 0.0)
    return origin + prepared.offset_base * d, d, weight


def _far_distance(prepared) -> float:
    """Sun paths start this far from the origin: well outside the scene, in its own units (an
    absolute distance would swamp a millimetre scene's coordinates in float32)."""
    return 4.0 * (float(np.max(np.abs(prepared.scene.vertices))) + prepared.extent)


def _caster_disk_points(obj: CasterObjects, d: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray]:
    """Points for parallel light along unit directions d (B, 3): an object chosen by the area of
    the disk its bounding sphere casts across d, a uniform point on that disk (in the plane
    through the origin normal to d), and the mixture pdf per unit area over all objects' disks
    (they overlap for some d). The suns' and the world's path starts share it."""
    b = len(d)
    area = np.pi * obj.radius**2
    prob = area / area.sum()
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


def _emit_sun_cone(prepared, li: int, b: int, rng):
    """A sun with an angle: a direction uniform in its cone (pdf 1 / (2 pi (1 - cos h))), then
    a point on the disk one caster's sphere casts across that direction (object chosen by its
    disk area), with the mixture pdf per unit area. Weight = (radiance / S) / (pdf_dir pdf_area)
    = g_sun / pdf_area with g_sun = 2 / (1 + cos h) (docs/physics.md section 7.7)."""
    from ...lights.sources import _sample_cone

    lights, obj = prepared.lights, prepared.light_targets.objects
    omc = float(lights.sun_omc[li])
    d = _sample_cone(lights.direction[li], omc, rng, b)  # travel directions (B, 3)
    pts, pdf = _caster_disk_points(obj, d, rng)
    weight = np.where(pdf > 0, (2.0 / (2.0 - omc)) / np.maximum(pdf, 1e-300), 0.0)
    return pts - _far_distance(prepared) * d, d, weight


def _emit_sized_point(prepared, li: int, b: int, rng):
    """A point or spot light with a radius: a uniform point on its sphere (pdf 1 / (4 pi r^2)),
    then a direction towards a caster (the mixture cone pdf), outward only. Radiance I / (pi r^2)
    (in the spectrum: I), so weight = 4 cos_l / pdf_dir, times the spot mask along the direction
    (docs/physics.md section 7.7). A soft-falloff light (a disk facing each shading point) is
    emitted as the sphere of the same radius: the same intensity, and the same cone seen from a
    caster to first order in r / distance."""
    from ...lights.sources import _sample_cone, _spot_mask

    lights, obj = prepared.lights, prepared.light_targets.objects
    r = float(lights.radius[li])
    nrm = _sample_cone(np.array([0.0, 0.0, 1.0]), 2.0, rng, b)  # uniform on the sphere
    q = lights.position[li] + r * nrm
    d, pdf = _sample_towards_casters(q, obj, rng)
    cos_l = np.einsum("ij,ij->i", d, nrm)
    weight = np.where((cos_l > 0) & (pdf > 0), 4.0 * cos_l / np.maximum(pdf, 1e-300), 0.0)
    if int(lights.kind[li]) == SPOT:
        weight = weight * _spot_mask(lights, li, d)
    return q + prepared.offset_base * d, d, weight


def _emit_mesh(prepared, b: int, rng):
    """Paths from the emissive triangles (prepared.mesh_lights): a triangle by area x luminance
    and a uniform point on it (area pdf p_A), a direction towards a caster (mixture cone pdf,
    either side: the emitters are two-sided). Returns origins, directions and spectral weights
    (B, n) = L_e |cos_l| / (p_A pdf_dir) (docs/physics.md section 7.7)."""
    ml, obj = prepared.mesh_lights, prepared.light_targets.objects
    q, j, pa = ml.sample_points(rng, b)
    d, pdf = _sample_towards_casters(q, obj, rng)
    n = ml.normal[j]
    cos_s = np.einsum("ij,ij->i", d, n)
    scalar = np.where((pdf > 0) & (cos_s != 0), np.abs(cos_s) / np.maximum(pa * pdf, 1e-300), 0.0)
    tri = ml.tri[j]
    emission = prepared.materials.emission[prepared.tri_material[tri]]
    eps = prepared.tri_offset[tri].astype(np.float64)
    origin = q + (np.sign(cos_s) * eps)[:, None] * n  # off the emitter, on the side the path leaves
    return origin, d, emission * scalar[:, None]


def _mesh_light_budget(mesh_lights, obj: CasterObjects, max_emitters: int = 16384) -> float:
    """Estimated luminous power the emissive triangles send towards the casters, as for area
    lights: sum over triangles of Y A Omega / pi (Omega: the casters' cones from the triangle's
    centroid). Over at most ``max_emitters`` triangles (an evenly spaced subset, rescaled)."""
    if mesh_lights is None or len(obj) == 0:
        return 0.0
    e = len(mesh_lights)
    step = max(1, -(-e // max_emitters))
    sel = np.arange(0, e, step)
    centroid = mesh_lights.v0[sel] + (mesh_lights.e1[sel] + mesh_lights.e2[sel]) / 3.0
    _, _, omega = _cones(centroid, obj)
    part = float(np.sum(mesh_lights.weight[sel] * omega.sum(axis=1)) / np.pi)
    return part * float(mesh_lights.weight.sum()) / max(float(mesh_lights.weight[sel].sum()), 1e-300)


def _emit_world(prepared, b: int, rng):
    """b path starts from the world (docs/physics.md section 7.9): a direction w towards the sky
    from the map's distribution (uniform over the sphere for a uniform world), then a point on
    the disk one caster object's bounding sphere casts across w (the object chosen by disk
    area, as for a SUN), the path starting far out along w and travelling along -w. Returns
    origins, directions, and the spectral weights L(w) / pdf(w) / pdf_A(point) (the flux of the
    world's radiance through the disks, unbiased: no clamping, no cut-off) as coefficients
    (B, k) over basis spectra (k, n): a uniform world's spectrum (k = 1), or for a map the
    spectra of pure red, green and blue (k = 3), since the RGB-to-illuminant upsampling
    (spectrum.SpectralConverter.illuminant_from_rgb: max(rgb) times a basis combination of
    rgb / max(rgb)) is linear in non-negative RGB."""
    obj = prepared.light_targets.objects
    env = prepared.environment
    if env is None:  # uniform world: directions uniform on the sphere
        z = 1.0 - 2.0 * rng.random(b)
        phi = 2 * np.pi * rng.random(b)
        s = np.sqrt(np.maximum(0.0, 1.0 - z * z))
        towards_sky = np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)
        coeff = np.full((b, 1), 4 * np.pi)
        basis = prepared.world_spectrum.astype(np.float64)[None, :]
    else:
        towards_sky, pdf, rgb = env.sample(rng.random(b), rng.random(b))
        inv = np.where(pdf > 0, 1.0 / np.where(pdf > 0, pdf, 1.0), 0.0)
        coeff = np.maximum(rgb.astype(np.float64), 0.0) * inv[:, None]
        basis = prepared.conv.illuminant_from_rgb(np.eye(3))  # (3, n): pure R, G, B
    pts, pdf_a = _caster_disk_points(obj, towards_sky, rng)
    o = pts + _far_distance(prepared) * towards_sky
    weight = np.where(pdf_a > 0, 1.0 / np.maximum(pdf_a, 1e-300), 0.0)
    return o, -towards_sky, coeff * weight[:, None], basis
