"""Depsgraph -> core Scene: modifiers, instancing, material slots, node materials, lights, camera,
world, grating directions, cancellation and speed."""

from __future__ import annotations

import math
import time

import bpy
import numpy as np
import pytest

import blender_scenes as bs
from opal_diffraction.blender.export import ExportCancelled, export_scene
from opal_diffraction.core.spectral.optics import DISPERSION_MODELS
from opal_diffraction.core.scene.model import LIGHT_KINDS, MATERIAL_KINDS
from opal_diffraction.core.scene.checks import SceneError


def _export():
    return export_scene(bpy.context.evaluated_depsgraph_get())


def _row(exported, name):
    m = exported.scene.materials
    i = list(m.name).index(name)
    return {"kind": int(m.kind[i]), "color": np.asarray(m.color[i]), "ior": float(m.ior[i]),
            "emission": np.asarray(m.emission[i]), "dispersion": int(m.dispersion[i]), "abbe": float(m.abbe[i]),
            "metallic": float(m.metallic[i]), "metal_color": np.asarray(m.metal_color[i]), "holdout": float(m.holdout[i])}


def _basic_scene():
    sc = bs.empty_scene(16, 16)
    bs.camera(location=(0, -8, 2), rotation=(math.radians(80), 0, 0))
    bs.light("POINT", (0, -2, 4), 500.0)
    return sc


# ---------------------------------------------------------------------------- geometry
def test_modifiers_are_applied_with_render_levels(last_render):
    sc = _basic_scene()
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    cube = bpy.context.active_object
    cube.modifiers.new("array", "ARRAY").count = 3
    sub = cube.modifiers.new("subsurf", "SUBSURF")
    sub.levels, sub.render_levels = 1, 2
    assert len(_export().scene.triangles) == 3 * 6 * 4 * 2  # the viewport depsgraph: level 1
    sc.opal.samples = 1
    bpy.ops.render.render()  # the render depsgraph: level 2
    assert last_render["export"]["triangles"] == 3 * 6 * 16 * 2
    v = _export().scene.vertices
    assert v[:, 0].max() - v[:, 0].min() > 2.5  # three cubes side by side


def test_collection_instances_with_world_matrices():
    _basic_scene()
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=1, radius=1.0)
    ico = bpy.context.active_object
    src = bpy.data.collections.new("source")  # not linked to the scene: only its instances render
    bpy.context.scene.collection.objects.unlink(ico)
    src.objects.link(ico)
    places = [((0, 0, 0), 1.0), ((10, 0, 0), 2.0), ((20, 0, 0), -1.0), ((0, 10, 3), 0.5)]
    for i, (loc, scale) in enumerate(places):
        e = bs.link(bpy.data.objects.new(f"inst{i}", None))
        e.instance_type = "COLLECTION"
        e.instance_collection = src
        e.location = loc
        e.scale = (scale, abs(scale), abs(scale))  # a negative x scale mirrors
        e.rotation_euler = (0, 0, 0.3 * i)
    ex = _export()
    s = ex.scene
    n = len(ico.data.polygons)  # 20: all triangles
    assert len(s.triangles) == 4 * n and ex.stats["meshes"] == 1 and ex.stats["objects"] == 4
    tri = s.vertices[s.triangles].astype(np.float64)
    centre = tri.mean(axis=1)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    for k, (loc, scale) in enumerate(places):
        part = slice(n * k, n * (k + 1))
        found = None
        for j, (l2, s2) in enumerate(places):
            if np.allclose(tri[part].reshape(-1, 3).mean(axis=0), l2, atol=1e-3):
                found = j
        assert found is not None, "an instance is not where its empty is"
        r = abs(places[found][1])
        radii = np.linalg.norm(tri[part].reshape(-1, 3) - places[found][0], axis=1)
        assert np.allclose(radii, r, rtol=1e-4)
        # winding stays outward, mirrored instance included
        assert (np.sum(normal[part] * (centre[part] - places[found][0]), axis=1) > 0).all()


def test_vertex_instancing(tmp_path, last_render):
    """Vertex instancing: the render shows the child at each vertex of the parent, not at its own
    place (as Cycles does; the render depsgraph hides it)."""
    sc = _basic_scene()
    parent = bs.mesh_object("parent", [(10, 0, 0), (13, 0, 0), (10, 3, 0), (13, 3, 0)], [])
    bpy.ops.mesh.primitive_cube_add(size=0.5)
    child = bpy.context.active_object
    child.parent = parent
    parent.instance_type = "VERTS"
    sc.opal.samples = 1
    sc.opal.scene_npz = str(tmp_path / "verts.npz")
    bpy.ops.render.render()
    assert last_render["export"]["triangles"] == 4 * 12
    from opal_diffraction.core.scene.npz import load_scene

    s = load_scene(tmp_path / "verts.npz")
    centres = s.vertices[s.triangles].reshape(4, -1, 3).mean(axis=1)
    assert sorted(map(tuple, np.round(centres[:, :2], 3))) == [(10, 0), (10, 3), (13, 0), (13, 3)]


def test_per_face_material_slots_and_object_slots():
    _basic_scene()
    red = bs.material("red", "DIFFUSE", (0.8, 0.1, 0.1))
    glass = bs.material("glass", "GLASS", (1, 1, 1), IOR=1.5)
    blue = bs.material("blue", "DIFFUSE", (0.1, 0.1, 0.8))
    ob = bs.mesh_object("two", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0), (2, 1, 0)],
                        [(0, 1, 2, 3), (1, 4, 5, 2)], red)
    ob.data.materials.append(glass)
    ob.data.polygons[1].material_index = 1
    twin = bs.link(bpy.data.objects.new("twin", ob.data))  # same mesh, an object-linked first slot
    twin.location = (0, 5, 0)
    twin.material_slots[0].link = "OBJECT"
    twin.material_slots[0].material = blue
    ex = _export()
    s = ex.scene
    names = s.materials.name[s.tri_material]
    cy = s.vertices[s.triangles].mean(axis=1)
    first, second = cy[:, 1] < 2, cy[:, 1] > 2
    left = cy[:, 0] < 1
    assert set(names[first & left]) == {"red"} and set(names[first & ~left]) == {"glass"}
    assert set(names[second & left]) == {"blue"} and set(names[second & ~left]) == {"glass"}
    assert _row(ex, "glass")["kind"] == MATERIAL_KINDS["DIELECTRIC"]
    assert ex.stats["meshes"] == 1  # the shared mesh is read once


def test_curves_and_text_become_triangles():
    _basic_scene()
    bpy.ops.object.text_add()
    bpy.ops.curve.primitive_bezier_circle_add()
    bpy.context.active_object.data.extrude = 0.2
    assert len(_export().scene.triangles) > 20


def test_nan_vertex_names_the_object():
    _basic_scene()
    bs.mesh_object("bad mesh", [(0, 0, 0), (1, 0, 0), (0, float("inf"), 0)], [(0, 1, 2)])
    with pytest.raises(SceneError, match="object 'bad mesh': 1 vertex coordinate"):
        _export()


def test_export_is_vectorised():
    """200 k triangles in well under a second or two (no Python loop per triangle)."""
    _basic_scene()
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=316, y_subdivisions=316, size=4)
    n_faces = len(bpy.context.active_object.data.polygons)
    t0 = time.perf_counter()
    s = _export().scene
    dt = time.perf_counter() - t0
    assert len(s.triangles) == 2 * n_faces > 190_000
    assert dt < 3.0, f"export took {dt:.2f} s"


def test_test_break_cancels_export():
    _basic_scene()
    with pytest.raises(ExportCancelled):
        export_scene(bpy.context.evaluated_depsgraph_get(), test_break=lambda: True)


# ---------------------------------------------------------------------------- materials
def _material_scene(mats):
    """Planes with the given materials (made after _basic_scene()), exported."""
    for i, m in enumerate(mats):
        bs.plane(name=f"p{i}", half=0.4, z=0.0, mat=m).location = (i, 0, 0)
    return _export()


def test_principled_and_bsdf_nodes():
    _basic_scene()
    mats = [
        bs.material("default", "PRINCIPLED", (0.8, 0.8, 0.8)),
        bs.material("metal", "PRINCIPLED", (0.9, 0.6, 0.2), Metallic=1.0, Roughness=0.05),
        bs.material("rough metal", "PRINCIPLED", (0.9, 0.6, 0.2), Metallic=1.0, Roughness=0.8),
        bs.material("clear", "PRINCIPLED", (1, 1, 1), **{"Transmission Weight": 1.0, "IOR": 1.6, "Roughness": 0.0}),
        bs.material("lamp", "PRINCIPLED", (0.5, 0.5, 0.5), **{"Emission Color": (1, 0.5, 0, 1),
                                                               "Emission Strength": 3.0}),
        bs.material("glass", "GLASS", (0.9, 0.9, 1.0), IOR=1.45, Roughness=0.0),
        bs.material("mirror", "GLOSSY", (0.7, 0.7, 0.7), Roughness=0.0),
        bs.material("emitter", "EMISSION", (1, 1, 1), Strength=5.0),
        bs.material("diffuse", "DIFFUSE", (0.2, 0.4, 0.6)),
    ]
    ex = _material_scene(mats)
    K = MATERIAL_KINDS
    assert _row(ex, "default")["kind"] == K["DIFFUSE"]
    np.testing.assert_allclose(_row(ex, "default")["color"], 0.8, rtol=1e-6)
    assert _row(ex, "metal")["kind"] == K["MIRROR"]
    np.testing.assert_allclose(_row(ex, "metal")["color"], (0.9, 0.6, 0.2), rtol=1e-6)
    # a rough metal stays a metal, its roughness carried (core/materials/bsdf.py renders it)
    m = ex.scene.materials
    i = list(m.name).index("rough metal")
    assert _row(ex, "rough metal")["kind"] == K["MIRROR"] and m.roughness[i] == pytest.approx(0.8)
    assert m.metallic[i] == 1.0 and m.conductor_fresnel[i] == 1
    assert not any("rough metal" in w for w in ex.warnings)
    assert _row(ex, "clear")["kind"] == K["DIELECTRIC"] and _row(ex, "clear")["ior"] == pytest.approx(1.6)
    np.testing.assert_allclose(_row(ex, "lamp")["emission"], (3.0, 1.5, 0.0), rtol=1e-6)
    assert _row(ex, "glass")["kind"] == K["DIELECTRIC"] and _row(ex, "glass")["ior"] == pytest.approx(1.45)
    assert _row(ex, "mirror")["kind"] == K["MIRROR"]
    np.testing.assert_allclose(_row(ex, "emitter")["emission"], 5.0, rtol=1e-6)
    np.testing.assert_allclose(_row(ex, "emitter")["color"], 0.0)
    np.testing.assert_allclose(_row(ex, "diffuse")["color"], (0.2, 0.4, 0.6), rtol=1e-6)


def test_dispersion_settings_map_to_the_core():
    _basic_scene()
    glass = bs.material("flint", "GLASS", (1, 1, 1), IOR=1.72)
    glass.opal.dispersion, glass.opal.abbe_number = "ABBE", 29.0
    diamond = bs.material("diamond", "GLASS", (1, 1, 1), IOR=2.42)
    diamond.opal.dispersion = "DIAMOND"
    ex = _material_scene([glass, diamond])
    assert _row(ex, "flint")["dispersion"] == DISPERSION_MODELS["ABBE"] and _row(ex, "flint")["abbe"] == 29.0
    assert _row(ex, "diamond")["dispersion"] == DISPERSION_MODELS["DIAMOND"]


def test_unsupported_and_textured_nodes_fall_back_with_warnings():
    _basic_scene()
    mix = bs.material("mix", "DIFFUSE", (0.8, 0.1, 0.1))
    nt = mix.node_tree
    diffuse = nt.nodes["Diffuse BSDF"]
    glossy = nt.nodes.new("ShaderNodeBsdfGlossy")
    glossy.inputs["Roughness"].default_value = 0.0
    mixer = nt.nodes.new("ShaderNodeMixShader")
    mixer.inputs["Fac"].default_value = 0.3
    nt.links.new(diffuse.outputs[0], mixer.inputs[1])
    nt.links.new(glossy.outputs[0], mixer.inputs[2])
    nt.links.new(mixer.outputs[0], nt.nodes["Material Output"].inputs["Surface"])

    textured = bs.material("textured", "DIFFUSE", (0.5, 0.5, 0.5))
    img = bpy.data.images.new("flat", 4, 4, float_buffer=True)
    img.pixels.foreach_set(np.tile([0.25, 0.5, 0.75, 1.0], 16).astype(np.float32))
    tex = textured.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = img
    textured.node_tree.links.new(tex.outputs["Color"], textured.node_tree.nodes["Diffuse BSDF"].inputs["Color"])

    noisy = bs.material("noisy", "DIFFUSE", (0.3, 0.3, 0.3))
    noise = noisy.node_tree.nodes.new("ShaderNodeTexNoise")
    noisy.node_tree.links.new(noise.outputs["Color"], noisy.node_tree.nodes["Diffuse BSDF"].inputs["Color"])

    hot = bs.material("hot", "EMISSION", (1, 1, 1), Strength=2.0)
    bb = hot.node_tree.nodes.new("ShaderNodeBlackbody")
    bb.inputs["Temperature"].default_value = 3000.0
    hot.node_tree.links.new(bb.outputs[0], hot.node_tree.nodes["Emission"].inputs["Color"])

    toon = bs.material("toon", "ShaderNodeBsdfToon", (0.1, 0.7, 0.1))
    holdout = bpy.data.materials.new("holdout")
    holdout.node_tree.nodes.clear()
    h = holdout.node_tree.nodes.new("ShaderNodeHoldout")
    holdout.node_tree.links.new(h.outputs[0], holdout.node_tree.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    ex = _material_scene([mix, textured, noisy, hot, toon, holdout])
    # Holdout: black (Cycles' combined colour) with holdout weight 1 (Film > Transparent: alpha 0,
    # tests/render/test_holdout.py), no warning
    np.testing.assert_array_equal(_row(ex, "holdout")["color"], 0.0)
    assert _row(ex, "holdout")["holdout"] == 1.0
    assert not any("material 'holdout'" in w for w in ex.warnings)

    # a Mix of unlike BSDFs is a lobe mixture (docs/physics.md section 14.8): the heavier layer's kind,
    # the Glossy's weight 0.3 as the metal layer, each with its own colour; nothing to warn
    assert _row(ex, "mix")["kind"] == MATERIAL_KINDS["DIFFUSE"]
    assert _row(ex, "mix")["metallic"] == pytest.approx(0.3)
    np.testing.assert_allclose(_row(ex, "mix")["color"], (0.8, 0.1, 0.1), rtol=1e-5)
    np.testing.assert_allclose(_row(ex, "mix")["metal_color"], tuple(glossy.inputs["Color"].default_value)[:3],
                               rtol=1e-5)
    assert not any("material 'mix'" in w and "mixes" in w for w in ex.warnings)
    np.testing.assert_allclose(_row(ex, "textured")["color"], (0.25, 0.5, 0.75), rtol=1e-5)
    # the image texture is sampled per hit (tests/blender/test_export_textures.py): bound, not averaged
    m = ex.scene.materials
    assert m.color_texture[list(m.name).index("textured")] >= 0
    assert not any("material 'textured'" in w and "average" in w for w in ex.warnings)
    # a procedural texture is compiled into the material's shader program (tests/blender/test_shader_nodes.py);
    # the colour column keeps its average (a noise's colour is about 1/2 in each channel)
    noisy_row = list(m.name).index("noisy")
    assert m.shader_program[noisy_row] >= 0
    assert ex.scene.shader_programs[m.shader_program[noisy_row]].outputs.keys() == {"color"}
    np.testing.assert_allclose(_row(ex, "noisy")["color"], 0.5, atol=0.1)
    assert not any("material 'noisy'" in w for w in ex.warnings)
    e = _row(ex, "hot")["emission"] / 2.0
    assert e[0] > e[1] > e[2] and float(e @ [0.2126, 0.7152, 0.0722]) == pytest.approx(1.0, rel=0.02)
    assert _row(ex, "toon")["kind"] == MATERIAL_KINDS["DIFFUSE"]
    np.testing.assert_allclose(_row(ex, "toon")["color"], (0.1, 0.7, 0.1), rtol=1e-5)
    assert any("material 'toon'" in w for w in ex.warnings)


def test_no_material_is_blenders_default_grey():
    _basic_scene()
    bs.plane()
    ex = _export()
    assert list(ex.scene.materials.name) == ["(default surface)"]
    np.testing.assert_allclose(ex.scene.materials.color[0], 0.8)


def test_grating_columns_and_directions():
    _basic_scene()
    opal = bs.material("opal", "DIFFUSE", (0.05, 0.05, 0.05))
    opal.opal.grating = True
    opal.opal.grating_type, opal.opal.lattice = "REFLECTION", "HEXAGONAL"
    opal.opal.period, opal.opal.slit_width, opal.opal.slit_count = 300.0, 150.0, 50
    opal.opal.rotation = 0.25
    bpy.ops.mesh.primitive_plane_add(size=2.0)
    uv_plane = bpy.context.active_object
    uv_plane.data.materials.append(opal)
    uv_plane.rotation_euler = (0, 0, math.radians(30))  # U follows the object's X: rotated 30 degrees
    cd = bs.material("cd", "GLOSSY", (0.8, 0.8, 0.8), Roughness=0.0)
    cd.opal.grating = True
    cd.opal.grating_direction = "OBJECT_X"
    axis_plane = bs.plane("axis", half=0.5, mat=cd)
    axis_plane.location = (5, 0, 0)
    axis_plane.rotation_euler = (0, 0, math.radians(-45))
    bs.plane("plain", half=0.5, mat=bs.material("plain")).location = (-5, 0, 0)
    ex = _export()
    s = ex.scene
    i = list(s.materials.name).index("opal")
    assert s.materials.grating[i] == 1 and s.materials.lattice[i] == 1 and s.materials.period[i] == 300.0
    assert s.materials.rotation[i] == pytest.approx(0.25)
    assert s.tri_tangent.shape == (len(s.triangles), 3)
    names = s.materials.name[s.tri_material]
    t = s.tri_tangent / np.maximum(np.linalg.norm(s.tri_tangent, axis=1, keepdims=True), 1e-30)
    a30, a45 = math.radians(30), math.radians(-45)
    np.testing.assert_allclose(np.abs(t[names == "opal"] @ [math.cos(a30), math.sin(a30), 0]), 1.0, atol=1e-5)
    np.testing.assert_allclose(np.abs(t[names == "cd"] @ [math.cos(a45), math.sin(a45), 0]), 1.0, atol=1e-5)
    assert np.all(s.tri_tangent[names == "plain"] == 0)


# ---------------------------------------------------------------------------- lights
def test_light_export_in_cycles_units():
    _basic_scene()
    for ob in [o for o in bpy.data.objects if o.type == "LIGHT"]:
        bpy.data.objects.remove(ob)
    bs.light("POINT", (1, 2, 3), 100.0, color=(1.0, 0.5, 0.25), exposure=1.0)
    bs.light("SPOT", (0, 0, 5), 50.0, rotation=(math.radians(90), 0, 0), spot_size=math.radians(40), spot_blend=0.5)
    bs.light("SUN", (0, 0, 9), 3.0, rotation=(0, math.radians(30), 0))
    area = bs.light("AREA", (0, 0, 2), 80.0, shape="RECTANGLE", size=2.0, size_y=0.5, normalize=False)
    area.scale = (2.0, 3.0, 1.0)
    bs.light("AREA", (4, 0, 2), 60.0, shape="DISK", size=1.0, use_temperature=True, temperature=2500.0)
    noded = bs.light("POINT", (0, 4, 2), 10.0)
    noded.data.use_nodes = True
    nt = noded.data.node_tree
    emission = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 2.0
    bb = nt.nodes.new("ShaderNodeBlackbody")
    bb.inputs["Temperature"].default_value = 4000.0
    nt.links.new(bb.outputs[0], emission.inputs["Color"])

    lt = _export().scene.lights
    kinds = list(lt.kind)
    p = kinds.index(LIGHT_KINDS["POINT"])
    assert lt.power[p] == pytest.approx(200.0) and np.allclose(lt.position[p], (1, 2, 3))
    np.testing.assert_allclose(lt.color[p], (1.0, 0.5, 0.25))
    sp = kinds.index(LIGHT_KINDS["SPOT"])
    np.testing.assert_allclose(lt.direction[sp], (0, 1, 0), atol=1e-6)  # -Z rotated 90 deg about X
    assert lt.spot_size[sp] == pytest.approx(math.radians(40)) and lt.spot_blend[sp] == pytest.approx(0.5)
    su = kinds.index(LIGHT_KINDS["SUN"])
    np.testing.assert_allclose(lt.direction[su], (-math.sin(math.radians(30)), 0, -math.cos(math.radians(30))),
                               atol=1e-6)
    assert lt.power[su] == pytest.approx(3.0)
    ar = kinds.index(LIGHT_KINDS["AREA_RECT"])
    assert (lt.size_u[ar], lt.size_v[ar]) == pytest.approx((4.0, 1.5))
    assert lt.power[ar] == pytest.approx(80.0 * 4.0 * 1.5)  # unnormalised: power per square metre
    ad = kinds.index(LIGHT_KINDS["AREA_DISK"])
    assert lt.temperature[ad] == pytest.approx(2500.0) and lt.power[ad] == pytest.approx(60.0)
    nd = [i for i, k in enumerate(kinds) if k == LIGHT_KINDS["POINT"] and i != p][0]
    assert lt.temperature[nd] == pytest.approx(4000.0) and lt.power[nd] == pytest.approx(20.0)


# ---------------------------------------------------------------------------- camera, world
def test_camera_export():
    sc = _basic_scene()
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = 400, 300, 50
    cam = sc.camera.data
    cam.lens, cam.sensor_fit, cam.sensor_height = 35.0, "VERTICAL", 20.0
    cam.shift_x, cam.shift_y = 0.1, -0.05
    c = _export().scene.camera
    assert (c.width, c.height, c.kind, c.sensor_fit) == (200, 150, "PERSP", "VERTICAL")
    assert (c.lens, c.sensor_height, c.shift_x, c.shift_y) == pytest.approx((35.0, 20.0, 0.1, -0.05))
    np.testing.assert_allclose(c.matrix, np.array(sc.camera.matrix_world), atol=1e-6)
    cam.type, cam.ortho_scale = "ORTHO", 7.0
    c = _export().scene.camera
    assert c.kind == "ORTHO" and c.ortho_scale == pytest.approx(7.0)
    cam.type = "PANO"
    cam.panorama_type = "FISHEYE_EQUISOLID"
    cam.fisheye_lens, cam.fisheye_fov = 12.0, 3.0
    c = _export().scene.camera
    assert (c.kind, c.panorama_type) == ("PANO", "FISHEYE_EQUISOLID")
    assert (c.fisheye_lens, c.fisheye_fov) == pytest.approx((12.0, 3.0))
    cam.panorama_type = "EQUIRECTANGULAR"
    cam.latitude_min, cam.longitude_max = -0.5, 1.0
    c = _export().scene.camera
    assert (c.latitude_min, c.longitude_max) == pytest.approx((-0.5, 1.0))
    cam.panorama_type = "MIRRORBALL"
    with pytest.raises(SceneError, match="mirrorball panorama is not supported"):
        _export()


def test_motion_blur_outside_final_renders_is_named_not_silently_ignored():
    """An export without the engine's frame_set (the .npz export, the viewport) cannot evaluate
    sub-frames: it renders the frame's own time and says so (final renders blur:
    tests/blender/test_motion_parity.py)."""
    sc = _basic_scene()
    assert not [w for w in _export().warnings if "motion blur" in w]
    sc.render.use_motion_blur = True
    assert [w for w in _export().warnings if "motion blur is rendered in final renders only" in w]


def test_camera_depth_of_field_export_follows_cycles():
    """Cycles' blender/camera.cpp: aperture radius lens / (2 f-number) (orthographic: 1 / (2 N) m),
    blades, rotation, ratio; the focus distance, or the distance to a Focus Object along the view
    axis."""
    sc = _basic_scene()
    cam = sc.camera.data
    cam.lens = 40.0
    cam.dof.use_dof = True
    cam.dof.aperture_fstop, cam.dof.aperture_blades = 2.0, 7
    cam.dof.aperture_rotation, cam.dof.aperture_ratio = 0.25, 1.5
    cam.dof.focus_distance = 3.5
    c = _export().scene.camera
    assert c.aperture_radius == pytest.approx(0.040 / 4.0)
    assert (c.aperture_blades, c.aperture_rotation, c.aperture_ratio) == (7, pytest.approx(0.25), pytest.approx(1.5))
    assert c.focus_distance == pytest.approx(3.5)
    target = bpy.data.objects.new("focus", None)
    sc.collection.objects.link(target)
    m = np.array(sc.camera.matrix_world)
    view = -m[:3, 2] / np.linalg.norm(m[:3, 2])
    target.location = tuple(m[:3, 3] + 2.0 * view + np.cross(view, [0.0, 0.0, 1.0]) * 0.7)  # 2 m ahead, off-axis
    cam.dof.focus_object = target
    bpy.context.view_layer.update()
    assert _export().scene.camera.focus_distance == pytest.approx(2.0, rel=1e-5)
    cam.type = "ORTHO"
    assert _export().scene.camera.aperture_radius == pytest.approx(1.0 / 4.0)
    cam.dof.use_dof = False
    assert _export().scene.camera.aperture_radius == 0.0


def test_camera_orientation_matches_blender(tmp_path):
    """A camera looking along +Y sees the object Blender's camera sees, where Blender would show it:
    an emitter to the right of the view axis lands in the right half of the image."""
    bs.empty_scene(16, 16)
    bs.camera(location=(0, -5, 0), rotation=(math.radians(90), 0, 0))
    bs.mesh_object("right", [(0.3, 0, -1), (1.5, 0, -1), (1.5, 0, 1), (0.3, 0, 1)], [(0, 1, 2, 3)],
                   bs.material("glow", "EMISSION", (1, 1, 1), Strength=1.0))
    img = bs.render_to_array(str(tmp_path / "o.exr"), samples=2)
    assert img[:, 9:, 1].mean() > 0.3 and img[:, :7, 1].max() < 1e-6


def test_world_colour():
    sc = _basic_scene()
    assert np.all(_export().scene.world_color == 0)
    w = bpy.data.worlds.new("w")
    sc.world = w
    bg = w.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (0.1, 0.2, 0.3, 1.0)
    bg.inputs["Strength"].default_value = 2.0
    before = _export()
    np.testing.assert_allclose(before.scene.world_color, (0.2, 0.4, 0.6), rtol=1e-6)
    sky = w.node_tree.nodes.new("ShaderNodeTexSky")  # baked into a map, its sun a lamp (test_world_nodes_cycles.py)
    w.node_tree.links.new(sky.outputs[0], bg.inputs["Color"])
    ex = _export()
    assert not ex.warnings and ex.scene.world_image.shape == (512, 1024, 3)
    assert len(ex.scene.lights) == len(before.scene.lights) + 1


def test_export_operator_writes_a_renderable_scene(tmp_path):
    from opal_diffraction.core.render.frame import render
    from opal_diffraction.core.scene.npz import load_scene
    from opal_diffraction.core.scene.settings import RenderSettings

    _basic_scene()
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    path = tmp_path / "scene.npz"
    assert bpy.ops.opal.export_scene(filepath=str(path)) == {"FINISHED"}
    s = load_scene(path)
    assert len(s.triangles) == 12 and len(s.lights) == 1 and s.camera.width == 16
    r = render(s, RenderSettings(samples=1, wavelength_step=20.0))
    assert r.rgb.max() > 0
    bpy.context.scene.camera = None
    with pytest.raises(RuntimeError, match="no camera"):
        bpy.ops.opal.export_scene(filepath=str(tmp_path / "nocam.npz"))
