"""Holdout with Film > Transparent (Cycles' integrate_surface_holdout; docs/physics.md section 14.8):
a camera ray meeting a surface takes its Holdout weight h off the pixel's alpha, and a pure
Holdout is black. An orthographic view from above of a lit diffuse floor with two quads on it:
a pure Holdout (h = 1, black) and a Mix(Holdout, Diffuse, 0.5) (h = 0.5, a diffuse of half its
colour); the pixels wholly on each have alpha 1 - h exactly (every camera ray meets the quad),
the floor's 1; the opaque film keeps alpha 1 and renders the Holdout black."""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.scene.validation import validate


def _scene(holdout=(1.0, 0.5)) -> Scene:
    mats = Materials.from_list([
        {"kind": "DIFFUSE", "color": (0.6, 0.6, 0.6)},
        {"kind": "DIFFUSE", "color": (0.0, 0.0, 0.0), "holdout": holdout[0]},
        {"kind": "DIFFUSE", "color": (0.4, 0.2, 0.1), "holdout": holdout[1]}])
    s = Scene(materials=mats, world_color=np.array([0.3, 0.3, 0.3], np.float32))
    s.add_mesh(*primitives.quad((0, 0, 0), (8, 0, 0), (0, 8, 0)), material=0)
    s.add_mesh(*primitives.quad((-0.5, 0, 0.1), (1.0, 0, 0), (0, 1.0, 0)), material=1)  # x in [-1, 0]
    s.add_mesh(*primitives.quad((0.75, 0, 0.1), (1.0, 0, 0), (0, 1.0, 0)), material=2)  # x in [0.25, 1.25]
    s.lights = Lights.from_list([{"kind": "POINT", "position": (0.0, 0.0, 3.0), "power": 200.0}])
    m = np.eye(4)
    m[:3, 3] = (0.0, 0.0, 5.0)
    s.camera = Camera(matrix=m, kind="ORTHO", ortho_scale=4.0, width=16, height=16)
    return s


def test_holdout_cuts_alpha_with_a_transparent_film():
    settings = RenderSettings(samples=8, light_paths=0, wavelength_step=20.0, film_transparent=True, seed=1)
    rr = render(_scene(), settings)
    # pixel x centres: -2 + (i + 0.5) / 4; rows y centres likewise (the quads span y in [-0.5, 0.5])
    rows = slice(7, 9)  # y in [-0.25, 0.25]: wholly inside both quads
    # x in [-1, 0] and [0.25, 1.25] at least 0.19 (the pixel filter's half width) inside, beyond 1.5
    hold, mix, floor = slice(5, 7), slice(10, 12), slice(14, 16)
    np.testing.assert_array_equal(rr.alpha[rows, hold], 0.0)
    np.testing.assert_array_equal(rr.rgb[rows, hold], 0.0)
    np.testing.assert_allclose(rr.alpha[rows, mix], 0.5, atol=1e-6)
    assert rr.rgb[rows, mix].mean() > 0.01
    np.testing.assert_array_equal(rr.alpha[rows, floor], 1.0)
    assert rr.rgb[rows, floor].mean() > 0.01
    # the opaque film: alpha 1 everywhere, the Holdout black
    rr2 = render(_scene(), RenderSettings(samples=8, light_paths=0, wavelength_step=20.0, seed=1))
    assert rr2.alpha is None or (rr2.alpha == 1.0).all()
    np.testing.assert_array_equal(rr2.rgb[rows, hold], 0.0)


def test_holdout_column_is_validated():
    with pytest.raises(SceneError, match="holdout"):
        validate(_scene(holdout=(1.5, 0.5)))
    assert float(Materials.from_list([{"kind": "DIFFUSE"}]).holdout[0]) == 0.0
