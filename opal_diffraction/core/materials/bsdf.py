"""Rough surfaces: GGX microfacet BSDFs as Cycles renders them, vectorised over a batch of hits.

Methods (formulas in docs/physics.md section 14):
- Trowbridge-Reitz (GGX) normal distribution D and the height-correlated Smith masking-shadowing
  G2 = 1 / (1 + Lambda(wo) + Lambda(wi)) (pbrt-v4, Pharr, Jakob & Humphreys 2023, section 9.6;
  Heitz 2014, "Understanding the masking-shadowing function", JCGT 3(2)).
- Sampling of the visible normals (Heitz 2018, "Sampling the GGX distribution of visible
  normals", JCGT 7(4)): pdf(wi) = D_wo(h) / (4 |wo.h|) for reflection, D_wo(h) |wi.h| /
  (wi.h + wo.h / eta)^2 for refraction (pbrt-v4 section 9.7).
- Conductors: Schlick's Fresnel with the F82-tint edge term of Cycles
  (``intern/cycles/kernel/closure/bsdf_util.h`` fresnel_f82 / fresnel_f82tint_B; Hoffman 2019,
  "Fresnel equations considered harmful"; Kutz et al. 2021, "Novel aspects of the Adobe Standard
  Material"): F = F_schlick(mu) - b mu (1 - mu)^6, b chosen so that F(1/7) = F_schlick(1/7) * tint.
- Rough dielectrics: reflection and refraction through microfacets (Walter, Marschner, Li &
  Torrance 2007, "Microfacet models for refraction through rough surfaces"; pbrt-v4
  DielectricBxDF) with the exact dielectric Fresnel at the microfacet, reflect / transmit chosen
  with probability F. Transmission carries no 1/eta^2 radiance factor, as the walker's smooth
  glass carries none (transport/walker.py): camera and lights sit outside closed glass, where the
  factors of entering and leaving cancel, so leaving it out at every interface keeps a closed
  object of any mix of smooth and rough faces lossless (docs/physics.md section 14.3).
- Multiple scattering: Cycles' "Multiscatter GGX" energy preservation
  (``bsdf_microfacet.h`` microfacet_ggx_preserve_energy; Turquin 2019, "Practical multiple
  scattering compensation for microfacet models", with the multi-bounce Fresnel of Kulla & Conty
  2017, "Revisiting physically based shading at Imageworks"): the single-scattering lobe times
  1 + F_ms (1 - E(mu_o)) / E(mu_o), F_ms = F_avg E_avg / (1 - F_avg (1 - E_avg)). E(mu, roughness)
  is the single-scattering albedo, tabulated once (first use) by quadrature over the visible-normal
  parameter square; glass uses its own table of reflect + transmit albedo, as Cycles does. The
  factor depends on wo only, as in Cycles, so the compensated lobe is not exactly reciprocal
  (:func:`energy_compensation` gives the factor so that the single-scattering part can be checked).
- Principled's dielectric specular layer over a diffuse base (PLASTIC): Cycles' generalized
  Schlick Fresnel F = mix(F0 * tint, 1, s), s = (F_real - F0) / (1 - F0), and the base scaled by
  1 - E_spec(mu_o), the specular layer's directional albedo (Cycles ``closure_layering_weight``;
  here per wavelength rather than by the maximum channel), tabulated the same way.
- Lambert: cosine-weighted sampling (Malley's method, concentric disk).
- Oren-Nayar (the Diffuse BSDF's Roughness sigma > 0), as Cycles 4.3+ has it
  (``intern/cycles/kernel/closure/bsdf_oren_nayar.h``): Fujii's improved Oren-Nayar ("A tiny
  improvement of Oren-Nayar reflectance model", mimosa-pudica.net) with A = 1 / (pi + sigma
  (pi/2 - 2/3)), B = sigma A, f = rho (A + B t), t = (wi.wo - mu_i mu_o) / max(mu_i, mu_o) where
  positive, plus OpenPBR's energy-preserving multiple scattering rho E_ms (1 - E(mu_o)) (1 - E(mu_i)),
  E(mu) = A pi + B G(mu), E_avg = A pi + (2 pi - 5.6) / 3 B, E_ms = rho^2 E_avg / (1 - E_avg) /
  (pi (1 - rho (1 - E_avg))) per wavelength; sampled cosine-weighted (docs/physics.md section 14.9).
  No compiled kernel: batches holding it take the NumPy lines.

Compiled kernels (core/util/jit.py; the NumPy lines stay the reference, chosen by
kernels_enabled()): evaluate, sample, with_outgoing and params_from_materials' per-hit tint and
edge rows each run as one pass over the hits (a loop over rows, an inner loop over wavelengths)
for every lobe code, doing the reference's float32 operations in its order (float64 where NumPy
promotes, pairwise sums where it sums): evaluate and with_outgoing give its bits; sample too,
but for sine and cosine (libm's there, NumPy's own SIMD code here, an ulp apart at times).
tests/materials/test_bsdf_kernels.py checks them.

Conventions: wo points towards the previous path vertex (the camera side), wi is the sampled
direction; ns is the unit shading normal and ng the geometric normal, both on wo's side. A
reflection needs wi on wo's side of both, a transmission the far side of both; other pairs
evaluate to zero (no light leaks). Everything is float32.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from functools import lru_cache

import numpy as np

from ..spectral.optics import fresnel_dielectric
from ..util.jit import kernels_enabled, njit
from . import sheen as _sheen
from .ggx import (ggx_d as _ggx_d, ggx_d_1, reflection_1, reflection_terms as _eval_reflection_common, sample_vndf_1,
                  smith_lambda as _lambda, smith_lambda_1)

__all__ = [
    "LAMBERT", "CONDUCTOR", "DIELECTRIC", "PLASTIC", "GLOSSY", "OREN_NAYAR", "SHEEN",
    "DIFFUSE_REFLECTION", "GLOSSY_REFLECTION", "TRANSMISSION", "SINGULAR",
    "MIN_ROUGHNESS", "SurfaceParams", "params_from_materials", "sample", "evaluate", "microfacet_materials",
    "energy_compensation", "coat_albedo", "fresnel_f82", "f82_b", "with_outgoing", "cosine_hemisphere",
]

#: Lobe codes per hit. GLOSSY is Blender's Glossy BSDF: GGX with a constant Fresnel (its colour).
LAMBERT, CONDUCTOR, DIELECTRIC, PLASTIC, GLOSSY = 0, 1, 2, 3, 4
#: The Diffuse BSDF with Roughness > 0: Cycles' Oren-Nayar (Fujii's improved model with OpenPBR's
#: energy-preserving multiple-scattering term; its ``alpha`` column holds the roughness sigma).
OREN_NAYAR = 5
#: Principled's sheen: Zeltner et al.'s microfiber sheen (core/materials/sheen.py), of unit albedo
#: here (its ``alpha`` column holds the sheen roughness; the lobe mixture weighs it by its albedo:
#: core/materials/mixtures.py). Principled's coat is a PLASTIC lobe of zero base.
SHEEN = 6
_LOBES = (LAMBERT, CONDUCTOR, DIELECTRIC, PLASTIC, GLOSSY, OREN_NAYAR, SHEEN)
#: Flags of a sampled event (0: absorbed / invalid). SINGULAR marks a delta event (pdf = inf).
DIFFUSE_REFLECTION, GLOSSY_REFLECTION, TRANSMISSION, SINGULAR = 1, 2, 4, 8

#: Blender roughness below which a surface is smooth: the GGX lobe (alpha = roughness^2 = 1e-4,
#: about 2e-4 rad wide) is narrower than a pixel of any usual camera (a 50 mm lens on a 36 mm
#: sensor at 1920 px: 3.7e-4 rad), so the image is the mirror's, while next-event estimation
#: through so sharp a lobe has variance ~ 1/alpha^2 and float32 half vectors (errors ~1e-7)
#: resolve it only to a few 1e-3. Such surfaces stay on the delta code (core/transport/walker.py);
#: sample() also treats them as delta events (SINGULAR), evaluate() gives them zero. Cycles'
#: own threshold is alpha^2 < 2e-10 (roughness 3.8e-3), visually the same.
MIN_ROUGHNESS = 0.01
_MIN_ALPHA = MIN_ROUGHNESS * MIN_ROUGHNESS

_F32 = np.float32
_INV_PI = _F32(1.0 / np.pi)


@dataclass
class SurfaceParams:
    """One row per hit; spectral arrays are (B, k), k = the grid's n for white rays, 1 for mono rays."""

    lobe: np.ndarray       # (B,) int: LAMBERT, CONDUCTOR, DIELECTRIC, PLASTIC, GLOSSY
    base: np.ndarray       # (B, k) albedo (LAMBERT, PLASTIC's diffuse), F0 (CONDUCTOR, GLOSSY), tint (DIELECTRIC)
    edge: np.ndarray       # (B, k) CONDUCTOR's F82 edge tint (Principled 'Specular Tint' on metals); ones otherwise
    alpha: np.ndarray      # (B,) GGX alpha = roughness^2 (isotropic); OREN_NAYAR: the roughness sigma in [0, 1]
    eta: np.ndarray        # (B,) DIELECTRIC: n on the far side / n on wo's side; 1 otherwise
    spec_f0: np.ndarray    # (B,) PLASTIC: F0 of the specular layer (((ior-1)/(ior+1))^2 * 2 * IOR level); 0: none
    spec_tint: np.ndarray  # (B, k) PLASTIC: specular tint
    # What depends on wo only, filled by with_outgoing() for the hits' wo and shading normal
    # (one next event and the bounce at a hit share them); None: computed in each call.
    frame_u: np.ndarray | None = None   # (B, 3) the shading frame's tangents (tangent_frame(ns))
    frame_v: np.ndarray | None = None
    wo_local: np.ndarray | None = None  # (B, 3) wo in that frame
    f82: np.ndarray | None = None       # (B, k) CONDUCTOR's F82 factor b (f82_b), every row a conductor
    ms: np.ndarray | None = None        # (B, k) the multiscatter factor, every row one CONDUCTOR or GLOSSY lobe
    # a thin film over the lobe's Fresnel (docs/physics.md section 2.8; None: no hit has one):
    film_d: np.ndarray | None = None    # (B,) float64 thickness (nm; 0: no film on that hit)
    film_n: np.ndarray | None = None    # (B,) float64 the film's index
    film_ni: np.ndarray | None = None   # (B,) float64 the incident medium's index (1, or a glass's from inside)
    film_wl: np.ndarray | None = None   # (B, k) float64 the wavelengths (nm) of the spectral columns

    def __len__(self):
        return len(self.lobe)

    def take(self, idx) -> "SurfaceParams":
        return SurfaceParams(*(None if v is None else v[idx] for v in (getattr(self, f.name) for f in fields(self))))


def _sub(p: SurfaceParams, idx: np.ndarray) -> SurfaceParams:
    """p.take(idx) for idx from np.flatnonzero (sorted, unique): p itself when it selects every row."""
    return p if len(idx) == len(p) else p.take(idx)


# ---------------------------------------------------------------------------------- Fresnel
def f82_b(f0, tint):
    """The F82-tint factor b: F(1/7) = F_schlick(1/7) * tint (Cycles fresnel_f82tint_B)."""
    f = 6.0 / 7.0
    f5 = f ** 5
    return (f0 + (1.0 - f0) * f5) * (7.0 / (f5 * f)) * (1.0 - tint)


def fresnel_f82(cos, f0, b):
    """Conductor Fresnel: Schlick minus b cos (1 - cos)^6, clamped to [0, 1] (Cycles fresnel_f82).
    cos (B,), f0 and b (B, k)."""
    s = np.clip(1.0 - cos, 0.0, 1.0)
    s2 = s * s
    s5 = s2 * s2 * s  # not s ** 5: NumPy's float32 power is SVML's on AVX-512 machines, libm's elsewhere
    # f0 (1 - s5) + s5 - b cos s5 s: the per-hit factors first, three (B, k) operations then
    return np.clip(f0 * (1.0 - s5)[:, None] + s5[:, None] - b * (np.asarray(cos) * s5 * s)[:, None], 0.0, 1.0)


def _f82_fss(f0, b):
    """Cosine-weighted average of fresnel_f82: 2 int mu F dmu = mix(f0, 1, 1/21) - b / 126."""
    return np.clip(f0 + (1.0 - f0) / 21.0 - b / 126.0, 0.0, 1.0)


def _dielectric_fss(eta):
    """Cosine-weighted average dielectric Fresnel, Kulla & Conty's fit (as Cycles' fresnel_dielectric_Fss)."""
    eta = np.asarray(eta, np.float64)
    lo = 0.997118 + eta * (0.1014 - eta * (0.965241 + eta * 0.130607))
    hi = (eta - 1.0) / (4.08567 + 1.00071 * eta)
    return np.where(eta < 1.0, lo, hi)


def _ior_from_f0(f0):
    r = np.sqrt(np.clip(f0, 0.0, 0.99))
    return (1.0 + r) / (1.0 - r)


def _principled_s(cos, eta, f0):
    """Cycles' generalized-Schlick remap s = (F_real - F0) / (1 - F0) in [0, 1]."""
    fr, _ = fresnel_dielectric(cos, eta)
    return np.clip((fr - f0) / np.maximum(1.0 - f0, 1e-6), 0.0, 1.0)


# ---------------------------------------------------------------------------------- GGX
def _sample_vndf(wo, alpha, u1, u2):
    """Heitz 2018: a visible normal for local wo (upper hemisphere), isotropic alpha (B,)."""
    vh = np.stack([alpha * wo[:, 0], alpha * wo[:, 1], wo[:, 2]], axis=1)
    vh /= np.linalg.norm(vh, axis=1, keepdims=True)
    lensq = vh[:, 0] ** 2 + vh[:, 1] ** 2
    big = lensq > 1e-7
    inv = np.where(big, 1.0 / np.sqrt(np.where(big, lensq, 1.0)), 0.0)
    t1x, t1y = np.where(big, -vh[:, 1] * inv, 1.0), np.where(big, vh[:, 0] * inv, 0.0)
    t1 = np.stack([t1x, t1y, np.zeros_like(lensq)], axis=1)
    # vh x t1 written out (t1 has no z): np.cross's general path costs several times more
    t2 = np.stack([-vh[:, 2] * t1y, vh[:, 2] * t1x, vh[:, 0] * t1y - vh[:, 1] * t1x], axis=1)
    r = np.sqrt(u1)
    phi = 2.0 * np.pi * u2
    p1 = r * np.cos(phi)
    p2 = r * np.sin(phi)
    s = 0.5 * (1.0 + vh[:, 2])
    p2 = (1.0 - s) * np.sqrt(np.maximum(0.0, 1.0 - p1 * p1)) + s * p2
    nh = p1[:, None] * t1 + p2[:, None] * t2 + np.sqrt(np.maximum(0.0, 1.0 - p1 * p1 - p2 * p2))[:, None] * vh
    h = np.stack([alpha * nh[:, 0], alpha * nh[:, 1], np.maximum(nh[:, 2], 0.0)], axis=1)
    return h / np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-30)


def _reflect_local(wo, h, cos_oh):
    return 2.0 * cos_oh[:, None] * h - wo


def _refract_local(wo, h, cos_oh, cos_t, eta):
    """pbrt's Refract with h on wo's side: wi = -wo / eta + (cos_oh / eta - cos_t) h."""
    return -wo / eta[:, None] + (cos_oh / eta - cos_t)[:, None] * h


# ---------------------------------------------------------------------------------- tables
# Grid nodes at i / (n - 1) in roughness r = sqrt(alpha), in x = sqrt(mu) (denser at grazing,
# where E changes fastest) and in z (the index axis). The 3-D tables use every other node of the
# 2-D grid, so one pass of visible-normal geometry serves all of them.
_N2 = 31                    # E(r, x) and E_avg(r)
_N3 = 16                    # the 3-D tables: r x x (x z)
_NZ_GLASS = 32              # glass tables' z nodes (the albedo inside glass bends sharply with the index)
_Z_MAX_GLASS = 0.98         # z = sqrt((ior - 1) / (ior + 1)): ior up to ~25 tabulated, clamped above
_Z_MAX_SPEC = 0.99 ** 0.25  # z = F0^(1/4), F0 up to 0.99 (Cycles' ior_from_F0 clamp)
_MU_MIN = 1e-4              # the mu = 0 column is computed here
_QUAD_POINTS = 2048         # visible-normal quadrature: points of the Fibonacci lattice per entry
_CHUNK = 96                 # table entries per vectorised block (memory)


def _vndf_block(r, mu):
    """Visible-normal quadrature for (roughness, mu) entries (E,) on a Fibonacci lattice of the
    sampling square, u = ((i + 1/2) / N, frac(i / golden ratio)) (a rank-1 lattice: no aliasing
    with the curve where reflections drop below the horizon, unlike a tensor grid; ~2e-4
    against a direct wi quadrature). Returns wo, h, cos(wo, h), Lambda(wo), alpha^2 per point
    (E * N rows) and the reflection weight G2 / G1(wo) with wi above the surface (0 otherwise)."""
    alpha = np.maximum(r * r, 1e-7).astype(_F32)  # float32: the tables' accuracy is set by the quadrature
    mu = np.maximum(mu, _MU_MIN).astype(_F32)
    i = np.arange(_QUAD_POINTS)
    u1 = ((i + 0.5) / _QUAD_POINTS).astype(_F32)
    u2 = np.mod(i * 0.6180339887498949, 1.0).astype(_F32)
    e, p = len(r), len(u1)
    wo = np.repeat(np.stack([np.sqrt(1.0 - mu * mu), np.zeros_like(mu), mu], axis=1), p, axis=0)
    a2 = np.repeat(alpha * alpha, p)
    h = _sample_vndf(wo, np.repeat(alpha, p), np.tile(u1, e), np.tile(u2, e))
    cos_oh = np.sum(wo * h, axis=1)
    wi = _reflect_local(wo, h, cos_oh)
    lo = _lambda(a2, wo)
    w = np.where(wi[:, 2] > 0, (1.0 + lo) / (1.0 + lo + _lambda(a2, wi)), 0.0)
    return wo, h, cos_oh, lo, a2, w


@lru_cache(maxsize=None)
def _tables():
    """All tables, computed once (about a million quadrature points):
    e_ss (N2, N2): single-scattering albedo of GGX reflection with F = 1, E(r, x);
    e_avg (N2,): 2 int_0^1 E mu dmu;
    s_tab (N3, N3, N3): int s(wo.h) f_ss cos of the Principled remap s (z = F0^(1/4));
    glass_out / glass_in (N3, N3, NZ_GLASS): reflect + eta^2-undone transmit albedo of a rough
    dielectric with the exact Fresnel, eta = ior > 1 and eta = 1 / ior (z = sqrt((ior-1)/(ior+1)))."""
    nodes = _grid(_N2)
    rr, xx = (a.ravel() for a in np.meshgrid(nodes, nodes, indexing="ij"))
    e_ss = np.empty(len(rr))
    even = (np.arange(_N2)[:, None] % 2 == 0) & (np.arange(_N2)[None, :] % 2 == 0)
    even = even.ravel()
    s_tab = np.empty((_N3 * _N3, _N3))
    glass = np.empty((2, _N3 * _N3, _NZ_GLASS))
    z_spec, z_glass = _grid(_N3, _Z_MAX_SPEC), _grid(_NZ_GLASS, _Z_MAX_GLASS)
    row3 = np.cumsum(even) - 1
    for start in range(0, len(rr), _CHUNK):
        sl = slice(start, start + _CHUNK)
        wo, h, cos_oh, lo, a2, w = _vndf_block(rr[sl], xx[sl] ** 2)
        n_e = len(rr[sl])
        e_ss[sl] = w.reshape(n_e, -1).mean(axis=1)
        sub = np.flatnonzero(even[sl])
        if not len(sub):
            continue
        p = len(w) // n_e
        pts = (sub[:, None] * p + np.arange(p)[None, :]).ravel()
        wo, h, cos_oh, lo, a2, w = wo[pts], h[pts], cos_oh[pts], lo[pts], a2[pts], w[pts]
        rows = row3[start + sub]
        for j in range(_N3):  # a loop over 16 F0 values
            f0 = z_spec[j] ** 4
            s = _principled_s(cos_oh, np.full(len(cos_oh), _ior_from_f0(f0), _F32), _F32(f0))
            s_tab[rows, j] = (s * w).reshape(len(sub), -1).mean(axis=1)
        for j in range(_NZ_GLASS):  # a loop over 32 indices
            zg = z_glass[j]
            ior = max((1.0 + zg * zg) / (1.0 - zg * zg), 1.0 + 1e-6)
            for t, eta_v in enumerate((ior, 1.0 / ior)):
                eta = np.full(len(cos_oh), eta_v, _F32)
                f, cos_t = fresnel_dielectric(cos_oh, eta)
                wt = _refract_local(wo, h, cos_oh, cos_t, eta)
                w_t = np.where((wt[:, 2] < 0) & (f < 1.0), (1.0 + lo) / (1.0 + lo + _lambda(a2, wt)), 0.0)
                glass[t, rows, j] = (f * w + (1.0 - f) * w_t).reshape(len(sub), -1).mean(axis=1)
    e_ss = e_ss.reshape(_N2, _N2)
    # E_avg = 2 int E mu dmu = 4 int E x^3 dx (mu = x^2), Simpson's rule on the 31 nodes
    wts = np.ones(_N2)
    wts[1:-1:2], wts[2:-1:2] = 4.0, 2.0
    e_avg = 4.0 * (e_ss * nodes ** 3 * wts).sum(axis=1) / (3.0 * (_N2 - 1))
    shape, gshape = (_N3, _N3, _N3), (_N3, _N3, _NZ_GLASS)
    return e_ss, e_avg, s_tab.reshape(shape), glass[0].reshape(gshape), glass[1].reshape(gshape)


def _grid(n, top=1.0):
    return np.linspace(0.0, top, n)


def _cell(x, n):
    f = np.clip(x, 0.0, 1.0) * (n - 1)
    i = np.minimum(f.astype(np.int64), n - 2)
    return i, (f - i).astype(_F32)


def _lookup2(tab, x, y):
    """Bilinear interpolation of tab (nx, ny, ...) at x, y in [0, 1] (grid nodes at i / (n - 1))."""
    i, tx = _cell(x, tab.shape[0])
    j, ty = _cell(y, tab.shape[1])
    if tab.ndim == 3:
        tx, ty = tx[:, None], ty[:, None]
    t = tab.astype(_F32)
    return (1 - tx) * ((1 - ty) * t[i, j] + ty * t[i, j + 1]) + tx * ((1 - ty) * t[i + 1, j] + ty * t[i + 1, j + 1])


def _lookup3(tab, x, y, z):
    """Trilinear interpolation of tab (nx, ny, nz)."""
    k, tz = _cell(z, tab.shape[2])
    rows = _lookup2(tab, x, y)  # (B, nz)
    b = np.arange(len(k))
    return (1 - tz) * rows[b, k] + tz * rows[b, k + 1]


def _lookup1(tab, x):
    i, t = _cell(x, len(tab))
    tb = tab.astype(_F32)
    return (1 - t) * tb[i] + t * tb[i + 1]


def _e_ss(alpha, mu):
    e_ss, e_avg = _tables()[:2]
    r = np.sqrt(alpha)
    return np.maximum(_lookup2(e_ss, r, np.sqrt(np.maximum(mu, 0.0))), 1e-3), _lookup1(e_avg, r)


def _ms_factor(alpha, mu, fss):
    """Cycles' multiscatter factor 1 + F_ms (1 - E) / E for average Fresnel fss (B, k)."""
    e, e_avg = _e_ss(alpha, mu)
    missing = ((1.0 - e) / e)[:, None]
    ea = e_avg[:, None]
    fms = fss * ea / np.maximum(1.0 - fss * (1.0 - ea), 1e-6)
    return (1.0 + fms * missing).astype(_F32)


def _glass_factor(alpha, mu, eta):
    t_out, t_in = _tables()[3:]
    ior = np.where(eta >= 1.0, eta, 1.0 / np.maximum(eta, 1e-6))
    z = np.sqrt((ior - 1.0) / (ior + 1.0)) / _Z_MAX_GLASS
    r = np.sqrt(alpha)
    x = np.sqrt(np.maximum(mu, 0.0))
    e = np.where(eta >= 1.0, _lookup3(t_out, r, x, z), _lookup3(t_in, r, x, z))
    return (1.0 / np.maximum(e, 1e-3)).astype(_F32)


def _plastic_terms(p, mu):
    """Per hit: f0t = F0 * tint (B, k), the layer's eta (B,), its multiscatter factor (B, k) and
    its directional albedo E_spec(mu) (B, k)."""
    f0 = np.clip(p.spec_f0, 0.0, 0.99)
    eta = _ior_from_f0(f0)
    f0t = np.clip(p.spec_f0[:, None] * p.spec_tint, 0.0, 1.0)
    s_avg = np.clip((_dielectric_fss(eta) - f0) / np.maximum(1.0 - f0, 1e-6), 0.0, 1.0)
    fss = f0t + (1.0 - f0t) * s_avg[:, None]
    fac = _ms_factor(p.alpha, mu, fss)
    e_ss, _ = _e_ss(p.alpha, mu)
    s_int = _lookup3(_tables()[2], np.sqrt(p.alpha), np.sqrt(np.maximum(mu, 0.0)), np.sqrt(np.sqrt(f0)) / _Z_MAX_SPEC)  # F0^(1/4), as sqrt(sqrt()): correctly rounded everywhere
    e_spec = np.clip(fac * (f0t * e_ss[:, None] + (1.0 - f0t) * s_int[:, None]), 0.0, 1.0)
    return f0t.astype(_F32), eta.astype(_F32), fac, e_spec.astype(_F32)


def coat_albedo(p, mu) -> np.ndarray:
    """(B,) the directional albedo E_spec(mu) of PLASTIC lobes' specular layer of unit tint (Principled's
    coat: the share of light it reflects, which Cycles' ``closure_layering_weight`` keeps from the
    layers under it; docs/physics.md section 14.10)."""
    return _plastic_terms(p, np.asarray(mu, _F32))[3][:, 0]


def _plastic_fresnel(cos, f0t, eta, spec_f0):
    f0 = np.clip(spec_f0, 0.0, 0.99)
    s = _principled_s(cos, eta, f0)[:, None]
    return f0t + (1.0 - f0t) * s


def _film_fresnel(p, code, cos, f):
    """``f`` (the lobe's Fresnel: (B, k), or (B,) for DIELECTRIC) with a thin film's Airy
    reflectance on the hits that have one (docs/physics.md section 2.8): over the conductor of F0
    ``base`` and F82 reflectance (Gulbrandsen's n, k) for CONDUCTOR / GLOSSY; over the glass of
    index ratio ``eta`` for DIELECTRIC (at the ray's one wavelength; white rows keep the plain
    Fresnel: dispersive splits make them mono first); over the specular layer's index for
    PLASTIC, scaled towards its F0 * tint as Cycles scales an iridescent generalized Schlick."""
    if p.film_d is None:
        return f
    m = np.flatnonzero(p.film_d > 0)
    if not len(m):
        return f
    from ..spectral import thin_film
    from ..spectral.thin_film import thin_film_conductor, conductor_ior_from_f0_f82

    c = np.abs(np.asarray(cos, np.float64))[m]
    d, nf, ni, wl = p.film_d[m, None], p.film_n[m, None], p.film_ni[m, None], p.film_wl[m]
    f = np.array(f, _F32)
    if code in (CONDUCTOR, GLOSSY):
        base = p.base[m].astype(np.float64)
        if code == CONDUCTOR:
            g = fresnel_f82(np.full(len(m), 1.0 / 7.0), base, f82_b(base, p.edge[m].astype(np.float64)))
        else:
            g = base
        n, k = conductor_ior_from_f0_f82(base, g)
        f[m] = thin_film_conductor(c[:, None], n, k, nf, d, wl, ni)
    elif code == DIELECTRIC:
        if p.base.shape[1] != 1:
            return f
        eta = p.eta[m].astype(np.float64)
        f[m] = thin_film.thin_film_dielectric(c, eta, nf[:, 0], d[:, 0], wl[:, 0], ni[:, 0])[0]
    else:  # PLASTIC: the layer's index from its F0 (F0_real = F0), then Cycles' scaling towards F0 * tint
        f0 = np.clip(p.spec_f0[m].astype(np.float64), 1e-6, 0.99)[:, None]
        film = thin_film.thin_film_dielectric(c[:, None], _ior_from_f0(f0), nf, d, wl, ni)[0].astype(np.float64)
        factor = p.spec_f0[m, None] * p.spec_tint[m].astype(np.float64) / f0
        s = np.clip((film - 1.0) / (f0 - 1.0), 0.0, 1.0)  # inverse_lerp(1, F0_real, F)
        f[m] = np.clip(film * (1.0 + (factor - 1.0) * s), 0.0, 1.0)
    return f


def energy_compensation(params: SurfaceParams, cos_o) -> np.ndarray:
    """(B, k) factor by which the multiple-scattering compensation scales each hit's
    single-scattering microfacet lobe for cos(wo, ns) = cos_o (1 for LAMBERT and for smooth
    surfaces); the PLASTIC value is its specular layer's."""
    p, mu = params, np.asarray(cos_o, _F32)
    out = np.ones(p.base.shape, _F32)
    rough = p.alpha >= _MIN_ALPHA
    for code in (CONDUCTOR, GLOSSY, DIELECTRIC, PLASTIC):
        idx = np.flatnonzero((p.lobe == code) & rough)
        if len(idx):
            out[idx] = _lobe_factor(_sub(p, idx), mu[idx], code)
    return out


def _lobe_factor(p, mu, code, b=None):
    """The lobe's multiscatter factor (B, k); ``b``: CONDUCTOR's f82_b(p.base, p.edge) when the
    caller has it already."""
    if code == CONDUCTOR:
        return _ms_factor(p.alpha, mu, _f82_fss(p.base, f82_b(p.base, p.edge) if b is None else b))
    if code == GLOSSY:
        return _ms_factor(p.alpha, mu, np.clip(p.base, 0.0, 1.0))
    if code == DIELECTRIC:
        return np.broadcast_to(_glass_factor(p.alpha, mu, p.eta)[:, None], p.base.shape)
    return _plastic_terms(p, mu)[2]


# ---------------------------------------------------------------------------------- frames
def tangent_frame(n):
    """Unit tangents (u, v) (B, 3) float32 with (u, v, n) orthonormal and right-handed (u x v =
    n), for unit normals n (B, 3): Duff, Burgess, Christensen, Hery, Kensler, Liani & Villemin
    2017, "Building an Orthonormal Basis, Revisited" (JCGT 6(1)), branchless, no cross product
    or square root (docs/physics.md section 4.8); discontinuous only across z = 0, which no
    isotropic lobe sees."""
    n = np.asarray(n, _F32)
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    sg = np.where(z >= 0, _F32(1), _F32(-1))
    a = _F32(-1) / (sg + z)
    b = x * y * a
    u = np.stack([_F32(1) + sg * x * x * a, sg * b, -sg * x], axis=1)
    v = np.stack([b, sg + y * y * a, -y], axis=1)
    return u, v


def cosine_hemisphere(n, rng):
    """Cosine-weighted unit directions about the unit normals n (B, 3) and their cosines (Malley's
    method: a uniform disk point lifted to the hemisphere; pdf = cos / pi), from two numbers per
    row of ``rng`` (a Generator or the eye pass's pixel sampler)."""
    b = len(n)
    u1, u2 = rng.random(b, _F32), rng.random(b, _F32)
    if kernels_enabled() and isinstance(n, np.ndarray) and n.dtype == _F32 and n.ndim == 2 and b:
        wi, cos = np.empty((b, 3), _F32), np.empty(b, _F32)
        _cosine_kernel(n, u1, u2, _F32(2 * np.pi), wi, cos)  # NumPy's own float32 sin / cos may differ by an ulp
        return wi, cos
    r, phi = np.sqrt(u1), _F32(2 * np.pi) * u2
    tu, tv = tangent_frame(n)
    cos = np.sqrt(np.maximum(_F32(1) - u1, 0))
    wi = (r * np.cos(phi))[:, None] * tu + (r * np.sin(phi))[:, None] * tv + cos[:, None] * n
    return wi.astype(_F32), cos.astype(_F32)


@njit
def _cosine_kernel(n, u1, u2, two_pi, wi, cos_out):
    """cosine_hemisphere's float32 lines per row (tangent_frame's basis inlined)."""
    one, zero = np.float32(1.0), np.float32(0.0)
    for i in range(n.shape[0]):
        x, y, z = n[i, 0], n[i, 1], n[i, 2]
        sg = one if z >= zero else -one
        a = -one / (sg + z)
        b = x * y * a
        r, phi = np.sqrt(u1[i]), two_pi * u2[i]
        c = np.sqrt(max(one - u1[i], zero))
        p, q = r * np.cos(phi), r * np.sin(phi)
        wi[i, 0] = (p * (one + sg * x * x * a) + q * b) + c * x
        wi[i, 1] = (p * (sg * b) + q * (sg + y * y * a)) + c * y
        wi[i, 2] = (p * (-sg * x) + q * -y) + c * z
        cos_out[i] = c


def _frame(ns):
    return tangent_frame(ns)


def _to_local(w, u, v, n):
    return np.stack([np.sum(w * u, 1), np.sum(w * v, 1), np.sum(w * n, 1)], axis=1)


def _to_world(w, u, v, n):
    return w[:, :1] * u + w[:, 1:2] * v + w[:, 2:3] * n


def _cosine_sample(u1, u2):
    """Malley's method on Shirley's concentric disk: local directions, pdf cos / pi."""
    a, b = 2.0 * u1 - 1.0, 2.0 * u2 - 1.0
    first = np.abs(a) > np.abs(b)
    r = np.where(first, a, b)
    safe_a = np.where(first, a, np.where(b == 0, 1.0, b))
    phi = np.where(first, (np.pi / 4) * b / np.where(a == 0, 1.0, a), np.pi / 2 - (np.pi / 4) * a / safe_a)
    x, y = r * np.cos(phi), r * np.sin(phi)
    z = np.sqrt(np.maximum(0.0, 1.0 - x * x - y * y))
    return np.stack([x, y, z], axis=1)


# ---------------------------------------------------------------------------------- lobes (local frame)
def _eval_lobe(p, code, wo, wi, terms=None):
    """f cos (B, k) and pdf (B,) of one lobe's hits in the local frame (wo.z > 0); wi.z > 0
    means reflection, < 0 transmission (the caller has checked the geometric side)."""
    B, k = p.base.shape
    fcos = np.zeros((B, k), _F32)
    pdf = np.zeros(B, _F32)
    up = wi[:, 2] > 0
    mu_o = wo[:, 2]
    if code == LAMBERT:
        c = np.where(up, wi[:, 2], 0.0) * _INV_PI
        return (p.base * c[:, None]).astype(_F32), c.astype(_F32)
    if code == OREN_NAYAR:
        return _oren_nayar(p, wo, wi)
    if code == SHEEN:
        fc, pd = _sheen.sheen_eval(wo, wi, p.alpha)
        return (p.base * fc[:, None]).astype(_F32), pd
    rough = p.alpha >= _MIN_ALPHA
    if code in (CONDUCTOR, GLOSSY) and p.ms is not None:  # wo's factors known: all rows, the rest zeroed
        ok = up & rough
        fc, pd, coh = _eval_reflection_common(p.alpha, wo, wi)
        f = _film_fresnel(p, code, coh, fresnel_f82(coh, p.base, p.f82) if code == CONDUCTOR else p.base)
        return (np.where(ok[:, None], f * (fc[:, None] * p.ms), _F32(0.0)).astype(_F32, copy=False),
                np.where(ok, pd, _F32(0.0)).astype(_F32, copy=False))
    if code in (CONDUCTOR, GLOSSY):
        m = np.flatnonzero(up & rough)
        if len(m):
            q = _sub(p, m)
            fc, pd, coh = _eval_reflection_common(q.alpha, wo[m], wi[m])
            b = f82_b(q.base, q.edge) if code == CONDUCTOR else None
            f = _film_fresnel(q, code, coh, fresnel_f82(coh, q.base, b) if code == CONDUCTOR else q.base)
            fcos[m] = f * (fc[:, None] * _lobe_factor(q, mu_o[m], code, b))
            pdf[m] = pd
        return fcos, pdf
    if code == DIELECTRIC:
        m = np.flatnonzero(up & rough)
        if len(m):
            q = _sub(p, m)
            fc, pd, coh = _eval_reflection_common(q.alpha, wo[m], wi[m])
            f = _film_fresnel(q, code, coh, fresnel_dielectric(coh, q.eta)[0])
            fcos[m] = q.base * (f * fc * _glass_factor(q.alpha, mu_o[m], q.eta))[:, None]
            pdf[m] = f * pd
        m = np.flatnonzero(~up & rough & (np.abs(p.eta - 1.0) >= 1e-4))
        if len(m):
            q = _sub(p, m)
            a2 = q.alpha * q.alpha
            o, i, eta = wo[m], wi[m], q.eta
            h = eta[:, None] * i + o
            h /= np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-30)
            h = np.where(h[:, 2:3] < 0, -h, h)
            coh, cih = np.sum(o * h, 1), np.sum(i * h, 1)
            ok = (coh > 0) & (cih < 0)
            f = _film_fresnel(q, code, coh, fresnel_dielectric(coh, eta)[0])
            d = _ggx_d(a2, h)
            lo, li = _lambda(a2, o), _lambda(a2, i)
            denom = cih + coh / eta
            denom2 = np.maximum(denom * denom, 1e-30)
            jac = np.abs(cih) / denom2
            t = np.where(ok, 1.0 - f, 0.0)
            val = t * d * coh * jac / (o[:, 2] * (1.0 + lo + li))  # no 1/eta^2: as the walker's smooth glass
            fcos[m] = q.base * (val * _glass_factor(q.alpha, mu_o[m], eta))[:, None]
            pdf[m] = t * d * coh * jac / (o[:, 2] * (1.0 + lo))
        return fcos, pdf
    # PLASTIC
    f0t, eta, fac, e_spec = _plastic_terms(p, mu_o) if terms is None else terms
    c = np.where(up, wi[:, 2], 0.0) * _INV_PI
    fcos = (p.base * (1.0 - e_spec) * c[:, None]).astype(_F32)
    ps = _plastic_p_spec(p, e_spec)
    pdf = ((1.0 - ps) * c).astype(_F32)
    m = np.flatnonzero(up & rough)
    if len(m):
        fc, pd, coh = _eval_reflection_common(p.alpha[m], wo[m], wi[m])
        f = _film_fresnel(_sub(p, m), PLASTIC, coh, _plastic_fresnel(coh, f0t[m], eta[m], p.spec_f0[m]))
        fcos[m] += f * fac[m] * fc[:, None]
        pdf[m] += ps[m] * pd
    return fcos, pdf


def _oren_nayar_g(cos):
    """Cycles' ``bsdf_oren_nayar_G``: G(mu) with E(mu) = A pi + B G(mu) the single-scattering
    albedo (its Taylor expansion below mu = 1e-6)."""
    cos = np.asarray(cos, _F32)
    c = np.maximum(cos, _F32(1e-6))
    s = np.sqrt(np.maximum(_F32(1) - c * c, _F32(0)))
    th = np.arccos(np.clip(c, _F32(-1), _F32(1)))
    two3 = _F32(2.0 / 3.0)
    g = s * (th - two3 - s * c) + two3 * (s / c) * (_F32(1) - s * s * s)
    return np.where(cos < _F32(1e-6), _F32(np.pi / 2 - 2.0 / 3.0) - cos, g).astype(_F32)


def _oren_nayar(p, wo, wi):
    """f cos (B, k) and pdf (B,) of OREN_NAYAR hits in the local frame (module docstring)."""
    sigma = np.clip(p.alpha, _F32(0), _F32(1))
    a = _F32(1) / (_F32(np.pi) + sigma * _F32(np.pi / 2 - 2.0 / 3.0))
    b = sigma * a
    nl = np.maximum(wi[:, 2], _F32(0))
    nv = np.maximum(wo[:, 2], _F32(0))
    t = np.sum(wi * wo, axis=1) - nl * nv
    t = np.where(t > 0, t / (np.maximum(nl, nv) + _F32(1.1754944e-38)), t)
    single = a + b * t
    e_avg = a * _F32(np.pi) + _F32((2 * np.pi - 5.6) / 3.0) * b
    rho = np.clip(p.base, _F32(0), _F32(1))
    e_ms = _INV_PI * rho * rho * (e_avg / (_F32(1) - e_avg))[:, None] / (_F32(1) - rho * (_F32(1) - e_avg)[:, None])
    e_v = a * _F32(np.pi) + b * _oren_nayar_g(nv)
    e_l = a * _F32(np.pi) + b * _oren_nayar_g(nl)
    multi = e_ms * ((_F32(1) - e_v) * (_F32(1) - e_l))[:, None]
    f = p.base * (nl * single)[:, None] + p.base * nl[:, None] * multi
    up = wi[:, 2] > 0
    return (np.where(up[:, None], f, _F32(0)).astype(_F32),
            np.where(up, wi[:, 2] * _INV_PI, _F32(0)).astype(_F32))


def _plastic_p_spec(p, e_spec):
    """Probability of sampling the specular layer: its share of the estimated albedo (as Cycles'
    sample weights)."""
    es = e_spec.mean(axis=1)
    ed = (p.base * (1.0 - e_spec)).mean(axis=1)
    tot = es + ed
    return np.where(tot > 0, es / np.where(tot > 0, tot, 1.0), 1.0).astype(_F32)


def _sample_lobe(p, code, wo, u):
    """Local wi, weight (B, k), pdf (B,), flags (B,) for one lobe's hits (wo.z > 0)."""
    B, k = p.base.shape
    mu_o = wo[:, 2]
    wi = np.zeros((B, 3), _F32)
    wi[:, 2] = 1.0
    weight = np.zeros((B, k), _F32)
    pdf = np.zeros(B, _F32)
    flags = np.zeros(B, np.int32)
    if code == LAMBERT:
        wi = _cosine_sample(u[:, 0], u[:, 1]).astype(_F32)
        ok = wi[:, 2] > 0
        weight[ok] = p.base[ok]
        pdf[ok] = wi[ok, 2] * _INV_PI
        flags[ok] = DIFFUSE_REFLECTION
        return wi, weight, pdf, flags
    if code == OREN_NAYAR:  # cosine-weighted, as Cycles samples it
        wi = _cosine_sample(u[:, 0], u[:, 1]).astype(_F32)
        fcos, pd = _oren_nayar(p, wo, wi)
        ok = (wi[:, 2] > 0) & (pd > 0)
        weight[ok] = fcos[ok] / pd[ok, None]
        pdf[ok] = pd[ok]
        flags[ok] = DIFFUSE_REFLECTION
        return wi, weight, pdf, flags
    if code == SHEEN:  # the LTC's own density: weight = base (Cycles labels it diffuse)
        wi, pd = _sheen.sheen_sample(wo, p.alpha, u[:, 0], u[:, 1])
        ok = (wi[:, 2] > 0) & (pd > 0)
        weight[ok] = p.base[ok]
        pdf[ok] = pd[ok]
        flags[ok] = DIFFUSE_REFLECTION
        return wi, weight, pdf, flags
    rough = p.alpha >= _MIN_ALPHA
    h = np.zeros((B, 3), _F32)
    h[:, 2] = 1.0
    r = np.flatnonzero(rough)
    if len(r):
        h[r] = _sample_vndf(wo[r], p.alpha[r], u[r, 0], u[r, 1])
    cos_oh = np.sum(wo * h, axis=1)
    a2 = p.alpha * p.alpha
    lo = _lambda(a2, wo)
    if code in (CONDUCTOR, GLOSSY):
        wi = _reflect_local(wo, h, cos_oh)
        ok = (wi[:, 2] > 0) & (cos_oh > 0)
        b = p.f82 if p.ms is not None else f82_b(p.base, p.edge) if code == CONDUCTOR else None
        f = _film_fresnel(p, code, cos_oh, fresnel_f82(cos_oh, p.base, b) if code == CONDUCTOR else p.base)
        g = np.where(rough, (1.0 + lo) / (1.0 + lo + _lambda(a2, wi)), 1.0)
        if p.ms is not None:
            fac = p.ms
        elif len(r) == B:
            fac = _lobe_factor(p, mu_o, code, b)
        else:
            fac = np.ones((B, k), _F32)
            if len(r):
                fac[r] = _lobe_factor(_sub(p, r), mu_o[r], code, None if b is None else b[r])
        weight = np.where(ok[:, None], f * fac * g[:, None], 0.0).astype(_F32)
        pdf = np.where(ok, np.where(rough, _ggx_d(a2, h) / ((1.0 + lo) * 4.0 * mu_o), np.inf), 0.0).astype(_F32)
        flags = np.where(ok, GLOSSY_REFLECTION | np.where(rough, 0, SINGULAR), 0).astype(np.int32)
        return wi.astype(_F32), weight, pdf, flags
    if code == DIELECTRIC:
        eta = p.eta
        unit = np.abs(eta - 1.0) < 1e-4  # index-matched: a straight pass, a delta transmission
        f, cos_t = fresnel_dielectric(cos_oh, eta)
        f = np.where(unit, 0.0, _film_fresnel(p, code, cos_oh, f))
        refl = u[:, 2] < f
        wr = _reflect_local(wo, h, cos_oh)
        wt = np.where(unit[:, None], -wo, _refract_local(wo, h, cos_oh, cos_t, eta))
        wi = np.where(refl[:, None], wr, wt)
        ok = np.where(refl, wi[:, 2] > 0, wi[:, 2] < 0) & (cos_oh > 0)
        g = np.where(rough, (1.0 + lo) / (1.0 + lo + _lambda(a2, wi)), 1.0)
        fac = np.ones(B, _F32)
        if len(r):
            fac[r] = _glass_factor(p.alpha[r], mu_o[r], eta[r])
        scale = g * fac  # transmission unscaled by 1/eta^2, as the walker's smooth glass (module docstring)
        weight = np.where(ok[:, None], p.base * scale[:, None], 0.0).astype(_F32)
        d_vis = _ggx_d(a2, h) * cos_oh / (mu_o * (1.0 + lo))
        cih = np.sum(wi * h, axis=1)
        denom = cih + cos_oh / eta
        pdf_r = f * d_vis / np.maximum(4.0 * cos_oh, 1e-30)
        pdf_t = (1.0 - f) * d_vis * np.abs(cih) / np.maximum(denom * denom, 1e-30)
        singular = ~rough | (unit & ~refl)
        pdf = np.where(ok, np.where(singular, np.inf, np.where(refl, pdf_r, pdf_t)), 0.0).astype(_F32)
        fl = np.where(refl, GLOSSY_REFLECTION, TRANSMISSION) | np.where(singular, SINGULAR, 0)
        flags = np.where(ok, fl, 0).astype(np.int32)
        return wi.astype(_F32), weight, pdf, flags
    # PLASTIC: the specular layer with its albedo share, else the diffuse base
    f0t, eta_l, fac, e_spec = _plastic_terms(p, mu_o)
    ps = _plastic_p_spec(p, e_spec)
    spec = u[:, 2] < ps
    wr = _reflect_local(wo, h, cos_oh)
    wd = _cosine_sample(u[:, 0], u[:, 1])
    wi = np.where(spec[:, None], wr, wd).astype(_F32)
    ok = (wi[:, 2] > 0) & np.where(spec, cos_oh > 0, True)
    delta = spec & ~rough & ok
    fcos, pd = _eval_lobe(p, PLASTIC, wo, wi, (f0t, eta_l, fac, e_spec))
    good = ok & ~delta & (pd > 0)
    weight[good] = fcos[good] / pd[good, None]
    pdf[good] = pd[good]
    flags[good] = np.where(spec[good], GLOSSY_REFLECTION, DIFFUSE_REFLECTION)
    if delta.any():  # a smooth coat: delta reflection, weight F / p_spec
        dm = np.flatnonzero(delta)
        f = _film_fresnel(_sub(p, dm), PLASTIC, mu_o[dm],
                          _plastic_fresnel(mu_o[dm], f0t[dm], eta_l[dm], p.spec_f0[dm]))
        weight[dm] = f / ps[dm, None]
        pdf[dm] = np.inf
        flags[dm] = GLOSSY_REFLECTION | SINGULAR
    return wi, weight, pdf, flags


# ---------------------------------------------------------------------------------- public API
def _prepare(params, wo, ns):
    wo = np.asarray(wo, _F32)
    ns = np.asarray(ns, _F32)
    if params.wo_local is not None:
        return wo, ns, params.frame_u, params.frame_v, params.wo_local
    u, v = _frame(ns)
    return wo, ns, u, v, _to_local(wo, u, v, ns)


def with_outgoing(params: SurfaceParams, wo, ns) -> SurfaceParams:
    """``params`` with what depends on wo only computed once for these hits: the shading frame,
    wo in it and, where every hit has one CONDUCTOR or GLOSSY lobe, F82's b and the multiscatter
    factor. ``evaluate`` and ``sample`` then skip them; they must be called with the same wo and
    ns (rows taken together with ``take``). The values are the ones they compute themselves."""
    if _kernel_fits(params):
        return _with_outgoing_kernel(params, wo, ns)
    wo, ns, fu, fv, wl = _prepare(params, wo, ns)
    out = replace(params, frame_u=fu, frame_v=fv, wo_local=wl)
    lobe = params.lobe
    if len(lobe) and lobe[0] in (CONDUCTOR, GLOSSY) and (lobe == lobe[0]).all():
        code = int(lobe[0])
        b = f82_b(params.base, params.edge).astype(_F32) if code == CONDUCTOR else None
        rough = params.alpha >= _MIN_ALPHA
        with np.errstate(all="ignore"):  # rows with wo below ns: evaluate and sample zero them
            fac = _lobe_factor(params, wl[:, 2], code, b)
        out.f82, out.ms = b, np.where(rough[:, None], fac, _F32(1.0)).astype(_F32)
    return out


def sample(params: SurfaceParams, wo, ns, ng, u):
    """Sample wi for each hit. wo (B, 3) unit towards the previous vertex; ns (B, 3) unit shading
    normal and ng (B, 3) geometric normal, both on wo's side; u (B, 3) uniforms in [0, 1)
    (u[:, 2], the reflect / transmit or coat / base choice, is read by DIELECTRIC and PLASTIC only).

    Returns wi (B, 3) unit, weight (B, k) = f |cos(wi, ns)| / pdf, pdf (B,) solid-angle density
    (inf for SINGULAR events), flags (B,) (0: absorbed; weight and pdf are 0 then)."""
    if _kernel_fits(params) and np.shape(u) == (len(params.lobe), 3):
        return _sample_with_kernel(params, wo, ns, ng, u)
    split = _sheen_split(params)
    if split is not None:  # the sheen rows on these lines, the others through the kernels
        parts = [sample(params.take(i), *(np.asarray(a)[i] for a in (wo, ns, ng, u))) for i in split]
        return _merged(split, parts, len(params.lobe))
    wo, ns, fu, fv, wl = _prepare(params, wo, ns)
    ng = np.asarray(ng, _F32)
    u = np.asarray(u, _F32)
    B, k = params.base.shape
    wi_l = np.zeros((B, 3), _F32)
    wi_l[:, 2] = 1.0
    weight = np.zeros((B, k), _F32)
    pdf = np.zeros(B, _F32)
    flags = np.zeros(B, np.int32)
    valid = wl[:, 2] > 0
    for code in _LOBES:  # a loop over the 7 lobes
        mine = params.lobe == code
        idx = np.flatnonzero(mine & valid)
        if len(idx) and mine.all():  # one lobe everywhere: all rows, the invalid ones zeroed (no take)
            with np.errstate(all="ignore"):
                wi_l, weight, pdf, flags = _sample_lobe(params, code, wl, u)
            if len(idx) < B:
                bad = ~valid
                wi_l[bad], weight[bad], pdf[bad], flags[bad] = (0.0, 0.0, 1.0), 0.0, 0.0, 0
            break
        if len(idx):
            wi_l[idx], weight[idx], pdf[idx], flags[idx] = _sample_lobe(params.take(idx), code, wl[idx], u[idx])
    wi = _to_world(wi_l, fu, fv, ns)
    wi /= np.maximum(np.linalg.norm(wi, axis=1, keepdims=True), 1e-30)
    side = np.sum(wi * ng, axis=1)
    trans = (flags & TRANSMISSION) != 0
    bad = (flags != 0) & np.where(trans, side >= 0, side <= 0)
    weight[bad] = 0.0
    pdf[bad] = 0.0
    flags[bad] = 0
    return wi.astype(_F32), weight, pdf, flags


def evaluate(params: SurfaceParams, wo, wi, ns, ng):
    """f |cos(wi, ns)| (B, k) and the pdf sample() has for wi (B,), for next-event estimation
    and MIS. Delta (SINGULAR) parts evaluate to zero; so does a wi on the wrong side of ng or ns
    for its kind of event."""
    if _kernel_fits(params):
        return _evaluate_with_kernel(params, wo, wi, ns, ng)
    split = _sheen_split(params)
    if split is not None:  # the sheen rows on these lines, the others through the kernels
        parts = [evaluate(params.take(i), *(np.asarray(a)[i] for a in (wo, wi, ns, ng))) for i in split]
        return _merged(split, parts, len(params.lobe))
    wo, ns, fu, fv, wl = _prepare(params, wo, ns)
    wi = np.asarray(wi, _F32)
    ng = np.asarray(ng, _F32)
    il = _to_local(wi, fu, fv, ns)
    B, k = params.base.shape
    fcos = np.zeros((B, k), _F32)
    pdf = np.zeros(B, _F32)
    side = np.sum(wi * ng, axis=1)
    consistent = np.where(il[:, 2] > 0, side > 0, (side < 0) & (il[:, 2] < 0))
    valid = (wl[:, 2] > 0) & consistent
    for code in _LOBES:
        mine = params.lobe == code
        idx = np.flatnonzero(mine & valid)
        if len(idx) and mine.all():  # one lobe everywhere: all rows, the invalid ones zeroed (no take)
            with np.errstate(all="ignore"):
                fcos, pdf = _eval_lobe(params, code, wl, il)
            if len(idx) < B:
                fcos[~valid], pdf[~valid] = 0.0, 0.0
            break
        if len(idx):
            fcos[idx], pdf[idx] = _eval_lobe(params.take(idx), code, wl[idx], il[idx])
    return fcos, pdf


# ---------------------------------------------------------------------------------- materials
def params_from_materials(materials, mat, front, lam=None, base=None, roughness=None, u_layer=None,
                          weights=None, layer=None) -> SurfaceParams:
    """SurfaceParams of hits on materials (core/materials.PreparedMaterials) rows ``mat`` (B,).

    front (B,) bool: the hit is on the side the normal points to (entering a dielectric: eta =
    ior; else 1 / ior). lam (B,) wavelength indices of mono rays, or None for white rays (a
    dispersive index then takes its mean over the grid: split such rays first, as
    core/transport/walker.py does). base (B, k) / roughness (B,) override the table per hit (textures).

    Principled's layers: with u_layer (B,) uniforms the layer is drawn per hit - the metal with
    probability metallic, else glass with probability transmission, else the dielectric base
    (PLASTIC, or LAMBERT without a specular layer) - which makes each hit's weight an unbiased
    estimate of the weighted sum; without u_layer the heaviest layer is used. Shader mixes of
    unlike BSDFs are the same layers as a lobe mixture (docs/physics.md section 14.8): the metal
    takes its own colour where the row has one (``metal_reflectance``), and ``weights``
    (metallic (B,), transmission (B,)) replace the table's per hit (a Fresnel / Layer Weight
    Fac: core/materials/mixtures.py ``per_hit_layers``). ``layer`` (B,) int (0 base, 1 metal,
    2 glass) forces that layer's lobe instead (the mixture's every lobe for next events:
    core/materials/mixtures.py ``LobeMixture``).
    """
    m = materials
    mat = np.asarray(mat, np.int64)
    front = np.asarray(front, bool)
    B = len(mat)
    metallic, transmission = (m.metallic[mat], m.transmission[mat]) if weights is None else weights
    if layer is not None:  # the layer asked for
        layer = np.asarray(layer)
        metal, glass = layer == 1, layer == 2
    elif u_layer is None:  # the heaviest layer (ties: metal, then glass)
        w_glass, w_base = (1.0 - metallic) * transmission, (1.0 - metallic) * (1.0 - transmission)
        metal = (metallic >= w_glass) & (metallic >= w_base)
        glass = ~metal & (w_glass >= w_base)
    else:
        u_layer = np.asarray(u_layer, np.float64)
        metal = u_layer < metallic
        rest = (u_layer - metallic) / np.maximum(1.0 - metallic, 1e-12)
        glass = ~metal & (rest < transmission)
    spec_f0 = np.where(metal | glass, 0.0, m.spec_f0[mat]).astype(_F32)
    dr = getattr(m, "diffuse_roughness", None)
    on = np.zeros(B, bool) if dr is None else dr[mat] > 0  # a rough Diffuse BSDF: Oren-Nayar
    lobe = np.where(metal, np.where(m.conductor_f82[mat], CONDUCTOR, GLOSSY),
                    np.where(glass, DIELECTRIC, np.where(spec_f0 > 0, PLASTIC,
                                                         np.where(on, OREN_NAYAR, LAMBERT)))).astype(np.int32)

    def spectral(table):
        return table[mat] if lam is None else table[mat, np.asarray(lam, np.int64)][:, None]

    b = spectral(m.reflectance) if base is None else np.asarray(base, _F32)
    if m.glass_tint is not None:  # the glass layer's tint per refraction (docs/physics.md section 2.7)
        own = glass & ~m.color_textured[mat]  # a colour texture's hits keep the texture's tint
        b = np.where(own[:, None], spectral(m.glass_tint), b) if own.any() else b
    if getattr(m, "metal_reflectance", None) is not None:  # a mix's metal layer of its own colour
        own = metal & m.own_metal[mat]
        b = np.where(own[:, None], spectral(m.metal_reflectance), b) if own.any() else b
    k = b.shape[1]
    rough = m.roughness[mat] if roughness is None else np.asarray(roughness, _F32)
    alpha = np.clip(rough, 0.0, 1.0) ** 2
    if (lobe == OREN_NAYAR).any():  # its alpha column holds sigma
        alpha = np.where(lobe == OREN_NAYAR, np.clip(dr[mat], 0.0, 1.0), alpha)
    st = m.specular_tint
    if (kernels_enabled() and isinstance(st, np.ndarray) and st.dtype == _F32 and st.ndim == 2
            and m.ior.dtype == _F32 and k == (st.shape[1] if lam is None else 1)):
        # the tint and edge rows in one pass; the index's mean per material, then gathered
        # (the same pairwise sums as the reference's per hit)
        lam_k = np.zeros(0, np.int64) if lam is None else np.asarray(lam, np.int64)
        if lam is None and B > 1 and (mat == mat[0]).all() and (lobe == lobe[0]).all():
            # one material and lobe (a single rough object's hits): the one row, broadcast (read-only
            # views; take() copies them): no (B, k) arrays to fill and fault in
            edge, tint = np.empty((1, k), _F32), np.empty((1, k), _F32)
            _gather_kernel(mat[:1], lam_k, lobe[:1], np.ascontiguousarray(st), edge, tint)
            edge, tint = np.broadcast_to(edge, (B, k)), np.broadcast_to(tint, (B, k))
        else:
            edge, tint = np.empty((B, k), _F32), np.empty((B, k), _F32)
            _gather_kernel(mat, lam_k, lobe, np.ascontiguousarray(st), edge, tint)
        ior = m.ior.mean(axis=1)[mat] if lam is None else m.ior[mat, lam_k]
        eta = np.where(lobe == DIELECTRIC, np.where(front, ior, 1.0 / ior), 1.0)
        return _with_film(SurfaceParams(lobe, np.ascontiguousarray(b, _F32), edge, alpha.astype(_F32),
                                        eta.astype(_F32), spec_f0, tint), m, mat, front, lam, ior)
    edge = np.where(lobe[:, None] == CONDUCTOR, np.minimum(spectral(m.specular_tint), 1.0), 1.0)
    tint = spectral(m.specular_tint)
    if lam is None:
        ior = m.ior[mat].mean(axis=1)
    else:
        ior = m.ior[mat, np.asarray(lam, np.int64)]
    eta = np.where(lobe == DIELECTRIC, np.where(front, ior, 1.0 / ior), 1.0)
    return _with_film(SurfaceParams(lobe, np.ascontiguousarray(b, _F32), np.broadcast_to(edge, (B, k)).astype(_F32),
                                    alpha.astype(_F32), eta.astype(_F32), spec_f0,
                                    np.broadcast_to(tint, (B, k)).astype(_F32)), m, mat, front, lam, ior)


def _with_film(p: SurfaceParams, m, mat, front, lam, ior) -> SurfaceParams:
    """``p`` with the thin-film columns where a hit's material has a film (docs/physics.md
    section 2.8): thickness, index, the incident medium's index (a glass layer hit from inside:
    its own) and the wavelengths of the spectral columns."""
    film = getattr(m, "film", None)
    if film is None or getattr(m, "wavelengths", None) is None or not film[mat].any():
        return p
    wl = np.asarray(m.wavelengths, np.float64)
    k = p.base.shape[1]
    p.film_d = m.film_thickness[mat].astype(np.float64)
    p.film_n = m.film_ior[mat].astype(np.float64)
    p.film_ni = np.where((p.lobe == DIELECTRIC) & ~front, np.asarray(ior, np.float64), 1.0)
    p.film_wl = np.broadcast_to(wl[None, :], (len(mat), k)).copy() if lam is None else \
        wl[np.asarray(lam, np.int64)][:, None]
    return p


def microfacet_materials(materials, textures=None) -> np.ndarray:
    """(M,) bool: the materials the eye pass shades with this module rather than with the delta
    mirror / glass code or the plain Lambertian path: rough mirrors and glass (roughness at least
    MIN_ROUGHNESS, or a roughness texture), Principled's layered mixes (0 < metallic < 1, glass
    with transmission below 1), and diffuse bases with a specular layer (PLASTIC) or a metal or
    glass layer. Files without these columns keep their old meaning (nothing is microfacet)."""
    from .spectra import DIELECTRIC as K_DIELECTRIC, DIFFUSE as K_DIFFUSE, MIRROR as K_MIRROR

    m = materials
    kind = np.asarray(m.kind)
    rough = np.asarray(m.roughness) >= MIN_ROUGHNESS
    if textures is not None and len(textures.roughness):
        rough = rough | (np.asarray(textures.roughness) >= 0)
    metallic, transmission = np.asarray(m.metallic), np.asarray(m.transmission)
    lf = getattr(m, "layer_fac", None)
    per_hit = np.zeros(len(kind), bool) if lf is None else np.asarray(lf) != 0  # a Fresnel-mixed row
    dr = getattr(m, "diffuse_roughness", None)
    if dr is not None:  # a rough Diffuse BSDF (Oren-Nayar)
        per_hit = per_hit | ((kind == K_DIFFUSE) & (np.asarray(dr) > 0))
    if getattr(m, "layered", None) is not None:  # Principled's coat or sheen (a lobe mixture)
        per_hit = per_hit | np.asarray(m.layered)
    return (per_hit | ((kind == K_MIRROR) & (rough | (metallic < 1)))
            | ((kind == K_DIELECTRIC) & (rough | (transmission < 1) | (metallic > 0)))
            | ((kind == K_DIFFUSE) & ((np.asarray(m.spec_f0) > 0) | (metallic > 0) | (transmission > 0))))


# ---------------------------------------------------------------------------------- kernels
# evaluate / sample / with_outgoing / params_from_materials as one compiled pass over the hits
# (core/util/jit.py): each row does the NumPy lines' float32 operations in their order (the
# PLASTIC layer's average Fresnel and multiscatter factor in float64, as NumPy promotes them
# there; np.sum / np.mean over the wavelengths summed pairwise, as NumPy does), so evaluate and
# with_outgoing give the reference's bits. Sampling draws through sine and cosine, which are
# libm's here and NumPy's own SIMD code in the reference (an ulp apart at times): sample's
# directions then agree to a few ulps (tests/materials/test_bsdf_kernels.py says how close).
_F82_F5 = _F32((6.0 / 7.0) ** 5)
_F82_C = _F32(7.0 / ((6.0 / 7.0) ** 5 * (6.0 / 7.0)))


@lru_cache(maxsize=None)
def _tables_f32():
    """The tables as the lookups read them (float32, C order): e_ss, e_avg, s_tab, glass_out, glass_in."""
    return tuple(np.ascontiguousarray(t, _F32) for t in _tables())


@njit
def _max_k(x, lo):
    """np.maximum(x, lo) for a constant lo: NaN propagates."""
    return lo if x < lo else x


@njit
def _clip_k(x, lo, hi):
    """np.clip(x, lo, hi): NaN propagates."""
    if x < lo:
        return lo
    if x > hi:
        return hi
    return x


@njit
def _cell_k(x, n):
    zero, one = np.float32(0.0), np.float32(1.0)
    f = _clip_k(x, zero, one) * np.float32(n - 1)
    if not f >= zero:  # NaN: the reference's index would be garbage too; stay inside the table
        f = zero
    i = int(f)
    if i > n - 2:
        i = n - 2
    return i, f - np.float32(i)


@njit
def _lookup2_k(tab, x, y):
    one = np.float32(1.0)
    i, tx = _cell_k(x, tab.shape[0])
    j, ty = _cell_k(y, tab.shape[1])
    return (one - tx) * ((one - ty) * tab[i, j] + ty * tab[i, j + 1]) + tx * ((one - ty) * tab[i + 1, j]
                                                                               + ty * tab[i + 1, j + 1])


@njit
def _lookup3_k(tab, x, y, z):
    one = np.float32(1.0)
    i, tx = _cell_k(x, tab.shape[0])
    j, ty = _cell_k(y, tab.shape[1])
    k, tz = _cell_k(z, tab.shape[2])
    r0 = (one - tx) * ((one - ty) * tab[i, j, k] + ty * tab[i, j + 1, k]) + tx * ((one - ty) * tab[i + 1, j, k]
                                                                                  + ty * tab[i + 1, j + 1, k])
    k1 = k + 1
    r1 = (one - tx) * ((one - ty) * tab[i, j, k1] + ty * tab[i, j + 1, k1]) + tx * ((one - ty) * tab[i + 1, j, k1]
                                                                                    + ty * tab[i + 1, j + 1, k1])
    return (one - tz) * r0 + tz * r1


@njit
def _e_ss_k(e_tab, eavg_tab, alpha, mu):
    """_e_ss for one hit: (max(E(r, sqrt(mu)), 1e-3), E_avg(r))."""
    one = np.float32(1.0)
    r = np.sqrt(alpha)
    e = _max_k(_lookup2_k(e_tab, r, np.sqrt(_max_k(mu, np.float32(0.0)))), np.float32(1e-3))
    i, t = _cell_k(r, eavg_tab.shape[0])
    return e, (one - t) * eavg_tab[i] + t * eavg_tab[i + 1]


@njit
def _ms_k(e, ea, fss):
    """_ms_factor's last lines for one float32 fss."""
    one = np.float32(1.0)
    missing = (one - e) / e
    return one + fss * ea / _max_k(one - fss * (one - ea), np.float32(1e-6)) * missing


@njit
def _ms64_k(e, ea, fss):
    """The same for a float64 fss (PLASTIC's): NumPy computes it in float64, then rounds."""
    one = np.float32(1.0)
    missing = (one - e) / e
    fms = fss * np.float64(ea) / _max_k(1.0 - fss * np.float64(one - ea), 1e-6)
    return np.float32(1.0 + fms * np.float64(missing))


@njit
def _fresnel_k(cos_i, eta):
    """spectral.optics.fresnel_dielectric for float32 scalars: (F, cos_t)."""
    zero, one, half, tiny = np.float32(0.0), np.float32(1.0), np.float32(0.5), np.float32(1e-30)
    c = _clip_k(cos_i, zero, one)
    sin2_t = (one - c * c) / (eta * eta)
    cos_t = np.sqrt(_max_k(one - sin2_t, zero))
    r_par = (eta * c - cos_t) / _max_k(eta * c + cos_t, tiny)
    r_perp = (c - eta * cos_t) / _max_k(c + eta * cos_t, tiny)
    return (one if sin2_t >= one else half * (r_par * r_par + r_perp * r_perp)), cos_t


@njit
def _f82_b_k(f0, tint):
    one = np.float32(1.0)
    return (f0 + (one - f0) * _F82_F5) * _F82_C * (one - tint)


@njit
def _glass_factor_k(alpha, mu, eta, t_out, t_in):
    one, zero = np.float32(1.0), np.float32(0.0)
    ior = eta if eta >= one else one / _max_k(eta, np.float32(1e-6))
    z = np.sqrt((ior - one) / (ior + one)) / np.float32(_Z_MAX_GLASS)
    r = np.sqrt(alpha)
    x = np.sqrt(_max_k(mu, zero))
    e = _lookup3_k(t_out, r, x, z) if eta >= one else _lookup3_k(t_in, r, x, z)
    return one / _max_k(e, np.float32(1e-3))


@njit
def _pairwise_block_k(a, lo, n):
    """NumPy's pairwise float32 sum of a[lo:lo + n] for n <= 128 (numpy/core/src/umath/loops_utils.h.src)."""
    if n < 8:
        res = np.float32(0.0)
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - (n % 8):
        j = lo + i
        r0 += a[j]
        r1 += a[j + 1]
        r2 += a[j + 2]
        r3 += a[j + 3]
        r4 += a[j + 4]
        r5 += a[j + 5]
        r6 += a[j + 6]
        r7 += a[j + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


# NumPy halves longer runs (at a multiple of 8) and adds the halves' sums. Three levels written
# out instead of a recursion, which numba's on-disk cache does not reload safely (a segfault):
# up to 968 wavelengths (_kernel_fits sends longer rows to the reference).
_PAIRWISE_MAX = 968


@njit
def _pairwise_1(a, lo, n):
    if n <= 128:
        return _pairwise_block_k(a, lo, n)
    n2 = n // 2
    n2 -= n2 % 8
    return _pairwise_block_k(a, lo, n2) + _pairwise_block_k(a, lo + n2, n - n2)


@njit
def _pairwise_2(a, lo, n):
    if n <= 128:
        return _pairwise_block_k(a, lo, n)
    n2 = n // 2
    n2 -= n2 % 8
    return _pairwise_1(a, lo, n2) + _pairwise_1(a, lo + n2, n - n2)


@njit
def _pairwise_sum_k(a, lo, n):
    if n <= 128:
        return _pairwise_block_k(a, lo, n)
    n2 = n // 2
    n2 -= n2 % 8
    return _pairwise_2(a, lo, n2) + _pairwise_2(a, lo + n2, n - n2)


@njit
def _mean_k(a):
    """np.mean of a float32 row: 0 + the pairwise sum, divided by the count in float32."""
    return (np.float32(0.0) + _pairwise_sum_k(a, 0, a.shape[0])) / np.float32(a.shape[0])


@njit
def _lobe_factor_k(code, b, base, er, f82, has_f82, alpha, mu, e_tab, eavg_tab, out):
    """_lobe_factor of a CONDUCTOR or GLOSSY hit into out (k,)."""
    zero, one = np.float32(0.0), np.float32(1.0)
    c21, c126 = np.float32(21.0), np.float32(126.0)
    e, ea = _e_ss_k(e_tab, eavg_tab, alpha, mu)
    if code == 4:  # GLOSSY: F = its colour
        for j in range(out.shape[0]):
            out[j] = _ms_k(e, ea, _clip_k(base[b, j], zero, one))
    elif has_f82:  # CONDUCTOR: _f82_fss
        for j in range(out.shape[0]):
            f0 = base[b, j]
            out[j] = _ms_k(e, ea, _clip_k(f0 + (one - f0) / c21 - f82[b, j] / c126, zero, one))
    else:
        for j in range(out.shape[0]):
            f0 = base[b, j]
            out[j] = _ms_k(e, ea, _clip_k(f0 + (one - f0) / c21 - _f82_b_k(f0, er[j]) / c126, zero, one))


@njit
def _plastic_terms_k(b, spec_f0, tr, alpha, mu, e_tab, eavg_tab, s_tab, f0t, fac, e_spec):
    """_plastic_terms of one hit: f0t, fac, e_spec into the (k,) rows; returns the layer's eta."""
    zero, one = np.float32(0.0), np.float32(1.0)
    sf = spec_f0[b]
    f0 = _clip_k(sf, zero, np.float32(0.99))
    r = np.sqrt(_clip_k(f0, zero, np.float32(0.99)))
    eta = (one + r) / (one - r)
    e64 = np.float64(eta)
    if e64 < 1.0:
        fss_d = 0.997118 + e64 * (0.1014 - e64 * (0.965241 + e64 * 0.130607))
    else:
        fss_d = (e64 - 1.0) / (4.08567 + 1.00071 * e64)
    s_avg = _clip_k((fss_d - np.float64(f0)) / np.float64(_max_k(one - f0, np.float32(1e-6))), 0.0, 1.0)
    e, ea = _e_ss_k(e_tab, eavg_tab, alpha, mu)
    s_int = _lookup3_k(s_tab, np.sqrt(alpha), np.sqrt(_max_k(mu, zero)),
                       np.sqrt(np.sqrt(f0)) / np.float32(_Z_MAX_SPEC))
    for j in range(f0t.shape[0]):
        ft = _clip_k(sf * tr[j], zero, one)
        f0t[j] = ft
        fa = _ms64_k(e, ea, np.float64(ft) + np.float64(one - ft) * s_avg)
        fac[j] = fa
        e_spec[j] = _clip_k(fa * (ft * e + (one - ft) * s_int), zero, one)
    return eta


@njit
def _plastic_p_spec_k(b, base, e_spec, tmp):
    one = np.float32(1.0)
    for j in range(tmp.shape[0]):
        tmp[j] = base[b, j] * (one - e_spec[j])
    es, ed = _mean_k(e_spec), _mean_k(tmp)
    tot = es + ed
    return es / tot if tot > np.float32(0.0) else one


@njit
def _plastic_s_k(cos, eta, spec_f0):
    zero, one = np.float32(0.0), np.float32(1.0)
    f0 = _clip_k(spec_f0, zero, np.float32(0.99))
    fr, _ = _fresnel_k(cos, eta)
    return _clip_k((fr - f0) / _max_k(one - f0, np.float32(1e-6)), zero, one)


@njit
def _plastic_eval_k(b, base, alpha, spec_f0, eta_l, f0t, fac, e_spec, ps, ox, oy, oz, ix, iy, iz, fcos):
    """_eval_lobe's PLASTIC lines for one hit with its terms; returns the pdf."""
    zero, one = np.float32(0.0), np.float32(1.0)
    c = (iz if iz > zero else zero) * _INV_PI
    for j in range(fcos.shape[1]):
        fcos[b, j] = base[b, j] * (one - e_spec[j]) * c
    pdf = (one - ps) * c
    if iz > zero and alpha[b] >= np.float32(_MIN_ALPHA):
        fc, pd, coh = reflection_1(alpha[b], ox, oy, oz, ix, iy, iz)
        s = _plastic_s_k(coh, eta_l, spec_f0[b])
        for j in range(fcos.shape[1]):
            f = f0t[j] + (one - f0t[j]) * s
            fcos[b, j] += f * fac[j] * fc
        pdf += ps * pd
    return pdf


@njit
def _eval_row_k(b, code, base, er, alpha, eta, spec_f0, tr, f82, ms, has_ms, ox, oy, oz, ix, iy, iz,
                e_tab, eavg_tab, s_tab, g_out, g_in, fcos, s1, s2, s3, s4):
    """_eval_lobe for one valid hit (wo.z > 0, wi on a consistent side) into fcos[b]; returns the pdf."""
    zero, one = np.float32(0.0), np.float32(1.0)
    k = fcos.shape[1]
    up = iz > zero
    if code == 0:  # LAMBERT
        c = (iz if up else zero) * _INV_PI
        for j in range(k):
            fcos[b, j] = base[b, j] * c
        return c
    rough = alpha[b] >= np.float32(_MIN_ALPHA)
    if code == 1 or code == 4:  # CONDUCTOR, GLOSSY
        if not (up and rough):
            return zero
        fc, pd, coh = reflection_1(alpha[b], ox, oy, oz, ix, iy, iz)
        if not has_ms:
            _lobe_factor_k(code, b, base, er, f82, False, alpha[b], oz, e_tab, eavg_tab, s1)
        fac = ms[b] if has_ms else s1
        if code == 4:
            for j in range(k):
                fcos[b, j] = base[b, j] * (fc * fac[j])
            return pd
        s = _clip_k(one - coh, zero, one)
        s2 = s * s
        s5 = s2 * s2 * s
        t1, t3 = one - s5, coh * s5 * s
        if has_ms:  # branch-free inner loops (vectorised)
            for j in range(k):
                fcos[b, j] = _clip_k(base[b, j] * t1 + s5 - f82[b, j] * t3, zero, one) * (fc * fac[j])
        else:
            for j in range(k):
                f0 = base[b, j]
                fcos[b, j] = _clip_k(f0 * t1 + s5 - _f82_b_k(f0, er[j]) * t3, zero, one) * (fc * fac[j])
        return pd
    if code == 2:  # DIELECTRIC
        if not rough:
            return zero
        e = eta[b]
        if up:
            fc, pd, coh = reflection_1(alpha[b], ox, oy, oz, ix, iy, iz)
            f, _ = _fresnel_k(coh, e)
            v = f * fc * _glass_factor_k(alpha[b], oz, e, g_out, g_in)
            for j in range(k):
                fcos[b, j] = base[b, j] * v
            return f * pd
        if not abs(e - one) >= np.float32(1e-4):
            return zero
        a2 = alpha[b] * alpha[b]
        hx, hy, hz = e * ix + ox, e * iy + oy, e * iz + oz
        n = _max_k(np.sqrt(((zero + hx * hx) + hy * hy) + hz * hz), np.float32(1e-30))
        hx, hy, hz = hx / n, hy / n, hz / n
        if hz < zero:
            hx, hy, hz = -hx, -hy, -hz
        coh = ((zero + ox * hx) + oy * hy) + oz * hz
        cih = ((zero + ix * hx) + iy * hy) + iz * hz
        f, _ = _fresnel_k(coh, e)
        d = ggx_d_1(a2, hx, hy, hz)
        lo, li = smith_lambda_1(a2, ox, oy, oz), smith_lambda_1(a2, ix, iy, iz)
        denom = cih + coh / e
        jac = abs(cih) / _max_k(denom * denom, np.float32(1e-30))
        t = one - f if (coh > zero and cih < zero) else zero
        val = t * d * coh * jac / (oz * (one + lo + li))
        v = val * _glass_factor_k(alpha[b], oz, e, g_out, g_in)
        for j in range(k):
            fcos[b, j] = base[b, j] * v
        return t * d * coh * jac / (oz * (one + lo))
    # PLASTIC
    eta_l = _plastic_terms_k(b, spec_f0, tr, alpha[b], oz, e_tab, eavg_tab, s_tab, s1, s2, s3)
    ps = _plastic_p_spec_k(b, base, s3, s4)
    return _plastic_eval_k(b, base, alpha, spec_f0, eta_l, s1, s2, s3, ps, ox, oy, oz, ix, iy, iz, fcos)


@njit
def _frame_k(nx, ny, nz):
    """tangent_frame of one normal: (ux, uy, uz, vx, vy, vz)."""
    one = np.float32(1.0)
    sg = one if nz >= np.float32(0.0) else -one
    a = -one / (sg + nz)
    b = nx * ny * a
    return one + sg * nx * nx * a, sg * b, -sg * nx, b, sg + ny * ny * a, -ny


@njit
def _dot3_k(a, b, c, x, y, z):
    """np.sum(w * u, axis=1) of one row: 0 + the products in order."""
    return ((np.float32(0.0) + a * x) + b * y) + c * z


@njit
def _prepare_kernel(wo, ns, fu, fv, wl):
    """_prepare's frame and local wo per hit."""
    for b in range(wo.shape[0]):
        ux, uy, uz, vx, vy, vz = _frame_k(ns[b, 0], ns[b, 1], ns[b, 2])
        fu[b, 0], fu[b, 1], fu[b, 2] = ux, uy, uz
        fv[b, 0], fv[b, 1], fv[b, 2] = vx, vy, vz
        x, y, z = wo[b, 0], wo[b, 1], wo[b, 2]
        wl[b, 0] = _dot3_k(x, y, z, ux, uy, uz)
        wl[b, 1] = _dot3_k(x, y, z, vx, vy, vz)
        wl[b, 2] = _dot3_k(x, y, z, ns[b, 0], ns[b, 1], ns[b, 2])


@njit
def _outgoing_kernel(code, base, edge, se, alpha, wl, e_tab, eavg_tab, f82, ms):
    """with_outgoing's F82 b (CONDUCTOR) and multiscatter factor (1 on smooth hits) per hit;
    ``se``: edge's row step (0: one row for every hit)."""
    k = base.shape[1]
    for b in range(base.shape[0]):
        er = edge[b * se]
        if code == 1:
            for j in range(k):
                f82[b, j] = _f82_b_k(base[b, j], er[j])
        if alpha[b] >= np.float32(_MIN_ALPHA):
            _lobe_factor_k(code, b, base, er, f82, code == 1, alpha[b], wl[b, 2], e_tab, eavg_tab, ms[b])
        else:
            for j in range(k):
                ms[b, j] = np.float32(1.0)


@njit
def _evaluate_kernel(lobe, base, edge, se, alpha, eta, spec_f0, tint, st, f82, ms, has_ms, fu, fv, ns, wl, wi, ng,
                     e_tab, eavg_tab, s_tab, g_out, g_in, fcos, pdf):
    """evaluate() per hit: wi into the frame, the side checks, the hit's lobe."""
    zero = np.float32(0.0)
    k = base.shape[1]
    s1, s2, s3, s4 = np.empty(k, np.float32), np.empty(k, np.float32), np.empty(k, np.float32), np.empty(k, np.float32)
    for b in range(lobe.shape[0]):
        for j in range(k):
            fcos[b, j] = zero
        pdf[b] = zero
        x, y, z = wi[b, 0], wi[b, 1], wi[b, 2]
        ix = _dot3_k(x, y, z, fu[b, 0], fu[b, 1], fu[b, 2])
        iy = _dot3_k(x, y, z, fv[b, 0], fv[b, 1], fv[b, 2])
        iz = _dot3_k(x, y, z, ns[b, 0], ns[b, 1], ns[b, 2])
        side = _dot3_k(x, y, z, ng[b, 0], ng[b, 1], ng[b, 2])
        consistent = side > zero if iz > zero else (side < zero and iz < zero)
        if not (wl[b, 2] > zero and consistent):
            continue
        pdf[b] = _eval_row_k(b, lobe[b], base, edge[b * se], alpha, eta, spec_f0, tint[b * st], f82, ms, has_ms,
                             wl[b, 0], wl[b, 1], wl[b, 2], ix, iy, iz, e_tab, eavg_tab, s_tab, g_out, g_in,
                             fcos, s1, s2, s3, s4)


@njit
def _cosine_sample_k(u1, u2):
    """_cosine_sample for one pair of numbers (concentric disk, lifted)."""
    zero, one, two = np.float32(0.0), np.float32(1.0), np.float32(2.0)
    a, b = two * u1 - one, two * u2 - one
    q = np.float32(np.pi / 4)
    if abs(a) > abs(b):
        r = a
        phi = q * b / (one if a == zero else a)
    else:
        r = b
        phi = np.float32(np.pi / 2) - q * a / (one if b == zero else b)
    x, y = r * np.cos(phi), r * np.sin(phi)
    w = one - x * x - y * y
    return x, y, np.sqrt(zero if w < zero else w)


@njit
def _sample_row_k(b, code, base, er, alpha, eta, spec_f0, tr, f82, ms, has_ms, ox, oy, oz, u0, u1, u2,
                  e_tab, eavg_tab, s_tab, g_out, g_in, weight, s1, s2, s3, s4):
    """_sample_lobe for one hit with wo.z > 0: (wi_x, wi_y, wi_z, pdf, flags), weight[b] filled."""
    zero, one, four = np.float32(0.0), np.float32(1.0), np.float32(4.0)
    inf = np.float32(np.inf)
    k = weight.shape[1]
    for j in range(k):
        weight[b, j] = zero
    if code == 0:  # LAMBERT
        wx, wy, wz = _cosine_sample_k(u0, u1)
        if wz > zero:
            for j in range(k):
                weight[b, j] = base[b, j]
            return wx, wy, wz, wz * _INV_PI, 1
        return wx, wy, wz, zero, 0
    al = alpha[b]
    rough = al >= np.float32(_MIN_ALPHA)
    if rough:
        hx, hy, hz = sample_vndf_1(ox, oy, oz, al, u0, u1)
    else:
        hx, hy, hz = zero, zero, one
    coh = _dot3_k(ox, oy, oz, hx, hy, hz)
    a2 = al * al
    lo = smith_lambda_1(a2, ox, oy, oz)
    two_c = np.float32(2.0) * coh
    rx, ry, rz = two_c * hx - ox, two_c * hy - oy, two_c * hz - oz
    if code == 1 or code == 4:  # CONDUCTOR, GLOSSY: reflect about h
        if not (rz > zero and coh > zero):
            return rx, ry, rz, zero, 0
        g = (one + lo) / (one + lo + smith_lambda_1(a2, rx, ry, rz)) if rough else one
        if not has_ms:
            if rough:
                _lobe_factor_k(code, b, base, er, f82, False, al, oz, e_tab, eavg_tab, s1)
            else:
                for j in range(k):
                    s1[j] = one
        fac = ms[b] if has_ms else s1
        if code == 4:
            for j in range(k):
                weight[b, j] = base[b, j] * fac[j] * g
        else:
            s = _clip_k(one - coh, zero, one)
            s2 = s * s
            sp = s2 * s2 * s
            t1, t3 = one - sp, coh * sp * s
            if has_ms:
                for j in range(k):
                    weight[b, j] = _clip_k(base[b, j] * t1 + sp - f82[b, j] * t3, zero, one) * fac[j] * g
            else:
                for j in range(k):
                    f0 = base[b, j]
                    weight[b, j] = _clip_k(f0 * t1 + sp - _f82_b_k(f0, er[j]) * t3, zero, one) * fac[j] * g
        if rough:
            return rx, ry, rz, ggx_d_1(a2, hx, hy, hz) / ((one + lo) * four * oz), 2
        return rx, ry, rz, inf, 2 | 8
    if code == 2:  # DIELECTRIC: reflect with probability F, else refract
        e = eta[b]
        unit = abs(e - one) < np.float32(1e-4)
        f, cos_t = _fresnel_k(coh, e)
        if unit:
            f = zero
        refl = u2 < f
        if refl:
            wx, wy, wz = rx, ry, rz
        elif unit:
            wx, wy, wz = -ox, -oy, -oz
        else:
            c = coh / e - cos_t
            wx, wy, wz = -ox / e + c * hx, -oy / e + c * hy, -oz / e + c * hz
        if not ((wz > zero if refl else wz < zero) and coh > zero):
            return wx, wy, wz, zero, 0
        g = (one + lo) / (one + lo + smith_lambda_1(a2, wx, wy, wz)) if rough else one
        fac = _glass_factor_k(al, oz, e, g_out, g_in) if rough else one
        scale = g * fac
        for j in range(k):
            weight[b, j] = base[b, j] * scale
        singular = (not rough) or (unit and not refl)
        fl = (2 if refl else 4) | (8 if singular else 0)
        if singular:
            return wx, wy, wz, inf, fl
        d_vis = ggx_d_1(a2, hx, hy, hz) * coh / (oz * (one + lo))
        if refl:
            return wx, wy, wz, f * d_vis / _max_k(four * coh, np.float32(1e-30)), fl
        cih = _dot3_k(wx, wy, wz, hx, hy, hz)
        denom = cih + coh / e
        return wx, wy, wz, (one - f) * d_vis * abs(cih) / _max_k(denom * denom, np.float32(1e-30)), fl
    # PLASTIC: the specular layer with its albedo share, else the diffuse base
    eta_l = _plastic_terms_k(b, spec_f0, tr, al, oz, e_tab, eavg_tab, s_tab, s1, s2, s3)
    ps = _plastic_p_spec_k(b, base, s3, s4)
    spec = u2 < ps
    if spec:
        wx, wy, wz = rx, ry, rz
    else:
        wx, wy, wz = _cosine_sample_k(u0, u1)
    ok = wz > zero and (coh > zero if spec else True)
    if not ok:
        return wx, wy, wz, zero, 0
    if spec and not rough:  # a smooth coat: delta reflection, weight F / p_spec
        s = _plastic_s_k(oz, eta_l, spec_f0[b])
        for j in range(k):
            weight[b, j] = (s1[j] + (one - s1[j]) * s) / ps
        return wx, wy, wz, inf, 2 | 8
    pd = _plastic_eval_k(b, base, alpha, spec_f0, eta_l, s1, s2, s3, ps, ox, oy, oz, wx, wy, wz, weight)
    if not pd > zero:
        for j in range(k):
            weight[b, j] = zero
        return wx, wy, wz, zero, 0
    for j in range(k):
        weight[b, j] = weight[b, j] / pd
    return wx, wy, wz, pd, 2 if spec else 1


@njit
def _sample_kernel(lobe, base, edge, se, alpha, eta, spec_f0, tint, st, f82, ms, has_ms, fu, fv, ns, wl, ng, u,
                   e_tab, eavg_tab, s_tab, g_out, g_in, wi, weight, pdf, flags):
    """sample() per hit: the hit's lobe in the local frame, wi back to the world, the side check."""
    zero, one = np.float32(0.0), np.float32(1.0)
    k = base.shape[1]
    s1, s2, s3, s4 = np.empty(k, np.float32), np.empty(k, np.float32), np.empty(k, np.float32), np.empty(k, np.float32)
    for b in range(lobe.shape[0]):
        ox, oy, oz = wl[b, 0], wl[b, 1], wl[b, 2]
        if oz > zero:
            x, y, z, pd, fl = _sample_row_k(b, lobe[b], base, edge[b * se], alpha, eta, spec_f0, tint[b * st], f82,
                                            ms, has_ms,
                                            ox, oy, oz, u[b, 0], u[b, 1], u[b, 2], e_tab, eavg_tab, s_tab,
                                            g_out, g_in, weight, s1, s2, s3, s4)
        else:
            x, y, z, pd, fl = zero, zero, one, zero, 0
            for j in range(k):
                weight[b, j] = zero
        wx = x * fu[b, 0] + y * fv[b, 0] + z * ns[b, 0]
        wy = x * fu[b, 1] + y * fv[b, 1] + z * ns[b, 1]
        wz = x * fu[b, 2] + y * fv[b, 2] + z * ns[b, 2]
        n = _max_k(np.sqrt(((zero + wx * wx) + wy * wy) + wz * wz), np.float32(1e-30))
        wx, wy, wz = wx / n, wy / n, wz / n
        wi[b, 0], wi[b, 1], wi[b, 2] = wx, wy, wz
        side = _dot3_k(wx, wy, wz, ng[b, 0], ng[b, 1], ng[b, 2])
        if fl != 0 and ((side >= zero) if (fl & 4) != 0 else (side <= zero)):
            pd, fl = zero, 0
            for j in range(k):
                weight[b, j] = zero
        pdf[b], flags[b] = pd, fl


@njit
def _gather_kernel(mat, lam, lobe, spec_tint, edge, tint):
    """params_from_materials' per-hit tint and F82 edge rows: specular_tint[mat] (or at lam), and
    min(tint, 1) on CONDUCTOR hits, 1 elsewhere."""
    one = np.float32(1.0)
    k = tint.shape[1]
    for b in range(mat.shape[0]):
        for j in range(k):
            t = spec_tint[mat[b], j] if lam.shape[0] == 0 else spec_tint[mat[b], lam[b]]
            tint[b, j] = t
            edge[b, j] = (one if t > one else t) if lobe[b] == 1 else one


_EMPTY2 = np.zeros((0, 0), _F32)


def _is32(a, ndim) -> bool:
    return isinstance(a, np.ndarray) and a.dtype == _F32 and a.ndim == ndim


def _kernel_fits(p: SurfaceParams) -> bool:
    """The kernels take float32 parameters as params_from_materials makes them (anything else:
    the reference, whose NumPy promotions they would not reproduce)."""
    if not kernels_enabled() or not len(p.lobe) or p.base.ndim != 2 or p.base.shape[1] > _PAIRWISE_MAX:
        return False
    if p.film_d is not None:  # thin films: the reference (core/materials/thin_film.py's Airy sum)
        return False
    if ((p.lobe == OREN_NAYAR) | (p.lobe == SHEEN)).any():  # Oren-Nayar and sheen have no compiled twin yet
        return False
    B = len(p.lobe)
    if not (all(_is32(a, 2) and a.shape == p.base.shape for a in (p.base, p.edge, p.spec_tint))
            and all(_is32(a, 1) and a.shape == (B,) for a in (p.alpha, p.eta, p.spec_f0))):
        return False
    if p.ms is not None and not (_is32(p.ms, 2) and p.ms.shape == p.base.shape
                                 and (p.f82 is None or (_is32(p.f82, 2) and p.f82.shape == p.base.shape))):
        return False
    if p.ms is not None and p.f82 is None and (p.lobe == CONDUCTOR).any():
        return False
    return p.wo_local is None or all(_is32(a, 2) and a.shape == (B, 3) for a in (p.frame_u, p.frame_v, p.wo_local))


def _sheen_split(p: SurfaceParams):
    """(the sheen rows, the others) where the kernels are on and would take the others (a batch
    mixing the SHEEN lobe, which has no compiled twin, with kernel lobes); None otherwise."""
    if not kernels_enabled() or not len(p.lobe):
        return None
    sheen = p.lobe == SHEEN
    if sheen.all() or not sheen.any() or (p.lobe == OREN_NAYAR).any():
        return None
    rest = np.flatnonzero(~sheen)
    if not _kernel_fits(p.take(rest)):
        return None
    return np.flatnonzero(sheen), rest


def _merged(split, parts, n):
    """The per-row results of ``parts`` (one tuple of arrays per index set of ``split``) in one batch of n."""
    out = []
    for j in range(len(parts[0])):
        arrs = [np.asarray(part[j]) for part in parts]
        shape = (n,) + max((a.shape[1:] for a in arrs), key=lambda t: (len(t), int(np.prod(t))))
        full = np.zeros(shape, arrs[0].dtype)
        for idx, a in zip(split, arrs):
            full[idx] = a
        out.append(full)
    return tuple(out)


def _rows(a):
    """(C-order array, row step) for the kernels: a (B, k) array broadcast from one row (stride 0,
    as params_from_materials makes for a batch of one material and lobe) as that row (1, k), step 0."""
    if a.shape[0] > 1 and a.strides[0] == 0:
        return np.ascontiguousarray(a[:1]), 0
    return np.ascontiguousarray(a), 1


def _c3(a):
    return np.ascontiguousarray(a, _F32)


def _prepare_with_kernel(p, wo, ns):
    """_prepare by _prepare_kernel (the same bits)."""
    wo, ns = _c3(wo), _c3(ns)
    if p.wo_local is not None:
        return wo, ns, _c3(p.frame_u), _c3(p.frame_v), _c3(p.wo_local)
    fu, fv, wl = (np.empty((len(wo), 3), _F32) for _ in range(3))
    _prepare_kernel(wo, ns, fu, fv, wl)
    return wo, ns, fu, fv, wl


def _kernel_params(p):
    """The parameter arrays in the kernels' argument order (C order), and the tables."""
    c = np.ascontiguousarray
    has_ms = p.ms is not None
    f82 = c(p.f82) if has_ms and p.f82 is not None else _EMPTY2
    ms = c(p.ms) if has_ms else _EMPTY2
    lobe = p.lobe if p.lobe.dtype == np.int32 else np.asarray(p.lobe, np.int32)
    edge, se = _rows(p.edge)
    tint, st = _rows(p.spec_tint)
    if (lobe == LAMBERT).all():  # Lambert alone never reads the tables (nor makes them)
        tabs = (np.zeros((2, 2), _F32), np.zeros(2, _F32), np.zeros((2, 2, 2), _F32),
                np.zeros((2, 2, 2), _F32), np.zeros((2, 2, 2), _F32))
    else:
        tabs = _tables_f32()
    return (c(lobe), c(p.base), edge, se, c(p.alpha), c(p.eta), c(p.spec_f0), tint, st, f82, ms,
            has_ms), tabs


def _with_outgoing_kernel(params, wo, ns):
    wo, ns, fu, fv, wl = _prepare_with_kernel(params, wo, ns)
    out = replace(params, frame_u=fu, frame_v=fv, wo_local=wl)
    lobe = params.lobe
    if lobe[0] in (CONDUCTOR, GLOSSY) and (lobe == lobe[0]).all():
        code = int(lobe[0])
        e_tab, eavg_tab = _tables_f32()[:2]
        shape = params.base.shape
        b = np.empty(shape, _F32) if code == CONDUCTOR else _EMPTY2
        ms = np.empty(shape, _F32)
        c = np.ascontiguousarray
        _outgoing_kernel(code, c(params.base), *_rows(params.edge), c(params.alpha), wl, e_tab, eavg_tab, b, ms)
        out.f82, out.ms = (b if code == CONDUCTOR else None), ms
    return out


def _evaluate_with_kernel(params, wo, wi, ns, ng):
    wo, ns, fu, fv, wl = _prepare_with_kernel(params, wo, ns)
    args, tabs = _kernel_params(params)
    fcos = np.empty(params.base.shape, _F32)
    pdf = np.empty(len(params.lobe), _F32)
    _evaluate_kernel(*args, fu, fv, ns, wl, _c3(wi), _c3(ng), *tabs, fcos, pdf)
    return fcos, pdf


def _sample_with_kernel(params, wo, ns, ng, u):
    wo, ns, fu, fv, wl = _prepare_with_kernel(params, wo, ns)
    args, tabs = _kernel_params(params)
    B = len(params.lobe)
    wi = np.empty((B, 3), _F32)
    weight = np.empty(params.base.shape, _F32)
    pdf = np.empty(B, _F32)
    flags = np.empty(B, np.int32)
    _sample_kernel(*args, fu, fv, ns, wl, _c3(ng), _c3(u), *tabs, wi, weight, pdf, flags)
    return wi, weight, pdf, flags
