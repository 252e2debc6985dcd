"""Lights with a size (docs/physics.md section 7.5): sphere and soft-falloff point lights, suns with
an angle, area lights. Each sampler against its pdf (chi-square, Mitsuba 3 style), irradiance
estimates against closed forms (Z-tests), ray intersections against analytic ones."""

from __future__ import annotations

import math

import numpy as np
import pytest

from chi2 import chi2_directions
from opal_diffraction.core.lights.sources import (intersect_lights, is_delta, light_pdf, prepare_lights, sample_light,
                                          sun_radiance)
from opal_diffraction.core.scene.model import Lights, Scene
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.npz import load_scene, save_scene
from opal_diffraction.core.scene.validation import validate
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.spectral.spectrum import SpectralConverter
from opal_diffraction.core.render.plan import plan_render

CONV = SpectralConverter(RenderSettings(wavelength_step=20.0).grid())
#: chi-square tests in this file and tests/lights/test_mesh_lights.py (Bonferroni)
CHI2_TESTS = 10
ALPHA = 0.01 / CHI2_TESTS
Z_MAX = 4.0  # |Z| beyond this: a two-sided probability of 6e-5 per comparison


def prepared(*rows):
    return prepare_lights(Lights.from_list(list(rows)), CONV)


def rng(seed=1):
    return np.random.default_rng(seed)


# ------------------------------------------------------------------------------ chi-square
SAMPLERS = {
    # name: (light row, shading point, grid axis, theta_max of the grid)
    "sphere_outside": ({"kind": "POINT", "position": (0, 0, 2), "radius": 0.5}, (0.3, -0.2, 0.0), None, 0.4),
    "sphere_inside": ({"kind": "POINT", "position": (0, 0, 0), "radius": 0.5}, (0.1, 0.2, -0.1), (0, 0, 1), np.pi),
    "spot_sphere": ({"kind": "SPOT", "position": (0, 0, 2), "radius": 0.3, "spot_size": math.radians(60)},
                    (0.2, 0.0, 0.0), None, 0.25),
    "soft_falloff_disk": ({"kind": "POINT", "position": (0, 0, 1), "radius": 0.5, "soft_falloff": 1},
                          (0.2, 0.1, 0.0), None, 0.7),
    "sun_10deg": ({"kind": "SUN", "direction": (0.3, 0.1, -1.0), "angle": math.radians(10)}, (0, 0, 0),
                  (-0.3, -0.1, 1.0), math.radians(7)),
    "area_rect": ({"kind": "AREA_RECT", "position": (0.3, 0, 1), "direction": (0, 0.2, -1), "size_u": 1.2,
                   "size_v": 0.6}, (0, 0, 0), None, 0.9),
    "area_disk": ({"kind": "AREA_DISK", "position": (0, 0.2, 0.8), "direction": (0, 0, -1), "size_u": 1.0,
                   "size_v": 0.7}, (0, 0, 0), None, 0.8),
}


@pytest.mark.parametrize("name", list(SAMPLERS))
def test_sampler_matches_light_pdf_chi2(name):
    row, p, axis, theta_max = SAMPLERS[name]
    pl = prepared(row)
    n = 200_000
    pts = np.broadcast_to(np.asarray(p, np.float32), (n, 3))
    wi, dist, g = sample_light(pl, 0, pts, rng(7))
    if axis is None:
        axis = np.asarray(row["position"], np.float64) - np.asarray(p)
    p64 = np.asarray(p, np.float64)

    def pdf(d):
        return light_pdf(pl, 0, np.broadcast_to(p64, d.shape), d)

    pval, info, total = chi2_directions(wi, pdf, axis, theta_max=theta_max)
    print(name, info)
    assert pval > ALPHA, info
    # chi-square is blind to a small error in the pdf's normalisation: it must integrate to 1
    # (the midpoint rule's error at the support's edge is below 0.5 % on these grids)
    assert abs(total - 1) < 0.01, f"the pdf integrates to {total}"
    # and the density of each drawn direction is the pdf at it (finite, > 0)
    assert np.all(light_pdf(pl, 0, pts, wi) > 0)


# ------------------------------------------------------------------------------ irradiance
def irradiance(pl, p, normal, n=400_000, seed=3):
    """MC irradiance (Y units of the spectrum's scale): mean and standard error of g cos."""
    pts = np.broadcast_to(np.asarray(p, np.float32), (n, 3))
    wi, _, g = sample_light(pl, 0, pts, rng(seed))
    cos_r = np.maximum(wi @ np.asarray(normal, np.float32), 0)
    x = (g * cos_r).astype(np.float64)
    return x.mean(), x.std() / math.sqrt(n)


def assert_z(est, se, expected, what):
    z = (est - expected) / max(se, 1e-12 * abs(expected))
    print(f"{what}: MC {est:.6g} +- {se:.2g}, analytic {expected:.6g}, Z = {z:.2f}")
    assert abs(z) < Z_MAX, f"{what}: Z = {z:.2f}"


def test_sphere_light_irradiance_outside_is_the_point_law():
    """A uniformly bright sphere wholly above the horizon lights a surface like a point at its
    centre: E = I cos / d^2 (Lambert), whatever its radius (docs/physics.md section 7.5)."""
    pl = prepared({"kind": "POINT", "position": (0, 0, 2.0), "radius": 0.5})
    for tilt in (0.0, 50.0):  # 50 deg + asin(0.25) = 64.5 deg < 90: the whole sphere is above
        t = math.radians(tilt)
        normal = (math.sin(t), 0.0, math.cos(t))
        est, se = irradiance(pl, (0, 0, 0), normal)
        assert_z(est, se, math.cos(t) / 4.0, f"sphere at 2 m, tilt {tilt}")


def test_sphere_light_irradiance_inside_and_partly_below_the_horizon():
    """Inside the sphere the radiance L = I / (pi r^2) fills the hemisphere: E = pi L = I / r^2.
    A sphere centred on the receiver's plane: half its cone is below the horizon, E = L times the
    integral of cos over the upper half of the cone (a fine quadrature)."""
    r = 0.5
    pl = prepared({"kind": "POINT", "position": (0, 0, 0.0), "radius": r})
    est, se = irradiance(pl, (0.1, -0.2, 0.05), (0, 0, 1))
    assert_z(est, se, 1.0 / r**2, "inside the sphere")
    # sphere centred on the receiver's plane at distance d: half the cone is above the horizon;
    # E = L * int_{cone, z>0} cos dw, integrated on a fine grid in the cone's own frame
    d = 1.5
    pl = prepared({"kind": "POINT", "position": (d, 0, 0.0), "radius": r})
    est, se = irradiance(pl, (0, 0, 0), (0, 0, 1))
    th_max = math.asin(r / d)
    th = (np.arange(4000) + 0.5) / 4000 * th_max
    ph = (np.arange(4000) + 0.5) / 4000 * 2 * np.pi
    T, P = np.meshgrid(th, ph, indexing="ij")
    z = np.sin(T) * np.sin(P)  # cone axis +x; z component of the direction
    e = np.sum(np.maximum(z, 0) * np.sin(T)) * (th_max / 4000) * (2 * np.pi / 4000)
    assert_z(est, se, e / (math.pi * r * r), "sphere cut by the horizon")


def test_soft_falloff_disk_irradiance():
    """Cycles' soft falloff: a disk of radius r facing the point, radiance I / (pi r^2):
    on its axis E = L pi r^2 / (d^2 + r^2) = I / (d^2 + r^2)."""
    for d in (0.3, 2.0):
        pl = prepared({"kind": "POINT", "position": (0, 0, d), "radius": 0.5, "soft_falloff": 1})
        est, se = irradiance(pl, (0, 0, 0), (0, 0, 1))
        assert_z(est, se, 1.0 / (d * d + 0.25), f"soft-falloff disk at {d} m")


def test_sun_with_an_angle_keeps_its_strength():
    """A sun of strength S and angular diameter 2h: E = S facing it, S cos a tilted by a while
    the cone is above the horizon (a + h < 90 deg)."""
    for angle, tilt in ((10.0, 0.0), (10.0, 40.0), (60.0, 20.0)):
        pl = prepared({"kind": "SUN", "direction": (0, 0, -1), "angle": math.radians(angle)})
        t = math.radians(tilt)
        est, se = irradiance(pl, (0, 0, 0), (math.sin(t), 0, math.cos(t)))
        assert_z(est, se, math.cos(t), f"sun {angle} deg, tilt {tilt}")
    # sun_radiance integrates to the same irradiance: S = int L cos dw over the cone
    pl = prepared({"kind": "SUN", "direction": (0, 0, -1), "angle": math.radians(10), "power": 3.0})
    h = math.radians(5)
    m = 2000
    th = (np.arange(m) + 0.5) / m * (h * 1.2)
    ph = (np.arange(64) + 0.5) / 64 * 2 * np.pi
    T, P = np.meshgrid(th, ph, indexing="ij")
    d = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    L = sun_radiance(pl, d)[:, 0].reshape(T.shape).astype(np.float64)
    e = np.sum(L * np.cos(T) * np.sin(T)) * (1.2 * h / m) * (2 * np.pi / 64)
    assert abs(e / float(pl.spectrum[0, 0]) - 1) < 2e-3  # the cone edge cuts one theta row of 2000


def polygon_irradiance(p, normal, corners):
    """Irradiance factor (E / L) of a uniformly emitting polygon at p on a surface of normal
    ``normal`` (the polygon wholly above the horizon): Lambert's edge sum
    (1/2) |sum_i gamma_i n . (r_i x r_i+1) / |r_i x r_i+1||."""
    r = np.asarray(corners, np.float64) - np.asarray(p, np.float64)
    r /= np.linalg.norm(r, axis=1, keepdims=True)
    total = 0.0
    for i in range(len(r)):
        a, b = r[i], r[(i + 1) % len(r)]
        c = np.cross(a, b)
        total += math.acos(np.clip(a @ b, -1, 1)) * (c @ np.asarray(normal)) / np.linalg.norm(c)
    return 0.5 * abs(total)


def test_rectangle_light_irradiance_off_axis_is_lamberts_polygon_formula():
    pl = prepared({"kind": "AREA_RECT", "position": (0.4, -0.3, 1.0), "direction": (0.0, 0.3, -1.0),
                   "axis_u": (1, 0, 0), "size_u": 1.0, "size_v": 0.5})
    c, u, v = pl.position[0], pl.axis_u[0] * 0.5, pl.axis_v[0] * 0.25
    corners = [c - u - v, c + u - v, c + u + v, c - u + v]
    normal = np.array([0.2, 0.0, 1.0]) / math.hypot(0.2, 1.0)
    est, se = irradiance(pl, (0, 0, 0), normal)
    # g * spectrum = irradiance with the spectrum holding the radiance: E / L
    assert_z(est, se, polygon_irradiance((0, 0, 0), normal, corners), "rectangle off axis")


# ------------------------------------------------------------------------------ intersections
def test_intersect_lights_against_analytic_hits():
    pl = prepared(
        {"kind": "POINT", "position": (0, 0, 3), "radius": 0.5, "power": 100.0},                      # 0 sphere
        {"kind": "AREA_RECT", "position": (2, 0, 1), "direction": (0, 0, -1), "axis_u": (1, 0, 0),
         "size_u": 1.0, "size_v": 1.0},                                                                # 1 rect
        {"kind": "POINT", "position": (-2, 0, 2), "radius": 0.25, "soft_falloff": 1},                # 2 disk
        {"kind": "POINT", "position": (5, 5, 5)},                                                     # 3 delta
        {"kind": "SUN", "angle": 0.2},                                                                # 4 sun
    )
    o = np.array([[0, 0, 0], [0, 0, 0], [2, 0, 0], [2, 0, 2], [-2, 0, 0], [-2, 0, 0], [0.6, 0, 0],
                  [0, 0, 2.9], [2.4, 0.4, 0]], np.float64)
    tgt = np.array([[0, 0, 1], [0.3, 0, 1], [0, 0, 1], [0, 0, -1], [0, 0, 1], [0.24, 0, 2], [0, 0, 1],
                    [0, 0, 1], [0, 0, 1]], np.float64)
    d = tgt / np.linalg.norm(tgt, axis=1, keepdims=True)
    idx, t, scale = intersect_lights(pl, o, d, np.full(len(o), np.inf))
    # 0: straight up into the sphere at 3 - 0.5; 1: misses everything (0.3/1 slope passes 0.9 m
    # from the axis at z = 3); 2: the rect from below at 1; 3: the rect from above - its back: not hit;
    # 4: the disk facing the origin at distance 2; 5: the disk's rim at 0.24/2 * 2 = 0.24 < 0.25
    # (hit at the plane z = 2 - the disk faces (0, 0, -1) from there);
    # 6: the sphere, off centre by 0.6 > 0.5: a miss; 7: from inside the sphere: its far side at
    # 3 + 0.5 - 2.9; 8: the rect near its corner (0.4 < 0.5)
    want_idx = [0, -1, 1, -1, 2, 2, -1, 0, 1]
    want_t = [2.5, np.inf, 1.0, np.inf, 2.0, math.hypot(0.24, 2.0), np.inf, 0.6, 1.0]
    np.testing.assert_array_equal(idx, want_idx)
    np.testing.assert_allclose(t, want_t, rtol=1e-5)
    L_sphere = 1.0 / (math.pi * 0.25)
    L_disk = 1.0 / (math.pi * 0.0625)
    want_scale = [L_sphere, 0, 1.0, 0, L_disk, L_disk, 0, L_sphere, 1.0]
    np.testing.assert_allclose(scale, want_scale, rtol=1e-5)
    # tmax stops a ray short of the light
    idx, t, _ = intersect_lights(pl, o[:1], d[:1], np.array([2.4]))
    assert idx[0] == -1 and np.isinf(t[0])
    # the nearer of two lights along one ray: a sphere in front of the rect
    pl2 = prepared({"kind": "AREA_RECT", "position": (0, 0, 3), "direction": (0, 0, -1)},
                   {"kind": "POINT", "position": (0, 0, 2), "radius": 0.2})
    idx, t, _ = intersect_lights(pl2, np.zeros((1, 3)), np.array([[0.0, 0, 1]]), np.array([np.inf]))
    assert idx[0] == 1 and abs(t[0] - 1.8) < 1e-6
    assert [is_delta(pl, i) for i in range(5)] == [False, False, False, True, False]


def test_seen_radiance_integrates_to_the_irradiance():
    """intersect_lights' radiance over the sphere of directions (uniform MC) gives the same
    irradiance as the closed form: its scale is the radiance the samplers assume."""
    n = 2_000_000
    r = rng(11)
    z = 1 - 2 * r.random(n)
    phi = 2 * np.pi * r.random(n)
    s = np.sqrt(1 - z * z)
    d = np.stack([s * np.cos(phi), s * np.sin(phi), z], -1)
    for row, expected in (({"kind": "POINT", "position": (0, 0, 1.5), "radius": 0.6}, 1 / 1.5**2),
                          ({"kind": "POINT", "position": (0, 0, 1.0), "radius": 0.5, "soft_falloff": 1},
                           1 / 1.25),
                          ({"kind": "AREA_DISK", "position": (0, 0, 1.0), "direction": (0, 0, -1), "size_u": 2.0,
                            "size_v": 2.0}, math.pi * 1.0 / 2.0)):
        pl = prepared(row)
        idx, _, scale = intersect_lights(pl, np.zeros((n, 3)), d, np.full(n, np.inf))
        x = scale.astype(np.float64) * np.maximum(d[:, 2], 0) * 4 * np.pi  # / pdf (1 / 4 pi)
        assert_z(x.mean(), x.std() / math.sqrt(n), expected, f"seen radiance of {row['kind']}")


def test_spot_with_radius_masks_along_the_ray():
    """Cycles' spot.h: the cone mask of a sized spot is evaluated on each sampled ray's
    direction: a point just outside the cone edge still receives light from the part of the
    sphere whose rays are inside the cone."""
    half = math.radians(30)
    pl = prepared({"kind": "SPOT", "position": (0, 0, 1), "direction": (0, 0, -1), "radius": 0.2,
                   "spot_size": 2 * half, "spot_blend": 0.0})
    x_edge = math.tan(half)
    inside, _ = irradiance(pl, (0.5 * x_edge, 0, 0), (0, 0, 1))
    assert inside > 0
    near, _ = irradiance(pl, (x_edge * 1.02, 0, 0), (0, 0, 1))
    far, _ = irradiance(pl, (x_edge * 2, 0, 0), (0, 0, 1))
    assert near > 0 and far == 0


# ------------------------------------------------------------------------------ the table
def test_radius_and_angle_round_trip_and_validate(tmp_path):
    from opal_diffraction.core.scene.model import Camera

    s = Scene(camera=Camera.look_at((0, 0, 5), (0, 0, 0), width=4, height=4))
    s.lights = Lights.from_list([{"kind": "POINT", "radius": 0.25, "soft_falloff": 1},
                                 {"kind": "SUN", "angle": 0.1}])
    path = tmp_path / "s.npz"
    save_scene(s, path)
    back = load_scene(path)
    np.testing.assert_array_equal(back.lights.radius, [0.25, 0.0])
    np.testing.assert_array_equal(back.lights.angle, [0.0, 0.1])
    np.testing.assert_array_equal(back.lights.soft_falloff, [1, 0])
    # an older file without the columns: zeros (delta lights, as it rendered then)
    z = dict(np.load(path))
    for name in ("radius", "angle", "soft_falloff"):
        z.pop("light_" + name)
    old = tmp_path / "old.npz"
    np.savez(old, **z)
    clean = validate(load_scene(old)).scene
    assert not clean.lights.radius.any() and not clean.lights.angle.any()
    for bad, msg in (({"kind": "POINT", "radius": -1.0}, "radius"), ({"kind": "SUN", "angle": 4.0}, "angle"),
                     ({"kind": "POINT", "soft_falloff": 2}, "soft falloff")):
        s.lights = Lights.from_list([bad])
        with pytest.raises(SceneError, match=msg):
            validate(s)


# ------------------------------------------------------------------------------ the light pass
def _big_slab_scene(light: dict) -> Scene:
    """A 40 x 40 x 0.05 m clear glass slab (top at z = 0.3) on a 100 m floor, one light above."""
    from opal_diffraction.core.scene import primitives
    from opal_diffraction.core.scene.model import Camera, Materials

    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
                                {"kind": "DIELECTRIC", "ior": 1.5, "color": (1, 1, 1)}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (100, 0, 0), (0, 100, 0)), material=0)
    s.add_mesh(*primitives.box((0, 0, 0.275), (40.0, 40.0, 0.05)), material=1)
    s.lights = Lights.from_list([light])
    s.camera = Camera.look_at((0, -4, 3), (0, 0, 0), width=8, height=8)
    return s


def _slab_transmission(cos_i):
    """(1 - R) / (1 + R): a clear slab's transmitted fraction with all internal reflections,
    R the unpolarised Fresnel reflectance entering from air (eta = n_t / n_i = 1.5)."""
    from opal_diffraction.core.spectral.optics import fresnel_dielectric

    r, _ = fresnel_dielectric(cos_i, np.full(np.shape(cos_i), 1.5))
    return (1 - r) / (1 + r)


LIGHT_PASS_CASES = {
    "point": {"kind": "POINT", "position": (0, 0, 0.8), "power": 100.0},
    "sphere": {"kind": "POINT", "position": (0, 0, 0.8), "power": 100.0, "radius": 0.05},
    "soft_falloff": {"kind": "POINT", "position": (0, 0, 0.8), "power": 100.0, "radius": 0.05, "soft_falloff": 1},
    "sun_20deg": {"kind": "SUN", "direction": (0, 0, -1), "power": 2.0, "angle": math.radians(20)},
}


@pytest.mark.parametrize("case", list(LIGHT_PASS_CASES))
def test_sized_lights_send_the_analytic_flux_through_a_glass_slab(case):
    """The light pass's flux on the floor under a clear slab (docs/physics.md section 7.7):
    - point, sphere or soft-falloff light of intensity I at height h above the slab's centre:
      every point of a sphere sees the slab's plane alike, and a sphere's intensity is I in every
      direction, so Phi = I int_slab T(theta) dw, whatever the radius (from the centre; the
      origins' spread changes the slab's edge directions by ~r / 20 m, below 0.05 %);
    - a sun of strength S and half angle h_s overhead: the cone's uniform radiance crossing the
      top of area A: Phi = A S int_0^h_s cos sin T / int_0^h_s cos sin.
    Six independent runs give the Monte Carlo error (Student t, 5 degrees of freedom)."""
    from opal_diffraction.core.integrators.light.light_pass import run_light_pass
    from opal_diffraction.core.render.prepare import prepare

    row = LIGHT_PASS_CASES[case]
    s = _big_slab_scene(row)
    runs = []
    for seed in range(6):
        ctx = prepare(s, RenderSettings(light_paths=40_000, max_bounces=32, seed=seed, wavelength_step=20.0))
        runs.append(float(run_light_pass(ctx, plan=plan_render(ctx)).caustics.flux.sum(axis=0).mean()))
    spectrum = float(ctx.lights.spectrum[0].mean())  # I (W/sr) or S (W/m^2) per bin
    th = np.linspace(0, np.pi / 2, 200_001)
    mid = 0.5 * (th[1:] + th[:-1])
    dth = np.diff(th)
    if row["kind"] == "SUN":
        hs = 0.5 * row["angle"]
        cone = mid < hs
        ratio = np.sum((np.cos(mid) * np.sin(mid) * _slab_transmission(np.cos(mid)) * dth)[cone]) / np.sum(
            (np.cos(mid) * np.sin(mid) * dth)[cone])
        expected = spectrum * 1600.0 * ratio
    else:
        h, half = 0.5, 20.0
        phi = (np.arange(8192) + 0.5) / 8192 * 2 * np.pi
        rho = half / np.maximum(np.abs(np.cos(phi)), np.abs(np.sin(phi)))  # the square's edge at phi
        cum = np.concatenate([[0.0], np.cumsum(np.sin(mid) * _slab_transmission(np.cos(mid)) * dth)])
        expected = spectrum * np.interp(np.arctan(rho / h), th, cum).mean() * 2 * np.pi
    mean, se = float(np.mean(runs)), float(np.std(runs, ddof=1) / math.sqrt(len(runs)))
    t = (mean - expected) / se
    print(f"{case}: flux {mean:.5g} +- {se:.2g}, analytic {expected:.5g}, t = {t:.2f}")
    assert abs(t) < 6.87  # two-sided probability 1e-3 at 5 degrees of freedom
    assert se / expected < 0.01


def _sun_view(camera_visible: int):
    """A camera looking straight at a sun of 20 degrees (strength 2, white) over a black world, no geometry."""
    from opal_diffraction.core.render.frame import render
    from opal_diffraction.core.scene.model import Camera
    s = Scene()
    s.lights = Lights.from_list([{"kind": "SUN", "direction": (0, 0, -1), "angle": math.radians(20), "power": 2.0,
                                  "camera_visible": camera_visible}])
    s.camera = Camera.look_at((0, 0, 0), (0, 0, 1), up=(0, 1, 0), width=24, height=24)
    return render(validate(s).scene, RenderSettings(samples=4, wavelength_step=10.0)).rgb


def test_camera_sees_the_disc_of_a_sun_marked_visible_to_it():
    """Cycles' sun lamps are hidden from camera rays unless their object's Visibility > Camera is
    on; a Sky Texture's sun (export/world.py) always is. Seen, the disc's radiance is
    S / (pi sin^2 h) (h the half angle): a white sun's RGB that in every channel, 0 outside it."""
    hidden, seen = _sun_view(0), _sun_view(1)
    assert np.all(hidden == 0)
    expect = 2.0 / (math.pi * math.sin(math.radians(10)) ** 2)
    centre = seen[10:14, 10:14].reshape(-1, 3)
    assert np.allclose(centre, expect, rtol=0.01), (centre.mean(0), expect)
    assert np.all(seen[0] == 0) and np.all(seen[:, 0] == 0)  # the 50 degree view's corners are outside the disc
    assert np.isfinite(seen).all() and (seen >= 0).all()


def test_camera_visible_is_a_0_or_1_column_saved_with_the_scene(tmp_path):
    from opal_diffraction.core.scene.model import Camera
    s = Scene()
    s.camera = Camera.look_at((0, 0, 0), (0, 0, 1), up=(0, 1, 0), width=4, height=4)
    s.lights = Lights.from_list([{"kind": "SUN", "angle": 0.1, "camera_visible": 1}])
    save_scene(validate(s).scene, tmp_path / "s.npz")
    assert load_scene(tmp_path / "s.npz").lights.camera_visible.tolist() == [1]
    s.lights = Lights.from_list([{"kind": "SUN", "angle": 0.1, "camera_visible": 2}])
    with pytest.raises(SceneError, match="camera visible must be 0 or 1"):
        validate(s)
