"""Adaptive sampling (core/render/adaptive.py, Cycles' Noise Threshold; docs/physics.md section 10.5):
the error estimate is an unbiased estimate of the mean's error for equal and unequal halves,
Cycles' parameters, the 3 x 3 dilation, the settings' validation, and on a scene with a noise-free
region (the world seen directly), a quiet one (a plane far from a wall) and a noisy one (the
plane beside the wall): converged pixels stop at the minimum, the noise left in every region is
below the threshold's prediction, the image mean is unbiased against a non-adaptive render, and
the image is deterministic (threads, Dask workers) and unchanged when adaptive sampling is off."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage, stats

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.render.adaptive import THRESHOLD_SCALE, dilate, error_estimate, min_samples, next_active
from opal_diffraction.core.sampling.camera import FilterSampler
from opal_diffraction.core.integrators.eye.eye_pass import EyePass
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Materials, Scene
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.settings import EYE_ONLY_SETTINGS, RenderSettings
from opal_diffraction.core.render.tiles import EyeWork, adaptive_rounds, trace_tile
from opal_diffraction.core.render.plan import plan_render

from scenes import top_down_camera

THRESHOLD = 0.01
BASE = dict(samples=256, round_samples=8, tile_size=8, diffuse_bounces=1, wavelength_step=20.0, threads=2)
# columns of the 32 x 32 image (8 px per metre): the world seen directly, the plane far from the
# wall, the plane beside it
REGIONS = {"world": np.s_[:, 0:6], "far plane": np.s_[:, 10:18], "near the wall": np.s_[:, 21:26]}


def wall_scene(pixels: int = 32) -> Scene:
    """A white-ish diffuse plane over the right three quarters of a top-down view in a uniform
    grey world, with a long wall standing on it near the right edge: the left quarter sees the
    world (no noise at all), the plane far from the wall sees almost all of the sky (little
    noise), beside the wall half the sky is blocked (noisy)."""
    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE", "color": (0.8, 0.8, 0.8)}]),
              world_color=np.array([0.5, 0.5, 0.5], np.float32))
    s.add_mesh(*primitives.quad((1.0, 0, 0), (2.0, 0, 0), (0, 4.0, 0)), material=0)
    s.add_mesh(*primitives.box((1.6, 0.0, 0.5), (0.4, 4.0, 1.0)), material=0)
    s.camera = top_down_camera(4.0, pixels)
    return s


# ------------------------------------------------------------------------------ the estimate
def test_min_samples_follow_cycles_rule():
    # intern/cycles/scene/integrator.cpp: "Threshold 0.1 -> 32, 0.01 -> 64, 0.001 -> 128", at least 4
    assert (min_samples(0.1, 0), min_samples(0.01, 0), min_samples(0.001, 0)) == (32, 64, 128)
    assert min_samples(0.01, 2) == 4 and min_samples(0.01, 100) == 100
    assert THRESHOLD_SCALE == 5.0


def test_equal_halves_give_cycles_formula_with_its_doubled_half_buffer():
    """Cycles stores A = 2 x (sum of half A) and computes sum_c |I - A| / N / (1e-4 + sqrt(L))."""
    rng = np.random.default_rng(1)
    n = 32
    samples = rng.exponential(0.2, (500, n, 3))
    total, half = samples.sum(1), samples[:, ::2].sum(1)
    lum = total.sum(-1) / n
    cycles = np.abs(total - 2 * half).sum(-1) / n / (1e-4 + np.where(lum < 1, np.sqrt(lum), lum))
    ours = error_estimate(total, np.full(500, n), half, np.full(500, n // 2))
    np.testing.assert_allclose(ours, cycles, rtol=1e-12)
    bright = samples * 40  # L > 1: normalised by L itself (over-exposed pixels take fewer samples)
    lum = bright.sum((1, 2)) / n
    assert (lum > 1).all()
    cycles = np.abs(bright.sum(1) - 2 * bright[:, ::2].sum(1)).sum(-1) / n / (1e-4 + lum)
    np.testing.assert_allclose(error_estimate(bright.sum(1), np.full(500, n), bright[:, ::2].sum(1),
                                              np.full(500, n // 2)), cycles, rtol=1e-12)


@pytest.mark.parametrize("n, n_a", [(16, 8), (24, 8), (40, 32)])
def test_the_estimate_is_the_mean_error_for_unequal_halves_too(n, n_a):
    """For Gaussian samples the expected error estimate is E|mean - mu| (per channel
    sigma / sqrt(N) * sqrt(2 / pi)) over the normaliser, whatever the split of the halves: a
    Z-test over many independent pixels."""
    rng = np.random.default_rng(n * 100 + n_a)
    trials, mu, sigma = 20000, np.array([0.3, 0.2, 0.1]), np.array([0.05, 0.04, 0.03])
    x = mu + sigma * rng.standard_normal((trials, n, 3))
    e = error_estimate(x.sum(1), np.full(trials, n), x[:, :n_a].sum(1), np.full(trials, n_a))
    lum = x.sum((1, 2)) / n
    e_abs = e * (1e-4 + np.sqrt(lum))  # back to sum_c |.|: the normaliser is the pixel's own
    expected = (sigma / math.sqrt(n) * math.sqrt(2 / math.pi)).sum()
    z = (e_abs.mean() - expected) / (e_abs.std(ddof=1) / math.sqrt(trials))
    assert abs(z) < 4.0, (e_abs.mean(), expected, z)


def test_a_half_without_samples_never_converges():
    e = error_estimate(np.ones((2, 3)), np.array([8, 8]), np.array([[1.0] * 3, [0.0] * 3]), np.array([8, 0]))
    assert np.isinf(e).all()


def test_dilation_is_a_3x3_box():
    rng = np.random.default_rng(3)
    for _ in range(20):
        m = rng.random((8, 11)) < 0.1
        np.testing.assert_array_equal(dilate(m), ndimage.binary_dilation(m, np.ones((3, 3), bool)))


def test_pixels_sample_until_the_minimum_and_stay_active_beside_unconverged_ones():
    act = np.ones((5, 5), bool)
    err = np.zeros((5, 5))
    err[2, 2] = 1.0  # one pixel above the threshold: it and its neighbours go on
    new = next_active(act, err, np.full((5, 5), 64), 0.01, 64)
    assert new.sum() == 9 and new[1:4, 1:4].all()
    assert next_active(act, np.zeros((5, 5)), np.full((5, 5), 32), 0.01, 64).all()  # below the minimum


def test_rounds_past_the_minimum_grow_by_a_quarter_within_the_cap():
    for spp, per, floor, cap in [(1024, 8, 64, 4096), (4096, 8, 64, 256), (100, 16, 32, 4096), (7, 8, 64, 64)]:
        r = np.array(adaptive_rounds(spp, per, floor, cap))
        taken = np.concatenate([[0], np.cumsum(r)[:-1]])
        assert r.sum() == spp and (r > 0).all()
        assert (r[taken < floor] == np.minimum(per, spp - taken[taken < floor])).all()
        late = taken >= floor
        assert (r[late] <= np.maximum(per, np.minimum(cap, taken[late] // 4))).all()  # overshoot <= 1/4
        assert r.max() <= max(per, cap)
    assert len(adaptive_rounds(1024, 8, 64, 4096)) < 25  # not 128 rounds of 8
    work = EyeWork.of(prepare(wall_scene(8), RenderSettings(samples=20, round_samples=8, tile_size=8)))
    assert work.rounds == (8, 8, 4)  # adaptive sampling off: the rounds of the setting


# ------------------------------------------------------------------------------ settings
@pytest.mark.parametrize("field, value", [("adaptive_threshold", -0.1), ("adaptive_threshold", 1.5),
                                          ("adaptive_threshold", float("nan")), ("adaptive_threshold", "x"),
                                          ("adaptive_min_samples", -1), ("adaptive_min_samples", 2.5),
                                          ("adaptive_min_samples", "many")])
def test_bad_adaptive_settings_are_readable_errors(field, value):
    with pytest.raises(SceneError, match=field.replace("_", " ")):
        RenderSettings(**{field: value}).validate()


def test_adaptive_settings_are_eye_only_and_off_by_default():
    assert {"adaptive_threshold", "adaptive_min_samples"} <= EYE_ONLY_SETTINGS
    assert RenderSettings().adaptive_threshold == 0.0
    prepared = prepare(wall_scene(8), RenderSettings(samples=2))
    assert prepared.with_view(adaptive_threshold=0.05, adaptive_min_samples=16).key == prepared.key


# ------------------------------------------------------------------------------ the render
def test_off_and_never_converging_are_the_plain_sum_of_every_tile():
    """Threshold 0 (off) and a threshold no pixel reaches both give the image the units make
    when every one of them traces its whole tile (summed here without the film)."""
    scene = wall_scene(16)
    s = RenderSettings(samples=6, round_samples=2, tile_size=8, diffuse_bounces=1, wavelength_step=20.0, seed=5)
    off = render(scene, s, spectral_film=True)
    never = render(scene, replace(s, adaptive_threshold=1e-9), spectral_film=True)
    prepared = prepare(scene, s)
    work, eye, filt = EyeWork.of(prepared), EyePass(prepared, plan=plan_render(prepared)), FilterSampler(s.filter_width)
    total = np.zeros((16, 16, prepared.grid.n), np.float32)
    for r in range(len(work.rounds)):
        for t, (x0, y0, x1, y1, _) in enumerate(work.tiles):
            total[y0:y1, x0:x1] += trace_tile(eye, filt, work, r, t).film.reshape(y1 - y0, x1 - x0, -1)
    np.testing.assert_array_equal(off.spectral, total * np.float32(1 / 6))
    np.testing.assert_array_equal(never.spectral, off.spectral)
    assert (off.sample_counts == 6).all() and (never.sample_counts == 6).all()


@pytest.fixture(scope="module")
def renders():
    scene = wall_scene()
    k = 5
    adaptive = [render(scene, RenderSettings(adaptive_threshold=THRESHOLD, seed=100 + i, **BASE)) for i in range(k)]
    full = [render(scene, RenderSettings(seed=200 + i, **BASE)) for i in range(k)]
    return adaptive, full


@pytest.mark.slow
def test_converged_pixels_stop_early_and_the_noisy_ones_go_on(renders):
    adaptive, _ = renders
    counts = np.mean([r.sample_counts for r in adaptive], axis=0)
    floor = min_samples(THRESHOLD, 0)
    for name, sl in REGIONS.items():
        print(f"{name}: mean {counts[sl].mean():.1f} samples per pixel")
    assert (counts[REGIONS["world"]] == floor).all()  # no noise at all: the minimum, exactly
    assert counts[REGIONS["far plane"]].mean() < 1.2 * floor
    # the penumbra goes on well past the minimum (with the stratified numbers of core/sampling/sampler.py
    # it is less noisy than with random ones: 86 samples where it took over 96)
    assert counts[REGIONS["near the wall"]].mean() > 1.25 * floor
    assert all(r.stats["samples_max"] <= BASE["samples"] and r.stats["samples_min"] == floor for r in adaptive)
    assert all(r.stats["samples_mean"] < 0.6 * BASE["samples"] for r in adaptive)


@pytest.mark.slow
def test_the_noise_left_in_every_region_is_below_the_threshold(renders):
    """The error measured against a reference (the mean of the non-adaptive renders), in the
    estimate's own units (sum over RGB of |error| over sqrt(luminance)), averaged over each
    region and the independent seeds, is below 5 x threshold: what a pixel stops at."""
    adaptive, full = renders
    ref = np.mean([r.rgb for r in full], axis=0).astype(np.float64)
    lum = ref.sum(-1)
    norm = 1e-4 + np.where(lum < 1, np.sqrt(lum), lum)
    for name, sl in REGIONS.items():
        err = np.mean([(np.abs(r.rgb - ref).sum(-1) / norm)[sl].mean() for r in adaptive])
        print(f"{name}: error {err:.4f} (stops below {THRESHOLD_SCALE * THRESHOLD})")
        assert err < THRESHOLD_SCALE * THRESHOLD, name


@pytest.mark.slow
def test_the_image_mean_is_unbiased_against_a_non_adaptive_render(renders):
    adaptive, full = renders
    regions = {**REGIONS, "whole image": np.s_[:, :]}
    for name, sl in regions.items():
        a = np.array([r.rgb[sl].mean() for r in adaptive])
        f = np.array([r.rgb[sl].mean() for r in full])
        se = math.sqrt(a.var(ddof=1) / len(a) + f.var(ddof=1) / len(f))
        if se == 0:  # the world region: no noise at all, so exactly equal
            assert a.mean() == pytest.approx(f.mean(), rel=1e-6), name
            continue
        z = (a.mean() - f.mean()) / se
        p = 2 * stats.norm.sf(abs(z))
        print(f"{name}: adaptive {a.mean():.5f} full {f.mean():.5f} z {z:.2f}")
        assert p > 0.01 / len(regions), name  # Bonferroni over the regions


def test_adaptive_renders_are_deterministic_for_any_thread_count():
    scene = wall_scene(16)
    s = dict(samples=48, round_samples=4, tile_size=4, diffuse_bounces=1, wavelength_step=20.0, seed=9,
             adaptive_threshold=0.05, adaptive_min_samples=8)
    one = render(scene, RenderSettings(threads=1, **s), spectral_film=True)
    two = render(scene, RenderSettings(threads=2, **s), spectral_film=True)
    again = render(scene, RenderSettings(threads=2, **s), spectral_film=True)
    assert one.sample_counts.min() < one.sample_counts.max()  # it did adapt
    for r in (two, again):
        np.testing.assert_array_equal(one.spectral, r.spectral)
        np.testing.assert_array_equal(one.sample_counts, r.sample_counts)
        for k in one.passes:
            np.testing.assert_array_equal(one.passes[k], r.passes[k], err_msg=k)


@pytest.mark.slow
def test_a_dask_cluster_renders_the_adaptive_image_bit_for_bit():
    pytest.importorskip("distributed")
    from dask.distributed import Client, LocalCluster

    scene = wall_scene(16)
    s = RenderSettings(samples=48, round_samples=4, tile_size=4, diffuse_bounces=1, wavelength_step=20.0, seed=9,
                       adaptive_threshold=0.05, adaptive_min_samples=8, threads=1)
    local = render(scene, s, spectral_film=True)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        dist = render(scene, s, client=client, spectral_film=True)
    assert local.sample_counts.min() < local.sample_counts.max()
    np.testing.assert_array_equal(local.spectral, dist.spectral)
    np.testing.assert_array_equal(local.sample_counts, dist.sample_counts)
    for k in local.passes:
        np.testing.assert_array_equal(local.passes[k], dist.passes[k], err_msg=k)
    assert dist.stats["eye_tasks"] < len(EyeWork.of(prepare(scene, s)).tiles) * 12  # converged tiles got none
