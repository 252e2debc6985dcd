"""Next events over a whole lobe mixture (core/materials/mixtures.py LobeMixture, docs/physics.md section 14.8).

- LobeMixture.evaluate is w_d f_Lambert + w_g f_Glossy and its pdf w_d p_Lambert + w_g p_Glossy,
  the pure lobes built independently of the material table (the table's weights, and a Fresnel
  node's per hit), rows of other materials in the batch keeping their one lobe.
- The bounce's weight f_mix / p_mix at a direction drawn from one lobe (chosen with probability
  w_i) has the same expectation as the one-sample weight f_i / p_i (the mixture's albedo, a
  Z-test) and a smaller variance; a white mixture's weight is 1 (white furnace).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import norm

from opal_diffraction.core.materials import bsdf as B
from opal_diffraction.core.materials.mixtures import LobeMixture, per_hit_layers
from opal_diffraction.core.materials.spectra import prepare_materials
from opal_diffraction.core.scene.model import Materials
from opal_diffraction.core.spectral.spectrum import SpectralConverter
from test_mixtures import DIFFUSE_RGB, GLOSSY_RGB, NS, _dirs, _fresnel_snell, _mix_table, _pure

Z = norm.isf(1e-3 / 2)


def _mixture(pm, mat, wo, ns, u_layer):
    front = np.ones(len(mat), bool)
    weights = per_hit_layers(pm, mat, wo @ NS, front)
    metallic, transmission = (pm.metallic[mat], pm.transmission[mat]) if weights is None else weights
    p = B.with_outgoing(B.params_from_materials(pm, mat, front, u_layer=u_layer, weights=weights), wo, ns)
    mixed = (pm.metallic[mat] > 0) & (pm.metallic[mat] < 1) | (pm.layer_fac[mat] != 0)
    return p, LobeMixture.of(pm, mat, front, mixed, metallic, transmission, wo, ns)


def _table_with_metal():
    """test_mixtures' rows 0 and 1 and a pure Glossy metal (metallic 1: no mixture)."""
    return Materials.from_list([
        dict(name="mix", kind="DIFFUSE", color=DIFFUSE_RGB, metal_color=GLOSSY_RGB, metallic=0.4, roughness=0.4),
        dict(name="fresnel", kind="DIFFUSE", color=DIFFUSE_RGB, metal_color=GLOSSY_RGB, metallic=0.1, roughness=0.4,
             layer_fac="FRESNEL", layer_fac_value=1.6, layer_fac_from=0, layer_fac_to=1),
        dict(name="metal", kind="DIFFUSE", color=DIFFUSE_RGB, metal_color=GLOSSY_RGB, metallic=1.0, roughness=0.3)])


@pytest.mark.parametrize("row", [0, 1])
def test_mixture_evaluate_is_the_weighted_sum_of_its_lobes(row):
    """Even rows the mixture, odd rows a pure metal."""
    conv = SpectralConverter()
    pm = prepare_materials(_table_with_metal(), conv)
    rng = np.random.default_rng(5 + row)
    n = 256
    wo, wi, ns = _dirs(n, rng)
    w_g = 0.4 if row == 0 else float(_fresnel_snell(float(wo[0] @ NS), 1.6))
    f_l, p_l = B.evaluate(_pure(pm, conv, B.LAMBERT, DIFFUSE_RGB, n, 0.4), wo, wi, ns, ns)
    f_g, p_g = B.evaluate(_pure(pm, conv, B.GLOSSY, GLOSSY_RGB, n, 0.4), wo, wi, ns, ns)
    want_f = (1 - w_g) * f_l.astype(np.float64) + w_g * f_g
    want_p = (1 - w_g) * p_l.astype(np.float64) + w_g * p_g
    mat = np.where(np.arange(n) % 2 == 0, row, 2)
    p, mix = _mixture(pm, mat, wo, ns, rng.random(n))
    assert mix is not None and np.array_equal(mix.rows, np.flatnonzero(mat == row))
    f, pdf = mix.evaluate(p, wo, wi, ns, ns)
    even = mat == row
    np.testing.assert_allclose(f[even], want_f[even], rtol=2e-4, atol=1e-7)
    np.testing.assert_allclose(pdf[even], want_p[even], rtol=2e-4, atol=1e-7)
    f1, p1 = B.evaluate(p, wo, wi, ns, ns)  # the odd rows: their one drawn lobe
    np.testing.assert_array_equal(f[~even], f1[~even])
    np.testing.assert_array_equal(pdf[~even], p1[~even])
    # take() keeps rows and weights together
    k = np.flatnonzero(np.arange(n) % 3 != 0)
    f2, p2 = mix.take(k).evaluate(p.take(k), wo[k], wi[k], ns[k], ns[k])
    np.testing.assert_allclose(f2, f[k], rtol=1e-6)
    np.testing.assert_allclose(p2, pdf[k], rtol=1e-6)


def _bounce_weights(pm, row, theta_deg, n, seed):
    """(one-sample weights f_i / p_i, mixture weights f / p) (n, k) of directions sampled at wo
    theta_deg from NS; refused samples weigh 0."""
    rng = np.random.default_rng(seed)
    th = math.radians(theta_deg)
    a = np.array([1.0, 0, 0]) - NS[0] * NS
    a /= np.linalg.norm(a)
    wo = np.tile(math.cos(th) * NS + math.sin(th) * a, (n, 1)).astype(np.float32)
    ns = np.tile(NS, (n, 1)).astype(np.float32)
    mat = np.full(n, row)
    p, mix = _mixture(pm, mat, wo, ns, rng.random(n))
    wi, w, pdf, flags = B.sample(p, wo, ns, ns, rng.random((n, 3), dtype=np.float32))
    f, pm_ = mix.evaluate(p, wo, wi, ns, ns)
    ok = (flags != 0) & ((flags & B.SINGULAR) == 0) & (pm_ > 0)
    w_mix = np.where(ok[:, None], f / np.where(ok, pm_, 1)[:, None], 0.0)
    return w.astype(np.float64), w_mix.astype(np.float64)


@pytest.mark.parametrize("row", [0, 1])
@pytest.mark.parametrize("theta_deg", [20.0, 70.0])
def test_mixture_weight_has_the_one_sample_mean_and_less_variance(row, theta_deg):
    pm = prepare_materials(_mix_table(), SpectralConverter())
    n = 100_000
    w1, wm = _bounce_weights(pm, row, theta_deg, n, 31 + row)
    x1, xm = w1.mean(axis=1), wm.mean(axis=1)
    d = xm - x1  # the same samples: a paired test
    z = d.mean() / (d.std() / math.sqrt(n))
    print(f"row {row} theta {theta_deg}: albedo {xm.mean():.4f} vs {x1.mean():.4f} (z {z:.2f}), "
          f"variance {xm.var():.4f} vs {x1.var():.4f}")
    assert abs(z) < Z
    assert xm.var() < 0.8 * x1.var()


@pytest.mark.parametrize("theta_deg", [0.0, 50.0, 80.0])
def test_white_mixture_weight_furnace(theta_deg):
    """A white Diffuse + white Glossy mixture (rough 0.5, multiscatter-compensated) reflects all
    energy through the mixture weights too."""
    pm = prepare_materials(_mix_table(), SpectralConverter())
    n = 100_000
    _, wm = _bounce_weights(pm, 2, theta_deg, n, 7)
    x = wm.mean(axis=1)
    se = x.std() / math.sqrt(n)
    print(f"theta {theta_deg}: albedo {x.mean():.5f} +- {se:.5f}")
    assert abs(x.mean() - 1.0) < Z * se + 0.005  # the multiscatter tables' accuracy (test_bsdf TABLE_TOL)
