"""core/render/frame.py's hooks for the engine's Persistent Data: ``render(..., reuse=, light=,
on_prepared=, on_light=)`` and ``reusable_light``. A render that reuses an earlier preparation and
light pass must give the image a render without them gives (bit for bit: same seed, same work),
and must run the light pass again wherever the kept one does not fit (another scene, the camera
splat of another view, a pass cut short)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

import pytest

from opal_diffraction.core.render.frame import render, reusable_light
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.model import Camera
from test_pipeline import SETTINGS, glass_scene  # a dispersive glass box on a floor under a point light


MOVED = Camera.look_at((1, -5, 3), (0, 0, 0.5), width=24, height=16)


def _kept(settings):
    keep = {}
    render(glass_scene(), settings, on_prepared=lambda p: keep.update(prepared=p),
           on_light=lambda lp: keep.update(light=lp))
    return keep["prepared"], keep["light"]


def _second(settings, scene, prepared, light):
    ran = []
    rr = render(scene, settings, reuse=prepared, light=light, on_prepared=lambda p: ran.append(("prepared", p)),
                on_light=lambda lp: ran.append(("light", lp)))
    return rr, dict(ran)


def test_camera_move_without_splat_keeps_the_light_pass_and_matches_a_fresh_render():
    s = replace(SETTINGS, caustic_splat=False)
    prepared, light = _kept(s)
    moved = replace(glass_scene(), camera=MOVED)
    rr, ran = _second(s, moved, prepared, light)
    assert "light" not in ran  # the kept light pass was read
    assert ran["prepared"].key == prepared.key and ran["prepared"].accel is prepared.accel
    fresh = render(moved, s)
    np.testing.assert_array_equal(rr.rgb, fresh.rgb)


def test_camera_move_with_splat_runs_the_light_pass_again():
    prepared, light = _kept(SETTINGS)
    assert light.splat is not None
    moved = replace(glass_scene(), camera=MOVED)
    rr, ran = _second(SETTINGS, moved, prepared, light)
    assert "light" in ran and ran["light"] is not light  # the splat belongs to the first camera
    assert ran["prepared"].key == prepared.key  # the map would still fit; the splat does not
    fresh = render(moved, SETTINGS)
    np.testing.assert_array_equal(rr.rgb, fresh.rgb)
    # the same camera again: the kept pass (with its splat) fits
    assert reusable_light(ran["prepared"], ran["light"]) is ran["light"]


def test_a_moved_object_or_another_seed_is_not_reused():
    s = replace(SETTINGS, caustic_splat=False)
    prepared, light = _kept(s)
    scene = glass_scene()
    v = np.array(scene.vertices)
    v[4:] += np.float32(0.25)  # the box moves
    scene = replace(scene, vertices=v)
    rr, ran = _second(s, scene, prepared, light)
    assert "light" in ran and ran["prepared"].key != prepared.key and ran["prepared"].accel is not prepared.accel
    np.testing.assert_array_equal(rr.rgb, render(scene, s).rgb)
    rr, ran = _second(replace(s, seed=6), glass_scene(), prepared, light)
    assert "light" in ran
    np.testing.assert_array_equal(rr.rgb, render(glass_scene(), replace(s, seed=6)).rgb)


def test_cut_short_or_cancelled_light_passes_are_not_reused():
    s = replace(SETTINGS, caustic_splat=False)
    prepared, light = _kept(s)
    assert reusable_light(prepared, light) is light
    assert reusable_light(prepared, None) is None
    assert reusable_light(prepared, replace(light, cancelled=True)) is None
    timed = replace(light, warnings=("time limit reached during the light pass: caustics from 0.01 M of 0.02 M light paths",))
    assert reusable_light(prepared, timed) is None
    assert reusable_light(prepared, replace(light, key=-1)) is None


def test_with_view_checks_the_camera():
    prepared, _ = _kept(SETTINGS)
    bad = replace(MOVED, matrix=np.full((4, 4), np.nan))
    with pytest.raises(SceneError, match="camera matrix"):
        prepared.with_view(bad)
