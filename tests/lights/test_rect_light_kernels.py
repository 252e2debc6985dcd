"""core/lights/rect_light.py's kernels (``_args_kernel``, ``_sample_kernel``,
``_solid_angle_kernel``) against its NumPy lines: the same float64 operations in the same order,
the arccos by NumPy in both, so the same bits (samples, distances, g, pdfs and solid angles), on
random shading points around rotated rectangles, points in the light's plane and behind it, very
far ones whose solid angle is below MIN_SOLID_ANGLE (the area fallback) and one at a corner."""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.lights import rect_light, sources
from opal_diffraction.core.scene.model import Lights
from opal_diffraction.core.spectral.spectrum import SpectralConverter
from opal_diffraction.core.util import jit

pytestmark = pytest.mark.skipif(not jit.AVAILABLE, reason="numba is not available")


def _lights(seed):
    """A rectangle light of random position, orientation and sides."""
    rng = np.random.default_rng(seed)
    n = rng.normal(size=3)
    return sources.prepare_lights(Lights.from_list([{
        "kind": "AREA_RECT", "position": tuple(rng.uniform(-1, 1, 3)), "direction": tuple(n / np.linalg.norm(n)),
        "power": 100.0, "size_u": float(rng.uniform(0.05, 2.0)), "size_v": float(rng.uniform(0.05, 2.0)),
        "axis_u": tuple(rng.normal(size=3))}]), SpectralConverter())


def _points(pl, rng, n=4000):
    """Shading points: around the light, in its plane, behind it, very far (tiny solid angles),
    at a corner and at the centre."""
    c, nrm = pl.position[0], pl.direction[0]
    eu, ev = pl.axis_u[0], pl.axis_v[0]
    near = c + rng.uniform(-3, 3, (n, 3))
    a, b = rng.uniform(-2, 2, (2, n // 4))
    plane = c + a[:, None] * eu + b[:, None] * ev          # z0 = 0: nothing seen
    behind = c - rng.uniform(0.1, 3, (n // 4, 1)) * nrm + rng.uniform(-1, 1, (n // 4, 3))  # the light emits along nrm
    far = c + rng.uniform(1e4, 1e6, (n // 4, 1)) * nrm + rng.uniform(-1e3, 1e3, (n // 4, 3))
    rect = rect_light._frame_of(pl, 0)
    special = np.array([rect.corner, c, c - 1e-12 * nrm])
    return np.concatenate([near, plane, behind, far, special])


def _both(f):
    with jit.kernel_mode("numpy"):
        ref = f()
    return f(), ref


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_sample_light_rect_kernel_is_the_numpy_lines(seed, dtype):
    pl = _lights(seed)
    rng = np.random.default_rng(seed + 10)
    p = _points(pl, rng).astype(dtype)
    r1, r2 = rng.random(len(p), np.float32), rng.random(len(p), np.float32)
    r1[:3], r2[:3] = 0.0, np.float32(1 - 2**-24)  # the map's ends
    rect = rect_light._frame_of(pl, 0)
    s = rect_light._setup(rect, p)[-1]
    tiny = s < rect_light.MIN_SOLID_ANGLE
    assert tiny.sum() > len(p) // 8  # the points in the plane and the far ones take the area fallback
    for with_pdf in (False, True):
        got, ref = _both(lambda: rect_light.sample_light_rect(pl, 0, p, r1, r2, with_pdf=with_pdf))
        assert len(got) == len(ref) == (4 if with_pdf else 3)
        for a, b in zip(got, ref):
            assert a.dtype == b.dtype == np.float32 and a.shape == b.shape
            np.testing.assert_array_equal(a, b)
        g = got[2]
        assert np.all(np.isfinite(g)) and np.all(g >= 0) and (g > 0).mean() > 0.2
        assert (g[tiny] > 0).sum() > len(p) // 10 and (g[~tiny] > 0).sum() > len(p) // 10  # both branches seen
        behind = ((p.astype(np.float64) - pl.position[0]) @ pl.direction[0]) < -1e-6
        assert behind.sum() > len(p) // 10 and not g[behind].any()  # behind the one-sided light


@pytest.mark.parametrize("seed", [4, 5])
def test_solid_angle_kernel_is_the_numpy_lines(seed):
    pl = _lights(seed)
    rect = rect_light._frame_of(pl, 0)
    rng = np.random.default_rng(seed)
    p = _points(pl, rng)
    got, ref = _both(lambda: rect_light.solid_angle(rect, p))
    np.testing.assert_array_equal(got, ref)
    assert ref.max() > 0.1 and (ref == 0).any()
    o = np.broadcast_to(p[0], (50, 3))  # a broadcast view, as the chi-square test passes
    got, ref = _both(lambda: rect_light.solid_angle(rect, o))
    np.testing.assert_array_equal(got, ref)


@pytest.mark.parametrize("seed", [6, 7])
def test_rect_light_pdf_kernel_is_the_numpy_lines(seed):
    """light_pdf of a rectangle (its hit test and solid angle or area pdf) for directions
    towards the light (most hit it, some from behind or below MIN_SOLID_ANGLE) and random ones."""
    pl = _lights(seed)
    rng = np.random.default_rng(seed)
    p = _points(pl, rng).astype(np.float32)
    wi, _, _ = sources.sample_light(pl, 0, p, np.random.default_rng(1))
    rand = rng.normal(size=p.shape)
    wi = np.concatenate([wi, (rand / np.linalg.norm(rand, axis=1, keepdims=True)).astype(np.float32)])
    p = np.concatenate([p, p])
    got, ref = _both(lambda: sources.light_pdf(pl, 0, p, wi))
    assert got.dtype == ref.dtype == np.float32
    np.testing.assert_array_equal(got, ref)
    assert (ref > 0).mean() > 0.2 and (ref == 0).mean() > 0.2


def test_sample_light_pdf_takes_the_kernel_with_the_same_numbers():
    """sample_light_pdf's one-pass rectangle path draws sample_light's numbers and gives its pdf."""
    pl = _lights(8)
    p = _points(pl, np.random.default_rng(8)).astype(np.float32)
    got, ref = _both(lambda: sources.sample_light_pdf(pl, 0, p, np.random.default_rng(3)))
    for a, b in zip(got, ref):
        np.testing.assert_array_equal(a, b)
    wi, dist, g = sources.sample_light(pl, 0, p, np.random.default_rng(3))
    np.testing.assert_array_equal(wi, got[0])
    np.testing.assert_array_equal(g, got[2])
