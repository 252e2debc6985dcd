"""Principled's coat and sheen as layers of the lobe mixture (core/materials/sheen.py,
core/materials/mixtures.py ``coat_sheen_layers``; docs/physics.md section 14.10).

- The sheen table is the published one (entries of Blender's ``table_sheen_ltc`` as printed in
  its source), and the sheen lobe's sampler draws its density (chi-square, tests/chi2.py), a
  density that integrates to 1 over the hemisphere (the transform keeps the upper hemisphere).
- The coat's directional albedo that the layering keeps from the base (bsdf.coat_albedo, from the
  tables) against a brute-force quadrature of the coat lobe's f cos over the hemisphere; a
  smooth coat's against the Fresnel reflectance (closed form).
- Energy bookkeeping: a white Lambert base under a white coat, a white sheen, or both reflects
  what arrives (white furnace: the bounce's mixture weight averages 1 within the tables'
  accuracy, never above), and a coloured base stays below.
- The whole layered mixture's sampling (the sheen, coat and base drawn with their probabilities,
  each lobe sampled) has the mixture's pdf (chi-square).
- The coat's tint absorbs the base's light by T^(1 / cos_t), cos_t the refracted cosine (Snell),
  mixed by the coat weight, as Cycles' principled closure does.
- The coat lobe (a PLASTIC lobe of zero base) goes through the compiled BSDF kernels with the
  reference's bits.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import norm

from chi2 import chi2_directions
from opal_diffraction.core.materials import bsdf as B
from opal_diffraction.core.materials.mixtures import LobeMixture
from opal_diffraction.core.materials.sheen import ltc_coefficients
from opal_diffraction.core.materials.spectra import prepare_materials
from opal_diffraction.core.scene.model import Materials
from opal_diffraction.core.spectral.optics import fresnel_dielectric
from opal_diffraction.core.spectral.spectrum import SpectralConverter
from opal_diffraction.core.util import jit

Z = norm.isf(1e-3 / 2)
P_MIN = 1e-3
ROWS = {
    "coat": dict(coat_weight=1.0, coat_roughness=0.3),
    "sheen": dict(sheen_weight=1.0, sheen_roughness=0.5),
    "both": dict(coat_weight=1.0, coat_roughness=0.3, sheen_weight=1.0, sheen_roughness=0.5),
    "red_both": dict(coat_weight=1.0, coat_roughness=0.3, sheen_weight=1.0, sheen_roughness=0.5, color=(0.8, 0.1, 0.1)),
    "tinted": dict(coat_weight=0.7, coat_roughness=0.05, coat_tint=(0.3, 0.6, 0.9), coat_ior=1.6),
    "clear": dict(coat_weight=0.7, coat_roughness=0.05, coat_ior=1.6),
}
NAMES = list(ROWS)


def _table(conv):
    rows = [dict(name=k, kind="DIFFUSE", color=v.pop("color", (1.0, 1.0, 1.0)), **v)
            for k, v in ((k, dict(v)) for k, v in ROWS.items())]
    return prepare_materials(Materials.from_list(rows), conv)


def _wo(theta_deg, n):
    t = math.radians(theta_deg)
    wo = np.tile([math.sin(t), 0.0, math.cos(t)], (n, 1)).astype(np.float32)
    return wo, np.tile([0.0, 0.0, 1.0], (n, 1)).astype(np.float32)


def _layered(pm, name, wo, ns, u_layer):
    """(bounce parameters, mixture) as the eye pass's surface_lobes makes them."""
    n = len(wo)
    mat = np.full(n, NAMES.index(name))
    front = np.ones(n, bool)
    mix = LobeMixture.of(pm, mat, front, np.ones(n, bool), pm.metallic[mat], pm.transmission[mat], wo, ns)
    u, top = mix.draw(u_layer)
    p = B.params_from_materials(pm, mat, front, u_layer=u)
    return B.with_outgoing(mix.put_top(p, top), wo, ns), mix


def test_sheen_table_is_the_published_one():
    """Entries of Blender's ``table_sheen_ltc`` (intern/cycles/scene/shader.tables) as printed there:
    plane a, rows 1 and 21 (roughness 1/31, 21/31); the table's shape and ranges."""
    from opal_diffraction.core.materials.sheen_ltc_table import A, ALBEDO, B as BT

    a = np.reshape(A, (32, 32))
    assert np.reshape(BT, (32, 32)).shape == np.reshape(ALBEDO, (32, 32)).shape == (32, 32)
    np.testing.assert_array_equal(a[1, :6], [0.01941, 0.01741, 0.04610, 0.10367, 0.06244, 0.23927])
    np.testing.assert_array_equal(a[21, :8], [0.38874, 0.42458, 0.46012, 0.48761, 0.51008, 0.52938, 0.54611, 0.56050])
    assert a[0, 0] == 0.01415 and not a[0, 1:].any()
    assert 0 <= min(ALBEDO) and max(ALBEDO) <= 1
    # the lookup is bilinear on the nodes (i / 31): a node reads its entry
    got = ltc_coefficients(np.float32([3 / 31]), np.float32([21 / 31]))[0]
    assert got[0] == pytest.approx(a[21, 3], rel=1e-5)


@pytest.mark.parametrize("theta_deg", [5.0, 50.0, 85.0])
@pytest.mark.parametrize("rough", [0.15, 0.5, 1.0])
def test_sheen_sampling_matches_its_density(theta_deg, rough):
    n = 100_000
    wo, ns = _wo(theta_deg, n)
    ones = np.ones((n, 1), np.float32)
    p = B.SurfaceParams(np.full(n, B.SHEEN, np.int32), ones, ones, np.full(n, rough, np.float32),
                        np.ones(n, np.float32), np.zeros(n, np.float32), ones)
    rng = np.random.default_rng(11)
    wi, w, pdf, flags = B.sample(p, wo, ns, ns, rng.random((n, 3), dtype=np.float32))
    ok = flags != 0
    assert ok.mean() > 0.999 and np.allclose(w[ok], 1.0)  # the lobe samples its own density
    f_at, p_at = B.evaluate(p, wo, wi, ns, ns)
    np.testing.assert_allclose(p_at[ok], pdf[ok], rtol=2e-3)
    np.testing.assert_allclose(f_at[ok, 0], p_at[ok], rtol=1e-6)

    def density(d):
        m = len(d)
        q = p.take(np.zeros(m, np.int64))
        return B.evaluate(q, np.tile(wo[:1], (m, 1)), d.astype(np.float32), np.tile(ns[:1], (m, 1)),
                          np.tile(ns[:1], (m, 1)))[1]

    pv, details, total = chi2_directions(wi[ok], density, (0, 0, 1), theta_max=math.pi / 2)
    print(f"theta {theta_deg} rough {rough}: {details}; integral {total:.4f}")
    assert pv > P_MIN / 9, details
    assert total == pytest.approx(1.0, abs=5e-3)  # a normalised density over the hemisphere


def _hemisphere(nt=256, nph=256):
    """(directions (N, 3), solid angles (N,)) of a midpoint grid in (cos theta, phi)."""
    mu = (np.arange(nt) + 0.5) / nt
    ph = (np.arange(nph) + 0.5) / nph * 2 * np.pi
    M, P = np.meshgrid(mu, ph, indexing="ij")
    s = np.sqrt(1 - M * M)
    d = np.stack([s * np.cos(P), s * np.sin(P), M], axis=-1).reshape(-1, 3)
    return d, np.full(len(d), 2 * np.pi / (nt * nph))


@pytest.mark.parametrize("rough", [0.05, 0.3, 0.6])
@pytest.mark.parametrize("theta_deg", [0.0, 45.0, 75.0])
def test_coat_albedo_is_the_coat_lobes_integral(rough, theta_deg):
    """bsdf.coat_albedo (what the layering keeps from the base) against the coat lobe's f cos
    integrated over the hemisphere (a midpoint rule; the sharp lobe at roughness 0.05 on a finer
    grid near its peak is not needed: its albedo is the Fresnel reflectance, checked in closed form)."""
    ior = 1.5
    f0 = ((ior - 1) / (ior + 1)) ** 2
    d, dw = _hemisphere()
    m = len(d)
    wo, ns = _wo(theta_deg, m)
    z1 = np.ones((m, 1), np.float32)
    p = B.SurfaceParams(np.full(m, B.PLASTIC, np.int32), np.zeros((m, 1), np.float32), z1,
                        np.full(m, rough * rough, np.float32), np.ones(m, np.float32), np.full(m, f0, np.float32), z1)
    e_table = float(B.coat_albedo(p.take(np.arange(1)), wo[:1, 2])[0])
    mu_o = math.cos(math.radians(theta_deg))
    if rough < 0.1:
        want = float(fresnel_dielectric(np.float64([mu_o]), np.float64([ior]))[0][0])
    else:
        f, _ = B.evaluate(p, wo, d.astype(np.float32), ns, ns)
        want = float((f[:, 0] * dw).sum())
    print(f"rough {rough} theta {theta_deg}: table {e_table:.4f}, integral {want:.4f}")
    assert abs(e_table - want) < 0.003  # the tables' accuracy


@pytest.mark.parametrize("name", ["coat", "sheen", "both", "red_both"])
@pytest.mark.parametrize("theta_deg", [0.0, 45.0, 80.0])
def test_layered_white_furnace(name, theta_deg):
    """The bounce's weight f_mix / p_mix over draws of the layered mixture: 1 on average for a
    white base (the coat keeps from the base what it reflects), below for a red one."""
    conv = SpectralConverter()
    pm = _table(conv)
    n = 100_000
    rng = np.random.default_rng(3)
    wo, ns = _wo(theta_deg, n)
    p, mix = _layered(pm, name, wo, ns, rng.random(n))
    wi, _, _, flags = B.sample(p, wo, ns, ns, rng.random((n, 3), dtype=np.float32))
    f, pdf = mix.evaluate(p, wo, wi, ns, ns)
    ok = (flags != 0) & (pdf > 0)
    x = np.where(ok[:, None], f / np.where(ok, pdf, 1)[:, None], 0.0).astype(np.float64)
    assert np.isfinite(x).all() and (x >= 0).all()
    a = x.mean(axis=1)
    se = a.std() / math.sqrt(n)
    print(f"{name} theta {theta_deg}: albedo {a.mean():.5f} +- {se:.5f}")
    assert a.mean() < 1.0 + Z * se + 0.005  # the tables' accuracy (test_bsdf TABLE_TOL)
    if name == "red_both":
        assert a.mean() < 0.9
    else:
        assert a.mean() > 1.0 - Z * se - 0.01


@pytest.mark.slow
@pytest.mark.parametrize("theta_deg", [20.0, 70.0])
def test_layered_mixture_sampling_has_the_mixture_pdf(theta_deg):
    """Directions drawn as the bounce draws them (sheen, coat or base by their probabilities, then
    that lobe's sampler) against p = sum_i P_i p_i (LobeMixture.evaluate's pdf)."""
    conv = SpectralConverter()
    pm = _table(conv)
    n = 200_000
    rng = np.random.default_rng(17)
    wo, ns = _wo(theta_deg, n)
    p, mix = _layered(pm, "red_both", wo, ns, rng.random(n))
    wi, _, _, flags = B.sample(p, wo, ns, ns, rng.random((n, 3), dtype=np.float32))
    ok = flags != 0

    def density(d):
        m = len(d)
        wo_m, ns_m = _wo(theta_deg, m)
        q, mx = _layered(pm, "red_both", wo_m, ns_m, np.full(m, 0.99))
        return mx.evaluate(q, wo_m, d.astype(np.float32), ns_m, ns_m)[1]

    pv, details, total = chi2_directions(wi[ok], density, (0, 0, 1), theta_max=math.pi / 2)
    print(f"theta {theta_deg}: {details}; integral {total:.4f}")
    assert pv > P_MIN / 2, details


def test_coat_tint_absorbs_the_base_by_its_optical_depth():
    """Away from the coat's (sharp, roughness 0.05) highlight the tinted and clear coats differ by
    the base's factor mix(1, T^(1 / cos_t), c), cos_t = sqrt(1 - sin^2(theta_o) / eta^2) (Snell)."""
    conv = SpectralConverter()
    pm = _table(conv)
    theta = 50.0
    got = []
    for n in (1, 4):  # one tinted hit too (a batch of one)
        wo, ns = _wo(theta, n)
        wi = np.tile([-0.3, 0.5, math.sqrt(1 - 0.34)], (n, 1)).astype(np.float32)  # far from the mirror direction
        for name in ("tinted", "clear"):
            p, mix = _layered(pm, name, wo, ns, np.full(n, 0.999))
            got.append(mix.evaluate(p, wo, wi, ns, ns)[0][-1].astype(np.float64))
    np.testing.assert_array_equal(got[0], got[2])
    got = got[2:]
    s = math.sin(math.radians(theta))
    cos_t = math.sqrt(1 - s * s / 1.6 ** 2)
    tint = conv.reflectance_from_rgb(np.array([0.3, 0.6, 0.9]))
    want = 1 + 0.7 * (tint ** (1 / cos_t) - 1)
    np.testing.assert_allclose(got[0] / got[1], want, rtol=1e-4)


@pytest.mark.skipif(jit.kernels_path() != "numba",  # no JIT, or OPAL_KERNELS=numpy (tests/conftest.py)
                    reason=f"no compiled kernels to compare: {jit.UNAVAILABLE_REASON or jit.KERNELS_ENV + '=numpy'}")
def test_coat_lobe_kernels_are_the_reference():
    """The coat's PLASTIC lobe of zero base: bsdf.evaluate with the compiled kernels gives the
    NumPy reference's bits."""
    conv = SpectralConverter()
    pm = _table(conv)
    n = 512
    rng = np.random.default_rng(2)
    wo, ns = _wo(35.0, n)
    mat = np.full(n, NAMES.index("coat"))
    wi = rng.normal(size=(n, 3))
    wi[:, 2] = np.abs(wi[:, 2])
    wi = (wi / np.linalg.norm(wi, axis=1, keepdims=True)).astype(np.float32)
    out = []
    for mode in ("auto", "numpy"):
        with jit.kernel_mode(mode):
            mix = LobeMixture.of(pm, mat, np.ones(n, bool), np.ones(n, bool), pm.metallic[mat],
                                 pm.transmission[mat], wo, ns)
            coat = mix.layers[mix.codes.index(3)]
            out.append(B.evaluate(coat, wo, wi, ns, ns))
    np.testing.assert_array_equal(out[0][0], out[1][0])
    np.testing.assert_array_equal(out[0][1], out[1][1])


@pytest.mark.parametrize("base", ["glass", "metal"])
@pytest.mark.parametrize("theta_deg", [0.0, 45.0, 80.0])
def test_coat_over_a_smooth_layer_furnace(base, theta_deg):
    """A rough coat over smooth white glass or a smooth white metal (delta lobes, weighted by their
    layer's W / P: LobeMixture.scale_singular): every bit of energy the coat leaves goes through
    (the furnace 1 within the tables' accuracy)."""
    row = dict(name=base, kind="DIELECTRIC" if base == "glass" else "MIRROR", color=(1.0, 1.0, 1.0),
               transmission=1.0 if base == "glass" else 0.0, metallic=1.0 if base == "metal" else 0.0,
               roughness=0.0, coat_weight=1.0, coat_roughness=0.2, conductor_fresnel="F82_TINT")
    pm = prepare_materials(Materials.from_list([row]), SpectralConverter())
    n = 100_000
    rng = np.random.default_rng(23)
    wo, ns = _wo(theta_deg, n)
    mat = np.zeros(n, np.int64)
    front = np.ones(n, bool)
    mix = LobeMixture.of(pm, mat, front, np.ones(n, bool), pm.metallic[mat], pm.transmission[mat], wo, ns)
    u, top = mix.draw(rng.random(n))
    p = B.with_outgoing(mix.put_top(B.params_from_materials(pm, mat, front, u_layer=u), top), wo, ns)
    wi, w, _, flags = B.sample(p, wo, ns, ns, rng.random((n, 3), dtype=np.float32))
    f, pdf = mix.evaluate(p, wo, wi, ns, ns)
    singular = (flags & B.SINGULAR) != 0
    assert singular.mean() > 0.5  # mostly the delta layer under the coat
    rough = (flags != 0) & ~singular & (pdf > 0)
    x = np.where(rough[:, None], f / np.where(rough, pdf, 1)[:, None], w)
    x = np.where((flags != 0)[:, None], mix.scale_singular(x, flags), 0.0).astype(np.float64).mean(axis=1)
    se = x.std() / math.sqrt(n)
    print(f"{base} theta {theta_deg}: albedo {x.mean():.5f} +- {se:.5f}")
    assert abs(x.mean() - 1.0) < Z * se + 0.005


@pytest.mark.skipif(jit.kernels_path() != "numba",  # no JIT, or OPAL_KERNELS=numpy (tests/conftest.py)
                    reason=f"no compiled kernels to compare: {jit.UNAVAILABLE_REASON or jit.KERNELS_ENV + '=numpy'}")
def test_a_batch_mixing_sheen_and_kernel_lobes_is_the_reference():
    """The bounce's parameters after put_top mix SHEEN rows (NumPy lines) with kernel lobes: with the
    kernels on, bsdf.evaluate gives the reference's bits and bsdf.sample its flags, and weights
    and pdfs within the kernels' sine / cosine ulps (test_bsdf_kernels' tolerance)."""
    conv = SpectralConverter()
    pm = _table(conv)
    n = 4000
    rng = np.random.default_rng(9)
    wo, ns = _wo(40.0, n)
    wi = rng.normal(size=(n, 3))
    wi[:, 2] = np.abs(wi[:, 2])
    wi = (wi / np.linalg.norm(wi, axis=1, keepdims=True)).astype(np.float32)
    u_layer, u = rng.random(n), rng.random((n, 3), dtype=np.float32)
    out = []
    for mode in ("auto", "numpy"):
        with jit.kernel_mode(mode):
            p, _ = _layered(pm, "both", wo, ns, u_layer)
            assert (p.lobe == B.SHEEN).any() and (p.lobe == B.PLASTIC).any()
            assert (B._sheen_split(p) is not None) == (mode == "auto")  # the split path is the one tested
            out.append((B.evaluate(p, wo, wi, ns, ns), B.sample(p, wo, ns, ns, u)))
    (e1, s1), (e2, s2) = out
    np.testing.assert_array_equal(e1[0], e2[0])
    np.testing.assert_array_equal(e1[1], e2[1])
    np.testing.assert_array_equal(s1[3], s2[3])
    np.testing.assert_allclose(s1[0], s2[0], atol=1e-4)
    np.testing.assert_allclose(s1[1], s2[1], rtol=1e-2, atol=1e-7)
