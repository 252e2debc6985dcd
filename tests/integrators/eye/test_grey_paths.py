"""Grey path weights (core/integrators/eye/grey_paths.py, docs/physics.md section 4.13): carrying a grey path's
throughput as one coefficient over the constant spectrum changes how the estimate is computed,
never what it is. The same render (same seed, so the same random numbers, paths and Russian
roulette decisions) with the coefficients and with dense spectral weights (the n samples per
path the eye pass used before) must agree to float32 rounding; a scene mixes grey, coloured,
textured and mirror surfaces, a world colour, a sized light and a world map, so batches switch
between the two representations."""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.integrators.eye import constants, grey_paths
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings


def _scene(world_map: bool, coloured: bool, textured: bool) -> Scene:
    mats = [{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},    # floor
            {"kind": "DIFFUSE", "color": (0.8, 0.8, 0.8)},    # cube
            {"kind": "MIRROR", "color": (0.9, 0.9, 0.9)},     # a grey mirror: the coefficients go on
            {"kind": "DIFFUSE", "color": (0.7, 0.3, 0.2) if coloured else (0.3, 0.3, 0.3),
             "color_texture": 0 if textured else -1}]
    s = Scene(materials=Materials.from_list(mats), world_color=np.array([0.8, 0.9, 1.0], np.float32))
    if world_map:
        s.world_image = np.random.default_rng(5).uniform(0.2, 1.5, (8, 16, 3)).astype(np.float32)
        s.world_rotation = np.eye(3)
    s.add_mesh(*primitives.quad((-3, -3, 0), (6, 0, 0), (0, 6, 0)), material=0)
    s.add_mesh(*primitives.box((0.3, 0.4, 0.5), (1.0, 1.0, 1.0)), material=1)
    s.add_mesh(*primitives.quad((-1.8, 1.2, 0.1), (1.2, 0, 0), (0, 0.3, 1.2)), material=2)
    v, t = primitives.box((-1.0, -0.6, 0.3), (0.6, 0.6, 0.6))
    s.add_mesh(v, t, 3, uvs=np.asarray(v)[:, :2] * 2.0 if textured else None)
    if textured:  # a coloured checker on the box's material
        tex = np.where((np.indices((8, 8)).sum(0) % 2 == 0)[..., None], (0.9, 0.6, 0.2, 1), (0.1, 0.2, 0.5, 1))
        s.add_texture(tex.astype(np.float32), "CLOSEST")
    s.lights = Lights.from_list([{"kind": "AREA_RECT", "position": (1.0, -1.0, 2.5), "direction": (0, 0, -1),
                                  "size_u": 0.8, "size_v": 0.8, "power": 150.0}])
    s.camera = Camera.look_at((2.5, -4.5, 2.6), (0.0, 0.2, 0.4), width=24, height=24)
    return s


def _render(scene, monkeypatch, grey: bool):
    if not grey:
        monkeypatch.setattr(constants, "GreyPaths", lambda pm, enabled=True: grey_paths.GreyPaths(pm, enabled=False))
    settings = RenderSettings(samples=16, light_paths=0, threads=1, wavelength_step=20.0, seed=3, diffuse_bounces=6,
                              max_bounces=8)
    out = render(scene, settings)
    monkeypatch.undo()
    return out


@pytest.mark.parametrize("world_map,coloured,textured", [(False, False, False), (True, True, False),
                                                         (False, True, True)])
def test_grey_coefficients_give_the_dense_spectral_estimate(monkeypatch, world_map, coloured, textured):
    s = _scene(world_map, coloured, textured)
    a = _render(s, monkeypatch, grey=True)
    b = _render(s, monkeypatch, grey=False)
    assert b.rgb.mean() > 0.05
    for name in ("Direct", "Indirect"):
        if name in b.passes:
            np.testing.assert_allclose(a.passes[name], b.passes[name], rtol=2e-4, atol=2e-5 * b.rgb.max())
    np.testing.assert_allclose(a.rgb, b.rgb, rtol=2e-4, atol=2e-5 * b.rgb.max())


def test_grey_materials_are_the_untextured_lambertian_ones_constant_over_wavelength():
    from opal_diffraction.core.render.prepare import prepare

    s = _scene(False, True, False)
    pm = prepare(s, RenderSettings(samples=1, light_paths=0, wavelength_step=20.0))
    g = grey_paths.GreyPaths(pm)
    assert g.grey.tolist() == [True, True, False, False]  # the mirror is not Lambertian; (0.7, 0.3, 0.2) is not grey
    np.testing.assert_allclose(g.value[:2], [0.5, 0.8], rtol=1e-6)
    assert g.enabled
