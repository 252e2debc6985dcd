"""Fresnel, Snell and dispersion against closed forms and the table of docs/physics.md
section 2.1."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from opal_diffraction.core.spectral.optics import (
    cauchy_from_abbe, fresnel_dielectric, ior_spectrum, reflect, refract, sellmeier_ior, LAMBDA_C, LAMBDA_D, LAMBDA_F,
)


@pytest.mark.parametrize("n", [1.33, 1.5, 2.42])
def test_fresnel_normal_incidence(n):
    """eta = n_t / n_i: n entering the medium from air, 1 / n leaving it; cos_t = 1 both ways."""
    expected = ((n - 1) / (n + 1)) ** 2
    f, cos_t = fresnel_dielectric(np.array(1.0), np.array(n))
    assert f == pytest.approx(expected, rel=1e-12) and cos_t == 1.0
    # same from inside the medium
    f, cos_t = fresnel_dielectric(np.array(1.0), np.array(1 / n))
    assert f == pytest.approx(expected, rel=1e-12) and cos_t == 1.0


@pytest.mark.parametrize("n", [1.33, 1.5, 2.42])
def test_fresnel_at_brewster_angle_is_half_the_s_reflectance(n):
    """At Brewster's angle r_p = 0, so unpolarised R = R_s / 2 with R_s = cos^2(2 theta_B)."""
    theta_b = np.arctan(n)
    theta_t = np.pi / 2 - theta_b
    rs = (np.sin(theta_b - theta_t) / np.sin(theta_b + theta_t)) ** 2
    r, cos_t = fresnel_dielectric(np.cos(theta_b), np.array(n))
    assert r == pytest.approx(rs / 2, rel=1e-9)
    assert cos_t == pytest.approx(np.cos(theta_t), rel=1e-12)
    # and it is a minimum of R_p: the p part is zero there, so R is below R at nearby angles' s/2 only
    assert rs == pytest.approx(np.cos(2 * theta_b) ** 2, rel=1e-9)


def test_total_internal_reflection_beyond_critical_angle():
    n = 1.5
    crit = np.arcsin(1 / n)
    cos_in = np.cos(np.array([crit - 1e-3, crit + 1e-3]))
    r, cos_t = fresnel_dielectric(cos_in, np.array(1 / n))
    assert r[0] < 1 and r[1] == 1.0 and cos_t[0] > 0 and cos_t[1] == 0.0
    d = np.array([[np.sin(crit + 0.01), 0, -np.cos(crit + 0.01)]])
    t, tir = refract(d, np.array([[0.0, 0, 1]]), np.array([n]))
    assert tir[0] and np.allclose(t, reflect(d, np.array([[0.0, 0, 1]])))


@settings(max_examples=200, deadline=None)
@given(theta=st.floats(0, 1.5), n1=st.floats(1.0, 2.5), n2=st.floats(1.0, 2.5), phi=st.floats(0, 6.28))
def test_snell_vector_form(theta, n1, n2, phi):
    d = np.array([[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), -np.cos(theta)]])
    nrm = np.array([[0.0, 0.0, 1.0]])
    t, tir = refract(d, nrm, np.array([n1 / n2]))
    assert np.linalg.norm(t) == pytest.approx(1.0, abs=1e-9)
    if not tir[0]:
        sin_t = np.hypot(t[0, 0], t[0, 1])
        assert n1 * np.sin(theta) == pytest.approx(n2 * sin_t, abs=1e-9)
        assert t[0, 2] < 0  # continues into the second medium
        # plane of incidence preserved
        assert abs(np.cross(d[0], nrm[0]) @ t[0]) < 1e-9


TABLE = {  # docs/physics.md section 2.1: n_d, V_d, n(400), n(550), n(700)
    "BK7": (1.51680, 64.17, 1.53085, 1.51852, 1.51306),
    "FUSED_SILICA": (1.45846, 67.82, 1.47012, 1.45991, 1.45529),
    "DIAMOND": (2.41749, 55.3, 2.46413, 2.42295, 2.40624),
}


@pytest.mark.parametrize("name", sorted(TABLE))
def test_sellmeier_presets_match_the_table(name):
    n_d, v_d, n400, n550, n700 = TABLE[name]
    n = ior_spectrum(np.array([LAMBDA_D, 400, 550, 700]), name)
    np.testing.assert_allclose(n, [n_d, n400, n550, n700], atol=6e-5)
    nf, nc = ior_spectrum(np.array([LAMBDA_F, LAMBDA_C]), name)
    assert (n_d - 1) / (nf - nc) == pytest.approx(v_d, rel=5e-3)


@pytest.mark.parametrize("n_d,v_d", [(1.5168, 64.17), (1.72, 29.0), (2.417, 55.3)])
def test_cauchy_from_abbe_reproduces_n_d_and_abbe_number(n_d, v_d):
    a, b = cauchy_from_abbe(n_d, v_d)
    n = lambda lam: a + b / lam**2  # noqa: E731
    assert n(LAMBDA_D) == pytest.approx(n_d, rel=1e-12)
    assert (n(LAMBDA_D) - 1) / (n(LAMBDA_F) - n(LAMBDA_C)) == pytest.approx(v_d, rel=1e-9)
    np.testing.assert_allclose(ior_spectrum(np.array([450.0]), "ABBE", n_d, v_d), n(450.0))


def test_snell_per_wavelength_with_sellmeier():
    """Each wavelength refracts by its own index: n(lambda) sin(theta_t) = sin(theta_i)."""
    wl = np.arange(400, 701, 5.0)
    n = sellmeier_ior(wl, (1.03961212, 0.231792344, 1.01046945), (0.00600069867, 0.0200179144, 103.560653))
    theta = np.radians(50.0)
    d = np.tile([np.sin(theta), 0.0, -np.cos(theta)], (len(wl), 1))
    t, tir = refract(d, np.tile([0.0, 0, 1], (len(wl), 1)), 1 / n)
    assert not tir.any()
    np.testing.assert_allclose(n * t[:, 0], np.sin(theta), rtol=1e-12)
    assert np.all(np.diff(t[:, 0]) > 0)  # blue bends most


def test_unknown_model_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown dispersion model"):
        ior_spectrum(np.array([500.0]), "UNOBTAINIUM")
    with pytest.raises(ValueError, match="Abbe"):
        cauchy_from_abbe(1.5, 0)
