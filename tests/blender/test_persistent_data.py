"""Persistent Data (Render > Performance > Final Render): the frames of an animation keep the
exported scene, the preparation and the light pass, and take what nothing they depend on
changed (opal_diffraction/blender/persistent.py, docs/blender.md "Persistent data").

Each test renders frames 1 and 2 of a small animation with Persistent Data on and compares frame
2 with a fresh render of frame 2 with it off: the same seed and the same work give the same
image bit for bit, so the reference is exact (an independent render, not a stored snapshot)."""

from __future__ import annotations

import math

import bpy
import numpy as np

import blender_scenes as bs
from opal_diffraction.blender.engine import last_render
from opal_diffraction.blender.persistent import PersistentData, Update, camera_only_updates
from opal_diffraction.core.scene.settings import RenderSettings


def _scene(splat: bool = False):
    """A glass box on a diffuse floor under a point light (a light pass for the caustic), a
    camera keyframed to move between frames 1 and 2."""
    sc = bs.empty_scene(48, 32)
    sc.opal.light_paths_auto = False
    sc.opal.light_paths = 20_000
    sc.opal.caustic_splat = splat
    bs.plane(half=3.0, mat=bs.material("floor", "DIFFUSE", (0.6, 0.6, 0.6)))
    box = bs.mesh_object(
        "box", [(-.3, -.3, .2), (.3, -.3, .2), (.3, .3, .2), (-.3, .3, .2),
                (-.3, -.3, .8), (.3, -.3, .8), (.3, .3, .8), (-.3, .3, .8)],
        [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)],
        bs.material("glass", "GLASS", (1.0, 1.0, 1.0), IOR=1.5))
    cam = bs.camera(location=(0.0, -4.0, 3.0), rotation=(math.radians(50), 0.0, 0.0))
    bs.light("POINT", (0.3, 0.2, 3.0), 300.0)
    cam.keyframe_insert("location", frame=1)
    cam.location = (0.4, -3.8, 3.1)
    cam.keyframe_insert("location", frame=2)
    return sc, cam, box


def _render(sc, frame: int, persistent: bool):
    if sc.render.use_persistent_data != persistent:  # an edit of the scene: its frame exports everything
        sc.render.use_persistent_data = persistent
    sc.frame_set(frame)
    bpy.ops.render.render()
    assert last_render["status"] == "FINISHED", last_render.get("message")
    return last_render["rgb"].copy(), dict(last_render["persistent"]), last_render["stats_log"][-1]


def test_camera_move_reuses_export_preparation_and_light_pass():
    sc, _, _ = _scene(splat=False)
    f1, p1, _ = _render(sc, 1, True)
    assert p1["exported_geometry"] and p1["light_pass_ran"] and p1["reused"] == ()
    f2, p2, line = _render(sc, 2, True)
    # frame 2: the camera alone was exported, the light pass was not run
    assert not p2["exported_geometry"] and not p2["light_pass_ran"], p2
    assert p2["reused"] == ("export", "preparation", "light pass")
    assert "persistent data: reused export, preparation, light pass" in line
    assert np.abs(f2 - f1).max() > 0.05  # the camera did move
    fresh, p_off, line_off = _render(sc, 2, False)
    assert p_off["on"] is False and p_off["reused"] == () and p_off["kept"] is False
    assert "persistent data" not in line_off
    np.testing.assert_array_equal(f2, fresh)  # bit for bit: same seed, same light pass, same camera


def test_camera_splat_is_resplatted_into_the_new_view():
    """The camera splat (light paths joined to the camera) is made for one view; the light pass
    keeps the splat's light-path vertices and frame 2's splat is made from them for the new
    camera: neither the export nor the light paths run again, and frame 2 is a fresh render of
    frame 2, bit for bit (the same landings joined to the same camera)."""
    sc, _, _ = _scene(splat=True)
    f1, p1, line1 = _render(sc, 1, True)
    assert p1["splat_vertices"]["vertices"] > 0 and not p1["splat_vertices"]["over_cap"], p1
    f2, p2, line = _render(sc, 2, True)
    assert not p2["exported_geometry"] and not p2["light_pass_ran"], p2
    assert p2["reused"] == ("export", "preparation", "light pass")
    rs = p2["resplat"]
    assert rs["resplat_vertices"] == p1["splat_vertices"]["vertices"] and rs["resplat_rays"] > 0
    assert "persistent data: reused export, preparation, light pass; camera splat re-splatted from" in line
    assert "no light paths traced" in line and "ran again" not in line
    assert np.abs(f2 - f1).max() > 0.05  # the camera did move
    # F12 again on frame 2: the re-splatted pass fits its own view, nothing is re-splatted
    again, p3, line3 = _render(sc, 2, True)
    assert p3["reused"] == ("export", "preparation", "light pass") and p3["resplat"] is None, p3
    assert "re-splatted" not in line3
    fresh, _, _ = _render(sc, 2, False)
    np.testing.assert_array_equal(f2, fresh)
    np.testing.assert_array_equal(again, fresh)


def test_camera_and_samples_changed_reexports_and_still_resplats():
    """Frame 2 changes the samples too (a scene edit: everything is exported again): the
    preparation's ray caster and the light pass are found unchanged by comparing the arrays, and
    the kept splat vertices are splatted into the moved camera; frame 2 is the fresh render's."""
    sc, _, _ = _scene(splat=True)
    _render(sc, 1, True)
    sc.opal.samples = sc.opal.samples + 2
    f2, p2, line = _render(sc, 2, True)
    assert p2["exported_geometry"] and not p2["light_pass_ran"], p2
    assert "ray caster" in p2["reused"] and "light pass" in p2["reused"] and p2["resplat"] is not None, p2
    assert "camera splat re-splatted" in line
    fresh, _, _ = _render(sc, 2, False)
    np.testing.assert_array_equal(f2, fresh)


def test_over_the_cap_the_light_pass_runs_again(monkeypatch):
    """Splat vertices over SPLAT_VERTEX_CAP are not kept (said on frame 1); frame 2 runs the light
    pass again for the new camera and says why; the image is still the fresh render's."""
    from opal_diffraction.blender import persistent

    monkeypatch.setattr(persistent, "SPLAT_VERTEX_CAP", 1000)
    sc, _, _ = _scene(splat=True)
    _, p1, line1 = _render(sc, 1, True)
    assert p1["splat_vertices"]["over_cap"] and p1["splat_vertices"]["bytes"] > 1000, p1
    assert "camera-splat vertices not kept" in line1 and "a camera move runs the light pass again" in line1
    f2, p2, line = _render(sc, 2, True)
    assert not p2["exported_geometry"] and p2["light_pass_ran"] and p2["resplat"] is None, p2
    assert p2["reused"] == ("export", "preparation")
    assert "light pass ran again: the camera splat's vertices" in line and "cap" in p2["light_pass_note"]
    fresh, _, _ = _render(sc, 2, False)
    np.testing.assert_array_equal(f2, fresh)


def _blurred_scene(keys):
    """_scene with the camera splat and Render > Motion Blur on, the camera keyframed at ``keys``
    ((frame, location), ...) instead."""
    sc, cam, box = _scene(splat=True)
    cam.animation_data_clear()
    for frame, loc in keys:
        cam.location = loc
        cam.keyframe_insert("location", frame=frame)
    sc.render.use_motion_blur = True
    sc.render.motion_blur_shutter = 0.5
    return sc


def test_motion_blur_moving_camera_reuses_the_light_pass_without_a_splat():
    """A camera moving through both frames' shutters has no splat (the eye pass reads the caustic
    map: docs/physics.md section 6.13), so frame 2 takes the camera-only path and the light pass as
    it is, and is the fresh render of frame 2."""
    sc = _blurred_scene([(1, (0.0, -4.0, 3.0)), (2, (0.4, -3.8, 3.1)), (3, (0.8, -3.6, 3.2))])
    _, p1, _ = _render(sc, 1, True)
    assert p1["splat_vertices"] is None  # no splat, nothing to keep
    f2, p2, line = _render(sc, 2, True)
    assert p2["reused"] == ("export", "preparation", "light pass") and not p2["light_pass_ran"], p2
    assert p2["resplat"] is None and "ran again" not in line
    fresh, _, _ = _render(sc, 2, False)
    np.testing.assert_array_equal(f2, fresh)


def test_motion_blur_still_camera_after_a_moving_one_runs_the_light_pass_again():
    """The camera moves during frame 1's shutter (no splat, so no vertices kept) and stands still
    through frame 2's (a splat is needed): the light pass runs again, the stats line says why,
    and frame 2 is the fresh render's. Frame 3 (still again) then re-splats frame 2's vertices."""
    sc = _blurred_scene([(1, (0.0, -4.0, 3.0)), (1.5, (0.4, -3.8, 3.1)), (3, (0.4, -3.8, 3.1))])
    sc.frame_end = 3
    _render(sc, 1, True)
    f2, p2, line = _render(sc, 2, True)
    assert not p2["exported_geometry"] and p2["light_pass_ran"], p2
    assert "light pass ran again: the kept light pass kept no camera-splat vertices" in line
    fresh, _, _ = _render(sc, 2, False)
    np.testing.assert_array_equal(f2, fresh)


def test_moved_object_is_exported_and_lit_again():
    sc, cam, box = _scene(splat=False)
    box.keyframe_insert("location", frame=1)
    box.location = (0.5, 0.3, 0.0)
    box.keyframe_insert("location", frame=2)
    _render(sc, 1, True)
    f2, p2, _ = _render(sc, 2, True)
    assert p2["exported_geometry"] and p2["light_pass_ran"], p2
    assert "ray caster" not in p2["reused"] and "light pass" not in p2["reused"]
    fresh, _, _ = _render(sc, 2, False)
    np.testing.assert_array_equal(f2, fresh)
    # back to frame 1: the box returns, and the image is frame 1's fresh render
    f1_again, p1, _ = _render(sc, 1, True)
    fresh1, _, _ = _render(sc, 1, False)
    np.testing.assert_array_equal(f1_again, fresh1)


def test_same_frame_again_reuses_everything_and_a_material_change_does_not():
    sc, _, _ = _scene(splat=False)
    a, _, _ = _render(sc, 1, True)
    b, p, _ = _render(sc, 1, True)  # F12 again, nothing changed
    assert p["reused"] == ("export", "preparation", "light pass"), p
    np.testing.assert_array_equal(a, b)
    bpy.data.materials["glass"].node_tree.nodes["Glass BSDF"].inputs["IOR"].default_value = 1.7
    c, p, _ = _render(sc, 1, True)
    assert p["exported_geometry"] and p["light_pass_ran"] and "light pass" not in p["reused"], p
    fresh, _, _ = _render(sc, 1, False)
    np.testing.assert_array_equal(c, fresh)


def test_persistent_data_off_keeps_nothing():
    sc, _, _ = _scene(splat=False)
    _render(sc, 1, True)
    _, p, _ = _render(sc, 2, False)
    assert p["on"] is False and p["reused"] == () and p["kept"] is False
    assert p["exported_geometry"] and p["light_pass_ran"]


def _u(id_type, name, geometry=False):
    return Update(id_type, name, geometry, True, False)


def test_camera_only_rule():
    cam = ("camera", "camera")
    assert camera_only_updates([], *cam)
    assert camera_only_updates([_u("OBJECT", "camera"), _u("ACTION", "cameraAction"), _u("CAMERA", "camera")], *cam)
    assert not camera_only_updates([_u("OBJECT", "camera"), _u("OBJECT", "box")], *cam)
    assert not camera_only_updates([_u("OBJECT", "camera", geometry=True)], *cam)
    for other in ("MATERIAL", "WORLD", "LIGHT", "MESH", "SCENE", "COLLECTION", "IMAGE", "NODETREE"):
        assert not camera_only_updates([_u(other, "camera")], *cam), other


def test_camera_only_needs_seen_updates_and_equal_settings():
    from opal_diffraction.blender.persistent import Kept

    pd = PersistentData()
    setup = (48, 32, None, "camera")
    s = RenderSettings(spectral_exr="/tmp/a_0001.exr")
    assert pd.camera_only([], s, setup, "camera", "camera") is None  # nothing kept yet
    pd.kept = Kept(RenderSettings(), setup, None, (), None)
    assert pd.camera_only([], s, setup, "camera", "camera") is pd.kept  # the EXR's frame path may differ
    assert pd.camera_only(None, s, setup, "camera", "camera") is None  # updates not seen: export all
    assert pd.camera_only([], RenderSettings(seed=1), setup, "camera", "camera") is None  # animated seed
    assert pd.camera_only([], s, (64, 32, None, "camera"), "camera", "camera") is None  # resolution
    pd.free()
    assert pd.kept is None


def test_each_view_layer_keeps_its_own_frame(monkeypatch):
    """Two view layers, the second without the glass box: each has its own depsgraph and its own
    kept frame, so each layer's frame 2 is its fresh render (not the other layer's kept scene)."""
    from opal_diffraction.blender.engine import OpalRenderEngine

    sc, _, box = _scene(splat=False)
    coll = bpy.data.collections.new("glass")
    sc.collection.children.link(coll)
    sc.collection.objects.unlink(box)
    coll.objects.link(box)
    layer_b = sc.view_layers.new("without glass")
    layer_b.layer_collection.children["glass"].exclude = True
    sc.render.use_single_layer = False
    per_layer = []  # (view layer, rgb, persistent) of every render call
    original = OpalRenderEngine._render

    def spy(self, depsgraph):
        original(self, depsgraph)
        per_layer.append((depsgraph.view_layer.name, last_render["rgb"].copy(), dict(last_render["persistent"])))

    monkeypatch.setattr(OpalRenderEngine, "_render", spy)
    _render(sc, 1, True)
    _render(sc, 2, True)
    frame2 = {name: (rgb, p) for name, rgb, p in per_layer[-2:]}
    per_layer.clear()
    _render(sc, 2, False)
    fresh = {name: rgb for name, rgb, _ in per_layer}
    assert set(frame2) == set(fresh) == {"ViewLayer", "without glass"}
    for name in fresh:
        np.testing.assert_array_equal(frame2[name][0], fresh[name], err_msg=name)
    assert np.abs(fresh["ViewLayer"] - fresh["without glass"]).max() > 0.05  # the layers differ
    assert frame2["ViewLayer"][1]["reused"], frame2["ViewLayer"][1]
    assert frame2["without glass"][1]["reused"] and not frame2["without glass"][1]["light_pass_ran"]
