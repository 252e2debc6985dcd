"""Camera conventions (Blender's): sensor fit, lens, shift, orthographic scale; pixel samples."""

import numpy as np
import pytest

from opal_diffraction.core.sampling.camera import FilterSampler, generate_rays, pixel_samples
from opal_diffraction.core.scene.model import Camera


def angle_deg(d, axis):
    return np.degrees(np.arccos(np.clip(d @ np.asarray(axis, float), -1, 1)))


def test_centre_ray_looks_down_minus_z_and_edges_follow_the_sensor():
    cam = Camera(width=200, height=100, lens=50, sensor_width=36)  # AUTO fit, landscape: width spans 36 mm
    o, d = generate_rays(cam, np.array([100.0, 0.0, 200.0, 100.0]), np.array([50.0, 50.0, 50.0, 0.0]))
    np.testing.assert_allclose(d[0], [0, 0, -1], atol=1e-7)
    half_h = np.degrees(np.arctan(18 / 50))
    assert angle_deg(d[1], [0, 0, -1]) == pytest.approx(half_h, abs=1e-4)
    assert d[1, 0] < 0 and d[2, 0] > 0  # image left is camera -X
    half_v = np.degrees(np.arctan(9 / 50))  # portrait half of the 36 mm at 2:1
    assert angle_deg(d[3], [0, 0, -1]) == pytest.approx(half_v, abs=1e-4)
    assert d[3, 1] > 0  # image top is camera +Y


def test_sensor_fit_auto_portrait_and_vertical():
    portrait = Camera(width=100, height=200, lens=50, sensor_width=36)
    _, d = generate_rays(portrait, np.array([50.0]), np.array([0.0]))
    assert angle_deg(d[0], [0, 0, -1]) == pytest.approx(np.degrees(np.arctan(18 / 50)), abs=1e-4)
    vert = Camera(width=200, height=100, lens=50, sensor_height=24, sensor_fit="VERTICAL")
    _, d = generate_rays(vert, np.array([100.0]), np.array([0.0]))
    assert angle_deg(d[0], [0, 0, -1]) == pytest.approx(np.degrees(np.arctan(12 / 50)), abs=1e-4)


def test_shift_is_a_fraction_of_the_fitted_dimension():
    cam = Camera(width=200, height=100, lens=50, sensor_width=36, shift_x=0.5)
    _, d = generate_rays(cam, np.array([100.0]), np.array([50.0]))
    # shift 0.5 moves the centre by half the 36 mm sensor: the old right edge direction
    assert d[0, 0] / -d[0, 2] == pytest.approx(18 / 50, rel=1e-5)


def test_orthographic_scale_and_world_transform():
    m = np.eye(4)
    m[:3, 3] = (1, 2, 3)
    cam = Camera(matrix=m, kind="ORTHO", ortho_scale=4.0, width=100, height=50)
    o, d = generate_rays(cam, np.array([0.0, 100.0, 50.0]), np.array([25.0, 25.0, 0.0]))
    np.testing.assert_allclose(d, [[0, 0, -1]] * 3, atol=1e-7)
    np.testing.assert_allclose(o[0], [-1, 2, 3], atol=1e-6)
    np.testing.assert_allclose(o[1], [3, 2, 3], atol=1e-6)
    np.testing.assert_allclose(o[2], [1, 3, 3], atol=1e-6)


def test_look_at_points_the_camera_at_the_target():
    cam = Camera.look_at((3, -4, 2), (0, 0, 1), width=64, height=64)
    _, d = generate_rays(cam, np.array([32.0]), np.array([32.0]))
    t = np.array([0, 0, 1.0]) - [3, -4, 2]
    np.testing.assert_allclose(d[0], t / np.linalg.norm(t), atol=1e-6)


def test_pixel_samples_are_stratified_and_follow_the_filter():
    rng = np.random.default_rng(0)
    filt = FilterSampler(1.5)
    x, y, ul, idx = pixel_samples(np.array([10.0]), np.array([20.0]), 64, rng, filt)
    assert np.all(np.abs(x - 10.5) <= 1.5) and np.all(np.abs(y - 20.5) <= 1.5)  # Cycles: width 1.5 spans +-1.5 px
    assert abs(np.mean(x) - 10.5) < 0.02  # symmetric filter, stratified: tiny mean error
    # one wavelength number per stratum of 1/64
    assert np.array_equal(np.sort(np.floor(ul * 64)), np.arange(64))
    # the box filter (width 0 -> pixel centre) degenerates to centre sampling
    x0, _, _, _ = pixel_samples(np.array([3.0]), np.array([3.0]), 4, rng, FilterSampler(0))
    np.testing.assert_array_equal(x0, 3.5)
