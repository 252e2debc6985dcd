"""Fraunhofer diffraction by a multi-slit grating: the kernel, its exact bin averages, radiometry.

Source: scalar Fraunhofer diffraction of N slits of width a and period D (e.g. Born & Wolf,
*Principles of Optics*, 7th ed., 1999, section 8.6.1; Hecht, *Optics*, 5th ed., 2017, section
10.2.3), with the source paper's notation for the renderer (Kobayashi & Kawai; docs/physics.md
section 3.1). With

    u = (w_o + w_i) . t,   v = (w_o + w_i) . s,
    xi = pi a u / lambda,  eta = pi D u / lambda,  zeta = pi L v / lambda,

the normalised pattern is

    P(u, v, lambda) = sinc^2(xi) [sin(N eta) / (N sin eta)]^2 sinc^2(zeta),   sinc x = sin x / x.

The source paper prints (sin N eta / eta)^2; that is a misprint for (sin N eta / sin eta)^2, which
is what the N-slit integral gives (tests compare it with a brute-force sum of N phasors). We do
not reproduce the misprint.

Numerics (docs/physics.md sections 3.6 and 3.8, "each has bitten someone"):
- [sin(N eta) / (N sin eta)]^2 has period pi in eta; we reduce eta_r = eta - pi round(eta / pi) in
  float64 first and switch to a series where N eta_r is tiny, so eta = m pi gives exactly 1
  (the naive ratio gives 0.0104 for N = 50 in float64, 0.752 for N = 6000 in float32).
- Peaks are lambda / (N D) wide in u: far narrower than a pixel or a 5 nm bin. The renderer
  therefore averages the kernel over each wavelength bin with the closed-form integral
      C(eta) = int_0^eta (sin N x / sin x)^2 dx = N eta + sum_{m=1}^{N-1} (N - m) sin(2 m eta) / m
  (exact, O(N), used for N <= EXACT_N), and for larger N its asymptotic form
      C(eta_r) ~ N [Si(2 N eta_r) - sin^2(N eta_r) / (N eta_r)] + (1/eta_r - cot eta_r) / 2
  (the first term integrates (sin N x / x)^2, the second the smooth remainder
  sin^2(N x) (1/sin^2 x - 1/x^2) with sin^2 replaced by its mean 1/2; error O(1/N)).
- sinc^2 integrates in closed form too: int_0^z sinc^2 = Si(2z) - sin^2(z)/z.

Harvey-Shack renormalisation (docs/physics.md section 3.2): K = (a/D) / (the power the orders
send into the propagating disk), from the infinite-N order sums (``propagating_power``) for the
light pass's discrete orders, and from the finite-N pattern's own propagating integral
(``finite_propagating_power``: a cumulative table in eta, exact in the N-slit factor) for the
eye pass's radiance, so no wavelength bin near a Rayleigh anomaly sends more than a/D.

All functions are vectorised and compute internally in float64 (cheap next to the ray casting,
and what makes float32 inputs agree with float64 ones); results come back in float64.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.special import sici

__all__ = [
    "EXACT_N",
    "multislit",
    "multislit_integral",
    "multislit_mean",
    "sinc2",
    "sinc2_integral",
    "sinc2_mean",
    "fraunhofer_pattern",
    "fraunhofer_pattern_binned",
    "grating_radiance_factor",
    "propagating_power",
    "harvey_shack_factor",
    "finite_propagating_power",
    "finite_pattern_table",
    "hexagonal_harvey_shack_factor",
    "box_mean_product",
    "fraunhofer_pattern_footprint",
]

#: Up to this slit count the exact O(N) integral is used, beyond it the asymptotic form.
EXACT_N = 64
# Below this width in N*eta an interval mean is the midpoint value (error < (N d_eta)^2 / 24).
_MIDPOINT_NETA = 0.05


def _reduce(eta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """eta = k pi + eta_r with eta_r in [-pi/2, pi/2]; returns (k, eta_r) in float64."""
    eta = np.asarray(eta, np.float64)
    k = np.round(eta / np.pi)
    return k, eta - k * np.pi


def multislit(eta, n) -> np.ndarray:
    """[sin(N eta) / (N sin eta)]^2, equal to 1 at every eta = m pi, stable for N up to 1e6+."""
    n = np.asarray(n, np.float64)
    _, er = _reduce(eta)
    x = n * er
    small = np.abs(x) < 1e-4
    safe_er = np.where(small, 1.0, er)
    ratio = np.where(small, 1.0 - (n * n - 1.0) * er * er / 6.0, np.sin(x) / (n * np.sin(safe_er)))
    return ratio * ratio


def _remainder_exact(er: np.ndarray, n: int) -> np.ndarray:
    """R(eta_r) = sum_{m=1}^{N-1} (N - m) sin(2 m eta_r) / m (loop over m <= EXACT_N, not rays)."""
    out = np.zeros_like(er)
    for m in range(1, n):
        out += (n - m) / m * np.sin(2 * m * er)
    return out


_FAR = 30.0  # beyond |x| = 30 the asymptotic series of Si replaces scipy's sici (error < 1e-12)


def _sinc2_cumulative(x: np.ndarray) -> np.ndarray:
    """S(x) = int_0^x (sin t / t)^2 dt = Si(2x) - sin^2(x) / x, odd in x.

    Near 0 through scipy's sici; for |x| > 30 from the asymptotic expansion
    Si(z) = pi/2 - f(z) cos z - g(z) sin z (Abramowitz & Stegun 5.2.8, 5.2.34-35), which with
    sin^2(x)/x = (1 - cos z)/z, z = 2x, gives S = pi/2 - 1/z + (1/z - f) cos z - g sin z.
    """
    x = np.asarray(x, np.float64)
    out = np.empty_like(x)
    ax = np.abs(x)
    far = ax > _FAR
    near = ~far
    if near.any():
        xn = x[near]
        tiny = np.abs(xn) < 1e-8
        safe = np.where(tiny, 1.0, xn)
        out[near] = np.where(tiny, xn, sici(2 * xn)[0] - np.sin(xn) ** 2 / safe)
    if far.any():
        z = 2 * ax[far]
        iz2 = 1.0 / (z * z)
        one_minus_f = iz2 / z * (2.0 - 24.0 * iz2 + 720.0 * iz2 * iz2)  # 1/z - f(z)
        g = iz2 * (1.0 - 6.0 * iz2 + 120.0 * iz2 * iz2)
        val = np.pi / 2 - 1.0 / z + one_minus_f * np.cos(z) - g * np.sin(z)
        out[far] = np.sign(x[far]) * val
    return out


def _remainder_asymptotic(er: np.ndarray, n: float) -> np.ndarray:
    """The periodic part of C for large N: C(eta_r) - N eta_r, from the asymptotic form."""
    x = n * er
    tiny = np.abs(er) < 1e-12
    safe_er = np.where(tiny, 1.0, er)
    main = n * _sinc2_cumulative(x)
    # (1/e - cot e) / 2 = e/6 + e^3/90 + ... : use the series near 0 to avoid cancellation
    corr = np.where(np.abs(er) < 1e-3, er / 6 + er**3 / 90, 0.5 * (1 / safe_er - 1 / np.tan(safe_er)))
    return np.where(tiny, 0.0, main + corr - x)


def multislit_integral(eta, n) -> np.ndarray:
    """C(eta) = int_0^eta (sin N x / sin x)^2 dx for a scalar slit count N (>= 1)."""
    n_int = int(n)
    if n_int < 1:
        raise ValueError(f"slit count must be >= 1, got {n}")
    eta = np.asarray(eta, np.float64)
    _, er = _reduce(eta)
    rem = _remainder_exact(er, n_int) if n_int <= EXACT_N else _remainder_asymptotic(er, float(n_int))
    return n_int * eta + rem


def multislit_mean(eta0, eta1, n, exclude_zeroth: bool = False) -> np.ndarray:
    """Mean of [sin(N eta) / (N sin eta)]^2 over [eta0, eta1] (either order), exact in closed form.

    ``exclude_zeroth``: leave out the zeroth order's period |eta| < pi/2 (its closed-form integral
    subtracted; a narrow interval takes its midpoint value outside that period only), where the
    base's specular continuation carries it (docs/physics.md section 3.3)."""
    eta0 = np.asarray(eta0, np.float64)
    eta1 = np.asarray(eta1, np.float64)
    n_f = float(int(n))
    width = eta1 - eta0
    narrow = np.abs(width) * n_f < _MIDPOINT_NETA
    safe_w = np.where(narrow, 1.0, width)
    integral = multislit_integral(eta1, n) - multislit_integral(eta0, n)
    mid_eta = 0.5 * (eta0 + eta1)
    mid = multislit(mid_eta, n_f)
    if exclude_zeroth:
        c0, c1 = (np.clip(x, -np.pi / 2, np.pi / 2) for x in (eta0, eta1))
        integral = integral - (multislit_integral(c1, n) - multislit_integral(c0, n))
        mid = mid * (np.abs(mid_eta) >= np.pi / 2)
    return np.clip(np.where(narrow, mid, integral / (n_f * n_f * safe_w)), 0.0, 1.0)


def sinc2(x) -> np.ndarray:
    """(sin x / x)^2 with the removable singularity at 0 handled."""
    x = np.asarray(x, np.float64)
    small = np.abs(x) < 1e-4
    safe = np.where(small, 1.0, x)
    r = np.where(small, 1.0 - x * x / 6.0, np.sin(safe) / safe)
    return r * r


def sinc2_integral(x) -> np.ndarray:
    """int_0^x (sin t / t)^2 dt = Si(2x) - sin^2(x) / x (odd in x)."""
    return _sinc2_cumulative(x)


def sinc2_mean(x0, x1) -> np.ndarray:
    """Mean of sinc^2 over [x0, x1]."""
    x0 = np.asarray(x0, np.float64)
    x1 = np.asarray(x1, np.float64)
    w = x1 - x0
    narrow = np.abs(w) < 1e-6
    safe = np.where(narrow, 1.0, w)
    return np.clip(np.where(narrow, sinc2(0.5 * (x0 + x1)), (sinc2_integral(x1) - sinc2_integral(x0)) / safe), 0, 1)


def fraunhofer_pattern(u, v, wavelength, a, d, n, length) -> np.ndarray:
    """P(u, v, lambda) at points (docs/physics.md section 3.1); lengths in one unit (e.g. nm)."""
    lam = np.asarray(wavelength, np.float64)
    u = np.asarray(u, np.float64)
    v = np.asarray(v, np.float64)
    return sinc2(np.pi * a * u / lam) * multislit(np.pi * d * u / lam, n) * sinc2(np.pi * length * v / lam)


def fraunhofer_pattern_binned(u, v, edges, a, d, n, length, subdivisions: int = 2, lam_power: int = 0,
                              exclude_zeroth: bool = False) -> np.ndarray:
    """The mean of P over each wavelength bin [edges[k], edges[k+1]], for every (u, v).

    u, v: (B,); edges: (K+1,) in the unit of a, d, length. Returns (B, K). Each bin is split into
    ``subdivisions`` equal parts; in each, the multi-slit and sinc^2(zeta) factors are averaged in
    closed form over their argument (both are proportional to 1/lambda) and the slowly varying
    slit envelope is taken at the part's centre; the parts are averaged with weights equal to
    their width in lambda. The error against fine quadrature is bounded in the tests.
    ``lam_power`` multiplies each part by lambda^lam_power (the radiance factor's 1/lambda^2 is
    averaged with the pattern this way). a and d may be scalars or (B, 1) arrays.
    ``exclude_zeroth``: leave out the zeroth order, i.e. the N-slit factor's period
    |eta| < pi/2 (|u| < lambda / (2 D)), where another lobe carries it (a mirror base's specular
    continuation, docs/physics.md section 3.3); its closed-form integral is subtracted.
    """
    u = np.asarray(u, np.float64)[:, None]
    v = np.asarray(v, np.float64)[:, None]
    e = np.asarray(edges, np.float64)
    k = len(e) - 1
    t = np.linspace(0.0, 1.0, subdivisions + 1)
    # all part boundaries once (neighbouring parts share them): K * S + 1 points
    bounds = np.concatenate([(e[:-1, None] + (e[1:] - e[:-1])[:, None] * t[None, :-1]).ravel(), e[-1:]])
    inv = 1.0 / bounds
    mid_lam = 2.0 / (inv[:-1] + inv[1:])  # each part's centre in 1/lambda
    n_f = float(int(n))
    # N-slit factor: cumulative integral at the boundaries, differenced
    eta = np.pi * d * u * inv[None, :]
    c = multislit_integral(eta, n)
    width = np.diff(eta, axis=1)
    narrow = np.abs(width) * n_f < _MIDPOINT_NETA
    ms = np.diff(c, axis=1) / (n_f * n_f * np.where(narrow, 1.0, width))
    if exclude_zeroth:  # the part of each interval inside |eta| < pi/2 carries the zeroth order
        ec = np.clip(eta, -np.pi / 2, np.pi / 2)
        ms -= np.diff(multislit_integral(ec, n), axis=1) / (n_f * n_f * np.where(narrow, 1.0, width))
    if narrow.any():  # tiny intervals (near u = 0): the midpoint value, computed only there
        mid = 0.5 * (eta[:, 1:] + eta[:, :-1])[narrow]
        ms[narrow] = multislit(mid, n_f) * ((np.abs(mid) >= np.pi / 2) if exclude_zeroth else 1.0)
    ms = np.clip(ms, 0.0, 1.0)
    # slit-length factor sinc^2(zeta), likewise
    zeta = np.pi * length * v * inv[None, :]
    zw = np.diff(zeta, axis=1)
    zc = sinc2_integral(zeta)
    znarrow = np.abs(zw) < 1e-6
    zf = np.diff(zc, axis=1) / np.where(znarrow, 1.0, zw)
    if znarrow.any():
        zf[znarrow] = sinc2(0.5 * (zeta[:, 1:] + zeta[:, :-1])[znarrow])
    zf = np.clip(zf, 0.0, 1.0)
    env = sinc2(np.pi * a * u / mid_lam[None, :])
    parts = env * ms * zf
    if lam_power:
        parts = parts * mid_lam[None, :] ** lam_power
    return parts.reshape(len(u), k, subdivisions).mean(axis=2)


def grating_radiance_factor(wavelength, a, d, n, length) -> np.ndarray:
    """a^2 L N / (lambda^2 D): L_o = E_i * factor * P (docs/physics.md section 3.2).

    The pattern lives in direction cosines and du dv = cos(theta_o) d(omega_o), so there is no
    1/cos(theta_o): the hemispherical integral of L_o cos(theta_o) is E_i * a / D (Parseval)
    times the fraction of the orders that propagate. Lengths in metres give radiance per unit
    irradiance in 1/sr.
    """
    lam = np.asarray(wavelength, np.float64)
    return a * a * length * n / (lam * lam * d)


def _sinc2_cumsum_table(ratio: float, m_max: int) -> np.ndarray:
    """T[j] = sum_{m=-m_max}^{j-m_max-1} sinc^2(pi m ratio), j = 0 .. 2 m_max + 1 (T[0] = 0)."""
    m = np.arange(-m_max, m_max + 1, dtype=np.float64)
    return np.concatenate([[0.0], np.cumsum(sinc2(np.pi * m * ratio))])


#: how far past the unit circle alpha^2 + beta^2 may lie from rounding alone: float32 unit vectors
#: and frames are unit and orthogonal to ~1e-7, so 1e-4 only passes rounding
DISK_ROUNDING = 1e-4


def _in_unit_disk(alpha: np.ndarray, beta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(alpha, beta) scaled onto the unit disk where rounding puts them just outside it; a
    ValueError where they lie further out or are not finite (not the tangential components of
    a unit vector: a caller's bug, never clamped silently).

    They are the tangential components of a unit vector, so alpha^2 + beta^2 <= 1 exactly; for
    grazing light (a light on the surface) float rounding can give 1 + 1e-16 (float32 vectors and
    frames: ~1e-7), which would make even the specular (zeroth) order evanescent and the
    Harvey-Shack factor 1 / 0. On the disk the zeroth order always propagates, which bounds K
    (docs/physics.md section 3.2). Beyond ``DISK_ROUNDING`` the input is an error."""
    rho2 = alpha * alpha + beta * beta
    bad = ~(rho2 <= 1.0 + DISK_ROUNDING)  # (NaN included)
    if np.any(bad):
        worst = np.asarray(rho2)[bad].ravel()[0]
        raise ValueError(f"grating direction cosines outside the unit disk (alpha^2 + beta^2 = {worst:.6g} > 1): "
                         "not the tangential components of a unit vector")
    shrink = np.where(rho2 > 1.0, 1.0 / np.sqrt(np.maximum(rho2, 1.0)), 1.0)
    return alpha * shrink, beta * shrink


def propagating_power(alpha_i, beta_i, wavelength, ratio, d) -> np.ndarray:
    """The fraction of the incident power a LINES grating sends into its propagating orders:
    sum over m with (m lambda / D - alpha_i)^2 + beta_i^2 <= 1 of (a/D)^2 sinc^2(pi m a / D).

    alpha_i = w_i . t and beta_i = w_i . s are the incident direction cosines; order m leaves
    with direction cosines (m lambda / D - alpha_i, -beta_i) (docs/physics.md section 3.2). The
    orders' own widths (lambda / (N D) in u, lambda / L in v) are neglected. Broadcasts alpha_i,
    beta_i, wavelength, d (d and wavelength in one unit); ``ratio`` = a / D, a scalar.
    """
    alpha, beta = _in_unit_disk(np.asarray(alpha_i, np.float64), np.asarray(beta_i, np.float64))
    lam = np.asarray(wavelength, np.float64)
    d = np.asarray(d, np.float64)
    r = np.sqrt(np.maximum(1.0 - beta * beta, 0.0))
    scale = d / lam
    lo = np.ceil((alpha - r) * scale - 1e-12)
    hi = np.floor((alpha + r) * scale + 1e-12)
    m_max = int(np.ceil(2.0 * float(np.max(scale)))) + 1
    table = _sinc2_cumsum_table(float(ratio), m_max)
    lo_i = np.clip(lo + m_max, 0, 2 * m_max).astype(np.int64)
    hi_i = np.clip(hi + m_max + 1, 0, 2 * m_max + 1).astype(np.int64)
    return float(ratio) ** 2 * np.maximum(table[hi_i] - table[lo_i], 0.0)


def harvey_shack_factor(alpha_i, beta_i, wavelength, ratio, d, n=None, bin_width=None) -> np.ndarray:
    """Harvey-Shack renormalisation of a LINES grating: K = (a/D) / propagating_power >= 1.

    Scalar theory in direction cosines puts (a/D)^2 sinc^2(pi m a/D) into order m, and by
    Parseval the orders together carry a/D; the evanescent ones (outside the unit circle of
    direction cosines) carry nothing away. Harvey et al. (Appl. Opt. 38, 6469, 1999; Harvey &
    Pfisterer, Opt. Eng. 58(8) 087105, 2019) rescale the propagating orders by K so the grating
    delivers the whole a/D, which reproduces the Rayleigh (Wood) anomalies - the jumps in the
    efficiency of the remaining orders as one turns evanescent. Ratios between propagating orders
    are unchanged. docs/physics.md section 3.2.

    ``n``: the slit count; the factor then renormalises the finite-N pattern the eye pass
    evaluates (``finite_propagating_power``: the lobes' tails across the horizon), so that its
    propagating integral is a/D exactly, also within a few lobe widths of a Rayleigh anomaly
    where the infinite-N sum over- or under-corrects; ``bin_width``: and for the mean over the
    wavelength bin around ``wavelength`` (the eye pass's bin-averaged pattern). None: the
    infinite-N order sum at the point (the light pass's discrete orders).
    """
    if n is not None:
        power = finite_propagating_power(alpha_i, beta_i, wavelength, ratio, d, n, bin_width)
    else:
        power = propagating_power(alpha_i, beta_i, wavelength, ratio, d)
    return float(ratio) / np.maximum(power, 1e-300)


# --- Harvey-Shack for the finite-N pattern (docs/physics.md section 3.2, "finite N") -----------------

#: nodes of the finite-N cumulative table per main-lobe half width pi / N (capped by _FINITE_NODES)
_FINITE_PER_LOBE = 32
_FINITE_NODES = 1 << 20  # three float64 arrays: 25 MB per cached table at most


@lru_cache(maxsize=8)
def _finite_tables(ratio: float, n: int, periods: int):
    """The cumulative power of the finite-N pattern along eta = pi D u / lambda, and its integral.

    W(eta) = ratio^2 / (N pi) int_0^eta sinc^2(ratio x) (sin N x / sin x)^2 dx, tabulated on
    nodes over |eta| <= periods * pi: between neighbouring nodes the slit envelope is taken at the
    interval's centre and the N-slit factor integrated exactly (``multislit_integral``), so the
    N-slit factor's lobes are never sampled, only integrated (a period carries
    ratio^2 sinc^2(ratio m pi) as N -> infinity: the order efficiency e_m). V = int W deta by
    the trapezoid rule (bin means in eta). Returns (eta nodes, W, V)."""
    step = np.pi / (_FINITE_PER_LOBE * n)
    count = int(min(2 * periods * np.pi / step, _FINITE_NODES)) // 2
    eta = np.linspace(-periods * np.pi, periods * np.pi, 2 * count + 1)
    c = multislit_integral(eta, n)
    mid = 0.5 * (eta[1:] + eta[:-1])
    w = np.concatenate([[0.0], np.cumsum(sinc2(ratio * mid) * np.diff(c))]) * (ratio * ratio / (n * np.pi))
    w -= w[count]  # W(0) = 0: odd
    v = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(eta))])
    return eta, w, v


def _finite_table_for(ratio: float, n: int, eta_max: float):
    periods = 1 << max(0, int(np.ceil(np.log2(max(eta_max / np.pi + 1.0, 1.0)))))  # few distinct tables
    return _finite_tables(float(ratio), int(n), periods)


def finite_pattern_table(ratio: float, n: int, eta_max: float) -> tuple[np.ndarray, np.ndarray]:
    """(eta nodes, W): the cumulative finite-N power W(eta) of ``finite_propagating_power`` on a
    table covering |eta| <= eta_max (``_finite_tables``; the eye path's order lobe samples eta
    from it, core/gratings/lobe.py)."""
    nodes, w, _ = _finite_table_for(float(ratio), int(n), float(eta_max))
    return nodes, w


def finite_propagating_power(alpha_i, beta_i, wavelength, ratio, d, n, bin_width=None) -> np.ndarray:
    """The share of the incident power the finite-N pattern of a LINES grating sends into the
    propagating disk: ratio^2 / (N pi) int sinc^2(ratio eta) (sin N eta / sin eta)^2 d eta over
    eta = pi D u / lambda with u in [alpha_i - r, alpha_i + r], r = sqrt(1 - beta_i^2) (the
    exit direction cosine along t, u - alpha_i, inside the unit disk at the order's v; the
    slit-length spread lambda / L in v is neglected as in ``propagating_power``). As N grows it
    tends to ``propagating_power``; for small N the lobes of evanescent orders reach into the
    disk and those of propagating ones out of it (docs/physics.md section 3.2).

    ``bin_width``: the mean over wavelengths uniform in [wavelength - w/2, wavelength + w/2]
    instead (each eta bound then runs linearly over its interval: the mean of W from V)."""
    alpha, beta = _in_unit_disk(np.asarray(alpha_i, np.float64), np.asarray(beta_i, np.float64))
    lam = np.asarray(wavelength, np.float64)
    d = np.asarray(d, np.float64)
    r = np.sqrt(np.maximum(1.0 - beta * beta, 0.0))
    if bin_width is None:
        lam_lo = lam_hi = lam
    else:
        half = 0.5 * np.asarray(bin_width, np.float64)
        lam_lo, lam_hi = lam - half, lam + half
    scale_hi, scale_lo = np.pi * d / lam_lo, np.pi * d / lam_hi  # eta per unit u at both ends
    eta_max = float(np.max(2.0 * scale_hi)) if np.size(scale_hi) else 1.0
    nodes, w, v = _finite_table_for(ratio, n, eta_max)

    def mean_w(u):  # W's mean while eta = pi D u / lambda runs over the wavelengths
        e0, e1 = u * scale_lo, u * scale_hi
        width = e1 - e0
        point = np.interp(0.5 * (e0 + e1), nodes, w)
        if bin_width is None:
            return point
        narrow = np.abs(width) < 1e-9
        mean = (np.interp(e1, nodes, v) - np.interp(e0, nodes, v)) / np.where(narrow, 1.0, width)
        return np.where(narrow, point, mean)

    return np.maximum(mean_w(alpha + r) - mean_w(alpha - r), 0.0)


def hexagonal_harvey_shack_factor(alpha_i, beta_i, wavelength, ratio, d) -> np.ndarray:
    """Harvey-Shack renormalisation of the HEXAGONAL lattice (disks of diameter a = ratio * D,
    nearest neighbours D apart, lattice vectors D t and D t2, t2 = t rotated by 60 degrees).

    Order (m1, m2) sits at the tangential vector h with h . t = m1 lambda / D and h . t2 =
    m2 lambda / D, i.e. (h_t, h_s) = (m1, (2 m2 - m1) / sqrt 3) lambda / D, and carries
    f^2 [2 J1(x)/x]^2 with x = pi a |h| / lambda = pi ratio |(m1, (2 m2 - m1) / sqrt 3)| (the same
    for every wavelength) and f = pi ratio^2 / (2 sqrt 3) the fill fraction; by Parseval all
    orders carry f (a <= D). It propagates where |h - w_i,tangential| <= 1: for each row m1 that
    is an interval of m2, summed from a cumulative table (a loop over the few rows, not over
    orders or rays). K = f / (the propagating orders' sum). docs/physics.md sections 3.2, 3.4.

    Work is bounded: the table spans |index| <= 2 min(D / lambda, HEX_SCALE_CAP) (at most
    ~1.4 M orders, ~60 MB at the peak, under a second; a period of 1e7 nm would otherwise need
    105 GiB). Beyond the cap (D / lambda > HEX_SCALE_CAP, D > ~92 um at 360 nm) the orders outside
    the table, radius R > R_c = 2 HEX_SCALE_CAP in index units |(m1, (2 m2 - m1) / sqrt 3)|, carry
    together exactly W = 1/f - (the table's sum) (Parseval: all orders sum to 1/f for a <= D),
    asymptotically W f ~ 2 / (pi^2 ratio R_c) (the Airy envelope's mean 4 / (pi x^3), x = pi ratio
    R, over sqrt 3 / 2 orders per unit area). Their propagating share is taken in closed form: spread
    over radii as the 1/R tail says (u = R_c / R uniform in (0, 1]), the fraction of each circle
    of radius R / (D / lambda) inside the unit disk around w_i,tangential (an arc: arccos). The
    error of the sum is below W (so K's relative error < W f K: 4e-4 / ratio at the cap, 2e-3
    at ratio 0.2), and the orders' own widths are neglected as below the cap.
    """
    from scipy.special import j1

    alpha, beta = _in_unit_disk(np.asarray(alpha_i, np.float64), np.asarray(beta_i, np.float64))
    scale = np.asarray(d, np.float64) / np.asarray(wavelength, np.float64)  # D / lambda
    shape = np.broadcast_shapes(alpha.shape, beta.shape, scale.shape)
    ratio = float(ratio)
    fill = np.pi * ratio * ratio / (2 * np.sqrt(3))
    s_max = float(np.max(scale))
    capped = s_max > HEX_SCALE_CAP
    s_max = min(s_max, HEX_SCALE_CAP)  # the table spans |h_t|, |h_s| <= 2 s_max / (D / lambda): bounded work
    m1_max = int(np.ceil(2 * s_max)) + 1  # |h_t| <= 2
    m2_max = int(np.ceil((m1_max + 2 * np.sqrt(3) * s_max) / 2)) + 1  # |h_s| <= 2
    m1 = np.arange(-m1_max, m1_max + 1)[:, None]
    m2 = np.arange(-m2_max, m2_max + 1)[None, :]
    x = np.pi * ratio * np.hypot(m1, (2 * m2 - m1) / np.sqrt(3))
    safe = np.where(x < 1e-9, 1.0, x)
    airy = np.where(x < 1e-9, 1.0, (2 * j1(safe) / safe) ** 2)
    table = np.concatenate([np.zeros((len(m1), 1)), np.cumsum(airy, axis=1)], axis=1)
    total = np.zeros(shape)
    for row, k in enumerate(range(-m1_max, m1_max + 1)):  # rows of the reciprocal lattice
        c = k / scale - alpha  # exit direction cosine along t
        r = np.sqrt(np.maximum(1.0 - c * c, 0.0))
        ok = c * c <= 1.0
        # (2 m2 - k) / sqrt 3 / scale in [beta - r, beta + r]
        lo = np.ceil((k + np.sqrt(3) * (beta - r) * scale) / 2 - 1e-12)
        hi = np.floor((k + np.sqrt(3) * (beta + r) * scale) / 2 + 1e-12)
        lo_i = np.clip(lo + m2_max, 0, 2 * m2_max + 1).astype(np.int64)
        hi_i = np.clip(hi + m2_max + 1, 0, 2 * m2_max + 1).astype(np.int64)
        total += np.where(ok, np.maximum(table[row, hi_i] - table[row, lo_i], 0.0), 0.0)
    if capped:  # the orders outside the table: their exact weight, its propagating share in closed form
        far = max(1.0 / fill - float(table[:, -1].sum()), 0.0)
        total = total + far * _far_share(alpha, beta, scale, 2.0 * s_max)
    return 1.0 / np.maximum(fill * total, 1e-300)


#: The hexagonal Harvey-Shack sum tabulates orders up to 2 * this many D / lambda (see its docstring).
HEX_SCALE_CAP = 256.0


def _far_share(alpha, beta, scale, r_cap: float, nodes: int = 16) -> np.ndarray:
    """The share of the orders beyond index radius ``r_cap`` that propagate, their weight spread
    as 1/R^2 dR (u = r_cap / R uniform): the mean over u of the fraction of the circle of radius
    rho = R / scale (direction cosines) inside the unit disk centred at (alpha, beta)."""
    d0 = np.hypot(alpha, beta)
    out = 0.0
    for j in range(nodes):  # midpoints in u (a loop over nodes, not rays)
        rho = r_cap / (((j + 0.5) / nodes) * scale)
        cos_half = (rho * rho + d0 * d0 - 1.0) / (2.0 * rho * np.maximum(d0, 1e-300))
        arc = np.arccos(np.clip(cos_half, -1.0, 1.0)) / np.pi
        out = out + np.where(rho + d0 <= 1.0, 1.0, np.where(rho >= 1.0 + d0, 0.0, arc))
    return out / nodes


def box_mean_product(mean_fn, c, x0, x1, k0, k1, nodes: int = 2) -> np.ndarray:
    """Mean of f(c x k) over the rectangle x in [x0, x1], k in [k0, k1] (both uniform).

    ``mean_fn(lo, hi)`` is f's closed-form mean over an argument interval (``multislit_mean``,
    ``sinc2_mean``). At fixed k the x-mean is f's mean over [c x0 k, c x1 k] exactly, and at
    fixed x the k-mean likewise; the mean is taken exactly in the dimension whose argument range
    is the wider (per element) and by a ``nodes``-point midpoint rule in the other
    (docs/physics.md section 3.7). Every node carries its exact share of f's integral, so the
    approximation only reshapes a peak's profile within the narrower range (a staircase for a
    ramp), never its area. Arrays broadcast together.
    """
    x0, x1, k0, k1 = (np.asarray(z, np.float64) for z in (x0, x1, k0, k1))
    c = np.asarray(c, np.float64)
    wx = np.abs(c * (x1 - x0) * 0.5 * (k0 + k1))
    wk = np.abs(c * 0.5 * (x0 + x1) * (k1 - k0))
    exact_x = wx >= wk
    out = 0.0
    for j in range(nodes):  # a loop over the few quadrature nodes, not rays
        f = (j + 0.5) / nodes
        kj = k0 + f * (k1 - k0)
        xj = x0 + f * (x1 - x0)
        lo = np.where(exact_x, c * x0 * kj, c * xj * k0)
        hi = np.where(exact_x, c * x1 * kj, c * xj * k1)
        out = out + mean_fn(lo, hi)
    return out / nodes


def fraunhofer_pattern_footprint(u, v, du, dv, edges, a, d, n, length, subdivisions: int = 2, lam_power: int = 0,
                                 nodes: int = 2, exclude_zeroth: bool = False) -> np.ndarray:
    """The mean of P over u in [u - du/2, u + du/2], v in [v - dv/2, v + dv/2] and each wavelength
    bin [edges[k], edges[k+1]] (docs/physics.md section 3.7): (B, K).

    The pixel footprint's extent (du, dv) (B,) comes from ray differentials (core/sampling/footprint.py);
    du = dv = 0 gives ``fraunhofer_pattern_binned``'s value. As there, each bin is split into
    ``subdivisions`` parts, the slit envelope sinc^2(xi) is taken at the part's centre (and at the
    footprint's centre u), and ``lam_power`` weights each part by its centre wavelength to that
    power. In each part, the N-slit factor F(pi D u / lambda) is averaged over the rectangle
    (u-interval) x (1/lambda-interval) and the slit-length factor sinc^2(pi L v / lambda) over
    (v-interval) x (1/lambda-interval), each by ``box_mean_product`` (closed form in the wider
    direction, ``nodes`` midpoints in the other); the two means are multiplied (the pattern is
    separable in u and v; within a part their common 1/lambda dependence is neglected, as in
    ``fraunhofer_pattern_binned``). Errors against brute-force quadrature of P over the whole box
    are bounded in tests/gratings/test_grating_footprint.py. ``exclude_zeroth``: as in
    ``fraunhofer_pattern_binned`` (the zeroth order carried by the base's continuation).
    """
    u = np.asarray(u, np.float64)[:, None]
    v = np.asarray(v, np.float64)[:, None]
    hu = 0.5 * np.abs(np.asarray(du, np.float64))[:, None]
    hv = 0.5 * np.abs(np.asarray(dv, np.float64))[:, None]
    e = np.asarray(edges, np.float64)
    k = len(e) - 1
    t = np.linspace(0.0, 1.0, subdivisions + 1)
    bounds = np.concatenate([(e[:-1, None] + (e[1:] - e[:-1])[:, None] * t[None, :-1]).ravel(), e[-1:]])
    inv = 1.0 / bounds
    k0, k1 = inv[None, :-1], inv[None, 1:]
    mid_lam = 2.0 / (inv[:-1] + inv[1:])
    n_i = int(n)
    ms = box_mean_product(lambda lo, hi: multislit_mean(lo, hi, n_i, exclude_zeroth), np.pi * np.asarray(d, np.float64),
                          u - hu, u + hu, k0, k1, nodes)
    zf = box_mean_product(sinc2_mean, np.pi * float(length), v - hv, v + hv, k0, k1, nodes)
    env = sinc2(np.pi * a * u / mid_lam[None, :])
    parts = env * ms * zf
    if lam_power:
        parts = parts * mid_lam[None, :] ** lam_power
    return parts.reshape(len(u), k, subdivisions).mean(axis=2)
