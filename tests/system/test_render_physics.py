"""Whole renders checked against closed-form radiometry (docs/physics.md sections 1.5 and 7).

Light units are Cycles': a white point light of power P has intensity P / (4 pi) W/sr, a sun of
strength S gives S W/m^2 on a facing surface, an area light of power P has radiance P / (pi A).
The diffuse BRDF is albedo / pi. Y is read from the spectral film through the CIE observer.
"""

import numpy as np
import pytest

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.spectral.spectrum import SpectralConverter

from scenes import glass_in_uniform_world, pixel_centres_world, plane_under_light

CONV = SpectralConverter()


def luminance(result):
    return CONV.to_xyz(result.spectral)[..., 1]


def test_inverse_square_law_point_light():
    """albedo 0.5, I = 1 W/sr at 2 m: Y = rho / pi * I / r^2 = 0.039789 below the light."""
    scene = plane_under_light({"kind": "POINT", "position": (0, 0, 2), "power": 4 * np.pi}, size_m=0.16, pixels=16)
    res = render(scene, RenderSettings(samples=4, threads=1), spectral_film=True)
    y = luminance(res)
    assert y[7:9, 7:9].mean() == pytest.approx(0.039789, rel=2e-4)


def test_point_light_falloff_cos_cubed_over_the_plane():
    scene = plane_under_light({"kind": "POINT", "position": (0, 0, 2), "power": 4 * np.pi}, size_m=6.0, pixels=48)
    y = luminance(render(scene, RenderSettings(samples=16, threads=1), spectral_film=True))
    x, yy = pixel_centres_world(scene.camera)
    r2 = x**2 + yy**2 + 4.0
    expected = 0.5 / np.pi * 2.0 / r2**1.5  # I cos(theta) / r^2 with cos = h / r
    # 16 filter-distributed samples per pixel over a sloped field: small per-pixel noise, no bias
    np.testing.assert_allclose(y, expected, rtol=8e-3)
    assert abs(np.mean(y / expected) - 1) < 5e-4


def test_sun_irradiance_on_a_tilted_incidence():
    """Sun strength 1 at 20 deg from the normal: Y = rho / pi * cos(20 deg)."""
    d = np.array([np.sin(np.radians(20)), 0, -np.cos(np.radians(20))])
    scene = plane_under_light({"kind": "SUN", "direction": d, "power": 1.0}, size_m=2.0, pixels=8)
    y = luminance(render(scene, RenderSettings(samples=1, threads=1), spectral_film=True))
    np.testing.assert_allclose(y, 0.5 / np.pi * np.cos(np.radians(20)), rtol=1e-5)


def test_spot_light_is_a_point_light_masked_by_its_cone():
    power = 4 * np.pi
    spot = {"kind": "SPOT", "position": (0, 0, 2), "direction": (0, 0, -1), "power": power,
            "spot_size": np.radians(60), "spot_blend": 0.0}
    scene = plane_under_light(spot, size_m=6.0, pixels=60)
    y = luminance(render(scene, RenderSettings(samples=16, threads=1), spectral_film=True))
    x, yy = pixel_centres_world(scene.camera)
    r = np.hypot(x, yy)
    angle = np.degrees(np.arctan2(r, 2.0))
    point = 0.5 / np.pi * 2.0 / (r**2 + 4.0) ** 1.5
    inside, outside = angle < 26, angle > 34  # the filter reaches ~1.5 px across the edge
    np.testing.assert_allclose(y[inside], point[inside], rtol=1e-2)
    assert abs(np.mean(y[inside] / point[inside]) - 1) < 1e-3
    assert np.all(y[outside] == 0)


def _rect_irradiance_on_axis(radiance, a, b, h):
    """E below the centre of an a x b Lambertian rectangle at height h (four corner form factors)."""
    x, y = a / 2 / h, b / 2 / h
    f = (x / np.sqrt(1 + x * x) * np.arctan(y / np.sqrt(1 + x * x))
         + y / np.sqrt(1 + y * y) * np.arctan(x / np.sqrt(1 + y * y))) / (2 * np.pi)
    return np.pi * radiance * 4 * f


@pytest.mark.parametrize("kind", ["AREA_RECT", "AREA_DISK"])
def test_area_light_irradiance_on_axis(kind):
    power, a, b, h = 50.0, 1.0, 0.6, 1.5
    light = {"kind": kind, "position": (0, 0, h), "direction": (0, 0, -1), "axis_u": (1, 0, 0),
             "power": power, "size_u": a, "size_v": b if kind == "AREA_RECT" else a}
    scene = plane_under_light(light, size_m=0.08, pixels=8)
    res = render(scene, RenderSettings(samples=256, threads=1), spectral_film=True)
    y = luminance(res)
    if kind == "AREA_RECT":
        e = _rect_irradiance_on_axis(power / (np.pi * a * b), a, b, h)
    else:
        r = a / 2
        e = power / (np.pi * np.pi * r * r) * np.pi * r * r / (h * h + r * r)
    expected = 0.5 / np.pi * e
    # Monte Carlo: 64 pixels x 256 samples; the estimator's spread is well under 1 %
    assert y.mean() == pytest.approx(expected, rel=0.01)


def test_area_light_is_one_sided():
    light = {"kind": "AREA_RECT", "position": (0, 0, 1.0), "direction": (0, 0, 1), "power": 50.0, "size_u": 1.0}
    y = luminance(render(plane_under_light(light, size_m=1.0, pixels=8), RenderSettings(samples=4, threads=1), spectral_film=True))
    assert np.all(y == 0)


def test_white_light_on_white_diffuse_is_neutral():
    scene = plane_under_light({"kind": "POINT", "position": (0, 0, 2), "power": 100.0}, albedo=(1, 1, 1), pixels=16)
    rgb = render(scene, RenderSettings(samples=2, threads=1)).rgb
    assert rgb.min() > 0
    np.testing.assert_allclose(rgb[..., 0], rgb[..., 1], rtol=1e-5)
    np.testing.assert_allclose(rgb[..., 2], rgb[..., 1], rtol=1e-5)


@pytest.mark.parametrize("step", [10.0, 20.0])
def test_coarser_wavelength_grids_agree_on_colour(step):
    scene = plane_under_light({"kind": "POINT", "position": (0, 0, 2), "power": 100.0}, albedo=(0.8, 0.3, 0.1), pixels=8)
    ref = render(scene, RenderSettings(samples=1, threads=1)).rgb
    coarse = render(scene, RenderSettings(samples=1, threads=1, wavelength_step=step)).rgb
    np.testing.assert_allclose(coarse, ref, rtol=0.03, atol=1e-3)


def test_glass_slab_in_a_uniform_world_conserves_energy():
    """Fresnel reflection + refraction with no absorption: every path ends in the same world, so
    every pixel equals the world's radiance (R + T = 1, chosen with probability R)."""
    scene = glass_in_uniform_world({"kind": "DIELECTRIC", "color": (1, 1, 1), "ior": 1.5}, world=(0.7, 0.7, 0.7))
    rgb = render(scene, RenderSettings(samples=4, threads=1)).rgb
    np.testing.assert_allclose(rgb, 0.7, rtol=1e-4)


def test_dispersive_slab_split_is_exact_and_sample_is_unbiased():
    mat = {"kind": "DIELECTRIC", "color": (1, 1, 1), "dispersion": "DIAMOND"}
    scene = glass_in_uniform_world(mat, world=(0.5, 0.5, 0.5), pixels=24)
    # diamond's TIR traps some paths for many bounces inside the slab: allow enough of them
    split = render(scene, RenderSettings(samples=2, threads=1, dispersion_sampling="SPLIT", max_bounces=64,
                                            glossy_bounces=64, transmission_bounces=64)).rgb
    np.testing.assert_allclose(split, 0.5, rtol=1e-4)
    sample = render(scene, RenderSettings(samples=64, threads=1, dispersion_sampling="SAMPLE")).rgb
    # one wavelength per sample: per-pixel colour noise, but the image mean is the world's
    np.testing.assert_allclose(sample.mean(axis=(0, 1)), 0.5, rtol=0.01)


def test_mirror_reflects_the_world_tinted():
    tint = (0.8, 0.5, 0.2)
    scene = glass_in_uniform_world({"kind": "MIRROR", "color": tint}, world=(1, 1, 1), pixels=8)
    rgb = render(scene, RenderSettings(samples=1, threads=1)).rgb.reshape(-1, 3)
    on_mirror = rgb.max(axis=1) < 0.99  # the others see the world directly
    assert on_mirror.mean() > 0.5
    np.testing.assert_allclose(rgb[on_mirror], np.tile(tint, (on_mirror.sum(), 1)), atol=5e-3)
    np.testing.assert_allclose(rgb[~on_mirror], 1.0, atol=1e-4)


def test_a_uniform_world_lights_diffuse_surfaces():
    """A floor of albedo rho under a uniform world of radiance L, with a black infinite wall (a
    very large one) on one side: the wall hides half of the cosine-weighted hemisphere of every
    floor point, so the floor's radiance is rho L / 2 where the wall subtends 90 degrees (far
    from its edges), and rho L where nothing blocks the sky. Checked on the spectrum at every
    wavelength against block-wise noise."""
    from scipy.stats import norm

    rho, world = 0.5, 0.8
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (rho, rho, rho)},
                                {"kind": "DIFFUSE", "color": (0.0, 0.0, 0.0)}])
    s = Scene(materials=mats, world_color=np.array([world, world, world], np.float32))
    s.add_mesh(*primitives.quad((0, 0, 0), (1e4, 0, 0), (0, 1e4, 0)), material=0)
    s.add_mesh(*primitives.quad((0, 0.5, 1e4 / 2), (1e4, 0, 0), (0, 0, 1e4)), material=1)  # the wall at y = 0.5
    cam = np.eye(4)  # looking straight down at the floor just in front of the wall
    cam[:3, 3] = (0.0, 0.0, 0.3)
    s.camera = Camera(matrix=cam, kind="ORTHO", ortho_scale=0.1, width=16, height=16)
    # independent pixels: the tolerance is the blocks' scatter
    res = render(s, RenderSettings(samples=64, light_paths=0, seed=3, threads=2, blue_noise=False), spectral_film=True)
    conv_white = render(Scene(materials=mats, world_color=s.world_color, camera=s.camera),
                        RenderSettings(samples=1, light_paths=0), spectral_film=True).spectral.mean(axis=(0, 1))  # L(lambda) seen directly
    expected = 0.5 * rho * conv_white
    blocks = res.spectral.reshape(4, 4, 4, 4, -1).mean(axis=(1, 3)).reshape(16, -1)
    mean = blocks.mean(axis=0)
    sigma = blocks.std(axis=0, ddof=1) / np.sqrt(len(blocks))
    z = norm.isf(0.001 / (2 * len(mean)))
    # + 1e-5 relative: float32 accumulation (the stratified estimate leaves almost no noise here)
    assert np.all(np.abs(mean - expected) <= z * sigma + 1e-5 * expected), (mean / expected)
    assert res.rgb.min() > 0
