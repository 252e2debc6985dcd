"""Color Attribute / Attribute nodes, the Bump node and shader node groups (issue 28;
docs/physics.md sections 13.6 and 13.7), in this bpy session.

- Attributes: an Emission plane (a 4 x 4 grid turned 0.3 rad) whose colour comes from a mesh
  attribute, seen by Cycles with one sample at the pixel centres; the expected value is the
  exported program evaluated at the exported hits (tests/blender/test_shader_nodes.py
  ``compare``), for byte face-corner colours, float point colours, a face-domain float through
  the Attribute's Fac and a missing attribute (black, as in Cycles, with a warning).
- Bump: a linear height h = a . x (Object coordinates through a Dot Product) has the same
  finite differences at any step, so the perturbed normal equals the closed form
  normalize(s normalize(N - d grad h) + (1 - s) N) exactly (to float32 rounding), with grad h
  the world-space gradient of a . x_object on the plane.
- Sunlit planes against Cycles pixel by pixel (radiance E cos(N', L) / pi with our shading
  normal at the exported hits): a Bump of a Noise height, and a Normal Map node of a procedural
  colour in every space (tangent at strength 1 and 0.6, object, world, Blender object / world).
- Groups: a red Diffuse inside two levels of node groups (a reroute inside, the colour a group
  input left at its default) renders red, not the 0.8 grey of an unread node; one group used
  twice in a Mix Shader with different inputs gives each its own colour.
"""

from __future__ import annotations

import bpy
import numpy as np
import pytest

import blender_scenes as bs
from test_export_textures import pixel_hits
from test_shader_nodes import P, compare

from opal_diffraction.blender.export import export_scene
from opal_diffraction.core.materials.surface import shading_normal
from opal_diffraction.core.render.prepare import prepare


def attribute_plane(build, attribute):
    """A 4 x 4 grid (3 x 3 m, turned 0.3 rad) whose Emission colour is ``build(nt)``, with the
    attribute(s) ``attribute(mesh)`` adds."""
    sc = bs.empty_scene(P, P, "CYCLES")
    bs.camera(location=(0, 0, 5), ortho_scale=2.0)
    sc.cycles.filter_width = 0.01
    mat = bpy.data.materials.new("attr")
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    em = nt.nodes.new("ShaderNodeEmission")
    nt.links.new(em.outputs[0], out.inputs["Surface"])
    nt.links.new(build(nt), em.inputs["Color"])
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=4, y_subdivisions=4, size=3.0)
    ob = bpy.context.object
    ob.rotation_euler = (0.0, 0.0, 0.3)
    ob.data.materials.append(mat)
    attribute(ob.data)
    return ob


def _random(n, width, seed):
    return np.random.default_rng(seed).uniform(0.05, 0.95, (n, width)).astype(np.float32)


def test_byte_colour_attribute_on_corners_as_cycles(tmp_path):
    """A byte face-corner colour attribute (sRGB bytes, which Cycles decodes to linear) through
    the Color Attribute node: equal to Cycles within 2e-6 on Blender 5.0; Blender 5.2's Cycles
    decodes the bytes by another route, up to 2.2e-4 away (1/18 of a byte step; measured), so the
    tolerance there is 3e-4 (an undecoded sRGB byte would be ~0.2 off)."""
    def attr(me):
        a = me.color_attributes.new("paint", "BYTE_COLOR", "CORNER")
        a.data.foreach_set("color", np.concatenate([_random(len(a.data), 3, 1), np.ones((len(a.data), 1),
                                                                                       np.float32)], 1).ravel())

    def build(nt):
        vc = nt.nodes.new("ShaderNodeVertexColor")
        vc.layer_name = "paint"
        return vc.outputs["Color"]

    attribute_plane(build, attr)
    compare(tmp_path, atol=2e-6 if bpy.app.version < (5, 1, 0) else 3e-4)


def test_default_float_point_colour_through_a_mix_as_cycles(tmp_path):
    """A float point-domain colour attribute, the mesh's render colour, read by a Color
    Attribute node with no name, its Alpha mixing it with a constant."""
    def attr(me):
        a = me.color_attributes.new("heat", "FLOAT_COLOR", "POINT")
        a.data.foreach_set("color", _random(len(a.data), 4, 2).ravel())
        me.color_attributes.render_color_index = 0

    def build(nt):
        vc = nt.nodes.new("ShaderNodeVertexColor")
        mix = nt.nodes.new("ShaderNodeMix")
        mix.data_type = "RGBA"
        mix.inputs[6].default_value = (0.2, 0.9, 0.4, 1)
        nt.links.new(vc.outputs["Alpha"], mix.inputs["Factor"])
        nt.links.new(vc.outputs["Color"], mix.inputs[7])
        return mix.outputs[2]

    attribute_plane(build, attr)
    compare(tmp_path, atol=2e-6)


def test_attribute_fac_of_a_face_float_and_a_vector_as_cycles(tmp_path):
    """An Attribute node's Fac of a face-domain float (constant per face) added to its Vector of a
    point-domain vector attribute (Vector Math)."""
    def attr(me):
        f = me.attributes.new("rough", "FLOAT", "FACE")
        f.data.foreach_set("value", _random(len(f.data), 1, 3).ravel())
        v = me.attributes.new("wind", "FLOAT_VECTOR", "POINT")
        v.data.foreach_set("vector", _random(len(v.data), 3, 4).ravel())

    def build(nt):
        a = nt.nodes.new("ShaderNodeAttribute")
        a.attribute_name = "rough"
        b = nt.nodes.new("ShaderNodeAttribute")
        b.attribute_name = "wind"
        vm = nt.nodes.new("ShaderNodeVectorMath")
        vm.operation = "SCALE"
        nt.links.new(b.outputs["Vector"], vm.inputs[0])
        nt.links.new(a.outputs["Fac"], vm.inputs["Scale"])
        return vm.outputs[0]

    attribute_plane(build, attr)
    compare(tmp_path, atol=2e-6)


def test_a_missing_attribute_reads_black_with_a_warning(tmp_path):
    def build(nt):
        a = nt.nodes.new("ShaderNodeAttribute")
        a.attribute_name = "nowhere"
        mix = nt.nodes.new("ShaderNodeMix")
        mix.data_type = "RGBA"
        mix.inputs[6].default_value = (0.5, 0.5, 0.5, 1)
        nt.links.new(a.outputs["Color"], mix.inputs[7])
        mix.inputs["Factor"].default_value = 1.0
        return mix.outputs[2]

    attribute_plane(build, lambda me: None)
    ex = export_scene(bpy.context.evaluated_depsgraph_get())
    named = [w for w in ex.warnings if "'nowhere'" in w]
    assert len(named) == 1 and "(0, 0, 0)" in named[0], ex.warnings
    p = prepare(ex.scene)
    hits = pixel_hits(p, pixels=P)
    rows, rgba = p.textures.lookup("emission", hits.mat, hits.prim, hits.bu, hits.bv)
    assert len(rows) == P * P and np.all(rgba[:, :3] == 0)
    got = bs.render_to_array(str(tmp_path / "cycles.exr"), "CYCLES", samples=1)
    assert np.all(got == 0)


# ------------------------------------------------------------------------------------ bump
@pytest.mark.parametrize("strength, invert", [(1.0, False), (0.5, False), (0.7, True)])
def test_bump_of_a_linear_height_is_the_closed_form(strength, invert):
    """h = a . x_object on a plane turned by 0.3 rad about z: grad h (world) = R a projected on
    the plane; N' = normalize(N - d grad h) (d negated by Invert), then the strength blend."""
    a = np.array([0.8, -0.5, 0.3])
    d = 0.4
    sc = bs.empty_scene(P, P, "CYCLES")
    bs.camera(location=(0, 0, 5), ortho_scale=2.0)
    mat = bpy.data.materials.new("bumpy")
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    tc = nt.nodes.new("ShaderNodeTexCoord")
    dot = nt.nodes.new("ShaderNodeVectorMath")
    dot.operation = "DOT_PRODUCT"
    dot.inputs[1].default_value = tuple(a)
    bump = nt.nodes.new("ShaderNodeBump")
    bump.inputs["Distance"].default_value = d
    bump.inputs["Strength"].default_value = strength
    bump.invert = invert
    nt.links.new(tc.outputs["Object"], dot.inputs[0])
    nt.links.new(dot.outputs["Value"], bump.inputs["Height"])
    nt.links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
    ob = bs.plane("plane", half=1.5, mat=mat)
    ob.rotation_euler = (0.0, 0.0, 0.3)
    ex = export_scene(bpy.context.evaluated_depsgraph_get())
    assert not ex.warnings, ex.warnings
    p = prepare(ex.scene)
    assert p.textures.uses("normal") and p.textures.bound("normal")[0]
    hits = pixel_hits(p, pixels=8)
    got = shading_normal(p, hits)
    c, s = np.cos(0.3), np.sin(0.3)
    grad = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ a
    grad[2] = 0.0  # the surface gradient: in the plane
    n = np.array([0.0, 0.0, 1.0])
    n1 = n - (-d if invert else d) * grad
    n1 /= np.linalg.norm(n1)
    n2 = strength * n1 + (1 - strength) * n
    n2 /= np.linalg.norm(n2)
    np.testing.assert_allclose(got, np.broadcast_to(n2, got.shape), atol=2e-4)
    assert np.degrees(np.arccos(n2[2])) > 5  # a real tilt


def test_a_bump_with_a_constant_height_leaves_the_normal():
    sc = bs.empty_scene(P, P, "CYCLES")
    bs.camera(location=(0, 0, 5), ortho_scale=2.0)
    mat = bpy.data.materials.new("flat bump")
    nt = mat.node_tree
    v = nt.nodes.new("ShaderNodeValue")
    v.outputs[0].default_value = 0.7
    bump = nt.nodes.new("ShaderNodeBump")
    nt.links.new(v.outputs[0], bump.inputs["Height"])
    nt.links.new(bump.outputs["Normal"], nt.nodes["Principled BSDF"].inputs["Normal"])
    bs.plane("plane", half=1.5, mat=mat)
    p = prepare(export_scene(bpy.context.evaluated_depsgraph_get()).scene)
    hits = pixel_hits(p, pixels=4)
    np.testing.assert_allclose(shading_normal(p, hits), hits.ng, atol=1e-6)


# ------------------------------------------------------------------------------------ groups
def _diffuse_group(name, default):
    g = bpy.data.node_groups.new(name, "ShaderNodeTree")
    s = g.interface.new_socket("Tint", in_out="INPUT", socket_type="NodeSocketColor")
    s.default_value = default
    g.interface.new_socket("Shader", in_out="OUTPUT", socket_type="NodeSocketShader")
    gi, go = g.nodes.new("NodeGroupInput"), g.nodes.new("NodeGroupOutput")
    d = g.nodes.new("ShaderNodeBsdfDiffuse")
    rr = g.nodes.new("NodeReroute")
    g.links.new(gi.outputs[0], rr.inputs[0])
    g.links.new(rr.outputs[0], d.inputs["Color"])
    g.links.new(d.outputs[0], go.inputs[0])
    return g


def _group_scene(build):
    bs.empty_scene(8, 8, "CYCLES")
    bs.camera(location=(0, 0, 5), ortho_scale=2.0)
    mat = bpy.data.materials.new("grouped")
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(build(nt), out.inputs["Surface"])
    bs.plane("plane", half=1.5, mat=mat)
    ex = export_scene(bpy.context.evaluated_depsgraph_get())
    return ex


def test_a_diffuse_inside_nested_groups_keeps_its_group_default_colour():
    """The issue's 'a node group renders grey 0.8': a Diffuse inside a group inside a group, its
    colour the inner group's input, linked to the outer group's input left at (0.9, 0.1, 0.1)."""
    def build(nt):
        inner = _diffuse_group("inner", (0.3, 0.3, 0.3, 1))
        outer = bpy.data.node_groups.new("outer", "ShaderNodeTree")
        s = outer.interface.new_socket("Col", in_out="INPUT", socket_type="NodeSocketColor")
        s.default_value = (0.9, 0.1, 0.1, 1)
        outer.interface.new_socket("Shader", in_out="OUTPUT", socket_type="NodeSocketShader")
        gi, go = outer.nodes.new("NodeGroupInput"), outer.nodes.new("NodeGroupOutput")
        g = outer.nodes.new("ShaderNodeGroup")
        g.node_tree = inner
        outer.links.new(gi.outputs[0], g.inputs[0])
        outer.links.new(g.outputs[0], go.inputs[0])
        top = nt.nodes.new("ShaderNodeGroup")
        top.node_tree = outer
        return top.outputs[0]

    ex = _group_scene(build)
    assert not ex.warnings, ex.warnings
    np.testing.assert_allclose(ex.scene.materials.color[0], (0.9, 0.1, 0.1), atol=1e-6)


def test_one_group_twice_in_a_mix_reads_each_instance_inputs():
    """The same group twice under a Mix Shader (Fac 0.25): red and a Checker's average (the
    Checker outside the group compiled per hit) are each read through their own instance."""
    def build(nt):
        grp = _diffuse_group("tinted", (0.5, 0.5, 0.5, 1))
        a, b = nt.nodes.new("ShaderNodeGroup"), nt.nodes.new("ShaderNodeGroup")
        a.node_tree = b.node_tree = grp
        a.inputs[0].default_value = (1.0, 0.0, 0.0, 1)
        b.inputs[0].default_value = (0.0, 0.0, 1.0, 1)
        mix = nt.nodes.new("ShaderNodeMixShader")
        mix.inputs["Fac"].default_value = 0.25
        nt.links.new(a.outputs[0], mix.inputs[1])
        nt.links.new(b.outputs[0], mix.inputs[2])
        return mix.outputs[0]

    ex = _group_scene(build)
    np.testing.assert_allclose(ex.scene.materials.color[0], (0.75, 0.0, 0.25), atol=1e-6)


# ------------------------------------------------------------------------------------ sunlit planes vs Cycles
def _sunlit(build, scale=(1.5, 1.5, 1.0), tmp_path=None):
    """A white Diffuse plane (turned 35 degrees about z, scaled) whose Normal is ``build(nt)``,
    under a sun, seen top-down at the pixel centres: Cycles' radiance is E cos(N', L) / pi with
    its shading normal N'; ours: the same with core.surface.shading_normal at the exported hits."""
    import math

    from test_export_textures import top_down_scene, uv_plane

    top_down_scene()
    mat = bpy.data.materials.new("lit")
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    bsdf = nt.nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (1, 1, 1, 1)
    nt.links.new(build(nt), bsdf.inputs["Normal"])
    nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
    ob = uv_plane(mat)
    ob.rotation_euler.z = math.radians(35)
    ob.scale = scale
    sun = bs.light("SUN", (0, 0, 3), 3.0, rotation=(math.radians(30), 0, math.radians(20)))
    bpy.context.view_layer.update()
    ex = export_scene(bpy.context.evaluated_depsgraph_get())
    assert not [w for w in ex.warnings if "not read" in w or "not supported" in w or "not perturbed" in w], \
        ex.warnings
    p = prepare(ex.scene)
    hits = pixel_hits(p, pixels=48)
    n = shading_normal(p, hits)
    to_sun = np.array(sun.matrix_world)[:3, :3] @ [0.0, 0.0, 1.0]
    to_sun /= np.linalg.norm(to_sun)
    want = 3.0 / np.pi * np.clip(n @ to_sun, 0, None)
    got = bs.render_to_array(str(tmp_path / "cycles.exr"), "CYCLES", samples=16).reshape(-1, 3) @ [0.2126, 0.7152,
                                                                                                   0.0722]
    tilt = np.degrees(np.arccos(np.clip(n[:, 2], -1, 1)))
    return got, want, tilt


def _procedural_colour(nt, z=0.85):
    """A colour varying over the plane, near the normal-map blue: Combine XYZ of a Gradient and a
    Noise (UV coordinates), z as given."""
    tc = nt.nodes.new("ShaderNodeTexCoord")
    gr = nt.nodes.new("ShaderNodeTexGradient")
    nz = nt.nodes.new("ShaderNodeTexNoise")
    nz.inputs["Scale"].default_value = 3.0
    nt.links.new(tc.outputs["UV"], gr.inputs["Vector"])
    nt.links.new(tc.outputs["UV"], nz.inputs["Vector"])
    mx = nt.nodes.new("ShaderNodeMapRange")
    mx.inputs["To Min"].default_value, mx.inputs["To Max"].default_value = 0.2, 0.8
    nt.links.new(gr.outputs["Fac"], mx.inputs["Value"])
    cb = nt.nodes.new("ShaderNodeCombineXYZ")
    cb.inputs["Z"].default_value = z
    nt.links.new(mx.outputs[0], cb.inputs["X"])
    nt.links.new(nz.outputs["Fac"], cb.inputs["Y"])
    return cb.outputs[0]


@pytest.mark.parametrize("space, strength", [("TANGENT", 1.0), ("TANGENT", 0.6), ("OBJECT", 1.0), ("WORLD", 1.0),
                                             ("BLENDER_OBJECT", 0.8), ("BLENDER_WORLD", 0.7)])
def test_a_normal_map_of_a_procedural_colour_matches_cycles(space, strength, tmp_path):
    """The Normal Map node with a procedural Color (read through the shader program) in each
    space, on a plane scaled uniformly by 1.5 (where the object transform taken from the
    triangle's corners is exact). Blender's object / world spaces negate y and z, so their colour
    has z 0.15 (the normal points up)."""
    def build(nt):
        nm = nt.nodes.new("ShaderNodeNormalMap")
        nm.space = space
        nm.inputs["Strength"].default_value = strength
        nt.links.new(_procedural_colour(nt, 0.15 if space.startswith("BLENDER") else 0.85), nm.inputs["Color"])
        return nm.outputs["Normal"]

    got, want, tilt = _sunlit(build, scale=(1.5, 1.5, 1.0) if space == "TANGENT" else (1.5, 1.5, 1.5), tmp_path=tmp_path)
    assert tilt.max() > 10  # the map bends the normal
    print(f"max |difference| {np.abs(got - want).max():.2e}, mean {want.mean():.3f}, Cycles mean {got.mean():.3f}")
    np.testing.assert_allclose(got, want, rtol=0.01, atol=0.003)


def test_a_bumped_plane_matches_cycles_pixel_by_pixel(tmp_path):
    """A Bump node (Distance 0.3, Noise of the Object coordinates at scale 2) on the sunlit plane:
    Cycles' shading normal, from its pixel-footprint differences, and ours agree per pixel."""
    def build(nt):
        tc = nt.nodes.new("ShaderNodeTexCoord")
        nz = nt.nodes.new("ShaderNodeTexNoise")
        nz.inputs["Scale"].default_value = 2.0
        nz.inputs["Detail"].default_value = 1.0
        nt.links.new(tc.outputs["Object"], nz.inputs["Vector"])
        b = nt.nodes.new("ShaderNodeBump")
        b.inputs["Distance"].default_value = 0.3
        nt.links.new(nz.outputs["Fac"], b.inputs["Height"])
        return b.outputs["Normal"]

    got, want, tilt = _sunlit(build, tmp_path=tmp_path)
    assert tilt.max() > 10
    err = np.abs(got - want)
    print(f"max |difference| {err.max():.2e}, mean {err.mean():.2e}, radiance mean {want.mean():.3f}")
    np.testing.assert_allclose(got, want, rtol=0.02, atol=0.005)


@pytest.mark.parametrize("name", ["heat", "generated", "uv"])
def test_attribute_names_cycles_takes_for_its_own(name, tmp_path):
    """Cycles resolves some names to its standard attributes (measured, Blender 5.0): 'heat' (a
    volume grid) reads zeros on a mesh even when the mesh has a 'heat' attribute, 'generated' and
    'uv' are those coordinates; ours the same, pixel by pixel."""
    def attr(me):
        a = me.attributes.new(name, "FLOAT_COLOR", "POINT")
        a.data.foreach_set("color", _random(len(a.data), 4, 5).ravel())
        me.uv_layers.new(name="UVMap")

    def build(nt):
        a = nt.nodes.new("ShaderNodeAttribute")
        a.attribute_name = name
        mix = nt.nodes.new("ShaderNodeMix")
        mix.data_type = "RGBA"
        mix.inputs["Factor"].default_value = 0.7
        mix.inputs[6].default_value = (0.3, 0.6, 0.2, 1)
        nt.links.new(a.outputs["Color"], mix.inputs[7])
        return mix.outputs[2]

    attribute_plane(build, attr)
    ex = compare(tmp_path, atol=2e-6) if name != "heat" else None
    if name == "heat":
        ex = export_scene(bpy.context.evaluated_depsgraph_get())
        assert any("volume grid" in w for w in ex.warnings), ex.warnings
        got = bs.render_to_array(str(tmp_path / "cycles.exr"), "CYCLES", samples=1).reshape(-1, 3)
        np.testing.assert_allclose(got, np.broadcast_to(np.float32([0.3, 0.6, 0.2]) * 0.3, got.shape), atol=2e-6)
        p = prepare(ex.scene)
        hits = pixel_hits(p, pixels=P)
        rows, rgba = p.textures.lookup("emission", hits.mat, hits.prim, hits.bu, hits.bv)
        np.testing.assert_allclose(rgba[:, :3], got, atol=2e-6)
