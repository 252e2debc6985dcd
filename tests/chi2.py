"""The chi-square harness of the tests, after Mitsuba 3's chi2.py: every Pearson test of a sampler
against its density goes through ``pearson``.

- ``pearson``: observed counts against expected ones; cells expecting fewer than 5 are pooled
  into one, and samples where nothing is expected fail the test (p = 0). Each test compares the
  p-value with its threshold divided by the number of tests it runs (Bonferroni), as Mitsuba does.
- ``chi2_directions``: directions histogrammed over a (theta, phi) grid around an axis, each cell's
  expected count the pdf integrated over the cell (a midpoint rule on a fine sub-grid, with the
  sin(theta) Jacobian), then ``pearson``.
- ``chi2_normal_scores``: the sum of squares of independent standard-normal scores against the
  chi-square distribution (a Z-test over many cells at once).
"""

from __future__ import annotations

import numpy as np
from scipy import stats


def frame(axis):
    axis = np.asarray(axis, np.float64)
    axis = axis / np.linalg.norm(axis)
    a = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(axis, a)
    u /= np.linalg.norm(u)
    return u, np.cross(axis, u), axis


def chi2_directions(dirs, pdf, axis, theta_max=np.pi, n_theta=16, n_phi=32, sub=24, min_expected=5.0):
    """(p-value, details, integral of the pdf over the sphere) for directions ``dirs`` (N, 3) against the solid-angle density
    ``pdf(directions (K, 3)) -> (K,)``. The grid spans theta in [0, theta_max] about ``axis``;
    samples beyond theta_max fall in one extra cell whose expected count is N times the pdf's
    integral there (computed on the same kind of grid)."""
    dirs = np.asarray(dirs, np.float64)
    n = len(dirs)
    u, v, w = frame(axis)
    x, y, z = dirs @ u, dirs @ v, dirs @ w
    theta = np.arccos(np.clip(z, -1, 1))
    phi = np.mod(np.arctan2(y, x), 2 * np.pi)
    ti = np.minimum((theta / theta_max * n_theta).astype(int), n_theta)  # n_theta: beyond
    pj = np.minimum((phi / (2 * np.pi) * n_phi).astype(int), n_phi - 1)
    observed = np.bincount(np.where(ti < n_theta, ti * n_phi + pj, n_theta * n_phi),
                           minlength=n_theta * n_phi + 1).astype(np.float64)

    def integrate(t0, t1, nt):
        """pdf integrated over nt x n_phi cells spanning theta in [t0, t1]: (nt, n_phi)."""
        dt, dp = (t1 - t0) / (nt * sub), 2 * np.pi / (n_phi * sub)
        tc = t0 + (np.arange(nt * sub) + 0.5) * dt
        pc = (np.arange(n_phi * sub) + 0.5) * dp
        out = np.zeros((nt, n_phi))
        for row in range(nt):  # one theta row at a time (bounded memory)
            tt = tc[row * sub:(row + 1) * sub]
            T, P = np.meshgrid(tt, pc, indexing="ij")
            d = (np.sin(T) * np.cos(P))[..., None] * u + (np.sin(T) * np.sin(P))[..., None] * v + \
                np.cos(T)[..., None] * w
            val = np.asarray(pdf(d.reshape(-1, 3)), np.float64).reshape(T.shape) * np.sin(T) * dt * dp
            out[row] = val.reshape(sub, n_phi, sub).sum(axis=(0, 2))
        return out

    expected = np.zeros(n_theta * n_phi + 1)
    expected[:-1] = integrate(0.0, theta_max, n_theta).ravel() * n
    if theta_max < np.pi:
        expected[-1] = integrate(theta_max, np.pi, 8).sum() * n
    p, details = pearson(observed, expected, min_expected)
    return p, f"{details}; expected total {expected.sum():.1f} of {n}", expected.sum() / n


def pearson(observed, expected, min_expected=5.0):
    """(p-value, details) of Pearson's statistic of the counts ``observed`` against ``expected``
    (arrays of one shape), the cells expecting fewer than ``min_expected`` pooled into one (as
    Mitsuba does). Samples in cells where nothing is expected give p = 0; a single cell left (no
    degree of freedom) gives p = 1."""
    observed = np.asarray(observed, np.float64).ravel()
    expected = np.asarray(expected, np.float64).ravel()
    small = expected < min_expected
    obs = list(observed[~small])
    exp = list(expected[~small])
    pooled_e, pooled_o = expected[small].sum(), observed[small].sum()
    if pooled_e > 0:
        obs.append(pooled_o)
        exp.append(pooled_e)
    elif pooled_o > 0:
        return 0.0, f"{pooled_o:g} samples where nothing is expected"
    obs, exp = np.array(obs), np.array(exp)
    stat = float(np.sum((obs - exp) ** 2 / exp))
    dof = len(obs) - 1
    p = float(stats.chi2.sf(stat, dof)) if dof > 0 else 1.0
    return p, f"chi2 {stat:.1f} over {dof} dof, p = {p:.3g} ({len(obs)} cells)"


def chi2_normal_scores(z):
    """p-value of sum(z^2) for independent standard-normal scores ``z``: chi-square with len(z)
    degrees of freedom."""
    z = np.asarray(z, np.float64).ravel()
    return float(stats.chi2.sf(np.sum(z**2), len(z)))
