"""Shared by the environment-map kernel tests (tests/lights/test_environment_kernels.py,
tests/util/test_kernels.py): the fused lookups checked against the NumPy reference."""

import numpy as np

from opal_diffraction.core.lights.environment import direction_to_uv
from opal_diffraction.core.util import jit


def same_bits(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype and a.shape == b.shape
    np.testing.assert_array_equal(a.view(np.uint8), b.view(np.uint8))  # signed zeros and NaNs too


#: How far the kernels' float32 (u, v) may lie from the reference's: the angles are libm's
#: atan2f / acosf in the kernels and NumPy's in the reference, which are SVML's on AVX-512
#: machines (within an ulp or two of libm's, and differing with an element's place in the array:
#: SIMD body or tail), libm's elsewhere (then the same bits). 2 ulps of 1.
UV_ATOL = 2 * float(np.finfo(np.float32).eps)


def kernel_uv(env, d):
    """The (u, v) the fused lookup kernel computes for float32 world directions d: the map frame
    as _kernel_lookup takes it (NumPy's rotation, or the kernel's sums with the identity), then
    the compiled direction_to_uv (the same _uv_one)."""
    m = d if env._identity else env._map_dirs(d)
    if env._identity:
        r = env._rot32
        m = np.stack([m[:, 0] * r[0, j] + m[:, 1] * r[1, j] + m[:, 2] * r[2, j] for j in range(3)], axis=1)
    with jit.kernel_mode("auto"):
        return direction_to_uv(np.ascontiguousarray(m, np.float32))


def lookups_match(env, d):
    """The fused kernels' radiance, density and lookup of float32 directions d: their (u, v)
    within UV_ATOL of the reference's, and at those (u, v) the reference's texels and density,
    bit for bit (so everything after the angles is the reference's arithmetic)."""
    u, v = kernel_uv(env, d)
    with jit.kernel_mode("numpy"):
        u0, v0 = direction_to_uv(env._map_dirs(d))
        rgb_want = env._lookup(u, v)
        i, j = env._texel(u, v)
        pdf_want = np.take(env.density, j * env.width + i)
    np.testing.assert_allclose(u, u0, rtol=0, atol=UV_ATOL)
    np.testing.assert_allclose(v, v0, rtol=0, atol=UV_ATOL)
    with jit.kernel_mode("auto"):
        same_bits(env.radiance_rgb(d), rgb_want)
        same_bits(env.pdf(d), pdf_want)
        rgb, pdf = env.lookup(d)
    same_bits(rgb, rgb_want)
    same_bits(pdf, pdf_want)
    return rgb, pdf
