"""Re-exporting for a rendered viewport: a persistent MeshCache reads only the meshes whose geometry
changed (invalidated from ``depsgraph.updates``), and the per-concept exports equal the parts of a
full export."""

from __future__ import annotations

import contextlib
import dataclasses
import math

import bpy
import numpy as np

import blender_scenes as bs
from opal_diffraction.blender.export import (
    MeshCache,
    Warnings,
    export_camera,
    export_lights,
    export_materials,
    export_scene,
    export_world,
)


def _fields(obj, prefix=""):
    """Every array and value of a core Scene (nested tables included), by dotted name."""
    out = {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if dataclasses.is_dataclass(v):
            out.update(_fields(v, f"{prefix}{f.name}."))
        else:
            out[prefix + f.name] = v
    return out


def _assert_same(a, b):
    fa, fb = _fields(a), _fields(b)
    assert fa.keys() == fb.keys()
    for k in fa:
        x, y = fa[k], fb[k]
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape, k
            np.testing.assert_array_equal(x, y, err_msg=k)
        else:
            assert x == y, k


def _scene():
    """Two meshes (one with a modifier and a grating material, with a linked duplicate), a light,
    a camera and a world colour."""
    bs.empty_scene(16, 16)
    bs.camera(location=(0, -8, 2), rotation=(math.radians(80), 0, 0))
    bs.light("POINT", (0, -2, 4), 500.0)
    bs.light("SUN", (0, 0, 5), 2.0)
    grating = bs.material("grating", "GLOSSY", Roughness=0.0)
    grating.opal.grating = True
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    a = bpy.context.active_object
    a.name = "A"
    a.modifiers.new("subsurf", "SUBSURF").levels = 1
    a.data.materials.append(grating)
    b = bs.plane("B", half=1.0, z=-1.0, mat=bs.material("grey"))
    dup = bs.link(bpy.data.objects.new("B_dup", b.data))  # shares B's mesh: read once
    dup.location = (3, 0, 0)
    world = bpy.data.worlds.new("w")
    world.color = (0.1, 0.2, 0.3)
    bpy.context.scene.world = world
    return a, b


@contextlib.contextmanager
def _invalidating(cache):
    """Invalidate ``cache`` from every depsgraph update while the block runs (as a viewport's
    ``view_update`` would); yields the list of (id name, is_updated_geometry) seen."""
    seen = []

    def handler(scene, depsgraph):
        seen.extend((u.id.name_full, u.is_updated_geometry) for u in depsgraph.updates)
        cache.invalidate(depsgraph.updates)

    bpy.app.handlers.depsgraph_update_post.append(handler)
    try:
        yield seen
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(handler)


def test_warm_cache_reads_no_mesh_and_gives_identical_arrays():
    _scene()
    cache = MeshCache()
    dg = bpy.context.evaluated_depsgraph_get()
    first = export_scene(dg, mesh_cache=cache)
    assert cache.reads == 2 and len(cache) == 2  # A, and B's mesh (shared with B_dup)
    second = export_scene(bpy.context.evaluated_depsgraph_get(), mesh_cache=cache)
    assert cache.reads == 2
    _assert_same(first.scene, second.scene)
    assert first.warnings == second.warnings
    cold = export_scene(dg)
    _assert_same(cold.scene, second.scene)
    assert cold.stats["meshes"] == second.stats["meshes"] == 2
    assert len(first.scene.tri_tangent) == len(first.scene.triangles)  # the grating path is cached too


def test_editing_one_mesh_rereads_only_that_mesh():
    a, b = _scene()
    cache = MeshCache()
    with _invalidating(cache) as seen:
        before = export_scene(bpy.context.evaluated_depsgraph_get(), mesh_cache=cache)
        assert cache.reads == 2
        seen.clear()
        b.data.vertices[0].co.z += 0.25
        b.data.update()
        dg = bpy.context.evaluated_depsgraph_get()  # evaluates the edit: the handler invalidates
        assert ("B", True) in seen and ("A", True) not in seen
        after = export_scene(dg, mesh_cache=cache)
    assert cache.reads == 3  # B's mesh only
    _assert_same(export_scene(dg).scene, after.scene)  # the same as a cold export
    assert not np.array_equal(before.scene.vertices, after.scene.vertices)


def test_editing_a_modified_mesh_invalidates_through_its_object():
    a, b = _scene()  # A's evaluated mesh (the subsurf's result) is not named after A's mesh
    cache = MeshCache()
    with _invalidating(cache):
        export_scene(bpy.context.evaluated_depsgraph_get(), mesh_cache=cache)
        a.data.vertices[0].co.x -= 0.3
        a.data.update()
        dg = bpy.context.evaluated_depsgraph_get()
        after = export_scene(dg, mesh_cache=cache)
    assert cache.reads == 3
    _assert_same(export_scene(dg).scene, after.scene)


def test_moving_an_object_rereads_no_mesh_but_moves_its_vertices():
    a, b = _scene()
    cache = MeshCache()
    with _invalidating(cache) as seen:
        before = export_scene(bpy.context.evaluated_depsgraph_get(), mesh_cache=cache)
        seen.clear()
        a.location.x += 2.0
        dg = bpy.context.evaluated_depsgraph_get()
        assert ("A", False) in seen  # a transform update, not a geometry one
        after = export_scene(dg, mesh_cache=cache)
    assert cache.reads == 2
    _assert_same(export_scene(dg).scene, after.scene)
    moved = np.any(before.scene.vertices != after.scene.vertices, axis=1)
    assert moved.any() and not moved.all()
    np.testing.assert_allclose(after.scene.vertices[moved, 0] - before.scene.vertices[moved, 0], 2.0, atol=1e-5)


def test_a_material_asking_for_uvs_rereads_without_a_geometry_update():
    a, b = _scene()
    cache = MeshCache()
    dg = bpy.context.evaluated_depsgraph_get()
    export_scene(dg, mesh_cache=cache)
    mat = b.data.materials[0]
    mat.opal.grating, mat.opal.grating_direction = True, "UV"
    mat.update_tag()  # a script's write does not reach the evaluated copy by itself (the UI's does)
    dg = bpy.context.evaluated_depsgraph_get()
    warm = export_scene(dg, mesh_cache=cache)
    assert cache.reads == 3  # B's mesh again, now with its UVs
    cold = export_scene(dg)
    _assert_same(cold.scene, warm.scene)
    assert warm.warnings == cold.warnings


def test_geometry_nodes_instances_of_one_object_keep_their_own_meshes():
    bs.empty_scene(16, 16)
    bs.camera(location=(0, -8, 2), rotation=(math.radians(80), 0, 0))
    ob = bs.plane("GN", half=0.5)
    tree = bpy.data.node_groups.new("instances", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    n = tree.nodes
    grid = n.new("GeometryNodeMeshGrid")
    join = n.new("GeometryNodeJoinGeometry")
    ico = n.new("GeometryNodeMeshIcoSphere")
    for shape in (n.new("GeometryNodeMeshCube"), ico):  # two meshes, both instanced by object 'GN'
        inst = n.new("GeometryNodeInstanceOnPoints")
        tree.links.new(grid.outputs[0], inst.inputs["Points"])
        tree.links.new(shape.outputs[0], inst.inputs["Instance"])
        tree.links.new(inst.outputs[0], join.inputs[0])
    tree.links.new(n.new("NodeGroupInput").outputs[0], join.inputs[0])
    tree.links.new(join.outputs[0], n.new("NodeGroupOutput").inputs[0])
    ob.modifiers.new("gn", "NODES").node_group = tree
    cache = MeshCache()
    with _invalidating(cache):
        dg = bpy.context.evaluated_depsgraph_get()
        first = export_scene(dg, mesh_cache=cache)
        assert cache.reads == 3 and first.stats["meshes"] == 3
        _assert_same(export_scene(bpy.context.evaluated_depsgraph_get(), mesh_cache=cache).scene, first.scene)
        assert cache.reads == 3
        ico.inputs["Subdivisions"].default_value = 2
        dg = bpy.context.evaluated_depsgraph_get()
        after = export_scene(dg, mesh_cache=cache)
    assert cache.reads == 6  # the object's geometry changed: all of its meshes
    _assert_same(export_scene(dg).scene, after.scene)
    assert len(after.scene.triangles) > len(first.scene.triangles)


def test_deleted_objects_leave_the_cache_and_invalidate_all_empties_it():
    a, b = _scene()
    cache = MeshCache()
    export_scene(bpy.context.evaluated_depsgraph_get(), mesh_cache=cache)
    assert len(cache) == 2
    bpy.data.objects.remove(a)
    export_scene(bpy.context.evaluated_depsgraph_get(), mesh_cache=cache)
    assert len(cache) == 1 and cache.reads == 2
    cache.invalidate_all()
    assert len(cache) == 0
    export_scene(bpy.context.evaluated_depsgraph_get(), mesh_cache=cache)
    assert cache.reads == 3


def test_per_concept_exports_equal_the_full_export():
    _scene()
    bpy.data.objects["B"].data.materials[0].opal.dispersion = "BK7"  # a warning from the materials
    dg = bpy.context.evaluated_depsgraph_get()
    full = export_scene(dg)
    _assert_same(export_lights(dg), full.scene.lights)
    _assert_same(export_materials(dg), full.scene.materials)
    _assert_same(export_camera(dg), full.scene.camera)
    world = export_world(dg)
    assert world.dtype == full.scene.world_color.dtype
    np.testing.assert_array_equal(world, full.scene.world_color)
    warn = Warnings()
    export_materials(dg, warn)
    assert warn.items and set(warn.items) <= set(full.warnings)
