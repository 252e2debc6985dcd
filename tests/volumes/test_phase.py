"""The Henyey-Greenstein phase function (core/volumes/phase.py): its normalisation and mean
cosine by quadrature, and a chi-square test of its sampler against its density (tests/chi2.py)."""

import numpy as np
import pytest

from chi2 import chi2_directions
from opal_diffraction.core.volumes.phase import hg, sample_hg

G_VALUES = (-0.7, 0.0, 0.3, 0.9)


@pytest.mark.parametrize("g", G_VALUES)
def test_hg_integrates_to_one_with_mean_cosine_g(g):
    # 2 pi int_{-1}^{1} p(mu) dmu = 1 and 2 pi int mu p(mu) dmu = g (the definition of g)
    mu = np.linspace(-1.0, 1.0, 400_001)
    p = hg(mu, g)
    trap = getattr(np, "trapezoid", None) or np.trapz
    assert 2 * np.pi * trap(p, mu) == pytest.approx(1.0, abs=2e-6)
    assert 2 * np.pi * trap(mu * p, mu) == pytest.approx(g, abs=2e-6)


@pytest.mark.parametrize("g", G_VALUES)
def test_hg_sampling_chi_square(g):
    rng = np.random.default_rng(31)
    n = 200_000
    axis = np.array([0.3, -0.5, 0.8])
    axis /= np.linalg.norm(axis)
    d = np.broadcast_to(axis, (n, 3))
    wi, pdf = sample_hg(d, np.full(n, g), rng.random(n), rng.random(n))
    assert np.allclose(np.linalg.norm(wi, axis=1), 1.0, atol=1e-12)
    # the returned pdf is the density at the sampled direction
    assert np.allclose(pdf, hg(wi @ axis, g), rtol=1e-9)
    p, info, total = chi2_directions(wi, lambda dirs: hg(dirs @ axis, g), axis)
    assert total == pytest.approx(1.0, abs=1e-3)
    assert p > 0.01 / len(G_VALUES), info
