"""Media through whole renders (core/integrators/eye/medium_interaction.py): Beer-Lambert per
wavelength through an absorbing slab against the closed form, and single scattering of a point
light in the world's fog against the radiative transfer integral computed by quadrature."""

import numpy as np
import pytest
from scipy import stats

from chi2 import chi2_normal_scores
from opal_diffraction.core.lights.sources import sample_light_pdf
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.volumes.media import prepare_media
from opal_diffraction.core.volumes.phase import hg
from scenes import top_down_camera


def _slab_scene(kind="DIELECTRIC", ior=1.0, scatter=0.0):
    """An emitter (white, radiance 1) at z = 0 under a 0.5 m slab at z = 0.75..1.25 holding a
    coloured absorbing medium (a volume-only boundary: a dielectric of index 1), seen from above."""
    mats = Materials.from_list([
        {"kind": "DIFFUSE", "color": (0, 0, 0), "emission": (1.0, 1.0, 1.0)},
        {"kind": kind, "ior": ior, "color": (1, 1, 1), "volume_absorption_density": 2.0,
         "volume_absorption_color": (0.9, 0.5, 0.1), "volume_scatter_density": scatter},
    ])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (10, 0, 0), (0, 10, 0)), material=0)
    s.add_mesh(*primitives.box((0, 0, 1.0), (3, 3, 0.5)), material=1)
    s.camera = top_down_camera(2.0, 8)
    return s


def test_beer_lambert_per_wavelength_through_an_absorbing_slab():
    s = _slab_scene()
    settings = RenderSettings(samples=4, threads=1)
    res = render(s, settings, spectral_film=True)
    prepared = prepare(s, settings)
    conv = prepared.conv
    sigma_a = 2.0 * conv.reflectance_from_rgb(np.array([0.9, 0.5, 0.1]))
    le = conv.illuminant_from_rgb(np.array([1.0, 1.0, 1.0]))
    want = le * np.exp(-sigma_a * 0.5)  # Beer-Lambert over the slab's 0.5 m, per wavelength
    got = res.spectral.reshape(-1, res.spectral.shape[-1])
    assert np.isfinite(got).all() and (got >= 0).all()
    assert np.allclose(got, want, rtol=2e-3, atol=0)
    # the attenuation is coloured: it differs over the wavelengths
    tr = want / le
    assert tr.max() > 1.5 * tr.min()


def test_glass_with_an_absorbing_interior_applies_beer_lambert_inside_only():
    # smooth glass (index 1.5): straight down through the slab, the two Fresnel transmissions
    # (each 1 - ((n - 1) / (n + 1))^2 at normal incidence) times Beer-Lambert inside; the
    # reflected branches lead back up into the empty world (black)
    s = _slab_scene(ior=1.5)
    settings = RenderSettings(samples=64, threads=1, filter_width=0.0)
    res = render(s, settings, spectral_film=True)
    conv = prepare(s, settings).conv
    sigma_a = 2.0 * conv.reflectance_from_rgb(np.array([0.9, 0.5, 0.1]))
    le = conv.illuminant_from_rgb(np.array([1.0, 1.0, 1.0]))
    t = 1 - (0.5 / 2.5) ** 2
    # (the slab's multiple internal reflections add t^2 R^2 e^{-3 sigma d} / (1 - R^2 e^{-2 sigma d}))
    r2 = (0.5 / 2.5) ** 4
    tr = np.exp(-sigma_a * 0.5)
    want = le * t * t * tr / (1 - r2 * tr * tr)
    got = res.spectral.reshape(-1, res.spectral.shape[-1]).mean(axis=0)
    assert np.isfinite(res.spectral).all() and (res.spectral >= 0).all()
    assert np.allclose(got, want, rtol=0.02)


def _fog_scene(pixels=12):
    mats = Materials.from_list([
        {"kind": "DIFFUSE", "volume_scatter_density": 0.3, "volume_scatter_color": (0.9, 0.6, 0.3),
         "volume_absorption_density": 0.1, "volume_absorption_color": (0.2, 0.5, 0.9), "volume_anisotropy": 0.4},
    ])
    s = Scene(materials=mats)
    s.world_volume = 0
    s.lights = Lights.from_list([{"kind": "POINT", "position": (0.0, 0.0, 0.0), "power": 1000.0}])
    # the view beside the light (its rays pass it at 0.5 m or more): free-flight sampling does
    # not aim at the light, and a ray passing next to it has a heavy-tailed estimate (the next
    # slice's equiangular sampling is for that)
    s.camera = top_down_camera(3.0, pixels, height=4.0, centre=(2.0, 0.0))
    return s


def _single_scattering(prepared, media, x, y):
    """L(lambda) (K, n) of the camera rays straight down from (x, y, 4) (K,) through the infinite
    fog: int_0^inf exp(-sigma_t s) sigma_s p(theta) g(s) exp(-sigma_t r(s)) ds times the light's
    spectrum, with g the point light's own intensity / r^2 (lights/sources.py), by the
    trapezoidal rule over s."""
    s = np.linspace(0.0, 30.0, 6001)
    k = len(x)
    p = np.stack(np.broadcast_arrays(x[:, None], y[:, None], 4.0 - s[None, :]), axis=-1).reshape(-1, 3)
    wi, dist, g, _ = sample_light_pdf(prepared.lights, 0, p.astype(np.float32), np.random.default_rng(0))
    cos = (np.asarray(wi, np.float64) @ np.array([0.0, 0.0, -1.0])).reshape(k, -1)
    dist = np.asarray(dist, np.float64).reshape(k, -1)
    a = hg(cos, media.g[0]) * np.asarray(g, np.float64).reshape(k, -1)  # (K, S)
    st, ss = media.sigma_t[0], media.sigma_s[0]
    trap = getattr(np, "trapezoid", None) or np.trapz
    out = np.empty((k, len(st)))
    for j in range(len(st)):  # per wavelength: (K, S) at a time
        out[:, j] = trap(a * np.exp(-st[j] * (s[None, :] + dist)), s, axis=1) * ss[j]
    return out * prepared.lights.spectrum[0]


@pytest.mark.slow
def test_single_scattering_of_a_point_light_in_fog_matches_the_transfer_integral():
    scene = _fog_scene()
    runs = []
    for seed in range(10):
        settings = RenderSettings(samples=32, threads=1, seed=seed, filter_width=0.0, volume_bounces=0)
        res = render(scene, settings, spectral_film=True)
        assert np.isfinite(res.spectral).all() and (res.spectral >= 0).all()
        runs.append(res.spectral)
    runs = np.array(runs)  # (seeds, H, W, n)
    prepared = prepare(scene, settings)
    media = prepare_media(prepared.scene, prepared.conv)
    cam = scene.camera
    n_px = cam.width
    px = cam.ortho_scale / n_px
    # the reference averaged over each pixel (4 x 4 sub-positions), in 2 x 2 pixel blocks and
    # three wavelength bands
    sub = (np.arange(4) + 0.5) / 4
    j, i, a, b = np.meshgrid(np.arange(n_px), np.arange(n_px), sub, sub, indexing="xy")
    x = ((j + a) * px - cam.ortho_scale / 2 + cam.matrix[0, 3]).ravel()
    y = (cam.ortho_scale / 2 - (i + b) * px).ravel()
    want = _single_scattering(prepared, media, x, y).reshape(j.shape + (-1,)).mean(axis=(2, 3))  # (H, W, n)
    bands = np.array_split(np.arange(runs.shape[-1]), 3)

    def band(a):
        a = np.stack([a[..., k].sum(axis=-1) for k in bands], axis=-1)
        return a.reshape(a.shape[:-3] + (n_px // 2, 2, n_px // 2, 2, 3)).sum(axis=(-4, -2))

    got = band(runs)  # (seeds, 6, 6, 3)
    ref = band(want)
    # per block, over all wavelengths (the bands share their paths: not independent), and the
    # bands' shares of each block (the colour): Student's t over the seeds as normal scores
    for g, r in ((got.sum(axis=-1), ref.sum(axis=-1)), (got / got.sum(axis=-1, keepdims=True),
                                                        ref / ref.sum(axis=-1, keepdims=True))):
        mean, se = g.mean(axis=0), g.std(axis=0, ddof=1) / np.sqrt(len(g))
        z = stats.norm.ppf(stats.t.cdf((mean - r) / se, len(g) - 1))
        assert chi2_normal_scores(z) > 1e-3, (np.abs(z).max(), (mean / r - 1).round(3))
    total = got.sum(axis=(1, 2, 3))
    assert abs(total.mean() / ref.sum() - 1) < 4 * total.std(ddof=1) / np.sqrt(len(total)) / ref.sum() + 1e-3
