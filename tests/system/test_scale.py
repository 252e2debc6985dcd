"""Scale-free numerics: the same scene at 1e-9, 1 and 1e9 times its size renders the same image.

Lengths scale by s; point, spot and area light powers by s^2 (so irradiances are unchanged: a
point light's I / r^2, an area light's P / (pi A)); a sun's irradiance needs no change. With the
same seed the random numbers are the same, so the images differ only by float rounding (a path
that grazes an edge may go another way); the test bounds the difference per 4x4 block by the
Monte Carlo noise, estimated from two renders at scale 1 with different seeds, with a
Bonferroni-corrected z threshold over all blocks and channels.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import norm

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings

W, H, BLOCK = 32, 24, 4


def scaled_scene(s: float) -> Scene:
    mats = Materials.from_list([
        {"kind": "DIFFUSE", "color": (0.6, 0.6, 0.6)},
        {"kind": "DIELECTRIC", "ior": 1.6, "dispersion": "ABBE", "abbe": 30.0, "color": (1, 1, 1)},
        {"kind": "MIRROR", "color": (0.9, 0.9, 0.9)},
        {"kind": "DIFFUSE", "color": (0.1, 0.4, 0.8), "grating": 1, "period": 1600.0, "slit_width": 800.0,
         "slit_count": 200, "coherence_length": 10.0},
    ])
    sc = Scene(materials=mats, world_color=np.array([0.02, 0.02, 0.03], np.float32))
    sc.add_mesh(*(np.asarray(a) * (s if i == 0 else 1) for i, a in enumerate(primitives.quad((0, 0, 0), (6, 0, 0), (0, 6, 0)))), material=0)
    v, t = primitives.box((0, 0, 0.6), (0.8, 0.8, 0.8))
    sc.add_mesh(np.asarray(v) * s, t, material=1)
    v, t = primitives.quad((1.4, 0.5, 0.5), (0.0, 0.8, 0.0), (0.0, 0.0, 0.8))
    sc.add_mesh(np.asarray(v) * s, t, material=2)
    v, t = primitives.quad((-1.6, 0.6, 0.01), (0.8, 0, 0), (0, 0.8, 0))
    sc.add_mesh(np.asarray(v) * s, t, material=3, tangent=(1, 0, 0))
    sc.lights = Lights.from_list([
        {"kind": "POINT", "position": (1.0 * s, -1.0 * s, 3.0 * s), "power": 600.0 * s * s},
        {"kind": "AREA_RECT", "position": (-1.5 * s, -1.0 * s, 2.5 * s), "direction": (0.3, 0.2, -1.0),
         "size_u": 0.5 * s, "size_v": 0.5 * s, "power": 200.0 * s * s},
        {"kind": "SUN", "direction": (0.2, 0.3, -1.0), "power": 1.0},
    ])
    sc.camera = Camera.look_at((0.0, -4.5 * s, 3.0 * s), (0.0, 0.0, 0.4 * s), width=W, height=H)
    return sc


def _blocks(img):
    return img.reshape(H // BLOCK, BLOCK, W // BLOCK, BLOCK, -1).mean(axis=(1, 3))


@pytest.fixture(scope="module")
def reference():
    st = RenderSettings(samples=16, light_paths=60_000, seed=1, threads=2, wavelength_step=20.0)
    a = render(scaled_scene(1.0), st)
    b = render(scaled_scene(1.0), RenderSettings(**{**st.__dict__, "seed": 2}))
    assert a.rgb.mean() > 0 and a.plan.light_pass and a.plan.gratings
    # the noise of one render's block mean, from the difference of two independent renders
    sigma = np.abs(_blocks(a.rgb) - _blocks(b.rgb)).std() / np.sqrt(2) + 1e-6 * a.rgb.mean()
    return st, a, sigma


@pytest.mark.parametrize("s", [1e-12, 1e-9, 1e9])
def test_the_image_does_not_depend_on_the_scene_scale(reference, s):
    st, ref, sigma = reference
    img = render(scaled_scene(s), st, spectral_film=True)
    # below 1e-10 m Embree's absolute epsilons fail: the NumPy BVH takes over, and says so
    assert any("too small for Embree" in w for w in img.warnings) == (s < 1e-10)
    assert np.isfinite(img.spectral).all()
    diff = _blocks(img.rgb) - _blocks(ref.rgb)
    z_max = norm.isf(0.001 / (2 * diff.size))  # two-sided, Bonferroni over blocks x channels
    # the same seed makes the two images nearly identical; a broken scale gives a black or
    # shifted image, many sigmas away
    assert np.abs(diff).max() < z_max * np.sqrt(2) * sigma, (np.abs(diff).max(), sigma)
    assert img.rgb.mean() == pytest.approx(ref.rgb.mean(), rel=0.02)
