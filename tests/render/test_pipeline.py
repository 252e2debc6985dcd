"""The one-way pipeline: immutable hand-offs and the reuse of a prepared scene and its light pass
(the import graph's checks are in tests/system/test_layers.py)."""

from __future__ import annotations

from dataclasses import FrozenInstanceError, replace

import numpy as np
import pytest

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.integrators.eye.eye_pass import EyePass
from opal_diffraction.core.integrators.light.light_pass import run_light_pass
from opal_diffraction.core.render.plan import plan_render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.frame import render, render_prepared
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings



def glass_scene(width=24, height=16):
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
                                {"kind": "DIELECTRIC", "ior": 1.5, "dispersion": "BK7", "color": (1, 1, 1)}])
    s = Scene(materials=mats, world_color=np.array([0.05, 0.05, 0.05], np.float32))
    s.add_mesh(*primitives.quad((0, 0, 0), (8, 0, 0), (0, 8, 0)), material=0)
    s.add_mesh(*primitives.box((0, 0, 1.0), (1.0, 1.0, 0.5)), material=1)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (0.5, -0.5, 4.0), "power": 800.0}])
    s.camera = Camera.look_at((0, -5, 3), (0, 0, 0.5), width=width, height=height)
    return s


SETTINGS = RenderSettings(samples=2, round_samples=1, light_paths=20_000, seed=5, threads=2, tile_size=8)


def test_render_equals_the_pipeline_run_step_by_step():
    full = render(glass_scene(), SETTINGS, spectral_film=True)
    prepared = prepare(glass_scene(), SETTINGS)
    plan = plan_render(prepared)
    assert plan.light_pass and plan.dispersion
    light = run_light_pass(prepared, plan=plan_render(prepared))
    staged = render_prepared(prepared, light, spectral_film=True)
    np.testing.assert_array_equal(full.spectral, staged.spectral)
    for k in full.passes:
        np.testing.assert_array_equal(full.passes[k], staged.passes[k])


def test_a_camera_move_reuses_the_light_pass_exactly():
    """with_view keeps the preparation and the light pass: the image equals a fresh render of
    the moved camera, bit for bit - one without the camera splat, which the kept light pass made
    for the first camera only (docs/physics.md section 4.7)."""
    prepared = prepare(glass_scene(), SETTINGS)
    light = run_light_pass(prepared, plan=plan_render(prepared))
    moved_cam = Camera.look_at((1, -5, 3), (0, 0, 0.5), width=24, height=16)
    moved = prepared.with_view(moved_cam, samples=3)
    assert moved.key == prepared.key and moved.accel is prepared.accel
    fresh_scene = replace(glass_scene(), camera=moved_cam)
    fresh = render(fresh_scene, replace(SETTINGS, samples=3, caustic_splat=False), spectral_film=True)
    reused = render_prepared(moved, light, spectral_film=True)
    np.testing.assert_array_equal(fresh.spectral, reused.spectral)
    with pytest.raises(ValueError, match="eye-pass settings"):
        prepared.with_view(light_paths=5)


def test_prepare_reuses_what_did_not_change():
    first = prepare(glass_scene(), SETTINGS)
    # the world colour: same geometry (structure reused), but the world lights the light pass
    # (caustics through the glass), so its key changes
    s = glass_scene()
    s.world_color = np.array([0.2, 0.1, 0.1], np.float32)
    world = prepare(s, SETTINGS, reuse=first)
    assert world.key != first.key and world.accel is first.accel
    assert not np.array_equal(world.world_spectrum, first.world_spectrum)
    # the same scene again: the same key
    assert prepare(glass_scene(), SETTINGS, reuse=first).key == first.key
    # a light's power: same geometry (structure reused), but the light pass must rerun
    s = glass_scene()
    s.lights.power[0] = 400.0
    brighter = prepare(s, SETTINGS, reuse=first)
    assert brighter.accel is first.accel and brighter.key != first.key
    # moving a vertex: everything is rebuilt
    s = glass_scene()
    s.vertices[0, 2] += 0.01
    moved = prepare(s, SETTINGS, reuse=first)
    assert moved.accel is not first.accel and moved.key != first.key
    # and a light pass never crosses preparations
    with pytest.raises(ValueError, match="another prepared scene"):
        EyePass(moved, run_light_pass(brighter, plan=plan_render(brighter)), plan=plan_render(moved))


def test_hand_offs_are_immutable():
    prepared = prepare(glass_scene(), SETTINGS)
    with pytest.raises(FrozenInstanceError):
        prepared.threads = 1
    with pytest.raises(FrozenInstanceError):
        SETTINGS.samples = 3
    with pytest.raises(ValueError, match="read-only"):
        prepared.tri_normal[0] = 0.0
    with pytest.raises(ValueError, match="read-only"):
        prepared.materials.reflectance[0] = 0.0
    with pytest.raises(ValueError, match="read-only"):
        prepared.lights.spectrum[0] = 0.0
    plan = plan_render(prepared)
    with pytest.raises(FrozenInstanceError):
        plan.light_pass = False
    light = run_light_pass(prepared, plan=plan_render(prepared))
    with pytest.raises(TypeError):
        light.stats["light_paths"] = 0
