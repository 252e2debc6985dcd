"""core/spectral/optics.py's ``reflect`` kernel against its NumPy line: the same float32 /
float64 operations in the same order (np.sum of three products sums them in order), the same bits."""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.spectral import optics
from opal_diffraction.core.util import jit

pytestmark = pytest.mark.skipif(not jit.AVAILABLE, reason="numba is not available")


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_reflect_kernel_is_the_numpy_line(dtype):
    rng = np.random.default_rng(4)
    d, n = rng.normal(size=(2, 5000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d, n = d.astype(dtype), n.astype(dtype)
    n[:10] = 0.0  # degenerate normals: d unchanged
    n[10] = d[10]  # head-on: -d
    got = optics.reflect(d, n)
    with jit.kernel_mode("numpy"):
        ref = optics.reflect(d, n)
    assert got.dtype == ref.dtype == dtype
    np.testing.assert_array_equal(got, ref)
    np.testing.assert_array_equal(got[:10], d[:10])
    with jit.kernel_mode("numpy"):  # a strided view and broadcast normals take the NumPy line either way
        np.testing.assert_array_equal(optics.reflect(d[::2], n[0]), d[::2] - 2.0 * np.sum(d[::2] * n[0], axis=-1,
                                                                                             keepdims=True) * n[0])
