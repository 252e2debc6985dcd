"""Denoising and adaptive sampling in Blender: the Denoising Albedo and Denoising Normal passes
reach the compositor with Cycles' values (a red plane's albedo, its normal in Cycles' camera
space: Cycles renders the same scene in this session), a compositor Denoise node links to them,
F12 with Denoise on lowers the error of a low-sample render against a converged one and keeps
the Noisy Image pass, without pyoidn a warning says what to do instead, and the Noise Threshold
settings reach the core's RenderSettings as Cycles reads its own."""

from __future__ import annotations

import math
import sys

import blender_scenes as bs
import bpy
import numpy as np
import pytest

from opal_diffraction.blender.engine import DENOISER_MISSING, NOISY_PASS, SAMPLE_COUNT_PASS
from opal_diffraction.blender.settings import render_settings

RED = (0.8, 0.1, 0.05)


def tilted_red_plane(engine: str):
    """A large red diffuse plane, tilted, seen at an angle by a perspective camera, under a sun."""
    sc = bs.empty_scene(16, 12, engine)
    ob = bs.plane(half=20.0, mat=bs.material("red", "DIFFUSE", RED))
    ob.rotation_euler = (math.radians(25), math.radians(-15), 0)
    bs.camera(location=(1.0, -4.0, 3.0), rotation=(math.radians(55), 0, math.radians(10)))
    bs.light("SUN", (0, 0, 3), 2.0)
    if engine == "CYCLES":
        sc.view_layers[0].cycles.denoising_store_passes = True
    return sc


def _compositor(sc):
    """(tree, Render Layers node, the output socket the image is written from)."""
    tree = bpy.data.node_groups.new("out", "CompositorNodeTree")
    if hasattr(sc, "compositing_node_group"):  # Blender 5.0+
        sc.compositing_node_group = tree
        tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        out = tree.nodes.new("NodeGroupOutput").inputs[0]
    else:
        sc.use_nodes = True
        tree = sc.node_tree
        out = tree.nodes.new("CompositorNodeComposite").inputs[0]
    sc.render.use_compositing = True
    return tree, tree.nodes.new("CompositorNodeRLayers"), out


def render_pass(sc, name: str, path: str, samples: int) -> np.ndarray:
    """The pass ``name`` of a render, routed through the compositor to the written EXR."""
    tree, layers, out = _compositor(sc)
    enabled = [o.name for o in layers.outputs if o.enabled]
    assert name in enabled, enabled
    tree.links.new(layers.outputs[name], out)
    return bs.render_to_array(path, samples=samples)


@pytest.mark.parametrize("name", ["Denoising Albedo", "Denoising Normal"])
def test_feature_passes_hold_cycles_values(name, tmp_path):
    cycles = render_pass(tilted_red_plane("CYCLES"), name, str(tmp_path / "cycles.exr"), 16)
    ours = render_pass(tilted_red_plane(bs.ENGINE), name, str(tmp_path / "ours.exr"), 8)
    if name == "Denoising Albedo":
        np.testing.assert_allclose(ours, np.broadcast_to(RED, ours.shape), rtol=1e-5)
    else:  # unit length, facing the camera: negative z in Cycles' camera space
        assert np.allclose(np.linalg.norm(ours, axis=-1), 1.0, atol=1e-5) and (ours[..., 2] < -0.3).all()
    print(name, "Cycles", cycles[6, 8], "ours", ours[6, 8])
    np.testing.assert_allclose(ours, cycles, atol=2e-3)


def test_a_compositor_denoise_node_links_to_the_feature_passes(tmp_path):
    sc = tilted_red_plane(bs.ENGINE)
    tree, layers, out = _compositor(sc)
    node = tree.nodes.new("CompositorNodeDenoise")
    tree.links.new(layers.outputs["Image"], node.inputs["Image"])
    tree.links.new(layers.outputs["Denoising Normal"], node.inputs["Normal"])
    tree.links.new(layers.outputs["Denoising Albedo"], node.inputs["Albedo"])
    tree.links.new(node.outputs[0], out)
    img = bs.render_to_array(str(tmp_path / "denoised.exr"), samples=4)
    assert np.isfinite(img).all() and img.mean() > 0


def noisy_scene(engine: str = bs.ENGINE):
    """A grey plane in a grey world beside a wall: soft sky occlusion, noisy at low samples."""
    sc = bs.empty_scene(32, 32, engine)
    world = bpy.data.worlds.new("grey")
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.6, 0.6, 0.6, 1.0)
    sc.world = world
    bs.plane(half=3.0, mat=bs.material("grey", "DIFFUSE", (0.8, 0.8, 0.8)))
    wall = bs.mesh_object("wall", [(-0.15, -3, 0), (0.15, -3, 0), (0.15, 3, 0), (-0.15, 3, 0),
                                   (-0.15, -3, 0.8), (0.15, -3, 0.8), (0.15, 3, 0.8), (-0.15, 3, 0.8)],
                          [(0, 1, 2, 3), (4, 7, 6, 5), (0, 4, 5, 1), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 4, 0)],
                          bs.material("white", "DIFFUSE", (0.8, 0.8, 0.8)))
    assert wall is not None
    bs.camera(location=(0, 0, 5), ortho_scale=4.0)
    sc.opal.diffuse_bounces = 1
    sc.opal.wavelength_step = 20.0
    return sc


def rmse(a, b) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)))


def test_f12_denoise_lowers_the_error_and_keeps_the_noisy_image(tmp_path, last_render):
    pytest.importorskip("pyoidn")
    sc = noisy_scene()
    reference = bs.render_to_array(str(tmp_path / "ref.exr"), samples=256)
    sc.opal.seed = 3
    noisy = bs.render_to_array(str(tmp_path / "noisy.exr"), samples=2)
    sc.opal.use_denoising = True
    denoised = bs.render_to_array(str(tmp_path / "denoised.exr"), samples=2)
    assert last_render["status"] == "FINISHED" and not last_render["warnings"], last_render["warnings"]
    assert NOISY_PASS in last_render["result_passes"]
    np.testing.assert_allclose(last_render["passes"][NOISY_PASS], noisy, atol=1e-6)  # Standard view: linear
    e_noisy, e_clean = rmse(noisy, reference), rmse(denoised, reference)
    print(f"F12 RMSE against 256 spp: 2 spp {e_noisy:.4f}, denoised {e_clean:.4f}")
    assert e_clean < 0.5 * e_noisy


def test_denoise_without_pyoidn_warns_and_renders_the_noisy_image(tmp_path, last_render, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyoidn", None)
    sc = noisy_scene()
    sc.opal.seed = 3
    plain = bs.render_to_array(str(tmp_path / "plain.exr"), samples=2)
    sc.opal.use_denoising = True
    again = bs.render_to_array(str(tmp_path / "again.exr"), samples=2)
    assert last_render["status"] == "FINISHED"
    assert DENOISER_MISSING in last_render["warnings"]
    assert "Denoise node" in DENOISER_MISSING and "Denoising Normal" in DENOISER_MISSING
    np.testing.assert_array_equal(again, plain)
    np.testing.assert_array_equal(last_render["passes"][NOISY_PASS], last_render["rgb"])


def test_noise_threshold_settings_reach_the_core_as_cycles_reads_them(last_render):
    sc = noisy_scene()
    o = sc.opal
    rna = o.bl_rna.properties
    assert rna["adaptive_threshold"].default == pytest.approx(0.01)  # Cycles' default
    assert rna["adaptive_min_samples"].default == 0 and not rna["use_adaptive_sampling"].default
    assert not rna["use_denoising"].default
    assert render_settings(o, sc).adaptive_threshold == 0.0  # the box unchecked: off
    o.use_adaptive_sampling = True
    o.adaptive_threshold, o.adaptive_min_samples = 0.05, 12
    s = render_settings(o, sc)
    assert (s.adaptive_threshold, s.adaptive_min_samples) == (pytest.approx(0.05), 12)
    o.adaptive_threshold, o.samples = 0.0, 200  # 0: Cycles' automatic max(0.001, 1 / samples)
    assert render_settings(o, sc).adaptive_threshold == pytest.approx(1 / 200)
    o.samples = 5000
    assert render_settings(o, sc).adaptive_threshold == pytest.approx(0.001)
    # 0.01: with the stratified numbers (core/sampling/sampler.py) every pixel of this scene is below 0.05 at 16
    o.samples, o.adaptive_threshold, o.adaptive_min_samples, o.round_samples = 64, 0.01, 8, 8
    bpy.ops.render.render()
    assert last_render["status"] == "FINISHED"
    counts = last_render["sample_counts"]
    assert counts.min() == 16 and counts.max() <= 64 and counts.min() < counts.max()  # it adapted
    assert SAMPLE_COUNT_PASS in last_render["result_passes"]
    assert last_render["stats"]["samples_min"] == 16


def test_the_sampling_panel_draws_noise_threshold_and_denoise():
    import types

    from opal_diffraction.blender import ui
    from test_properties_ui import _context, _Layout

    bs.empty_scene()
    for adaptive in (False, True):
        bpy.context.scene.opal.use_adaptive_sampling = adaptive
        log = []
        ui.OPAL_RENDER_PT_sampling.draw(types.SimpleNamespace(layout=_Layout(log)), _context(bs.ENGINE))
        props = [e[1] for e in log if e[0] == "prop"]
        assert {"use_adaptive_sampling", "adaptive_threshold", "adaptive_min_samples", "use_denoising",
                "samples"} <= set(props), props
