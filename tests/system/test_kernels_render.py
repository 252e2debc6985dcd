"""Whole renders on the compiled kernels (RenderSettings.kernels 'auto') against the NumPy
reference ('numpy'): the same image within noise, and each path the same bits for any thread count.

Three small scenes between them take every kind of path the kernels serve: flat and smooth
triangles; a point light, an area light and an environment map; a diffuse floor, a rough
(GGX) metal, a rough glass and a dispersive flint prism (whose caustics the light pass carries).

The statistics: each path renders every scene with K independent seeds (seeds differ between the
paths too, so the two sets of images are independent). Per 4 x 4 pixel block and RGB channel the
two sets' means are compared by a two-sample t-test whose variance is pooled from both sets' spread
over their seeds (2K - 2 degrees of freedom; the block means of one render are one draw each, so
the spread over seeds holds every noise: eye pass, light pass, wavelengths). The mean of each
image (per seed, per channel) gets the same test: it has the power to see a small bias
everywhere. The comparisons are counted and the file's false-alarm rate 0.001 is shared between
them (Bonferroni, as tests/chi2.py does): half to the image means, half to the blocks. The test
can fail: the same statistic finds the kernels' images against the reference's made 5 % brighter.
On this base (all kernels bit-identical or within a few ulps) equal seeds give equal images; the
test does not ask for that, since a kernel may sum in another order.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.util import jit

needs_numba = pytest.mark.skipif(not jit.AVAILABLE, reason=f"no JIT: {jit.UNAVAILABLE_REASON}")

PIXELS = 24
BLOCK = 4
SEEDS = 4          # independent renders per path and scene
SPP = 8
ALPHA = 1e-3       # the file's false-alarm rate, shared by all its comparisons (Bonferroni)


def _floor(s: Scene, mat: int = 0) -> None:
    s.add_mesh(*primitives.quad((0, 0, 0), (8, 0, 0), (0, 8, 0)), material=mat)


def _smooth_sphere(s: Scene, centre, radius, mat):
    v, t = primitives.uv_sphere(centre, radius, segments=24, rings=12)
    s.add_mesh(v, t, material=mat, normals=(v - np.asarray(centre, np.float32)) / radius)


def _camera(s: Scene, eye=(0.0, -4.0, 2.2), target=(0.0, 0.0, 0.5)) -> None:
    s.camera = Camera.look_at(eye, target, lens=40.0, width=PIXELS, height=PIXELS)


def flat_point() -> Scene:
    """A diffuse floor and a box (flat triangles) under a point light and a dim uniform world."""
    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE", "color": (0.6, 0.6, 0.6)},
                                             {"kind": "DIFFUSE", "color": (0.8, 0.3, 0.2)}]))
    _floor(s)
    s.add_mesh(*primitives.box((0.0, 0.3, 0.5), (1.0, 1.0, 1.0)), material=1)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (1.5, -2.0, 3.0), "power": 400.0}])
    s.world_color = np.full(3, 0.05, np.float32)
    _camera(s)
    return s


def smooth_area_metal() -> Scene:
    """A smooth rough gold sphere (GGX, roughness 0.3) and a smooth rough glass sphere on a
    diffuse floor, lit by an area light."""
    s = Scene(materials=Materials.from_list([
        {"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
        {"kind": "MIRROR", "color": (0.9, 0.7, 0.3), "roughness": 0.3},
        {"kind": "DIELECTRIC", "ior": 1.5, "roughness": 0.25},
    ]))
    _floor(s)
    _smooth_sphere(s, (-0.7, 0.3, 0.6), 0.6, 1)
    _smooth_sphere(s, (0.8, 0.0, 0.5), 0.5, 2)
    s.lights = Lights.from_list([{"kind": "AREA_RECT", "position": (0.0, -0.5, 3.0), "direction": (0, 0, -1),
                                  "size_u": 1.5, "power": 600.0}])
    _camera(s)
    return s


def sky(width=32, height=16) -> np.ndarray:
    """An equirectangular sky: blue above, grey below, a bright patch (a sun) above the horizon."""
    v = (np.arange(height) + 0.5) / height
    img = np.empty((height, width, 3), np.float32)
    img[:] = np.where(v[:, None] < 0.5, 1.0, 0.3)[..., None] * np.array([0.5, 0.7, 1.0], np.float32)
    img[height // 4, width // 3] = (40.0, 38.0, 30.0)
    return img


def dispersive_glass_env() -> Scene:
    """A dispersive flint prism (IOR 1.72, Abbe 29) and a smooth clear glass sphere on a floor,
    under an environment map and a point light: caustics through the glass (the light pass)."""
    s = Scene(materials=Materials.from_list([
        {"kind": "DIFFUSE", "color": (0.7, 0.7, 0.7)},
        {"kind": "DIELECTRIC", "ior": 1.72, "dispersion": "ABBE", "abbe": 29.0},
        {"kind": "DIELECTRIC", "ior": 1.45},
    ]))
    _floor(s)
    s.add_mesh(*primitives.prism((-0.5, 0.0, 0.6), side=0.9, length=1.4, axis="X", rotation_deg=180.0), material=1)
    _smooth_sphere(s, (0.9, 0.4, 0.45), 0.45, 2)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (0.5, -1.0, 3.5), "power": 500.0}])
    s.world_image = sky()
    s.world_color = np.full(3, 0.2, np.float32)
    _camera(s)
    return s


SCENES = {"flat_point": flat_point, "smooth_area_metal": smooth_area_metal,
          "dispersive_glass_env": dispersive_glass_env}


def settings(seed: int, kernels: str, threads: int = 1) -> RenderSettings:
    return RenderSettings(samples=SPP, threads=threads, seed=seed, light_paths=20_000, tile_size=8,
                          kernels=kernels)


def blocks(img: np.ndarray) -> np.ndarray:
    """(H / BLOCK, W / BLOCK, 3) block means."""
    h, w = img.shape[:2]
    return img.reshape(h // BLOCK, BLOCK, w // BLOCK, BLOCK, 3).mean(axis=(1, 3), dtype=np.float64)


def pooled_t_pvalues(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Two-sided p-values of the pooled-variance two-sample t-test along axis 0 (seeds), each of
    the other cells its own test. Cells where both sets are exactly constant (no noise, e.g. black)
    must be equal: p = 1 if they are, else 0."""
    n, m = len(a), len(b)
    va, vb = a.var(axis=0, ddof=1), b.var(axis=0, ddof=1)
    pooled = ((n - 1) * va + (m - 1) * vb) / (n + m - 2)
    diff = a.mean(axis=0) - b.mean(axis=0)
    se = np.sqrt(pooled * (1.0 / n + 1.0 / m))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(se > 0, diff / np.where(se > 0, se, 1.0), np.where(np.abs(diff) > 0, np.inf, 0.0))
    return 2 * stats.t.sf(np.abs(t), n + m - 2)


@pytest.fixture(scope="module")
def renders():  # ~12 s on an idle 2-core machine (24 renders)
    """{scene: {path: (SEEDS, H, W, 3) images}}; the kernels' seeds 1.., the reference's 101.."""
    out = {}
    for name, build in SCENES.items():
        scene = build()
        out[name] = {
            kernels: np.stack([render(scene, settings(seed0 + k, kernels)).rgb.astype(np.float64)
                               for k in range(SEEDS)])
            for kernels, seed0 in (("auto", 1), ("numpy", 101))
        }
    return out


def comparisons(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The p-values of one scene's tests: (image mean per channel (3,), per block and channel)."""
    means = pooled_t_pvalues(a.mean(axis=(1, 2)), b.mean(axis=(1, 2)))
    per_block = pooled_t_pvalues(np.stack([blocks(x) for x in a]), np.stack([blocks(x) for x in b])).ravel()
    return means, per_block


def verdicts(pairs: dict) -> tuple[bool, str]:
    """(every p-value above its Bonferroni threshold, a summary) over {scene: (a, b)}."""
    p = {name: comparisons(a, b) for name, (a, b) in pairs.items()}
    n_means = sum(len(m) for m, _ in p.values())
    n_blocks = sum(len(b) for _, b in p.values())
    t_means, t_blocks = ALPHA / 2 / n_means, ALPHA / 2 / n_blocks
    ok = all(m.min() > t_means and b.min() > t_blocks for m, b in p.values())
    worst = {name: (float(m.min()), float(b.min())) for name, (m, b) in p.items()}
    return ok, (f"{n_means} image-mean tests (threshold {t_means:.1e}), {n_blocks} block tests (threshold "
                f"{t_blocks:.1e}); smallest p (mean, block) per scene: {worst}")


@needs_numba
def test_kernels_and_reference_render_the_same_images_within_noise(renders):
    for name, r in renders.items():
        assert np.isfinite(r["auto"]).all(), name
        assert r["numpy"].mean() > 0, name  # a scene that shows something
    ok, summary = verdicts({name: (r["auto"], r["numpy"]) for name, r in renders.items()})
    assert ok, summary


def test_the_comparison_can_fail(renders):
    """The kernels' images against the reference's made 5 % brighter in one scene: seen."""
    pairs = {name: (r["auto"], r["numpy"]) for name, r in renders.items()}
    a, b = pairs["dispersive_glass_env"]
    pairs["dispersive_glass_env"] = (a, b * 1.05)
    ok, summary = verdicts(pairs)
    assert not ok, summary


@pytest.mark.parametrize("kernels", ["auto", "numpy"])
def test_the_image_is_the_same_bits_for_one_and_two_threads(kernels):
    if kernels == "auto" and not jit.AVAILABLE:
        pytest.skip(f"no JIT: {jit.UNAVAILABLE_REASON}")
    scene = dispersive_glass_env()
    one = render(scene, settings(7, kernels, threads=1))
    two = render(scene, settings(7, kernels, threads=2))
    assert one.stats["kernels"] == two.stats["kernels"] == ("numba" if kernels == "auto" else "numpy")
    np.testing.assert_array_equal(one.rgb, two.rgb)
