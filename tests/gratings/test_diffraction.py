"""The Fraunhofer grating kernel against independent numbers (docs/physics.md section 3)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from opal_diffraction.core.gratings.kernel import (
    fraunhofer_pattern, fraunhofer_pattern_binned, grating_radiance_factor, multislit, multislit_integral,
    multislit_mean, sinc2, sinc2_integral, sinc2_mean,
)

#: NumPy 2 renamed np.trapz to np.trapezoid (the same trapezoidal rule); NumPy 1.24-1.26 (Blender 4.2-5.0) has only trapz
_trapezoid = getattr(np, "trapezoid", None) or np.trapz


def phasor_sum(eta, n):
    """|sum_k exp(2 i k eta)|^2 / N^2: N slits, phase step 2 pi D u / lambda = 2 eta."""
    k = np.arange(n)[None, :]
    return np.abs(np.exp(2j * k * np.asarray(eta)[:, None]).sum(axis=1)) ** 2 / n**2


@pytest.mark.parametrize("n", [1, 2, 7, 50, 1000])
def test_kernel_equals_brute_force_phasor_sum(n):
    eta = np.random.default_rng(n).uniform(-20, 20, 500)
    eta = np.concatenate([eta, np.pi * np.arange(-5, 6), np.pi * np.arange(-5, 6) + 1e-9])
    np.testing.assert_allclose(multislit(eta, n), phasor_sum(eta, n), atol=1e-9)


def test_principal_maxima_are_exactly_one():
    m = np.arange(-50, 51)
    assert np.allclose(multislit(np.pi * m, 50), 1.0)  # the naive ratio gives 0.0104 here
    eta32 = (np.pi * m).astype(np.float32)  # float32 input: eta is m pi to 7 digits only
    assert multislit(eta32, 6000).min() > 0.99  # the naive float32 ratio gives 0.752
    assert multislit(np.array([np.pi * 1e5]), 10**6)[0] == pytest.approx(1.0)


def test_grating_equation_cd_and_dvd():
    """Peaks at u = m lambda / D; normal incidence u = sin(theta_o). Principal maxima only
    (threshold 0.2: the side lobes of N = 2000 slits stay below 0.05 of the envelope)."""
    theta = np.radians(np.linspace(-1, 89.999, 2_000_001))

    def peaks(d, a, lam=550.0, n=2000):
        p = fraunhofer_pattern(np.sin(theta), 0 * theta, lam, a, d, n, 1e4)
        idx = np.flatnonzero((p[1:-1] > p[:-2]) & (p[1:-1] >= p[2:]) & (p[1:-1] > 0.2)) + 1
        return np.degrees(theta[idx])

    np.testing.assert_allclose(peaks(1600.0, 400.0), [0.0, 20.11, 43.43], atol=0.01)  # m = 3: 3*550/1600 > 1
    np.testing.assert_allclose(peaks(1600.0, 800.0), [0.0, 20.11], atol=0.01)  # a = D/2: m = 2 missing
    np.testing.assert_allclose(peaks(740.0, 300.0), [0.0, 48.0], atol=0.02)  # DVD


def test_half_width_slits_missing_order_and_heights():
    d, lam, n = 1600.0, 550.0, 100
    u = np.arange(4) * lam / d
    p = fraunhofer_pattern(u, 0 * u, lam, d / 2, d, n, 1e5)
    np.testing.assert_allclose(p, [1.0, 4 / np.pi**2, 0.0, 4 / (9 * np.pi**2)], atol=1e-12)
    np.testing.assert_allclose(p[[1, 3]], [0.4053, 0.0450], atol=5e-5)
    # missing orders for every integer D/a: a = D/3 -> m = 3, 6 vanish
    u3 = np.array([3, 6]) * lam / d
    assert np.all(fraunhofer_pattern(u3, 0 * u3, lam, d / 3, d, n, 1e5) < 1e-20)


@pytest.mark.parametrize("n", [1, 2, 7, 50, 1000])
def test_mean_over_a_period_is_one_over_n_and_first_zero(n):
    assert multislit_mean(0.3, 0.3 + np.pi, n) == pytest.approx(1.0 / n, rel=1e-9)
    # first zero at delta eta = pi / N, i.e. delta u = lambda / (N D)
    if n > 1:
        assert multislit(np.pi / n, n) < 1e-25
        assert multislit(0.5 * np.pi / n, n) > 0.3


@pytest.mark.parametrize("n", [1, 2, 7, 50, 64, 65, 1000, 10**5])
def test_closed_form_integral_matches_quadrature(n):
    """C(eta1) - C(eta0) against a fine trapezoid rule, exact and asymptotic branches alike."""
    rng = np.random.default_rng(n)
    for _ in range(5):
        e0 = rng.uniform(-4, 4)
        w = rng.choice([0.5 / n, 3.0 / n, 0.05, 1.0])
        x = np.linspace(e0, e0 + w, 400_001)
        f = multislit(x, n)
        quad = _trapezoid(f, x) / w
        assert multislit_mean(e0, e0 + w, n) == pytest.approx(quad, abs=2e-5)
    # odd, with period-mean N
    assert multislit_integral(np.pi, n) == pytest.approx(n * np.pi, rel=1e-6)
    assert multislit_integral(-0.7, n) == pytest.approx(-multislit_integral(0.7, n), rel=1e-9)


def test_sinc2_integral():
    x = np.linspace(-30, 30, 600_001)
    cum = np.concatenate([[0], np.cumsum(0.5 * (sinc2(x[1:]) + sinc2(x[:-1])) * np.diff(x))])
    cum -= cum[300_000]
    np.testing.assert_allclose(sinc2_integral(x[::1000]), cum[::1000], atol=1e-8)
    assert sinc2_integral(1e6) == pytest.approx(np.pi / 2, abs=1e-5)
    assert sinc2_mean(-1e-9, 1e-9) == pytest.approx(1.0)


@pytest.mark.parametrize("n", [1, 2, 7, 50, pytest.param(1000, marks=pytest.mark.slow),
                               pytest.param(10**5, marks=pytest.mark.slow)])
def test_bin_averaged_kernel_matches_fine_quadrature(n):
    """The renderer's per-bin value equals the pattern's mean over the bin's wavelengths."""
    d, a, length = 1600.0, 700.0, 2e4  # nm; L = 20 um
    edges = np.arange(400.0, 701.0, 5.0)
    rng = np.random.default_rng(n)
    # u near the first and second orders and random, v in and slightly out of the plane
    u = np.concatenate([rng.uniform(0.25, 0.44, 6), rng.uniform(0.5, 0.88, 4), rng.uniform(-1, 1, 4), [0.0]])
    v = np.concatenate([np.zeros(8), rng.uniform(-0.02, 0.02, 7)])
    got = fraunhofer_pattern_binned(u, v, edges, a, d, n, length)
    for k in range(0, len(edges) - 1, 3):
        lam = np.linspace(edges[k], edges[k + 1], 200_001 if n >= 1000 else 20_001)
        p = fraunhofer_pattern(u[:, None], v[:, None], lam[None, :], a, d, n, length)
        ref = _trapezoid(p, lam, axis=1) / (edges[k + 1] - edges[k])
        np.testing.assert_allclose(got[:, k], ref, atol=1e-3)


def test_energy_transmission_grating_normal_incidence():
    """Hemispherical integral of L_o cos(theta_o) = (a / D) E over the propagating orders.

    With w_i along the normal, u and v are the exit direction cosines and
    d(omega) cos(theta) = du dv, so the integral is E * factor * cos(theta) * iint_disk P du dv.
    Cells in u use the exact cell mean of the N-slit factor; v integrates in closed form.
    """
    lam, d, a, n, length = 550e-9, 50e-6, 25e-6, 200, 1e-3  # metres
    edges = np.linspace(-1, 1, 400_001)
    uc = 0.5 * (edges[1:] + edges[:-1])
    du = np.diff(edges)
    ms = multislit_mean(np.pi * d * edges[:-1] / lam, np.pi * d * edges[1:] / lam, n)
    env = sinc2(np.pi * a * uc / lam)
    vmax = np.sqrt(1 - uc**2)
    v_int = lam / (np.pi * length) * 2 * sinc2_integral(np.pi * length * vmax / lam)
    # du dv = cos(theta_o) d(omega): the radiance itself is integrated in direction cosines
    total = grating_radiance_factor(lam, a, d, n, length) * np.sum(env * ms * v_int * du)
    m = np.arange(-int(d / lam), int(d / lam) + 1)
    propagating = (a / d) ** 2 * np.sum(sinc2(np.pi * a * m / d))  # Parseval: sum over all m = D / a
    assert total == pytest.approx(propagating, rel=0.01)
    assert total == pytest.approx(a / d, rel=0.01)


@settings(max_examples=150, deadline=None)
@given(
    n=st.integers(1, 10**6),
    ratio=st.floats(0.01, 1.0),
    d=st.floats(200.0, 1e5),
    u=st.floats(-2.0, 2.0),
    v=st.floats(-0.5, 0.5),
    length=st.floats(100.0, 1e6),
    lam0=st.floats(380.0, 770.0),
)
def test_stress_no_nan_inf_negative_and_float32_agrees(n, ratio, d, u, v, length, lam0):
    a = ratio * d
    edges = np.array([lam0, lam0 + 5.0, lam0 + 10.0])
    p64 = fraunhofer_pattern_binned(np.array([u]), np.array([v]), edges, a, d, n, length)
    p32 = fraunhofer_pattern_binned(np.array([u], np.float32), np.array([v], np.float32),
                                    edges.astype(np.float32), np.float32(a), np.float32(d), n, np.float32(length))
    pt = fraunhofer_pattern(np.array([u]), np.array([v]), np.array([lam0]), a, d, n, length)
    for x in (p64, p32, pt):
        assert np.all(np.isfinite(x)) and np.all(x >= 0) and np.all(x <= 1 + 1e-12)
    np.testing.assert_allclose(p32, p64, atol=2e-4)


def test_grazing_exit_is_bounded():
    """No 1/cos(theta_o) (docs/physics.md section 3.2): an exit in the surface's plane is finite and
    no larger than the radiance factor times the Harvey-Shack bound 1 / (a / D)."""
    from opal_diffraction.core.gratings.radiance import PreparedGratings, diffracted_radiance

    g = PreparedGratings(np.array([True]), np.array([False]), np.array([False]), np.array([2000.0]),
                         np.array([1000.0]), np.array([1000]), np.array([1e5]), np.ones(1), np.zeros(1))
    b = 3
    n = np.tile([0.0, 0.0, 1.0], (b, 1))
    t = np.tile([1.0, 0.0, 0.0], (b, 1))
    s = np.cross(n, t)
    w_i = np.tile([0.0, 0.0, 1.0], (b, 1))
    w_o = np.array([[1.0, 0.0, 0.0], [np.cos(1e-9), 0.0, np.sin(1e-9)], [0.55 / 2, np.sqrt(1 - 0.275**2), 0.0]])
    rad = diffracted_radiance(g, 0, w_o, w_i, t, s, n, np.full(b, 2000.0), np.array([549.0, 551.0]), None)
    bound = grating_radiance_factor(549e-9, 1e-6, 2e-6, 1000, 1e-4) * 2.0
    assert np.all(np.isfinite(rad)) and np.all(rad >= 0) and np.all(rad <= bound)
