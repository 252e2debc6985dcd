"""Geometric optics at a smooth interface: reflection, refraction, Fresnel, and dispersion.

- Law of reflection and Snell's law in vector form (e.g. Pharr, Jakob & Humphreys, *Physically
  Based Rendering*, 4th ed., 2023, section 9.3).
- Fresnel equations for an unpolarised wave at a dielectric interface (ibid., section 9.3.3):
  R = (R_s + R_p) / 2, total internal reflection when sin(theta_t) >= 1. The one Fresnel function
  of the renderer (smooth glass, rough glass at the microfacet, Principled's specular layer, the
  opal's surface): its ``eta`` is n_transmitted / n_incident, pbrt-v4's ``FrDielectric`` convention.
  ``refract``'s is the inverse, n_incident / n_transmitted: the factor Snell's law multiplies the
  incident direction by.
- Sellmeier's equation n^2 = 1 + sum B_k lambda^2 / (lambda^2 - C_k), lambda in micrometres, with the
  coefficients of docs/physics.md section 2.1: SCHOTT N-BK7 (SCHOTT data sheet), fused silica
  (Malitson, I. H. 1965, JOSA 55(10), doi:10.1364/JOSA.55.001205), diamond (Peter, F. 1923,
  Z. Physik 15).
- Cauchy's n = A + B / lambda^2 fitted to an artist's IOR n_d (587.56 nm) and Abbe number V_d, with
  the Fraunhofer F (486.13 nm) and C (656.27 nm) lines.

Directions are unit vectors; ``d`` is the direction of travel, ``n`` a unit normal. All functions
are vectorised over leading axes.
"""

from __future__ import annotations

import numpy as np

from ..util.enums import DispersionModel, codes
from ..util.jit import kernels_enabled, njit

__all__ = [
    "SELLMEIER_PRESETS",
    "DISPERSION_MODELS",
    "LAMBDA_D",
    "LAMBDA_F",
    "LAMBDA_C",
    "reflect",
    "refract",
    "fresnel_dielectric",
    "sellmeier_ior",
    "cauchy_from_abbe",
    "ior_spectrum",
]

LAMBDA_D = 587.56  # nm, helium d line
LAMBDA_F = 486.13  # nm, hydrogen F line
LAMBDA_C = 656.27  # nm, hydrogen C line

#: Sellmeier coefficients (B1..B3, C1..C3 in um^2) of docs/physics.md section 2.1.
SELLMEIER_PRESETS: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {
    "BK7": ((1.03961212, 0.231792344, 1.01046945), (0.00600069867, 0.0200179144, 103.560653)),
    "FUSED_SILICA": ((0.6961663, 0.4079426, 0.8974794), (0.0684043**2, 0.1162414**2, 9.896161**2)),
    "DIAMOND": ((0.3306, 4.3356, 0.0), (0.175**2, 0.106**2, 0.0)),
}

#: Dispersion models: name -> stable code (enums.py; stored in scene files).
DISPERSION_MODELS = codes(DispersionModel)


def reflect(d: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Mirror direction of travel ``d`` about the normal ``n`` (either side). Rows (B, 3) of one
    float dtype run the compiled kernel when kernels are on (``_reflect_kernel``: the same
    operations in the same order and precision, the same bits)."""
    if (kernels_enabled() and isinstance(d, np.ndarray) and isinstance(n, np.ndarray) and d.ndim == 2
            and d.shape == n.shape and d.shape[1] == 3 and d.dtype == n.dtype and d.dtype.char in "fd"):
        out = np.empty(d.shape, d.dtype)
        _reflect_kernel(d, n, d.dtype.type(2.0), out)
        return out
    return d - 2.0 * np.sum(d * n, axis=-1, keepdims=True) * n


@njit
def _reflect_kernel(d, n, two, out):
    """reflect per row: d - (2 (d . n)) n, the dot product summed in order as np.sum does."""
    for i in range(d.shape[0]):
        t = two * (d[i, 0] * n[i, 0] + d[i, 1] * n[i, 1] + d[i, 2] * n[i, 2])
        for k in range(3):
            out[i, k] = d[i, k] - t * n[i, k]


def refract(d: np.ndarray, n: np.ndarray, eta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Snell's law. ``n`` faces the incoming side (dot(d, n) < 0); ``eta`` = n_incident / n_transmitted.

    Returns (transmitted direction, total-internal-reflection mask). Where TIR occurs the direction
    is the mirror direction, so the result is always a valid unit vector.
    """
    eta = np.asarray(eta)
    cos_i = -np.sum(d * n, axis=-1)
    sin2_t = eta * eta * np.maximum(0.0, 1.0 - cos_i * cos_i)
    tir = sin2_t > 1.0
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2_t))
    t = eta[..., None] * d + (eta * cos_i - cos_t)[..., None] * n
    t = np.where(tir[..., None], reflect(d, n), t)
    return t, tir


def fresnel_dielectric(cos_i, eta) -> tuple[np.ndarray, np.ndarray]:
    """(F, cos_t): the unpolarised Fresnel reflectance and the refracted cosine at a dielectric
    interface. ``cos_i`` >= 0 on the incident side (negative values count as 0, grazing),
    ``eta`` = n_transmitted / n_incident. F = 1 under total internal reflection (cos_t = 0 there).
    Float32 in, float32 out (float64 stays float64). Arrays run the compiled kernel when kernels
    are on (core/util/jit.py): the same operations in the same precisions, so the same bits."""
    if kernels_enabled() and _fits_fresnel_kernel(cos_i, eta):
        return _fresnel_with_kernel(cos_i, eta)
    cos_i = np.clip(cos_i, 0.0, 1.0)
    sin2_t = (1.0 - cos_i * cos_i) / (eta * eta)
    tir = sin2_t >= 1.0
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2_t))
    # r_par = (n_t cos_i - n_i cos_t) / (n_t cos_i + n_i cos_t), r_perp = (n_i cos_i - n_t cos_t) /
    # (n_i cos_i + n_t cos_t), both divided through by n_i
    r_par = (eta * cos_i - cos_t) / np.maximum(eta * cos_i + cos_t, 1e-30)
    r_perp = (cos_i - eta * cos_t) / np.maximum(cos_i + eta * cos_t, 1e-30)
    f = np.where(tir, 1.0, 0.5 * (r_par * r_par + r_perp * r_perp))
    dtype = np.result_type(np.asarray(cos_i).dtype, np.float32)  # by dtype, not value: a float64 scalar stays float64
    return f.astype(dtype), cos_t.astype(dtype)


_FLOATS = (np.dtype(np.float32), np.dtype(np.float64))


def _fits_fresnel_kernel(cos_i, eta) -> bool:
    """Float32/float64 arrays (not scalars, whose NumPy promotion rules differ) of at least one dimension."""
    return (isinstance(cos_i, np.ndarray) and isinstance(eta, np.ndarray) and cos_i.dtype in _FLOATS
            and eta.dtype in _FLOATS and cos_i.ndim >= 1 and eta.ndim >= 1)


def _fresnel_with_kernel(cos_i: np.ndarray, eta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """fresnel_dielectric by _fresnel_kernel over the broadcast arrays (viewed as 2-D rows)."""
    shape = np.broadcast_shapes(cos_i.shape, eta.shape)
    c, e = np.broadcast_to(cos_i, shape), np.broadcast_to(eta, shape)  # read-only views, no copies
    work = np.result_type(cos_i.dtype, eta.dtype).type  # the precision NumPy computes in
    out_type = np.result_type(cos_i.dtype, np.float32)  # the reference's result dtype
    if c.ndim != 2:
        c, e = c.reshape(-1, shape[-1] if shape[-1] else 1), e.reshape(-1, shape[-1] if shape[-1] else 1)
    f, cos_t = np.empty(c.shape, out_type), np.empty(c.shape, out_type)
    one_c = cos_i.dtype.type(1.0)
    _fresnel_kernel(c, e, one_c - one_c, one_c, work(1.0), work(1e-30), f, cos_t)
    return f.reshape(shape), cos_t.reshape(shape)


@njit
def _fresnel_kernel(cos_i, eta, zero_c, one_c, one, tiny, f_out, cos_t_out):
    """fresnel_dielectric's NumPy lines per element: cos_i's own precision (``one_c``) up to
    1 - cos_i^2, the working precision (``one``, ``tiny`` = 1e-30) from there, stored in the
    outputs' dtype; NaN propagates as through np.clip / np.maximum (comparisons with NaN are false)."""
    zero = one - one
    half = one / (one + one)
    for r in range(cos_i.shape[0]):
        for k in range(cos_i.shape[1]):
            c = cos_i[r, k]
            if c < zero_c:
                c = zero_c
            if c > one_c:
                c = one_c
            e = eta[r, k]
            sin2_t = (one_c - c * c) / (e * e)
            t = one - sin2_t
            if t < zero:
                t = zero
            cos_t = np.sqrt(t)
            den_par = e * c + cos_t
            if den_par < tiny:
                den_par = tiny
            den_perp = c + e * cos_t
            if den_perp < tiny:
                den_perp = tiny
            r_par = (e * c - cos_t) / den_par
            r_perp = (c - e * cos_t) / den_perp
            f_out[r, k] = one if sin2_t >= one else half * (r_par * r_par + r_perp * r_perp)
            cos_t_out[r, k] = cos_t


def sellmeier_ior(wavelength_nm, b, c) -> np.ndarray:
    """Sellmeier: n(lambda) = sqrt(1 + sum B_k lambda^2 / (lambda^2 - C_k)), lambda in um, C in um^2."""
    lam2 = (np.asarray(wavelength_nm, dtype=np.float64) * 1e-3) ** 2
    n2 = 1.0 + sum(bk * lam2 / (lam2 - ck) for bk, ck in zip(b, c) if bk != 0.0)
    return np.sqrt(n2)


def cauchy_from_abbe(n_d: float, abbe: float) -> tuple[float, float]:
    """(A, B) of n = A + B / lambda^2 (lambda in nm) matching n_d at 587.56 nm and Abbe number V_d."""
    if abbe <= 0:
        raise ValueError(f"Abbe number must be > 0, got {abbe}")
    b = (n_d - 1.0) / (abbe * (1.0 / LAMBDA_F**2 - 1.0 / LAMBDA_C**2))
    return n_d - b / LAMBDA_D**2, b


def ior_spectrum(wavelengths_nm: np.ndarray, model: str, ior: float = 1.5, abbe: float = 0.0) -> np.ndarray:
    """Refractive index at each wavelength for a dispersion ``model`` (a DISPERSION_MODELS key).

    'NONE' is the constant ``ior``; 'ABBE' the Cauchy fit to (``ior``, ``abbe``); the others are
    Sellmeier presets (their own n_d; ``ior`` is ignored).
    """
    wl = np.asarray(wavelengths_nm, dtype=np.float64)
    if model == "NONE":
        return np.full(wl.shape, float(ior))
    if model == "ABBE":
        a, b = cauchy_from_abbe(float(ior), float(abbe))
        return a + b / wl**2
    if model in SELLMEIER_PRESETS:
        return sellmeier_ior(wl, *SELLMEIER_PRESETS[model])
    raise ValueError(f"unknown dispersion model {model!r}; expected one of {sorted(DISPERSION_MODELS)}")
