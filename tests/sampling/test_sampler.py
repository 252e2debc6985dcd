"""core/sampling/sampler.py: Owen-scrambled shuffled Sobol' points (docs/physics.md section 6.5).

Checked against their definitions, not against our own output: every power-of-two prefix of a
pixel's points is a (0, k, 2)-net (one point in each elementary interval), the numbers are
uniform over pixels (chi-square) and independent between dimension pairs, and a smooth
integrand's pixel estimate is unbiased and converges faster than 1/sqrt(N).
"""

import numpy as np
import pytest

from chi2 import pearson
from opal_diffraction.core.sampling.sampler import PixelSampler, blue_noise_numbers, blue_noise_rank, sobol_owen_2d, vertex_pair


@pytest.mark.parametrize("k", [2, 5, 8])
@pytest.mark.parametrize("pixel,pair", [(0, 0), (4097, 3), (123456, 41)])
def test_every_prefix_is_a_net(k, pixel, pair):
    n = 1 << k
    x, y = sobol_owen_2d(np.full(n, pixel), np.arange(n), pair, seed=11)
    for i in range(k + 1):  # elementary intervals 2^-i x 2^-(k-i)
        cells = (np.floor(x * (1 << i)).astype(np.int64) << (k - i)) + np.floor(y * (1 << (k - i))).astype(np.int64)
        assert len(np.unique(cells)) == n


def test_uniform_over_pixels_and_independent_pairs():
    m = 200_000
    pix = np.arange(m)
    x, y = sobol_owen_2d(pix, np.full(m, 5), 7, seed=2)
    x2, _ = sobol_owen_2d(pix, np.full(m, 5), 8, seed=2)
    # a 16 x 16 histogram of (x, y) and of (x, x2): uniform (two chi-square tests, Bonferroni)
    for a, b in ((x, y), (x, x2)):
        h, _, _ = np.histogram2d(a, b, bins=16, range=[[0, 1], [0, 1]])
        p, info = pearson(h, np.full(h.shape, m / h.size))
        assert p > 0.01 / 2, info
    assert x.max() < 1 and x.min() >= 0
    assert np.float32(x.max()) < 1  # below 1 in float32 too


def test_smooth_integrand_unbiased_and_faster_than_random():
    """f(x, y) = exp(x) sin(pi y) has the integral (e - 1) 2 / pi. Over 4096 pixels of 64 samples
    the mean is unbiased (Z-test), and the per-pixel RMS error is far below random sampling's
    sigma / 8 (the error of 64 independent samples)."""
    exact = (np.e - 1) * 2 / np.pi
    pixels, spp = 4096, 64
    pix = np.repeat(np.arange(pixels), spp)
    x, y = sobol_owen_2d(pix, np.tile(np.arange(spp), pixels), 3, seed=9)
    est = (np.exp(x) * np.sin(np.pi * y)).reshape(pixels, spp).mean(axis=1)
    sigma_random = np.sqrt(np.mean(np.exp(2 * np.linspace(0, 1, 100001))) * 0.5 - exact**2)
    err = est - exact
    assert abs(err.mean()) < 4 * err.std(ddof=1) / np.sqrt(pixels)
    assert np.sqrt(np.mean(err**2)) < 0.25 * sigma_random / np.sqrt(spp)


def test_pixel_sampler_counts_dimensions_and_falls_back():
    rng = np.random.default_rng(0)
    b = 1000
    s = PixelSampler(rng, np.arange(b), np.zeros(b, np.int64), vertex_pair(np.zeros(b), 0), seed=1, pairs=2)
    a1, a2 = s.random(b), s.random(b, np.float32)
    ex, ey = sobol_owen_2d(np.arange(b), np.zeros(b), vertex_pair(np.zeros(b), 0), 1)
    assert np.array_equal(a1, ex) and np.array_equal(a2, ey.astype(np.float32))
    rows = s.random((b, 2))  # the second pair
    fx, fy = sobol_owen_2d(np.arange(b), np.zeros(b), vertex_pair(np.zeros(b), 0) + 1, 1)
    assert np.array_equal(rows, np.stack([fx, fy], axis=1))
    # pairs used up, and other sizes: the pseudo-random stream
    assert not np.isin(s.random(b), np.concatenate([ex, ey, fx, fy])).all()
    assert s.random(7).shape == (7,)


def test_seeds_differing_above_32_bits_give_other_points():
    """The seed's high words take part in the scramble: seeds 5 and 5 + 2^32 (and 5 + 2^64) give
    unrelated points, while one seed always gives the same."""
    pix, smp = np.arange(64) % 8, np.arange(64)
    a = sobol_owen_2d(pix, smp, 0, seed=5)
    for other in (5 + (1 << 32), 5 + (1 << 64)):
        b = sobol_owen_2d(pix, smp, 0, seed=other)
        assert np.mean(a[0] == b[0]) < 0.1
    np.testing.assert_array_equal(a[0], sobol_owen_2d(pix, smp, 0, seed=5)[0])


def test_bit_reversal_and_sobols_second_dimension_match_their_definitions():
    """The shift-and-mask bit reversal equals reversing the binary digits, and Sobol's second
    dimension from superset parities equals the xor of its direction numbers v_0 = 2^31,
    v_i = v_(i-1) xor (v_(i-1) >> 1) over the index's set bits (Joe & Kuo's polynomial x + 1)."""
    from opal_diffraction.core.sampling.sampler import _reverse_bits, _sobol_y

    rng = np.random.default_rng(9)
    x = np.concatenate([rng.integers(0, 1 << 32, 3000, dtype=np.uint64), [0, 1, 0xFFFFFFFF, 1 << 31]]).astype(np.uint32)
    want = np.array([int(f"{int(v):032b}"[::-1], 2) for v in x], np.uint64)
    assert np.array_equal(_reverse_bits(x).astype(np.uint64), want)
    v = [1 << 31]
    for _ in range(31):
        v.append(v[-1] ^ (v[-1] >> 1))
    y = []
    for i in x:
        acc = 0
        for bit in range(32):
            if int(i) >> bit & 1:
                acc ^= v[bit]
        y.append(acc)
    assert np.array_equal(_sobol_y(x).astype(np.uint64), np.array(y, np.uint64))


def _is_net(x, y, k):
    """Every elementary interval 2^-i x 2^-(k-i) holds exactly one of the 2^k points."""
    n = 1 << k
    for i in range(k + 1):
        cells = (np.floor(x * (1 << i)).astype(np.int64) << (k - i)) + np.floor(y * (1 << (k - i))).astype(np.int64)
        if len(np.unique(cells)) != n:
            return False
    return True


@pytest.mark.parametrize("seed", [0, 9, 2**40 + 3])
def test_blue_noise_rank_is_a_hierarchical_bijection(seed):
    """The ranks of a 32 x 32 image are a permutation of 0 .. 1023, and every aligned 2^k x 2^k
    square of pixels holds one aligned block of 4^k consecutive ranks (the ordering is a
    scrambled quadtree: what makes neighbouring pixels' sample blocks one net)."""
    ys, xs = np.mgrid[0:32, 0:32]
    r = blue_noise_rank(xs.ravel(), ys.ravel(), seed, 5).reshape(32, 32).astype(np.int64)
    assert sorted(r.ravel()) == list(range(1024))
    for k in range(1, 5):
        s = 1 << k
        for by in range(0, 32, s):
            for bx in range(0, 32, s):
                block = r[by:by + s, bx:bx + s]
                assert block.max() - block.min() == s * s - 1 and block.min() % (s * s) == 0
    other = blue_noise_rank(xs.ravel(), ys.ravel(), seed + 1, 5)
    assert (other != r.ravel()).mean() > 0.9  # another seed, another order


@pytest.mark.parametrize("spp", [4, 16, 32])
def test_blue_noise_squares_of_pixels_share_one_net(spp):
    """With blue noise the pixels number their samples in blocks of one shared sequence: each
    pixel's spp points are a net, and so are the 4 spp points of every aligned 2 x 2 square and
    the 16 spp of every aligned 4 x 4 square, in every dimension pair (the pixel position, the
    light numbers, the bounce). Per-pixel sequences (the classic pattern) give no such squares."""
    ys, xs = np.mgrid[0:8, 0:8]
    xs, ys = xs.ravel(), ys.ravel()
    starts = blue_noise_numbers(xs, ys, 8, 8, spp, seed=5).astype(np.int64)
    k = spp.bit_length() - 1
    for pair in (0, 2, 13):
        num = (starts[:, None] + np.arange(spp)[None, :]).ravel()
        x, y = sobol_owen_2d(np.zeros(len(num), np.uint32), num, pair, seed=5)
        x, y = x.reshape(8, 8, spp), y.reshape(8, 8, spp)
        ind_x, ind_y = sobol_owen_2d(np.repeat(ys * 8 + xs, spp), np.tile(np.arange(spp), 64), pair, seed=5)
        ind_x, ind_y = ind_x.reshape(8, 8, spp), ind_y.reshape(8, 8, spp)
        assert all(_is_net(x[j, i], y[j, i], k) for j in range(8) for i in range(8))
        for s, kk in ((2, k + 2), (4, k + 4)):
            squares = [(x[j:j + s, i:i + s].ravel(), y[j:j + s, i:i + s].ravel())
                       for j in range(0, 8, s) for i in range(0, 8, s)]
            assert all(_is_net(a, b, kk) for a, b in squares)
            classic = [(ind_x[j:j + s, i:i + s].ravel(), ind_y[j:j + s, i:i + s].ravel())
                       for j in range(0, 8, s) for i in range(0, 8, s)]
            assert not all(_is_net(a, b, kk) for a, b in classic)


def test_blue_noise_numbers_are_uniform_over_pixels_and_fall_back_when_too_long():
    """The first sample's 2-D point over a 256 x 256 image is uniform (chi-square); blocks that
    would not fit in 32-bit indices (4096 x 4096 pixels at 512 samples) are not used."""
    ys, xs = np.mgrid[0:256, 0:256]
    starts = blue_noise_numbers(xs.ravel(), ys.ravel(), 256, 256, 64, seed=1)
    x, y = sobol_owen_2d(np.zeros(len(starts), np.uint32), starts, 3, seed=1)
    h, _, _ = np.histogram2d(x, y, bins=16, range=[[0, 1], [0, 1]])
    p, info = pearson(h, np.full(h.shape, len(x) / h.size))
    assert p > 0.01, info
    assert blue_noise_numbers(np.zeros(1), np.zeros(1), 4096, 4096, 512, seed=1) is None
    assert blue_noise_numbers(np.zeros(1), np.zeros(1), 4096, 4096, 256, seed=1) is not None
