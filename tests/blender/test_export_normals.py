"""Export of smooth shading (docs/physics.md section 4.6): Blender's corner normals, as Cycles
shades with them, in world space, on the core Scene's ``corner_normals``.

References are analytic: a sphere's normal at a point is radial, an ellipsoid's is the gradient
of x^2/a^2 + y^2/b^2 + z^2/c^2, a cube's split normals are its face normals and its smooth
normals the diagonals.
"""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest
from blender_scenes import camera, empty_scene, link, material

from opal_diffraction.blender.export import MeshCache, export_scene
from opal_diffraction.core.util.geometry import triangle_normals


def _export(cache=None):
    return export_scene(bpy.context.evaluated_depsgraph_get(), mesh_cache=cache).scene


def _scene():
    empty_scene(8, 8)
    camera((0, -10, 0), (math.pi / 2, 0, 0))


def _uv_sphere(location=(0, 0, 0), radius=1.0, smooth=True, name="sphere"):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=radius, location=location)
    ob = bpy.context.object
    ob.name = name
    if smooth:
        bpy.ops.object.shade_smooth()
    ob.data.materials.append(material("grey"))
    return ob


def _corner_positions(scene):
    return np.asarray(scene.vertices, np.float64)[np.asarray(scene.triangles)]  # (T, 3, 3)


def angle_weighted_vertex_normals(vertices, triangles):
    """Blender's smooth vertex normal: the face normals around a vertex weighted by the face's
    corner angle there (planar faces: the same from the triangles)."""
    p = np.asarray(vertices, np.float64)[triangles]
    face = triangle_normals(vertices, triangles)
    out = np.zeros((len(vertices), 3))
    for c in range(3):  # the three corners
        a, b = p[:, (c + 1) % 3] - p[:, c], p[:, (c + 2) % 3] - p[:, c]
        ang = np.arccos(np.clip(np.sum(a * b, 1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1), -1, 1))
        np.add.at(out, triangles[:, c], ang[:, None] * face)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def test_a_smooth_uv_sphere_exports_its_radial_normals_at_every_corner():
    _scene()
    _uv_sphere(location=(0.5, -1.0, 2.0), radius=1.5)
    s = _export()
    assert s.corner_normals.shape == (len(s.triangles), 3, 3) and s.corner_normals.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(s.corner_normals, axis=2), 1, atol=1e-6)
    radial = _corner_positions(s) - (0.5, -1.0, 2.0)
    radial /= np.linalg.norm(radial, axis=2, keepdims=True)
    # the analytic normals, to the tessellation's own error (64 x 32: the angle-weighted mean of
    # the faces around a vertex leans up to 1.5e-3 off radial, most near the poles)
    assert np.linalg.norm(s.corner_normals - radial, axis=2).max() < 2e-3
    # and exactly what Blender's smooth shading defines, the angle-weighted face normals
    ref = angle_weighted_vertex_normals(s.vertices, np.asarray(s.triangles))[np.asarray(s.triangles)]
    assert np.linalg.norm(s.corner_normals - ref, axis=2).max() < 2e-5


def test_a_flat_cube_stores_no_normals_and_its_triangles_in_a_smooth_scene_get_face_normals():
    _scene()
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(3, 0, 0))
    assert _export().corner_normals.shape == (0, 3, 3)
    _uv_sphere()  # now some face is smooth: the cube's corners carry its face normals
    s = _export()
    cube = np.abs(_corner_positions(s)[:, :, 0] - 3).max(axis=1) <= 0.5 + 1e-6
    assert cube.sum() == 12
    face = triangle_normals(s.vertices, s.triangles)[cube]
    np.testing.assert_allclose(s.corner_normals[cube], np.repeat(face[:, None], 3, axis=1), atol=1e-6)


def test_sharp_edges_split_the_normals_of_a_smooth_cube():
    _scene()
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    ob = bpy.context.object
    bpy.ops.object.shade_smooth()
    s = _export()
    corners = _corner_positions(s)
    # smooth: one normal per vertex, the cube's diagonal there
    np.testing.assert_allclose(s.corner_normals, corners / np.sqrt(3), atol=1e-5)
    # the top face's four edges sharp: the top keeps +Z at its corners, the sides meet the top
    # vertices with the mean of the two side faces there, the bottom corners stay diagonal
    me = ob.data
    ev = np.empty(len(me.edges) * 2, np.int32)
    me.edges.foreach_get("vertices", ev)
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    top_edge = (co.reshape(-1, 3)[ev.reshape(-1, 2), 2] > 0).all(axis=1)
    attr = me.attributes.get("sharp_edge") or me.attributes.new("sharp_edge", "BOOLEAN", "EDGE")
    attr.data.foreach_set("value", top_edge)
    me.update()
    s = _export()
    corners = _corner_positions(s)
    face = triangle_normals(s.vertices, s.triangles)
    top = face[:, 2] > 0.99
    expected = np.where(corners[:, :, 2:] > 0, corners * [1, 1, 0] / np.sqrt(2), corners / np.sqrt(3))
    expected[top] = (0, 0, 1)
    np.testing.assert_allclose(s.corner_normals, expected, atol=1e-5)
    # every edge sharp: the cube is flat again, and a flat mesh stores nothing
    attr.data.foreach_set("value", np.ones(len(me.edges), bool))
    me.update()
    assert _export().corner_normals.shape == (0, 3, 3)


@pytest.mark.parametrize("how", ["operator", "modifier"])
def test_smooth_by_angle_splits_a_cylinder_at_its_rims(how):
    """Smooth by Angle (30 deg) on a 32-sided cylinder: the sides are smooth (horizontal radial
    normals), the caps flat (+-Z), and the rim vertices carry both: split normals. Either as
    the one-off operator or as Blender's "Smooth by Angle" modifier (evaluated in the depsgraph)."""
    _scene()
    bpy.ops.mesh.primitive_cylinder_add(vertices=32, radius=1.0, depth=2.0)
    if how == "operator":
        bpy.ops.object.shade_smooth_by_angle(angle=math.radians(30))
    else:
        bpy.ops.object.shade_auto_smooth(angle=math.radians(30))
        assert any(m.type == "NODES" for m in bpy.context.object.modifiers)
    s = _export()
    corners = _corner_positions(s)
    cn = s.corner_normals.astype(np.float64)
    face = triangle_normals(s.vertices, s.triangles)
    cap = np.abs(face[:, 2]) > 0.99
    assert cap.sum() and (~cap).sum()
    np.testing.assert_allclose(cn[cap], np.repeat(face[cap, None], 3, axis=1), atol=1e-5)
    side = corners[~cap] * [1, 1, 0]
    np.testing.assert_allclose(cn[~cap], side / np.linalg.norm(side, axis=2, keepdims=True), atol=1e-5)
    rim = np.abs(corners[:, :, 2]) > 0.999
    assert rim[cap].all() and rim[~cap].any()  # the same vertices, with different normals


def test_object_transforms_use_the_inverse_transpose_and_mirrored_instances_keep_their_corners():
    """A smooth sphere scaled (2, 1, 0.5) is an ellipsoid: its normal at p is the gradient
    (x / a^2, y / b^2, z / c^2), not the scaled radial direction. A linked duplicate mirrored in
    X (negative determinant: its winding is flipped) shares the mesh and keeps each corner's normal
    at its own corner, pointing out."""
    _scene()
    ob = _uv_sphere()
    ob.scale = (2.0, 1.0, 0.5)
    twin = link(bpy.data.objects.new("twin", ob.data))
    twin.location = (6, 0, 0)
    twin.scale = (-1.0, 1.0, 1.0)
    cache = MeshCache()
    s = export_scene(bpy.context.evaluated_depsgraph_get(), mesh_cache=cache)
    assert cache.reads == 1 and s.stats["objects"] == 2
    s = s.scene
    corners = _corner_positions(s)
    first = corners[:, :, 0].max(axis=1) < 3
    grad = corners[first] / np.array([4.0, 1.0, 0.25])
    grad /= np.linalg.norm(grad, axis=2, keepdims=True)
    assert np.linalg.norm(s.corner_normals[first] - grad, axis=2).max() < 2e-3
    radial = corners[~first] - (6, 0, 0)
    radial /= np.linalg.norm(radial, axis=2, keepdims=True)
    assert np.linalg.norm(s.corner_normals[~first] - radial, axis=2).max() < 2e-3
    # the mirrored twin's geometric normals still point out, like its shading normals
    centroid = corners[~first].mean(axis=1) - (6, 0, 0)
    assert np.all(np.sum(triangle_normals(s.vertices, s.triangles)[~first] * centroid, axis=1) > 0)


def test_flat_faces_of_a_smooth_mesh_keep_their_face_normal():
    _scene()
    ob = _uv_sphere()
    me = ob.data
    sharp = me.attributes.get("sharp_face") or me.attributes.new("sharp_face", "BOOLEAN", "FACE")
    flat_faces = np.zeros(len(me.polygons), bool)
    centres = np.empty(len(me.polygons) * 3, np.float32)
    me.polygons.foreach_get("center", centres)
    flat_faces[centres.reshape(-1, 3)[:, 0] > 0] = True  # the +x half flat
    sharp.data.foreach_set("value", flat_faces)
    me.update()
    s = _export()
    corners = _corner_positions(s)
    face = triangle_normals(s.vertices, s.triangles)
    flat = corners.mean(axis=1)[:, 0] > 0
    np.testing.assert_allclose(s.corner_normals[flat], np.repeat(face[flat, None], 3, axis=1), atol=1e-5)
    radial = corners[~flat] / np.linalg.norm(corners[~flat], axis=2, keepdims=True)
    # the smooth half: radial, but at the border its vertex normals average only the smooth faces
    inner = corners[~flat][:, :, 0].max(axis=1) < -0.2
    assert np.linalg.norm(s.corner_normals[~flat][inner] - radial[inner], axis=2).max() < 2e-3


def test_custom_split_normals_are_exported():
    _scene()
    bpy.ops.mesh.primitive_plane_add(size=2.0)
    me = bpy.context.object.data
    bpy.ops.object.shade_smooth()
    tilt = np.array([0.3, 0.0, 1.0]) / np.linalg.norm([0.3, 0.0, 1.0])
    me.normals_split_custom_set([tuple(tilt)] * len(me.loops))
    s = _export()
    np.testing.assert_allclose(s.corner_normals, np.broadcast_to(tilt, (2, 3, 3)), atol=1e-4)


def test_shade_smooth_after_an_export_reaches_the_next_one_through_the_cache():
    """The rendered viewport's path: a MeshCache invalidated from the depsgraph's updates."""
    _scene()
    ob = _uv_sphere(smooth=False)
    cache = MeshCache()
    seen = []

    def handler(scene, depsgraph):
        seen.extend((u.id.name_full, u.is_updated_geometry) for u in depsgraph.updates)
        cache.invalidate(depsgraph.updates)

    bpy.app.handlers.depsgraph_update_post.append(handler)
    try:
        assert _export(cache).corner_normals.shape == (0, 3, 3)
        ob.data.shade_smooth()
        ob.data.update()
        smooth = _export(cache)
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(handler)
    assert smooth.corner_normals.shape == (len(smooth.triangles), 3, 3), seen
    assert cache.reads == 2


@pytest.mark.slow
def test_a_shade_smooth_glass_sphere_renders_differently_from_the_flat_one(tmp_path):
    """Through the engine (F12): shade smooth changes the image by far more than the Monte Carlo
    noise: E[(smooth - flat)^2] = difference^2 + 2 sigma^2 against E[(flat - flat')^2] = 2 sigma^2
    for flat' another seed (before shading normals the two images were bit-identical)."""
    from blender_scenes import render_to_array

    images = {}
    for smooth, seed in ((False, 0), (True, 0), (False, 1)):
        _scene()
        sc = bpy.context.scene
        sc.render.resolution_x = sc.render.resolution_y = 16
        sc.opal.light_paths = 0
        sc.opal.seed = seed
        sc.camera.data.lens = 120.0  # the ball fills most of the frame
        bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, radius=1.0)
        ob = bpy.context.object
        if smooth:
            bpy.ops.object.shade_smooth()
        ob.data.materials.append(material("glass", "GLASS", (1, 1, 1), IOR=1.5))
        for i in range(-3, 3):  # a striped wall behind it, lit by a sun
            bpy.ops.mesh.primitive_plane_add(size=1.0, location=(i + 0.5, 3, 0), rotation=(math.pi / 2, 0, 0))
            bpy.context.object.scale = (1, 4, 1)
            bpy.context.object.data.materials.append(material(f"s{i}", color=(0.9, 0.9, 0.9) if i % 2 else (0.02, 0.02, 0.02)))
        sun = bpy.data.lights.new("sun", "SUN")
        sun.energy = 3.0
        # a delta sun: with light paths off, a sized sun is reached through the ball by bounces
        # off the wall (the caustic), rare fireflies of ~200 that swamp the squared differences
        sun.angle = 0.0
        link(bpy.data.objects.new("sun", sun)).rotation_euler = (math.pi / 2, 0, 0)  # shining along +Y
        images[smooth, seed] = render_to_array(str(tmp_path / f"{smooth}{seed}.exr"), samples=256)
    flat, smooth, flat2 = images[False, 0], images[True, 0], images[False, 1]
    assert flat.mean() > 0.05  # the wall is lit and seen
    noise = np.mean((flat - flat2) ** 2)
    print("mean squared difference smooth - flat", np.mean((smooth - flat) ** 2), "flat - flat'", noise)
    assert np.mean((smooth - flat) ** 2) > 4 * noise > 0
