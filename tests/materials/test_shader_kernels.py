"""The compiled Perlin noise kernels (core/materials/shader_kernels.py) against the NumPy
reference (shader_textures.perlin_reference): bit for bit, on random points, negative and large
coordinates, lattice points and cell faces; and the texture built on them (fBM, distortion)
under the kernels equal to the reference path."""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.materials import shader_textures as T
from opal_diffraction.core.materials.shader_kernels import perlin2_kernel, perlin3_kernel
from opal_diffraction.core.util.jit import AVAILABLE, kernel_mode

pytestmark = pytest.mark.skipif(not AVAILABLE, reason="numba is not available: only the reference runs")


def points(d, n=20000, seed=4):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-60, 60, (n, d)).astype(np.float32)
    p[:200] = rng.integers(-5, 5, (200, d))                     # lattice points
    p[200:400, 0] = np.float32(3.0) - np.float32(1e-7)          # just below a cell face
    p[400:600] *= np.float32(1e4)                                # large (the 1e5 period's range)
    p[600:700] = -np.abs(p[600:700])                             # all negative
    return p


@pytest.mark.parametrize("d", [2, 3])
def test_perlin_kernels_equal_the_reference_bit_for_bit(d):
    p = points(d)
    out = np.empty(len(p), np.float32)
    cols = [np.ascontiguousarray(p[:, i]) for i in range(d)]
    (perlin2_kernel if d == 2 else perlin3_kernel)(*cols, out)
    ref = T.perlin_reference(p)
    assert np.array_equal(out.view(np.uint32), ref.view(np.uint32))


def test_the_noise_texture_is_the_same_under_both_paths():
    p = np.random.default_rng(2).uniform(-3, 3, (3000, 3)).astype(np.float32)
    with kernel_mode("numpy"):
        ref = T.noise_texture(p, detail=3.5, distortion=0.4)
    with kernel_mode("auto"):
        ker = T.noise_texture(p, detail=3.5, distortion=0.4)
    assert np.array_equal(ref[0], ker[0]) and np.array_equal(ref[1], ker[1])


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("metric", ["EUCLIDEAN", "MANHATTAN", "CHEBYCHEV"])
@pytest.mark.parametrize("feature", ["F1", "F2"])
def test_voronoi_octave_kernel_equals_the_reference_bit_for_bit(d, metric, feature):
    p = points(d, n=5000) / np.float32(7)
    rnd = np.random.default_rng(1).uniform(0, 1, len(p)).astype(np.float32)
    rnd[:50] = 0
    with kernel_mode("auto"):
        ker = T._voronoi_octave(p, feature, metric, rnd, None, None)
    ref = T._voronoi_octave_reference(p, feature, metric, rnd, None, None)
    for a, b in zip(ker, ref):
        assert np.array_equal(np.asarray(a, np.float32).view(np.uint32), np.asarray(b, np.float32).view(np.uint32))


@pytest.mark.parametrize("d", [2, 3])
def test_voronoi_edge_kernel_equals_the_reference_bit_for_bit(d):
    p = points(d, n=5000) / np.float32(7)
    rnd = np.random.default_rng(2).uniform(0, 1, len(p)).astype(np.float32)
    with kernel_mode("auto"):
        ker = T._distance_to_edge(p, rnd)
    ref = T._distance_to_edge_reference(p, rnd)
    assert np.array_equal(ker.view(np.uint32), ref.view(np.uint32))


def test_the_voronoi_texture_is_the_same_under_both_paths():
    p = np.random.default_rng(3).uniform(-3, 3, (3000, 3)).astype(np.float32)
    for feature in ("F1", "F2", "DISTANCE_TO_EDGE"):
        with kernel_mode("numpy"):
            ref = T.voronoi_texture(p, detail=2.5, normalize=True, feature=feature)
        with kernel_mode("auto"):
            ker = T.voronoi_texture(p, detail=2.5, normalize=True, feature=feature)
        for k in ref:
            assert np.array_equal(ref[k], ker[k]), (feature, k)
