"""Rendering through Blender: F12-equivalent output, passes, border render, progress, partial
results, cancellation, spectral EXR, scene files, colour spaces and error reporting."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time

import bpy
import numpy as np
import pytest

import blender_scenes as bs
from opal_diffraction.blender.engine import OpalRenderEngine
from opal_diffraction.core.render.output import read_exr
from opal_diffraction.core.scene.npz import load_scene

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def _box_scene(width=32, height=24):
    """A grey floor, a red cube and a point light, seen by a perspective camera."""
    sc = bs.empty_scene(width, height)
    bs.plane(half=4.0, mat=bs.material("floor", "DIFFUSE", (0.5, 0.5, 0.5)))
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 0.5))
    bpy.context.active_object.data.materials.append(bs.material("red", "PRINCIPLED", (0.8, 0.1, 0.1)))
    bs.light("POINT", (1.0, -2.0, 4.0), 800.0)
    cam = bs.camera(location=(0, -6, 3))
    cam.rotation_euler = (math.radians(65), 0, 0)
    return sc


def test_f12_equivalent_writes_a_lit_image(tmp_path, last_render):
    sc = _box_scene()
    sc.render.image_settings.file_format = "PNG"
    sc.render.filepath = str(tmp_path / "f12.png")
    bpy.ops.render.render(write_still=True)
    assert os.path.exists(tmp_path / "f12.png")
    img = bpy.data.images.load(str(tmp_path / "f12.png"))
    px = np.empty(len(img.pixels), np.float32)
    img.pixels.foreach_get(px)
    px = px.reshape(img.size[1], img.size[0], -1)
    assert tuple(img.size) == (32, 24)
    assert px[..., :3].max() > 0.3, "the image is black"
    assert last_render["status"] == "FINISHED"
    assert last_render["samples"] == sc.opal.samples
    assert last_render["stats"]["rays"] > 0 and last_render["export"]["triangles"] == 2 + 12


def test_rows_are_in_blender_order(tmp_path):
    """A bright emitter in the top half of the view must be at the top of the written image."""
    bs.empty_scene(16, 16)
    bs.camera(location=(0, 0, 5), ortho_scale=4.0)
    bs.mesh_object("top", [(-2, 0.2, 0), (2, 0.2, 0), (2, 2, 0), (-2, 2, 0)], [(0, 1, 2, 3)],
                   bs.material("glow", "EMISSION", (1, 1, 1), Strength=2.0))
    img = bs.render_to_array(str(tmp_path / "o.exr"), samples=4)  # row 0 = top of the image
    assert img[:6, :, 1].mean() > 1.5 and img[-6:, :, 1].mean() < 1e-3


def test_passes_reach_the_compositor(tmp_path):
    """Direct, Caustics and Diffraction are Render Layers outputs, and their pixels flow through the
    compositor: routing Direct to the output drops the visible background that Combined holds."""
    sc = bs.lit_plane_scene("SUN")
    world = bpy.data.worlds.new("grey")
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.3, 0.3, 0.3, 1.0)
    sc.world = world
    bpy.data.objects["camera"].data.ortho_scale = 8.0  # the plane fills the central 6 m of 8 m
    combined = bs.render_to_array(str(tmp_path / "combined.exr"), samples=4)

    tree = bpy.data.node_groups.new("passes", "CompositorNodeTree")
    if hasattr(sc, "compositing_node_group"):  # Blender 5.0+
        sc.compositing_node_group = tree
        tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        out = tree.nodes.new("NodeGroupOutput")
    else:
        sc.use_nodes = True
        tree = sc.node_tree
        out = tree.nodes.new("CompositorNodeComposite")
    layers = tree.nodes.new("CompositorNodeRLayers")
    enabled = [o.name for o in layers.outputs if o.enabled]
    for name in ("Direct", "Caustics", "Diffraction"):
        assert name in enabled, enabled
    tree.links.new(layers.outputs["Direct"], out.inputs[0])
    sc.render.use_compositing = True
    direct = bs.render_to_array(str(tmp_path / "direct.exr"), samples=4)
    assert combined[0, 0, 1] == pytest.approx(0.3, abs=1e-4)  # background in the corner
    assert direct[0, 0, 1] == pytest.approx(0.0, abs=1e-6)  # not direct light
    np.testing.assert_allclose(direct[8:24, 8:24], combined[8:24, 8:24], rtol=1e-5, atol=1e-6)


def test_result_holds_all_passes(last_render):
    _box_scene()
    bpy.ops.render.render()
    assert last_render["result_passes"] == ["Combined", "Direct", "Indirect", "Caustics", "Diffraction",
                                            "Denoising Albedo", "Denoising Normal"]
    np.testing.assert_allclose(last_render["passes"]["Direct"] + last_render["passes"]["Indirect"], last_render["rgb"],
                               atol=1e-5)
    assert np.abs(last_render["passes"]["Caustics"]).max() == 0.0


def test_border_render_matches_the_same_pixels_of_the_full_frame(tmp_path, last_render):
    sc = _box_scene(32, 32)
    sc.opal.tile_size = 8
    full = bs.render_to_array(str(tmp_path / "full.exr"), samples=4)
    sc.render.use_border = True
    sc.render.use_crop_to_border = True
    sc.render.border_min_x, sc.render.border_max_x = 0.25, 0.75
    sc.render.border_min_y, sc.render.border_max_y = 0.5, 1.0  # the top half (Blender's y is up)
    crop = bs.render_to_array(str(tmp_path / "crop.exr"), samples=4)
    assert crop.shape == (16, 16, 3)
    assert last_render["region"] == (8, 0, 24, 16)  # core rows count from the top
    np.testing.assert_allclose(crop, full[0:16, 8:24], rtol=1e-5, atol=1e-6)


def test_progress_stats_and_partial_results(last_render):
    sc = _box_scene()
    sc.opal.samples, sc.opal.round_samples = 12, 4
    bpy.ops.render.render()
    assert last_render["partial_updates"] == 3  # one partial result per progressive round
    progress, stats = last_render["progress"], last_render["stats_log"]
    assert progress and progress[-1] == pytest.approx(1.0) and progress == sorted(progress)
    assert any("round 3/3" in s and "M rays" in s for s in stats), stats
    assert "12 samples" in stats[-1] and "M rays" in stats[-1]


def test_cancel_through_test_break_stops_early(monkeypatch, last_render):
    sc = _box_scene(64, 64)
    sc.opal.samples, sc.opal.round_samples, sc.opal.tile_size = 64, 4, 16
    t0 = time.perf_counter()
    bpy.ops.render.render()
    full_s, full_rays = time.perf_counter() - t0, last_render["stats"]["rays"]
    assert last_render["status"] == "FINISHED"
    calls = []

    def should_stop(self):  # Esc after the export and a few tiles
        calls.append(1)
        return len(calls) > 6

    monkeypatch.setattr(OpalRenderEngine, "_should_stop", should_stop)
    t0 = time.perf_counter()
    bpy.ops.render.render()  # no exception
    assert last_render["status"] == "CANCELLED"
    assert last_render["stats"]["rays"] < 0.25 * full_rays
    assert time.perf_counter() - t0 < full_s


def test_cancel_during_export(monkeypatch, last_render):
    _box_scene()
    monkeypatch.setattr(OpalRenderEngine, "_should_stop", lambda self: True)
    bpy.ops.render.render()
    assert last_render["status"] == "CANCELLED"
    assert "export" in last_render["message"]


def test_ctrl_c_ends_the_render_cleanly(monkeypatch, capfd, last_render):
    """Ctrl-C (KeyboardInterrupt from the terminal) during a render: a consistent CANCELLED
    status and no traceback."""
    _box_scene()
    calls = []

    def interrupt(self):  # the interrupt arrives after the export, inside the core
        calls.append(1)
        if len(calls) > 3:
            raise KeyboardInterrupt
        return False

    monkeypatch.setattr(OpalRenderEngine, "_should_stop", interrupt)
    bpy.ops.render.render()
    assert last_render["status"] == "CANCELLED" and last_render["message"] == "interrupted"
    assert "Traceback" not in capfd.readouterr().err


def test_spectral_exr_and_scene_file(tmp_path, last_render):
    sc = _box_scene(16, 12)
    sc.frame_set(3)
    sc.opal.wavelength_step = 20.0
    sc.opal.spectral_exr = str(tmp_path / "spectral_##.exr")
    sc.opal.scene_npz = str(tmp_path / "scene_##")
    rgb = bs.render_to_array(str(tmp_path / "rgb.exr"), samples=4)
    path = tmp_path / "spectral_03.exr"
    assert last_render["spectral_exr"] == str(path)
    ch = read_exr(path)
    lam = [n for n in ch if n.startswith("S0.")]
    assert lam[0] == "S0.400,000000nm" and len(lam) == 16
    np.testing.assert_allclose(np.stack([ch[c] for c in "RGB"], -1), rgb, rtol=1e-4, atol=1e-5)
    import OpenEXR

    header = OpenEXR.File(str(path)).header()
    assert header["spectralLayoutVersion"] == "1.0" and header["emissiveUnits"] == "W.m^-2.sr^-1"
    scene = load_scene(tmp_path / "scene_03.npz")
    assert len(scene.triangles) == 14 and scene.camera.width == 16 and len(scene.lights) == 1


def test_relative_spectral_path_needs_a_saved_file(tmp_path, last_render):
    sc = _box_scene(8, 8)
    sc.opal.spectral_exr = "//spectral.exr"
    with pytest.raises(RuntimeError, match="has not been saved"):
        bpy.ops.render.render()
    assert last_render["status"] == "ERROR"
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "saved.blend"))
    bpy.context.scene.opal.samples = 2
    bpy.ops.render.render()
    assert os.path.exists(tmp_path / "spectral.exr")


def test_working_space_rec2020(tmp_path):
    """Colours are read in the file's working space and the result is written in it: converting a
    file to Linear Rec.2020 (Blender converts its colours) renders the same picture."""
    if not hasattr(bpy.ops.wm, "set_working_color_space"):
        pytest.skip("this Blender has no per-file working space")  # bpy 5.0.1 has one
    from opal_diffraction.blender.export import working_space_to_rec709

    bs.lit_plane_scene("POINT", color=(0.9, 0.4, 0.1))
    bpy.data.materials["grey"].node_tree.nodes["Diffuse BSDF"].inputs["Color"].default_value = (0.2, 0.5, 0.7, 1)
    ref = bs.render_to_array(str(tmp_path / "709.exr"), samples=4)
    try:
        bpy.ops.wm.set_working_color_space(working_space="Linear Rec.2020", convert_colors=True)
        assert working_space_to_rec709() is not None
        wide = bs.render_to_array(str(tmp_path / "2020.exr"), samples=4)
        back = wide @ working_space_to_rec709().T
    finally:
        bpy.ops.wm.set_working_color_space(working_space="Linear Rec.709", convert_colors=True)
    np.testing.assert_allclose(back.mean(axis=(0, 1)), ref.mean(axis=(0, 1)), rtol=0.01)
    assert np.abs(wide.mean(axis=(0, 1)) - ref.mean(axis=(0, 1))).max() > 1e-3  # really another space


# ---------------------------------------------------------------------------- errors
def _expect_render_error(match, capfd):
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.render.render(write_still=True)
    err = capfd.readouterr().err
    assert "Traceback" not in err, err


def test_nan_coordinates_are_a_clear_error(tmp_path, capfd, last_render):
    sc = _box_scene(8, 8)
    bs.mesh_object("broken", [(0, 0, 0), (1, 0, 0), (float("nan"), 1, 0)], [(0, 1, 2)])
    sc.render.filepath = str(tmp_path / "nan.png")
    _expect_render_error(r"object 'broken': 1 vertex coordinate\(s\) are NaN", capfd)
    assert not os.path.exists(tmp_path / "nan.png"), "no silent black image"
    assert last_render["status"] == "ERROR"


def test_no_camera_is_a_clear_error(tmp_path, capfd):
    sc = _box_scene(8, 8)
    sc.camera = None
    sc.render.filepath = str(tmp_path / "nocam.png")
    _expect_render_error("no camera", capfd)


def test_no_lights_is_a_warning(last_render):
    _box_scene(8, 8)
    for ob in [o for o in bpy.data.objects if o.type == "LIGHT"]:
        bpy.data.objects.remove(ob)
    bpy.ops.render.render()
    assert last_render["status"] == "FINISHED"
    assert any("no lights" in w for w in last_render["warnings"])


@pytest.mark.parametrize("period, slit, message", [
    (0.0, 800.0, r"grating period must be > 0 nm"),
    (500.0, 800.0, r"grating slit width \(800 nm\) is larger than its period \(500 nm\)"),
])
def test_bad_grating_is_a_clear_error(period, slit, message, capfd):
    _box_scene(8, 8)
    mat = bpy.data.materials["red"]
    mat.opal.grating = True
    mat.opal["period"], mat.opal["slit_width"] = period, slit  # stored as given (an older file's 0 too)
    _expect_render_error(f"material 'red': {message}", capfd)


def test_valid_grating_renders(last_render):
    """A grating material renders with its diffraction (the plan's grating work), no warning."""
    _box_scene(16, 16)
    mat = bpy.data.materials["red"]
    mat.opal.grating = True
    mat.opal.grating_direction = "OBJECT_X"
    bpy.ops.render.render()
    assert last_render["status"] == "FINISHED"
    assert last_render["plan_gratings"]
    assert not any("grating" in w for w in last_render["warnings"]), last_render["warnings"]


def test_bad_settings_are_a_clear_error(capfd):
    sc = _box_scene(8, 8)
    sc.opal.wavelength_min, sc.opal.wavelength_max = 600.0, 500.0
    _expect_render_error("wavelength grid", capfd)


def test_unsupported_nodes_warn_and_render(last_render):
    _box_scene(8, 8)
    mat = bs.material("toon", "ShaderNodeBsdfToon", (0.2, 0.6, 0.2))
    bpy.data.objects["Cube"].data.materials[0] = mat
    bpy.ops.render.render()
    assert last_render["status"] == "FINISHED"
    assert any("material 'toon'" in w and "not supported" in w for w in last_render["warnings"])


# ---------------------------------------------------------------------------- headless example
@pytest.mark.slow  # a subprocess that imports bpy
def test_render_example_runs_headless(tmp_path):
    out = tmp_path / "example"
    res = subprocess.run([sys.executable, os.path.join(ROOT, "examples", "render_example.py"), "--spp", "1",
                          "--resolution", "48", "30", "--light-paths", "20000", "--out", str(out)], capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    assert os.path.exists(str(out) + ".png") and os.path.exists(str(out) + ".blend")
    assert "Traceback" not in res.stderr
