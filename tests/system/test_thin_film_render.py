"""Thin films in whole renders (docs/physics.md section 2.8), against the closed form.

A large filmed plane seen by an orthographic camera at 45 degrees under a uniform white world:
every pixel sees the world reflected once, so its spectral radiance is the world's spectrum
times the film's reflectance at 45 degrees, computed here by the independent characteristic
matrix (tests/thin_film_matrix.py). A filmed mirror is deterministic (float32 rounding only); a
filmed glass sheet over a black floor chooses reflect / refract at random, so it is a Z-test
per wavelength over the pixels. A filmed glass ball in a glowing furnace neither adds nor loses
energy (a lossless film: R + T = 1).
"""

import math

import numpy as np
import pytest

from opal_diffraction.core.render.frame import render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.model import Camera, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings

from thin_film_matrix import matrix_unpolarised

FILM_D, FILM_N, GLASS_N = 350.0, 1.33, 1.5
Z_MAX = 4.5


def _plane_scene(kind: str, color=(1.0, 1.0, 1.0), pixels=12) -> Scene:
    mats = [{"kind": kind, "color": color, "ior": GLASS_N, "thin_film_thickness": FILM_D, "thin_film_ior": FILM_N},
            {"kind": "DIFFUSE", "color": (0.0, 0.0, 0.0)}]
    s = Scene(materials=Materials.from_list(mats))
    v = np.array([[-50, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0]], float)
    t = np.array([[0, 1, 2], [0, 2, 3]])
    s.add_mesh(v, t, material=0)
    s.add_mesh(v + [0, 0, -1], t, material=1)  # a black floor under a glass sheet
    s.camera = Camera.look_at((0, -3, 3), (0, 0, 0), kind="ORTHO", ortho_scale=1.0, width=pixels, height=pixels)
    s.world_color = np.array([1.0, 1.0, 1.0])
    return s


def _settings(**kw) -> RenderSettings:
    base = dict(samples=16, light_paths=0, threads=1, seed=5, blue_noise=False, wavelength_step=10.0)
    base.update(kw)
    return RenderSettings(**base)


def _expected(scene, settings, n_sub_of):
    """The world's spectrum (as prepared) times the matrix's reflectance at 45 degrees per grid wavelength."""
    prepared = prepare(scene, settings)
    wl = prepared.grid.wavelengths
    r = np.array([matrix_unpolarised(1.0, FILM_N, FILM_D, n_sub_of(prepared, k), math.radians(45.0), w)[0]
                  for k, w in enumerate(wl)])
    return prepared.world_spectrum.astype(np.float64) * r, r


def _gulbrandsen(f0, g):
    """Gulbrandsen 2014 (JCGT 3(4)) eqs. for n and k from the reflectance r and edge tint g."""
    r = min(f0, 0.999)
    n = g * (1 - r) / (1 + r) + (1 - g) * (1 + math.sqrt(r)) / (1 - math.sqrt(r))
    k = math.sqrt(max((r * (n + 1) ** 2 - (n - 1) ** 2) / (1 - r), 0.0))
    return complex(n, k)


def test_filmed_mirror_reflects_the_world_times_the_film_reflectance():
    scene, settings = _plane_scene("MIRROR", color=(0.9, 0.9, 0.9)), _settings(samples=4)
    # a constant-colour mirror: F0 = its reflectance spectrum, edge tint = F0
    expected, r = _expected(scene, settings,
                            lambda p, k: _gulbrandsen(float(p.materials.reflectance[0, k]),
                                                      float(p.materials.reflectance[0, k])))
    assert np.ptp(r) > 0.05  # the film colours the reflection
    res = render(scene, settings, spectral_film=True)
    spec = res.spectral.reshape(-1, len(r)).astype(np.float64)
    np.testing.assert_allclose(spec, np.broadcast_to(expected, spec.shape), rtol=2e-4, atol=1e-6)


@pytest.mark.parametrize("sampling", ["SAMPLE", "SPLIT"])
def test_filmed_glass_sheet_reflects_the_film_reflectance(sampling):
    """White camera rays at the filmed glass: reflected white with weight F_k / P (SAMPLE) or split
    into mono rays (SPLIT); the refracted light dies on the black floor."""
    scene = _plane_scene("DIELECTRIC")
    settings = _settings(samples=32, dispersion_sampling=sampling)
    expected, r = _expected(scene, settings, lambda p, k: GLASS_N)
    res = render(scene, settings, spectral_film=True)
    spec = res.spectral.reshape(-1, len(r)).astype(np.float64)
    # the level: a Z-test of the pixels' totals (SAMPLE's reflect / refract choice is per ray, so
    # its noise is one factor shared by every wavelength of a sample)
    tot = spec.sum(axis=1)
    err = tot.std(ddof=1) / math.sqrt(len(tot))
    z = (tot.mean() - expected.sum()) / max(err, 1e-5 * expected.sum())
    print(f"{sampling}: total {tot.mean():.6f} +- {err:.6f}, expected {expected.sum():.6f} (z {z:+.2f})")
    assert abs(z) < Z_MAX and err < 0.05 * expected.sum()
    # the spectrum's shape, exact up to float32: the film's colour at every wavelength
    mean = spec.mean(axis=0)
    np.testing.assert_allclose(mean / mean.sum(), expected / expected.sum(), rtol=1e-3)
    assert np.ptp(r) > 0.03  # the test can tell the film from plain glass (4 % at every wavelength)


def test_filmed_glass_in_the_furnace_neither_adds_nor_loses_energy():
    """A filmed glass ball (a lossless film) inside a closed room of albedo rho glowing E: E / (1 - rho)."""
    rho, e = 0.5, 0.4
    mats = [{"kind": "DIFFUSE", "color": (rho,) * 3, "emission": (e,) * 3},
            {"kind": "DIELECTRIC", "color": (1.0, 1.0, 1.0), "ior": GLASS_N, "thin_film_thickness": 420.0,
             "thin_film_ior": 1.38}]
    s = Scene(materials=Materials.from_list(mats))
    v, t = primitives.box((0.0, 0.0, 0.0), (4.0,) * 3)
    s.add_mesh(v, np.asarray(t)[:, ::-1], material=0)
    s.add_mesh(*primitives.icosphere((0.0, 0.0, 0.0), 0.8, 2), material=1)
    s.camera = Camera.look_at((0.0, -1.6, 0.3), (0.0, 0.0, 0.0), lens=20, width=12, height=12)
    res = render(s, _settings(samples=48, diffuse_bounces=60, glossy_bounces=60, transmission_bounces=60,
                              max_bounces=60, wavelength_step=20.0))
    y = res.rgb.mean(axis=2).ravel()
    expected = e / (1 - rho) * (1 - rho ** 62)
    mean, err = float(y.mean()), float(y.std(ddof=1) / math.sqrt(len(y)))
    z = (mean - expected) / max(err, 1e-5 * expected)
    print(f"furnace: {mean:.5f} +- {err:.5f} (expected {expected:.5f}, z {z:+.2f})")
    assert abs(z) < Z_MAX and err < 0.01 * expected


@pytest.mark.parametrize("row, message", [
    ({"thin_film_thickness": -5.0}, "thin film thickness must be >= 0 nm"),
    ({"thin_film_thickness": float("nan")}, "thin film thickness is NaN or infinite"),
    ({"thin_film_thickness": 300.0, "thin_film_ior": 0.5}, "thin film IOR must be between 1"),
])
def test_bad_film_values_are_one_scene_error_line(row, message):
    scene = _plane_scene("DIELECTRIC")
    for name, value in row.items():
        getattr(scene.materials, name)[0] = value
    with pytest.raises(SceneError, match=message) as err:
        prepare(scene, _settings())
    assert "\n" not in str(err.value)


@pytest.mark.slow  # four renders with the light pass
def test_filmed_glass_and_mirror_in_the_furnace_with_the_light_pass():
    """The light pass's paths through a filmed glass ball and off a filmed clear mirror: the
    furnace stays E / (1 - rho) (the glass's film is lossless; the mirror's conductor, F0 = 1 read
    as 0.999 by Gulbrandsen's mapping, absorbs 0.1-0.3 % under the film), each path counted once,
    with tests/integrators/eye/test_path_tracing.py's tolerance for the light pass. Measured
    0.79581 +- 0.00080 for 0.8; the same scene without any film gives 0.7964 +- 0.0020 (the
    light pass's furnace is 0.45 % low without films too)."""
    rho, e = 0.5, 0.4
    mats = [{"kind": "DIFFUSE", "color": (rho,) * 3, "emission": (e,) * 3},
            {"kind": "DIELECTRIC", "color": (1.0, 1.0, 1.0), "ior": GLASS_N, **{"thin_film_thickness": 420.0,
                                                                               "thin_film_ior": 1.38}},
            {"kind": "MIRROR", "color": (1.0, 1.0, 1.0), "thin_film_thickness": 300.0, "thin_film_ior": 1.5}]
    s = Scene(materials=Materials.from_list(mats))
    v, t = primitives.box((0.0, 0.0, 0.0), (4.0,) * 3)
    s.add_mesh(v, np.asarray(t)[:, ::-1], material=0)
    s.add_mesh(*primitives.icosphere((-0.5, 0.3, 0.0), 0.6, 2), material=1)
    s.add_mesh(*primitives.icosphere((0.7, 0.5, -0.3), 0.4, 2), material=2)
    s.camera = Camera.look_at((0.0, -1.6, 0.3), (0.0, 0.0, 0.0), lens=20, width=12, height=12)
    means = []
    for seed in range(4):
        res = render(s, _settings(samples=16, seed=seed, light_paths=50_000, diffuse_bounces=60, glossy_bounces=60,
                                  transmission_bounces=60, max_bounces=60, wavelength_step=20.0))
        assert res.plan.light_pass and res.passes["Caustics"].max() > 0
        means.append(float(res.rgb.mean()))
    means = np.array(means)
    expected = e / (1 - rho) * (1 - rho ** 62)
    err = means.std(ddof=1) / math.sqrt(len(means))
    t_stat = (means.mean() - expected) / max(err, 1e-5 * expected)
    print(f"light pass: {means.mean():.5f} +- {err:.5f} (expected {expected:.5f}, t {t_stat:+.2f})")
    assert abs(t_stat) < 9 and abs(means.mean() - expected) < 0.02 * expected  # t with 3 dof: P(|t| > 9) < 0.003


def test_a_film_under_a_grating_is_warned_about():
    scene = _plane_scene("MIRROR")
    scene.materials.grating[0] = 1
    scene.materials.name[0] = "filmed grating"
    warnings = prepare(scene, _settings()).warnings
    assert any("'filmed grating': its thin film is not rendered under its grating layer" in w for w in warnings)
