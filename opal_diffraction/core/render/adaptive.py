"""Adaptive sampling: Cycles' Noise Threshold, per pixel, checked between the eye pass's rounds.

The stopping rule is Cycles' (intern/cycles/kernel/film/adaptive_sampling.h, the per-pixel form
of Dammertz et al. 2010, "A hierarchical automatic stopping condition for Monte Carlo global
illumination", section 2.1; parameters from intern/cycles/scene/integrator.cpp): besides the
pixel's sum I over all its N samples, the film keeps the sum A of one half of them (here: the
samples of the even rounds, N_A of them). The error estimate is

    e = sum_c |I_c / N - A_c / N_A| * sqrt(N_A / N_B) / (1e-4 + s),
    s = sqrt(L) if L < 1 else L,   L = sum_c I_c / N,

which is Cycles' formula when the halves are equal (N_A = N_B = N / 2: Cycles writes 2 A); the
factor sqrt(N_A / N_B) keeps e an estimate of the whole mean's standard error (of its absolute
value) when a pixel's halves differ, after a pixel skipped rounds (docs/physics.md section 10.5).
A pixel converges when e < 5 t (Cycles multiplies the user's threshold t by 5), once it has at
least the minimum samples, max(4, N_min), N_min = 0 meaning Cycles' automatic
ceil(16 / t ** 0.3) (64 at t = 0.01). Pixels next to one that has not converged keep sampling
(Cycles' two-pass box filter: a 3 x 3 dilation of the unconverged set), here within the tile, so
a tile's mask depends on its own pixels only and a cluster can check it as soon as the tile's
round is added. A tile whose pixels have all converged takes no more samples: that is what saves
time in a tile renderer; the others trace only their active pixels, in rounds that grow past the
minimum (tiles.adaptive_rounds) so a few pixels left do not pay the tracer's fixed cost per
round many times.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["THRESHOLD_SCALE", "MIN_SAMPLES_FLOOR", "min_samples", "error_estimate", "dilate", "next_active"]

#: Cycles: "arbitrary factor that makes the threshold more similar to what it was before"
THRESHOLD_SCALE = 5.0
MIN_SAMPLES_FLOOR = 4
ERROR_EPSILON = 1e-4


def min_samples(threshold: float, requested: int) -> int:
    """Samples a pixel takes before its first convergence check (Cycles' rule)."""
    if requested > 0:
        return max(MIN_SAMPLES_FLOOR, int(requested))
    return max(MIN_SAMPLES_FLOOR, int(math.ceil(16.0 / float(threshold) ** 0.3)))


def error_estimate(rgb_sum: np.ndarray, count: np.ndarray, rgb_a: np.ndarray, count_a: np.ndarray) -> np.ndarray:
    """Cycles' per-pixel error from the (..., 3) RGB sums of all samples and of half A, with
    their sample counts (...). Inf where a half is empty (nothing to compare yet)."""
    n = np.asarray(count, np.float64)
    na = np.asarray(count_a, np.float64)
    nb = n - na
    ok = (na > 0) & (nb > 0)
    n_, na_, nb_ = (np.where(ok, x, 1.0) for x in (n, na, nb))
    mean = np.asarray(rgb_sum, np.float64) / n_[..., None]
    mean_a = np.asarray(rgb_a, np.float64) / na_[..., None]
    diff = np.abs(mean - mean_a).sum(axis=-1) * np.sqrt(na_ / nb_)
    lum = mean.sum(axis=-1)
    norm = np.where(lum < 1.0, np.sqrt(np.maximum(lum, 0.0)), lum)
    return np.where(ok, diff / (ERROR_EPSILON + norm), np.inf)


def dilate(mask: np.ndarray) -> np.ndarray:
    """A (h, w) bool mask grown by one pixel in x, then in y (a 3 x 3 box)."""
    out = mask.copy()
    out[:, 1:] |= mask[:, :-1]
    out[:, :-1] |= mask[:, 1:]
    grown = out.copy()
    out[1:] |= grown[:-1]
    out[:-1] |= grown[1:]
    return out


def next_active(active: np.ndarray, error: np.ndarray, count: np.ndarray, threshold: float,
                min_spp: int) -> np.ndarray:
    """The (h, w) pixels of a tile that sample in the next round: the active ones that have not
    converged (error >= THRESHOLD_SCALE * threshold, or fewer than ``min_spp`` samples), and
    their neighbours."""
    unconverged = active & ((error >= THRESHOLD_SCALE * threshold) | (count < min_spp))
    return dilate(unconverged)
