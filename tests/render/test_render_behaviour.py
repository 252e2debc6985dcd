"""Render behaviour: reproducibility, cancellation, progress, SPLIT vs SAMPLE, the CLI."""

import os
import subprocess
import sys

import time

import numpy as np
import pytest

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.render.output import read_exr, spectral_channel_name
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.npz import save_scene
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.settings import RenderSettings
import stripe_scenes  # tests/stripe_scenes.py

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")


def prism_and_stripes(pixels=32):
    """Horizontal stripes seen through a dispersive prism (the prism bends the view up), grey."""
    return stripe_scenes.prism_and_stripes(pixels)


def test_same_seed_same_image_whatever_the_threads():
    s = prism_and_stripes()
    a = render(s, RenderSettings(light_paths=0, samples=4, seed=7, threads=1, tile_size=8), spectral_film=True).spectral
    b = render(s, RenderSettings(light_paths=0, samples=4, seed=7, threads=2, tile_size=8), spectral_film=True).spectral
    np.testing.assert_array_equal(a, b)
    c = render(s, RenderSettings(light_paths=0, samples=4, seed=8, threads=2, tile_size=8), spectral_film=True).spectral
    assert not np.array_equal(a, c)


def test_split_and_sample_agree_in_expectation():
    """Compare 4x4-pixel block means with a tolerance from the blocks' own sample spread."""
    s = prism_and_stripes(pixels=32)
    split = render(s, RenderSettings(light_paths=0, samples=16, seed=1, dispersion_sampling="SPLIT")).rgb
    sample = render(s, RenderSettings(light_paths=0, samples=64, seed=2, dispersion_sampling="SAMPLE")).rgb
    def blocks(img):
        b = img.reshape(8, 4, 8, 4, 3).transpose(0, 2, 1, 3, 4).reshape(64, 16, 3)
        return b.mean(axis=1), b.var(axis=1, ddof=1) / 16
    m1, v1 = blocks(split)
    m2, v2 = blocks(sample)
    # pixel-to-pixel variance inside a block includes real image structure, so this bound is
    # conservative; it still catches a biased estimator (a wrong weight shows as a colour shift)
    z = np.abs(m1 - m2) / np.sqrt(v1 + v2 + 1e-8)
    assert np.mean(z < 3) > 0.97
    np.testing.assert_allclose(split.mean(axis=(0, 1)), sample.mean(axis=(0, 1)), rtol=0.02)
    # the prism really disperses: through it the image is coloured (not grey)
    assert np.abs(split[..., 0] - split[..., 2]).max() > 0.05


def test_cancel_stops_early_without_an_exception():
    s = prism_and_stripes()
    calls = []
    res = render(s, RenderSettings(light_paths=0, samples=64, round_samples=4, tile_size=8),
                 should_cancel=lambda: len(calls) > 20, progress=lambda f, m: calls.append(f))
    assert res.cancelled
    assert res.samples < 64
    assert len(calls) < 64  # 16 tiles x 16 rounds if it had not stopped


def test_progress_reaches_one_and_partial_results_arrive_per_round():
    s = prism_and_stripes(pixels=16)
    fractions, partial = [], []
    res = render(s, RenderSettings(light_paths=0, samples=8, round_samples=2), progress=lambda f, m: fractions.append(f),
                 on_round=lambda r: partial.append(r.samples))
    assert fractions[-1] == pytest.approx(1.0) and np.all(np.diff(fractions) > 0)
    assert partial == [2, 4, 6, 8] and res.samples == 8 and not res.cancelled


@pytest.mark.slow  # a subprocess: python -m opal_diffraction render
def test_cli_renders_exr_png_and_spectral_exr(tmp_path):
    s = prism_and_stripes(pixels=12)
    save_scene(s, tmp_path / "scene.npz")
    out = tmp_path / "out.exr"
    spec = tmp_path / "spec.exr"
    cmd = [sys.executable, "-m", "opal_diffraction", "render", str(tmp_path / "scene.npz"), "-o", str(out),
           "--spp", "2", "--seed", "3", "--wavelength-step", "10", "--light-paths", "20000", "--spectral-exr", str(spec)]
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert out.exists() and (tmp_path / "out.png").exists()
    rgb = read_exr(out)
    assert rgb["R"].shape == (12, 12) and rgb["G"].max() > 0
    ch = read_exr(spec)
    assert spectral_channel_name(550.0) == "S0.550,000000nm" and "S0.550,000000nm" in ch
    assert len([k for k in ch if k.startswith("S0.")]) == 31
    # the RGB stored with the spectra is the spectra's colour, brought into the Rec.709 gamut where
    # the prism's spectral fringes leave it (film.into_gamut: the luminance kept, no channel negative)
    from opal_diffraction.core.spectral.spectrum import SpectralConverter, WavelengthGrid
    conv = SpectralConverter(WavelengthGrid(400, 700, 10))
    cube = np.stack([ch[spectral_channel_name(w)] for w in conv.grid.wavelengths], axis=-1)
    y709 = np.array([0.2126729, 0.7151522, 0.0721750])  # CIE Y of the linear Rec.709 primaries
    stored = np.stack([ch["R"], ch["G"], ch["B"]], axis=-1).astype(np.float64)
    np.testing.assert_allclose(stored @ y709, conv.to_rgb(cube).astype(np.float64) @ y709, rtol=1e-4, atol=1e-6)
    assert stored.min() >= 0
    np.testing.assert_allclose(ch["G"], rgb["G"], rtol=1e-6)
    # same seed, same image
    again = tmp_path / "again.exr"
    p2 = subprocess.run(cmd[:6] + [str(again)] + cmd[7:-2], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert p2.returncode == 0, p2.stderr
    np.testing.assert_array_equal(read_exr(again)["R"], rgb["R"])


def test_cli_reports_bad_input_without_a_traceback(tmp_path):
    s = prism_and_stripes(pixels=8)
    s.vertices[0, 0] = np.inf
    save_scene(s, tmp_path / "bad.npz")
    p = subprocess.run([sys.executable, "-m", "opal_diffraction", "render", str(tmp_path / "bad.npz"), "-o",
                        str(tmp_path / "o.exr")], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert p.returncode == 2
    assert "error:" in p.stderr and "NaN or infinite" in p.stderr and "Traceback" not in p.stderr


def test_passes_split_direct_light_from_the_world():
    from scenes import glass_in_uniform_world, plane_under_light

    lit = render(plane_under_light({"kind": "POINT", "position": (0, 0, 2), "power": 100.0}, pixels=8),
                 RenderSettings(samples=2))
    np.testing.assert_allclose(lit.passes["Direct"], lit.rgb, rtol=1e-6)
    assert not lit.passes["Caustics"].any() and not lit.passes["Diffraction"].any()
    world = render(glass_in_uniform_world({"kind": "DIELECTRIC", "ior": 1.5}, pixels=8), RenderSettings(samples=2))
    np.testing.assert_allclose(world.passes["Direct"], 0.0, atol=1e-5)
    assert set(lit.passes) == {"Direct", "Indirect", "Caustics", "Diffraction", "Denoising Albedo", "Denoising Normal"}


def test_region_renders_the_same_pixels_as_the_full_image():
    s = prism_and_stripes(pixels=32)
    full = render(s, RenderSettings(light_paths=0, samples=2, seed=4, tile_size=8)).rgb
    part = render(s, RenderSettings(light_paths=0, samples=2, seed=4, tile_size=8), region=(8, 16, 24, 32)).rgb
    assert part.shape == (16, 16, 3)
    # aligned to the tile grid: the same random streams, so exactly the same pixels
    np.testing.assert_array_equal(part, full[16:32, 8:24])
    odd = render(s, RenderSettings(light_paths=0, samples=2, seed=4, tile_size=8), region=(5, 3, 20, 30)).rgb
    assert odd.shape == (27, 15, 3)
    from opal_diffraction.core.scene.checks import SceneError
    with pytest.raises(SceneError, match="outside"):
        render(s, RenderSettings(light_paths=0, samples=1), region=(0, 0, 64, 8))


def test_emissive_surface_is_seen_with_its_radiance():
    from opal_diffraction.core.scene import primitives as prim
    from scenes import top_down_camera
    sc = Scene(materials=Materials.from_list([{"kind": "DIFFUSE", "color": (0, 0, 0), "emission": (2.0, 1.0, 0.5)}]))
    sc.add_mesh(*prim.quad((0, 0, 0), (10, 0, 0), (0, 10, 0)), material=0)
    sc.camera = top_down_camera(1.0, 4)
    res = render(sc, RenderSettings(samples=1))
    np.testing.assert_allclose(res.rgb.reshape(-1, 3), np.tile([2.0, 1.0, 0.5], (16, 1)), rtol=5e-3)
    np.testing.assert_allclose(res.passes["Direct"], 0.0, atol=1e-5)


def test_numpy_bvh_backend_renders_the_same_image_as_embree():
    from opal_diffraction.core.accel import available_backends
    if "embree" not in available_backends():
        pytest.skip("embreex has no wheel on this platform: only the NumPy backend exists here")
    s = prism_and_stripes(pixels=24)
    # the eye pass alone: same random streams, same hits up to float32 rounding at a few edge pixels
    a = render(s, RenderSettings(light_paths=0, samples=2, seed=5, backend="embree")).rgb
    b = render(s, RenderSettings(light_paths=0, samples=2, seed=5, backend="numpy")).rgb
    assert np.isclose(a, b, rtol=1e-3, atol=1e-4).all(axis=2).mean() > 0.97
    # with the light pass: one light path whose choice flips on a rounding difference (a Fresnel or
    # wavelength draw at a CDF boundary) shifts its batch's random stream, so the caustic is
    # another sample of the same estimate: everything else per pixel, the caustic in the mean
    a = render(s, RenderSettings(light_paths=20_000, samples=2, seed=5, backend="embree"))
    b = render(s, RenderSettings(light_paths=20_000, samples=2, seed=5, backend="numpy"))
    rest_a, rest_b = a.rgb - a.passes["Caustics"], b.rgb - b.passes["Caustics"]
    assert np.isclose(rest_a, rest_b, rtol=1e-3, atol=1e-4).all(axis=2).mean() > 0.97
    ca, cb = a.passes["Caustics"].mean(), b.passes["Caustics"].mean()
    assert ca > 0 and abs(ca - cb) < 0.05 * ca
    assert abs(a.rgb.mean() - b.rgb.mean()) < 0.01 * a.rgb.mean()


def test_time_limit_is_honoured_inside_the_light_pass_and_inside_a_round():
    """A 1 s limit with 20 M light paths (about a minute of work) and one huge round: the render
    stops within the limit's latency (the limit is hard: it may end before every pixel has a
    sample, and the per-pixel counts say so), says so, and its image is finite."""
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
                                {"kind": "DIELECTRIC", "ior": 1.5, "color": (1, 1, 1)}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (8, 0, 0), (0, 8, 0)), material=0)
    s.add_mesh(*primitives.box((0, 0, 1.0), (1.0, 1.0, 0.5)), material=1)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (0, 0, 4), "power": 500.0}])
    s.camera = Camera.look_at((0, -5, 3), (0, 0, 0), width=64, height=64)
    render(s, RenderSettings(samples=1, light_paths=1000))  # imports and kernels loaded: the limit counts preparing
    t0 = time.perf_counter()
    res = render(s, RenderSettings(samples=4096, round_samples=4096, light_paths=20_000_000, time_limit=1.0,
                                   threads=2), spectral_film=True)
    took = time.perf_counter() - t0
    assert took < 1.0 + 1.5, took  # the limit, its latency (<= 1 s) and slack for a shared machine
    assert res.stats["light_paths"] < 20_000_000
    assert any("time limit reached during the light pass" in w for w in res.warnings)
    assert any("time limit reached after" in w for w in res.warnings)
    assert res.samples < 4096 and not res.cancelled
    assert np.isfinite(res.spectral).all() and (res.spectral >= 0).all()


def test_cancel_while_preparing_returns_a_cancelled_black_image():
    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE"}]))
    s.add_mesh(*primitives.quad((0, 0, 0), (1, 0, 0), (0, 1, 0)), material=0)
    s.camera = Camera.look_at((0, -2, 2), (0, 0, 0), width=8, height=6)
    res = render(s, RenderSettings(samples=4), should_cancel=lambda: True)
    assert res.cancelled and res.samples == 0 and res.rgb.shape == (6, 8, 3) and not res.rgb.any()
    assert "cancelled while preparing the scene" in res.warnings


def _quad_scene(width=8, height=6):
    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE"}]))
    s.add_mesh(*primitives.quad((0, 0, 0), (1, 0, 0), (0, 1, 0)), material=0)
    s.camera = Camera.look_at((0, -2, 2), (0, 0, 0), width=width, height=height)
    return s


def test_a_time_limit_that_runs_out_while_preparing_says_so_and_renders_nothing():
    res = render(_quad_scene(), RenderSettings(samples=4, time_limit=1e-9))
    assert not res.cancelled and res.samples == 0 and not res.rgb.any()
    assert "time limit (1e-09 s) reached while preparing the scene: nothing rendered" in res.warnings


def test_bad_input_is_named_before_a_time_limit_can_run_out():
    s = _quad_scene()
    s.vertices[0, 0] = np.nan
    with pytest.raises(SceneError):
        render(s, RenderSettings(samples=4, time_limit=1e-9))


@pytest.mark.parametrize("spp, per_round, expected", [(40, 16, (1, 16, 16, 7)), (17, 16, (1, 16)), (1, 16, (1,)),
                                                      (5, 2, (1, 2, 2))])
def test_a_time_limited_render_takes_one_sample_first(spp, per_round, expected):
    """With a time limit the first round holds one sample: the limit can stop the render as soon as
    every pixel has one; without a limit the rounds are unchanged."""
    from opal_diffraction.core.render.prepare import prepare
    from opal_diffraction.core.render.tiles import EyeWork

    s = _quad_scene()
    limited = EyeWork.of(prepare(s, RenderSettings(samples=spp, round_samples=per_round, time_limit=60.0)))
    assert limited.rounds == expected and sum(limited.rounds) == spp
    plain = EyeWork.of(prepare(s, RenderSettings(samples=spp, round_samples=per_round)))
    assert plain.rounds == tuple(min(per_round, spp - k) for k in range(0, spp, per_round))


def test_a_time_limit_stops_a_long_preparation_stage_within_a_poll(monkeypatch):
    """The deadline is enforced by the calling thread too, not only between preparation's stages:
    a ray-caster build that takes 3 s (a stand-in for a 10 M-triangle Embree build) is left
    after the 0.3 s limit within about one cancel.POLL_S, and the render says why."""
    import time

    from opal_diffraction.core.render import prepare as prepare_module

    real_build = prepare_module.build_accelerator

    def slow_build(*args, **kwargs):
        time.sleep(3.0)
        return real_build(*args, **kwargs)

    monkeypatch.setattr(prepare_module, "build_accelerator", slow_build)
    t0 = time.perf_counter()
    res = render(_quad_scene(), RenderSettings(samples=4, time_limit=0.3))
    took = time.perf_counter() - t0
    assert res.samples == 0 and not res.rgb.any()
    assert "time limit (0.3 s) reached while preparing the scene: nothing rendered" in res.warnings
    assert took < 1.5, took


@pytest.mark.parametrize("field, value", [("time_limit", np.array([1.0, 2.0])), ("time_limit", "5"),
                                          ("kernels", np.array(["auto", "numpy"]))])
def test_settings_read_before_validation_are_named_when_bad(field, value):
    """The time limit and the kernels' mode are read before preparation validates the settings
    (the limit counts preparation; the compile stage runs first): a bad value there is still a
    named SceneError (fuzz seed 28: an array time_limit raised numpy's ValueError)."""
    settings = RenderSettings(samples=1)
    object.__setattr__(settings, field, value)  # as the fuzz's mutations do (the dataclass is frozen)
    with pytest.raises(SceneError):
        render(_quad_scene(), settings)
