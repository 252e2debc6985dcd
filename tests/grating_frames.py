"""The smoothed grating tangents by their definition (a loop per corner): the reference that
tests/gratings/test_prepare_frames.py and tests/render/test_prepare_scale.py compare
gratings/directions.smooth_corner_tangents with."""

from __future__ import annotations

import numpy as np

from opal_diffraction.core.gratings import directions as gd


def corner_tangents_by_loop(t, n, tt, mat, grating, ang):
    """The smoothed grating tangents (T, 3, 3) by their definition, one loop per corner: the
    corner-angle-weighted (``ang`` (T, 3)), sign-aligned sum over the grating corners at the vertex
    with the same material, tangent within MAX_TANGENT_ANGLE and normal within MAX_NORMAL_ANGLE,
    normalised (its own tangent when it vanishes); non-grating rows keep their tangent."""
    tt64 = tt.astype(np.float64)
    cos_t, cos_n = np.cos(np.radians(gd.MAX_TANGENT_ANGLE)), np.cos(np.radians(gd.MAX_NORMAL_ANGLE))
    at_vertex = {}
    for i in np.flatnonzero(grating):
        for c in range(3):
            at_vertex.setdefault(int(t[i, c]), []).append((i, c))
    ref = np.repeat(tt64[:, None, :], 3, axis=1)
    for i in np.flatnonzero(grating):
        for c in range(3):
            acc = np.zeros(3)
            for j, cj in at_vertex[int(t[i, c])]:
                d = tt64[i] @ tt64[j]
                if abs(d) >= cos_t and mat[i] == mat[j] and n[i] @ n[j] >= cos_n:
                    acc += ang[j, cj] * np.sign(d) * tt64[j]
            ln = np.linalg.norm(acc)
            ref[i, c] = acc / ln if ln > 1e-12 else tt64[i]
    return ref
