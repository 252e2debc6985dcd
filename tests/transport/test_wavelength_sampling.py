"""Wavelength sampling at dispersive glass (core/transport/wavelengths.py, docs/physics.md section 2.6).

- chi-square tests of the wavelength sampler against its pdf (Mitsuba 3's chi2 test: cells
  with an expected count below 5 pooled, the p-value threshold divided by the number of tests);
- the estimator's expectation: Z-tests of ``draw``'s weights against the exact per-wavelength
  sum, and of a rendered prism (white reflection + sampled refraction) against SPLIT's exact
  sum over wavelengths;
- energy: a clear dispersive prism in a uniform white world (a furnace) shows the world's
  spectrum at every pixel, in expectation, for every wavelength.
"""

import numpy as np
import pytest
from scipy import stats

from chi2 import pearson
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.transport import wavelengths
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.spectral.spectrum import SpectralConverter, WavelengthGrid

GRID = WavelengthGrid(400.0, 700.0, 5.0)
N_TESTS = 8  # chi-square tests in this file (Bonferroni)
ALPHA = 1e-3


def test_sensitivity_is_the_norm_of_the_rec709_matching_functions():
    conv = SpectralConverter(GRID)
    s = wavelengths.sensitivity(GRID)
    np.testing.assert_allclose(s, np.linalg.norm(conv.rgb_weights, axis=1), rtol=1e-12)
    np.testing.assert_allclose(wavelengths.sensitivity(GRID, white=True), s * conv.white_illuminant, rtol=1e-12)
    # the eye's sensitivity peaks in the green and is small at the grid's ends
    peak = GRID.wavelengths[np.argmax(wavelengths.sensitivity(GRID, white=True))]
    assert 500.0 < peak < 620.0


@pytest.mark.parametrize("weighted,by_sensitivity", [(False, True), (True, True), (True, False)])
def test_chi2_of_the_wavelength_sampler(weighted, by_sensitivity):
    """Histogram of drawn wavelengths vs the (defended) importance pdf, one number per ray
    (without ``by_sensitivity``: the weights' own distribution, no defensive share)."""
    rng = np.random.default_rng(1)
    b, n = 200_000, GRID.n
    w = None
    if weighted:  # a tint: a smooth spectrum with a zero band (never drawn)
        w = np.tile(np.clip(np.sin(np.linspace(0, 3, n)), 0, None), (b, 1))
        w[:, 10:14] = 0.0
    q = wavelengths.importance(GRID, w, b, by_sensitivity)
    p = wavelengths._defended(q[:1], by_sensitivity)[0]
    assert p.sum() == pytest.approx(1.0, abs=1e-12)
    parent, lam, _ = wavelengths.draw(GRID, w, rng.random(b), 1, by_sensitivity)
    assert len(parent) == b
    counts = np.bincount(lam, minlength=n)
    assert counts[p == 0].sum() == 0  # nothing where the pdf is zero
    pv, info = pearson(counts, b * p)
    assert pv > ALPHA / N_TESTS, info


@pytest.mark.parametrize("k", [2, 4])
def test_chi2_of_each_rotated_hero_wavelength(k):
    """Each of the K rotated numbers u + j / K is uniform, so each column follows the pdf."""
    rng = np.random.default_rng(2 + k)
    b, n = 100_000, GRID.n
    u = rng.random(b)
    p = wavelengths._defended(wavelengths.importance(GRID, None, 1, True), True)[0]
    lam = wavelengths.sample_indices(np.broadcast_to(p, (b, n)), wavelengths.rotated(u, k))
    for j in (0, k - 1):
        counts = np.bincount(lam[:, j], minlength=n)
        assert counts[p == 0].sum() == 0  # nothing where the pdf is zero
        pv, info = pearson(counts, b * p)
        assert pv > ALPHA / N_TESTS, (j, info)
    # and stratified: the K wavelengths of one ray lie in K different quarters of the CDF
    cdf = np.cumsum(p)
    quarter = np.minimum((cdf[lam] - p[lam] * 0.5) * k, k - 1).astype(int)
    assert (np.sort(quarter, axis=1) == np.arange(k)).mean() > 0.9


@pytest.mark.parametrize("k,extra", [(1, False), (4, False), (4, True)])
def test_draw_is_unbiased_for_the_exact_sum(k, extra):
    """E[sum of children weights at wavelength m] = target_m = w_m q_m (Z-test per wavelength)."""
    rng = np.random.default_rng(10 + k)
    b, n = 100_000, GRID.n
    w = np.tile(0.2 + np.cos(np.linspace(0, 2, n)) ** 2, (b, 1)).astype(np.float32)
    q = np.tile(np.linspace(0.3, 0.9, n), (b, 1)) if extra else None
    parent, lam, weight = wavelengths.draw(GRID, w, rng.random(b), k, True, q_extra=q)
    per_ray = np.zeros((b, n))
    np.add.at(per_ray, (parent, lam), weight)
    mean, sem = per_ray.mean(axis=0), per_ray.std(axis=0, ddof=1) / np.sqrt(b)
    target = w[0] * (1.0 if q is None else q[0])
    z = (mean - target) / sem
    # two-sided, Bonferroni over the n wavelengths at overall 1e-3
    assert np.abs(z).max() < stats.norm.isf(ALPHA / (2 * n)), np.abs(z).max()
    # energy: the expected total per ray is the target's sum
    zt = (per_ray.sum(axis=1).mean() - target.sum()) / (per_ray.sum(axis=1).std(ddof=1) / np.sqrt(b))
    assert abs(zt) < stats.norm.isf(ALPHA / 2)


def _prism_scene(world=True, wall=False, size=(32, 24)):
    mats = [{"name": "flint", "kind": "DIELECTRIC", "color": (1, 1, 1), "ior": 1.72, "dispersion": "ABBE",
             "abbe": 29.0},
            {"name": "white", "kind": "DIFFUSE", "color": (0.9, 0.9, 0.9)},
            {"name": "black", "kind": "DIFFUSE", "color": (0.02, 0.02, 0.02)}]
    s = Scene(materials=Materials.from_list(mats))
    s.add_mesh(*primitives.prism((0, 0, 0.75), side=1.2, length=2.4, axis="X", rotation_deg=180.0), material=0)
    if wall:  # stripes behind the prism (examples/prism.py): edges fan out into spectra
        for i in range(8):
            z = (i + 0.5) * 0.5
            s.add_mesh(*primitives.quad((0.0, 3.0, z), (10.0, 0, 0), (0, 0, 0.5)), material=1 + i % 2)
    s.camera = Camera.look_at((0.0, -4.0, 1.4), (0.0, 0.5, 0.9), lens=50.0, width=size[0], height=size[1])
    s.world_color = np.full(3, 1.0 if world else 0.0, np.float32)
    return s


def _settings(mode, seed, spp=16):
    # high bounce limits: a furnace loses no energy to them; independent pixels (Z-tests over pixels)
    return RenderSettings(samples=spp, seed=seed, dispersion_sampling=mode, light_paths=0, max_bounces=64,
                          glossy_bounces=64, transmission_bounces=64, threads=1, blue_noise=False)


def test_furnace_a_dispersive_prism_in_a_white_world_is_invisible():
    """A clear dielectric in a uniform world: every path ends in the world with unit expected
    weight per wavelength, so every pixel's spectrum equals the world's (docs/physics.md section 2.6)."""
    s = _prism_scene(world=True)
    r = render(s, _settings("SAMPLE", 5, spp=32), spectral_film=True)
    spec = r.spectral.reshape(-1, r.spectral.shape[-1]).astype(np.float64)
    # pixels that miss the prism see the world exactly: the most common spectrum is the expected one
    rows, counts = np.unique(spec, axis=0, return_counts=True)
    world = rows[np.argmax(counts)]
    assert counts.max() > 0.2 * len(spec)
    through = np.abs(spec / world - 1).max(axis=1) > 1e-4  # pixels whose paths met the glass
    assert through.mean() > 0.2
    ratio = spec[through] / world  # per pixel and wavelength: mean 1
    m = ratio.mean(axis=0)
    sem = ratio.std(axis=0, ddof=1) / np.sqrt(through.sum())
    z = (m - 1.0) / sem
    assert np.abs(z).max() < stats.norm.isf(ALPHA / (2 * len(m))), (np.abs(z).max(), m.min(), m.max())
    # the sum over wavelengths and the image's R, G, B (where the per-wavelength test has little power)
    rgb = r.rgb.reshape(-1, 3).astype(np.float64)
    vals = np.concatenate([spec[through].sum(axis=1, keepdims=True) / world.sum(),
                           rgb[through] / rgb[~through].mean(axis=0)], axis=1)
    z = (vals.mean(axis=0) - 1.0) / (vals.std(axis=0, ddof=1) / np.sqrt(len(vals)))
    assert np.abs(z).max() < stats.norm.isf(ALPHA / 8), (z, vals.mean(axis=0))


def test_sampled_dispersion_matches_split_on_the_prism():
    """The striped wall through the prism: the SAMPLE estimator's expected spectrum per pixel
    block equals SPLIT's exact sum over wavelengths (Z-test, the noise of both measured from
    independent renders)."""
    s = _prism_scene(world=False, wall=True, size=(32, 24))
    from opal_diffraction.core.scene.model import Lights

    s.lights = Lights.from_list([{"kind": "POINT", "position": (2.0, -3.0, 5.0), "power": 1500.0}])

    def blocks(mode, seeds):
        out = []
        for seed in seeds:
            rgb = render(s, _settings(mode, seed, spp=8)).rgb.astype(np.float64)
            out.append(rgb.reshape(3, 8, 4, 8, 3).mean(axis=(1, 3)).ravel())  # 4 x 8-px blocks
        return np.array(out)

    a = blocks("SAMPLE", range(1, 9))
    b = blocks("SPLIT", range(11, 14))
    ma, mb = a.mean(axis=0), b.mean(axis=0)
    va = a.var(axis=0, ddof=1) / len(a)
    vb = b.var(axis=0, ddof=1) / len(b)
    ok = (va + vb) > 0
    z = (ma - mb)[ok] / np.sqrt(va + vb)[ok]
    # the variances are estimated from few renders: Student-t quantiles (Welch's dof, at least 2)
    dof = np.maximum((va + vb)[ok] ** 2 / (va[ok] ** 2 / (len(a) - 1) + vb[ok] ** 2 / (len(b) - 1) + 1e-300), 2.0)
    assert np.all(np.abs(z) < stats.t.isf(ALPHA / (2 * ok.sum()), dof)), np.abs(z).max()
    # and the test has power: the blocks differ from each other far more than the noise
    assert np.ptp(mb) > 20 * np.sqrt(vb.max())
