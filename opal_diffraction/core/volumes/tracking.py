"""Free-flight distance sampling in homogeneous spectral media with spectral MIS, and closed-form
transmittance (docs/physics.md section 15.4).

A white path carries n wavelengths; a medium's sigma_t differs per wavelength. A distance is
sampled with one channel's sigma_t, the channel drawn uniformly: the one-sample MIS over channels
(the balance heuristic, Veach 1997 section 9.2.4) makes the distance's pdf the channels' mean,
p(t) = (1/n) sum_c sigma_t,c exp(-sigma_t,c t) for a scattering at t before the segment's end
t_e, and P = (1/n) sum_c exp(-sigma_t,c t_e) for reaching it - the spectral MIS of pbrt-v4's
volumetric path integrator (VolPathIntegrator's r_u rescaled path probabilities, with the hero
wavelengths replaced by all n channels). The weights are then
    scattering at t:   sigma_s(lambda) exp(-sigma_t(lambda) t) / p(t)
    reaching t_e:      exp(-sigma_t(lambda) t_e) / P
per wavelength, bounded by n sigma_s / sigma_t and 1 / (fraction of channels) respectively, so
a coloured medium does not turn into colour noise. A mono ray (one wavelength) samples its own
sigma_t: weights sigma_s / sigma_t and 1. A medium that only absorbs is not sampled: its
transmittance exp(-sigma_t t_e) (Beer-Lambert) multiplies the weight. Emission along a segment is
integrated in closed form: int_0^t_e exp(-sigma_t s) L_e ds = L_e (1 - exp(-sigma_t t_e)) / sigma_t.

Equiangular sampling (Kulla & Fajardo 2012, "Importance Sampling Techniques for Path Tracing in
Participating Media"; Cycles' volume_equiangular_sample, intern/cycles/kernel/integrator/
shade_volume.h) draws a point on a segment with density proportional to 1 / r^2 towards a point
light c: with Delta the distance along the ray to c's foot and D the distance from c to the ray,
theta uniform in [atan(-Delta / D), atan((t_e - Delta) / D)] and t = Delta + D tan(theta):
pdf(t) = D / ((theta_b - theta_a) (D^2 + (t - Delta)^2)). It removes the 1 / r^2 spike that makes
free-flight points near a light noisy; the two strategies are combined by MIS (section 15.4).
"""

from __future__ import annotations

import numpy as np

__all__ = ["transmittance", "free_flight", "free_flight_pdf", "segment_emission", "equiangular", "equiangular_pdf"]


def transmittance(sigma_t, d) -> np.ndarray:
    """exp(-sigma_t d) for (B, n) or (B,) coefficients and distances (B,) (inf: 0 where
    sigma_t > 0, 1 where it is 0)."""
    sigma_t = np.asarray(sigma_t, np.float64)
    d = np.asarray(d, np.float64)
    dd = d[:, None] if sigma_t.ndim == 2 else d
    with np.errstate(invalid="ignore"):
        x = sigma_t * dd
    return np.exp(-np.where(sigma_t > 0, x, 0.0))


def free_flight(sigma_t, sigma_s, t_end, u_channel, u_dist, lam=None):
    """Sample a scattering distance along segments of length ``t_end`` (B,) (inf: unbounded).

    ``sigma_t``, ``sigma_s`` (B, n): the segments' media; ``lam`` (B,) wavelength indices of mono
    rays (None: white rays, spectral MIS over the n channels). Returns (scattered (B,) bool,
    t (B,) the distance (t_end where not scattered), weight factor (B, n) white or (B,) mono)."""
    sigma_t = np.asarray(sigma_t, np.float64)
    sigma_s = np.asarray(sigma_s, np.float64)
    t_end = np.asarray(t_end, np.float64)
    b, n = sigma_t.shape
    rows = np.arange(b)
    if lam is None:
        ch = np.minimum((np.asarray(u_channel) * n).astype(np.int64), n - 1)
    else:
        ch = np.asarray(lam, np.int64)
    st = sigma_t[rows, ch]
    with np.errstate(divide="ignore"):
        t = np.where(st > 0, -np.log1p(-np.asarray(u_dist, np.float64)) / np.where(st > 0, st, 1.0), np.inf)
    scattered = t < t_end
    t = np.where(scattered, t, t_end)
    if lam is not None:
        with np.errstate(divide="ignore", invalid="ignore"):
            f = np.where(scattered, sigma_s[rows, ch] / np.where(st > 0, st, 1.0), 1.0)
        return scattered, t, f
    tr = transmittance(sigma_t, t)  # (B, n) at the sampled distance or the end
    with np.errstate(divide="ignore", invalid="ignore"):
        p_scatter = np.mean(sigma_t * tr, axis=1)
        p_pass = np.mean(tr, axis=1)
        f = np.where(scattered[:, None], sigma_s * tr / p_scatter[:, None], tr / p_pass[:, None])
    return scattered, t, np.where(np.isfinite(f), f, 0.0)


def segment_emission(sigma_t, emission, t_end) -> np.ndarray:
    """int_0^t_end exp(-sigma_t s) L_e ds per wavelength, (B, n) or (B,) (sigma_t = 0: L_e t_end)."""
    sigma_t = np.asarray(sigma_t, np.float64)
    t = np.asarray(t_end, np.float64)
    t = t[:, None] if sigma_t.ndim == 2 else t
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        length = np.where(sigma_t > 0, -np.expm1(-sigma_t * t) / np.where(sigma_t > 0, sigma_t, 1.0), t)
        out = np.asarray(emission, np.float64) * length
    return np.where(np.isfinite(out), out, 0.0)


def free_flight_pdf(sigma_t, t, lam=None) -> np.ndarray:
    """The density (B,) of a free-flight scattering at distance t (B,): the channels' mean
    sigma_t exp(-sigma_t t) (white, spectral MIS) or the wavelength's own (mono, ``lam``)."""
    sigma_t = np.asarray(sigma_t, np.float64)
    t = np.asarray(t, np.float64)
    if lam is not None:
        st = sigma_t[np.arange(len(t)), np.asarray(lam, np.int64)]
        return st * np.exp(-st * t)
    return np.mean(sigma_t * np.exp(-sigma_t * t[:, None]), axis=1)


def _equiangular_frame(o, d, c, t_end):
    delta = np.einsum("ij,ij->i", np.asarray(c, np.float64) - o, d)
    foot = o + delta[:, None] * d
    dist = np.maximum(np.linalg.norm(foot - c, axis=1), 1e-7)
    theta_a = np.arctan2(-delta, dist)
    theta_b = np.where(np.isinf(t_end), np.pi / 2, np.arctan2(np.where(np.isinf(t_end), 0.0, t_end) - delta, dist))
    return delta, dist, theta_a, theta_b


def equiangular(o, d, c, t_end, u):
    """Points on the segments o + t d, 0 <= t < t_end (inf: unbounded), drawn towards the points
    c (B, 3) with density proportional to 1 / |o + t d - c|^2: (t (B,), pdf (B,))."""
    o, d = np.asarray(o, np.float64), np.asarray(d, np.float64)
    t_end = np.asarray(t_end, np.float64)
    delta, dist, ta, tb = _equiangular_frame(o, d, c, t_end)
    theta = ta + np.asarray(u, np.float64) * (tb - ta)
    t = np.clip(delta + dist * np.tan(theta), 0.0, t_end)
    with np.errstate(divide="ignore"):
        pdf = dist / ((tb - ta) * (dist * dist + (t - delta) ** 2))
    return t, np.where(tb > ta, pdf, 0.0)


def equiangular_pdf(o, d, c, t_end, t) -> np.ndarray:
    """The density of ``equiangular`` at distances t (B,)."""
    o, d = np.asarray(o, np.float64), np.asarray(d, np.float64)
    delta, dist, ta, tb = _equiangular_frame(o, d, c, np.asarray(t_end, np.float64))
    t = np.asarray(t, np.float64)
    with np.errstate(divide="ignore"):
        pdf = dist / ((tb - ta) * (dist * dist + (t - delta) ** 2))
    return np.where(tb > ta, pdf, 0.0)
