"""The eye pass as a path tracer: indirect bounces, bounce limits and the path-space split with
the light pass (docs/physics.md section 4.5), checked against analytic furnaces.

A closed room whose walls all have albedo rho and emit radiance E: the radiance everywhere is
E (1 + rho + rho^2 + ...) = E / (1 - rho), or the partial sum when bounces are limited. A
lossless glass object inside changes nothing (the radiance field is uniform and glass preserves
radiance). The tolerance of each check is a Z-test over pixels (pixels are independent samples:
each pixel its own sequence, ``blue_noise=False``); the default blue-noise pattern, whose pixels
share one sequence, is checked against the same furnace with independent renders (seeds).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings

RHO, E = 0.5, 0.4
Z_MAX = 4.5  # a few comparisons per test: |z| > 4.5 has probability < 1e-5 for a correct renderer


def _inward_box(half: float):
    """A closed cube of side 2 * half, its triangles facing inwards."""
    v, t = primitives.box((0.0, 0.0, 0.0), (2 * half,) * 3)
    return v, np.asarray(t)[:, ::-1]


def furnace(glass: bool = False, pixels: int = 24) -> Scene:
    mats = [{"kind": "DIFFUSE", "color": (RHO,) * 3, "emission": (E,) * 3}]
    if glass:
        mats.append({"kind": "DIELECTRIC", "color": (1.0, 1.0, 1.0), "ior": 1.5})
    s = Scene(materials=Materials.from_list(mats))
    s.add_mesh(*_inward_box(2.0), material=0)
    if glass:
        s.add_mesh(*primitives.icosphere((0.0, 0.0, 0.0), 0.8, 2), material=1)
    s.camera = Camera.look_at((0.0, -1.6, 0.3), (0.0, 0.0, 0.0), lens=20, width=pixels, height=pixels)
    return s


def _luma_mean_and_error(rgb: np.ndarray) -> tuple[float, float]:
    y = rgb.mean(axis=2).ravel()  # a grey scene: the channel mean
    return float(y.mean()), float(y.std(ddof=1) / np.sqrt(len(y)))


def _assert_close(rgb, expected: float, what: str):
    mean, err = _luma_mean_and_error(rgb)
    # (float32 rounding floor: a furnace with every wall alike has no variance at all)
    z = (mean - expected) / max(err, 1e-5 * expected)
    print(f"{what}: mean {mean:.5f} expected {expected:.5f} (standard error {err:.2g}, z {z:+.2f})")
    assert abs(z) < Z_MAX, f"{what}: mean {mean:.5f} vs {expected:.5f} (z = {z:+.1f})"
    # and the tolerance is tight enough to mean something: 1 % of the value
    assert err < 0.01 * expected, f"{what}: too noisy to test ({err:.3g})"


def _settings(**kw) -> RenderSettings:
    base = dict(samples=64, light_paths=0, threads=1, wavelength_step=20.0, seed=3, blue_noise=False)
    base.update(kw)
    return RenderSettings(**base)


@pytest.mark.parametrize("diffuse_bounces", [0, 1, 3])
def test_furnace_honours_the_diffuse_bounce_limit(diffuse_bounces):
    """With D diffuse bounces, light that scattered at most D + 1 times reaches the eye (the last
    vertex's direct light, as Cycles' next-event estimation at its last bounce): E sum_{i<=D+1} rho^i."""
    rgb = render(furnace(), _settings(diffuse_bounces=diffuse_bounces, max_bounces=64)).rgb
    expected = E * sum(RHO**i for i in range(diffuse_bounces + 2))
    _assert_close(rgb, expected, f"diffuse bounces {diffuse_bounces}")


def test_furnace_converges_to_the_analytic_radiance():
    """Unlimited bounces (Russian roulette ends the paths, unbiased): E / (1 - rho)."""
    rgb = render(furnace(), _settings(diffuse_bounces=200, max_bounces=200, samples=128)).rgb
    _assert_close(rgb, E / (1 - RHO) * (1 - RHO**202), "unlimited")


def test_blue_noise_sampling_converges_to_the_same_radiance():
    """The default pattern (pixels take blocks of one shared sequence, docs/physics.md section
    6.6) is unbiased: six renders' image means against E / (1 - rho) with three diffuse bounces'
    partial sum, the tolerance from the renders' scatter (a t-test, 5 degrees of freedom)."""
    expected = E * sum(RHO**i for i in range(5))
    means = np.array([render(furnace(pixels=16),
                             _settings(diffuse_bounces=3, max_bounces=64, samples=16, seed=seed,
                                       blue_noise=True)).rgb.mean() for seed in range(6)])
    err = means.std(ddof=1) / np.sqrt(len(means))
    t = (means.mean() - expected) / max(err, 1e-5 * expected)
    print(f"blue noise: {means.mean():.5f} +- {err:.5f} (expected {expected:.5f}, t {t:+.2f})")
    assert abs(t) < 6.9 and abs(means.mean() - expected) < 0.01 * expected  # P(|t_5| > 6.9) < 0.001


def test_glass_in_the_furnace_neither_adds_nor_loses_energy():
    """A clear glass ball in the furnace: every pixel, on the glass or not, sees E / (1 - rho).
    Paths diffuse -> glass -> emitter are found by the eye pass here (the light pass traces no
    mesh emitters), so the check covers the eye pass's share of the split."""
    s = furnace(glass=True)
    rgb = render(s, _settings(diffuse_bounces=200, glossy_bounces=200, transmission_bounces=200,
                              max_bounces=200, samples=128)).rgb
    _assert_close(rgb, E / (1 - RHO) * (1 - RHO**202), "glass in the furnace")


def test_dispersive_glass_in_the_furnace_is_unbiased_under_mono_roulette():
    """A dispersive (Abbe 30) glass ball in the furnace: the rays it refracts become mono rays,
    which bounce on the walls until Russian roulette ends them (judged by their white parent's
    throughput times their own losses: core/transport/wavelengths.py ``child_split``). Every pixel
    still sees E / (1 - rho); and the roulette did end mono paths (fewer rays than with mono rays
    kept to the bounce limit, the rule before)."""
    from opal_diffraction.core.integrators.eye import eye_pass

    s = furnace(glass=True)
    s.materials = Materials.from_list([
        {"kind": "DIFFUSE", "color": (RHO,) * 3, "emission": (E,) * 3},
        {"kind": "DIELECTRIC", "color": (1.0, 1.0, 1.0), "ior": 1.6, "dispersion": "ABBE", "abbe": 30.0}])
    st = _settings(diffuse_bounces=200, glossy_bounces=200, transmission_bounces=200, max_bounces=200, samples=128)
    res = render(s, st)
    _assert_close(res.rgb, E / (1 - RHO) * (1 - RHO**202), "dispersive glass in the furnace")
    rule = eye_pass.russian_roulette

    def bounce_limit_for_mono(c, rays, rng):
        return (rays.depth < c.limits[0]) & ~rays.state.final if rays.lam is not None else rule(c, rays, rng)

    eye_pass.russian_roulette = bounce_limit_for_mono
    try:
        kept = render(s, dataclasses.replace(st, samples=8))
    finally:
        eye_pass.russian_roulette = rule
    rouletted = render(s, dataclasses.replace(st, samples=8))
    assert rouletted.stats["rays"] < 0.8 * kept.stats["rays"], (rouletted.stats["rays"], kept.stats["rays"])


def test_max_bounces_zero_is_direct_light_only():
    """max_bounces 0: emission seen plus one emission-only segment (direct light), E (1 + rho)."""
    rgb = render(furnace(), _settings(max_bounces=0)).rgb
    _assert_close(rgb, E * (1 + RHO), "max bounces 0")


def test_bump_shadowing_is_the_conty_estevez_smith_term():
    """Conty Estevez et al. 2019: G1 of GGX with alpha^2 = tan^2(theta_d) / 8 towards the light;
    1 for an unbent normal, 0 below the interpolated surface (values by hand)."""
    from opal_diffraction.core.integrators.eye.surface_interaction import bump_shadowing

    ni = np.array([[0.0, 0.0, 1.0]] * 3, np.float32)
    d45 = np.float32(np.sqrt(0.5))
    ns = np.array([[0.0, 0.0, 1.0], [d45, 0.0, d45], [d45, 0.0, d45]], np.float32)
    wi = np.array([[0.6, 0.0, 0.8], [np.sin(np.pi / 3), 0.0, 0.5], [0.6, 0.0, -0.8]], np.float32)
    g = bump_shadowing(ni, ns, wi)
    np.testing.assert_allclose(g, [1.0, 2 / (1 + np.sqrt(1 + 0.125 * 3.0)), 0.0], rtol=1e-5)


def test_glass_in_the_furnace_with_the_light_pass_counts_each_path_once():
    """The same glass ball in the furnace with the light pass on: it emits from the glowing walls
    through the glass onto the walls (caustic paths, read from its map), and the eye pass leaves
    those paths out, so the radiance is still E / (1 - rho). The light pass's map is shared by
    all pixels of a render, so the tolerance comes from independent renders (seeds), not pixels."""
    s = furnace(glass=True, pixels=16)
    means = []
    for seed in range(4):
        res = render(s, _settings(diffuse_bounces=200, glossy_bounces=200, transmission_bounces=200,
                                  max_bounces=200, samples=32, light_paths=100_000, seed=seed))
        assert res.plan.light_pass and res.passes["Caustics"].max() > 0  # the split is exercised
        means.append(float(res.rgb.mean()))
    means = np.array(means)
    expected = E / (1 - RHO) * (1 - RHO**202)
    err = means.std(ddof=1) / np.sqrt(len(means))
    z = (means.mean() - expected) / max(err, 1e-5 * expected)
    print(f"with the light pass: {means.mean():.5f} +- {err:.5f} (expected {expected:.5f}, z {z:+.2f})")
    # four renders: a t-distribution with 3 degrees of freedom; |t| < 9 has probability 0.997
    assert abs(z) < 9 and abs(means.mean() - expected) < 0.02 * expected
