"""Camera motion blur (docs/physics.md section 6.13), each against an independent computation:

- the interpolated camera against SciPy's Slerp (rotation) and a linear position, between the
  right two steps as Cycles' transform_motion_array_interpolate, and exactly the steps at their times;
- camera_rays with a time against the rays of a still camera at SciPy's interpolated matrix;
- the shutter curve's inverse CDF by chi-square against the curve's density (a triangle and a
  ramp with a closed shutter stretch), a flat curve being the identity;
- the shutter times' numbers: uniform (chi-square) and stratified over a pixel's samples;
- validation and the scene file keep the motion; the camera splat steps aside for a moving camera.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from chi2 import pearson
from opal_diffraction.core.integrators.light.camera_splat import view_key
from opal_diffraction.core.sampling.camera import (camera_rays, motion_frames, shutter_table, shutter_times,
                                                   time_samples)
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.model import Camera
from opal_diffraction.core.scene.validation import _validate_motion


def _steps(n=3, seed=4):
    rng = np.random.default_rng(seed)
    rots = Rotation.random(n, random_state=seed)
    m = np.tile(np.eye(4), (n, 1, 1))
    m[:, :3, :3] = rots.as_matrix() * np.array([1.0, 2.0, 0.5])  # a scaled camera: scale is dropped
    m[:, :3, 3] = rng.normal(size=(n, 3)) * 2.0
    return m, rots


def test_motion_frames_are_slerp_and_lerp_between_steps():
    m, rots = _steps(3)
    cam = Camera(motion=m, matrix=m[1])
    t = np.concatenate([np.linspace(0.0, 1.0, 41), np.random.default_rng(1).random(200)])
    r, pos = motion_frames(cam, t)
    ref_r = Slerp([0.0, 0.5, 1.0], rots)(t).as_matrix()  # SciPy: slerp per segment, the shorter arc
    np.testing.assert_allclose(r, ref_r, atol=1e-9)
    seg = np.minimum((t * 2).astype(int), 1)
    f = t * 2 - seg
    ref_p = (1 - f)[:, None] * m[seg, :3, 3] + f[:, None] * m[seg + 1, :3, 3]
    np.testing.assert_allclose(pos, ref_p, atol=1e-12)
    r0, p0 = motion_frames(cam, np.array([0.0, 0.5, 1.0]))
    np.testing.assert_allclose(r0, rots.as_matrix(), atol=1e-9)
    np.testing.assert_allclose(p0, m[:, :3, 3], atol=1e-12)


def test_moving_camera_rays_are_the_interpolated_still_cameras():
    m, rots = _steps(5, seed=9)
    kw = dict(width=40, height=30, lens=35.0, clip_start=0.3)
    cam = Camera(matrix=m[2], motion=m, **kw)
    rng = np.random.default_rng(2)
    x, y, t = rng.random(64) * 40, rng.random(64) * 30, rng.random(64)
    o, d, _, _ = camera_rays(cam, x, y, None, t)
    key = np.linspace(0, 1, 5)
    for i in range(64):
        seg = min(int(t[i] * 4), 3)
        f = t[i] * 4 - seg
        still = np.eye(4)
        still[:3, :3] = Slerp(key, rots)(t[i]).as_matrix()
        still[:3, 3] = (1 - f) * m[seg, :3, 3] + f * m[seg + 1, :3, 3]
        oi, di, _, _ = camera_rays(Camera(matrix=still, **kw), x[i:i + 1], y[i:i + 1])
        np.testing.assert_allclose(d[i], di[0], atol=2e-6)
        np.testing.assert_allclose(o[i], oi[0], atol=2e-5)
    # no time: the frame's own matrix
    o2, d2, _, _ = camera_rays(cam, x, y)
    o3, d3, _, _ = camera_rays(Camera(matrix=m[2], **kw), x, y)
    np.testing.assert_array_equal(d2, d3)


@pytest.mark.parametrize("curve", ["triangle", "ramp_closed"])
def test_shutter_table_samples_the_curve(curve):
    knots = np.linspace(0, 1, 256)  # the curve as Blender's 256 readings, linear between them
    if curve == "triangle":
        w = np.interp(knots, [0, 0.5, 1], [0.0, 1.0, 0.0])
    else:  # closed for the first quarter, then rising
        w = np.interp(knots, [0, 0.25, 1], [0.0, 0.0, 1.0])
    density = lambda x: np.interp(x, knots, w)  # noqa: E731
    cam = Camera(shutter_table=shutter_table(w))
    t = shutter_times(cam, np.random.default_rng(3).random(200_000))
    assert t.min() >= 0 and t.max() <= 1
    edges = np.linspace(0, 1, 41)
    fine = np.linspace(0, 1, 40 * 200 + 1)
    cell = np.add.reduceat(density(0.5 * (fine[1:] + fine[:-1])), np.arange(0, 40 * 200, 200))
    expected = cell / cell.sum() * len(t)
    observed = np.histogram(t, edges)[0]
    assert observed[expected == 0].sum() == 0  # a closed shutter exposes nothing
    # the table is linear between its 4096 entries: where the density opens from zero the first
    # entry's 1 / 4096 of the exposure is spread evenly, not as the square root it is; cells
    # expecting less than 0.1 % of the exposure get at most that entry's share, the rest the chi-square
    live = expected > 1e-3 * len(t)
    assert observed[~live].sum() <= expected[~live].sum() + 2 * len(t) / 4096
    p, _ = pearson(observed[live], expected[live])
    assert p > 1e-3, p
    flat = Camera(shutter_table=shutter_table(np.ones(256)))
    u = np.linspace(0, 1, 101)
    np.testing.assert_allclose(shutter_times(flat, u), u, atol=1e-3)
    np.testing.assert_array_equal(shutter_times(Camera(), u), u)


@pytest.mark.parametrize("qmc", [True, False])
def test_time_numbers_uniform_and_stratified_per_pixel(qmc):
    p, spp = 500, 16
    rng = np.random.default_rng(5)
    ids = np.arange(p, dtype=np.uint32)
    u = time_samples(p, spp, rng, (ids, np.zeros(p, np.uint32), 77) if qmc else None)
    assert u.shape == (p * spp,) and u.min() >= 0 and u.max() < 1
    per_pixel = np.sort(np.floor(u.reshape(p, spp) * spp), axis=1)
    np.testing.assert_array_equal(per_pixel, np.broadcast_to(np.arange(spp), (p, spp)))  # one per stratum
    fine = np.floor(u.reshape(p, spp) * spp * 8) % 8  # within the strata: uniform
    observed = np.bincount(fine.astype(int).ravel(), minlength=8)
    assert pearson(observed, np.full(8, p * spp / 8))[0] > 1e-3


def test_motion_validated_saved_and_keyed(tmp_path):
    from opal_diffraction.core.scene.npz import load_scene, save_scene
    from opal_diffraction.core.scene import primitives
    from opal_diffraction.core.scene.model import Materials, Scene

    m, _ = _steps(3)
    _validate_motion(Camera(motion=m))
    with pytest.raises(SceneError, match="motion"):
        _validate_motion(Camera(motion=m[:1]))
    bad = m.copy()
    bad[1, 0, 3] = np.nan
    with pytest.raises(SceneError, match="NaN"):
        _validate_motion(Camera(motion=bad))
    with pytest.raises(SceneError, match="real numbers"):
        _validate_motion(Camera(motion=m.astype(str)))
    with pytest.raises(SceneError, match="real numbers"):
        _validate_motion(Camera(motion=m.astype(complex)))
    with pytest.raises(SceneError, match="shutter_table"):
        _validate_motion(Camera(motion=m, shutter_table=np.array([0.5, 0.2, 1.0])))
    cam = Camera(matrix=m[1], motion=m, shutter_table=shutter_table(np.linspace(0, 1, 8)), width=8, height=8)
    v, t = primitives.box((0, 0, 0), 1.0)
    scene = Scene(vertices=v, triangles=t, tri_material=np.zeros(len(t), np.int32),
                  materials=Materials.from_list([{"kind": "DIFFUSE"}]), camera=cam)
    save_scene(scene, tmp_path / "s.npz")
    back = load_scene(tmp_path / "s.npz").camera
    np.testing.assert_array_equal(back.motion, cam.motion)
    np.testing.assert_array_equal(back.shutter_table, cam.shutter_table)
    assert view_key(cam, 1.5) != view_key(Camera(matrix=m[1], width=8, height=8), 1.5)
    assert view_key(cam, 1.5) == view_key(back, 1.5)


def _blackman_harris(s, width=1.5):
    """Cycles' Blackman-Harris filter over +-width px (core/sampling/camera.py FilterSampler's window)."""
    x = s / (2 * width) + 0.5
    return 0.35875 - 0.48829 * np.cos(2 * np.pi * x) + 0.14128 * np.cos(4 * np.pi * x) - 0.01168 * np.cos(6 * np.pi * x)


@pytest.mark.parametrize("curve", ["flat", "triangle"])
def test_moving_camera_render_blurs_an_edge_by_the_motion(curve):
    """An orthographic camera 10 m above a plane covering x < 0.05 m (0.1 m pixels, 32 x 8),
    sliding 0.8 m along x during the shutter (3 steps): each pixel's coverage (alpha) is the
    share of shutter time and filter footprint over the plane, 1{x_c + c(t) + 0.1 s < 0.05}
    integrated over t (the shutter curve's density) and the filter offset s (Blackman-Harris),
    numerically here. A still camera's edge spans 3 px, the blurred one up to 11."""
    from opal_diffraction.core.render.frame import render
    from opal_diffraction.core.scene import primitives
    from opal_diffraction.core.scene.model import Materials, Scene
    from opal_diffraction.core.scene.settings import RenderSettings

    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)}]))
    s.add_mesh(*primitives.quad((-10.0 + 0.05, 0.0, 0.0), (20.0, 0, 0), (0, 40.0, 0)), material=0)
    steps = np.tile(np.eye(4), (3, 1, 1))
    steps[:, :3, 3] = [(-0.4, 0.0, 10.0), (0.0, 0.0, 10.0), (0.4, 0.0, 10.0)]
    knots = np.linspace(0, 1, 256)
    w = np.ones(256) if curve == "flat" else np.interp(knots, [0, 0.5, 1], [0.0, 1.0, 0.0])
    table = shutter_table(w) if curve != "flat" else np.zeros(0)
    s.camera = Camera(matrix=steps[1], kind="ORTHO", ortho_scale=3.2, width=32, height=8, motion=steps,
                      shutter_table=table)
    s.world_color = np.array([0.2, 0.4, 0.6], np.float32)
    spp = 256
    rr = render(s, RenderSettings(samples=spp, light_paths=0, wavelength_step=20.0, max_bounces=1))
    measured = rr.alpha.mean(axis=0)
    t = np.linspace(0, 1, 2001)
    wt = np.interp(t, knots, w)
    sf = np.linspace(-1.5, 1.5, 3001)
    wf = _blackman_harris(sf)
    cam_x = -0.4 + 0.8 * t
    xc = (np.arange(32) + 0.5 - 16.0) * 0.1
    inside = (xc[:, None, None] + cam_x[None, :, None] + 0.1 * sf[None, None, :]) < 0.05
    expected = (inside * wt[None, :, None] * wf[None, None, :]).sum(axis=(1, 2)) / (wt.sum() * wf.sum())
    sigma = np.sqrt(np.maximum(expected * (1 - expected), 1 / (8 * spp)) / (8 * spp))  # binomial, per column
    z = (measured - expected) / sigma
    print(curve, "max |z|", np.abs(z).max().round(2), "ramp columns", int(((expected > 0.02) & (expected < 0.98)).sum()))
    assert np.abs(z).max() < 4.5, np.round(np.stack([measured, expected]), 3)
    ramp = (expected > 0.02) & (expected < 0.98)
    assert ramp.sum() >= 7  # the blur is there (flat 9-10, triangle 7 columns): a still camera's edge has 3


def test_object_motion_bins_blur_a_moving_edge():
    """Object motion (docs/physics.md section 6.13): the half-plane of the edge test moves 0.8 m
    along x during the shutter under a still orthographic camera, held as K = 8 time bins (the
    plane at each bin's centre time). The coverage of each column is then the mean over the bins
    of the filter's share beyond the edge at that bin's position (numerical integration), within
    4.5 sigma; and that bin approximation stays within 0.8 m / (2 K) = 0.05 m (half a pixel) of
    the continuous motion's edge: its coverage profile differs from the continuous one by at
    most 0.02 in any column (0.006 computed here, both by integration)."""
    from opal_diffraction.core.render.frame import render
    from opal_diffraction.core.scene import primitives
    from opal_diffraction.core.scene.model import Materials, Scene
    from opal_diffraction.core.scene.settings import RenderSettings

    K = 8
    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)}]))
    s.add_mesh(*primitives.quad((-10.0 + 0.05, 0.0, 0.0), (20.0, 0, 0), (0, 40.0, 0)), material=0)
    shift = -0.4 + 0.8 * (np.arange(K) + 0.5) / K  # the plane's x offset at each bin's centre time
    s.motion_vertices = np.stack([s.vertices + np.array([dx, 0.0, 0.0], np.float32) for dx in shift])
    m = np.eye(4)
    m[:3, 3] = (0.0, 0.0, 10.0)
    s.camera = Camera(matrix=m, kind="ORTHO", ortho_scale=3.2, width=32, height=8)
    s.world_color = np.array([0.2, 0.4, 0.6], np.float32)
    spp = 256
    rr = render(s, RenderSettings(samples=spp, light_paths=0, wavelength_step=20.0, max_bounces=1))
    measured = rr.alpha.mean(axis=0)
    sf = np.linspace(-1.5, 1.5, 3001)
    wf = _blackman_harris(sf)
    xc = (np.arange(32) + 0.5 - 16.0) * 0.1

    def coverage(edges):  # mean over edge positions of the filter's share on the plane (x < edge)
        inside = (xc[:, None, None] + 0.1 * sf[None, None, :]) < edges[None, :, None]
        return (inside * wf[None, None, :]).sum(axis=(1, 2)) / (len(edges) * wf.sum())

    expected = coverage(0.05 + shift)
    continuous = coverage(0.05 - 0.4 + 0.8 * (np.arange(4000) + 0.5) / 4000)
    sigma = np.sqrt(np.maximum(expected * (1 - expected), 1 / (8 * spp)) / (8 * spp))
    z = (measured - expected) / sigma
    print("max |z|", np.abs(z).max().round(2), "bins vs continuous", np.abs(expected - continuous).max().round(4))
    assert np.abs(z).max() < 4.5, np.round(np.stack([measured, expected]), 3)
    assert np.abs(expected - continuous).max() < 0.02
    assert ((expected > 0.02) & (expected < 0.98)).sum() >= 7  # blurred: a still edge has 3 such columns
