"""Film adds of contributions that are a scalar times one of a few spectra, without a spectrum
per ray.

Where a path's throughput is still grey (camera rays through clear glass and perfect mirrors
keep unit weights: core/transport/walker.py), what it adds to its pixel at an emitter is
s_i E_{k(i)}(lambda): a scalar s_i (1, or an MIS weight) times the emission spectrum of the
material k(i) it hit. Summing the scalars per (pixel, spectrum) first and expanding once per
pixel, film[p] += sum_k (sum_{i: pix_i = p, k(i) = k} s_i) E_k, costs O(B + P U n) instead of
the O(B n) of building and reducing a (B, n) spectrum per ray (U: spectra present in the batch).
It is the same sum regrouped (docs/physics.md section 4.10); tile_output.TileOutput.accumulate_factored
does the same for next events of unit-weight rays.
"""

from __future__ import annotations

import numpy as np

__all__ = ["add_scaled_spectra"]


def add_scaled_spectra(film: np.ndarray, n_pixels: int, pix: np.ndarray, key: np.ndarray, scale,
                       table: np.ndarray) -> bool:
    """film (P * n,) += for every entry i: scale_i * table[key_i] added to pixel pix_i.

    ``pix`` (B,) pixel indices in [0, n_pixels), ``key`` (B,) rows of ``table`` (K, n) float32,
    ``scale`` (B,) or a scalar. Returns False, and adds nothing, when the batch holds so many
    (pixel, key) combinations that the regrouping would not pay (P U > B)."""
    b = len(pix)
    if b == 0:
        return True
    key = np.asarray(key, np.int64)
    present = np.bincount(key, minlength=len(table)) > 0
    uniq = np.flatnonzero(present)
    nu = len(uniq)
    if nu * n_pixels > b:
        return False
    u = (np.cumsum(present) - 1)[key] if nu > 1 else np.zeros(b, np.int64)
    weights = None if np.ndim(scale) == 0 and float(scale) == 1.0 else np.broadcast_to(
        np.asarray(scale, np.float64), (b,))
    sums = np.bincount(np.asarray(pix, np.int64) * nu + u, weights=weights, minlength=n_pixels * nu)
    n = table.shape[1]
    film.reshape(n_pixels, n)[:] += sums.reshape(n_pixels, nu).astype(np.float32) @ table[uniq]
    return True
