"""The light pass's aiming kernels (core/lights/aiming.py, core/util/jit.py) against their NumPy references.

The kernels draw nothing themselves: the callers draw the reference's random numbers in its
order, so the same seed gives the same paths. The formulas are the reference's in its order,
but where the reference sums three products by BLAS (``@``) or einsum (whose summation order
and use of FMA are the library's) a kernel sums them left to right, so results agree to a few
units in the last place of the quantities' magnitude (rtol 1e-12 on directions and pdfs; points
on a disk also get an absolute 1e-14 x the scene's size where a coordinate cancels to ~0); the
random stream after the call is the same (bit for bit), which the light pass's per-batch
streams rely on.
"""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.lights.aiming import (CasterObjects, caster_cones, caster_disk_points, sample_cones,
                                                 sample_towards_casters)
from opal_diffraction.core.util import jit

pytestmark = pytest.mark.skipif(not jit.AVAILABLE, reason=f"no JIT: {jit.UNAVAILABLE_REASON}")

B = 5000


def objects(c, seed=0):
    rng = np.random.default_rng(seed)
    centre = rng.normal(size=(c, 3))
    centre[0] = [0.3, -2.0, 1.0]  # one sphere holding the shared origin below: its cone is the whole sphere
    return CasterObjects(centre, rng.uniform(0.2, 0.8, c))


def unit(rng, b):
    d = rng.normal(size=(b, 3))
    d[:4] = [[1, 0, 0], [0, 1, 0], [0.9, 0.1, 0], [0.89999, 0.3, 0.1]]  # the frame's switch from X to Y
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def both(fn):
    """(kernel results, reference results) of fn(rng) with the same seed, and the stream's next draws."""
    def run():
        rng = np.random.default_rng(7)
        return tuple(fn(rng)) + (rng.random(4),)

    assert jit.kernels_enabled()
    got = run()
    with jit.kernel_mode("numpy"):
        want = run()
    return got, want


def close(got, want, atol=0.0):
    for g, w in zip(got[:-1], want[:-1]):
        assert g.shape == w.shape and g.dtype == w.dtype
        np.testing.assert_allclose(g, w, rtol=1e-12, atol=atol)
    assert np.array_equal(got[-1], want[-1])  # the stream is left where the reference leaves it


@pytest.mark.parametrize("c", [1, 2, 7, 12])
def test_cones_from_one_origin(c):
    obj = objects(c)
    origin = np.broadcast_to(np.array([0.5, -2.5, 1.5]), (B, 3))

    def sample(rng):
        axis, cos_max, omega = (np.broadcast_to(x, (B,) + x.shape[1:]) for x in caster_cones(origin[:1], obj))
        return sample_cones(origin, omega, axis, cos_max, omega, rng)

    got, want = both(sample)
    close(got, want)
    d, pdf = got[0], got[1]
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, rtol=1e-12)
    assert np.all(pdf > 0)


@pytest.mark.parametrize("c", [1, 3, 12])
def test_cones_from_per_path_origins(c):
    obj = objects(c)

    def sample(rng):
        origin = np.random.default_rng(3).normal(size=(B, 3)) * 2
        origin[0] = obj.centre[0]  # inside a sphere
        return sample_towards_casters(origin, obj, rng)

    got, want = both(sample)
    close(got, want)


@pytest.mark.parametrize("c", [1, 5, 40])
def test_cones_per_path_given(c):
    """sample_cones with per-path cones and weights other than the solid angles."""
    obj = objects(c)

    def sample(rng):
        origin = np.random.default_rng(6).normal(size=(B, 3)) * 2
        axis, cos_max, omega = caster_cones(origin, obj)
        weights = omega * np.random.default_rng(8).random(omega.shape)
        return sample_cones(origin, weights, axis, cos_max, omega, rng)

    got, want = both(sample)
    close(got, want)


@pytest.mark.parametrize("c", [1, 2, 12])
def test_disk_points(c):
    obj = objects(c)
    got, want = both(lambda rng: caster_disk_points(obj, unit(np.random.default_rng(4), B), rng))
    close(got, want, atol=1e-14 * float(np.abs(obj.centre).max() + obj.radius.max()))
    assert np.all(got[1] > 0)


def test_empty_batches():
    obj = objects(3)
    got, want = both(lambda rng: caster_disk_points(obj, np.zeros((0, 3)), rng) +
                     sample_towards_casters(np.zeros((0, 3)), obj, rng))
    close(got, want)


def test_mesh_emission_agrees_with_the_reference():
    """emit_mesh on the kernels (the aiming kernels and the spectral weights' fused product) from a
    glowing panel of two colours towards a glass box: the weights are the reference's products of a scalar that agrees as
    the aiming kernels do (its pdf), and so do the origins and directions."""
    from opal_diffraction.core.lights.emission import emit_mesh
    from opal_diffraction.core.render.prepare import prepare
    from opal_diffraction.core.scene import primitives
    from opal_diffraction.core.scene.model import Camera, Materials, Scene
    from opal_diffraction.core.scene.settings import RenderSettings

    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
                                {"kind": "DIELECTRIC", "ior": 1.5, "color": (1, 1, 1)},
                                {"kind": "DIFFUSE", "color": (0, 0, 0), "emission": (3.0, 2.0, 1.0)},
                                {"kind": "DIFFUSE", "color": (0, 0, 0), "emission": (0.5, 1.0, 4.0)}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (4, 0, 0), (0, 4, 0)), material=0)
    s.add_mesh(*primitives.box((0, 0, 0.6), (0.6, 0.6, 0.3)), material=1)
    s.add_mesh(*primitives.quad((-0.3, 0, 2.0), (0.6, 0, 0), (0, 0.8, 0)), material=2)
    s.add_mesh(*primitives.quad((0.3, 0, 2.0), (0.6, 0, 0), (0, 0.8, 0)), material=3)
    s.camera = Camera.look_at((0, -3, 3), (0, 0, 0), width=16, height=16)
    ctx = prepare(s, RenderSettings(wavelength_step=20.0, light_paths=1000))
    got, want = both(lambda rng: emit_mesh(ctx, B, rng))
    close(got[:2] + (got[-1],), want[:2] + (want[-1],), atol=1e-14)
    assert got[2].dtype == want[2].dtype == np.float64
    np.testing.assert_allclose(got[2], want[2], rtol=1e-12)  # the scalar's pdf: the aiming kernels' ulps
    assert (want[2] > 0).any() and len(np.unique(want[2][:, 0] > want[2][:, -1])) == 2  # both colours
