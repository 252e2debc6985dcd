"""Free-flight sampling with spectral MIS and closed-form transmittance (core/volumes/tracking.py),
against the integrals they estimate, per wavelength: Z-tests of the Monte Carlo means."""

import numpy as np
import pytest

from chi2 import chi2_normal_scores
from opal_diffraction.core.volumes.tracking import free_flight, segment_emission, transmittance

# a coloured medium over 7 "wavelengths": one channel that does not interact at all
SIGMA_S = np.array([0.0, 0.2, 0.5, 1.0, 1.5, 0.1, 0.0])
SIGMA_A = np.array([0.0, 0.1, 0.1, 0.3, 0.0, 2.0, 0.7])


def _estimate(t_end, a, lam=None, n=400_000, seed=7):
    """Per-sample estimates of (the pass weight times 1{passed}, the scatter weight times
    1{scattered before a}) over n samples."""
    rng = np.random.default_rng(seed)
    st = np.broadcast_to(SIGMA_S + SIGMA_A, (n, 7))
    ss = np.broadcast_to(SIGMA_S, (n, 7))
    te = np.full(n, t_end)
    ok, t, f = free_flight(st, ss, te, rng.random(n), rng.random(n), None if lam is None else np.full(n, lam))
    ff = f if lam is None else f[:, None]
    passed = np.where(~ok[:, None], ff, 0.0)
    early = np.where((ok & (t < a))[:, None], ff, 0.0)
    return passed, early


@pytest.mark.parametrize("t_end", [0.7, 3.0])
def test_spectral_mis_estimates_transmittance_and_scattering_per_wavelength(t_end):
    a = 0.5 * t_end
    passed, early = _estimate(t_end, a)
    sigma_t = SIGMA_S + SIGMA_A
    want_pass = np.exp(-sigma_t * t_end)  # Beer-Lambert
    # int_0^a sigma_s exp(-sigma_t t) dt
    want_early = np.where(sigma_t > 0, SIGMA_S / np.where(sigma_t > 0, sigma_t, 1) * -np.expm1(-sigma_t * a), 0.0)
    z = []
    for got, want in ((passed, want_pass), (early, want_early)):
        m, se = got.mean(axis=0), got.std(axis=0) / np.sqrt(len(got))
        live = se > 0
        z.append((m[live] - want[live]) / se[live])
        assert np.allclose(m[~live], want[~live], atol=1e-12)  # deterministic channels exactly
    assert chi2_normal_scores(np.concatenate(z)) > 1e-3, np.concatenate(z)
    # bounded weights: spectral MIS keeps colour noise down
    assert early.max() <= 7 * (SIGMA_S / np.maximum(sigma_t, 1e-12)).max() + 1e-9


def test_mono_rays_sample_their_own_wavelength():
    t_end, a, lam = 2.0, 1.0, 3
    passed, early = _estimate(t_end, a, lam=lam, n=200_000)
    st = SIGMA_S[lam] + SIGMA_A[lam]
    for got, want in ((passed[:, 0], np.exp(-st * t_end)),
                      (early[:, 0], SIGMA_S[lam] / st * -np.expm1(-st * a))):
        z = (got.mean() - want) / (got.std() / np.sqrt(len(got)))
        assert abs(z) < 4.5, z


def test_closed_forms():
    st = np.array([[0.0, 1.0, 2.0]])
    assert np.allclose(transmittance(st, np.array([1.5])), np.exp(-st * 1.5))
    assert np.allclose(transmittance(st, np.array([np.inf])), [[1.0, 0.0, 0.0]])
    le = np.array([[1.0, 2.0, 3.0]])
    got = segment_emission(st, le, np.array([1.5]))
    assert np.allclose(got, [[1.5, 2.0 * (1 - np.exp(-1.5)), 3.0 * (1 - np.exp(-3.0)) / 2.0]])
