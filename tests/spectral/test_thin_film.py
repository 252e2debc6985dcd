"""Thin-film interference (core/spectral/thin_film.py) against an independent characteristic-matrix
computation (tests/thin_film_matrix.py: Born & Wolf section 1.6; Macleod ch. 2):
reflectance per wavelength for 3 thicknesses x 3 angles over dielectric and metal substrates,
R + T = 1 for lossless films from the matrix's transmittance, d = 0 gives the plain Fresnel."""

import math

import numpy as np
import pytest

from opal_diffraction.core.spectral.optics import fresnel_dielectric
from thin_film_matrix import matrix_unpolarised
from opal_diffraction.core.spectral.thin_film import (airy_reflectance, conductor_ior_from_f0_f82,
                                                      thin_film_conductor, thin_film_dielectric)

WAVELENGTHS = np.arange(380.0, 781.0, 10.0)
THICKNESSES = (80.0, 310.0, 1200.0)
ANGLES_DEG = (0.0, 40.0, 75.0)


def _check_against_matrix(n0, n_film, n_sub_of_wl, code):
    for d in THICKNESSES:
        for a in ANGLES_DEG:
            th = math.radians(a)
            ours = code(math.cos(th), d, WAVELENGTHS)
            ref = np.array([matrix_unpolarised(n0, n_film, d, n_sub_of_wl(wl), th, wl)[0] for wl in WAVELENGTHS])
            np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-10, err_msg=f"d={d} nm, angle={a}")
            # the film's interference must show: the spectrum is not flat
            assert np.ptp(ref) > 1e-3 or d < 100 or ref.min() > 1 - 1e-12  # (total internal reflection)


def test_dielectric_substrate_dispersive_against_characteristic_matrix():
    """Water film (1.33) on a dispersive glass (Cauchy 1.5 + 4200 / lambda^2) in air."""
    sub = lambda wl: 1.5 + 4200.0 / wl ** 2  # noqa: E731
    _check_against_matrix(1.0, 1.33, sub, lambda c, d, wl: airy_reflectance(c, 1.0, 1.33, sub(wl), d, wl))


def test_dielectric_function_float64_matches_matrix_and_high_index_film():
    """thin_film_dielectric itself (the walker's call), in float64: a TiO2-like film 2.4 on 1.52."""
    _check_against_matrix(1.0, 2.4, lambda wl: 1.52,
                          lambda c, d, wl: thin_film_dielectric(np.full(wl.shape, c), np.full(wl.shape, 1.52), 2.4, d,
                                                                wl)[0])


def test_from_inside_glass_against_characteristic_matrix():
    """Glass (1.5) -> film (1.38, MgF2) -> air: incidence from the dense side, past the film's
    and the air's critical angles at 75 degrees (frustrated total internal reflection)."""
    _check_against_matrix(1.5, 1.38, lambda wl: 1.0,
                          lambda c, d, wl: thin_film_dielectric(np.full(wl.shape, c), np.full(wl.shape, 1 / 1.5),
                                                                1.38, d, wl, n_i=1.5)[0])


def test_metal_substrate_against_characteristic_matrix():
    """A film (1.45) over gold-like n + ik (dispersive) and over a conductor from F0 / F82."""
    gold = lambda wl: (0.2 + 1.3 * (500 / wl) ** 4) + 1j * (1.8 + 3.0 * (wl - 380) / 400)  # noqa: E731
    _check_against_matrix(1.0, 1.45, gold, lambda c, d, wl: thin_film_conductor(
        c, gold(wl).real, gold(wl).imag, 1.45, d, wl))
    n, k = conductor_ior_from_f0_f82(0.7, 0.8)
    _check_against_matrix(1.0, 1.45, lambda wl: complex(n, k),
                          lambda c, d, wl: thin_film_conductor(c, n, k, 1.45, d, wl))


def test_lossless_energy_conservation():
    """R (ours) + T (the matrix's transmitted power, computed independently) = 1 without absorption."""
    for n0, nf, ns in ((1.0, 1.33, 1.0), (1.0, 1.33, 1.7), (1.6, 1.2, 1.0)):
        for d in THICKNESSES:
            for a in (0.0, 30.0, 60.0):
                th = math.radians(a)
                for wl in (400.0, 555.0, 700.0):
                    _, t = matrix_unpolarised(n0, nf, d, ns, th, wl)
                    r = float(airy_reflectance(math.cos(th), n0, nf, ns, d, wl))
                    if n0 * math.sin(th) >= ns:  # total internal reflection: nothing goes through
                        assert r == pytest.approx(1.0, abs=1e-12)
                    else:
                        assert r + t == pytest.approx(1.0, abs=1e-12)


def test_zero_thickness_is_plain_fresnel():
    cos = np.linspace(0.0, 1.0, 101)
    for eta in (1.5, 1.0 / 1.5, 2.4):
        f_plain, ct_plain = fresnel_dielectric(cos, np.full(cos.shape, eta))
        f, ct = thin_film_dielectric(cos, np.full(cos.shape, eta), 1.33, 0.0, 550.0, n_i=1.0 if eta > 1 else 1.5)
        np.testing.assert_allclose(f, f_plain, rtol=0, atol=1e-12)
        np.testing.assert_allclose(ct, ct_plain, rtol=0, atol=1e-12)
    # a film of the substrate's own index or of the incident medium's is no film at any thickness
    f_plain = fresnel_dielectric(cos, np.full(cos.shape, 1.5))[0]
    for nf in (1.0, 1.5):
        np.testing.assert_allclose(airy_reflectance(cos, 1.0, nf, 1.5, 437.0, 600.0), f_plain, atol=1e-12)


def test_conductor_mapping_reproduces_f0():
    """Gulbrandsen's (n, k) reflect F0 at normal incidence: ((n-1)^2 + k^2) / ((n+1)^2 + k^2)."""
    f0 = np.array([0.05, 0.3, 0.6, 0.95])
    for g in (0.2, 0.9):
        n, k = conductor_ior_from_f0_f82(f0, g)
        np.testing.assert_allclose(((n - 1) ** 2 + k ** 2) / ((n + 1) ** 2 + k ** 2), f0, rtol=1e-12)
        np.testing.assert_allclose(thin_film_conductor(1.0, n, k, 1.4, 0.0, 500.0), f0, rtol=1e-12)


def test_float32_in_float32_out_and_tir():
    cos = np.array([0.1, 0.5, 0.9], np.float32)
    f, ct = thin_film_dielectric(cos, np.full(3, 1 / 1.5, np.float32), 1.33, 250.0, 500.0, n_i=1.5)
    assert f.dtype == np.float32 and ct.dtype == np.float32
    assert f[0] == 1.0 and ct[0] == 0.0  # past the critical angle of glass -> air
    assert np.all((f >= 0) & (f <= 1))


def test_compiled_kernel_matches_the_numpy_reference():
    """_airy_kernel (kernels on) against the NumPy lines (kernels off): random films over glass
    from both sides (total internal reflection included), over metals, grazing and normal."""
    from opal_diffraction.core.util.jit import AVAILABLE, kernel_mode

    if not AVAILABLE:
        pytest.skip("numba is not available: only the reference runs")
    rng = np.random.default_rng(7)
    m = 4000
    cos = np.concatenate([rng.random(m - 4), [0.0, 1.0, 0.0, 1.0]])
    n_i = rng.choice([1.0, 1.5, 2.4], m)
    n_f = 1.0 + 1.5 * rng.random(m)
    n_t = np.where(rng.random(m) < 0.5, 1.0 + rng.random(m), (0.2 + 3 * rng.random(m)) + 1j * 4 * rng.random(m))
    d = np.where(rng.random(m) < 0.1, 0.0, 2000 * rng.random(m))
    wl = 380 + 400 * rng.random(m)
    with kernel_mode("numpy"):
        ref = airy_reflectance(cos, n_i, n_f, n_t, d, wl)
    with kernel_mode("auto"):
        got = airy_reflectance(cos, n_i, n_f, n_t, d, wl)
        grid = airy_reflectance(0.7, 1.0, 1.33, np.array([1.5, 1.6])[:, None], 300.0, np.array([400.0, 500.0, 600.0]))
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)
    assert grid.shape == (2, 3)
    with kernel_mode("numpy"):
        np.testing.assert_allclose(grid, airy_reflectance(0.7, 1.0, 1.33, np.array([1.5, 1.6])[:, None], 300.0,
                                                          np.array([400.0, 500.0, 600.0])), atol=1e-12)
