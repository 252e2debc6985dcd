"""The eye pass's film deposits (core/integrators/eye/tile_output.py) on the compiled kernel
against the NumPy reference: the same bits (the kernel sums each pixel's run as np.add.reduceat
does), and against a brute-force float64 sum."""

from types import SimpleNamespace

import numpy as np
import pytest

from opal_diffraction.core.integrators.eye.tile_output import TileOutput
from opal_diffraction.core.transport.path_state import PathState
from opal_diffraction.core.transport.walker import Rays
from opal_diffraction.core.util import jit

pytestmark = pytest.mark.skipif(not jit.AVAILABLE, reason=jit.UNAVAILABLE_REASON or "numba missing")

P, N = 37, 61


def _rays(rng, b, mono, nd_max=0, per_pixel=None):
    pix = rng.integers(0, P if per_pixel is None else per_pixel, b).astype(np.int64)
    state = PathState.new(b)
    state.nd[:] = rng.integers(0, nd_max + 1, b)
    lam = rng.integers(0, N, b) if mono else None
    w = rng.random(b).astype(np.float32) if mono else None
    z = np.zeros((b, 3), np.float32)
    return Rays(z, z, pix, w, lam, np.zeros(b, np.int64), np.zeros(b), state)


def _contrib(rng, b, mono, dtype=np.float32):
    # magnitudes over six decades: float32 sums in a different order would differ in the last bits
    scale = 10.0 ** rng.uniform(-3, 3, (b, 1))
    c = rng.random((b, 1 if mono else N)) * scale
    return (c[:, 0] if mono else c).astype(dtype)


def _both(fn):
    """(reference TileOutput, kernel TileOutput) after fn(out) on each."""
    outs = []
    for mode in ("numpy", "auto"):
        out = TileOutput(P, N)
        out.film[:] = np.float32(0.25)  # something there already
        with jit.kernel_mode(mode):
            fn(out)
        outs.append(out)
    return outs


@pytest.mark.parametrize("mono", [False, True])
@pytest.mark.parametrize("b", [1, 5, 300, 2000])  # runs under 8, under 128 and over 128 rays per pixel
def test_accumulate_is_bit_identical_to_the_reference(mono, b):
    rng = np.random.default_rng(b + mono)
    rays = _rays(rng, b, mono, per_pixel=3 if b == 2000 else None)  # 2000 rays on 3 pixels: recursion
    contrib = _contrib(rng, b, mono)
    ref, ker = _both(lambda out: out.accumulate(rays, contrib))
    np.testing.assert_array_equal(ker.film.view(np.uint32), ref.film.view(np.uint32))


def test_accumulate_float64_contributions_and_views():
    rng = np.random.default_rng(3)
    rays = _rays(rng, 400, False)
    c64 = _contrib(rng, 400, False, np.float64)
    bg = np.broadcast_to(rng.random(N).astype(np.float32), (400, N))  # a read-only stride-0 view
    for contrib in (c64, bg, c64[:, ::-1].astype(np.float32)[:, ::-1]):
        ref, ker = _both(lambda out: out.accumulate(rays, contrib))
        np.testing.assert_array_equal(ker.film, ref.film)


def test_accumulate_matches_a_brute_force_sum():
    rng = np.random.default_rng(5)
    rays = _rays(rng, 3000, False)
    contrib = _contrib(rng, 3000, False)
    out = TileOutput(P, N)
    with jit.kernel_mode("auto"):
        out.accumulate(rays, contrib)
    expect = np.zeros((P, N))
    for i in range(3000):
        expect[rays.pix[i]] += contrib[i].astype(np.float64)
    # float32 sums of at most ~3000 / 37 = 80 positive rows (pairwise): relative error < 80 * 2^-24 ~ 5e-6
    np.testing.assert_allclose(out.film.reshape(P, N), expect, rtol=1e-5, atol=0)


@pytest.mark.parametrize("mono", [False, True])
@pytest.mark.parametrize("nd_max", [0, 1, 3])
def test_add_by_vertices_is_bit_identical_and_allocates_the_same_parts(mono, nd_max):
    rng = np.random.default_rng(10 * nd_max + mono)
    rays = _rays(rng, 700, mono, nd_max=nd_max)
    contrib = _contrib(rng, 700, mono)
    ref, ker = _both(lambda out: out.add_by_vertices(rays, contrib))
    assert list(ker.parts) == list(ref.parts)
    np.testing.assert_array_equal(ker.film.view(np.uint32), ref.film.view(np.uint32))
    for k in ref.parts:
        np.testing.assert_array_equal(ker.parts[k].view(np.uint32), ref.parts[k].view(np.uint32))
    rk, rr = ker.result(0), ref.result(0)
    np.testing.assert_array_equal(rk.film, rr.film)


def test_parts_follow_the_vertex_counts():
    rng = np.random.default_rng(2)
    rays = _rays(rng, 50, False)
    rays.state.nd[:] = 0
    rays.state.nd[::2] = 5  # 5 diffuse vertices: indirect
    contrib = _contrib(rng, 50, False)
    out = TileOutput(P, N)
    with jit.kernel_mode("auto"):
        out.add_by_vertices(rays, contrib)
    assert set(out.parts) == {"background", "indirect"}
    assert not out.film.any()
    expect = np.zeros((P, N))
    np.add.at(expect, rays.pix[::2], contrib[::2].astype(np.float64))
    np.testing.assert_allclose(out.parts["indirect"].reshape(P, N), expect, rtol=1e-5)


@pytest.mark.parametrize("mono", [False, True])
def test_an_index_out_of_range_raises_as_the_reference_does(mono):
    rng = np.random.default_rng(4)
    rays = _rays(rng, 20, mono)
    rays.pix[7] = P  # one past the tile
    contrib = _contrib(rng, 20, mono)
    for mode in ("numpy", "auto"):
        out = TileOutput(P, N)
        with jit.kernel_mode(mode), pytest.raises(IndexError):
            out.accumulate(rays, contrib)
        if mode == "auto":
            assert not out.film.any()  # the kernel wrote nothing before the reference raised


@pytest.mark.parametrize("kind", ["unit", "white", "mono"])
def test_denoising_features_are_bit_identical_to_the_reference(kind):
    from opal_diffraction.core.transport.walker import Hit

    rng = np.random.default_rng(12)
    b = 500
    rays = _rays(rng, b, kind == "mono")
    if kind == "white":
        rays.w = rng.random((b, N)).astype(np.float32)
    elif kind == "unit":
        rays.w = None
    ns = rng.normal(size=(b, 3)).astype(np.float32)
    mat = rng.integers(0, 4, b)
    hit = SimpleNamespace(mat=mat, ns=ns)
    albedo_rgb = rng.random((4, 3)).astype(np.float32)
    ref, ker = _both(lambda out: out.denoising_features(rays, hit, albedo_rgb))
    for a, r in ((ker.albedo, ref.albedo), (ker.normal, ref.normal)):
        np.testing.assert_array_equal(a.view(np.uint32), r.view(np.uint32))
    assert ker.albedo.any() and ker.normal.any()
    assert Hit  # the real Hit has these fields
    assert {"mat", "ns"} <= set(Hit.__dataclass_fields__)
