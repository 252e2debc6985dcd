"""Nothing a user builds in Blender crashes, hangs or blackens a render without a word: node
cycles, volume-only materials (null boundaries), EEVEE-only outputs, FLT_MAX / inf / NaN / negative values, hair and
other skipped geometry each end with a named warning (and finite pixels) or a one-line error; every
warning reaches the user once; an error's text once; cancel is consistent. Also the property
contract that backs it: minimums, units and one-line tooltips."""

from __future__ import annotations

import math
import types

import bpy
import numpy as np
import pytest

import blender_scenes as bs
from opal_diffraction.blender import properties, ui
from opal_diffraction.blender.engine import ENGINE_ID, OpalRenderEngine, warning_summary
from opal_diffraction.blender.export import export_scene
from opal_diffraction.blender.export.nodes import MAX_INTENSITY
from opal_diffraction.core.scene.checks import SceneError

FLT_MAX = float(np.finfo(np.float32).max)


def _export():
    return export_scene(bpy.context.evaluated_depsgraph_get())


def _scene(pixels=16):
    """A grey floor and a 1 m cube (material slot free for the test) under a point light."""
    sc = bs.empty_scene(pixels, pixels)
    bs.plane(half=4.0, mat=bs.material("floor", "DIFFUSE", (0.5, 0.5, 0.5)))
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 0.5))
    bs.light("POINT", (1.0, -2.0, 4.0), 800.0)
    cam = bs.camera(location=(0, -6, 3))
    cam.rotation_euler = (math.radians(65), 0, 0)
    sc.opal.samples = 2
    sc.opal.light_paths = 0
    return sc


def _cube_material(mat):
    bpy.data.objects["Cube"].data.materials.append(mat)
    return mat


def _empty_material(name):
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    mat.node_tree.nodes.clear()
    return mat, mat.node_tree


def _render_finishes(last_render, *fragments):
    """Render; it finishes with finite pixels and a warning containing all ``fragments``."""
    bpy.ops.render.render()
    assert last_render["status"] == "FINISHED", last_render.get("message")
    assert np.isfinite(last_render["rgb"]).all(), "non-finite pixels"
    assert all(np.isfinite(p).all() for p in last_render["passes"].values())
    hits = [w for w in last_render["warnings"] if all(f in w for f in fragments)]
    assert hits, last_render["warnings"]
    return hits[0]


def _render_error(capfd, match):
    with pytest.raises(RuntimeError, match=match) as err:
        bpy.ops.render.render()
    assert "Traceback" not in capfd.readouterr().err
    return str(err.value)


# ---------------------------------------------------------------------------- node trees
def test_reroute_cycle_warns_and_renders_the_default_surface(last_render):
    _scene()
    mat, nt = _empty_material("looped")
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    r1, r2 = nt.nodes.new("NodeReroute"), nt.nodes.new("NodeReroute")
    nt.links.new(r1.outputs[0], out.inputs["Surface"])
    nt.links.new(r2.outputs[0], r1.inputs[0])
    nt.links.new(r1.outputs[0], r2.inputs[0])  # closes the loop: Blender marks this link invalid
    _cube_material(mat)
    w = _render_finishes(last_render, "material 'looped'", "cycle", "default surface")
    assert "Reroute" in w
    m = _export().scene.materials
    i = list(m.name).index("looped")
    np.testing.assert_allclose(m.color[i], 0.8)  # grey diffuse, not black
    # the cube is visible: the rendered image is not darker than with the default surface
    assert last_render["rgb"].max() > 0.05


def test_shader_mix_cycle_is_detected():
    _scene()
    mat, nt = _empty_material("mixloop")
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    mix, add = nt.nodes.new("ShaderNodeMixShader"), nt.nodes.new("ShaderNodeAddShader")
    nt.links.new(mix.outputs[0], out.inputs["Surface"])
    nt.links.new(add.outputs[0], mix.inputs[1])
    nt.links.new(mix.outputs[0], add.inputs[0])
    _cube_material(mat)
    ex = _export()
    assert any("material 'mixloop'" in w and "cycle" in w for w in ex.warnings), ex.warnings


def test_invalid_link_without_cycle_is_ignored_as_in_cycles():
    _scene()
    mat = _cube_material(bs.material("redlink", "DIFFUSE", (0.2, 0.3, 0.4)))
    nt = mat.node_tree
    glossy = nt.nodes.new("ShaderNodeBsdfGlossy")
    link = nt.links.new(glossy.outputs[0], nt.nodes["Diffuse BSDF"].inputs["Color"])  # shader -> colour
    if link.is_valid:
        pytest.skip("this Blender accepts a shader -> colour link")
    ex = _export()
    assert any("material 'redlink'" in w and "invalid" in w and "ignored" in w for w in ex.warnings)
    m = ex.scene.materials
    np.testing.assert_allclose(m.color[list(m.name).index("redlink")], (0.2, 0.3, 0.4), rtol=1e-5)


def _row(ex, name):
    m = ex.scene.materials
    return list(m.name).index(name), m


def test_volume_only_material_is_a_null_boundary_holding_its_medium(last_render):
    _scene()
    mat, nt = _empty_material("smoke")
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    vol = nt.nodes.new("ShaderNodeVolumePrincipled")
    nt.links.new(vol.outputs[0], out.inputs["Volume"])
    _cube_material(mat)
    bpy.ops.render.render()
    assert last_render["status"] == "FINISHED", last_render.get("message")
    assert np.isfinite(last_render["rgb"]).all() and (last_render["rgb"] >= 0).all()
    assert last_render["export"]["triangles"] == 2 + 12  # the cube's faces: its medium's boundary
    ex = _export()
    assert not any("volume" in w for w in ex.warnings), ex.warnings
    i, m = _row(ex, "smoke")
    # a null boundary: smooth glass of index 1, clear
    assert m.kind[i] == 2 and m.ior[i] == 1.0 and np.all(m.color[i] == 1.0)
    # Principled Volume's defaults (Color 0.5, Density 1, Absorption Color black), as Cycles' SVM:
    # sigma_s = 0.5, sigma_a = 0.5 x (1 - sqrt(0)) = 0.5, white
    np.testing.assert_allclose([m.volume_scatter_density[i], m.volume_absorption_density[i]], [0.5, 0.5], rtol=1e-5)
    np.testing.assert_allclose(m.volume_scatter_color[i], 1.0, rtol=1e-5)
    np.testing.assert_allclose(m.volume_absorption_color[i], 1.0, rtol=1e-5)
    # a material with a surface and a volume keeps its surface, and the medium inside it
    nt.links.new(nt.nodes.new("ShaderNodeBsdfDiffuse").outputs[0], out.inputs["Surface"])
    ex = _export()
    i, m = _row(ex, "smoke")
    assert m.kind[i] == 0 and m.volume_scatter_density[i] == pytest.approx(0.5)


def test_volume_only_slot_makes_only_its_faces_null():
    _scene()
    cube = bpy.data.objects["Cube"]
    mat, nt = _empty_material("fog")
    nt.links.new(nt.nodes.new("ShaderNodeVolumeAbsorption").outputs[0],
                 nt.nodes.new("ShaderNodeOutputMaterial").inputs["Volume"])
    cube.data.materials.append(bs.material("solid"))
    cube.data.materials.append(mat)
    cube.data.polygons[0].material_index = 1  # one face (2 triangles) of six is fog
    ex = _export()
    assert len(ex.scene.triangles) == 2 + 12
    i, m = _row(ex, "fog")
    assert np.count_nonzero(ex.scene.tri_material == i) == 2
    # Volume Absorption's defaults: sigma_a = Density x (1 - Color) = 1 x (1 - 0.8)
    assert m.volume_absorption_density[i] == pytest.approx(0.2, rel=1e-5) and m.volume_scatter_density[i] == 0


@pytest.mark.parametrize("outputs", [("EEVEE",), ("EEVEE", "EEVEE")])
def test_eevee_only_output_is_named(outputs, last_render):
    _scene()
    mat = _cube_material(bs.material("eevee", "DIFFUSE", (0.8, 0.2, 0.2)))
    nt = mat.node_tree
    nt.nodes["Material Output"].target = "EEVEE"
    for _ in outputs[1:]:
        nt.nodes.new("ShaderNodeOutputMaterial").target = "EEVEE"
    w = _render_finishes(last_render, "material 'eevee'", "EEVEE only")
    assert "no Material Output node" not in w and "set the Target to All or Cycles" in w


def test_several_outputs_use_the_one_cycles_renders():
    _scene()
    mat = _cube_material(bs.material("multi", "DIFFUSE", (0.1, 0.2, 0.9)))
    nt = mat.node_tree
    nt.nodes["Material Output"].target = "EEVEE"  # EEVEE: diffuse blue
    red = nt.nodes.new("ShaderNodeBsdfDiffuse")
    red.inputs["Color"].default_value = (0.9, 0.1, 0.1, 1)
    cycles_out = nt.nodes.new("ShaderNodeOutputMaterial")
    cycles_out.target = "CYCLES"
    nt.links.new(red.outputs[0], cycles_out.inputs["Surface"])
    all_out = nt.nodes.new("ShaderNodeOutputMaterial")  # ALL, but Cycles prefers its own target
    nt.links.new(nt.nodes.new("ShaderNodeEmission").outputs[0], all_out.inputs["Surface"])
    ex = _export()
    m = ex.scene.materials
    i = list(m.name).index("multi")
    np.testing.assert_allclose(m.color[i], (0.9, 0.1, 0.1), rtol=1e-5)
    np.testing.assert_allclose(m.emission[i], 0.0)
    assert not any("material 'multi'" in w for w in ex.warnings)


def test_no_output_and_empty_surface_say_so():
    _scene()
    none, _ = _empty_material("nothing")
    empty, nt = _empty_material("unplugged")
    nt.nodes.new("ShaderNodeOutputMaterial")
    cube = bpy.data.objects["Cube"]
    cube.data.materials.append(none)
    cube.data.materials.append(empty)
    cube.data.polygons[0].material_index = 1
    ex = _export()
    assert any("material 'nothing': no Material Output node: rendered black, as in Cycles" in w for w in ex.warnings)
    assert any("material 'unplugged'" in w and "nothing is connected to the Surface" in w for w in ex.warnings)


def test_material_panel_names_an_eevee_only_output():
    _scene()
    mat = bs.material("eevee_panel")
    mat.node_tree.nodes["Material Output"].target = "EEVEE"
    log = []
    ctx = types.SimpleNamespace(engine=ENGINE_ID, material=mat, scene=bpy.context.scene)
    ui.OPAL_MATERIAL_PT_surface.draw(types.SimpleNamespace(layout=_Layout(log)), ctx)
    labels = [(a[1].get("text", ""), a[1].get("icon", "")) for a in log if a[0] == "label"]
    assert any("EEVEE only" in t and icon == "ERROR" for t, icon in labels), labels


# ---------------------------------------------------------------------------- huge, inf, NaN, negative
@pytest.mark.parametrize("strength", [FLT_MAX, float("inf")])
def test_flt_max_emission_is_clamped_with_finite_pixels(strength, last_render):
    _scene()
    mat = _cube_material(bs.material("blinding", "EMISSION", (1, 1, 1)))
    mat.node_tree.nodes["Emission"].inputs["Strength"].default_value = strength
    _render_finishes(last_render, "material 'blinding'", "clamped")
    m = _export().scene.materials
    assert m.emission[list(m.name).index("blinding")].max() <= MAX_INTENSITY * (1 + 1e-6)


def test_flt_max_principled_emission_colour_and_strength(last_render):
    _scene()
    mat = _cube_material(bs.material("sun_surface", "PRINCIPLED", (0.5, 0.5, 0.5)))
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Emission Color"].default_value = (FLT_MAX, FLT_MAX, 1.0, 1.0)
    p.inputs["Emission Strength"].default_value = FLT_MAX
    _render_finishes(last_render, "material 'sun_surface'", "clamped")


@pytest.mark.parametrize("energy", [FLT_MAX, float("inf")])
def test_flt_max_light_power_is_clamped_with_finite_pixels(energy, last_render):
    _scene()
    light = bpy.data.objects["point_light"].data
    light.energy = energy
    light.color = (1.0, 1.0, 1.0)
    _render_finishes(last_render, "light 'point_light'", "power", "clamped")


def test_huge_light_colour_times_power_is_clamped(last_render):
    _scene()
    light = bpy.data.objects["point_light"].data
    light.energy, light.color = 1e30, (FLT_MAX, 1.0, 1.0)
    _render_finishes(last_render, "light 'point_light'", "clamped")
    lt = _export().scene.lights
    assert float(lt.power[0]) * float(np.max(lt.color[0])) <= MAX_INTENSITY * (1 + 1e-6)


def test_negative_strength_and_power_are_zero_with_a_warning(last_render):
    _scene()
    mat = _cube_material(bs.material("anti", "EMISSION", (1, 1, 1)))
    mat.node_tree.nodes["Emission"].inputs["Strength"].default_value = -5.0
    bs.light("SUN", (0, 0, 5), 1.0)
    bpy.data.objects["point_light"].data.energy = -100.0
    _render_finishes(last_render, "material 'anti'", "negative", "rendered as 0")
    assert any("light 'point_light'" in w and "negative power" in w for w in last_render["warnings"])
    lt = _export().scene.lights
    assert (np.asarray(lt.power) >= 0).all()


@pytest.mark.parametrize("what, setup, match", [
    ("emission", lambda: bpy.data.materials["cube"].node_tree.nodes["Emission"].inputs["Strength"]
     .__setattr__("default_value", float("nan")), r"material 'cube': 'Strength' of 'Emission' is NaN"),
    ("colour", lambda: bpy.data.materials["cube"].node_tree.nodes["Emission"].inputs["Color"]
     .__setattr__("default_value", (float("nan"), 1, 1, 1)), r"material 'cube': 'Color' of 'Emission' is NaN"),
    ("power", lambda: setattr(bpy.data.lights["point_light"], "energy", float("nan")),
     r"light 'point_light': its power is NaN"),
    ("light colour", lambda: setattr(bpy.data.lights["point_light"], "color", (float("nan"), 1, 1)),
     r"light 'point_light': its colour is NaN"),
])
def test_nan_values_are_a_clear_error(what, setup, match, capfd, last_render):
    _scene()
    _cube_material(bs.material("cube", "EMISSION", (1, 1, 1)))
    setup()
    text = _render_error(capfd, match)
    assert text.count(match.split(": ", 1)[1].replace("\\", "")[:20]) == 1, text  # the error's text once
    assert last_render["status"] == "ERROR"


def test_nan_world_strength_is_a_clear_error(capfd):
    sc = _scene()
    world = bpy.data.worlds.new("sky")
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = float("nan")
    sc.world = world
    _render_error(capfd, r"world 'sky': 'Strength' of 'Background' is NaN")


def test_huge_ior_and_blackbody_extremes_stay_finite(last_render):
    _scene()
    glass = _cube_material(bs.material("dense", "GLASS", (1, 1, 1), IOR=FLT_MAX))
    cold = bs.material("cold", "EMISSION", (1, 1, 1), Strength=1.0)
    bb = cold.node_tree.nodes.new("ShaderNodeBlackbody")
    bb.inputs["Temperature"].default_value = 1.0  # Planck's law underflows: the node's 800 K colour
    cold.node_tree.links.new(bb.outputs[0], cold.node_tree.nodes["Emission"].inputs["Color"])
    bpy.data.objects["plane"].data.materials[0] = cold
    _render_finishes(last_render, "material 'dense'", "IOR", "lowered")
    m = _export().scene.materials
    assert np.isfinite(m.emission).all() and m.ior[list(m.name).index("dense")] <= 1000.0
    assert glass.name == "dense"


@pytest.mark.parametrize("rotation", [float("nan"), float("inf")])
def test_nan_or_inf_grating_rotation(rotation, capfd, last_render):
    _scene()
    mat = _cube_material(bs.material("ruled", "PRINCIPLED", (0.5, 0.5, 0.5)))
    mat.opal.grating = True
    mat.opal.grating_direction = "OBJECT_X"
    mat.opal.rotation = rotation  # Blender stores NaN as given and inf as FLT_MAX
    if math.isnan(mat.opal.rotation):
        _render_error(capfd, r"material 'ruled': grating rotation must be a finite angle \(got nan\)")
        assert last_render["status"] == "ERROR"
    else:
        bpy.ops.render.render()
        assert last_render["status"] == "FINISHED"
        assert np.isfinite(last_render["rgb"]).all()
        rot = _export().scene.materials.rotation
        assert np.isfinite(rot).all() and (np.abs(rot) <= math.pi + 1e-6).all()


def test_nan_grating_values_are_problems():
    mat = bpy.data.materials.new("nan_grating")
    for name in ("period", "slit_width", "coherence_length"):
        setattr(mat.opal, name, float("nan"))
    problems = " ".join(mat.opal.grating_problems())
    assert "period must be > 0 nm (got nan nm)" in problems
    assert "slit width must be > 0 nm" in problems and "coherence length must be > 0 µm" in problems


# ---------------------------------------------------------------------------- skipped geometry
def test_hair_particle_systems_are_reported_with_counts(last_render):
    _scene()
    cube = bpy.data.objects["Cube"]
    cube.modifiers.new("fur", type="PARTICLE_SYSTEM")
    ps = cube.particle_systems[0].settings
    ps.type, ps.count = "HAIR", 40
    w = _render_finishes(last_render, "hair particle systems are not rendered")
    assert "1 skipped" in w and "'Cube'" in w and "40 strands" in w
    assert last_render["export"]["triangles"] == 2 + 12  # the emitter itself still renders


def test_hair_curves_and_point_clouds_are_reported_with_counts():
    _scene()
    curves = bpy.data.hair_curves.new("fur") if hasattr(bpy.data, "hair_curves") else None
    if curves is None:
        pytest.skip("no hair curves data in this Blender")
    curves.add_curves([4, 4, 4])
    bs.link(bpy.data.objects.new("Fur", curves))
    if hasattr(bpy.data, "pointclouds"):
        pc = bpy.data.pointclouds.new("dust")
        if hasattr(pc, "resize"):
            pc.resize(25)
        bs.link(bpy.data.objects.new("Dust", pc))
    ws = _export().warnings
    assert any(w.startswith("hair curves are not rendered: 1 skipped ('Fur'; 3 strands)") for w in ws), ws
    if hasattr(bpy.data, "pointclouds"):
        assert any(w.startswith("point clouds are not rendered: 1 skipped ('Dust'") for w in ws), ws


# ---------------------------------------------------------------------------- reporting
def test_every_warning_is_reported_once_and_counted(capfd, last_render):
    """Each warning is one report (Blender prints reports in background mode, one line each), and
    the stats line counts them."""
    _scene()
    _cube_material(bs.material("toon", "ShaderNodeBsdfToon"))
    bpy.data.objects["plane"].data.materials[0] = bs.material("toon2", "ShaderNodeBsdfToon")
    bpy.context.scene.opal.wavelength_step = 25.0
    capfd.readouterr()
    bpy.ops.render.render()
    out = capfd.readouterr().out
    warnings = last_render["warnings"]
    assert len(warnings) >= 3 and len(set(warnings)) == len(warnings)
    for w in warnings:
        assert out.count(f"Opal Diffraction: {w}") == 1, (w, out)
    assert f"{len(warnings)} warnings (all in the Info editor): {warnings[0]}" in last_render["stats_log"][-1]
    assert warning_summary([]) == "" and warning_summary(["a"]) == " | 1 warning: a"


def test_an_errors_text_appears_once(capfd, last_render):
    _scene()
    bs.mesh_object("broken", [(0, 0, 0), (1, 0, 0), (float("nan"), 1, 0)], [(0, 1, 2)])
    text = _render_error(capfd, "object 'broken'")
    assert text.count("vertex coordinate(s) are NaN") == 1, text
    assert last_render["stats_log"][-1] == f"Error: {last_render['message']}"


def test_cancel_leaves_a_consistent_status(monkeypatch, last_render):
    sc = _scene(32)
    sc.opal.samples, sc.opal.round_samples, sc.opal.tile_size = 32, 2, 8
    calls = []

    def should_stop(self):  # Esc once the render is under way
        calls.append(1)
        return len(calls) > 4

    monkeypatch.setattr(OpalRenderEngine, "_should_stop", should_stop)
    bpy.ops.render.render()
    assert last_render["status"] == "CANCELLED" and last_render["message"]
    assert last_render["stats_log"][-1].startswith("Cancelled")
    assert not any(w.startswith("cancelled") for w in last_render["warnings"])
    monkeypatch.setattr(OpalRenderEngine, "_should_stop", lambda self: True)  # Esc during the export
    bpy.ops.render.render()
    assert last_render["status"] == "CANCELLED" and last_render["stats_log"][-1] == "Cancelled"


def test_coarse_wavelength_step_warns_in_the_render(last_render):
    sc = _scene()
    sc.opal.wavelength_step = 30.0
    w = _render_finishes(last_render, "wavelength step of 30 nm", "only 11 wavelength samples")
    assert "use a step of 20 nm or less" in w
    sc.opal.wavelength_step = 20.0  # 16 samples: enough
    bpy.ops.render.render()
    assert not any("wavelength step" in w for w in last_render["warnings"])


# ---------------------------------------------------------------------------- properties
class _Layout:
    """Records labels (with their icons) and props a panel draws."""

    def __init__(self, log):
        self.log = log

    def __getattr__(self, name):
        if name in ("row", "column", "box", "split"):
            return lambda *a, **k: _Layout(self.log)
        if name in ("label", "separator", "template_node_view", "menu"):
            return lambda *a, **k: self.log.append((name, k))
        raise AttributeError(name)

    def __setattr__(self, name, value):
        object.__setattr__(self, name, value)

    def prop(self, data, name, **kw):
        assert name in data.bl_rna.properties, name
        self.log.append(("prop", dict(kw, name=name)))


def _spectrum_labels(step, lo=400.0, hi=700.0):
    sc = bpy.context.scene
    sc.opal.wavelength_min, sc.opal.wavelength_max, sc.opal.wavelength_step = lo, hi, step
    log = []
    ctx = types.SimpleNamespace(engine=ENGINE_ID, scene=sc)
    ui.OPAL_RENDER_PT_spectrum.draw(types.SimpleNamespace(layout=_Layout(log)), ctx)
    return [(k.get("text", ""), k.get("icon", "")) for kind, k in log if kind == "label"]


def test_spectrum_panel_warns_about_a_coarse_step():
    bs.empty_scene()
    labels = _spectrum_labels(30.0)
    assert ("Only 11 wavelengths: colours are approximate", "ERROR") in labels, labels
    assert _spectrum_labels(5.0) == [("61 wavelengths", "INFO")]
    assert _spectrum_labels(20.0) == [("16 wavelengths", "INFO")]
    assert ("Min must be below Max", "ERROR") in _spectrum_labels(5.0, 600.0, 500.0)
    assert ("Invalid wavelength range or step", "ERROR") in _spectrum_labels(float("nan"))  # no traceback


def _props(owner):
    return {p.identifier: p for p in getattr(bpy.types, owner).bl_rna.properties["opal"].fixed_type.properties
            if p.identifier != "rna_type"}


def test_minimums_exclude_values_that_can_only_fail_later():
    m, s = _props("Material"), _props("Scene")
    assert m["period"].hard_min == pytest.approx(properties.MIN_PERIOD_NM) and properties.MIN_PERIOD_NM > 0
    assert m["slit_width"].hard_min > 0 and m["slit_width"].hard_min <= m["period"].hard_min
    assert m["coherence_length"].hard_min == pytest.approx(properties.MIN_COHERENCE_UM)
    assert properties.MIN_COHERENCE_UM > 0
    assert m["slit_count"].hard_min >= 1 and m["abbe_number"].hard_min > 0
    assert s["wavelength_step"].hard_min > 0 and s["samples"].hard_min >= 1 and s["round_samples"].hard_min >= 1
    assert s["tile_size"].hard_min >= 1 and s["wavelength_min"].hard_min >= 360 and s["wavelength_max"].hard_max <= 830
    mat = bpy.data.materials.new("mins")
    mat.opal.period, mat.opal.coherence_length, mat.opal.slit_count = 0.0, 0.0, 0
    assert mat.opal.period > 0 and mat.opal.coherence_length > 0 and mat.opal.slit_count == 1
    mat.opal.slit_width = 5000.0  # wider than the period: only the render can tell, with a clear message
    assert any("larger than its period" in p for p in mat.opal.grating_problems())


#: Properties that are lengths, and how each says its unit.
LENGTHS = {("Scene", "wavelength_min"), ("Scene", "wavelength_max"), ("Scene", "wavelength_step"),
           ("Material", "period"), ("Material", "slit_width"), ("Material", "coherence_length"),
           ("Material", "sphere_diameter"), ("Material", "diameter_spread")}


def test_every_length_says_its_unit():
    for owner, name in LENGTHS:
        p = _props(owner)[name]
        says = (p.unit == "LENGTH" or p.subtype == "WAVELENGTH" or "nm" in p.description or "µm" in p.description
                or "nm" in p.name or "µm" in p.name)
        assert says, (owner, name)
    assert "µm" in _props("Material")["coherence_length"].description
    mat = bpy.data.materials.new("units")
    mat.opal.grating = True
    log = []
    ui.OPAL_MATERIAL_PT_grating.draw(types.SimpleNamespace(layout=_Layout(log)),
                                     types.SimpleNamespace(engine=ENGINE_ID, material=mat))
    drawn = {k["name"]: k.get("text", "") for kind, k in log if kind == "prop"}
    assert drawn["coherence_length"] == "Coherence Length (µm)"
    for owner in ("Scene", "Material"):  # every float with a physical unit is covered above
        for name, p in _props(owner).items():
            if p.type == "FLOAT" and p.subtype in ("WAVELENGTH", "DISTANCE") or p.unit == "LENGTH":
                assert (owner, name) in LENGTHS, (owner, name)


def _clean(text: str) -> bool:
    return bool(text) and "\n" not in text and text == text.strip() and "  " not in text and not text.endswith(".")


def test_tooltips_are_one_clean_line():
    """Every property of scene.opal and material.opal and every enum item: one line, no doubled or
    trailing spaces, no final period (Blender adds one, as for its own tooltips)."""
    for owner in ("Scene", "Material"):
        for name, p in _props(owner).items():
            assert _clean(p.description), (owner, name, p.description)
            if p.type == "ENUM":
                for item in p.enum_items:
                    assert _clean(item.description), (owner, name, item.identifier, item.description)
    for op in (bpy.ops.opal.export_scene, bpy.ops.opal.dispersion_preset):
        rna = op.get_rna_type()
        assert _clean(rna.description), (rna.identifier, rna.description)
        for p in rna.properties:
            if p.identifier != "rna_type" and not p.is_hidden:
                assert _clean(p.description), (rna.identifier, p.identifier, p.description)
                for item in getattr(p, "enum_items", ()):
                    assert _clean(item.description), (rna.identifier, item.identifier)


def test_export_operator_reports_warnings_and_errors_without_a_traceback(tmp_path, capfd):
    _scene()
    _cube_material(bs.material("looped_op", "DIFFUSE"))
    nt = bpy.data.materials["looped_op"].node_tree
    r1, r2 = nt.nodes.new("NodeReroute"), nt.nodes.new("NodeReroute")
    nt.links.new(r1.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    nt.links.new(r2.outputs[0], r1.inputs[0])
    nt.links.new(r1.outputs[0], r2.inputs[0])
    assert bpy.ops.opal.export_scene(filepath=str(tmp_path / "s.npz")) == {"FINISHED"}
    bpy.data.lights["point_light"].energy = float("nan")
    with pytest.raises(RuntimeError, match="light 'point_light': its power is NaN"):
        bpy.ops.opal.export_scene(filepath=str(tmp_path / "t.npz"))
    assert "Traceback" not in capfd.readouterr().err


def test_nan_material_raises_scene_error_from_the_export():
    _scene()
    mat = _cube_material(bs.material("bad_mix", "DIFFUSE"))
    nt = mat.node_tree
    mix = nt.nodes.new("ShaderNodeMixShader")
    mix.inputs["Fac"].default_value = float("nan")
    nt.links.new(nt.nodes["Diffuse BSDF"].outputs[0], mix.inputs[1])
    nt.links.new(mix.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    with pytest.raises(SceneError, match="material 'bad_mix': 'Fac' of 'Mix Shader' is NaN"):
        _export()


@pytest.mark.parametrize("clip", [(0.1, 100.0), (0.1, 5.0), (6.5, 100.0)])
def test_camera_clipping_is_exported_and_rendered_without_a_warning(clip):
    """Clip start / end are rendered as Cycles applies them (core/sampling/camera.py; the parity
    test tests/blender/test_camera_parity.py compares the image): exported as they are, no
    warning any more."""
    _scene()
    cam = bpy.context.scene.camera
    cam.data.clip_start, cam.data.clip_end = clip
    ex = _export()
    assert (ex.scene.camera.clip_start, ex.scene.camera.clip_end) == pytest.approx(clip)
    assert not [w for w in ex.warnings if "clip" in w], ex.warnings
