"""The specular walker's compiled kernels (core/transport/walker.py, wavelengths.py) against their
NumPy reference: the same operations in the same order and precisions, so the same bits."""

import numpy as np
import pytest

from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.transport import walker as walker_module, wavelengths
from opal_diffraction.core.transport.walker import Rays, SpecularWalker
from opal_diffraction.core.util.jit import AVAILABLE, kernel_mode

pytestmark = pytest.mark.skipif(not AVAILABLE, reason="numba is not installed")


def _glass(smooth_normals: bool, tint=(1, 1, 1), **settings):
    """A prepared scene of one dispersive glass: a prism (flat) or an icosphere with vertex normals."""
    s = Scene(materials=Materials.from_list([{"kind": "DIELECTRIC", "color": tint, "dispersion": "DIAMOND"}]))
    if smooth_normals:
        v, t = primitives.icosphere((0, 0, 0), 1.0, subdivisions=1)
        s.add_mesh(v, t, material=0, normals=v / np.linalg.norm(v, axis=1, keepdims=True))
    else:
        s.add_mesh(*primitives.prism((0, 0, 0), side=2.0, length=4.0, axis="Y"), material=0)
    s.camera = Camera()
    return prepare(s, RenderSettings(**settings))


def _hits(prepared, b=3000, seed=1, weighted=True):
    """White rays from outside and from inside the glass and their hits (both sides, TIR inside)."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(b, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.where(np.arange(b)[:, None] % 2 == 0, -4.0 * d + rng.uniform(-0.3, 0.3, (b, 3)),
                 rng.uniform(-0.2, 0.2, (b, 3)) + [0, 0, 0.3])
    o, d = o.astype(np.float32), d.astype(np.float32)
    h = prepared.accel.intersect(o, d)
    k = np.flatnonzero(h.prim >= 0)
    n = prepared.grid.n
    w = rng.uniform(0, 1, (len(k), n)).astype(np.float32) if weighted else None
    if weighted:
        w[rng.random(len(k)) < 0.2, : n // 2] = 0  # rays whose spectrum is zero somewhere
    rays = Rays(o[k], d[k], np.arange(len(k)), w, None, np.zeros(len(k), np.int32), rng.random(len(k)))
    walker = SpecularWalker(prepared, rng)
    with kernel_mode("numpy"):
        hit = walker.hit_info(rays, h.t[k], h.prim[k], h.u[k], h.v[k])
    return walker, rays, hit, rng.random(len(k))


def _split(walker, rays, hit, u, mode):
    walker._spawned = []
    with kernel_mode(mode):
        children, child_hits, white = wavelengths.split_at_glass(walker, rays, hit, None, u)
    mono = walker._spawned
    walker._spawned = []
    return white, mono


def _same_rays(a, b):
    for f in ("o", "d", "pix", "w", "lam", "depth", "u_lam"):
        x, y = getattr(a, f), getattr(b, f)
        assert (x is None) == (y is None), f
        if x is not None:
            assert x.dtype == y.dtype, f
            np.testing.assert_array_equal(x, y, err_msg=f)


@pytest.mark.parametrize("smooth", [False, True])
@pytest.mark.parametrize("weighted", [False, True])
@pytest.mark.parametrize("by_sensitivity", [False, True])
def test_glass_split_kernel_is_bit_identical(smooth, weighted, by_sensitivity):
    prepared = _glass(smooth, tint=(1, 0.8, 0.5) if weighted else (1, 1, 1), dispersion_importance=by_sensitivity)
    walker, rays, hit, u = _hits(prepared, weighted=weighted)
    assert hit.front.any() and (~hit.front).any()
    assert wavelengths._fits_glass_kernel(rays, hit, walker.specular_normal(rays, hit), walker.tinted_weight(rays, hit),
                                          prepared.materials.ior)  # the kernel runs
    w_ref, m_ref = _split(walker, rays, hit, u, "numpy")
    w_ker, m_ker = _split(walker, rays, hit, u, "auto")
    _same_rays(w_ref, w_ker)
    assert len(m_ref) == len(m_ker) == 1
    _same_rays(m_ref[0], m_ker[0])
    assert len(w_ker) > 50 and len(m_ker[0]) > 1000  # both branches taken


@pytest.mark.parametrize("n", [1, 3, 7, 8, 61, 128, 129, 200, 240, 300, 460, 700, 900])
def test_pairwise_row_sum_is_numpys(n):
    a = np.random.default_rng(n).random((4, n)) * 10.0 ** np.random.default_rng(n + 1).uniform(-8, 8, (4, n))
    for row, s in zip(a, a.sum(axis=1)):
        assert wavelengths._pairwise(row, 0, n) == s


def _same_hits(a, b):
    for f in ("p", "ng", "ns", "cos_i", "front", "mat", "eps", "prim", "bu", "bv"):
        x, y = getattr(a, f), getattr(b, f)
        assert x.dtype == y.dtype, f
        np.testing.assert_array_equal(x, y, err_msg=f)
    assert (a.ns is a.ng) == (b.ns is b.ng)


@pytest.mark.parametrize("smooth", [False, True])
def test_hit_info_kernel_is_bit_identical(smooth):
    prepared = _glass(smooth)
    walker, rays, _, _ = _hits(prepared)
    h = prepared.accel.intersect(rays.o, rays.d)
    args = (rays, h.t, h.prim, h.u, h.v)
    assert (h.prim >= 0).all() and walker_module._fits_hit_kernel(rays, h.t, prepared)  # the kernel runs
    with kernel_mode("numpy"):
        ref = walker.hit_info(*args)
    with kernel_mode("auto"):
        ker = walker.hit_info(*args)
    _same_hits(ref, ker)


@pytest.mark.parametrize("smooth", [False, True])
@pytest.mark.parametrize("mono", [False, True])
def test_dielectric_bounce_kernel_is_bit_identical(smooth, mono):
    prepared = _glass(smooth, tint=(1, 0.8, 0.5))
    walker, rays, hit, u = _hits(prepared)
    if mono:
        lam = np.random.default_rng(5).integers(0, prepared.grid.n, len(rays))
        rays = Rays(rays.o, rays.d, rays.pix, rays.w[np.arange(len(rays)), lam], lam, rays.depth, rays.u_lam)
    assert walker_module._fits_dielectric_kernel(rays, hit, walker.specular_normal(rays, hit), prepared.materials.ior)
    out = {}
    for mode in ("numpy", "auto"):
        with kernel_mode(mode):
            out[mode] = walker.dielectric_bounce(rays, hit, None, u)
    _same_rays(out["numpy"][0], out["auto"][0])
    np.testing.assert_array_equal(out["numpy"][1], out["auto"][1])
    assert 0.05 < out["auto"][1].mean() < 0.95  # both reflections and refractions


def test_shading_normal_kernel_on_mixed_flat_smooth_and_bad_normals():
    """Per-corner normals: smooth triangles, flat-shaded ones (one normal, some pointing inwards)
    and corners that interpolate to zero: hit_info's kernel gives the reference's bits."""
    v, t = primitives.icosphere((0, 0, 0), 1.0, subdivisions=2)
    vn = v / np.linalg.norm(v, axis=1, keepdims=True)
    cn = vn[t].astype(np.float64)  # (T, 3, 3)
    face = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    face /= np.linalg.norm(face, axis=1, keepdims=True)
    rng = np.random.default_rng(3)
    kind = rng.integers(0, 4, len(t))
    cn[kind == 1] = face[kind == 1, None, :]  # flat-shaded
    cn[kind == 2] = -face[kind == 2, None, :]  # flat, pointing inwards
    cn[kind == 3, 1] = -cn[kind == 3, 0]  # opposite corners: interpolates towards zero
    cn[kind == 3, 2] = cn[kind == 3, 0]
    s = Scene(materials=Materials.from_list([{"kind": "DIELECTRIC", "color": (1, 1, 1), "dispersion": "DIAMOND"}]))
    s.add_mesh(v, t, material=0, normals=cn)
    s.camera = Camera()
    prepared = prepare(s, RenderSettings())
    assert prepared.smooth_triangles.any() and not prepared.smooth_triangles.all()
    assert prepared.corner_normals.dtype == np.float32  # the kernel runs
    walker, rays, _, _ = _hits(prepared, b=20000)
    h = prepared.accel.intersect(rays.o, rays.d)
    with kernel_mode("numpy"):
        ref = walker.hit_info(rays, h.t, h.prim, h.u, h.v)
    with kernel_mode("auto"):
        ker = walker.hit_info(rays, h.t, h.prim, h.u, h.v)
    _same_hits(ref, ker)
