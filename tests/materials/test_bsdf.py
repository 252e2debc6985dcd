"""core/materials/bsdf.py: GGX microfacet BSDFs (docs/physics.md section 14).

- sample() against evaluate()'s pdf: chi-square goodness of fit on a (theta, phi) grid of the
  whole sphere, the expected count of each cell by Gauss-Legendre integration of the pdf over it,
  cells expecting < 5 pooled, the threshold Bonferroni-corrected for the number of
  configurations (Mitsuba 3's chi2.py);
- weight == f cos / pdf for sampled directions, and the same pdf from both functions;
- white furnace: the directional albedo (mean weight) is <= 1 for every lobe, 1 for a white
  conductor / Glossy with the multiscatter compensation, for a dielectric (reflection plus
  transmission: the lobe carries no 1/eta^2 radiance factor, docs/physics.md section 14.3) and
  for a white Principled base;
  the analytic Fresnel reflectance as roughness -> 0;
- reciprocity of the single-scattering lobes (the compensation factor divided out) and Walter's
  generalized reciprocity for transmission (Walter's for the radiance BTDF f eta^-2:
  f(wo, wi) / n_i^2 = f(wi, wo) / n_o^2 for this lobe without the factor);
- the MC albedo against an independent quadrature of evaluate()'s f cos over the sphere;
- the material columns: validation, .npz round trip, defaults of older files, params_from_materials.
"""

from __future__ import annotations

import math
import zlib

import numpy as np
import pytest
from scipy.stats import norm

from chi2 import pearson
from opal_diffraction.core.materials import bsdf as B
from opal_diffraction.core.util.geometry import orthonormal_basis
from opal_diffraction.core.materials.spectra import prepare_materials
from opal_diffraction.core.scene.model import Camera, Materials, Scene
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.npz import load_scene, save_scene
from opal_diffraction.core.scene.validation import validate
from opal_diffraction.core.spectral.optics import fresnel_dielectric
from opal_diffraction.core.spectral.spectrum import SpectralConverter

NS = np.array([0.3, -0.5, 0.81])
NS = NS / np.linalg.norm(NS)  # a tilted shading frame, so the frame code is exercised
U_AX, V_AX = orthonormal_basis(NS)


def params(lobe, n, roughness, eta=1.0, base=1.0, edge=1.0, spec_f0=0.0, tint=1.0, k=1):
    def f(v, shape):
        return np.broadcast_to(np.asarray(v, np.float32), shape).copy()
    return B.SurfaceParams(np.full(n, lobe, np.int32), f(base, (n, k)), f(edge, (n, k)),
                           f(roughness * roughness, n), f(eta, n), f(spec_f0, n), f(tint, (n, k)))


def world(theta, phi):
    """Directions at polar angle theta from NS and azimuth phi about it, (..., 3)."""
    st = np.sin(theta)[..., None]
    return (st * np.cos(phi)[..., None] * U_AX + st * np.sin(phi)[..., None] * V_AX
            + np.cos(theta)[..., None] * NS)


def frame(n):
    return np.tile(NS, (n, 1)).astype(np.float32)


def wo_at(theta_o, n):
    return np.tile(world(np.array(theta_o), np.array(0.0)), (n, 1)).astype(np.float32)


def draw(p, theta_o, seed=0):
    n = len(p)
    rng = np.random.default_rng(seed)
    wo, ns = wo_at(theta_o, n), frame(n)
    wi, w, pdf, fl = B.sample(p, wo, ns, ns, rng.random((n, 3), dtype=np.float32))
    return wo, ns, wi, w, pdf, fl


def angles(wi):
    x, y, z = wi @ U_AX, wi @ V_AX, wi @ NS
    return np.arccos(np.clip(z, -1, 1)), np.mod(np.arctan2(y, x), 2 * np.pi)


# ----------------------------------------------------------------------------- configurations
def _configs():
    out = [("lambert", B.LAMBERT, 1.0, 1.0, {}, 0.8)]
    for r in (0.3, 0.6, 1.0):
        for t in (0.0, 45.0, 80.0):
            th = math.radians(t)
            out.append(("conductor", B.CONDUCTOR, r, 1.0, dict(base=0.8, edge=0.6), th))
            out.append(("plastic", B.PLASTIC, r, 1.0, dict(base=0.5, spec_f0=0.04), th))
            for eta in (1.5, 1 / 1.5):
                out.append(("dielectric", B.DIELECTRIC, r, eta, {}, th))
    out.append(("glossy", B.GLOSSY, 0.5, 1.0, dict(base=0.7), 1.0))
    return out


CONFIGS = _configs()
IDS = [f"{c[0]}-r{c[2]}-eta{c[3]:.3f}-t{math.degrees(c[5]):.0f}" for c in CONFIGS]
SIGNIFICANCE = 0.01 / len(CONFIGS)  # Bonferroni: a 1 % chance that any of the tests fails by chance


def _cell_integrals(p1, wo1, n_theta=30, n_phi=60, sub=16):
    """Each (theta, phi) cell's integral of evaluate()'s pdf by the midpoint rule on sub x sub
    points (robust where the pdf's support ends inside a cell, as transmission lobes' do)."""
    tb = np.linspace(0, np.pi, n_theta + 1)
    pb = np.linspace(0, 2 * np.pi, n_phi + 1)
    th = (np.arange(n_theta * sub) + 0.5) * (np.pi / (n_theta * sub))
    ph = (np.arange(n_phi * sub) + 0.5) * (2 * np.pi / (n_phi * sub))
    T, P = np.meshgrid(th, ph, indexing="ij")
    wi = world(T, P).reshape(-1, 3).astype(np.float32)
    m = len(wi)
    rep = p1.take(np.zeros(m, np.int64))
    _, pdf = B.evaluate(rep, np.repeat(wo1, m, 0), wi, frame(m), frame(m))
    dA = np.sin(T) * (np.pi / (n_theta * sub)) * (2 * np.pi / (n_phi * sub))
    val = (pdf.astype(np.float64) * dA.ravel()).reshape(n_theta, sub, n_phi, sub)
    return val.sum(axis=(1, 3)), tb, pb


@pytest.mark.slow
@pytest.mark.parametrize("cfg", CONFIGS, ids=IDS)
def test_sampling_matches_pdf_chi_square(cfg):
    name, lobe, r, eta, kw, th = cfg
    n = 200_000
    p = params(lobe, n, r, eta=eta, **kw)
    wo, ns, wi, w, pdf, fl = draw(p, th, seed=zlib.crc32(IDS[CONFIGS.index(cfg)].encode()))  # stable across processes (hash() is salted)
    assert not (fl & B.SINGULAR).any()
    ok = fl != 0
    t, ph = angles(wi[ok].astype(np.float64))
    expected, tb, pb = _cell_integrals(p.take(np.arange(1)), wo[:1])
    expected *= n
    observed, _, _ = np.histogram2d(t, ph, bins=[tb, pb])
    # the pdf integrates to the probability of a valid sample (+ the midpoint rule's error)
    assert expected.sum() == pytest.approx(ok.sum(), rel=5 / math.sqrt(n) + 2e-3)
    pval, info = pearson(observed, expected)
    print(f"{IDS[CONFIGS.index(cfg)]}: {info}")
    assert pval > SIGNIFICANCE, info


@pytest.mark.parametrize("cfg", CONFIGS, ids=IDS)
def test_weight_is_f_cos_over_pdf(cfg):
    name, lobe, r, eta, kw, th = cfg
    p = params(lobe, 20_000, r, eta=eta, **kw)
    wo, ns, wi, w, pdf, fl = draw(p, th, seed=3)
    ok = fl != 0
    fc, pe = B.evaluate(p.take(ok), wo[ok], wi[ok], ns[ok], ns[ok])
    np.testing.assert_allclose(pe, pdf[ok], rtol=2e-3)
    np.testing.assert_allclose(fc / pe[:, None], w[ok], rtol=2e-3, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0, atol=1e-5)
    assert (w[~ok] == 0).all() and (pdf[~ok] == 0).all()


# ----------------------------------------------------------------------------- energy
def _albedo(p, theta_o, seed=1):
    """Mean weight and its standard error (transmission carries no 1/eta^2: the weights are energy)."""
    wo, ns, wi, w, pdf, fl = draw(p, theta_o, seed)
    x = w[:, 0].astype(np.float64)
    return x.mean(), x.std() / math.sqrt(len(x)), w, fl


#: Accuracy of the compensation tables (bilinear / trilinear interpolation of a 2048-point
#: lattice quadrature): measured below by test_tables_match_an_independent_quadrature (0.3 %).
TABLE_TOL = 0.005
Z = norm.isf(1e-3 / 2)  # a two-sided 1e-3 test for each furnace case


@pytest.mark.slow
@pytest.mark.parametrize("r", [0.2, 0.45, 0.7, 1.0])
@pytest.mark.parametrize("theta_deg", [0.0, 40.0, 75.0])
def test_white_furnace_is_one(r, theta_deg):
    th = math.radians(theta_deg)
    n = 200_000
    cases = {
        "conductor": params(B.CONDUCTOR, n, r, base=1.0, edge=1.0),
        "glossy": params(B.GLOSSY, n, r, base=1.0),
        "dielectric 1.5": params(B.DIELECTRIC, n, r, eta=1.5),
        "dielectric 1/1.5": params(B.DIELECTRIC, n, r, eta=1 / 1.5),
        "dielectric 2.4": params(B.DIELECTRIC, n, r, eta=2.4),
        "plastic": params(B.PLASTIC, n, r, base=1.0, spec_f0=0.04),
        "plastic f0 0.2": params(B.PLASTIC, n, r, base=1.0, spec_f0=0.2),
        "lambert": params(B.LAMBERT, n, r),
    }
    for name, p in cases.items():
        a, se, _, _ = _albedo(p, th)
        print(f"r {r} theta {theta_deg}: {name} albedo {a:.5f} +- {se:.5f}")
        assert abs(a - 1.0) < Z * se + TABLE_TOL, f"{name}: albedo {a:.5f} +- {se:.5f}"


@pytest.mark.slow
@pytest.mark.parametrize("r", [0.05, 0.4, 0.8])
@pytest.mark.parametrize("theta_deg", [0.0, 60.0, 85.0])
def test_albedo_never_exceeds_one(r, theta_deg):
    th = math.radians(theta_deg)
    n, k = 100_000, 3
    rng = np.random.default_rng(7)
    cases = {
        "gold F82": params(B.CONDUCTOR, n, r, base=[1.0, 0.78, 0.34], edge=[1.0, 0.9, 0.5], k=k),
        "dark F82": params(B.CONDUCTOR, n, r, base=0.05, edge=0.2, k=k),
        "glossy": params(B.GLOSSY, n, r, base=[0.9, 0.5, 0.1], k=k),
        "tinted glass": params(B.DIELECTRIC, n, r, eta=1.33, base=[1.0, 0.7, 0.4], k=k),
        "plastic": params(B.PLASTIC, n, r, base=[0.9, 0.2, 0.4], spec_f0=0.08, tint=[1.0, 0.5, 0.2], k=k),
        "random plastic": params(B.PLASTIC, n, r, base=rng.random((n, k)), spec_f0=rng.random(n) * 0.5,
                                 tint=rng.random((n, k)), k=k),
    }
    for name, p in cases.items():
        wo, ns, wi, w, pdf, fl = draw(p, th, seed=5)
        x = w.astype(np.float64)
        a, se = x.mean(axis=0), x.std(axis=0) / math.sqrt(n)
        assert np.all(a <= 1.0 + Z * se + TABLE_TOL), f"{name}: albedo {a}"


@pytest.mark.slow
def test_smooth_limit_is_the_analytic_fresnel():
    """At roughness just above MIN_ROUGHNESS (rough code path) and at 0 (delta events) the
    albedo is the Fresnel reflectance at mu_o: F82 for a metal, the exact dielectric Fresnel
    for the reflected share of glass, Cycles' remapped Fresnel for a black plastic."""
    n = 100_000
    for r in (B.MIN_ROUGHNESS * 1.5, 0.0):
        for t in (0.0, 50.0, 80.0):
            th = math.radians(t)
            mu = np.array([math.cos(th)], np.float32)
            f0, edge = np.array([[0.6]], np.float32), np.array([[0.4]], np.float32)
            want = B.fresnel_f82(mu, f0, B.f82_b(f0, edge))[0, 0]
            a, se, _, fl = _albedo(params(B.CONDUCTOR, n, r, base=0.6, edge=0.4), th)
            assert abs(a - want) < Z * se + 2e-3, (r, t, a, want)
            assert bool((fl & B.SINGULAR).all()) == (r == 0)
            # glass: the share of reflection events is F(mu_o) (exact Fresnel)
            for eta in (1.5, 1 / 1.5):
                _, _, w, fl = _albedo(params(B.DIELECTRIC, n, r, eta=eta), th)
                frac = ((fl & B.GLOSSY_REFLECTION) != 0).mean()
                want = float(fresnel_dielectric(mu, np.float32(eta))[0][0])
                assert abs(frac - want) < Z * math.sqrt(want * (1 - want) / n) + 3e-3, (r, t, eta, frac, want)
            # black Principled base: its specular layer alone
            a, se, _, _ = _albedo(params(B.PLASTIC, n, r, base=0.0, spec_f0=0.04), th)
            fr = float(fresnel_dielectric(mu, np.float32(1.5))[0][0])
            assert abs(a - fr) < Z * se + 2e-3, (r, t, a, fr)


# ----------------------------------------------------------------------------- reciprocity
def _pairs(n, seed, transmit=False):
    rng = np.random.default_rng(seed)
    to = np.arccos(rng.uniform(0.05, 1.0, n))
    ti = np.arccos(rng.uniform(0.05, 1.0, n))
    if transmit:
        ti = np.pi - ti
    return (world(to, rng.uniform(0, 2 * np.pi, n)).astype(np.float32),
            world(ti, rng.uniform(0, 2 * np.pi, n)).astype(np.float32))


def _f(p, wo, wi, ns):
    """f = f cos / |cos(wi, ns)| with the compensation factor of wo's side divided out."""
    fc, _ = B.evaluate(p, wo, wi, ns, ns)
    c = np.abs(np.sum(wi * ns, axis=1))[:, None]
    return fc / c / B.energy_compensation(p, np.sum(wo * ns, axis=1))


@pytest.mark.parametrize("lobe,kw", [(B.LAMBERT, dict(base=0.6)), (B.CONDUCTOR, dict(base=0.7, edge=0.5)),
                                     (B.GLOSSY, dict(base=0.4)), (B.DIELECTRIC, dict(eta=1.5)),
                                     (B.DIELECTRIC, dict(eta=1 / 1.7))])
def test_reflection_is_reciprocal(lobe, kw):
    n = 5000
    for r in (0.2, 0.6, 1.0):
        p = params(lobe, n, r, **kw)
        wo, wi = _pairs(n, 11)
        a, b = _f(p, wo, wi, frame(n)), _f(p, wi, wo, frame(n))
        assert (a > 0).mean() > 0.99
        np.testing.assert_allclose(a, b, rtol=2e-3, atol=1e-7)


def test_transmission_generalized_reciprocity():
    """Walter et al. 2007 eq. 22 for the radiance BTDF f_rad: f_rad(wo, wi) / n_o^2 = f_rad(wi,
    wo) / n_i^2, n_o the index on wo's side. This lobe is f = f_rad eta^2 = f_rad (n_i / n_o)^2 (no
    radiance factor, docs/physics.md section 14.3), so f(wo, wi) / n_i^2 = f(wi, wo) / n_o^2.
    Swapping the directions puts wi on the near side: eta -> 1/eta and the normals flip."""
    n = 5000
    for r in (0.2, 0.6, 1.0):
        for n_o, n_i in ((1.0, 1.5), (1.5, 1.0), (1.33, 2.4)):
            wo, wi = _pairs(n, 12, transmit=True)
            fwd = _f(params(B.DIELECTRIC, n, r, eta=n_i / n_o), wo, wi, frame(n))
            back = _f(params(B.DIELECTRIC, n, r, eta=n_o / n_i), wi, wo, -frame(n))
            ok = fwd[:, 0] > 0
            assert ok.mean() > 0.1
            a, b = fwd[ok] / n_i ** 2, back[ok] / n_o ** 2
            # float32: near total internal reflection 1 - F keeps few digits, so small values
            # get an absolute tolerance of 1e-3 of the median
            np.testing.assert_allclose(a, b, rtol=3e-3, atol=1e-3 * float(np.median(b)))
            assert (back[~ok] == 0).all()  # the same pairs are invalid (back-facing microfacets) both ways


# ----------------------------------------------------------------------------- independent quadrature
def _quadrature_albedo(p1, wo1, n_theta=400, n_phi=200):
    """int f cos dw over the whole sphere of evaluate(), theta by Gauss-Legendre in four ranges
    (the reflected and refracted peaks resolved) and phi by the midpoint rule."""
    x, w = np.polynomial.legendre.leggauss(n_theta // 4)
    edges = [0, np.pi / 4, np.pi / 2, 3 * np.pi / 4, np.pi]
    th = np.concatenate([0.5 * (a + b) + 0.5 * (b - a) * x for a, b in zip(edges[:-1], edges[1:])])
    wt = np.concatenate([0.5 * (b - a) * w for a, b in zip(edges[:-1], edges[1:])])
    ph = (np.arange(n_phi) + 0.5) / n_phi * 2 * np.pi
    T, P = np.meshgrid(th, ph, indexing="ij")
    wi = world(T, P).reshape(-1, 3).astype(np.float32)
    m = len(wi)
    rep = B.SurfaceParams(*(np.repeat(getattr(p1, f), m, axis=0) for f in
                            ("lobe", "base", "edge", "alpha", "eta", "spec_f0", "spec_tint")))
    fc, _ = B.evaluate(rep, np.repeat(wo1, m, 0), wi, frame(m), frame(m))
    dA = (np.sin(T) * wt[:, None] * (2 * np.pi / n_phi)).ravel()
    return float((fc[:, 0] * dA).sum())


@pytest.mark.slow
@pytest.mark.parametrize("lobe,kw", [(B.CONDUCTOR, dict(base=0.9, edge=0.5)), (B.CONDUCTOR, dict(base=1.0)),
                                     (B.DIELECTRIC, dict(eta=1.5)), (B.DIELECTRIC, dict(eta=1 / 1.5)),
                                     (B.PLASTIC, dict(base=0.6, spec_f0=0.04)), (B.GLOSSY, dict(base=0.5)),
                                     (B.LAMBERT, dict(base=0.7))])
@pytest.mark.parametrize("r,theta_deg", [(0.35, 30.0), (0.7, 70.0), (1.0, 0.0)])
def test_mc_albedo_matches_quadrature(lobe, kw, r, theta_deg):
    th = math.radians(theta_deg)
    p = params(lobe, 200_000, r, **kw)
    a, se, _, _ = _albedo(p, th, seed=9)
    q = _quadrature_albedo(p.take(np.arange(1)), wo_at(th, 1))
    print(f"lobe {lobe} {kw} r {r} theta {theta_deg}: MC {a:.5f} +- {se:.5f}, quadrature {q:.5f}")
    assert abs(a - q) < Z * se + 2e-3 * q


@pytest.mark.slow
def test_tables_match_an_independent_quadrature():
    """The white conductor's compensated albedo by wi-space quadrature (independent of the
    visible-normal quadrature that built the tables) is 1 within TABLE_TOL, also between nodes."""
    worst = 0.0
    for r in (0.37, 0.45, 0.55, 0.66, 0.81, 0.98):  # lobes the 400 x 200 wi quadrature resolves at grazing too
        for t in (5.0, 37.0, 63.0, 78.0):
            th = math.radians(t)
            for p in (params(B.CONDUCTOR, 1, r, base=1.0), params(B.DIELECTRIC, 1, r, eta=1.45),
                      params(B.DIELECTRIC, 1, r, eta=1 / 1.45)):
                q = _quadrature_albedo(p, wo_at(th, 1))
                worst = max(worst, abs(q - 1.0))
    print(f"largest |albedo - 1| of the compensated white lobes: {worst:.4f}")
    assert worst < TABLE_TOL


# ----------------------------------------------------------------------------- side rules
def test_no_light_leaks_with_a_tilted_shading_normal():
    """With ng tilted from ns, reflections stay on wo's side of ng and transmissions cross it;
    evaluate() gives zero to pairs on the wrong side of either normal."""
    n = 50_000
    rng = np.random.default_rng(4)
    ng = np.array([0.0, 0.0, 1.0])
    ns_v = np.array([0.5, 0.0, 0.866])
    wo = np.tile([-0.8, 0.0, 0.6], (n, 1)).astype(np.float32)  # above both
    nsn, ngn = np.tile(ns_v, (n, 1)).astype(np.float32), np.tile(ng, (n, 1)).astype(np.float32)
    for p in (params(B.LAMBERT, n, 0.5), params(B.CONDUCTOR, n, 0.8), params(B.DIELECTRIC, n, 0.8, eta=1.5),
              params(B.PLASTIC, n, 0.8, base=0.5, spec_f0=0.04)):
        wi, w, pdf, fl = B.sample(p, wo, nsn, ngn, rng.random((n, 3), dtype=np.float32))
        side = wi @ ng
        refl = (fl & (B.DIFFUSE_REFLECTION | B.GLOSSY_REFLECTION)) != 0
        assert (side[refl] > 0).all() and (side[(fl & B.TRANSMISSION) != 0] < 0).all()
        assert (fl == 0).any()  # some samples are refused (ns-side reflections below ng)
        # a direction above ns but below ng, and one below ns but above ng: zero
        bad = np.tile([[0.95, 0.0, -0.1], [-0.3, 0.0, 0.1]], (n // 2, 1)).astype(np.float32)
        bad /= np.linalg.norm(bad, axis=1, keepdims=True)
        fc, pe = B.evaluate(p, wo, bad, nsn, ngn)
        assert (fc == 0).all() and (pe == 0).all()


# ----------------------------------------------------------------------------- materials
def _materials():
    return Materials.from_list([
        {"name": "gold", "kind": "MIRROR", "color": (1.0, 0.78, 0.34), "metallic": 1.0, "roughness": 0.4,
         "specular_tint": (1.0, 0.9, 0.6), "conductor_fresnel": "F82_TINT"},
        {"name": "frosted", "kind": "DIELECTRIC", "ior": 1.5, "roughness": 0.3},
        {"name": "plastic", "kind": "DIFFUSE", "color": (0.2, 0.5, 0.8), "roughness": 0.5, "ior": 1.5,
         "specular_ior_level": 0.5},
        {"name": "half", "kind": "DIFFUSE", "color": (0.5, 0.5, 0.5), "metallic": 0.3, "transmission": 0.5,
         "ior": 1.45, "specular_ior_level": 0.25, "roughness": 0.2},
        {"name": "mirror", "kind": "MIRROR", "color": (0.9, 0.9, 0.9)},
        {"name": "chalk", "kind": "DIFFUSE"},
    ])


def test_material_columns_defaults_and_validation():
    m = _materials()
    assert list(m.metallic) == [1.0, 0.0, 0.0, pytest.approx(0.3), 1.0, 0.0]  # mirror: 1 by its kind
    assert list(m.transmission) == [0.0, 1.0, 0.0, 0.5, 0.0, 0.0]  # glass: 1 by its kind
    assert m.specular_ior_level[-1] == 0.0 and m.roughness[-1] == 0.0  # old rows: smooth, no layer
    assert list(m.conductor_fresnel) == [1, 0, 0, 0, 0, 0]
    for bad, text in ((dict(roughness=1.5), "roughness must be between 0 and 1"),
                      (dict(metallic=-0.1), "metallic must be between 0 and 1"),
                      (dict(transmission=float("nan")), "transmission is NaN"),
                      (dict(specular_ior_level=-1.0), "specular ior level must be >= 0"),
                      (dict(specular_ior_level=0.5, ior=0.5), "IOR must be >= 1")):
        s = Scene(materials=Materials.from_list([dict(name="x", **bad)]), camera=Camera())
        with pytest.raises(SceneError, match=text):
            validate(s)
    with pytest.raises(SceneError, match="conductor_fresnel"):
        Materials.from_list([{"conductor_fresnel": "SCHLICK"}])


def test_material_columns_npz_round_trip_and_older_files(tmp_path):
    s = Scene(materials=_materials(), camera=Camera())
    save_scene(s, tmp_path / "a.npz")
    back = load_scene(tmp_path / "a.npz").materials
    for name in ("roughness", "metallic", "transmission", "specular_ior_level", "specular_tint", "conductor_fresnel"):
        np.testing.assert_array_equal(getattr(back, name), getattr(s.materials, name))
    # a file written before the columns: its mirrors are metals, its glass is glass, all smooth
    with np.load(tmp_path / "a.npz") as z:
        old = {k: z[k] for k in z.files if not any(k == "material_" + c for c in
               ("roughness", "metallic", "transmission", "specular_ior_level", "specular_tint", "conductor_fresnel"))}
    np.savez(tmp_path / "old.npz", **old)
    m = load_scene(tmp_path / "old.npz").materials
    assert list(m.metallic) == [1, 0, 0, 0, 1, 0] and list(m.transmission) == [0, 1, 0, 0, 0, 0]
    assert (m.roughness == 0).all() and (m.specular_ior_level == 0).all() and (m.conductor_fresnel == 0).all()
    validate(load_scene(tmp_path / "old.npz"))


def test_params_from_materials():
    conv = SpectralConverter()
    pm = prepare_materials(_materials(), conv)
    n = len(conv.grid.wavelengths)
    mat = np.array([0, 1, 1, 2, 5, 4])
    front = np.array([True, True, False, True, True, True])
    p = B.params_from_materials(pm, mat, front)
    assert list(p.lobe) == [B.CONDUCTOR, B.DIELECTRIC, B.DIELECTRIC, B.PLASTIC, B.LAMBERT, B.GLOSSY]
    np.testing.assert_allclose(p.eta, [1, 1.5, 1 / 1.5, 1, 1, 1], rtol=1e-6)
    np.testing.assert_allclose(p.alpha, [0.16, 0.09, 0.09, 0.25, 0, 0], rtol=1e-5)
    np.testing.assert_allclose(p.spec_f0[3], 0.04, rtol=1e-5)  # IOR 1.5 at level 0.5: the physical F0
    assert p.base.shape == (6, n) and (p.edge[1:] == 1).all() and (p.edge[0] < 1).any()
    # mono rays: one wavelength each; a texture's roughness overrides the table
    lam = np.array([0, 3, 5, 7, 9, 11])
    q = B.params_from_materials(pm, mat, front, lam=lam, roughness=np.full(6, 0.5, np.float32))
    assert q.base.shape == (6, 1) and (q.alpha == 0.25).all()
    np.testing.assert_allclose(q.base[:, 0], pm.reflectance[mat, lam])
    # Principled layers drawn per hit: metal 0.3, glass 0.7 x 0.5, base the rest
    k = 200_000
    u = np.random.default_rng(2).random(k)
    r = B.params_from_materials(pm, np.full(k, 3), np.ones(k, bool), u_layer=u)
    frac = [(r.lobe == c).mean() for c in (B.GLOSSY, B.DIELECTRIC, B.PLASTIC)]
    np.testing.assert_allclose(frac, [0.3, 0.35, 0.35], atol=4 * math.sqrt(0.25 / k))
    np.testing.assert_allclose(r.spec_f0[r.lobe == B.PLASTIC], ((0.45 / 2.45) ** 2) * 0.5, rtol=1e-5)


def test_tangent_frame_is_orthonormal_and_right_handed():
    """docs/physics.md section 4.8: Duff et al. 2017's basis, checked on random normals and the
    poles (n_z = +-1, 0)."""
    from opal_diffraction.core.materials.bsdf import tangent_frame

    n = np.random.default_rng(5).normal(size=(2000, 3))
    n = np.concatenate([n, [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, 1, 0], [0.6, 0.8, 0.0]]])
    n = (n / np.linalg.norm(n, axis=1, keepdims=True)).astype(np.float32)
    u, v = tangent_frame(n)
    dot = lambda a, b: np.einsum("ij,ij->i", a, b)  # noqa: E731
    for a, b in ((u, v), (u, n), (v, n)):
        assert np.abs(dot(a, b)).max() < 1e-5
    for a in (u, v):
        assert np.abs(np.linalg.norm(a, axis=1) - 1).max() < 1e-5
    assert np.abs(np.cross(u, v) - n).max() < 1e-5


@pytest.mark.parametrize("lobe", [B.CONDUCTOR, B.GLOSSY, B.DIELECTRIC])
def test_with_outgoing_changes_no_value(lobe):
    """with_outgoing() only moves work (the frame, F82's b, the multiscatter factor) to once per
    hit: evaluate and sample give the same numbers with and without it, on varied hits (random
    shading normals, directions on both sides, a smooth row, F82 tints), also after take()."""
    rng = np.random.default_rng(5)
    n, k = 400, 3
    p = params(lobe, n, 0.4, eta=1.5, base=rng.uniform(0.2, 1.0, (n, k)), edge=rng.uniform(0.3, 1.0, (n, k)), k=k)
    p.alpha[:5] = 1e-6  # smooth rows: delta events
    ns = rng.normal(size=(n, 3)).astype(np.float32)
    ns /= np.linalg.norm(ns, axis=1, keepdims=True)
    wo = (ns + 0.9 * rng.normal(size=(n, 3))).astype(np.float32)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    wi = rng.normal(size=(n, 3)).astype(np.float32)
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    u = rng.random((n, 3), dtype=np.float32)
    q = B.with_outgoing(p, wo, ns)
    assert (q.ms is not None) == (lobe != B.DIELECTRIC)
    for a, b in zip(B.evaluate(p, wo, wi, ns, ns), B.evaluate(q, wo, wi, ns, ns)):
        np.testing.assert_allclose(a, b, rtol=2e-6, atol=1e-7)
    for a, b in zip(B.sample(p, wo, ns, ns, u), B.sample(q, wo, ns, ns, u)):
        np.testing.assert_allclose(a, b, rtol=2e-6, atol=1e-7)
    rows = np.flatnonzero(rng.random(n) < 0.5)
    for a, b in zip(B.evaluate(p.take(rows), wo[rows], wi[rows], ns[rows], ns[rows]),
                    B.evaluate(q.take(rows), wo[rows], wi[rows], ns[rows], ns[rows])):
        np.testing.assert_allclose(a, b, rtol=2e-6, atol=1e-7)
