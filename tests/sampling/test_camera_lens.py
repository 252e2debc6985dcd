"""The camera's thin lens, clipping, panoramic mappings and film coverage (docs/physics.md
sections 6.7-6.12), each against a closed form or an independent computation:

- the aperture sampler (disk, polygons with blades, rotation and ratio) by chi-square against
  the shape's area, cell by cell (the cells' areas by point-in-polygon on a fine sub-grid);
- every lens ray of an image point meets its chief ray on the plane of focus (geometry);
- clip start / end: origins on the near plane, ends on the far plane (Cycles' planes);
- equirectangular and fisheye (equidistant, equisolid) directions against the closed forms and
  against Cycles' inverse mappings (direction -> image);
- coverage (alpha) and Film > Transparent on a half-covered image, and clip end in a render.
"""

from __future__ import annotations

import numpy as np
import pytest

from chi2 import pearson
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.sampling.camera import (aperture_points, camera_rays, lens_samples, panorama_directions,
                                                   panorama_sensor)
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.model import Camera, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.scene.validation import validate as validate_scene


def _inside_polygon(x, y, blades, rotation, ratio):
    """Point-in-polygon of the regular polygon (corners on the unit circle at rotation +
    (2k + 1) pi / blades) stretched by 1 / ratio in x; blades < 3: the unit disk."""
    x = x * ratio
    if blades < 3:
        return x * x + y * y <= 1.0
    ang = rotation + (2 * np.arange(blades) + 1) * np.pi / blades
    cx, cy = np.cos(ang), np.sin(ang)
    inside = np.ones(x.shape, bool)
    for k in range(blades):
        ax, ay, bx, by = cx[k], cy[k], cx[(k + 1) % blades], cy[(k + 1) % blades]
        inside &= (bx - ax) * (y - ay) - (by - ay) * (x - ax) >= 0  # left of each counter-clockwise edge
    return inside


@pytest.mark.parametrize("blades, rotation, ratio", [(0, 0.0, 1.0), (3, 0.0, 1.0), (5, 0.4, 1.0), (6, 0.3, 1.3),
                                                     (8, -1.0, 0.7)])
def test_aperture_samples_are_uniform_over_the_polygon(blades, rotation, ratio):
    n, cells, sub = 200_000, 20, 48
    rng = np.random.default_rng(29 + blades)
    x, y = aperture_points(rng.random(n), rng.random(n), blades, rotation, ratio)
    ext = max(1.0, 1.0 / ratio)
    # every sample inside the shape (a small tolerance for the edges' rounding)
    assert _inside_polygon(x * (1 - 1e-9), y * (1 - 1e-9), blades, rotation, ratio).all()
    obs = np.histogram2d(x, y, bins=cells, range=[[-ext, ext], [-1, 1]])[0]
    # expected: each cell's area inside the shape (sub x sub midpoints), over the shape's area
    gx = -ext + (np.arange(cells * sub) + 0.5) * (2 * ext / (cells * sub))
    gy = -1 + (np.arange(cells * sub) + 0.5) * (2 / (cells * sub))
    X, Y = np.meshgrid(gx, gy, indexing="ij")
    ins = _inside_polygon(X, Y, blades, rotation, ratio).reshape(cells, sub, cells, sub).sum(axis=(1, 3))
    area = np.pi if blades < 3 else blades / 2 * np.sin(2 * np.pi / blades)
    fine_area = ins.sum() * (2 * ext / (cells * sub)) * (2 / (cells * sub))
    assert fine_area == pytest.approx(area / ratio, rel=2e-3)  # the grid measures the closed-form area
    p, details = pearson(obs, n * ins / ins.sum())
    assert p > 1e-3 / 5, details


def test_lens_numbers_are_stratified_per_pixel_and_differ_from_the_pixel_position():
    rng = np.random.default_rng(0)
    ids = np.arange(4, dtype=np.uint32)
    u = lens_samples(4, 64, rng, (ids, np.zeros(4, np.uint32), 7))
    assert u.shape == (256, 2) and (u >= 0).all() and (u < 1).all()
    # a (0, 2)-sequence: 64 points of one pixel put one point in each 8 x 8 cell
    cells = (u[:64] * 8).astype(int)
    assert len({tuple(c) for c in cells}) == 64
    from opal_diffraction.core.sampling.sampler import sobol_owen_2d
    px, _ = sobol_owen_2d(np.zeros(64, np.uint32), np.arange(64), 0, 7)
    assert abs(np.corrcoef(px, u[:64, 0])[0, 1]) < 0.4  # not the pixel position's numbers


def _dof_camera(**kw):
    args = dict(width=64, height=48, lens=50.0, aperture_radius=0.05, focus_distance=3.0, aperture_blades=6,
                aperture_rotation=0.2, aperture_ratio=1.2)
    args.update(kw)
    return Camera.look_at((1.0, -4.0, 1.5), (0.0, 0.0, 0.5), **args)


@pytest.mark.parametrize("kind", ["PERSP", "ORTHO", "PANO"])
def test_lens_rays_meet_the_chief_ray_on_the_plane_of_focus(kind):
    cam = _dof_camera(kind=kind, ortho_scale=3.0)
    rng = np.random.default_rng(1)
    x = np.full(500, 20.3)
    y = np.full(500, 31.7)
    o, d, _, _ = camera_rays(cam, x, y, rng.random((500, 2)))
    o0, d0, _, _ = camera_rays(cam, x[:1], y[:1], None)  # the chief ray (lens centre)
    m = cam.matrix
    rot = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0)
    eye = m[:3, 3]
    o, d, o0, d0 = (a.astype(np.float64) for a in (o, d, o0, d0))
    # lens points: within the aperture, spread over it
    lens_pts = o - eye if kind != "ORTHO" else (o - o0) - ((o - o0) @ rot[:, 2])[:, None] * rot[:, 2]
    r = np.linalg.norm(lens_pts, axis=1)
    assert r.max() <= cam.aperture_radius * max(1.0, 1 / cam.aperture_ratio) * (1 + 1e-5)
    assert r.max() > 0.8 * cam.aperture_radius
    if kind == "PANO":  # Cycles: the focus point is at focus_distance along the chief ray
        focus = o0[0] + cam.focus_distance * d0[0]
        t = np.einsum("ij,ij->i", focus - o, d)
    else:  # on the plane at depth focus_distance along the view axis
        depth_o = -((o - eye) @ rot[:, 2])
        depth_d = -(d @ rot[:, 2])
        t = (cam.focus_distance - depth_o) / depth_d
        t0 = (cam.focus_distance + ((o0[0] - eye) @ rot[:, 2])) / -(d0[0] @ rot[:, 2])
        focus = o0[0] + t0 * d0[0]
    hits = o + t[:, None] * d
    np.testing.assert_allclose(hits, np.broadcast_to(focus, hits.shape), atol=2e-5)


@pytest.mark.parametrize("kind", ["PERSP", "ORTHO"])
def test_clip_start_and_end_are_planes_along_the_view_axis(kind):
    cam = Camera.look_at((0.5, -3.0, 2.0), (0.0, 0.0, 0.0), width=40, height=30, kind=kind, ortho_scale=2.0,
                         clip_start=1.25, clip_end=4.5)
    rng = np.random.default_rng(2)
    x, y = rng.random(200) * 40, rng.random(200) * 30
    o, d, tmax, valid = camera_rays(cam, x, y)
    assert valid is None and tmax is not None
    m = cam.matrix
    axis = -m[:3, 2] / np.linalg.norm(m[:3, 2])
    depth_start = (o.astype(np.float64) - m[:3, 3]) @ axis
    depth_end = (o.astype(np.float64) + tmax[:, None] * d - m[:3, 3]) @ axis
    np.testing.assert_allclose(depth_start, 1.25, rtol=2e-6)
    np.testing.assert_allclose(depth_end, 4.5, rtol=2e-6)
    # without clipping: the pinhole rays, unbounded
    o2, d2, t2, _ = camera_rays(Camera.look_at((0.5, -3.0, 2.0), (0, 0, 0), width=40, height=30, kind=kind,
                                               ortho_scale=2.0), x, y)
    assert t2 is None
    np.testing.assert_allclose(d2, d, atol=2e-6)


def _pano(kind, w=64, h=32, **kw):
    return Camera(kind="PANO", panorama_type=kind, width=w, height=h, **kw)


def test_equirectangular_directions_match_the_closed_form_and_cycles_inverse():
    cam = _pano("EQUIRECTANGULAR", latitude_min=-1.2, latitude_max=1.4, longitude_min=-2.5, longitude_max=2.0)
    rng = np.random.default_rng(3)
    x, y = rng.random(300) * 64, rng.random(300) * 32
    _, d, _, valid = camera_rays(cam, x, y)
    assert valid is None
    d = d.astype(np.float64)
    # Blender camera space (identity matrix): forward -z, left -x, up +y
    fwd, left, up = -d[:, 2], -d[:, 0], d[:, 1]
    lon = np.arctan2(left, fwd)  # longitude: 0 ahead, positive to the left
    lat = np.arcsin(np.clip(up, -1, 1))
    u, v = x / 64, 1 - y / 32
    # the image spans longitude_max (left edge) ... longitude_min? Cycles: phi = (min - max) u - min
    np.testing.assert_allclose(lon, -(-2.5) + (-2.5 - 2.0) * u, atol=2e-6)
    np.testing.assert_allclose(lat, -1.2 + (1.4 + 1.2) * v, atol=2e-6)
    # Cycles' direction_to_equirectangular_range gives (u, v) back
    rng4 = (-2.5 - 2.0, 2.5, -1.2 - 1.4, 1.2 + np.pi / 2)
    dc = np.stack([fwd, left, up], axis=1)  # Cycles' panorama space
    uu = (np.arctan2(dc[:, 1], dc[:, 0]) - rng4[1]) / rng4[0]
    vv = (np.arccos(dc[:, 2]) - rng4[3]) / rng4[2]
    np.testing.assert_allclose(uu, u, atol=2e-6)
    np.testing.assert_allclose(vv, v, atol=2e-6)


def test_fisheye_equidistant_angle_grows_with_the_radius():
    cam = _pano("FISHEYE_EQUIDISTANT", w=64, h=64, fisheye_fov=np.radians(200))
    rng = np.random.default_rng(4)
    x, y = rng.random(400) * 64, rng.random(400) * 64
    _, d, tmax, valid = camera_rays(cam, x, y)
    a, b = (x / 64 - 0.5) * 2, ((1 - y / 64) - 0.5) * 2
    r = np.hypot(a, b)
    np.testing.assert_array_equal(valid, r <= 1)
    np.testing.assert_array_equal(tmax[~valid], 0)
    d = d[valid].astype(np.float64)
    theta = np.arccos(np.clip(-d[:, 2], -1, 1))
    np.testing.assert_allclose(theta, r[valid] * np.radians(200) / 2, atol=3e-6)
    # the direction's azimuth is the image point's: right is camera +x, up camera +y
    np.testing.assert_allclose(np.arctan2(d[:, 1], d[:, 0]), np.arctan2(b[valid], a[valid]), atol=3e-5)


@pytest.mark.parametrize("w, h, fit", [(64, 64, "AUTO"), (80, 40, "AUTO"), (40, 80, "AUTO"), (80, 40, "VERTICAL")])
def test_fisheye_equisolid_radius_is_2f_sin_half_theta(w, h, fit):
    cam = _pano("FISHEYE_EQUISOLID", w=w, h=h, fisheye_lens=8.0, fisheye_fov=np.pi, sensor_width=36.0,
                sensor_height=24.0, sensor_fit=fit)
    sw, sh = panorama_sensor(cam)
    horizontal = fit == "HORIZONTAL" or (fit == "AUTO" and w > h)
    size = 36.0 if fit != "VERTICAL" else 24.0
    assert (sw, sh) == pytest.approx((size, size * h / w) if horizontal else (size * w / h, size))
    rng = np.random.default_rng(5)
    x, y = rng.random(400) * w, rng.random(400) * h
    _, d, _, valid = camera_rays(cam, x, y)
    a, b = (x / w - 0.5) * sw, ((1 - y / h) - 0.5) * sh  # millimetres on the sensor
    r = np.hypot(a, b)
    np.testing.assert_array_equal(valid, r <= 2 * 8.0 * np.sin(np.pi / 4))
    d = d[valid].astype(np.float64)
    theta = np.arccos(np.clip(-d[:, 2], -1, 1))
    np.testing.assert_allclose(2 * 8.0 * np.sin(theta / 2), r[valid], atol=2e-4)


def test_panorama_space_maps_to_blender_camera_axes():
    """Cycles' panorama space (x ahead, y left, z up): the image centre looks ahead (camera -z),
    a quarter to the left looks left (camera -x), the top row up (camera +y)."""
    cam = _pano("EQUIRECTANGULAR")
    _, d, _, _ = camera_rays(cam, np.array([32.0, 16.0, 32.0]), np.array([16.0, 16.0, 0.0]))
    np.testing.assert_allclose(d[0], [0, 0, -1], atol=1e-6)
    np.testing.assert_allclose(d[1], [-1, 0, 0], atol=1e-6)
    np.testing.assert_allclose(d[2], [0, 1, 0], atol=1e-6)
    dc, _ = panorama_directions(cam, np.array([0.5]), np.array([0.5]))
    np.testing.assert_allclose(dc[0], [1, 0, 0], atol=1e-12)


def _half_plane_scene(transparent, clip_end=np.inf, plane_z=0.0):
    """An orthographic camera 10 m above a plane covering x < 0.05 m of its 3.2 m wide, 32 px view
    (the edge in the middle of column 16: 0.1 m pixels), a uniform world."""
    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)}]))
    s.add_mesh(*primitives.quad((-10.0 + 0.05, 0.0, plane_z), (20.0, 0, 0), (0, 40.0, 0)), material=0)
    m = np.eye(4)
    m[:3, 3] = (0.0, 0.0, 10.0)
    s.camera = Camera(matrix=m, kind="ORTHO", ortho_scale=3.2, width=32, height=8, clip_end=clip_end)
    s.world_color = np.array([0.2, 0.4, 0.6], np.float32)
    settings = RenderSettings(samples=64, light_paths=0, wavelength_step=20.0, film_transparent=transparent,
                              max_bounces=1)
    return s, settings


def test_alpha_is_the_coverage_and_transparent_film_hides_the_world():
    s, settings = _half_plane_scene(True)
    rr = render(s, settings)
    a = rr.alpha
    assert a.shape == (8, 32)
    # columns beyond the filter's reach (1.5 px) of the edge at x = 16.5 px: exactly 1 or 0
    np.testing.assert_array_equal(a[:, :14], 1.0)
    np.testing.assert_array_equal(a[:, 19:], 0.0)
    # the edge's column: half its filter (symmetric) on the plane; binomial noise of 64 samples
    assert a[:, 16].mean() == pytest.approx(0.5, abs=4 * 0.5 / np.sqrt(64 * 8))
    # neighbours (centres 1 px from the edge): the Blackman-Harris mass beyond 1 px, by numerical integration
    t = np.linspace(-1.5, 1.5, 300001)
    f = 0.35875 - 0.48829 * np.cos(2 * np.pi * (t / 3 + 0.5)) + 0.14128 * np.cos(4 * np.pi * (t / 3 + 0.5)) \
        - 0.01168 * np.cos(6 * np.pi * (t / 3 + 0.5))
    share = f[t > 1.0].sum() / f.sum()
    assert a[:, 15].mean() == pytest.approx(1 - share, abs=4 * 0.5 / np.sqrt(64 * 8))
    assert a[:, 17].mean() == pytest.approx(share, abs=4 * 0.5 / np.sqrt(64 * 8))
    # transparent: the world's pixels are black (the plane's are not)
    np.testing.assert_array_equal(rr.rgb[:, 19:], 0.0)
    assert (rr.rgb[:, :14].mean(axis=(0, 1)) > 0).all()
    # opaque film: the world is there, the alpha the same coverage
    s, settings = _half_plane_scene(False)
    rr2 = render(s, settings)
    assert rr2.rgb[:, 19:].mean() > 0.1
    np.testing.assert_array_equal(rr2.alpha[:, 19:], 0.0)


def test_clip_end_shows_the_world_beyond_it():
    s, settings = _half_plane_scene(False, clip_end=9.0)  # the plane is 10 m away: clipped
    rr = render(s, settings)
    np.testing.assert_array_equal(rr.alpha, 0.0)
    world = rr.rgb[:, 19:].mean(axis=(0, 1))
    np.testing.assert_allclose(rr.rgb.mean(axis=(0, 1)), world, rtol=1e-5)
    s, settings = _half_plane_scene(False, clip_end=10.5)
    assert render(s, settings).alpha[:, :14].min() == 1.0


@pytest.mark.parametrize("field, value, words", [
    ("aperture_radius", -0.1, "aperture_radius"), ("aperture_ratio", 0.0, "aperture_ratio"),
    ("clip_start", -1.0, "clip_start"), ("clip_end", 0.05, "beyond clip_start"),
    ("focus_distance", 0.0, "focus_distance"), ("panorama_type", "MIRRORBALL", "panorama type"),
    ("fisheye_fov", 0.0, "fisheye_fov"), ("latitude_max", -2.0, "latitude_min"),
    ("aperture_blades", 2.5, "aperture_blades"), ("clip_end", float("nan"), "clip_end"),
])
def test_bad_lens_values_are_one_scene_error(field, value, words):
    s, _ = _half_plane_scene(False)
    from dataclasses import replace
    kw = {field: value, "clip_start": 0.1}
    if field in ("focus_distance",):
        kw["aperture_radius"] = 0.01
    if field in ("panorama_type", "fisheye_fov", "latitude_max"):
        kw["kind"] = "PANO"
    if field == "clip_start":
        kw["clip_start"] = value
    s.camera = replace(s.camera, **kw)
    with pytest.raises(SceneError, match=words):
        validate_scene(s)


def test_cli_transparent_writes_the_coverage_as_alpha(tmp_path):
    import io
    from contextlib import redirect_stderr

    from opal_diffraction import cli
    from opal_diffraction.core.render.output import read_exr
    from opal_diffraction.core.scene.npz import save_scene

    s, _ = _half_plane_scene(False)
    s.camera.clip_start = 0.5  # a file with the new camera fields round-trips
    path = tmp_path / "scene.npz"
    save_scene(s, path)
    out = tmp_path / "out.exr"
    args = ["render", str(path), "-o", str(out), "--spp", "16", "--wavelength-step", "20", "--light-paths", "0",
            "--no-preview", "-q"]
    with redirect_stderr(io.StringIO()):
        assert cli.main(args + ["--transparent"]) == 0
    ch = read_exr(str(out))
    np.testing.assert_array_equal(ch["A"][:, :14], 1.0)
    np.testing.assert_array_equal(ch["A"][:, 19:], 0.0)
    np.testing.assert_array_equal(ch["R"][:, 19:], 0.0)
    with redirect_stderr(io.StringIO()):
        assert cli.main(args) == 0
    ch = read_exr(str(out))
    assert "A" not in ch and ch["R"][:, 19:].mean() > 0.1  # an opaque film: the world, no alpha


@pytest.mark.parametrize("dispersion", [None, "BK7"])
def test_transparent_glass_alpha_is_one_minus_the_direct_transmission(dispersion):
    """Film > Transparent with Transparent Glass (Cycles' PATH_RAY_TRANSPARENT_BACKGROUND): an
    orthographic view straight through a smooth glass slab (n = 1.5) against the world. Only the
    path refracted twice reaches the world transparent (a reflection inside makes a path opaque),
    so alpha = 1 - (1 - R)^2 with R = ((n - 1) / (n + 1))^2 = 0.04 at normal incidence: 0.0784.
    With dispersion (BK7, n ~ 1.517 at 550 nm) the mean over the grid of 1 - (1 - R(lambda))^2."""
    mat = {"kind": "DIELECTRIC", "ior": 1.5}
    if dispersion:
        mat = {"kind": "DIELECTRIC", "ior": 1.5168, "dispersion": dispersion}
    s = Scene(materials=Materials.from_list([mat]))
    s.add_mesh(*primitives.box((0, 0, 0), (4.0, 4.0, 0.3)), material=0)
    m = np.eye(4)
    m[:3, 3] = (0.0, 0.0, 5.0)
    s.camera = Camera(matrix=m, kind="ORTHO", ortho_scale=1.0, width=8, height=8)
    s.world_color = np.array([0.5, 0.5, 0.5], np.float32)
    settings = RenderSettings(samples=64, light_paths=0, wavelength_step=10.0, film_transparent=True,
                              film_transparent_glass=True)
    rr = render(s, settings)
    n = np.array([1.5])
    if dispersion:  # BK7's index at the render's wavelengths (Sellmeier, core/spectral/optics.py)
        from opal_diffraction.core.spectral.optics import ior_spectrum
        n = ior_spectrum(settings.grid().wavelengths, dispersion, 1.5168)
    r = ((n - 1) / (n + 1)) ** 2
    expected = float(np.mean(1 - (1 - r) ** 2))
    # binomial-like noise of 64 x 64 samples of a two-valued estimate (0 or about 1): ~0.004
    assert rr.alpha.mean() == pytest.approx(expected, abs=0.004)
    assert (rr.alpha >= 0).all() and (rr.alpha <= 1).all()
    # what reaches the camera through the glass is the world reflected inside (not transparent): small, >= 0
    assert rr.rgb.min() >= 0 and rr.rgb.mean() < 0.5 * 0.1
    # Transparent Glass off: the glass is opaque (coverage 1) and shows the world through it
    rr2 = render(s, replace_settings(settings, film_transparent_glass=False))
    np.testing.assert_array_equal(rr2.alpha, 1.0)
    assert rr2.rgb.mean() > 0.4


def replace_settings(settings, **kw):
    from dataclasses import replace
    return replace(settings, **kw)
