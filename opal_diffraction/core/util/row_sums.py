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
def _pairwise_block(values, order, lo, n, k, res):
    """NumPy's pairwise sum of ``values[order[lo:lo + n], k]`` for n <= 128 (``pairwise_sum`` of its
    add loops: sequential below 8 terms, else eight interleaved partial sums); ``res`` is the
    dtype's -0.0, NumPy's start."""
    if n < 8:
        for i in range(n):
            res += values[order[lo + i], k]
        return res
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


@njit
def _pairwise_sum(values, order, lo, n, k, res):
    """NumPy's pairwise sum of ``values[order[lo:lo + n], k]``: blocks of up to 128 terms
    (_pairwise_block), above that the sum of the two halves (the first a multiple of 8 long).
    The halving runs on an explicit stack, not by recursion: numba's on-disk cache cannot
    always load a recursive kernel back (LLVM 'Symbol not found', or a crash)."""
    if n <= 128:
        return _pairwise_block(values, order, lo, n, k, res)
    # frames: start, count, stage (0: push left, 1: push right, 2: add), and the halves' sums
    los, ns, stage = np.empty(64, np.int64), np.empty(64, np.int64), np.empty(64, np.int64)
    left, right = np.empty(64, values.dtype), np.empty(64, values.dtype)
    los[0], ns[0], stage[0] = lo, n, 0
    sp = 1
    v = res
    while sp > 0:
        t = sp - 1
        c = ns[t]
        done = False
        if c <= 128:
            v = _pairwise_block(values, order, los[t], c, k, res)
            done = True
        elif stage[t] < 2:
            half = c // 2
            half -= half % 8
            los[sp] = los[t] if stage[t] == 0 else los[t] + half
            ns[sp] = half if stage[t] == 0 else c - half
            stage[sp] = 0
            stage[t] += 1
            sp += 1
        else:
            v = left[t] + right[t]
            done = True
        if done:
            sp -= 1
            if sp > 0:
                if stage[sp - 1] == 1:
                    left[sp - 1] = v
                else:
                    right[sp - 1] = v
    return v


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
