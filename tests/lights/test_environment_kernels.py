"""The environment map's compiled kernels (core/lights/environment.py: direction lookups, the
density, importance sampling) against the NumPy reference: the same bits, except the float32
angles of a direction's (u, v) (libm's in the kernels, NumPy's - SVML's on AVX-512 - in the
reference: within 2 ulps; everything after them the same bits)."""

import numpy as np
import pytest

from opal_diffraction.core.lights.environment import EnvironmentMap, direction_to_uv
from opal_diffraction.core.util import jit
from environment_checks import UV_ATOL, lookups_match

pytestmark = pytest.mark.skipif(not jit.AVAILABLE, reason=jit.UNAVAILABLE_REASON or "numba missing")


def both(fn, *args):
    out = []
    for mode in ("numpy", "auto"):
        with jit.kernel_mode(mode):
            assert jit.kernels_enabled() == (mode == "auto")
            out.append(fn(*args))
    return out


def same_bits(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype and a.shape == b.shape
    np.testing.assert_array_equal(a.view(np.uint8), b.view(np.uint8))  # signed zeros and NaNs too




def _rotation(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q


def _map(rng, size, interpolation, holes=False):
    rgb = rng.uniform(0, 5, size + (3,)) ** 3  # a high dynamic range
    if holes:  # black rows and texels: zero-width CDF steps
        rgb[rng.random(size) < 0.3] = 0
        rgb[::3] = 0
    return rgb.astype(np.float32)


def _directions(rng, b):
    d = rng.normal(size=(b, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d = d.astype(np.float32)
    d[:8] = [[0, 0, 1], [0, 0, -1], [-1, 0, 0], [-1, -0.0, 0], [1, 0, 0], [0, 1, 0], [-0.0, -0.0, 1], [0, -1, 0]]
    return d


@pytest.mark.parametrize("interpolation", ["LINEAR", "CLOSEST"])
@pytest.mark.parametrize("size", [(1, 1), (2, 7), (33, 64)])
@pytest.mark.parametrize("rotated", [False, True])
@pytest.mark.parametrize("holes", [False, True])
def test_lookups_and_density_are_the_reference_after_the_angles(interpolation, size, rotated, holes):
    rng = np.random.default_rng(size[0] * 7 + rotated + 2 * holes)
    env = EnvironmentMap(_map(rng, size, interpolation, holes), _rotation(rng) if rotated else None, interpolation)
    d = _directions(rng, 4000)
    rgb, pdf = lookups_match(env, d)
    same_bits(*both(env.pdf, d[:0]))
    assert pdf.dtype == np.float64 and rgb.dtype == np.float32


def test_direction_to_uv_is_the_reference_within_two_ulps():
    rng = np.random.default_rng(4)
    m = (rng.normal(size=(5000, 3)) * 10.0 ** rng.uniform(-3, 3, (5000, 1))).astype(np.float32)
    m[:8] = _directions(rng, 8)[:8]
    (u0, v0), (u1, v1) = both(direction_to_uv, m)
    np.testing.assert_allclose(u1, u0, rtol=0, atol=UV_ATOL)
    np.testing.assert_allclose(v1, v0, rtol=0, atol=UV_ATOL)
    # the poles and the seam's directions, where the angles are exact
    same_bits(u1[:8], u0[:8])
    same_bits(v1[:8], v0[:8])
    assert u1.dtype == np.float32


@pytest.mark.parametrize("interpolation", ["LINEAR", "CLOSEST"])
@pytest.mark.parametrize("size", [(1, 1), (2, 7), (33, 64), (5, 300)])
@pytest.mark.parametrize("holes", [False, True])
@pytest.mark.parametrize("rotated", [False, True])
def test_sample_is_the_reference_bit_for_bit(interpolation, size, holes, rotated):
    rng = np.random.default_rng(size[1] + holes)
    env = EnvironmentMap(_map(rng, size, interpolation, holes), _rotation(rng) if rotated else None, interpolation)
    u1, u2 = rng.random(6000), rng.random(6000)
    # the numbers at the CDFs' steps and the ends of [0, 1)
    u1[:size[0] + 1] = env._row_cdf
    u1[-4:], u2[-4:] = [0.0, 1 - 2 ** -53, 0.5, 1 - 2 ** -53], [0.0, 1 - 2 ** -53, 1 - 2 ** -53, 0.0]
    row = np.clip(np.searchsorted(env._row_cdf, u1[100:600], side="right") - 1, 0, size[0] - 1)
    u2[100:600] = env._cond_flat[row * (size[1] + 1) + rng.integers(0, size[1], 500)] - row  # in [0, 1)
    for got, want in zip(*both(env.sample, u1, u2)):
        same_bits(got, want)


def test_black_map_sample_is_the_reference_bit_for_bit():
    rng = np.random.default_rng(8)
    env = EnvironmentMap(np.zeros((4, 8, 3), np.float32))
    for got, want in zip(*both(env.sample, rng.random(500), rng.random(500))):
        same_bits(got, want)
    rgb = both(env.sample, rng.random(10), rng.random(10))[1][2]
    assert not rgb.any()


def test_sampled_directions_have_the_density_of_their_texel():
    """The kernel's samples (not only equal to the reference's): pdf() of each sampled direction
    is the density sample() returned for it (a texel boundary may round to its neighbour)."""
    rng = np.random.default_rng(9)
    env = EnvironmentMap(_map(rng, (16, 32), "LINEAR", True))
    with jit.kernel_mode("auto"):
        d, pdf, rgb = env.sample(rng.random(4000), rng.random(4000))
        again = env.pdf(d.astype(np.float32))
        rgb_again = env.radiance_rgb(d.astype(np.float32))
    assert np.mean(again == pdf) > 0.99
    assert (pdf > 0).all()
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1, atol=1e-12)
    np.testing.assert_allclose(rgb_again, rgb, rtol=1e-3, atol=1e-3 * rgb.max())
