"""The illumination map's landing deposit (elements.IlluminationMap.deposit_hits) on the kernels
against its NumPy reference (ElementLayout.index, then deposit).

The kernels index with ``element_of`` (the reference's float64 steps) and sum each (element,
wavelength)'s mono flux in float64 in the landings' order, which is np.bincount's order: the
same bits. White and coefficient deposits share the reference's ``deposit`` after the index.
"""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.transport.elements import ElementLayout, IlluminationMap
from opal_diffraction.core.util import jit

pytestmark = pytest.mark.skipif(not jit.AVAILABLE, reason=f"no JIT: {jit.UNAVAILABLE_REASON}")


def layout(rng, triangles=40):
    area = rng.uniform(0.05, 2.0, triangles)
    mask = rng.random(triangles) < 0.7  # some triangles receive nothing: hits there are off the map
    mask[:2] = True, False
    return ElementLayout.from_areas(area, mask, 0.01)


def hits(rng, lay, b):
    """Hits on any triangle, barycentrics inside and on the edges and corners of the triangle."""
    prim = rng.integers(0, len(lay.k), b)
    bu = rng.random(b).astype(np.float32)
    bv = (rng.random(b) * (1 - bu)).astype(np.float32)
    e = min(b, 6)
    bu[:e] = [0.0, 1.0, 0.0, 0.5, 1.0, 0.25][:e]
    bv[:e] = [0.0, 0.0, 1.0, 0.5, 1e-8, 0.75][:e]
    prim[:e] = 0
    front = rng.random(b) < 0.5
    return prim.astype(np.int32), bu, bv, front


def deposit_both(lay, n, args, kw):
    """(kernel map, reference map, kernel count, reference count) after the same deposits."""
    a, b = IlluminationMap.empty(lay, n), IlluminationMap.empty(lay, n)
    assert jit.kernels_enabled()
    ca = [a.deposit_hits(*x, **kw_) for x, kw_ in zip(args, kw)]
    with jit.kernel_mode("numpy"):
        cb = [b.deposit_hits(*x, **kw_) for x, kw_ in zip(args, kw)]
    return a.flux, b.flux, ca, cb


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("b", [1, 7, 3000])
def test_mono_deposit_is_the_reference_bit_for_bit(seed, b):
    """Several deposits into one map, many landings on the same (element, wavelength): the
    order of the float64 sums and of the float32 adds matters, and must be the reference's."""
    rng = np.random.default_rng(seed)
    lay, n = layout(rng), 16
    args, kw = [], []
    for _ in range(3):
        prim, bu, bv, front = hits(rng, lay, b)
        prim[b // 2:] = prim[0]  # crowd half the landings onto few elements
        w = rng.exponential(1.0, b).astype(np.float32) * np.float32(1e-3)
        if b >= 3:
            w[:3] = [0.0, 1e-30, 7.0]
        lam = rng.integers(0, n, b).astype(np.int64)
        args.append((prim, bu, bv, front, w, lam))
        kw.append({})
    fa, fb, ca, cb = deposit_both(lay, n, args, kw)
    assert ca == cb and sum(ca) > 0
    assert np.array_equal(fa.view(np.uint32), fb.view(np.uint32))
    assert fb.max() > 0


@pytest.mark.parametrize("k", [None, 1, 3])
def test_white_and_coefficient_deposits_are_the_reference_bit_for_bit(k):
    rng = np.random.default_rng(7)
    lay, n = layout(rng), 12
    args, kw = [], []
    for b in (500, 1, 40):
        prim, bu, bv, front = hits(rng, lay, b)
        flux = rng.random((b, n if k is None else k)).astype(np.float32)
        args.append((prim, bu, bv, front, flux))
        kw.append({} if k is None else {"basis": rng.random((k, n)).astype(np.float32)})
    fa, fb, ca, cb = deposit_both(lay, n, args, kw)
    assert ca == cb and sum(ca) > 0
    assert np.array_equal(fa.view(np.uint32), fb.view(np.uint32))


def test_hits_all_off_the_map_and_no_hits():
    rng = np.random.default_rng(3)
    lay = layout(rng)
    off = np.flatnonzero(lay.k == 0)[:1]
    prim = np.repeat(off, 5).astype(np.int32)
    bu = np.full(5, 0.2, np.float32)
    for lam in (np.arange(5), None):
        m = IlluminationMap.empty(lay, 8)
        flux = np.ones(5, np.float32) if lam is not None else np.ones((5, 8), np.float32)
        assert m.deposit_hits(prim, bu, bu, np.ones(5, bool), flux, lam) == 0
        assert m.deposit_hits(prim[:0], bu[:0], bu[:0], np.ones(0, bool), flux[:0], None if lam is None else lam[:0]) == 0
        assert not m.flux.any()
