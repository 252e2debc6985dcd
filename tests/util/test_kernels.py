"""The compiled kernels (core/util/jit.py) against their NumPy references, and the switch between them.

Each kernel runs inside the function that holds its NumPy reference; ``kernel_mode('numpy')`` forces
the reference, so every test calls the same public function twice. Where the kernel does the
reference's operations in its order and precisions (Fresnel, the environment lookup, the
Sobol-Burley sampler) the results must be the same bits; the RGB -> spectrum uplift multiplies
by the white illuminant in its table and sums three products itself, so it agrees to a few units
in the last place. Inputs: random rows and the edges (grazing and normal incidence, total
internal reflection, NaN and infinite colours, zero and negative weights, texel seams, empty
batches).
"""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.lights.environment import EnvironmentMap
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.sampling import sampler
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.spectral.optics import fresnel_dielectric
from opal_diffraction.core.spectral.spectrum import SpectralConverter, WavelengthGrid
from opal_diffraction.core.util import jit
from environment_checks import lookups_match

needs_numba = pytest.mark.skipif(not jit.AVAILABLE, reason=f"no JIT: {jit.UNAVAILABLE_REASON}")


def both(fn, *args):
    """(kernel result, NumPy reference result) of fn(*args)."""
    assert jit.kernels_enabled()
    got = fn(*args)
    with jit.kernel_mode("numpy"):
        assert not jit.kernels_enabled()
        want = fn(*args)
    return got, want


def same_bits(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype and a.shape == b.shape
    assert np.array_equal(a.view(np.uint8), b.view(np.uint8)) or np.array_equal(a, b, equal_nan=True)


# ------------------------------------------------------------------------------ the switch
def test_kernel_mode_nests_and_the_reference_wins_while_held():
    if not jit.AVAILABLE:
        assert not jit.kernels_enabled() and jit.kernels_path("auto") == "numpy"
        return
    assert jit.kernels_enabled() and jit.kernels_path("auto") == "numba"
    with jit.kernel_mode("numpy") as outer:
        assert outer == "numpy" and not jit.kernels_enabled()
        with jit.kernel_mode("auto") as inner:  # another render's 'auto' while one forces the reference
            assert inner == "numba" and not jit.kernels_enabled()
        assert not jit.kernels_enabled()
    assert jit.kernels_enabled()


def test_environment_variable_forces_the_reference(monkeypatch):
    monkeypatch.setenv(jit.KERNELS_ENV, "numpy")
    assert not jit.kernels_enabled() and jit.kernels_path("auto") == "numpy"


@needs_numba
def test_a_render_reads_the_environment_variable_when_it_starts(monkeypatch):
    """Inside kernel_mode (a render) kernels_enabled() does not read OPAL_KERNELS per call: a
    block that starts with it set holds the reference, one that started without keeps the kernels."""
    monkeypatch.setenv(jit.KERNELS_ENV, "numpy")
    with jit.kernel_mode("auto") as path:
        assert path == "numpy" and not jit.kernels_enabled()
        monkeypatch.delenv(jit.KERNELS_ENV)
        assert not jit.kernels_enabled()
    assert jit.kernels_enabled()
    with jit.kernel_mode("auto") as path:
        monkeypatch.setenv(jit.KERNELS_ENV, "numpy")
        assert path == "numba" and jit.kernels_enabled()
    assert not jit.kernels_enabled()  # outside a render: read on every call


def test_without_numba_the_reference_runs(monkeypatch):
    monkeypatch.setattr(jit, "AVAILABLE", False)
    assert not jit.kernels_enabled() and jit.kernels_path("auto") == "numpy"
    conv = SpectralConverter()
    rgb = np.array([[0.2, 0.5, 0.9]])
    np.testing.assert_array_equal(conv.reflectance_from_rgb(rgb), np.clip(rgb, 0, 1) @ conv._mallett_basis.T)


def test_cache_folder_is_writable():
    folder = jit.cache_dir()
    assert folder and jit.os.access(folder, jit.os.W_OK)
    if jit.AVAILABLE:
        import numba

        assert numba.config.CACHE_DIR


def test_settings_validate_the_kernels_field():
    RenderSettings(kernels="numpy").validate()
    RenderSettings(kernels="auto").validate()
    for bad in ("fast", "NUMPY", None, 1):
        with pytest.raises(SceneError, match="kernels"):
            RenderSettings(kernels=bad).validate()


def test_a_render_names_its_path_in_the_stats(tiny_scene):
    for mode in ("numpy", "auto"):
        r = render(tiny_scene, RenderSettings(samples=1, light_paths=0, threads=1, kernels=mode))
        assert r.stats["kernels"] == jit.kernels_path(mode)


@pytest.fixture
def tiny_scene():
    from opal_diffraction._scripts import load_example

    return load_example("prism").build_scene(16, 10)


# ------------------------------------------------------------------------------ Fresnel
FRESNEL_CASES = [
    # (cos shape, eta shape, cos dtype, eta dtype): the callers' (B,) x (B,) float32 and (B, 1) x (B, n) float64
    ((4000,), (4000,), np.float32, np.float32),
    ((300, 1), (300, 61), np.float64, np.float64),
    ((50, 1), (61,), np.float32, np.float64),
    ((9,), (9,), np.float64, np.float32),
    ((2, 3, 5), (5,), np.float64, np.float64),
    ((0,), (0,), np.float32, np.float32),
    ((0, 1), (0, 61), np.float64, np.float64),
]


@needs_numba
@pytest.mark.parametrize("cos_shape,eta_shape,cos_dtype,eta_dtype", FRESNEL_CASES)
def test_fresnel_kernel_is_the_reference_bit_for_bit(cos_shape, eta_shape, cos_dtype, eta_dtype):
    rng = np.random.default_rng(7)
    cos = rng.uniform(-1.1, 1.1, cos_shape).astype(cos_dtype)
    eta = rng.uniform(0.3, 2.6, eta_shape).astype(eta_dtype)
    flat = cos.reshape(-1)
    edges = [0.0, 1.0, -1.0, 1e-9, 0.05, np.nan, 1.5, -0.0]  # grazing, normal, beyond 1, NaN
    flat[:min(len(flat), len(edges))] = edges[:len(flat)]
    (got_f, got_cos), (want_f, want_cos) = both(fresnel_dielectric, cos, eta)
    same_bits(got_f, want_f)
    same_bits(got_cos, want_cos)


@needs_numba
def test_fresnel_kernel_at_total_internal_reflection_and_index_matching():
    cos = np.linspace(0.0, 1.0, 1001)
    for eta in (1.0, 1.5, 1 / 1.5, 1 / 2.417, 1.000001):  # eta = n_t / n_i < 1 from inside glass: TIR
        (got, got_cos), (want, want_cos) = both(fresnel_dielectric, cos, np.full_like(cos, eta))
        same_bits(got, want)
        same_bits(got_cos, want_cos)
        if eta < 1:  # below the critical cosine sqrt(1 - eta^2)
            assert (got[cos < np.sqrt(1 - eta**2) - 1e-9] == 1).all()


def test_fresnel_scalars_take_the_reference():
    assert fresnel_dielectric(np.float64(1.0), 1.5)[0] == pytest.approx(0.04, abs=1e-12)
    assert float(fresnel_dielectric(0.0, 1.5)[0]) == 1.0


# ------------------------------------------------------------------------------ RGB -> spectrum
@needs_numba
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("method", ["reflectance_from_rgb", "illuminant_from_rgb"])
@pytest.mark.parametrize("grid", [WavelengthGrid(), WavelengthGrid(380, 780, 10), WavelengthGrid(400, 700, 1)])
def test_uplift_kernel_matches_the_reference(dtype, method, grid):
    conv = SpectralConverter(grid)
    rng = np.random.default_rng(3)
    rgb = rng.uniform(-0.5, 4.0, (3000, 3)).astype(dtype)
    rgb[:8] = [[0, 0, 0], [1, 1, 1], [-1, -2, -3], [np.nan, 0.5, 0.2], [0.2, np.nan, 5], [np.inf, 1, 0],
               [1e-30, 0, 0], [1e30, 1e30, 1]]
    with np.errstate(invalid="ignore"):
        got, want = both(getattr(conv, method), rgb)
    assert got.dtype == want.dtype == np.float64 and got.shape == want.shape == (3000, grid.n)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    fin = np.isfinite(want)
    np.testing.assert_allclose(got[fin], want[fin], rtol=4e-15, atol=1e-300)
    if method == "illuminant_from_rgb":  # white light stays RGB (1, 1, 1) on the kernels too
        np.testing.assert_allclose(conv.to_rgb(conv.illuminant_from_rgb(np.ones(3))), 1.0, atol=1e-6)


@needs_numba
@pytest.mark.parametrize("shape", [(3,), (1, 3), (0, 3), (2, 4, 3)])
def test_uplift_kernel_keeps_the_leading_shape(shape):
    conv = SpectralConverter()
    rgb = np.random.default_rng(0).uniform(0, 2, shape)
    for method in ("reflectance_from_rgb", "illuminant_from_rgb"):
        got, want = both(getattr(conv, method), rgb)
        assert got.shape == want.shape == shape[:-1] + (conv.grid.n,)
        np.testing.assert_allclose(got, want, rtol=4e-15, atol=0)
    got, want = both(conv.illuminant_from_rgb, [[0.5, 0.25, 1]])  # a list, as lights and materials pass
    np.testing.assert_allclose(got, want, rtol=4e-15)


# ------------------------------------------------------------------------------ environment lookup
@needs_numba
@pytest.mark.parametrize("interpolation", ["LINEAR", "CLOSEST"])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("size", [(1, 1), (3, 5), (64, 128)])
def test_environment_lookup_kernel_is_the_reference_bit_for_bit(interpolation, dtype, size):
    rng = np.random.default_rng(11)
    env = EnvironmentMap(rng.uniform(0, 5, size + (3,)).astype(np.float32), interpolation=interpolation)
    u = rng.uniform(-0.2, 1.2, 5000).astype(dtype)
    v = rng.uniform(-0.1, 1.1, 5000).astype(dtype)
    u[:6], v[:6] = [0, 1, 0.5, 1 - 1e-7, 0.25, 0], [0, 1, 0.5, 1, 1 - 1e-7, 0.5]  # seams and poles
    same_bits(*both(env._lookup, u, v))
    d = rng.normal(size=(3000, 3)).astype(dtype)
    d[:3] = [[0, 0, 1], [0, 0, -1], [-1, 0, 0]]  # straight up, down, along the seam
    if dtype == np.float32:  # the angles may differ by an ulp (tests/lights/test_environment_kernels.py)
        lookups_match(env, d)
    else:
        same_bits(*both(env.radiance_rgb, d))
    for got, want in zip(*both(env.sample, rng.random(2000), rng.random(2000))):
        same_bits(got, want)
    same_bits(*both(env._lookup, np.zeros(0, dtype), np.zeros(0, dtype)))


# ------------------------------------------------------------------------------ sampler
@needs_numba
@pytest.mark.parametrize("seed", [0, 3, 2**32 + 5, 2**64 - 1])
def test_sampler_kernel_is_the_reference_bit_for_bit(seed):
    rng = np.random.default_rng(seed % 1000)
    n = 20000
    pixel = rng.integers(0, 1 << 22, n)
    for sample in (rng.integers(0, 1 << 34, n), rng.integers(0, 1 << 32, n).astype(np.uint32)):
        for pair in (rng.integers(0, 400, n), 7):
            for fn in (sampler.sobol_owen_2d, sampler.sobol_owen_x):
                got, want = both(fn, pixel, sample, pair, seed)
                for g, w in zip(np.atleast_2d(got), np.atleast_2d(want)):
                    same_bits(g, w)


@needs_numba
def test_sampler_kernel_on_empty_and_odd_batches():
    for fn in (sampler.sobol_owen_2d, sampler.sobol_owen_x):
        got, want = both(fn, np.zeros(0, np.int64), np.zeros(0, np.int64), 0, 1)
        for g, w in zip(np.atleast_2d(got), np.atleast_2d(want)):
            same_bits(g, w)
    # a 2-D batch takes the reference (the kernel is for (B,) rows)
    got, want = both(sampler.sobol_owen_2d, np.arange(6).reshape(2, 3), np.arange(6).reshape(2, 3), 1, 2)
    same_bits(got[0], want[0])
    # the points stay a stratified (0, 2)-net on the kernels: 16 samples, one per 4 x 4 cell
    x, y = sampler.sobol_owen_2d(np.zeros(16, np.int64), np.arange(16), 3, 9)
    cells = np.floor(x * 4).astype(int) * 4 + np.floor(y * 4).astype(int)
    assert sorted(cells) == list(range(16))


# ------------------------------------------------------------------------------ illumination map
@needs_numba
@pytest.mark.parametrize("map_dtype", [np.float32, np.float64])
@pytest.mark.parametrize("flux_dtype", [np.float32, np.float64])
def test_illumination_deposit_kernel_is_the_reference_bit_for_bit(map_dtype, flux_dtype):
    """Runs of every length NumPy's pairwise sum treats apart (1, < 8, 8-128, > 128, recursive);
    a float64 map shows the summation order itself, unrounded."""
    from opal_diffraction.core.transport.elements import ElementLayout, IlluminationMap

    rng = np.random.default_rng(5)
    layout = ElementLayout.from_areas(np.ones(20), np.ones(20, bool), 0.01)
    for rows in (0, 1, 9, 200, 3000):
        elements = rng.integers(0, layout.total, rows)
        elements[: rows // 2] = 17  # one long run (pairwise halves above 128 rows)
        elements[rows // 2: rows // 2 + min(rows // 4, 130)] = 3
        flux = rng.exponential(1.0, (rows, 31)).astype(flux_dtype)
        flux[::7] = 0.0  # zero weights
        start = rng.random((layout.total, 31)).astype(map_dtype)
        got, want = IlluminationMap(layout, start.copy()), IlluminationMap(layout, start.copy())
        got.deposit(elements, flux)
        with jit.kernel_mode("numpy"):
            want.deposit(elements, flux)
        same_bits(got.flux, want.flux)


@needs_numba
def test_row_sums_kernel_on_sorted_and_unsorted_rows():
    """add_row_sums as a film takes per-ray spectra (rows already in pixel order skip the sort)."""
    from opal_diffraction.core.util.row_sums import add_row_sums

    rng = np.random.default_rng(9)
    for rows in (np.sort(rng.integers(0, 50, 4000)), rng.integers(0, 50, 4000), np.zeros(1, np.int64)):
        values = rng.normal(size=(len(rows), 13)).astype(np.float32)
        got, want = np.zeros((50, 13), np.float32), np.zeros((50, 13), np.float32)
        add_row_sums(got, rows, values)
        with jit.kernel_mode("numpy"):
            add_row_sums(want, rows, values)
        same_bits(got, want)
        plain = np.zeros((50, 13))
        np.add.at(plain, rows, values.astype(np.float64))
        np.testing.assert_allclose(got, plain, rtol=1e-4, atol=1e-4)


# ------------------------------------------------------------------------------ GGX
def _upper_dirs(rng, rows):
    v = rng.normal(size=(rows, 3))
    v[:, 2] = np.abs(v[:, 2])
    return (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)


@needs_numba
def test_ggx_reflection_kernel_is_the_reference_bit_for_bit():
    from opal_diffraction.core.materials.ggx import reflection_terms

    rng = np.random.default_rng(13)
    rows = 20000
    wo, wi = _upper_dirs(rng, rows), _upper_dirs(rng, rows)
    alpha = rng.uniform(1e-4, 1.0, rows).astype(np.float32)
    wo[0], wi[0] = [0, 0, 1], [0, 0, 1]               # normal incidence
    wo[1], wi[1] = [1, 0, 0], [-1, 0, 0]              # grazing both ways: h = 0, mu_o = 0
    wo[2], wi[2] = [0.99995, 0, 0.01], [0.99995, 0, 0.01]  # grazing mirror pair
    wi[3] = -wo[3]                                    # opposite directions
    alpha[4] = 0.0
    with np.errstate(all="ignore"):
        got, want = both(reflection_terms, alpha, wo, wi)
    for g, w in zip(got, want):
        same_bits(g, w)
    with np.errstate(all="ignore"):
        for g, w in zip(*both(reflection_terms, alpha[:0], wo[:0], wi[:0])):
            same_bits(g, w)


@needs_numba
def test_ggx_evaluate_on_the_kernels_matches_the_reference():
    """bsdf.evaluate of rough conductors, glossy, glass and plastic (their reflection terms on the kernel)."""
    from opal_diffraction.core.materials import bsdf

    rng = np.random.default_rng(21)
    rows = 3000
    for lobe in (bsdf.CONDUCTOR, bsdf.GLOSSY, bsdf.DIELECTRIC, bsdf.PLASTIC):
        f32 = np.float32
        params = bsdf.SurfaceParams(
            lobe=np.full(rows, lobe), base=rng.uniform(0.05, 1, (rows, 4)).astype(f32),
            edge=np.ones((rows, 4), f32), alpha=rng.uniform(0.02, 1, rows).astype(f32),
            eta=np.full(rows, 1.5 if lobe == bsdf.DIELECTRIC else 1.0, f32),
            spec_f0=np.full(rows, 0.04 if lobe == bsdf.PLASTIC else 0.0, f32), spec_tint=np.ones((rows, 4), f32))
        ns = np.tile(np.array([0, 0, 1], f32), (rows, 1))
        wo, wi = _upper_dirs(rng, rows), _upper_dirs(rng, rows)
        with np.errstate(all="ignore"):
            (fg, pg), (fw, pw) = both(bsdf.evaluate, params, wo, wi, ns, ns)
        same_bits(fg, fw)
        same_bits(pg, pw)
        assert (fg > 0).any()
