"""The reflection band of opal's (111) planes: a 1-D periodic multilayer by characteristic matrices.

Method: Born & Wolf, *Principles of Optics*, section 1.6 (the characteristic matrix of a
stratified medium, eqs. 1.6.(33), (56)-(58)), with the period matrix raised to the power N by
repeated squaring; s and p polarisation averaged (unpolarised light). docs/physics.md section 5.7.

The FCC opal's (111) planes are a period d111 = sqrt(2/3) D_s of a 3-D permittivity. Its 1-D
equivalent (:func:`equivalent_stack`) keeps the FCC's mean permittivity
eps_eff = 0.74 n_s^2 + 0.26 n_void^2 and its first (111) Fourier component (the two-wave /
scalar-wave approximation of photonic-crystal theory; Bertone et al., PRL 83, 300, 1999, use it
for opal's stop band):

    eps_111 = 3 f (eps_s - eps_void) (sin u - u cos u) / u^3,   u = |G111| D_s / 2 = pi sqrt(3/2),  f = 0.74

in a stack of two layers of equal thickness d111 / 2 with eps = eps_eff +- pi eps_111 / 2 (a
square wave of that first harmonic; its even harmonics vanish, as the FCC (222) is weak).
So the band centre is the Bragg law of n_eff (to 0.2 % at 45 degrees, where a 0.74 / 0.26
thickness split of n_s / n_void layers is 2.3 % off), and the relative band width is the
FCC's, ~ eps_111 / eps_eff (5.4 % for silica in air, 1.6 % in water).

The stack sits in n_eff on both sides and is lossless (R + T = 1). With non-dispersive indices R
depends on lambda / d111 and the angle only, so :class:`BandTable` tabulates one function of
y = lambda / (2 d111 n_eff cos theta_int) (the Bragg peak at y ~ 1 for every angle, so
interpolating between angle rows moves no peak) and cos theta_int per (n_s, n_void, layers),
as its running integral over y: the average of R over a wavelength bin for any D_s is a
difference of two lookups (the band is often narrower than a 5 nm bin).
"""

from __future__ import annotations

import threading
from functools import lru_cache

import numpy as np

from ..opal.bragg import d111_spacing, effective_index

__all__ = ["FILL", "fourier_contrast", "equivalent_stack", "stack_reflectance", "BandTable", "band_table"]

#: Volume fraction of the spheres in an FCC packing.
FILL = 0.74
_U111 = np.pi * np.sqrt(1.5)  # |G111| R = (2 pi / d111) (D_s / 2)


def fourier_contrast(n_sphere: float, n_void: float) -> float:
    """eps_111, the (111) Fourier component of the FCC's permittivity (spheres touching): 0.0981
    for silica (1.45) in air."""
    u = _U111
    shape = (np.sin(u) - u * np.cos(u)) / u**3
    return float(3.0 * FILL * (n_sphere**2 - n_void**2) * shape)


def equivalent_stack(n_sphere: float, n_void: float) -> tuple[float, float, float]:
    """(n_high, n_low, n_eff) of the 1-D equivalent: two layers of thickness d111 / 2 each."""
    eps = effective_index(n_sphere, n_void) ** 2
    de = 0.5 * np.pi * abs(fourier_contrast(n_sphere, n_void))
    return float(np.sqrt(eps + de)), float(np.sqrt(eps - de)), float(np.sqrt(eps))


def _matmul(a, b):
    """2x2 complex matrices stored as (..., 2, 2) (written out: einsum is slow on 2x2 blocks)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), np.complex128)
    a00, a01, a10, a11 = a[..., 0, 0], a[..., 0, 1], a[..., 1, 0], a[..., 1, 1]
    b00, b01, b10, b11 = b[..., 0, 0], b[..., 0, 1], b[..., 1, 0], b[..., 1, 1]
    out[..., 0, 0] = a00 * b00 + a01 * b10
    out[..., 0, 1] = a00 * b01 + a01 * b11
    out[..., 1, 0] = a10 * b00 + a11 * b10
    out[..., 1, 1] = a10 * b01 + a11 * b11
    return out


def _normalised(m):
    """(m / s, log s) with s the largest |real or imaginary part| of each matrix's entries."""
    s = np.maximum(np.abs(m.reshape(len(m), 4).view(np.float64)).max(axis=1), 1e-300)
    m *= (1.0 / s)[:, None, None]
    return m, np.log(s)


def stack_reflectance(lam_over_d, cos_int, indices, fractions, layers: int, n_outer: float):
    """(R, T) of ``layers`` periods of a stack in n_outer (both sides), unpolarised.

    ``lam_over_d``: vacuum wavelength over the period; ``cos_int``: cosine of the angle of
    incidence in n_outer (broadcast together); ``indices`` / ``fractions``: the period's layers
    (indices, thickness fractions of the period, from the incident side). Characteristic
    matrices (Born & Wolf 1.6.(33)); R = |r|^2, T = |t|^2 (same medium both sides).
    """
    x, c = np.broadcast_arrays(np.asarray(lam_over_d, np.float64), np.asarray(cos_int, np.float64))
    shape = x.shape
    x, c = x.ravel(), np.clip(c.ravel(), 0.0, 1.0)
    beta2 = n_outer**2 * (1.0 - c * c)  # (n sin theta)^2, the invariant
    p_out = {"s": n_outer * c, "p": c / n_outer}
    out_r = np.zeros(x.size)
    out_t = np.zeros(x.size)
    for pol in ("s", "p"):
        period = np.broadcast_to(np.eye(2, dtype=np.complex128), (x.size, 2, 2)).copy()
        for n_j, f_j in zip(indices, fractions):
            cos_j = np.sqrt((n_j**2 - beta2).astype(np.complex128)) / n_j  # complex: evanescent layers
            q = n_j * cos_j if pol == "s" else cos_j / n_j
            delta = 2.0 * np.pi * n_j * f_j * cos_j / x
            cd, sd = np.cos(delta), np.sin(delta)
            m = np.empty((x.size, 2, 2), np.complex128)
            m[:, 0, 0], m[:, 1, 1] = cd, cd
            m[:, 0, 1] = -1j * sd / np.where(q != 0, q, 1e-300)  # q = 0 only at exact grazing (measure zero)
            m[:, 1, 0] = -1j * q * sd
            period = _matmul(period, m)
        # M^N by repeated squaring; in the band the entries grow like exp(N kappa), so both
        # factors are kept normalised with their log scales apart (r is scale-free, t is not)
        total = np.broadcast_to(np.eye(2, dtype=np.complex128), (x.size, 2, 2)).copy()
        log_total = np.zeros(x.size)
        power, log_power, k = period, np.zeros(x.size), int(layers)
        while k:
            if k & 1:
                total, s_t = _normalised(_matmul(total, power))
                log_total += log_power + s_t
            k >>= 1
            if k:
                power, s_p = _normalised(_matmul(power, power))
                log_power = 2.0 * log_power + s_p
        p = p_out[pol]
        a = (total[:, 0, 0] + total[:, 0, 1] * p) * p
        b = total[:, 1, 0] + total[:, 1, 1] * p
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            r = (a - b) / (a + b)
            t2 = np.abs(2.0 * p / (a + b)) ** 2 * np.exp(-2.0 * log_total)
        graze = c <= 0  # grazing incidence: everything reflects
        out_r += 0.5 * np.where(graze, 1.0, np.abs(r) ** 2)
        out_t += 0.5 * np.where(graze, 0.0, t2)
    return out_r.reshape(shape), out_t.reshape(shape)


class BandTable:
    """R(y, cos theta_int) of one (n_s, n_void, layers), y = lambda / (2 d111 n_eff cos theta_int),
    as its running integral over y on a log-uniform y grid (bin averages by two lookups).

    ``cos theta_int`` is the cosine between the light inside the stone (index n_eff) and the
    planes' normal; the table spans cos in [COS_MIN, 1] (clamped below).
    """

    COS_MIN = 0.05
    N_COS = 48
    Y_RANGE = (0.25, 16.0)

    def __init__(self, n_sphere: float, n_void: float, layers: int):
        self.n_sphere, self.n_void, self.layers = float(n_sphere), float(n_void), int(layers)
        n_hi, n_lo, n_eff = equivalent_stack(n_sphere, n_void)
        self.n_eff = n_eff
        self.indices = (n_hi, n_lo)
        lo, hi = np.log(self.Y_RANGE[0]), np.log(self.Y_RANGE[1])
        # resolve the band's fringes (spacing ~ 1 / layers in y): ln-y step 1 / (12 N), 0.004 at
        # most, and at most 8000 nodes (for thousands of layers the band is a saturated top hat)
        h = max((hi - lo) / 8000, min(0.004, 1.0 / (12.0 * self.layers)))
        self.n_y = int(np.ceil((hi - lo) / h)) + 1
        self.ln_y0, self.h = lo, (hi - lo) / (self.n_y - 1)
        y = np.exp(lo + self.h * np.arange(self.n_y))
        self.cos = np.linspace(self.COS_MIN, 1.0, self.N_COS)
        rows = []
        for ci in self.cos:  # one angle row at a time (bounded memory): 48 rows
            lam_over_d = 2.0 * n_eff * ci * y
            r, _ = stack_reflectance(lam_over_d, ci, self.indices, (0.5, 0.5), self.layers, n_eff)
            rows.append(r)
        self.reflectance = np.array(rows)  # (N_COS, n_y)
        dy = np.diff(y)
        cum = np.concatenate([np.zeros((self.N_COS, 1)),
                              np.cumsum(0.5 * (self.reflectance[:, 1:] + self.reflectance[:, :-1]) * dy, axis=1)],
                             axis=1)
        self.cumulative = cum  # (N_COS, n_y): int_{y0}^{y} R dy'
        self.y = y

    def _lookup(self, table, cos, y):
        """Bilinear lookup of ``table`` at (cos, y) (broadcast arrays), clamped to the grid."""
        fc = (np.clip(cos, self.COS_MIN, 1.0) - self.COS_MIN) / (1.0 - self.COS_MIN) * (self.N_COS - 1)
        i0 = np.minimum(fc.astype(np.int64), self.N_COS - 2)
        tc = fc - i0
        fy = (np.log(np.clip(y, self.Y_RANGE[0], self.Y_RANGE[1])) - self.ln_y0) / self.h
        j0 = np.clip(fy.astype(np.int64), 0, self.n_y - 2)
        ty = np.clip(fy - j0, 0.0, 1.0)
        flat = table.ravel()
        n = self.n_y
        a = flat[i0 * n + j0] * (1 - ty) + flat[i0 * n + j0 + 1] * ty
        b = flat[(i0 + 1) * n + j0] * (1 - ty) + flat[(i0 + 1) * n + j0 + 1] * ty
        return a * (1 - tc) + b * tc

    def band_average(self, edges, cos_int, diameter, bins=None):
        """The average of R over wavelength bins: (B, n) for bin ``edges`` (n + 1,) nm, or (B,)
        over the single bins ``bins`` (B,) int. ``cos_int`` and ``diameter`` (nm) are (B,)."""
        c = np.maximum(np.asarray(cos_int, np.float64), self.COS_MIN)
        scale = 1.0 / (2.0 * d111_spacing(diameter) * self.n_eff * c)  # y per nm
        edges = np.asarray(edges, np.float64)
        if bins is None:
            y = edges[None, :] * scale[:, None]
            cum = self._lookup(self.cumulative, c[:, None], y)
            return (np.diff(cum, axis=1) / np.diff(y, axis=1)).astype(np.float32)
        y0, y1 = edges[bins] * scale, edges[bins + 1] * scale
        cum0, cum1 = self._lookup(self.cumulative, c, y0), self._lookup(self.cumulative, c, y1)
        return ((cum1 - cum0) / (y1 - y0)).astype(np.float32)


_LOCK = threading.Lock()


@lru_cache(maxsize=32)
def _cached(n_sphere: float, n_void: float, layers: int) -> BandTable:
    return BandTable(n_sphere, n_void, layers)


def band_table(n_sphere: float, n_void: float, layers: int) -> BandTable:
    """The table of these parameters, built once per process (tiles on several threads share it)."""
    with _LOCK:
        return _cached(round(float(n_sphere), 6), round(float(n_void), 6), int(layers))
