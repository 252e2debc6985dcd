"""RGB Curves, Float Curves, Wavelength and Blackbody compiled to shader programs
(blender/export/shader_compiler.py, core/materials/shader_eval.py; docs/physics.md section 13.6)
against Cycles rendering the same node setup in this bpy session: an Emission plane seen straight
down with point pixel samples (tests/blender/test_shader_nodes.py ``emission_plane`` /
``compare``), a gradient across it driving the node over a range that reaches past the curves'
ends (so the extrapolation is read too)."""

from __future__ import annotations

import pytest

from test_shader_nodes import compare, emission_plane, link

G_LO, G_HI = 1.0 / 6.0, 5.0 / 6.0  # the Generated x the camera sees on the 3 x 3 plane


def gradient(nt, vec, lo, hi):
    """Generated x mapped linearly from what the camera sees to [lo, hi] (a float socket)."""
    sep = nt.nodes.new("ShaderNodeSeparateXYZ")
    link(nt, vec, sep.inputs[0])
    mr = nt.nodes.new("ShaderNodeMapRange")
    mr.clamp = False
    mr.inputs["From Min"].default_value, mr.inputs["From Max"].default_value = G_LO, G_HI
    mr.inputs["To Min"].default_value, mr.inputs["To Max"].default_value = lo, hi
    link(nt, sep.outputs["X"], mr.inputs["Value"])
    return mr.outputs["Result"], sep.outputs["Y"]


@pytest.mark.parametrize("extend", ["EXTRAPOLATED", "HORIZONTAL"])
def test_rgb_curves_match_cycles(extend, tmp_path):
    def build(nt, vec):
        x, y = gradient(nt, vec, -0.3, 1.4)
        comb = nt.nodes.new("ShaderNodeCombineXYZ")  # r = x, g = 1 - x, b = x / 2 + 0.2 (through Math)
        inv = nt.nodes.new("ShaderNodeMath")
        inv.operation = "SUBTRACT"
        inv.inputs[0].default_value = 1.0
        link(nt, x, inv.inputs[1])
        half = nt.nodes.new("ShaderNodeMath")
        half.operation = "MULTIPLY_ADD"
        half.inputs[1].default_value, half.inputs[2].default_value = 0.5, 0.2
        link(nt, x, half.inputs[0])
        link(nt, x, comb.inputs[0])
        link(nt, inv.outputs[0], comb.inputs[1])
        link(nt, half.outputs[0], comb.inputs[2])
        cu = nt.nodes.new("ShaderNodeRGBCurve")
        m = cu.mapping
        m.extend = extend
        m.curves[0].points.new(0.3, 0.7)
        m.curves[1].points[1].location = (0.9, 0.6)
        m.curves[2].points[0].location = (0.1, 0.25)
        m.curves[3].points.new(0.5, 0.35)
        m.curves[3].points[2].handle_type = "VECTOR"
        m.update()
        cu.inputs["Fac"].default_value = 0.8
        link(nt, comb.outputs[0], cu.inputs["Color"])
        return cu.outputs["Color"]

    emission_plane(build)
    compare(tmp_path, atol=2e-3)


def test_float_curve_matches_cycles_with_the_factor_linked(tmp_path):
    def build(nt, vec):
        x, y = gradient(nt, vec, -0.8, 1.9)
        fc = nt.nodes.new("ShaderNodeFloatCurve")
        m = fc.mapping
        m.use_clip = False
        m.curves[0].points[0].location = (-0.5, 0.9)
        m.curves[0].points[1].location = (1.5, 0.2)
        m.curves[0].points.new(0.4, 1.2)
        m.update()
        link(nt, x, fc.inputs["Value"])
        link(nt, y, fc.inputs["Factor"])  # Generated y: the mix varies across the plane
        return fc.outputs["Value"]

    emission_plane(build)
    compare(tmp_path, atol=2e-3)


def test_wavelength_matches_cycles(tmp_path):
    def build(nt, vec):
        x, _ = gradient(nt, vec, 360.0, 800.0)
        w = nt.nodes.new("ShaderNodeWavelength")
        link(nt, x, w.inputs["Wavelength"])
        return w.outputs["Color"]

    emission_plane(build)
    compare(tmp_path, atol=2e-3)


def test_blackbody_matches_cycles(tmp_path):
    def build(nt, vec):
        x, _ = gradient(nt, vec, 600.0, 13000.0)
        bb = nt.nodes.new("ShaderNodeBlackbody")
        link(nt, x, bb.inputs["Temperature"])
        return bb.outputs["Color"]

    emission_plane(build)
    compare(tmp_path, atol=2e-3)


def test_a_curve_without_an_x_range_is_one_warning(tmp_path):
    """Every point at one x: Cycles would divide by a zero range; the node is named in one
    warning and its input keeps the socket's value."""
    import bpy

    from opal_diffraction.blender.export import export_scene

    def build(nt, vec):
        x, _ = gradient(nt, vec, 0.0, 1.0)
        fc = nt.nodes.new("ShaderNodeFloatCurve")
        fc.name = "Flat Curve"
        for p in fc.mapping.curves[0].points:
            p.location = (0.5, p.location[1])
        fc.mapping.update()
        link(nt, x, fc.inputs["Value"])
        return fc.outputs["Value"]

    emission_plane(build)
    ex = export_scene(bpy.context.evaluated_depsgraph_get())
    named = [w for w in ex.warnings if "Flat Curve" in w]
    assert len(named) == 1 and "not read" in named[0], ex.warnings
