"""bsdf.cosine_hemisphere's compiled kernel against its NumPy reference, and its directions
against the cosine density (tests/chi2.py)."""

import numpy as np
import pytest

from chi2 import chi2_directions
from opal_diffraction.core.materials import bsdf
from opal_diffraction.core.util.jit import AVAILABLE, kernel_mode

pytestmark = pytest.mark.skipif(not AVAILABLE, reason="numba is not installed")


def _normals(b, seed):
    n = np.random.default_rng(seed).normal(size=(b, 3))
    n[: b // 8, 2] = -1.0 + 1e-7  # the frame's branch near z = -1
    n[b // 8: b // 4, :2] = 0  # poles
    return (n / np.linalg.norm(n, axis=1, keepdims=True)).astype(np.float32)


def test_cosine_kernel_matches_the_reference():
    n = _normals(100_000, 1)
    out = {}
    for mode in ("numpy", "auto"):
        with kernel_mode(mode):
            out[mode] = bsdf.cosine_hemisphere(n, np.random.default_rng(2))
    (wr, cr), (wk, ck) = out["numpy"], out["auto"]
    assert wk.dtype == ck.dtype == np.float32
    np.testing.assert_array_equal(cr, ck)  # sqrt: correctly rounded on both paths
    # the same float32 operations except sin / cos: NumPy's SIMD float32 sin / cos and the C
    # library's sinf / cosf may round differently (an ulp of a number <= 1), times |r| <= 1 and
    # the frame's entries (<= 2 in size), summed over three terms: a few 1e-7
    np.testing.assert_allclose(wk, wr, rtol=0, atol=2e-6)


def test_cosine_kernel_directions_are_cosine_distributed():
    rng = np.random.default_rng(7)
    with kernel_mode("auto"):
        for axis in ((0.0, 0.0, 1.0), (0.0, 0.0, -1.0), (0.6, -0.48, 0.64)):
            a = np.asarray(axis, np.float64) / np.linalg.norm(axis)
            wi, cos = bsdf.cosine_hemisphere(np.tile(a.astype(np.float32), (200_000, 1)), rng)
            wi = wi.astype(np.float64)
            np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0, atol=1e-5)
            np.testing.assert_allclose(wi @ a, cos, atol=1e-5)
            pval, info, total = chi2_directions(wi, lambda d: np.maximum(d @ a, 0.0) / np.pi, a,
                                                theta_max=np.pi / 2)
            assert abs(total - 1.0) < 1e-3
            assert pval > 0.01 / 3, info
