"""Volume shaders -> the core's medium columns (blender/export/volumes.py; docs/physics.md section
15.1): the World Output's Volume as Scene.world_volume, sums and mixes as Cycles' SVM weighs
closures, and what has no homogeneous form named in warnings."""

import math

import bpy
import numpy as np
import pytest

import blender_scenes as bs
from opal_diffraction.blender.export import export_scene


def _world_volume(*nodes):
    """A world whose Volume is ``nodes`` (idname, inputs) added together (one: alone)."""
    sc = bs.empty_scene(8, 8)
    bs.plane(half=2.0, mat=bs.material("floor"))
    bs.camera(location=(0, 0, 3))
    world = bpy.data.worlds.new("fog")
    nt = world.node_tree
    made = []
    for idname, inputs in nodes:
        n = nt.nodes.new(idname)
        for k, v in inputs.items():
            n.inputs[k].default_value = v
        made.append(n)
    sock = made[0].outputs[0]
    for n in made[1:]:
        add = nt.nodes.new("ShaderNodeAddShader")
        nt.links.new(sock, add.inputs[0])
        nt.links.new(n.outputs[0], add.inputs[1])
        sock = add.outputs[0]
    nt.links.new(sock, nt.nodes["World Output"].inputs["Volume"])
    sc.world = world
    return made


def _exported():
    ex = export_scene(bpy.context.evaluated_depsgraph_get())
    s = ex.scene
    assert s.world_volume >= 0
    return ex, s.materials, s.world_volume


def test_world_scatter_plus_absorption_is_the_world_medium():
    _world_volume(("ShaderNodeVolumeScatter", {"Color": (0.9, 0.6, 0.3, 1), "Density": 0.4, "Anisotropy": 0.5}),
                  ("ShaderNodeVolumeAbsorption", {"Color": (0.5, 0.75, 1.0, 1), "Density": 0.2}))
    ex, m, w = _exported()
    assert m.name[w] == "(world volume)"
    # sigma_s = 0.4 x (0.9, 0.6, 0.3); sigma_a = 0.2 x (1 - (0.5, 0.75, 1)) (colours in linear Rec.709:
    # the default working space is Rec.709)
    np.testing.assert_allclose(m.volume_scatter_density[w] * m.volume_scatter_color[w], [0.36, 0.24, 0.12], rtol=1e-4)
    np.testing.assert_allclose(m.volume_absorption_density[w] * m.volume_absorption_color[w], [0.1, 0.05, 0.0],
                               atol=1e-6)
    assert m.volume_anisotropy[w] == pytest.approx(0.5)
    assert not (ex.scene.tri_material == w).any()  # no face uses the world's row


def test_mix_shader_weighs_and_principled_emits():
    sc = bs.empty_scene(8, 8)
    bs.plane(half=2.0, mat=bs.material("floor"))
    world = bpy.data.worlds.new("mix")
    nt = world.node_tree
    p = nt.nodes.new("ShaderNodeVolumePrincipled")
    p.inputs["Density"].default_value = 2.0
    p.inputs["Color"].default_value = (0.5, 0.5, 0.5, 1)
    p.inputs["Absorption Color"].default_value = (0.25, 0.25, 0.25, 1)
    p.inputs["Emission Strength"].default_value = 3.0
    p.inputs["Emission Color"].default_value = (1.0, 0.5, 0.25, 1)
    mix = nt.nodes.new("ShaderNodeMixShader")
    mix.inputs["Fac"].default_value = 0.25
    nt.links.new(p.outputs[0], mix.inputs[2])  # weight Fac = 0.25; the other input empty
    nt.links.new(mix.outputs[0], nt.nodes["World Output"].inputs["Volume"])
    sc.world = world
    _, m, w = _exported()
    # 0.25 x Principled: sigma_s = 0.25 x 2 x 0.5, sigma_a = 0.25 x 2 x 0.5 x (1 - sqrt(0.25))
    assert m.volume_scatter_density[w] == pytest.approx(0.25, rel=1e-5)
    assert m.volume_absorption_density[w] == pytest.approx(0.125, rel=1e-5)
    np.testing.assert_allclose(m.volume_emission[w], [0.75, 0.375, 0.1875], rtol=1e-5)


def test_what_has_no_homogeneous_form_is_named():
    nodes = _world_volume(("ShaderNodeVolumePrincipled", {"Blackbody Intensity": 1.0}))
    ex, _, _ = _exported()
    assert any("blackbody emission" in w for w in ex.warnings), ex.warnings
    scatter = nodes[0].id_data.nodes.new("ShaderNodeVolumeScatter")
    if hasattr(scatter, "phase"):  # Blender 4.3+: phase functions other than Henyey-Greenstein
        scatter.phase = "RAYLEIGH"
        nt = nodes[0].id_data
        nt.links.new(scatter.outputs[0], nt.nodes["World Output"].inputs["Volume"])
        ex, _, _ = _exported()
        assert any("rendered as Henyey-Greenstein" in w for w in ex.warnings), ex.warnings


def test_fog_render_is_finite_and_lights_the_air(last_render):
    _world_volume(("ShaderNodeVolumeScatter", {"Density": 0.3}))
    bs.light("SPOT", (0, 0, 2.5), 300.0, spot_size=math.radians(40))
    bpy.context.scene.opal.samples = 4
    bpy.ops.render.render()
    assert last_render["status"] == "FINISHED", last_render.get("message")
    rgb = last_render["rgb"]
    assert np.isfinite(rgb).all() and (rgb >= 0).all() and rgb.mean() > 0
