"""The camera check (core/render/view_check.py): a camera that sees none of the scene's objects is
named in the render's warnings, with the settings to check; one that sees them is not."""

import dataclasses

import numpy as np
import pytest

from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings

SETTINGS = RenderSettings(samples=1, light_paths=0, wavelength_step=20)


def _scene(world=(0.0, 0.0, 0.0)) -> Scene:
    s = Scene(materials=Materials.from_list([{"color": (0.8, 0.8, 0.8)}]))
    s.add_mesh(*primitives.quad((-1, -1, 0), (2, 0, 0), (0, 2, 0)), material=0)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (0, 0, 3), "power": 100}])
    s.camera = Camera.look_at((0, -4, 3), (0, 0, 0), width=24, height=16)
    s.world_color = np.asarray(world, np.float32)
    return s


def _warnings(scene) -> list[str]:
    return [w for w in render(scene, SETTINGS).warnings if "camera sees none" in w]


def test_a_camera_that_sees_the_scene_gives_no_warning():
    assert _warnings(_scene()) == []


@pytest.mark.parametrize("change, named", [({"shift_x": 10.0}, "shift 10"), ({"shift_x": -10.0}, "shift -10 / 0"),
                                           ({"shift_y": 10.0}, "shift 0 / 10"), ({"lens": 1.0}, "lens 1 mm"),
                                           ({"kind": "ORTHO", "ortho_scale": 1e6}, "orthographic scale 1e+06")])
def test_a_camera_that_sees_nothing_is_named_with_its_settings(change, named):
    s = _scene()
    s.camera = dataclasses.replace(s.camera, **change)
    r = render(s, SETTINGS)
    assert float(r.rgb.max()) == 0.0  # the image the warning explains
    (w,) = [w for w in r.warnings if "camera sees none" in w]
    assert named in w and "a black image" in w


def test_a_camera_looking_away_under_a_lit_world_sees_only_the_world():
    s = _scene(world=(0.2, 0.2, 0.2))
    s.camera = Camera.look_at((0, -4, 3), (0, -8, 3), width=24, height=16)  # facing away from the quad
    (w,) = _warnings(s)
    assert "only the world" in w
