"""Thin-film interference in the Fresnel term: Airy's sum of a film's multiple reflections, per wavelength.

Method (docs/physics.md section 2.8): a film of thickness d (nm) and real index n_f between the
incident medium n_i (real) and a substrate n_t (real for a dielectric, n + i k for a conductor).
Each polarisation's amplitude reflectance is Airy's sum of the film's internal reflections
(Born & Wolf, *Principles of Optics*, 7th ed., section 7.6.1, eq. (7.6.56); Heavens 1955,
*Optical Properties of Thin Solid Films*):

    r = (r_if + r_ft e^{2 i delta}) / (1 + r_if r_ft e^{2 i delta}),  delta = 2 pi d n_f cos(theta_f) / lambda,

with the Fresnel amplitude coefficients of the two interfaces written with q_j = n_j cos(theta_j)
= sqrt(n_j^2 - n_i^2 sin^2(theta_i)) (principal root: Im q >= 0, a wave that decays into an
absorbing substrate or, past a critical angle, into the film or the substrate):
r_s(a, b) = (q_a - q_b) / (q_a + q_b), r_p(a, b) = (n_b^2 q_a - n_a^2 q_b) / (n_b^2 q_a + n_a^2 q_b).
The unpolarised reflectance is R = (|r_s|^2 + |r_p|^2) / 2; a lossless film over a dielectric
transmits T = 1 - R. Belcour & Barla 2017 ("A practical extension to microfacet theory for the
modeling of varying iridescence", ACM TOG 36(4)) use the same sum in RGB with an analytic
spectral integration; here it is exact at every wavelength of the grid. d = 0 gives the plain
Fresnel reflectance exactly (r = (r_if + r_ft) / (1 + r_if r_ft) = r_it).

Conductors whose colour is given as Cycles' F0 and F82 tint get a complex index from Gulbrandsen's
artist-friendly mapping (Gulbrandsen 2014, "Artist friendly metallic Fresnel", JCGT 3(4)), reading
F0 as r and the F82 reflectance as g, as Cycles does for a thin film over a metal
(``intern/cycles/kernel/closure/bsdf_microfacet.h``, microfacet_fresnel's F82_TINT branch).

Everything is NumPy in float64 complex arithmetic, vectorised over broadcast arguments; the walker
and the BSDFs call it only for rows with a film (their compiled kernels skip those batches). The
Airy sum has a compiled twin (``_airy_kernel``, core/util/jit.py: one pass over the broadcast
elements in complex128 scalars instead of NumPy's chain of (B, n) complex temporaries), chosen
inside ``airy_reflectance`` when kernels are on; tests/spectral/test_thin_film.py compares them
(the same operations, equal to within 1e-12: complex division and exp are not NumPy's bit for bit).
"""

from __future__ import annotations

import cmath

import numpy as np

from ..util.jit import kernels_enabled, njit

__all__ = ["THIN_FILM_CUTOFF_NM", "airy_reflectance", "thin_film_dielectric", "conductor_ior_from_f0_f82",
           "thin_film_conductor"]

#: Films thinner than this (nm) are no film (Cycles' THINFILM_THICKNESS_CUTOFF is 0.1 nm too).
THIN_FILM_CUTOFF_NM = 0.1


def _q(n, n_i_sin2):
    """n cos(theta) in a medium of (complex) index n: the principal sqrt(n^2 - n_i^2 sin^2 theta_i)."""
    return np.sqrt(np.asarray(n, np.complex128) ** 2 - n_i_sin2)


def airy_reflectance(cos_i, n_i, n_f, n_t, thickness_nm, wavelength_nm) -> np.ndarray:
    """Unpolarised reflectance (float64, broadcast shape) of a film of index ``n_f`` (real) and
    thickness ``thickness_nm`` between an incident medium ``n_i`` (real) and a substrate ``n_t``
    (real, or complex n + i k for an absorbing one) at incident cosine ``cos_i`` (clipped to
    [0, 1]) and vacuum wavelength ``wavelength_nm``."""
    if kernels_enabled():
        return _airy_with_kernel(cos_i, n_i, n_f, n_t, thickness_nm, wavelength_nm)
    c = np.clip(np.asarray(cos_i, np.float64), 0.0, 1.0)
    n_i = np.asarray(n_i, np.float64)
    s2 = (n_i * n_i) * (1.0 - c * c)  # (n_i sin theta_i)^2, conserved across the layers
    q_i = (n_i * c).astype(np.complex128)
    q_f, q_t = _q(n_f, s2), _q(n_t, s2)
    e_f, e_t = np.asarray(n_f, np.complex128) ** 2, np.asarray(n_t, np.complex128) ** 2
    e_i = (n_i * n_i).astype(np.complex128)
    phase = np.exp(2j * (2.0 * np.pi * np.asarray(thickness_nm, np.float64) / np.asarray(wavelength_nm, np.float64))
                   * q_f)
    r_sum = np.zeros(np.broadcast(q_i, q_f, q_t, phase).shape)
    # s: (q_a - q_b) / (q_a + q_b); p: (e_b q_a - e_a q_b) / (e_b q_a + e_a q_b), e = n^2
    r_if_s = _ratio(q_i - q_f, q_i + q_f)
    r_ft_s = _ratio(q_f - q_t, q_f + q_t)
    r_if_p = _ratio(e_f * q_i - e_i * q_f, e_f * q_i + e_i * q_f)
    r_ft_p = _ratio(e_t * q_f - e_f * q_t, e_t * q_f + e_f * q_t)
    for r1, r2 in ((r_if_s, r_ft_s), (r_if_p, r_ft_p)):
        r = (r1 + r2 * phase) / (1.0 + r1 * r2 * phase)
        r_sum = r_sum + 0.5 * (r.real * r.real + r.imag * r.imag)
    return np.clip(r_sum, 0.0, 1.0)


def _airy_with_kernel(cos_i, n_i, n_f, n_t, thickness_nm, wavelength_nm) -> np.ndarray:
    """airy_reflectance by _airy_kernel over the broadcast arguments, as read-only 2-D views
    (a per-hit column and a per-wavelength row are not expanded: their strides are 0)."""
    n_t = np.asarray(n_t, np.complex128)
    args = [np.asarray(a, np.float64) for a in (cos_i, n_i, n_f, thickness_nm, wavelength_nm)] + [n_t.real, n_t.imag]
    shape = np.broadcast_shapes(*(a.shape for a in args))
    cols = shape[-1] if shape else 1
    views = [np.broadcast_to(a, shape).reshape(-1, cols) for a in args]
    out = np.empty(views[0].shape, np.float64)
    _airy_kernel(*views, out)
    return out.reshape(shape)


@njit
def _ratio_k(num, den):
    return num / den if den != 0 else complex(-1.0, 0.0)


@njit
def _airy_kernel(cos_i, n_i, n_f, d, wl, nt_re, nt_im, out):
    """airy_reflectance's lines per element in complex128 scalars (cmath's principal sqrt, as
    NumPy's), the result clipped to [0, 1]."""
    two_pi = 2.0 * np.pi
    for row in range(out.shape[0]):
        for j in range(out.shape[1]):
            out[row, j] = _airy_1(cos_i[row, j], n_i[row, j], n_f[row, j], d[row, j], wl[row, j], nt_re[row, j],
                                  nt_im[row, j], two_pi)


@njit
def _airy_1(c, ni, n_f, d, wl, nt_re, nt_im, two_pi):
    """One element of _airy_kernel."""
    c = min(max(c, 0.0), 1.0)
    s2 = (ni * ni) * (1.0 - c * c)
    q_i = complex(ni * c, 0.0)
    nf = complex(n_f, 0.0)
    nt = complex(nt_re, nt_im)
    e_f, e_t, e_i = nf * nf, nt * nt, complex(ni * ni, 0.0)
    q_f = cmath.sqrt(e_f - s2)
    q_t = cmath.sqrt(e_t - s2)
    phase = cmath.exp(2j * (two_pi * d / wl) * q_f)
    total = 0.0
    for pol in range(2):
        if pol == 0:
            r1 = _ratio_k(q_i - q_f, q_i + q_f)
            r2 = _ratio_k(q_f - q_t, q_f + q_t)
        else:
            r1 = _ratio_k(e_f * q_i - e_i * q_f, e_f * q_i + e_i * q_f)
            r2 = _ratio_k(e_t * q_f - e_f * q_t, e_t * q_f + e_f * q_t)
        r = (r1 + r2 * phase) / (1.0 + r1 * r2 * phase)
        total += 0.5 * (r.real * r.real + r.imag * r.imag)
    return min(max(total, 0.0), 1.0)


def _ratio(num, den):
    """num / den with a zero denominator (grazing incidence on matched media) read as -1 (a grazing
    wave is reflected whole)."""
    ok = den != 0
    return np.where(ok, num / np.where(ok, den, 1.0), -1.0 + 0j)


def thin_film_dielectric(cos_i, eta, film_ior, thickness_nm, wavelength_nm, n_i=1.0) -> tuple[np.ndarray, np.ndarray]:
    """(F, cos_t) as spectral.optics.fresnel_dielectric gives them (``eta`` = n_t / n_i, F = 1
    under total internal reflection, float32 in, float32 out) for the interface covered by a
    film of index ``film_ior`` and thickness ``thickness_nm`` at ``wavelength_nm``; ``n_i`` is the
    incident medium's absolute index (1 from the air, the glass's from inside it), which the
    film's phase needs. The refracted direction is Snell's (the film's faces are parallel)."""
    eta64 = np.asarray(eta, np.float64)
    n_i64 = np.asarray(n_i, np.float64)
    c = np.clip(np.asarray(cos_i, np.float64), 0.0, 1.0)
    f = airy_reflectance(c, n_i64, film_ior, n_i64 * eta64, thickness_nm, wavelength_nm)
    sin2_t = (1.0 - c * c) / (eta64 * eta64)
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2_t))
    f = np.where(sin2_t >= 1.0, 1.0, f)
    dtype = np.result_type(np.asarray(cos_i).dtype, np.float32)
    return f.astype(dtype), cos_t.astype(dtype)


def conductor_ior_from_f0_f82(f0, f82) -> tuple[np.ndarray, np.ndarray]:
    """(n, k) of a conductor whose normal reflectance is ``f0`` and whose reflectance at
    cos = 1/7 is ``f82``: Gulbrandsen 2014's mapping with r = min(f0, 0.999) and the edge tint
    g = f82, as Cycles reads an F82-tint metal under a thin film."""
    r = np.minimum(np.asarray(f0, np.float64), 0.999)
    g = np.clip(np.asarray(f82, np.float64), 0.0, 1.0)
    sr = np.sqrt(np.maximum(r, 0.0))
    n = g * (1.0 - r) / (1.0 + r) + (1.0 - g) * (1.0 + sr) / (1.0 - sr)
    k = np.sqrt(np.maximum((r * (n + 1.0) ** 2 - (n - 1.0) ** 2) / (1.0 - r), 0.0))
    return n, k


def thin_film_conductor(cos_i, n, k, film_ior, thickness_nm, wavelength_nm, n_i=1.0) -> np.ndarray:
    """Reflectance (float64) of a film of index ``film_ior`` and thickness ``thickness_nm`` over a
    conductor of complex index ``n`` + i ``k`` (nothing is transmitted)."""
    return airy_reflectance(cos_i, n_i, film_ior, np.asarray(n, np.float64) + 1j * np.asarray(k, np.float64),
                            thickness_nm, wavelength_nm)
