"""Glass paths in the eye pass (docs/physics.md section 4.10): the stratified reflect / refract
choice, both branches of a smooth dielectric written as a d + b n, shading normals interpolated
only on smooth triangles, and emission of unit-weight paths added per pixel and material.

Each is checked against an independent computation: the choice's numbers against the 2-D
Sobol-Burley sampler's and against the stratification a (0,2)-sequence guarantees; directions
against Snell's law and the law of reflection in float64 about the Phong-interpolated normal;
normals against geometry.interpolate_corners; film adds against a per-ray np.add.at.
"""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.integrators.eye.factored_film import add_scaled_spectra
from opal_diffraction.core.util.geometry import interpolate_corners
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.sampling.sampler import SLOT_BOUNCE, PixelSampler, sobol_owen_2d, vertex_pair
from opal_diffraction.core.scene.model import Camera, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.sampling.sampler import sobol_owen_x
from opal_diffraction.core.sampling.specular_numbers import bounce_choice
from opal_diffraction.core.transport.walker import Rays, SpecularWalker, hit_shading_normals, smooth_triangles


# ============================================================================ the choice's numbers
@pytest.mark.parametrize("seed", [0, 7, 2**40 + 5])
def test_sobol_owen_x_is_the_2d_samplers_first_coordinate(seed):
    rng = np.random.default_rng(seed % 1000)
    b = 5000
    pixel = rng.integers(0, 1 << 20, b).astype(np.uint32)
    sample = rng.integers(0, 1 << 16, b)
    pair = rng.integers(0, 200, b)
    x, _ = sobol_owen_2d(pixel, sample, pair, seed)
    got = sobol_owen_x(pixel, sample, pair, seed)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got.astype(np.float64), x)


def test_bounce_choice_is_the_vertex_samplers_bounce_number():
    """The same number PixelSampler gives the vertex's SLOT_BOUNCE decision (eye_pass._TileTrace.numbers)."""
    rng = np.random.default_rng(2)
    b = 3000
    extra = {"pid": rng.integers(0, 4096, b).astype(np.uint32), "sid": rng.integers(0, 256, b).astype(np.uint32)}
    depth = rng.integers(0, 12, b)
    ps = PixelSampler(rng, extra["pid"], extra["sid"], vertex_pair(depth, SLOT_BOUNCE), 11)
    np.testing.assert_array_equal(bounce_choice(extra["pid"], extra["sid"], depth, 11, rng).astype(np.float64),
                                  ps.random(b))


def test_the_fresnel_choice_is_stratified_over_a_pixels_samples():
    """The first 2^k samples of a pixel put one number in each interval [j / 2^k, (j + 1) / 2^k)
    (a (0,2)-sequence's x, Owen-scrambled and shuffled within the power-of-two prefix: Burley
    2020), so of N = 64 samples exactly floor(N F) or floor(N F) + 1 reflect at a Fresnel factor
    F, at every bounce depth: the count's variance is below 1/4, against N F (1 - F) for
    independent numbers (what the tile's stream gave before)."""
    n_pix, n = 300, 64
    rng = np.random.default_rng(4)
    fr = rng.uniform(0.02, 0.98, n_pix)
    pid = np.repeat(np.arange(n_pix, dtype=np.uint32) * 37 + 5, n)
    sid = np.tile(np.arange(n, dtype=np.uint32), n_pix)
    for depth in (0, 1, 5):
        u = bounce_choice(pid, sid, np.full(n_pix * n, depth), 123, rng)
        counts = (u.reshape(n_pix, n) < fr[:, None]).sum(axis=1)
        lo = np.floor(n * fr)
        assert np.all((counts == lo) | (counts == lo + 1)), depth
    # the same check fails for independent numbers (so it can fail)
    u = rng.random((n_pix, n))
    counts = (u < fr[:, None]).sum(axis=1)
    assert not np.all((counts == np.floor(n * fr)) | (counts == np.floor(n * fr) + 1))


# ============================================================================ the smooth dielectric
def tilted_glass(ior=1.5):
    """A glass triangle in z = 0 whose corner normals lean 20 deg towards -x, +x and +y."""
    s = Scene(materials=Materials.from_list([{"kind": "DIELECTRIC", "ior": ior}]))
    s.camera = Camera(width=4, height=4)
    v = np.array([[-1, -1, 0], [1, -1, 0], [0, 1, 0]], np.float64)
    a = np.radians(20)
    nrm = np.array([[-np.sin(a), 0, np.cos(a)], [np.sin(a), 0, np.cos(a)], [0, np.sin(a), np.cos(a)]])
    s.add_mesh(v, [[0, 1, 2]], 0, normals=nrm)
    return s, v, nrm


@pytest.mark.parametrize("downwards", [True, False])
def test_smooth_glass_refracts_by_snell_and_reflects_about_the_interpolated_normal(downwards):
    ior = 1.5
    s, v, nrm = tilted_glass(ior)
    prepared = prepare(s, RenderSettings())
    walker = SpecularWalker(prepared, np.random.default_rng(1))
    rng = np.random.default_rng(0)
    b = 400
    w = rng.dirichlet((2, 2, 2), b)
    p = w @ v
    d = np.stack([rng.normal(0, 0.15, b), rng.normal(0, 0.15, b), -np.ones(b)], 1)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    if not downwards:  # from inside the glass (below the triangle): eta = ior, TIR possible
        d = -d
    rays = Rays((p - 3 * d).astype(np.float32), d.astype(np.float32), np.arange(b), None, None,
                np.zeros(b, np.int32), np.zeros(b))
    h = prepared.accel.intersect(rays.o, rays.d)
    assert np.all(h.prim >= 0)
    hit = walker.hit_info(rays, h.t, h.prim, h.u, h.v)
    # the expected directions in float64 about the Phong normal, facing the incoming ray
    n = w @ nrm
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(np.sum(n * d, axis=1, keepdims=True) > 0, -n, n)
    eta = 1 / ior if downwards else ior
    cos_i = -np.sum(d * n, axis=1)
    sin2_t = eta ** 2 * (1 - cos_i ** 2)
    reflected = d + 2 * cos_i[:, None] * n
    ok = reflected[:, 2] * (1 if not downwards else -1) < -0.05  # no specular fix-up needed
    ok &= sin2_t < 0.98
    assert ok.mean() > 0.5
    refracted = eta * d + (eta * cos_i - np.sqrt(np.maximum(0, 1 - sin2_t)))[:, None] * n
    for u, expected, crossed in ((np.zeros(b), reflected, False), (np.ones(b), refracted, True)):
        out, transmitted = walker.dielectric_bounce(rays, hit, walker.rng, u.astype(np.float32))
        np.testing.assert_allclose(out.d[ok], expected[ok], atol=3e-5)
        assert np.all(transmitted[ok] == crossed)
        # offset to the side the ray leaves on
        side = np.sign(np.sum(out.d * hit.ng, axis=1))
        assert np.all(np.sign(np.sum((out.o - hit.p) * hit.ng, axis=1)) == side)


# ============================================================================ shading normals
def test_hit_shading_normals_interpolate_smooth_triangles_and_take_the_corner_on_flat_ones():
    rng = np.random.default_rng(6)
    t = 50
    cn = rng.normal(size=(t, 3, 3)).astype(np.float32)
    flat = rng.random(t) < 0.5
    cn[flat] = cn[flat, :1]  # one normal for all three corners
    cn[3] = cn[3, 0]  # (flat too)
    flat[3] = True
    cn /= np.linalg.norm(cn, axis=2, keepdims=True)  # unit, as the scene's validation leaves them
    ng_tri = rng.normal(size=(t, 3)).astype(np.float32)
    ng_tri /= np.linalg.norm(ng_tri, axis=1, keepdims=True)
    np.testing.assert_array_equal(smooth_triangles(cn), ~flat)
    b = 4000
    prim = rng.integers(0, t, b)
    bu = (rng.random(b) * 0.5).astype(np.float32)
    bv = (rng.random(b) * 0.5).astype(np.float32)
    ng = ng_tri[prim]
    got = hit_shading_normals(cn, smooth_triangles(cn), prim, bu, bv, ng)
    ref = interpolate_corners(cn.astype(np.float64), prim, bu, bv)
    ref /= np.linalg.norm(ref, axis=1, keepdims=True)
    ref = np.where(np.sum(ref * ng, axis=1, keepdims=True) < 0, -ref, ref)
    assert got.dtype == np.float32
    np.testing.assert_allclose(got, ref, atol=2e-6)
    assert np.all(np.sum(got * ng, axis=1) >= 0)


# ============================================================================ the film
def test_add_scaled_spectra_is_the_per_ray_sum():
    rng = np.random.default_rng(8)
    p, n, k, b = 64, 31, 5, 4000
    table = rng.random((k, n)).astype(np.float32)
    pix = rng.integers(0, p, b)
    key = rng.choice([1, 3, 4], b)
    scale = rng.random(b).astype(np.float32)
    for s in (scale, 1.0):
        film = rng.random(p * n).astype(np.float32)
        expected = film.astype(np.float64).reshape(p, n).copy()
        np.add.at(expected, pix, np.broadcast_to(s, (b,))[:, None] * table[key].astype(np.float64))
        assert add_scaled_spectra(film, p, pix, key, s, table)
        np.testing.assert_allclose(film.reshape(p, n), expected, rtol=2e-6)
    # too many (pixel, key) combinations for the batch: nothing added, False
    film = np.zeros(p * n, np.float32)
    assert not add_scaled_spectra(film, p, pix[:100], key[:100], 1.0, table)
    assert not film.any()


def test_a_glass_ball_before_emitters_renders_the_same_with_and_without_the_factored_emission():
    """The regrouped film add is the same sum: one render with the factored emission and one
    with it switched off (the per-ray spectra), same seed, agree to float rounding."""
    from opal_diffraction.core.integrators.eye import emission
    from opal_diffraction.core.render.frame import render

    s = Scene(materials=Materials.from_list([
        {"kind": "DIELECTRIC", "ior": 1.45},
        {"kind": "DIFFUSE", "color": (0, 0, 0), "emission": (3.0, 2.7, 2.1)},
        {"kind": "DIFFUSE", "color": (0, 0, 0), "emission": (0.1, 0.3, 0.6)}]))
    s.camera = Camera.look_at((0, -3, 0), (0, 0, 0), width=24, height=24)
    v, t = primitives.uv_sphere((0, 0, 0), 0.8, 24, 12)
    s.add_mesh(v, t, 0, normals=v / 0.8)
    s.add_mesh(*primitives.quad((0, 2, -1.5), (6, 0, 0), (0, 0, 3)), 1)  # two emitters behind the ball
    s.add_mesh(*primitives.quad((0, 2, 1.5), (6, 0, 0), (0, 0, 3)), 2)
    settings = RenderSettings(samples=8, seed=3)
    orig = emission.surface_emission_unit
    used = []
    try:
        emission.surface_emission_unit = lambda *args: used.append(orig(*args)) or used[-1]
        a = render(s, settings)
        emission.surface_emission_unit = lambda *args: False
        b = render(s, settings)
    finally:
        emission.surface_emission_unit = orig
    ia, ib = a.rgb, b.rgb
    assert any(used)  # the factored add ran
    assert ia.max() > 0.5
    np.testing.assert_allclose(ia, ib, rtol=1e-5, atol=1e-6)
