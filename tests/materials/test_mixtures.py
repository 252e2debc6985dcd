"""Shader mixes of unlike BSDFs as lobe mixtures (core/materials/mixtures.py, docs/physics.md section 14.8).

- The Fresnel and Layer Weight Facs against independent formulas: the s- and p-polarised
  Fresnel equations through Snell's law in float64, F0 = ((n - 1) / (n + 1))^2, total internal
  reflection beyond the critical angle, and the Facing output's power law.
- The layer weights of a two-layer mix in the table's terms (metallic, transmission) give back
  the weights for every pair of layers.
- The mixture evaluated over the lobe choice is the weighted sum of the pure lobes (a
  Diffuse + Glossy mix with its own colours, and a Fresnel-mixed one with per-hit weights),
  its sampling density over the lobe choice and the direction is the weighted sum of the lobes'
  pdfs (chi-square, tests/chi2.py), and a white mixture reflects all energy (white furnace).
- The new material columns: defaults, validation, the npz round trip.
"""

from __future__ import annotations

import math
import zlib

import numpy as np
import pytest
from scipy.stats import norm

from chi2 import chi2_directions
from opal_diffraction.core.materials import bsdf as B
from opal_diffraction.core.materials.mixtures import fresnel_dielectric_cos, layer_fac, layer_weights, per_hit_layers
from opal_diffraction.core.materials.spectra import prepare_materials
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.model import Camera, Materials, Scene
from opal_diffraction.core.scene.npz import load_scene, save_scene
from opal_diffraction.core.scene.validation import validate
from opal_diffraction.core.spectral.spectrum import SpectralConverter
from opal_diffraction.core.util.enums import LayerFac

Z = norm.isf(1e-3 / 2)
#: the multiscatter tables' accuracy (tests/materials/test_bsdf.py TABLE_TOL)
TABLE_TOL = 0.005


def _fresnel_snell(cos_i, eta):
    """Unpolarised reflectance from the s and p amplitudes with Snell's law (float64; 1 under
    total internal reflection)."""
    cos_i = np.abs(np.asarray(cos_i, np.float64))
    sin2_t = (1.0 - cos_i * cos_i) / (eta * eta)
    tir = sin2_t >= 1.0
    cos_t = np.sqrt(np.maximum(1.0 - sin2_t, 0.0))
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return np.where(tir, 1.0, 0.5 * (rs * rs + rp * rp))


@pytest.mark.parametrize("eta", [1.01, 1.33, 1.5, 2.4, 1 / 1.5, 1 / 1.33])
def test_cycles_fresnel_is_the_fresnel_equations(eta):
    cos = np.linspace(0.0005, 1.0, 2001)
    np.testing.assert_allclose(fresnel_dielectric_cos(cos, np.full_like(cos, eta)), _fresnel_snell(cos, eta),
                               atol=3e-6, rtol=2e-5)


def test_fresnel_node():
    cos = np.linspace(0.001, 1.0, 500).astype(np.float32)
    code = np.full(cos.shape, int(LayerFac.FRESNEL))
    n = 1.45
    front = layer_fac(code, np.full(cos.shape, n), cos, np.ones(cos.shape, bool))
    np.testing.assert_allclose(front, _fresnel_snell(cos, n), atol=3e-6, rtol=2e-5)
    assert front[-1] == pytest.approx(((n - 1) / (n + 1)) ** 2, rel=1e-5)
    back = layer_fac(code, np.full(cos.shape, n), cos, np.zeros(cos.shape, bool))  # from inside: 1 / n
    crit = math.sqrt(1 - 1 / n**2)
    assert (back[cos < crit - 1e-3] == 1.0).all()
    np.testing.assert_allclose(back, _fresnel_snell(cos, 1 / n), atol=3e-6, rtol=2e-5)


@pytest.mark.parametrize("blend", [0.0, 0.2, 0.5, 0.8, 1.0])
def test_layer_weight_node(blend):
    cos = np.linspace(0.001, 1.0, 500).astype(np.float32)
    ones = np.ones(cos.shape, bool)
    fres = layer_fac(np.full(cos.shape, int(LayerFac.LAYER_FRESNEL)), np.full(cos.shape, blend), cos, ones)
    eta = 1.0 / max(1.0 - blend, 1e-5)  # front face: 1 / eta, eta = 1 - blend
    np.testing.assert_allclose(fres, _fresnel_snell(cos, eta), atol=3e-6, rtol=2e-5)
    if blend < 1:
        assert fres[-1] == pytest.approx((blend / (2 - blend)) ** 2, abs=1e-6)
    facing = layer_fac(np.full(cos.shape, int(LayerFac.LAYER_FACING)), np.full(cos.shape, blend), cos, ones)
    b = min(blend, 1 - 1e-5)
    e = 1.0 if blend == 0.5 else (2 * b if b < 0.5 else 0.5 / (1 - b))
    np.testing.assert_allclose(facing, 1 - cos.astype(np.float64) ** e, atol=2e-6)


@pytest.mark.parametrize("src,dst", [(a, b) for a in range(3) for b in range(3) if a != b])
def test_layer_weights_give_back_the_weights(src, dst):
    fac = np.linspace(0, 1, 11)
    m, t = layer_weights(fac, np.full(11, src), np.full(11, dst))
    w = np.stack([(1 - m) * (1 - t), m, (1 - m) * t], axis=1)
    want = np.zeros((11, 3))
    want[:, dst] += fac
    want[:, src] += 1 - fac
    np.testing.assert_allclose(w, want, atol=1e-6)


# ----------------------------------------------------------------------------- the mixture
DIFFUSE_RGB, GLOSSY_RGB = (0.8, 0.2, 0.1), (0.3, 0.6, 0.9)


def _mix_table(fac_rows=False):
    """Diffuse (0.8, 0.2, 0.1) mixed 0.6 / 0.4 with a Glossy (0.3, 0.6, 0.9) of roughness 0.4, and
    the same two mixed by a Fresnel node of IOR 1.6 (per hit), and a white pair."""
    rows = [
        dict(name="mix", kind="DIFFUSE", color=DIFFUSE_RGB, metal_color=GLOSSY_RGB, metallic=0.4, roughness=0.4),
        dict(name="fresnel", kind="DIFFUSE", color=DIFFUSE_RGB, metal_color=GLOSSY_RGB, metallic=0.1, roughness=0.4,
             layer_fac="FRESNEL", layer_fac_value=1.6, layer_fac_from=0, layer_fac_to=1),
        dict(name="white", kind="DIFFUSE", color=(1, 1, 1), metal_color=(1, 1, 1), metallic=0.5, roughness=0.5),
        dict(name="white glass", kind="DIFFUSE", color=(1, 1, 1), glass_color=(1, 1, 1), transmission=0.5,
             roughness=0.5, ior=1.5, layer_fac="LAYER_FACING", layer_fac_value=0.3, layer_fac_from=0,
             layer_fac_to=2),
    ]
    return Materials.from_list(rows)


def _pure(pm, conv, lobe, rgb, n, roughness):
    k = len(conv.grid.wavelengths)
    spec = conv.reflectance_from_rgb(np.asarray([rgb], np.float64)).astype(np.float32)
    return B.SurfaceParams(np.full(n, lobe, np.int32), np.broadcast_to(spec, (n, k)).copy(),
                           np.ones((n, k), np.float32), np.full(n, roughness**2, np.float32),
                           np.ones(n, np.float32), np.zeros(n, np.float32), np.ones((n, k), np.float32))


NS = np.array([0.2, -0.3, 0.93])
NS /= np.linalg.norm(NS)


def _dirs(n, rng):
    """Fixed wo (60 degrees from NS) and wi spread over NS's hemisphere."""
    a = np.array([1.0, 0, 0]) - NS[0] * NS
    a /= np.linalg.norm(a)
    wo = 0.5 * NS + math.sqrt(0.75) * a
    wi = rng.normal(size=(n, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wi = np.where((wi @ NS)[:, None] < 0, -wi, wi)
    return np.tile(wo, (n, 1)).astype(np.float32), wi.astype(np.float32), np.tile(NS, (n, 1)).astype(np.float32)


@pytest.mark.parametrize("row", [0, 1])
def test_mixture_evaluates_to_the_weighted_sum(row):
    """Over the lobe choice (stratified u_layer: the fractions exact to 1 / N), the mean of
    evaluate() is w_diffuse f_lambert(Diffuse colour) + w_glossy f_glossy(Glossy colour), the
    weights the table's (row 0) or the Fresnel node's at this wo (row 1)."""
    conv = SpectralConverter()
    pm = prepare_materials(_mix_table(), conv)
    rng = np.random.default_rng(11)
    n_dir, n_u = 64, 1000
    wo1, wi1, ns1 = _dirs(n_dir, rng)
    cos_o = float(wo1[0] @ NS)
    w_glossy = 0.4 if row == 0 else float(_fresnel_snell(cos_o, 1.6))
    u = (np.arange(n_u) + 0.5) / n_u
    w_glossy = float(np.mean(u < w_glossy))  # the stratified draw's exact fraction (w within 1 / n_u)
    lam, fl = _pure(pm, conv, B.LAMBERT, DIFFUSE_RGB, n_dir, 0.4), _pure(pm, conv, B.GLOSSY, GLOSSY_RGB, n_dir, 0.4)
    f_l, _ = B.evaluate(lam, wo1, wi1, ns1, ns1)
    f_g, _ = B.evaluate(B.with_outgoing(fl, wo1, ns1), wo1, wi1, ns1, ns1)
    want = (1 - w_glossy) * f_l.astype(np.float64) + w_glossy * f_g
    mat = np.full(n_u, row)
    got = np.zeros_like(want)
    for j in range(n_dir):
        wo, wi, ns = (np.repeat(x[j:j + 1], n_u, 0) for x in (wo1, wi1, ns1))
        weights = per_hit_layers(pm, mat, wo @ NS, np.ones(n_u, bool))
        assert (weights is None) == (row == 0)
        p = B.params_from_materials(pm, mat, np.ones(n_u, bool), u_layer=u, weights=weights)
        fc, _ = B.evaluate(p, wo, wi, ns, ns)
        got[j] = fc.astype(np.float64).mean(axis=0)
    np.testing.assert_allclose(got, want, rtol=2e-3, atol=2e-6)
    assert want.max() > 0.01


@pytest.mark.slow
@pytest.mark.parametrize("row", [0, 1])
def test_mixture_sampling_chi_square(row):
    """The directions sampled with a lobe drawn per hit follow sum_i w_i pdf_i (Pearson's test
    over a (theta, phi) grid, tests/chi2.py)."""
    conv = SpectralConverter()
    pm = prepare_materials(_mix_table(), conv)
    n = 200_000
    rng = np.random.default_rng(zlib.crc32(f"mixture-chi2-{row}".encode()))
    wo1, _, ns1 = _dirs(1, rng)
    wo, ns = np.repeat(wo1, n, 0), np.repeat(ns1, n, 0)
    mat = np.full(n, row)
    front = np.ones(n, bool)
    weights = per_hit_layers(pm, mat, wo @ NS, front)
    p = B.params_from_materials(pm, mat, front, u_layer=rng.random(n), weights=weights)
    wi, w, pdf, flags = B.sample(p, wo, ns, ns, rng.random((n, 3), dtype=np.float32))
    ok = flags != 0
    w_glossy = 0.4 if row == 0 else float(_fresnel_snell(float(wo1[0] @ NS), 1.6))

    def density(d):
        m = len(d)
        d32 = d.astype(np.float32)
        f = np.repeat(wo1, m, 0), np.repeat(ns1, m, 0)
        _, p_l = B.evaluate(_pure(pm, conv, B.LAMBERT, DIFFUSE_RGB, m, 0.4), f[0], d32, f[1], f[1])
        _, p_g = B.evaluate(_pure(pm, conv, B.GLOSSY, GLOSSY_RGB, m, 0.4), f[0], d32, f[1], f[1])
        return (1 - w_glossy) * p_l.astype(np.float64) + w_glossy * p_g

    # the refused samples (reflections below the horizon: probability 1 - the pdf's integral over
    # the hemisphere) are counted below it, spread uniformly, so that their number is tested too
    th = (np.arange(400) + 0.5) * (np.pi / 2 / 400)
    ph = (np.arange(800) + 0.5) * (2 * np.pi / 800)
    T, P = np.meshgrid(th, ph, indexing="ij")
    a = np.cross(NS, [1.0, 0, 0])
    a /= np.linalg.norm(a)
    b = np.cross(NS, a)
    grid = (np.sin(T) * np.cos(P))[..., None] * a + (np.sin(T) * np.sin(P))[..., None] * b + np.cos(T)[..., None] * NS
    upper = float((density(grid.reshape(-1, 3)).reshape(T.shape) * np.sin(T)).sum() * (np.pi / 2 / 400) * (2 * np.pi / 800))
    below = rng.normal(size=(int((~ok).sum()), 3))
    below -= np.maximum(below @ NS, 0)[:, None] * NS * 2  # reflected to NS's lower side
    dirs = np.concatenate([wi[ok].astype(np.float64), below / np.linalg.norm(below, axis=1, keepdims=True)])

    def full(d):
        return np.where(d @ NS > 0, density(d), (1.0 - upper) / (2 * np.pi))

    pval, info, total = chi2_directions(dirs, full, NS, theta_max=np.pi / 2)
    print(info)
    assert pval > 0.01 / 2, info
    assert total == pytest.approx(1.0, abs=2e-3)
    assert 1.0 - upper == pytest.approx((~ok).mean(), abs=5 * math.sqrt(max(1 - upper, 1e-4) / n))


@pytest.mark.slow
@pytest.mark.parametrize("row", [2, 3])
@pytest.mark.parametrize("theta_deg", [0.0, 50.0, 80.0])
def test_white_mixture_furnace(row, theta_deg):
    """A mixture of white lobes (white Diffuse + white Glossy 0.5 / 0.5; white Diffuse + clear
    glass by a Layer Weight Facing node) reflects and transmits all energy: the mean sampled
    weight is 1 (glass: transmission unscaled, docs/physics.md section 14.3)."""
    conv = SpectralConverter()
    pm = prepare_materials(_mix_table(), conv)
    n = 200_000
    rng = np.random.default_rng(int(theta_deg) + 100 * row)
    th = math.radians(theta_deg)
    a = np.array([1.0, 0, 0]) - NS[0] * NS
    a /= np.linalg.norm(a)
    wo = np.tile(math.cos(th) * NS + math.sin(th) * a, (n, 1)).astype(np.float32)
    ns = np.tile(NS, (n, 1)).astype(np.float32)
    mat, front = np.full(n, row), np.ones(n, bool)
    weights = per_hit_layers(pm, mat, wo @ NS, front)
    p = B.params_from_materials(pm, mat, front, u_layer=rng.random(n), weights=weights)
    p = B.with_outgoing(p, wo, ns)
    _, w, _, _ = B.sample(p, wo, ns, ns, rng.random((n, 3), dtype=np.float32))
    x = w.astype(np.float64).mean(axis=1)
    mean, se = x.mean(), x.std() / math.sqrt(n)
    print(f"row {row} theta {theta_deg}: albedo {mean:.5f} +- {se:.5f}")
    assert abs(mean - 1.0) < Z * se + TABLE_TOL


def test_prepared_layer_colours():
    conv = SpectralConverter()
    m = _mix_table()
    pm = prepare_materials(m, conv)
    np.testing.assert_allclose(pm.metal_reflectance[0], conv.reflectance_from_rgb(np.array([GLOSSY_RGB]))[0], rtol=1e-5)
    np.testing.assert_allclose(pm.reflectance[0], conv.reflectance_from_rgb(np.array([DIFFUSE_RGB]))[0], rtol=1e-5)
    assert list(pm.own_metal) == [True, True, True, False]
    # the metal drawn: its own colour; the base: the row's
    p = B.params_from_materials(pm, np.array([0, 0]), np.ones(2, bool), u_layer=np.array([0.1, 0.9]))
    assert list(p.lobe) == [B.GLOSSY, B.LAMBERT]
    np.testing.assert_allclose(p.base[0], pm.metal_reflectance[0])
    np.testing.assert_allclose(p.base[1], pm.reflectance[0])


def test_columns_defaults_validation_round_trip(tmp_path):
    m = Materials.from_list([dict(name="plain")])
    assert (m.metal_color == -1).all() and (m.glass_color == -1).all() and m.layer_fac[0] == 0
    s = Scene(materials=_mix_table(), camera=Camera())
    validate(s)
    save_scene(s, tmp_path / "m.npz")
    back = load_scene(tmp_path / "m.npz").materials
    for name in ("metal_color", "glass_color", "layer_fac", "layer_fac_value", "layer_fac_from", "layer_fac_to"):
        np.testing.assert_array_equal(getattr(back, name), getattr(s.materials, name))
    for bad, text in ((dict(layer_fac="FRESNEL", layer_fac_from=1, layer_fac_to=1), "two different layers"),
                      (dict(layer_fac_to=3), "layer fac to 3 is not a layer"),
                      (dict(metal_color=(float("nan"), 0, 0)), "metal color is NaN")):
        with pytest.raises(SceneError, match=text):
            validate(Scene(materials=Materials.from_list([dict(name="x", **bad)]), camera=Camera()))
    with pytest.raises(SceneError, match="layer_fac"):
        Materials.from_list([{"layer_fac": "SCHLICK"}])


def test_program_fac_per_hit():
    """LayerFac.PROGRAM: the shader program's 'mix' output per hit (clamped to [0, 1]) weighs the
    layer layer_fac_to; a hit without a value (NaN) keeps the table's mean."""
    conv = SpectralConverter()
    m = Materials.from_list([dict(name="masked", kind="DIFFUSE", color=(0.5, 0.5, 0.5), metal_color=(1, 1, 1),
                                  metallic=0.5, roughness=0.3, layer_fac="PROGRAM", layer_fac_from=0,
                                  layer_fac_to=1)])
    pm = prepare_materials(m, conv)
    fac = np.array([0.0, 0.25, 1.0, 1.5, -0.2, np.nan], np.float32)
    metallic, transmission = per_hit_layers(pm, np.zeros(6, np.int64), np.ones(6), np.ones(6, bool), fac)
    np.testing.assert_allclose(metallic, [0.0, 0.25, 1.0, 1.0, 0.0, 0.5])
    assert (transmission == 0).all()
