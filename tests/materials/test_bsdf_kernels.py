"""The compiled kernels of core/materials/bsdf.py (``_evaluate_kernel``, ``_sample_kernel``,
``_outgoing_kernel``, ``_prepare_kernel``, ``_gather_kernel``) against their NumPy reference.

- evaluate, with_outgoing and params_from_materials: the reference's float32 (and, for the
  PLASTIC layer's average Fresnel, float64) operations in its order, so the same bits, on random
  hits of every lobe code with the edge cases mixed in: roughness 0 / just below / at
  MIN_ROUGHNESS and 1, grazing wo and wi, wi below the surface or on the wrong side of ng, wo
  below ns, indices near 1 (straight passes), eta < 1 (total internal reflection), F0 = 0 and
  above 0.99, tints above 1; white rays (k = 61 and other widths) and mono rays (k = 1).
- sample: the kernel draws through libm's float32 sine and cosine, the reference through NumPy's
  own SIMD ones (an ulp apart at times). With libm's functions put into the reference (its module's
  ``np`` seen through a proxy) the two give the same bits; against the plain reference the
  directions agree to 1e-4, the weights and pdfs to 1e-2 relative (grazing hits and the sharp
  peaks of a rough dielectric amplify a direction's ulp; typically 1e-6), the flags everywhere.
- a whole render of a rough metal, a Principled plastic and a rough glass with the BSDF kernels
  against the same render with bsdf.py on its reference (libm's sine and cosine): the same image.
"""

from __future__ import annotations

import types

import numpy as np
import pytest

from opal_diffraction.core.materials import bsdf as B
from opal_diffraction.core.materials.spectra import prepare_materials
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.spectral.spectrum import SpectralConverter
from opal_diffraction.core.util import jit

pytestmark = pytest.mark.skipif(not jit.AVAILABLE, reason=f"no JIT: {jit.UNAVAILABLE_REASON}")

LOBES = (B.LAMBERT, B.CONDUCTOR, B.DIELECTRIC, B.PLASTIC, B.GLOSSY)
MIXED = "mixed"


def _unit(v):
    return (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)


def _tilt(ns, cos, rng):
    """Unit directions at cosine ``cos`` (B,) from ns, random azimuth."""
    t = _unit(np.cross(ns, rng.normal(size=ns.shape)))
    sin = np.sqrt(np.maximum(0.0, 1.0 - cos * cos))
    return _unit(cos[:, None] * ns + sin[:, None] * t)


def hits(seed, n, k, lobes):
    """Random hits of ``lobes`` (one code or MIXED) with the edge cases mixed in."""
    rng = np.random.default_rng(seed)
    codes = np.array(LOBES if lobes == MIXED else (lobes,), np.int32)
    lobe = rng.choice(codes, n).astype(np.int32)
    rough = np.where(rng.random(n) < 0.5, rng.random(n),
                     rng.choice([0.0, 0.5 * B.MIN_ROUGHNESS, B.MIN_ROUGHNESS, 0.02, 0.3, 0.5, 1.0], n))
    eta = rng.choice([1.0, 1.0 + 5e-5, 1.0 + 2e-4, 1.05, 1.33, 1.5, 1 / 1.5, 2.4, 1 / 2.4], n)
    spec_f0 = rng.choice([0.0, 1e-4, 0.02, 0.04, 0.08, 0.5, 0.99, 1.2], n)
    p = B.SurfaceParams(lobe, rng.random((n, k), dtype=np.float32), (0.5 + rng.random((n, k))).astype(np.float32),
                        (rough * rough).astype(np.float32), np.where(lobe == B.DIELECTRIC, eta, 1.0).astype(np.float32),
                        np.where(lobe == B.PLASTIC, spec_f0, 0.0).astype(np.float32),
                        (1.3 * rng.random((n, k))).astype(np.float32))
    ns = _unit(rng.normal(size=(n, 3)))
    ng = np.where((rng.random(n) < 0.7)[:, None], ns, _unit(ns + 0.3 * rng.normal(size=(n, 3))))
    # wo: mostly above ns, some grazing (cos 1e-4 .. 1e-2), a few below
    cos_o = np.where(rng.random(n) < 0.15, 10.0 ** rng.uniform(-4, -2, n), rng.uniform(-0.1, 1.0, n))
    wo = _tilt(ns, cos_o, rng)
    # wi: anywhere, some grazing on either side, some the mirror direction about ns
    cos_i = np.where(rng.random(n) < 0.15, rng.choice([-1, 1], n) * 10.0 ** rng.uniform(-4, -2, n),
                     rng.uniform(-1.0, 1.0, n))
    wi = _tilt(ns, cos_i, rng)
    mirror = rng.random(n) < 0.1
    wi[mirror] = _unit(2 * np.sum(wo * ns, 1)[:, None] * ns - wo)[mirror]
    u = rng.random((n, 3), dtype=np.float32)
    u[rng.random(n) < 0.05] = 0.0  # the sampling square's edges
    return p, wo, wi, ns, ng.astype(np.float32), u


def _reference(fn, *args, **kwargs):
    with jit.kernel_mode("numpy"), np.errstate(all="ignore"):
        return fn(*args, **kwargs)


def _same(a, b, what):
    """Bit-identical (NaNs in the same places count as equal)."""
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape and a.dtype == b.dtype, what
    eq = (a == b) | (np.isnan(a) & np.isnan(b)) if a.dtype.kind == "f" else a == b
    assert eq.all(), f"{what}: {int((~eq).sum())} entries differ, e.g. {a[~eq][:3]} vs {b[~eq][:3]}"


class _LibmNumpy(types.ModuleType):
    """numpy with libm's float32 / float64 sine and cosine (numba's), for bsdf.py's module global ``np``."""

    def __init__(self):
        super().__init__("numpy_libm")
        from numba import vectorize

        self.cos = vectorize(["float32(float32)", "float64(float64)"])(lambda x: np.cos(x))
        self.sin = vectorize(["float32(float32)", "float64(float64)"])(lambda x: np.sin(x))

    def __getattr__(self, name):
        return getattr(np, name)


@pytest.fixture(scope="module")
def libm_numpy():
    B._tables_f32()  # the tables before any swap (they are the reference's either way)
    return _LibmNumpy()


CASES = [(lobes, k) for lobes in LOBES + (MIXED,) for k in (1, 61)] + [(MIXED, 7), (B.PLASTIC, 9), (MIXED, 200)]


@pytest.mark.parametrize("lobes,k", CASES)
def test_evaluate_and_with_outgoing_are_the_reference_bit_for_bit(lobes, k):
    p, wo, wi, ns, ng, _ = hits(11 + k, 3000, k, lobes)
    q, q_ref = B.with_outgoing(p, wo, ns), _reference(B.with_outgoing, p, wo, ns)
    for name in ("frame_u", "frame_v", "wo_local", "f82", "ms"):
        a, b = getattr(q, name), getattr(q_ref, name)
        assert (a is None) == (b is None), name
        if a is not None:
            _same(a, b, name)
    if lobes in (B.CONDUCTOR, B.GLOSSY):
        assert q.ms is not None  # the precomputed factors are exercised
    for pp, pr in ((p, p), (q, q_ref)):  # without and with the outgoing terms
        fcos, pdf = B.evaluate(pp, wo, wi, ns, ng)
        fcos_r, pdf_r = _reference(B.evaluate, pr, wo, wi, ns, ng)
        _same(fcos, fcos_r, "f cos")
        _same(pdf, pdf_r, "pdf")
        assert (fcos > 0).any() and np.isfinite(fcos).all() and (fcos >= 0).all()


@pytest.mark.parametrize("lobes,k", CASES)
def test_sample_is_the_reference_with_libm_sine_and_cosine(lobes, k, libm_numpy, monkeypatch):
    p, wo, _, ns, ng, u = hits(23 + k, 3000, k, lobes)
    q = B.with_outgoing(p, wo, ns)
    for pp in (p, q):
        out = B.sample(pp, wo, ns, ng, u)
        plain = _reference(B.sample, pp, wo, ns, ng, u)
        with monkeypatch.context() as mp:
            mp.setattr(B, "np", libm_numpy)
            ref = _reference(B.sample, pp, wo, ns, ng, u)
        for a, b, what in zip(out, ref, ("wi", "weight", "pdf", "flags")):
            _same(a, b, what)
        flags = out[3]
        assert (flags != 0).mean() > 0.3 and np.isfinite(out[1]).all() and (out[1] >= 0).all()
        # against NumPy's own sine and cosine: close, the same events
        _same(flags, plain[3], "flags (NumPy's sin / cos)")
        np.testing.assert_allclose(out[0], plain[0], rtol=0, atol=1e-4)
        np.testing.assert_allclose(out[1], plain[1], rtol=1e-2, atol=1e-7)
        fin = np.isfinite(plain[2])
        _same(np.isfinite(out[2]), fin, "finite pdfs")
        np.testing.assert_allclose(out[2][fin], plain[2][fin], rtol=1e-2, atol=1e-7)


def test_sample_kernel_at_the_sampling_square_corners(libm_numpy, monkeypatch):
    """u at 0 and just below 1 (VNDF's disk centre and rim; the concentric map's axes), every
    lobe, roughness at MIN_ROUGHNESS and 1."""
    n, k = 600, 5
    p, wo, _, ns, ng, _ = hits(5, n, k, MIXED)
    p.alpha[: n // 2] = np.float32(B.MIN_ROUGHNESS) ** 2
    p.alpha[n // 2:] = 1.0
    top = np.nextafter(np.float32(1), np.float32(0))
    u = np.random.default_rng(6).choice(np.array([0.0, 0.25, 0.5, top], np.float32), (n, 3))
    out = B.sample(p, wo, ns, ng, u)
    with monkeypatch.context() as mp:
        mp.setattr(B, "np", libm_numpy)
        ref = _reference(B.sample, p, wo, ns, ng, u)
    for a, b, what in zip(out, ref, ("wi", "weight", "pdf", "flags")):
        _same(a, b, what)


def _materials():
    return Materials.from_list([
        {"name": "gold", "kind": "MIRROR", "color": (1.0, 0.78, 0.34), "metallic": 1.0, "roughness": 0.3,
         "specular_tint": (1.0, 0.9, 0.6), "conductor_fresnel": "F82_TINT"},
        {"name": "frosted", "kind": "DIELECTRIC", "ior": 1.5, "roughness": 0.2},
        {"name": "flint", "kind": "DIELECTRIC", "ior": 1.6, "dispersion": "ABBE", "abbe": 30.0, "roughness": 0.1},
        {"name": "plastic", "kind": "DIFFUSE", "color": (0.2, 0.5, 0.8), "roughness": 0.5, "ior": 1.5,
         "specular_ior_level": 0.5, "specular_tint": (1.0, 0.5, 0.2)},
        {"name": "half", "kind": "DIFFUSE", "color": (0.5, 0.5, 0.5), "metallic": 0.3, "transmission": 0.5,
         "ior": 1.45, "specular_ior_level": 0.25, "roughness": 0.2, "specular_tint": (1.5, 1.0, 0.3)},
        {"name": "glossy", "kind": "MIRROR", "color": (0.9, 0.9, 0.9), "roughness": 0.6},
        {"name": "chalk", "kind": "DIFFUSE"},
    ])


@pytest.mark.parametrize("mono", [False, True])
def test_params_from_materials_kernel_is_the_reference(mono):
    conv = SpectralConverter()
    pm = prepare_materials(_materials(), conv)
    n = len(conv.grid.wavelengths)
    rng = np.random.default_rng(3)
    b = 5000
    mat = rng.integers(0, len(pm.kind), b)
    front = rng.random(b) < 0.6
    lam = rng.integers(0, n, b) if mono else None
    for kw in ({}, {"u_layer": rng.random(b)},
               {"base": rng.random((b, 1 if mono else n), dtype=np.float32),
                "roughness": rng.random(b, dtype=np.float32), "u_layer": rng.random(b)}):
        p = B.params_from_materials(pm, mat, front, lam, **kw)
        r = _reference(B.params_from_materials, pm, mat, front, lam, **kw)
        for f in ("lobe", "base", "edge", "alpha", "eta", "spec_f0", "spec_tint"):
            _same(getattr(p, f), getattr(r, f), f)
        assert set(np.unique(p.lobe)) >= {B.CONDUCTOR, B.DIELECTRIC, B.PLASTIC}
    # one material and lobe per batch (the rows then broadcast from one): the same values, and
    # evaluate / sample / with_outgoing on them the same bits as on the reference's own arrays
    for m in range(len(pm.kind)):
        one = np.full(400, m)
        p = B.params_from_materials(pm, one, front[:400], lam if lam is None else lam[:400])
        r = _reference(B.params_from_materials, pm, one, front[:400], lam if lam is None else lam[:400])
        for f in ("lobe", "base", "edge", "alpha", "eta", "spec_f0", "spec_tint"):
            _same(getattr(p, f), getattr(r, f), f)
        _, wo, wi, ns, ng, u = hits(m, 400, 1, B.LAMBERT)
        q, q_ref = B.with_outgoing(p, wo, ns), _reference(B.with_outgoing, r, wo, ns)
        _same(q.ms if q.ms is not None else 0, q_ref.ms if q_ref.ms is not None else 0, "ms")
        for a, b in zip(B.evaluate(q, wo, wi, ns, ng), _reference(B.evaluate, q_ref, wo, wi, ns, ng)):
            _same(a, b, "evaluate")
        a, b = B.sample(q, wo, ns, ng, u), _reference(B.sample, q_ref, wo, ns, ng, u)
        _same(a[3], b[3], "flags")
        np.testing.assert_allclose(a[1], b[1], rtol=1e-2, atol=1e-7)


# ------------------------------------------------------------------------------------ a whole render
def _render_scene() -> Scene:
    """A grey floor under an area light with a rough gold sphere, a Principled plastic one and a rough glass one."""
    mats = Materials.from_list([
        {"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
        {"kind": "MIRROR", "color": (0.95, 0.7, 0.4), "roughness": 0.3, "metallic": 1.0},
        {"kind": "DIFFUSE", "color": (0.8, 0.2, 0.1), "ior": 1.5, "specular_ior_level": 0.5, "roughness": 0.5},
        {"kind": "DIELECTRIC", "color": (1.0, 1.0, 1.0), "ior": 1.5, "roughness": 0.2},
    ])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((-4, -4, 0), (8, 0, 0), (0, 8, 0)), material=0)
    for i, x in enumerate((-1.1, 0.0, 1.1)):
        v, t = primitives.uv_sphere((x, 0.0, 0.5), 0.5, segments=24, rings=12)[:2]
        s.add_mesh(v, t, material=1 + i, normals=(v - np.array([x, 0.0, 0.5], np.float32)) / 0.5)
    d = np.array([1.0, 1.5, -3.0])
    d /= np.linalg.norm(d)
    s.lights = Lights.from_list([{"kind": "AREA_RECT", "position": (-1.0, -1.5, 3.0), "direction": tuple(d),
                                  "power": 400.0, "size_u": 2.0, "size_v": 2.0, "axis_u": (1, 0, 0)}])
    s.camera = Camera.look_at((0.0, -4.0, 1.8), (0.0, 0.0, 0.5), lens=40.0, width=32, height=20)
    return s


def test_render_with_the_bsdf_kernels_is_the_reference_render(libm_numpy, monkeypatch):
    """Every other kernel on in both renders; bsdf.py's kernels against its reference (with libm's
    sine and cosine): the same image, bit for bit."""
    settings = RenderSettings(samples=8, seed=7, threads=1, light_paths=0)
    a = render(_render_scene(), settings, spectral_film=True).spectral
    with monkeypatch.context() as mp:
        mp.setattr(B, "kernels_enabled", lambda: False)
        mp.setattr(B, "np", libm_numpy)
        b = render(_render_scene(), settings, spectral_film=True).spectral
    assert np.isfinite(a).all() and (a >= 0).all() and a.mean() > 0
    _same(a, b, "image")
