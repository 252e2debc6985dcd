"""core/lights/sources.py's kernels against its NumPy lines: the point-light kernel
(``_point_kernel``, sample_light's float32 steps), the hit test of the sized lights
(``_hit_kernel``: intersect_lights and lights_met) and their pdfs (``_pdf_kernel``: light_pdf),
the same operations in the same order, so the same bits. Rays from random points towards every
light (most meet one, some from behind an area light or from inside a sphere), random rays,
finite tmax, and lights in front of each other."""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.lights import sources
from opal_diffraction.core.scene.model import Lights
from opal_diffraction.core.spectral.spectrum import SpectralConverter
from opal_diffraction.core.util import jit
from opal_diffraction.core.util.jit import AVAILABLE

pytestmark = pytest.mark.skipif(not AVAILABLE, reason="numba is not available")


def _sample(pl, p, on, monkeypatch):
    with monkeypatch.context() as m:
        m.setattr(sources, "kernels_enabled", lambda: on)
        return sources.sample_light_pdf(pl, 0, p, np.random.default_rng(1))


def test_the_point_light_kernel_is_sample_lights_numpy_lines(monkeypatch):
    pl = sources.prepare_lights(Lights.from_list([{"kind": "POINT", "position": (0.3, -1.2, 2.5), "power": 50.0}]),
                                SpectralConverter())
    rng = np.random.default_rng(2)
    p = (rng.random((5000, 3)) * 6 - 3).astype(np.float32)
    p[0] = pl.position[0].astype(np.float32)  # at the light: d^2 clamped to 1e-30
    got = _sample(pl, p, True, monkeypatch)
    ref = _sample(pl, p, False, monkeypatch)
    assert got[3] is None and ref[3] is None  # a delta light: no pdf
    for a, b in zip(got[:3], ref[:3]):
        assert a.dtype == b.dtype == np.float32
        np.testing.assert_array_equal(a, b)


SIZED = [
    {"kind": "AREA_RECT", "position": (0.2, -0.3, 2.0), "direction": (0.1, 0.2, -1.0), "power": 100.0,
     "size_u": 1.2, "size_v": 0.7, "axis_u": (1, 0.3, 0)},
    {"kind": "AREA_DISK", "position": (-1.2, 0.3, 1.5), "direction": (0.5, 0.0, -1.0), "power": 100.0,
     "size_u": 0.8, "size_v": 0.5, "axis_u": (0, 1, 0)},
    {"kind": "POINT", "position": (1.0, 1.0, 1.0), "power": 50.0, "radius": 0.3},
    {"kind": "POINT", "position": (-1.0, 1.0, 1.2), "power": 50.0, "radius": 0.25, "soft_falloff": 1},
    {"kind": "SPOT", "position": (0.0, 1.5, 1.6), "direction": (0, -0.3, -1), "power": 50.0, "radius": 0.2,
     "spot_size": 1.0, "spot_blend": 0.3},
    {"kind": "SPOT", "position": (0.5, -1.5, 1.6), "direction": (0, 0.3, -1), "power": 50.0, "radius": 0.2,
     "spot_size": 1.2, "spot_blend": 0.2, "soft_falloff": 1},
    {"kind": "POINT", "position": (0.0, 0.0, 3.0), "power": 10.0},          # a delta light: never met
    {"kind": "SUN", "direction": (0, 0, -1), "power": 2.0, "angle": 0.1},   # at infinity: never met
    {"kind": "AREA_RECT", "position": (0.2, -0.3, 2.6), "direction": (0.0, 0.0, -1.0), "power": 80.0,
     "size_u": 2.0, "size_v": 2.0, "axis_u": (0, 1, 0)},                  # behind the first rectangle
]


def _sized(n=len(SIZED)):
    return sources.prepare_lights(Lights.from_list(SIZED[:n]), SpectralConverter())


def _rays(pl, seed, n=3000):
    """Points around the lights (some inside the spheres), directions sampled towards each light
    and uniformly random ones, and tmax inf or random."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(-2.5, 2.5, (n, 3)).astype(np.float32)
    p[:20] = (pl.position[2] + rng.uniform(-0.1, 0.1, (20, 3))).astype(np.float32)  # inside the sphere light
    o, d = [], []
    for li in range(len(pl)):
        if not sources.is_delta(pl, li):
            wi = sources.sample_light(pl, li, p, np.random.default_rng(seed + li))[0]
            o.append(p)
            d.append(np.asarray(wi, np.float32))
    r = rng.normal(size=(n, 3))
    o.append(p)
    d.append((r / np.linalg.norm(r, axis=1, keepdims=True)).astype(np.float32))
    o, d = np.concatenate(o), np.concatenate(d)
    tmax = np.where(rng.random(len(o)) < 0.6, np.inf, rng.uniform(0, 4, len(o))).astype(np.float32)
    return o, d, tmax


def _both(f):
    with jit.kernel_mode("numpy"):
        ref = f()
    return f(), ref


@pytest.mark.parametrize("seed", [1, 2])
def test_the_hit_kernel_is_intersect_lights_numpy_lines(seed):
    pl = _sized()
    o, d, tmax = _rays(pl, seed)
    got, ref = _both(lambda: sources.intersect_lights(pl, o, d, tmax))
    for a, b in zip(got, ref):
        assert a.dtype == b.dtype
        np.testing.assert_array_equal(a, b)
    met = np.bincount(ref[0] + 1, minlength=len(pl) + 1)
    assert (met[1:7] > 20).all() and met[9] > 20, met  # every sized light, the far rectangle too
    assert met[7] == met[8] == 0  # the delta point and the sun
    assert np.all(ref[2] >= 0) and np.isfinite(ref[2]).all() and (ref[2][ref[0] >= 0] > 0).mean() > 0.5
    got, ref = _both(lambda: sources.intersect_lights(pl, o.astype(np.float64), d.astype(np.float64), 2.5))
    for a, b in zip(got, ref):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("li", range(len(SIZED)))
def test_the_pdf_kernel_is_light_pdfs_numpy_lines(li):
    pl = _sized()
    o, d, _ = _rays(pl, 3 + li)
    got, ref = _both(lambda: sources.light_pdf(pl, li, o, d))
    assert got.dtype == ref.dtype == np.float32
    np.testing.assert_array_equal(got, ref)
    if not sources.is_delta(pl, li):
        assert (ref > 0).mean() > 0.05 and (ref == 0).any()


@pytest.mark.parametrize("seed", [4, 5])
def test_lights_met_kernels_are_its_numpy_lines(seed):
    """lights_met (emission.lights_passed's call): the rays seen that meet a light, the light,
    its scale and its light_pdf along the ray."""
    pl = _sized()
    o, d, tmax = _rays(pl, seed)
    seen = np.random.default_rng(seed).random(len(o)) < 0.7
    got, ref = _both(lambda: sources.lights_met(pl, o, d, tmax, seen))
    for a, b in zip(got, ref):
        assert a.dtype == b.dtype
        np.testing.assert_array_equal(a, b)
    rows, idx, scale, pdf = ref
    assert len(rows) > 1000 and seen[rows].all()
    assert np.all(pdf > 0)  # a light met along a ray is a light that ray's direction can be drawn towards
    for li in np.unique(idx):
        sel = idx == li
        np.testing.assert_array_equal(pdf[sel], sources.light_pdf(pl, int(li), o[rows[sel]], d[rows[sel]]))
    got = sources.lights_met(pl, o, d, tmax, np.zeros(len(o), bool))
    assert all(len(x) == 0 for x in got)


@pytest.mark.parametrize("seed", [6, 7])
def test_the_disk_light_kernel_is_sample_lights_numpy_lines(seed):
    """A disk light (and a tilted, elliptic one) sampled from points around it, behind it and on it."""
    pl = _sized(2)
    rng = np.random.default_rng(seed)
    p = rng.uniform(-2.5, 2.5, (4000, 3)).astype(np.float32)
    p[:50] = (pl.position[1] + rng.uniform(-0.3, 0.3, (50, 1)) * pl.axis_u[1]).astype(np.float32)  # on its plane
    for li in (0, 1) if seed == 6 else (1,):
        if int(pl.kind[li]) != sources.AREA_DISK:
            continue
        got, ref = _both(lambda: sources.sample_light_pdf(pl, li, p, np.random.default_rng(seed)))
        for a, b in zip(got, ref):
            assert a.dtype == b.dtype == np.float32
            np.testing.assert_array_equal(a, b)
        assert (ref[2] > 0).mean() > 0.2 and (ref[2] == 0).mean() > 0.05  # in front and behind


@pytest.mark.parametrize("li", [2, 4])
def test_the_sphere_light_kernel_is_sample_lights_numpy_lines(li):
    """A sphere light (point, and spot with its cone mask) from points around it and inside it."""
    pl = _sized(5)
    rng = np.random.default_rng(li)
    p = rng.uniform(-2.5, 2.5, (4000, 3)).astype(np.float32)
    p[:40] = (pl.position[li] + rng.uniform(-0.1, 0.1, (40, 3))).astype(np.float32)  # inside the sphere
    for rows in (p, p[40:]):  # with and without points inside
        got, ref = _both(lambda: sources.sample_light_pdf(pl, li, rows, np.random.default_rng(li)))
        for a, b in zip(got, ref):
            assert a.dtype == b.dtype == np.float32
            np.testing.assert_array_equal(a, b)
        assert np.isfinite(ref[2]).all() and (ref[2] >= 0).all() and (ref[2] > 0).mean() > 0.2
