"""Denoising: the feature passes (Cycles' Denoising Albedo and Denoising Normal: the albedo of
a red plane, its normal in Cycles' camera space), Open Image Denoise through pyoidn
(core/render/denoise.py) lowering the error of a low-sample render against a converged one, and the
command line's --denoise (OUT.exr denoised, OUT.noisy.exr the render itself), its readable
error without pyoidn, and its adaptive-sampling flags."""

from __future__ import annotations

import io
import sys
from contextlib import redirect_stderr

import numpy as np
import pytest

from opal_diffraction import cli
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.render.output import read_exr
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.npz import save_scene
from opal_diffraction.core.scene.settings import RenderSettings

from scenes import top_down_camera

RED = (0.8, 0.1, 0.05)


def red_plane(camera: Camera, normal=(0.0, 0.0, 1.0)) -> Scene:
    """A large red diffuse plane through the origin with the given normal, under a sun."""
    n = np.asarray(normal, np.float64) / np.linalg.norm(normal)
    u = np.cross(n, [0.3, 0.5, 0.8])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE", "color": RED}]))
    s.add_mesh(*primitives.quad((0, 0, 0), 60 * u, 60 * v), material=0)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": tuple(-n), "power": 2.0}])
    s.camera = camera
    return s


def rgb_exr(path) -> np.ndarray:
    ch = read_exr(path)
    return np.stack([ch["R"], ch["G"], ch["B"]], axis=-1).astype(np.float64)


def test_the_albedo_pass_holds_the_planes_albedo_and_the_world_none():
    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE", "color": RED}]))
    s.add_mesh(*primitives.quad((-1.5, 0, 0), (3.0, 0, 0), (0, 8.0, 0)), material=0)  # the left half of the view
    s.lights = Lights.from_list([{"kind": "SUN", "direction": (0, 0, -1), "power": 2.0}])
    s.camera = top_down_camera(4.0, 16)  # 4 pixels per metre
    r = render(s, RenderSettings(samples=4, wavelength_step=20.0))
    albedo = r.passes["Denoising Albedo"]
    np.testing.assert_allclose(albedo[:, :6], np.broadcast_to(RED, (16, 6, 3)), rtol=1e-6)
    np.testing.assert_array_equal(albedo[:, 10:], 0.0)  # the world: no diffuse surface
    np.testing.assert_array_equal(r.passes["Denoising Normal"][:, 10:], 0.0)
    np.testing.assert_allclose(r.passes["Denoising Normal"][:, :6], np.broadcast_to((0, 0, -1.0), (16, 6, 3)),
                               atol=1e-6)  # facing the camera: -z in Cycles' camera space


@pytest.mark.parametrize("eye, target, normal", [((0.5, -1.0, 6.0), (0.0, 0.0, 0.0), (0, 0, 1)),
                                                 ((3.0, -4.0, 2.5), (0.2, 0.1, 0.0), (0.2, -0.3, 1.0)),
                                                 ((-2.0, 1.0, 5.0), (0.0, 0.0, 0.0), (-0.5, 0.4, 0.7))])
def test_the_normal_pass_is_the_normal_in_cycles_camera_space(eye, target, normal):
    """Cycles writes the normal in its camera space: x right, y up, z the viewing direction
    (intern/cycles/kernel/film/denoising_passes.h, blender_camera_matrix: Blender's camera
    axes with z flipped), so a plane facing the camera has z < 0. Expected from the view
    itself: forward = target - eye, right = forward x up, up = right x forward."""
    cam = Camera.look_at(eye, target, width=12, height=12, lens=50.0)
    n = np.asarray(normal, np.float64) / np.linalg.norm(normal)
    r = render(red_plane(cam, n), RenderSettings(samples=2, wavelength_step=20.0))
    fwd = np.subtract(target, eye) / np.linalg.norm(np.subtract(target, eye))
    right = np.cross(fwd, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    expected = np.array([n @ right, n @ up, n @ fwd])
    assert expected[2] < 0
    got = r.passes["Denoising Normal"]
    np.testing.assert_allclose(got.reshape(-1, 3), np.broadcast_to(expected, (144, 3)), atol=2e-6)


def noisy_scene(pixels=32) -> Scene:
    """A plane in a uniform world beside a wall (soft, noisy sky occlusion), plus a red and a
    white half so the image has edges for the denoiser to keep."""
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.8, 0.8, 0.8)}, {"kind": "DIFFUSE", "color": RED}])
    s = Scene(materials=mats, world_color=np.array([0.6, 0.6, 0.6], np.float32))
    s.add_mesh(*primitives.quad((-1.0, 0, 0), (2.0, 0, 0), (0, 6.0, 0)), material=1)
    s.add_mesh(*primitives.quad((1.0, 0, 0), (2.0, 0, 0), (0, 6.0, 0)), material=0)
    s.add_mesh(*primitives.box((0.0, 0.0, 0.4), (0.3, 6.0, 0.8)), material=0)
    s.camera = top_down_camera(4.0, pixels)
    return s


NOISY = dict(wavelength_step=20.0, diffuse_bounces=1, tile_size=16)


@pytest.fixture(scope="module")
def converged():
    return render(noisy_scene(), RenderSettings(samples=256, seed=7, **NOISY))


def rmse(a, b) -> float:
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - b) ** 2)))


def test_denoising_lowers_the_error_of_a_low_sample_render(converged):
    pytest.importorskip("pyoidn")
    from opal_diffraction.core.render.denoise import NOISY_PASS, denoise_result

    noisy = render(noisy_scene(), RenderSettings(samples=2, seed=1, **NOISY), spectral_film=True)
    clean = denoise_result(noisy)
    e_noisy, e_clean = rmse(noisy.rgb, converged.rgb), rmse(clean.rgb, converged.rgb)
    print(f"RMSE against 256 spp: 2 spp {e_noisy:.4f}, denoised {e_clean:.4f}")
    assert e_clean < 0.5 * e_noisy
    np.testing.assert_array_equal(clean.passes[NOISY_PASS], noisy.rgb)
    np.testing.assert_array_equal(clean.spectral, noisy.spectral)  # the spectral film is not denoised


def run_main(argv) -> tuple[int, str]:
    err = io.StringIO()
    with redirect_stderr(err):
        code = cli.main(argv)
    return code, err.getvalue()


def test_cli_denoise_writes_the_denoised_and_the_noisy_image(tmp_path, converged):
    pytest.importorskip("pyoidn")
    path = tmp_path / "scene.npz"
    save_scene(noisy_scene(), path)
    args = ["render", str(path), "--spp", "2", "--seed", "1", "--wavelength-step", "20", "--diffuse-bounces", "1",
            "--light-paths", "0", "-q", "--no-preview"]
    code, err = run_main(args + ["-o", str(tmp_path / "out.exr"), "--denoise"])
    assert code == 0, err
    code, err = run_main(args + ["-o", str(tmp_path / "plain.exr")])
    assert code == 0, err
    denoised, noisy = rgb_exr(tmp_path / "out.exr"), rgb_exr(tmp_path / "out.noisy.exr")
    np.testing.assert_array_equal(noisy, rgb_exr(tmp_path / "plain.exr"))  # the noisy image is the render
    e_noisy, e_clean = rmse(noisy, converged.rgb), rmse(denoised, converged.rgb)
    print(f"CLI RMSE against 256 spp: noisy {e_noisy:.4f}, denoised {e_clean:.4f}")
    assert e_clean < 0.5 * e_noisy


def test_cli_denoise_without_pyoidn_is_a_one_line_error_before_rendering(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyoidn", None)  # import pyoidn raises ImportError
    path = tmp_path / "scene.npz"
    save_scene(noisy_scene(8), path)
    code, err = run_main(["render", str(path), "-o", str(tmp_path / "out.exr"), "--denoise", "-q"])
    assert code == 2 and err.startswith("error: ") and len(err.strip().splitlines()) == 1, err
    assert "pyoidn" in err and "requirements-denoise.txt" in err
    assert not list(tmp_path.glob("out*"))


def test_cli_adaptive_flags_reach_the_render(tmp_path):
    path = tmp_path / "scene.npz"
    save_scene(noisy_scene(16), path)
    base = ["render", str(path), "--spp", "64", "--wavelength-step", "20", "--diffuse-bounces", "1",
            "--light-paths", "0", "--no-preview"]
    code, err = run_main(base + ["-o", str(tmp_path / "a.exr"), "--adaptive-threshold", "0.05",
                                 "--adaptive-min-samples", "8"])
    assert code == 0, err
    line = [ln for ln in err.splitlines() if ln.startswith("adaptive sampling:")]
    # rounds of 16 samples (the default): the first check needs both halves (two rounds), so at least 32
    assert line and line[0].startswith("adaptive sampling: 32 to "), err
    assert int(line[0].split()[4]) <= 64
    code, err = run_main(base + ["-o", str(tmp_path / "b.exr"), "--adaptive-threshold", "2"])
    assert code == 2 and err.startswith("error: adaptive threshold") and "between 0 (off) and 1" in err, err


def test_the_denoise_extra_is_the_requirements_pin_and_this_venv_runs_it():
    """pyproject.toml's extra "denoise" and requirements-denoise.txt (what ./setup.sh installs)
    agree, and the venv has exactly those pins."""
    import importlib.metadata as md
    import os
    import tomllib

    from packaging.requirements import Requirement

    from opal_diffraction._scripts import REPO_ROOT

    with open(os.path.join(REPO_ROOT, "pyproject.toml"), "rb") as f:
        (extra,) = [Requirement(r) for r in tomllib.load(f)["project"]["optional-dependencies"]["denoise"]]
    with open(os.path.join(REPO_ROOT, "requirements-denoise.txt")) as f:
        pinned = [Requirement(line.strip()) for line in f if line.strip() and not line.startswith("#")]
    assert (extra.name, str(extra.specifier)) == (pinned[0].name, str(pinned[0].specifier))
    for r in pinned:
        assert str(r.specifier).startswith("=="), r
        assert md.version(r.name) == str(r.specifier)[2:], r.name
