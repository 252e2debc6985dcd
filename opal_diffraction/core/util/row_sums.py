"""Sums of rows per target row: ``target[rows[i]] += values[i]``, each target row's values summed first.

What: the scatter-add of a batch of per-ray (or per-photon) spectra into a film or an
illumination map: each target row receives one sum. How (the NumPy reference): a stable sort of
the target rows, ``np.add.reduceat`` over each run of equal rows and one fancy-index ``+=`` of the
run sums (``np.add.at`` would add row by row, ~10x slower).

Where the compiled kernels run (core/util/jit.py), ``_add_runs`` does it in one pass over the
sorted order without the sorted (B, n) copy and reduceat's output: the same additions in the same
order, so the same bits. That order is reduceat's: a run's sum is its first row plus NumPy's
pairwise sum of the others, since reduceat's inner loop is a reduction along the rows
(``pairwise_sum`` in NumPy's add loops; tests/util/test_kernels.py checks every branch of it).
"""

from __future__ import annotations

import numpy as np

from .jit import kernels_enabled, njit

__all__ = ["add_row_sums"]


def add_row_sums(target: np.ndarray, rows: np.ndarray, values: np.ndarray) -> None:
    """``target`` (R, n) += per target row the sum of ``values`` (B, n) whose ``rows`` (B,) int name
    it, in place; rows already in order skip the sort."""
    if len(rows) == 0:
        return
    rows = np.asarray(rows)
    order = np.argsort(rows, kind="stable") if np.any(rows[1:] < rows[:-1]) else None
    if kernels_enabled() and isinstance(values, np.ndarray) and values.ndim == 2 and values.dtype.kind == "f":
        _add_runs(target, rows, np.arange(len(rows)) if order is None else order, values, values.dtype.type(-0.0))
        return
    r, v = (rows, values) if order is None else (rows[order], values[order])
    starts = np.flatnonzero(np.concatenate([[True], r[1:] != r[:-1]]))
    target[r[starts]] += np.add.reduceat(v, starts, axis=0)


@njit
def _pairwise_sum(values, order, lo, n, k, res):
    """NumPy's pairwise sum (``pairwise_sum`` of its add loops: sequential below 8 terms, eight
    interleaved partial sums up to 128, halves above) of ``values[order[lo:lo + n], k]``;
    ``res`` is the dtype's -0.0, NumPy's start."""
    if n < 8:
        for i in range(n):
            res += values[order[lo + i], k]
        return res
    if n <= 128:
        r0, r1, r2, r3 = values[order[lo], k], values[order[lo + 1], k], values[order[lo + 2], k], values[order[lo + 3], k]
        r4, r5, r6, r7 = values[order[lo + 4], k], values[order[lo + 5], k], values[order[lo + 6], k], values[order[lo + 7], k]
        i = 8
        while i < n - n % 8:
            r0 += values[order[lo + i], k]
            r1 += values[order[lo + i + 1], k]
            r2 += values[order[lo + i + 2], k]
            r3 += values[order[lo + i + 3], k]
            r4 += values[order[lo + i + 4], k]
            r5 += values[order[lo + i + 5], k]
            r6 += values[order[lo + i + 6], k]
            r7 += values[order[lo + i + 7], k]
            i += 8
        res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
        while i < n:
            res += values[order[lo + i], k]
            i += 1
        return res
    half = n // 2
    half -= half % 8
    return (_pairwise_sum(values, order, lo, half, k, res)
            + _pairwise_sum(values, order, lo + half, n - half, k, res))


@njit
def _add_runs(target, rows_of, order, values, neg_zero):
    """``target[rows_of[i]] += values[i]`` summed per target row first, in ``order`` (a stable
    sort of ``rows_of``), exactly as np.add.reduceat over the sorted rows and one += do: a run's
    sum is its first value plus NumPy's pairwise sum of the others (reduceat's inner loop is a
    reduction along the rows), added to ``target`` in the wider of the two precisions."""
    b = 0
    while b < order.shape[0]:
        row = rows_of[order[b]]
        end = b + 1
        while end < order.shape[0] and rows_of[order[end]] == row:
            end += 1
        for k in range(values.shape[1]):
            s = values[order[b], k]
            if end - b > 1:
                s += _pairwise_sum(values, order, b + 1, end - b - 1, k, neg_zero)
            target[row, k] += s
        b = end
