"""Oren-Nayar (the Diffuse BSDF's Roughness > 0; core/materials/bsdf.py OREN_NAYAR, docs/physics.md
section 14.9), as Cycles 4.3+ renders it.

- f against Fujii's formula written out independently in float64 from the polar and azimuthal
  angles (s = cos(phi) sin(theta_i) sin(theta_o), t = s / max(cos theta_i, cos theta_o) where
  s > 0), plus OpenPBR's multiple-scattering term.
- G(mu), the single-scattering albedo's closed form E(mu) = A pi + B G(mu), and E_avg = A pi +
  (2 pi - 5.6) / 3 B against numerical quadrature over the hemisphere.
- Sampling: Pearson's chi-square against evaluate()'s pdf; weight = f cos / pdf.
- White furnace: a white Oren-Nayar reflects all energy at every roughness and angle (the
  multiple-scattering term's purpose), a grey one at most its Lambertian albedo's neighbourhood.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import norm

from chi2 import chi2_directions
from opal_diffraction.core.materials import bsdf as B
from opal_diffraction.core.materials.spectra import prepare_materials
from opal_diffraction.core.scene.model import Materials
from opal_diffraction.core.spectral.spectrum import SpectralConverter

Z = norm.isf(1e-3 / 2)
NS = np.array([0.0, 0.0, 1.0])


def _params(n, sigma, rho=1.0, k=1):
    return B.SurfaceParams(np.full(n, B.OREN_NAYAR, np.int32), np.full((n, k), rho, np.float32),
                           np.ones((n, k), np.float32), np.full(n, sigma, np.float32), np.ones(n, np.float32),
                           np.zeros(n, np.float32), np.ones((n, k), np.float32))


def _dir(theta, phi):
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)


def _e_single(mu, sigma, n=400):
    """E(mu) = int (A + B t) cos_i dw_i by the midpoint rule over (theta_i, phi_i) (float64)."""
    a = 1 / (math.pi + sigma * (math.pi / 2 - 2 / 3))
    b = sigma * a
    th = (np.arange(n) + 0.5) * (math.pi / 2 / n)
    ph = (np.arange(2 * n) + 0.5) * (2 * math.pi / (2 * n))
    T, P = np.meshgrid(th, ph, indexing="ij")
    so = math.sqrt(max(1 - mu * mu, 0.0))
    s = np.cos(P) * np.sin(T) * so
    t = np.where(s > 0, s / np.maximum(np.cos(T), mu), s)
    return float(((a + b * t) * np.cos(T) * np.sin(T)).sum() * (math.pi / 2 / n) * (2 * math.pi / (2 * n)))


def _fujii(theta_i, phi_i, theta_o, sigma, rho):
    """f cos of Cycles' Oren-Nayar, float64, from angles (wo at azimuth 0)."""
    a = 1 / (math.pi + sigma * (math.pi / 2 - 2 / 3))
    b = sigma * a
    mi, mo = np.cos(theta_i), math.cos(theta_o)
    s = np.cos(phi_i) * np.sin(theta_i) * math.sin(theta_o)
    t = np.where(s > 0, s / np.maximum(mi, mo), s)

    def g(mu):
        mu = np.maximum(mu, 1e-6)
        sn = np.sqrt(1 - mu * mu)
        th = np.arccos(mu)
        return sn * (th - 2 / 3 - sn * mu) + 2 / 3 * (sn / mu) * (1 - sn ** 3)

    e_avg = a * math.pi + (2 * math.pi - 5.6) / 3 * b
    e_ms = rho * rho * e_avg / (1 - e_avg) / (math.pi * (1 - rho * (1 - e_avg)))
    ms = e_ms * (1 - (a * math.pi + b * g(mo))) * (1 - (a * math.pi + b * g(mi)))
    return rho * mi * (a + b * t + ms)


@pytest.mark.parametrize("sigma", [0.25, 0.6, 1.0])
def test_g_and_e_avg_are_the_hemispherical_integrals(sigma):
    a = 1 / (math.pi + sigma * (math.pi / 2 - 2 / 3))
    b = sigma * a
    mus = np.array([0.05, 0.3, 0.6, 0.9, 1.0])
    closed = a * math.pi + b * B._oren_nayar_g(mus.astype(np.float32)).astype(np.float64)
    numeric = np.array([_e_single(m, sigma) for m in mus])
    np.testing.assert_allclose(closed, numeric, atol=2e-4)
    x = (np.arange(2000) + 0.5) / 2000
    e = a * math.pi + b * B._oren_nayar_g(x.astype(np.float32)).astype(np.float64)
    assert 2 * np.mean(e * x) == pytest.approx(a * math.pi + (2 * math.pi - 5.6) / 3 * b, abs=2e-4)


@pytest.mark.parametrize("sigma", [0.3, 1.0])
@pytest.mark.parametrize("theta_o", [0.0, 0.7, 1.3])
def test_f_is_fujiis_formula(sigma, theta_o):
    rng = np.random.default_rng(3)
    n = 2000
    ti, pi_ = rng.random(n) * math.pi / 2, rng.random(n) * 2 * math.pi
    wi = _dir(ti, pi_).astype(np.float32)
    wo = np.tile(_dir(np.array(theta_o), np.array(0.0)), (n, 1)).astype(np.float32)
    ns = np.tile(NS, (n, 1)).astype(np.float32)
    rho = 0.7
    fc, pdf = B.evaluate(_params(n, sigma, rho), wo, wi, ns, ns)
    np.testing.assert_allclose(fc[:, 0], _fujii(ti, pi_, theta_o, sigma, rho), rtol=2e-4, atol=2e-6)
    np.testing.assert_allclose(pdf, np.cos(ti) / math.pi, rtol=1e-5, atol=1e-7)


@pytest.mark.slow
@pytest.mark.parametrize("theta_o", [0.3, 1.2])
def test_sampling_chi_square_and_weight(theta_o):
    n, sigma = 200_000, 0.8
    rng = np.random.default_rng(int(theta_o * 10))
    wo = np.tile(_dir(np.array(theta_o), np.array(0.0)), (n, 1)).astype(np.float32)
    ns = np.tile(NS, (n, 1)).astype(np.float32)
    p = _params(n, sigma, 0.6)
    wi, w, pdf, fl = B.sample(p, wo, ns, ns, rng.random((n, 3), dtype=np.float32))
    ok = fl != 0
    assert ok.mean() > 0.999 and ((fl[ok] & B.DIFFUSE_REFLECTION) != 0).all()

    def density(d):
        m = len(d)
        _, pp = B.evaluate(_params(m, sigma, 0.6), np.repeat(wo[:1], m, 0), d.astype(np.float32),
                           np.repeat(ns[:1], m, 0), np.repeat(ns[:1], m, 0))
        return pp.astype(np.float64)

    pval, info, _ = chi2_directions(wi[ok], density, NS, theta_max=np.pi / 2)
    print(info)
    assert pval > 0.01 / 2, info
    fc, pe = B.evaluate(p.take(np.flatnonzero(ok)[:5000]), wo[:5000], wi[ok][:5000], ns[:5000], ns[:5000])
    np.testing.assert_allclose(fc / pe[:, None], w[ok][:5000], rtol=1e-5, atol=1e-7)


@pytest.mark.slow
@pytest.mark.parametrize("sigma", [0.2, 0.5, 1.0])
@pytest.mark.parametrize("theta_deg", [0.0, 45.0, 80.0])
def test_white_furnace(sigma, theta_deg):
    n = 200_000
    rng = np.random.default_rng(int(sigma * 100 + theta_deg))
    wo = np.tile(_dir(np.array(math.radians(theta_deg)), np.array(0.0)), (n, 1)).astype(np.float32)
    ns = np.tile(NS, (n, 1)).astype(np.float32)
    _, w, _, _ = B.sample(_params(n, sigma, 1.0), wo, ns, ns, rng.random((n, 3), dtype=np.float32))
    x = w[:, 0].astype(np.float64)
    mean, se = x.mean(), x.std() / math.sqrt(n)
    print(f"sigma {sigma} theta {theta_deg}: albedo {mean:.5f} +- {se:.5f}")
    assert abs(mean - 1) < Z * se + 1e-3


def test_table_routes_a_rough_diffuse_to_oren_nayar():
    conv = SpectralConverter()
    m = Materials.from_list([dict(name="rough", kind="DIFFUSE", diffuse_roughness=0.7),
                             dict(name="plain", kind="DIFFUSE"),
                             dict(name="plastic", kind="DIFFUSE", diffuse_roughness=0.7, specular_ior_level=0.5,
                                  roughness=0.3)])
    pm = prepare_materials(m, conv)
    assert list(B.microfacet_materials(pm)) == [True, False, True]
    p = B.params_from_materials(pm, np.array([0, 1, 2]), np.ones(3, bool))
    assert list(p.lobe) == [B.OREN_NAYAR, B.LAMBERT, B.PLASTIC]  # a specular layer's base stays Lambert
    assert p.alpha[0] == pytest.approx(0.7)
