"""Geometry: evaluated objects -> object-space triangles, their instances -> world-space arrays.

A mesh is read with ``foreach_get`` into NumPy (:mod:`..mesh_io`; no Python loop per triangle or
vertex), once per distinct evaluated mesh however many instances share it: linked duplicates,
collection and vertex instances, geometry-nodes instances. The instances of one mesh with one
set of material slots are transformed together in one vectorised product (:func:`transform`);
mirrored instances get their winding flipped. Grating faces also get an object-space grating
vector (:func:`tangents`: the UV map's U direction, the local X axis or the opal tools' face
attribute) and, where the mesh has the period attribute, a per-triangle period
(:func:`periods`). Smooth-shaded meshes carry their per-corner shading normals as Cycles shades
with them (:func:`read_corner_normals`: Blender's ``Mesh.corner_normals``, which already
account for flat and smooth faces, sharp edges, "Smooth by Angle" and custom split normals),
taken to world space with the inverse transpose of each instance's matrix
(:func:`world_corner_normals`); a fully flat mesh carries none.
Textured materials get per-corner texture coordinates (a UV map, or Generated:
object space over the mesh's texture space) and, for normal maps, MikkTSpace tangents
(:func:`read_corners`, :func:`flatten_corners`; docs/physics.md section 13).

:class:`MeshCache` keeps the meshes read between exports of one depsgraph (a rendered viewport
re-exports after every change), dropping those whose geometry changed
(:meth:`MeshCache.invalidate` with ``depsgraph.updates``); transforms, materials and lights are
re-read on every export.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from ...core.util.geometry import triangle_normals
from ...core.scene.checks import SceneError
from ..mesh_io import GRATING_ATTRIBUTE, PERIOD_ATTRIBUTE, attribute_ok, foreach

__all__ = [
    "GEOMETRY_TYPES",
    "UNSUPPORTED_GEOMETRY",
    "is_surface_instance",
    "element_count",
    "hair_systems",
    "strand_count",
    "MeshData",
    "read_mesh",
    "wants_uv",
    "mesh_for",
    "tangents",
    "periods",
    "read_corner_normals",
    "world_corner_normals",
    "transform",
    "subset",
    "MeshCache",
    "SceneMeshes",
    "flatten",
    "read_corners",
    "flatten_corners",
]

GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META"}
UNSUPPORTED_GEOMETRY = {"CURVES", "POINTCLOUD", "VOLUME", "GREASEPENCIL", "GPENCIL"}


def element_count(ob) -> int:
    """Strands of a hair curves object, points of a point cloud (0 for other kinds), for the
    warning that says what was skipped."""
    data = ob.data
    for name in ("curves", "points"):
        coll = getattr(data, name, None)
        if coll is not None:
            try:
                return len(coll)
            except TypeError:
                return 0
    return 0


def hair_systems(ob) -> list:
    """The hair particle systems of an evaluated object that Cycles would render as strands."""
    out = []
    for psys in getattr(ob, "particle_systems", ()):
        ps = psys.settings
        if ps is not None and ps.type == "HAIR" and ps.render_type == "PATH":
            out.append(psys)
    return out


def strand_count(psys) -> int:
    """Strands a hair particle system renders: its parents or, when it has children, those (the
    evaluated children, or parents x the render child count where they are not evaluated) and
    the parents only with "Parents" on."""
    parents = len(psys.particles)
    ps = psys.settings
    if getattr(ps, "child_type", "NONE") == "NONE":
        return parents
    children = len(psys.child_particles) or parents * int(getattr(ps, "rendered_child_count", 0))
    return children + (parents if getattr(ps, "use_parent_particles", False) else 0)


def is_surface_instance(inst) -> bool:
    """Whether a depsgraph object instance renders as a surface (geometry that shows itself)."""
    return inst.object.type in GEOMETRY_TYPES and inst.show_self


@dataclass
class MeshData:
    vertices: np.ndarray      # (V, 3) float64, object space
    triangles: np.ndarray     # (T, 3) int32
    slot: np.ndarray          # (T,) int32 material slot per triangle
    uv: np.ndarray | None     # (T, 3, 2) float32 per-corner UVs of triangles, or None
    face_dir: np.ndarray | None  # (T, 3) per-triangle grating attribute, or None
    name: str
    face_period: np.ndarray | None = None  # (T,) per-triangle period attribute (nm), or None
    corner_normal: np.ndarray | None = None  # (T, 3, 3) float32 object-space shading normals, or None: all flat
    flat_tri: np.ndarray | None = None  # (T,) bool: triangles of flat faces (face normal), or None: none flat
    # textures (read_corners): ('UV', map) -> (T, 3, 2) float32, ('TANGENT', map) -> (T, 3, 4) float32
    # object space, ('GENERATED', '') -> (T, 3, 3) float32 in [0, 1] over the texture space,
    # ('OBJECT', '') -> (T, 3, 3) float32 object-space positions (shader programs)
    corners: dict | None = None
    needs: frozenset = frozenset()


def read_mesh(me, name: str, want_uv: bool) -> MeshData:
    """Object-space triangles of a mesh, their material slots and, with ``want_uv`` (a grating
    material), UVs and the opal face attributes; ``name`` (the object's) is for warnings."""
    if hasattr(me, "calc_loop_triangles"):
        me.calc_loop_triangles()
    lt = me.loop_triangles
    nt, nv = len(lt), len(me.vertices)
    pos = me.attributes.get("position")
    if pos is not None and pos.data_type == "FLOAT_VECTOR":
        verts = foreach(pos.data, "vector", nv, np.float32, 3)
    else:
        verts = foreach(me.vertices, "co", nv, np.float32, 3)
    tris = foreach(lt, "vertices", nt, np.int32, 3)
    # material slot per triangle: through the triangle -> face map when this Blender has it
    mi_attr = me.attributes.get("material_index")
    if hasattr(me, "loop_triangle_polygons") and nt:
        face = foreach(me.loop_triangle_polygons, "value", nt, np.int32)
        if mi_attr is not None and mi_attr.domain == "FACE":
            slot = foreach(mi_attr.data, "value", len(me.polygons), np.int32)[face]
        else:
            slot = np.zeros(nt, np.int32)
    else:
        face = None
        slot = foreach(lt, "material_index", nt, np.int32)
    uv = face_dir = face_period = None
    if want_uv and nt:
        uvl = me.uv_layers.active
        if uvl is not None:
            loops = foreach(lt, "loops", nt, np.int32, 3)
            uv_all = foreach(uvl.uv if hasattr(uvl, "uv") else uvl.data, "vector" if hasattr(uvl, "uv") else "uv",
                              len(me.loops), np.float32, 2)
            uv = uv_all[loops]
        attr = me.attributes.get(GRATING_ATTRIBUTE)
        if attribute_ok(attr, "FLOAT_VECTOR") and face is not None:
            face_dir = foreach(attr.data, "vector", len(me.polygons), np.float32, 3)[face]
        attr = me.attributes.get(PERIOD_ATTRIBUTE)
        if attribute_ok(attr, "FLOAT") and face is not None:
            face_period = foreach(attr.data, "value", len(me.polygons), np.float32)[face]
    md = MeshData(verts.astype(np.float64), tris, slot, uv, face_dir, name, face_period)
    md.corner_normal, md.flat_tri = read_corner_normals(me, lt, nt, face)
    return md


def read_corner_normals(me, lt, nt: int, face) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(corner normals (T, 3, 3) float32 object space, flat (T,) bool or None) of a mesh's
    triangles, as Cycles shades them: Blender's ``corner_normals`` (4.1+), which hold the smooth,
    split (sharp edges, "Smooth by Angle", auto smooth) and custom normals; triangles of flat
    faces are marked (they take their own face normal after the transform). (None, None) for a
    mesh with no smooth face (``normals_domain`` 'FACE'). ``face``: triangle -> polygon, or None."""
    if nt == 0 or getattr(me, "normals_domain", "FACE") == "FACE" or not hasattr(me, "corner_normals"):
        return None, None
    loops = foreach(lt, "loops", nt, np.int32, 3)
    normals = foreach(me.corner_normals, "vector", len(me.loops), np.float32, 3)[loops]
    sharp = me.attributes.get("sharp_face")
    flat = None
    if attribute_ok(sharp, "BOOLEAN") and face is not None:
        flat = foreach(sharp.data, "value", len(me.polygons), bool)[face]
        flat = flat if flat.any() else None
    return normals, flat


def world_corner_normals(md: MeshData, mats: np.ndarray, verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(K*T, 3, 3) float32 unit world shading normals of K instances (matrices (K, 4, 4)) of
    ``md``, whose world vertices and triangles :func:`transform` gave. A normal n goes to
    M^-T n (the inverse transpose keeps it perpendicular to the surface under non-uniform
    scale), computed as sign(det M) cof(M) n, which needs no inverse; mirrored instances get
    their corners in the flipped winding's order. Flat triangles, and every triangle of a mesh
    without corner normals, get their world face normal at all three corners."""
    k, nt = len(mats), len(md.triangles)
    face = triangle_normals(verts, tris).reshape(k, nt, 1, 3)
    out = np.repeat(face, 3, axis=2)
    if md.corner_normal is not None:
        c0, c1, c2 = (mats[:, :3, j] for j in range(3))  # columns of each matrix
        n = md.corner_normal.astype(np.float64)
        cof = np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=2)  # (K, 3, 3) cof(M)
        det = np.einsum("ki,ki->k", c0, np.cross(c1, c2))
        world = np.einsum("kij,tcj->ktci", cof * np.sign(det)[:, None, None], n)
        world /= np.maximum(np.linalg.norm(world, axis=3, keepdims=True), 1e-30)
        mirrored = det < 0
        if mirrored.any():
            world[mirrored] = world[mirrored][:, :, [0, 2, 1]]
        smooth = np.ones(nt, bool) if md.flat_tri is None else ~md.flat_tri
        out[:, smooth] = world[:, smooth]
    return out.reshape(-1, 3, 3).astype(np.float32)


def tangents(md: MeshData, gratings: list, tri_mat_local: np.ndarray, warn) -> np.ndarray:
    """Object-space grating vectors (T, 3) for one mesh: the UV map's U direction, the local X
    axis, or the per-face attribute, per the material's ``grating_direction`` (the core projects
    them onto each triangle and applies the material's rotation)."""
    v = md.vertices[md.triangles]
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    # a BRAGG lattice has no surface direction (its (111) planes are the volume domains')
    modes = np.array([g["grating_direction"] if g and g.get("lattice") != "BRAGG" else "" for g in gratings],
                     dtype=object)[tri_mat_local]
    t = np.zeros((len(md.triangles), 3))
    t[:] = (1.0, 0.0, 0.0)
    if (modes == "UV").any() and md.uv is None:
        warn(f"object '{md.name}': no UV map for the grating direction: using the object's local X axis")
    if md.uv is not None and (modes == "UV").any():
        duv1 = (md.uv[:, 1] - md.uv[:, 0]).astype(np.float64)
        duv2 = (md.uv[:, 2] - md.uv[:, 0]).astype(np.float64)
        det = duv1[:, 0] * duv2[:, 1] - duv2[:, 0] * duv1[:, 1]
        ok = (modes == "UV") & (np.abs(det) > 1e-20)
        tu = (e1 * duv2[:, 1:2] - e2 * duv1[:, 1:2]) / np.where(ok, det, 1.0)[:, None]
        t[ok] = tu[ok]
    if (modes == "ATTRIBUTE").any():
        if md.face_dir is not None:
            attr = modes == "ATTRIBUTE"
            t[attr] = md.face_dir[attr]
        else:
            warn(f"object '{md.name}': no '{GRATING_ATTRIBUTE}' face attribute: using the object's local X axis")
    return t


def periods(md: MeshData, has: np.ndarray, warn) -> np.ndarray:
    """Per-triangle period overrides (T,) nm for one mesh: the face attribute on grating
    triangles, 0 elsewhere (0: the material's period); NaN, infinite or negative values are 0."""
    out = np.zeros(len(md.triangles), np.float32)
    if md.face_period is None or not has.any():
        return out
    p = np.asarray(md.face_period, np.float32)
    bad = has & ~(np.isfinite(p) & (p >= 0))
    if bad.any():
        warn(f"object '{md.name}': {int(bad.sum())} face(s) have a NaN, infinite or negative "
             f"'{PERIOD_ATTRIBUTE}': using the material's period there")
    out[has] = np.where(np.isfinite(p[has]) & (p[has] > 0), p[has], 0.0)
    return out


def transform(md: MeshData, mats: np.ndarray):
    """World vertices (K*V, 3) and triangles for K instances (matrices (K, 4, 4)); mirrored
    instances get their winding flipped so normals keep pointing outwards."""
    k, nv = len(mats), len(md.vertices)
    verts = np.einsum("kij,vj->kvi", mats[:, :3, :3], md.vertices) + mats[:, None, :3, 3]
    det = np.linalg.det(mats[:, :3, :3])
    base = (np.arange(k, dtype=np.int64) * nv)[:, None, None]
    tris = np.broadcast_to(md.triangles[None].astype(np.int64), (k,) + md.triangles.shape) + base
    if (det < 0).any():
        tris = tris.copy()
        tris[det < 0] = tris[det < 0][:, :, [0, 2, 1]]
    return verts.reshape(-1, 3), tris.reshape(-1, 3), det


def wants_uv(ob) -> bool:
    """Whether a material of ``ob`` has a grating (its mesh is then read with UVs and attributes)."""
    return any(s.material is not None and getattr(s.material, "opal", None) is not None and s.material.opal.grating
               for s in ob.material_slots)


def mesh_for(ob, otype: str, want_uv: bool, needs: frozenset = frozenset(), warn=None) -> MeshData | None:
    """Triangles of an evaluated object (modifiers applied), object space; None if it has none.
    ``needs``: the per-corner data its textured materials read (:func:`read_corners`)."""
    if otype == "MESH":
        md = read_mesh(ob.data, ob.name, want_uv)
        if md is not None and needs:
            read_corners(ob.data, md, needs, warn)
    else:
        try:
            me = ob.to_mesh()
        except RuntimeError:
            return None
        try:
            md = None if me is None else read_mesh(me, ob.name, want_uv)
            if md is not None and needs:
                read_corners(me, md, needs, warn)
        finally:
            ob.to_mesh_clear()
    if md is not None and len(md.vertices) and not np.isfinite(md.vertices).all():
        bad = int((~np.isfinite(md.vertices).all(axis=1)).sum())
        raise SceneError(f"object '{ob.name}': {bad} vertex coordinate(s) are NaN or infinite; fix or delete them")
    return md


# ============================================================================ the cache
@dataclass
class _Entry:
    mesh: MeshData | None
    want_uv: bool
    needs: frozenset          # per-corner texture data read (read_corners)
    data_name: str            # the object's original data (what a Mesh / Curve update names)
    eval_name: str            # the evaluated data's name (a modifier stack's result is "Mesh")
    size: tuple[int, int] | None  # MESH: (vertices, faces) of the data it was read from


def _data_names(ob) -> tuple[str, str]:
    data = ob.data
    original = getattr(getattr(ob, "original", None), "data", None)
    return (original.name_full if original is not None else "", data.name_full if data is not None else "")


class MeshCache:
    """Meshes read by earlier exports of one depsgraph, kept until their geometry changes.

    Pass the same cache to every :func:`export_scene` of one depsgraph (a rendered viewport's;
    the final render's has other modifier levels), and call :meth:`invalidate` with the
    depsgraph's updates before re-exporting. Evaluated data pointers change whenever Blender
    re-evaluates, so an entry is keyed by the object's name and the mesh's place among that
    object's distinct meshes in the export (0 but for geometry-nodes instances, which all carry
    their instancer's name); it is used again only while the material slots ask for the same
    data (UVs and attributes for gratings), the data's names are unchanged and, for a mesh, its
    vertex and face counts match. ``reads`` counts the meshes read from Blender.
    """

    def __init__(self):
        self._entries: dict[tuple[str, int], _Entry] = {}
        self.reads = 0

    def __len__(self) -> int:
        return len(self._entries)

    def invalidate(self, updates) -> int:
        """Drop the meshes whose geometry an update changed: ``updates`` is ``depsgraph.updates``
        (read it while it is valid: in ``view_update`` or a ``depsgraph_update_post`` handler).
        An Object with ``is_updated_geometry`` drops every mesh of that object; any other ID
        (a Mesh, Curve, ...) every mesh read from data of that name. Returns how many were dropped."""
        objects, data = set(), set()
        for update in updates:
            if not update.is_updated_geometry:
                continue
            idb = update.id
            (objects if idb.id_type == "OBJECT" else data).add(idb.name_full)
        drop = [k for k, e in self._entries.items() if k[0] in objects or e.data_name in data]
        for k in drop:
            del self._entries[k]
        return len(drop)

    def invalidate_all(self) -> None:
        """Forget every mesh (after an undo, a file load, or a change of depsgraph)."""
        self._entries.clear()

    def _get(self, ob, otype: str, index: int, used: set, needs: frozenset = frozenset(),
             warn=None) -> MeshData | None:
        key = (ob.name_full, index)
        used.add(key)
        want_uv = wants_uv(ob)
        data_name, eval_name = _data_names(ob)
        data = ob.data
        size = (len(data.vertices), len(data.polygons)) if otype == "MESH" and data is not None else None
        e = self._entries.get(key)
        if e is None or (e.want_uv, e.needs, e.data_name, e.eval_name, e.size) != (want_uv, needs, data_name,
                                                                                 eval_name, size):
            self.reads += 1
            e = self._entries[key] = _Entry(mesh_for(ob, otype, want_uv, needs, warn), want_uv, needs, data_name,
                                            eval_name, size)
        return e.mesh

    def _keep_only(self, used: set) -> None:
        for k in [k for k in self._entries if k not in used]:  # deleted, renamed or hidden objects
            del self._entries[k]


class SceneMeshes:
    """The distinct meshes of one export, each read once (or taken from a :class:`MeshCache`):
    a mesh object's by its evaluated data, which linked duplicates and instances share; other
    geometry (curves, text, metaballs) by object."""

    def __init__(self, cache: MeshCache | None = None):
        self.cache = cache if cache is not None else MeshCache()
        self.meshes: dict[tuple, MeshData | None] = {}
        self._per_object: dict[str, int] = defaultdict(int)
        self._index: dict[tuple, int] = {}
        self._used: set = set()

    def __len__(self) -> int:
        return len(self.meshes)

    def __getitem__(self, mkey) -> MeshData | None:
        return self.meshes[mkey]

    def get(self, ob, otype: str, needs: frozenset = frozenset(), warn=None) -> tuple[tuple, MeshData | None]:
        """(this export's key of ``ob``'s mesh, the mesh or None). ``needs``: the per-corner data
        its textured materials read (a mesh shared by objects whose materials read more is read
        again with all of it)."""
        data = ob.data
        mkey = ("data", data.as_pointer()) if (otype == "MESH" and data is not None) else ("obj", ob.name)
        if mkey not in self.meshes:
            index = self._per_object[ob.name_full]
            self._per_object[ob.name_full] += 1
            self._index[mkey] = index
            self.meshes[mkey] = self.cache._get(ob, otype, index, self._used, needs, warn)
        else:
            md = self.meshes[mkey]
            if md is not None and not needs <= md.needs:
                self.meshes[mkey] = self.cache._get(ob, otype, self._index[mkey], self._used, needs | md.needs, warn)
        return mkey, self.meshes[mkey]

    def done(self) -> None:
        """The export finished: the cache forgets the meshes it did not use."""
        self.cache._keep_only(self._used)


# ============================================================================ instances -> arrays
def subset(md: MeshData, keep: np.ndarray) -> MeshData:
    """``md`` with only the triangles where ``keep`` is True (the vertices all kept)."""
    pick = (lambda a: None if a is None else a[keep])
    corners = None if md.corners is None else {k: v[keep] for k, v in md.corners.items()}
    return MeshData(md.vertices, md.triangles[keep], md.slot[keep], pick(md.uv), pick(md.face_dir), md.name,
                    pick(md.face_period), corner_normal=pick(md.corner_normal), flat_tri=pick(md.flat_tri),
                    corners=corners, needs=md.needs)


def instance_groups(groups: dict, meshes: SceneMeshes, hidden: np.ndarray | None = None, with_key: bool = False):
    """The instance groups :func:`flatten` and :func:`flatten_corners` walk, in the same order:
    for each (mesh key, material rows of its slots) -> world matrices, yields (the mesh with the
    triangles of ``hidden`` rows left out, the (K, 4, 4) matrices, each triangle's material row);
    a group whose triangles are all hidden is skipped, a NaN or infinite matrix an error.
    ``with_key``: each item starts with the group's key (export/domains.py)."""
    for (mkey, slots), mlist in groups.items():
        md = meshes[mkey]
        mats = np.stack(mlist)
        if not np.isfinite(mats).all():
            raise SceneError(f"object '{md.name}': its transform is NaN or infinite")
        slot_map = np.asarray(slots, np.int32)
        tri_mat_local = slot_map[np.clip(md.slot, 0, len(slot_map) - 1)]
        if hidden is not None and hidden[slot_map].any():
            keep = ~hidden[tri_mat_local]
            if not keep.any():
                continue
            md, tri_mat_local = subset(md, keep), tri_mat_local[keep]
        yield ((mkey, slots), md, mats, tri_mat_local) if with_key else (md, mats, tri_mat_local)


def flatten(groups: dict, meshes: SceneMeshes, grating: list, warn, hidden: np.ndarray | None = None):
    """World-space arrays of every instance: ``groups`` maps (mesh key, material rows of its
    slots) to the instances' world matrices; ``grating`` is the material table's grating
    settings per row (None: no grating); ``hidden`` (per row, optional): rows whose triangles
    are left out (volume-only materials). Returns (vertices (V, 3) float32, triangles (T, 3)
    int32, tri_material (T,) int32, tri_tangent (T, 3) float32 or (0, 3) without gratings,
    tri_period (T,) float32 or (0,) without period attributes, corner_normals (T, 3, 3) float32
    or (0, 3, 3) when no mesh has a smooth face)."""
    any_grating = any(g is not None for g in grating)
    vert_chunks, tri_chunks, mat_chunks, tan_chunks, per_chunks = [], [], [], [], []
    smooth = any(meshes[mkey] is not None and meshes[mkey].corner_normal is not None for mkey, _ in groups)
    normal_chunks = []
    n_verts = 0
    for md, mats, tri_mat_local in instance_groups(groups, meshes, hidden):
        verts, tris, det = transform(md, mats)
        if smooth:
            normal_chunks.append(world_corner_normals(md, mats, verts, tris))
        vert_chunks.append(verts)
        tri_chunks.append(tris + n_verts)
        mat_chunks.append(np.tile(tri_mat_local, len(mats)))
        if any_grating:
            grat = list(grating)
            has = np.array([g is not None for g in grat])[tri_mat_local]
            if has.any():
                t_local = tangents(md, grat, tri_mat_local, warn)
                t_world = np.einsum("kij,tj->kti", mats[:, :3, :3], t_local)
                t_world /= np.maximum(np.linalg.norm(t_world, axis=2, keepdims=True), 1e-30)
                t_world[:, ~has] = 0.0
                tan_chunks.append(t_world.reshape(-1, 3).astype(np.float32))
            else:
                tan_chunks.append(np.zeros((len(mats) * len(md.triangles), 3), np.float32))
            per_chunks.append(np.tile(periods(md, has, warn), len(mats)))
        n_verts += len(verts)
    vertices = np.concatenate(vert_chunks).astype(np.float32) if vert_chunks else np.zeros((0, 3), np.float32)
    triangles = np.concatenate(tri_chunks).astype(np.int32) if tri_chunks else np.zeros((0, 3), np.int32)
    tri_material = np.concatenate(mat_chunks).astype(np.int32) if mat_chunks else np.zeros(0, np.int32)
    tri_period = np.zeros(0, np.float32)
    if any_grating and per_chunks and any(p.any() for p in per_chunks):
        tri_period = np.concatenate(per_chunks).astype(np.float32)
    if n_verts >= 2**31:
        raise SceneError(f"the scene has {n_verts} vertices, more than a 32-bit index can address")
    tri_tangent = np.concatenate(tan_chunks) if (any_grating and tan_chunks) else np.zeros((0, 3), np.float32)
    corner_normals = np.concatenate(normal_chunks) if normal_chunks else np.zeros((0, 3, 3), np.float32)
    return vertices, triangles, tri_material, tri_tangent, tri_period, corner_normals


# ============================================================================ textures: per-corner data
def _uv_layer(me, name: str):
    """The UV layer ``name`` ('': the active render one, Cycles' default UV), or None."""
    layers = me.uv_layers
    if not len(layers):
        return None
    if name:
        return layers.get(name)
    for layer in layers:
        if layer.active_render:
            return layer
    return layers.active


def read_corners(me, md: MeshData, needs: frozenset, warn=None) -> None:
    """Fill ``md.corners`` with the per-corner data textured materials read (``needs``, from
    ``MaterialTable.corner_needs``): UVs of a UV map (``uv_layers[...].uv``, per triangle corner),
    Generated coordinates ((co - texspace_location) / (2 texspace_size) + 1/2, Cycles' generated
    attribute, from the evaluated positions) and MikkTSpace tangents (``calc_tangents`` on that
    map: per corner ``tangent`` and ``bitangent_sign``). A missing UV map gives (0, 0), as Cycles
    reads a missing attribute, with a warning; a mesh whose tangents Blender cannot compute
    (n-gons) gets per-triangle UV tangents, with a warning."""
    lt = me.loop_triangles
    nt = len(lt)
    loops = foreach(lt, "loops", nt, np.int32, 3) if nt else np.zeros((0, 3), np.int32)
    out: dict = {}
    say = warn if warn is not None else (lambda _m: None)
    for kind, name in sorted(needs):
        if kind == "UV":
            out[(kind, name)] = _corner_uvs(me, name, loops, md.name, say)
        elif kind == "GENERATED":
            loc = np.array(me.texspace_location, np.float64)
            size = np.array(me.texspace_size, np.float64)
            size = np.where(size != 0, size, 1.0)
            gen = (md.vertices - loc) / (2 * size) + 0.5
            out[(kind, name)] = gen[md.triangles].astype(np.float32)
        elif kind == "OBJECT":  # a shader program's Object coordinates: the object-space position
            out[(kind, name)] = md.vertices[md.triangles].astype(np.float32)
        elif kind == "ATTRIBUTE":  # an Attribute / Color Attribute node's mesh attribute
            out[(kind, name)] = corner_attribute(me, name, lt, loops, md.name, say)
    for kind, name in sorted(needs):
        if kind == "TANGENT":
            out[(kind, name)] = _corner_tangents(me, name, loops, md, out, say)
    md.corners, md.needs = out, needs


#: Attribute data types read, with their ``foreach_get`` property and width.
_ATTRIBUTE_TYPES = {"FLOAT_COLOR": ("color", 4), "BYTE_COLOR": ("color", 4), "FLOAT": ("value", 1),
                    "INT": ("value", 1), "BOOLEAN": ("value", 1), "FLOAT_VECTOR": ("vector", 3),
                    "FLOAT2": ("vector", 2), "INT8": ("value", 1)}


def corner_attribute(me, name: str, lt, loops: np.ndarray, obname: str, say) -> np.ndarray:
    """(T, 3, 4) float32 RGBA per triangle corner of the mesh attribute ``name`` ('' the default
    colour attribute, as a Color Attribute node with no name reads), as Cycles reads it: colours
    in scene linear (a byte colour's ``color`` is its sRGB bytes decoded, as Cycles decodes them),
    a float f as (f, f, f, 1), a vector as (x, y, z, 1); point, face-corner and face domains. A
    mesh without it reads zeros (Cycles' missing attribute), with a warning naming it."""
    nt = len(loops)
    attr = None
    if name:
        attr = me.attributes.get(name)
    else:
        cols = getattr(me, "color_attributes", None)
        if cols is not None and len(cols):
            idx = getattr(cols, "render_color_index", -1)
            attr = cols[idx] if 0 <= idx < len(cols) else cols[0]
    what = f"attribute {name!r}" if name else "colour attribute"
    if attr is None or attr.data_type not in _ATTRIBUTE_TYPES or attr.domain not in ("POINT", "CORNER", "FACE"):
        why = "has no" if attr is None else f"has a {attr.data_type.lower()} {attr.domain.lower()}-domain"
        say(f"object '{obname}' {why} {what}: its Attribute / Color Attribute nodes read (0, 0, 0), as in Cycles")
        return np.zeros((nt, 3, 4), np.float32)
    prop, width = _ATTRIBUTE_TYPES[attr.data_type]
    count = len(attr.data)
    raw = foreach(attr.data, prop, count, np.float32, width) if width > 1 else \
        foreach(attr.data, prop, count, np.float32 if attr.data_type == "FLOAT" else np.int32).astype(np.float32)
    raw = np.asarray(raw, np.float32).reshape(count, width)
    rgba = np.ones((count, 4), np.float32)
    if width == 1:
        rgba[:, :3] = raw
    else:
        rgba[:, :width] = raw
        if width == 2:
            rgba[:, 2] = 0.0
    if attr.domain == "CORNER":
        return rgba[loops]
    if attr.domain == "POINT":
        return rgba[foreach(lt, "vertices", nt, np.int32, 3)]
    face = foreach(me.loop_triangle_polygons, "value", nt, np.int32)
    return np.repeat(rgba[face][:, None, :], 3, axis=1)


def _corner_uvs(me, name: str, loops: np.ndarray, obname: str, say) -> np.ndarray:
    layer = _uv_layer(me, name)
    if layer is None:
        say(f"object '{obname}' has no UV map{f' {name!r}' if name else ''} for its image textures: they read "
            "UV (0, 0), as in Cycles")
        return np.zeros((len(loops), 3, 2), np.float32)
    data = layer.uv if hasattr(layer, "uv") else layer.data
    uv_all = foreach(data, "vector" if hasattr(layer, "uv") else "uv", len(me.loops), np.float32, 2)
    return uv_all[loops]


def _corner_tangents(me, name: str, loops: np.ndarray, md: MeshData, out: dict, say) -> np.ndarray:
    layer = _uv_layer(me, name)
    if layer is None:
        say(f"object '{md.name}' has no UV map{f' {name!r}' if name else ''} for its normal map's tangents: the "
            "normal map is ignored, as in Cycles")
        return np.zeros((len(loops), 3, 4), np.float32)
    try:
        me.calc_tangents(uvmap=layer.name)
    except RuntimeError as e:  # n-gons: Blender's MikkTSpace takes triangles and quads only
        from ...core.util.geometry import uv_tangents

        say(f"object '{md.name}': Blender cannot compute its tangents ({str(e).strip()}): using per-triangle UV "
            "tangents for its normal map")
        uv = out.get(("UV", name))
        uv = _corner_uvs(me, name, loops, md.name, say) if uv is None else uv
        return uv_tangents(md.vertices, md.triangles, uv)
    n = len(me.loops)
    tan = foreach(me.loops, "tangent", n, np.float32, 3)
    sign = foreach(me.loops, "bitangent_sign", n, np.float32)
    if hasattr(me, "free_tangents"):
        me.free_tangents()
    return np.concatenate([tan[loops], sign[loops][..., None]], axis=2)


def flatten_corners(groups: dict, meshes: SceneMeshes, corners: list, hidden: np.ndarray | None = None):
    """World-space per-corner texture data of every instance, in :func:`flatten`'s triangle
    order: ``corners`` is the material table's CornerSpec per row (None: untextured). Returns
    (corner_uvs (T, 3, 2) float32 or (0, 3, 2) when no material is textured, corner_tangents
    (T, 3, 4) float32 or (0, 3, 4) without normal maps). UVs have each material's Mapping folded
    in; tangents are turned by the instance's normal matrix (relative to its normal's length, so
    they need not be unit) and their sign flips with a mirroring matrix, so B = sign (N x T) is
    the image of the object-space bitangent."""
    if not any(c is not None for c in corners):
        return np.zeros((0, 3, 2), np.float32), np.zeros((0, 3, 4), np.float32)
    with_tangents = any(c is not None and c.tangent_map is not None for c in corners)
    uv_chunks, tan_chunks = [], []
    for md, mats, tri_mat_local in instance_groups(groups, meshes, hidden):  # flatten's triangle order
        nt, k = len(md.triangles), len(mats)
        uv = np.zeros((nt, 3, 2), np.float32)
        tan = np.zeros((k, nt, 3, 4), np.float32) if with_tangents else None
        have = md.corners or {}
        for row in np.unique(tri_mat_local):  # loop over the mesh's materials (a few)
            spec = corners[row]
            if spec is None:
                continue
            sel = tri_mat_local == row
            src = have.get((spec.coords, spec.uv_map if spec.coords == "UV" else ""))
            if src is not None:
                p = src[sel].astype(np.float64)
                if p.shape[-1] == 2:  # UV (u, v) -> the point (u, v, 0)
                    p = np.concatenate([p, np.zeros(p.shape[:-1] + (1,))], axis=-1)
                m = spec.affine()
                uv[sel] = (p @ m[:3, :3].T + m[:3, 3])[..., :2].astype(np.float32)
            if tan is not None and spec.tangent_map is not None:
                t_obj = have.get(("TANGENT", spec.tangent_map))
                if t_obj is not None:
                    t_sel = t_obj[sel].astype(np.float64)
                    # Cycles maps in object space and turns the result by the normal matrix M^-T:
                    # M^-T T over |M^-T N| (N the face's object-space normal) keeps the tangent's
                    # length relative to the world normal, so x T + y B + z N comes out as
                    # Cycles' under non-uniform scale (exactly where the scale axes lie along
                    # the tangent frame)
                    normal_m = np.linalg.inv(mats[:, :3, :3]).transpose(0, 2, 1)
                    face = np.cross(md.vertices[md.triangles[sel, 1]] - md.vertices[md.triangles[sel, 0]],
                                    md.vertices[md.triangles[sel, 2]] - md.vertices[md.triangles[sel, 0]])
                    face /= np.maximum(np.linalg.norm(face, axis=1, keepdims=True), 1e-300)
                    n_len = np.linalg.norm(np.einsum("kij,tj->kti", normal_m, face), axis=-1)  # (k, nsel)
                    t_w = np.einsum("kij,tcj->ktci", normal_m, t_sel[..., :3])
                    t_w /= np.maximum(n_len, 1e-300)[:, :, None, None]
                    flip = np.sign(np.linalg.det(mats[:, :3, :3]))[:, None, None]
                    sign = np.broadcast_to(t_sel[None, ..., 3] * flip, t_w.shape[:-1])
                    tan[:, sel] = np.concatenate([t_w, sign[..., None]], axis=-1)
        uv_k = np.broadcast_to(uv, (k,) + uv.shape)
        mirrored = np.linalg.det(mats[:, :3, :3]) < 0
        if mirrored.any():  # flatten swaps corners 1 and 2 of a mirrored instance's triangles
            uv_k = uv_k.copy()
            uv_k[mirrored] = uv_k[mirrored][:, :, [0, 2, 1]]
            if tan is not None:
                tan[mirrored] = tan[mirrored][:, :, [0, 2, 1]]
        uv_chunks.append(uv_k.reshape(k * nt, 3, 2))
        if tan is not None:
            tan_chunks.append(tan.reshape(k * nt, 3, 4))
    corner_uvs = np.concatenate(uv_chunks) if uv_chunks else np.zeros((0, 3, 2), np.float32)
    corner_tan = np.concatenate(tan_chunks) if tan_chunks else np.zeros((0, 3, 4), np.float32)
    return corner_uvs, corner_tan


def flatten_program_corners(groups: dict, meshes: SceneMeshes, reads: list, hidden: np.ndarray | None = None):
    """The per-corner coordinates shader programs read (docs/physics.md section 13.6), in
    :func:`flatten`'s triangle order: ``reads`` is the material table's per-row set of
    coordinates ('generated', 'object'). Returns (corner_generated, corner_object), each
    (T, 3, 3) float32, or (0, 3, 3) when no program reads it. Both are object space (Cycles'
    Generated and Object coordinates do not move with the instance), with a mirrored instance's
    corners 1 and 2 swapped as flatten swaps them."""
    out = []
    for name, kind in (("generated", "GENERATED"), ("object", "OBJECT")):
        if not any(name in r for r in reads):
            out.append(np.zeros((0, 3, 3), np.float32))
            continue
        chunks = []
        for md, mats, tri_mat_local in instance_groups(groups, meshes, hidden):
            nt, k = len(md.triangles), len(mats)
            src = (md.corners or {}).get((kind, ""))
            data = np.zeros((nt, 3, 3), np.float32) if src is None else np.asarray(src, np.float32)
            data_k = np.broadcast_to(data, (k,) + data.shape)
            mirrored = np.linalg.det(mats[:, :3, :3]) < 0
            if mirrored.any():
                data_k = data_k.copy()
                data_k[mirrored] = data_k[mirrored][:, :, [0, 2, 1]]
            chunks.append(data_k.reshape(k * nt, 3, 3))
        out.append(np.concatenate(chunks) if chunks else np.zeros((0, 3, 3), np.float32))
    return out[0], out[1]


def flatten_attribute_corners(groups: dict, meshes: SceneMeshes, reads: list, hidden: np.ndarray | None = None) -> dict:
    """The mesh attributes shader programs read (Attribute / Color Attribute nodes), in
    :func:`flatten`'s triangle order: ``reads`` is the material table's per-row set of what its
    program reads ('attribute:NAME' items). Returns name -> (T, 3, 4) float32 (zeros on meshes
    without it), a mirrored instance's corners 1 and 2 swapped as flatten swaps them."""
    names = sorted({r.split(":", 1)[1] for rr in reads for r in rr if r.startswith("attribute:")})
    out = {}
    for name in names:
        chunks = []
        for md, mats, tri_mat_local in instance_groups(groups, meshes, hidden):
            nt, k = len(md.triangles), len(mats)
            src = (md.corners or {}).get(("ATTRIBUTE", name))
            data = np.zeros((nt, 3, 4), np.float32) if src is None else np.asarray(src, np.float32)
            data_k = np.broadcast_to(data, (k,) + data.shape)
            mirrored = np.linalg.det(mats[:, :3, :3]) < 0
            if mirrored.any():
                data_k = data_k.copy()
                data_k[mirrored] = data_k[mirrored][:, :, [0, 2, 1]]
            chunks.append(data_k.reshape(k * nt, 3, 4))
        out[name] = np.concatenate(chunks) if chunks else np.zeros((0, 3, 4), np.float32)
    return out
