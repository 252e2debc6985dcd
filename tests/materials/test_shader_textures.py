"""Procedural textures (core/materials/shader_textures.py) against closed forms: Perlin noise
vanishes at lattice points, Voronoi with randomness 0 is the unit-cube lattice (F1, F2 and the
distance to the cell faces by hand), the Checker's parity, the Gradient's formulas, White Noise as
the hash of the coordinates' bits. Against Cycles: tests/blender/test_procedural_textures_cycles.py."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from opal_diffraction.core.materials import shader_hash as H
from opal_diffraction.core.materials import shader_textures as T

RNG = np.random.default_rng(11)
P = RNG.uniform(-3, 3, (500, 3)).astype(np.float32)


@pytest.mark.parametrize("d", [1, 2, 3, 4])
def test_perlin_noise_is_zero_on_the_lattice_and_bounded(d):
    ints = RNG.integers(-50, 50, (200, d)).astype(np.float32)
    assert np.all(T.perlin(ints) == 0)
    x = RNG.uniform(-20, 20, (4000, d)).astype(np.float32)
    s = T.snoise(x)
    assert s.dtype == np.float32 and np.abs(s).max() <= 1.1 and s.std() > 0.05


def test_perlin_is_continuous_across_cell_faces():
    x = np.array([[1.0, 0.3, 0.7]], np.float32)
    eps = np.float32(1e-4)
    lo, hi = T.perlin(x - [eps, 0, 0]), T.perlin(x + [eps, 0, 0])
    assert abs(float(lo[0] - hi[0])) < 1e-2


def test_noise_at_lattice_points_is_one_half_for_every_octave():
    # fBM normalized: 0.5 sum/maxamp + 0.5 with every octave's noise 0 at integer points
    # (lacunarity 2 keeps integers integer), so Fac is 0.5 exactly
    v = RNG.integers(-20, 20, (50, 3)).astype(np.float32) / np.float32(5.0)  # scale 5 -> integers
    fac, col = T.noise_texture(v, scale=5.0, detail=3.0, roughness=0.5, lacunarity=2.0)
    assert np.all(fac == np.float32(0.5))


def test_noise_detail_fraction_blends_the_two_neighbouring_octave_counts():
    f2, _ = T.noise_texture(P, detail=2.0, color=False)
    f3, _ = T.noise_texture(P, detail=3.0, color=False)
    f25, _ = T.noise_texture(P, detail=2.25, color=False)
    np.testing.assert_allclose(f25, f2 + np.float32(0.25) * (f3 - f2), atol=2e-6)


def _lattice_distances(x):
    """Sorted Euclidean distances from x (B, 3) to the 5^3 nearest lattice points."""
    cell = np.floor(x)
    pts = np.array(list(itertools.product(range(-2, 3), repeat=3)), np.float64)
    d = np.linalg.norm((cell[:, None, :] + pts[None]) - x[:, None, :], axis=2)
    return np.sort(d, axis=1)


def test_voronoi_without_randomness_is_the_cubic_lattice():
    x = P.astype(np.float64)
    out1 = T.voronoi_texture(P, scale=1.0, randomness=0.0, feature="F1")
    out2 = T.voronoi_texture(P, scale=1.0, randomness=0.0, feature="F2")
    edge = T.voronoi_texture(P, scale=1.0, randomness=0.0, feature="DISTANCE_TO_EDGE")
    ld = _lattice_distances(x)
    np.testing.assert_allclose(out1["Distance"], ld[:, 0], atol=2e-6)
    np.testing.assert_allclose(out1["Position"], np.round(x), atol=1e-6)
    # F2: the second-nearest lattice point (ties between equal distances are equal anyway)
    np.testing.assert_allclose(out2["Distance"], ld[:, 1], atol=2e-6)
    # the cell of a lattice point is the unit cube around it: distance to its nearest face
    np.testing.assert_allclose(edge["Distance"], 0.5 - np.abs(x - np.round(x)).max(axis=1), atol=2e-6)
    # the cell colour is the PCG hash of the cell's integer coordinates
    cell = np.round(x).astype(np.int32)
    np.testing.assert_array_equal(out1["Color"], H.hash_int3_to_float3(cell[:, 0], cell[:, 1], cell[:, 2]))


def test_voronoi_metrics_and_normalisation_bounds():
    for metric in T.VORONOI_METRICS:
        out = T.voronoi_texture(P, metric=metric, normalize=True, exponent=1.5)
        assert np.isfinite(out["Distance"]).all() and out["Distance"].min() >= 0
        assert out["Distance"].max() <= 1.0 + 1e-6
    sm = T.voronoi_texture(P, feature="SMOOTH_F1", smoothness=0.0)
    f1 = T.voronoi_texture(P, feature="F1")
    np.testing.assert_array_equal(sm["Distance"], f1["Distance"])  # smoothness 0 is F1, as in Cycles


def test_checker_parity_and_colours():
    v = RNG.uniform(-4, 4, (400, 3)).astype(np.float32)
    fac, col = T.checker_texture(v, (1, 0, 0), (0, 0, 1), scale=1.0)
    q = np.floor(v.astype(np.float64) + 1e-6)
    par = np.abs(q).astype(int) % 2
    want = ((par[:, 0] == par[:, 1]) == (par[:, 2] == 1)).astype(np.float32)
    np.testing.assert_array_equal(fac, want)
    np.testing.assert_array_equal(col, np.where(want[:, None] == 1, [1, 0, 0], [0, 0, 1]))


def test_gradient_formulas():
    v = RNG.uniform(-1.2, 1.2, (300, 3)).astype(np.float32)
    x, y = v[:, 0].astype(np.float64), v[:, 1].astype(np.float64)
    r = np.linalg.norm(v.astype(np.float64), axis=1)
    want = {"LINEAR": x, "QUADRATIC": np.maximum(x, 0) ** 2,
            "EASING": 3 * np.clip(x, 0, 1) ** 2 - 2 * np.clip(x, 0, 1) ** 3,
            "DIAGONAL": (x + y) / 2, "RADIAL": np.arctan2(y, x) / (2 * np.pi) + 0.5,
            "SPHERICAL": np.maximum(0.999999 - r, 0), "QUADRATIC_SPHERE": np.maximum(0.999999 - r, 0) ** 2}
    for kind, w in want.items():
        fac, col = T.gradient_texture(v, kind)
        np.testing.assert_allclose(fac, np.clip(w, 0, 1), atol=2e-6, err_msg=kind)
        np.testing.assert_array_equal(col[:, 1], fac)


def test_white_noise_is_the_hash_of_the_coordinate_bits():
    v, c = T.white_noise_texture(P, dimensions=3)
    np.testing.assert_array_equal(v, H.hash_float3_to_float(P[:, 0], P[:, 1], P[:, 2]))
    np.testing.assert_array_equal(c[:, 2], H.hash_float4_to_float(P[:, 0], P[:, 1], P[:, 2], np.float32(2.0)))
    v1, _ = T.white_noise_texture(P, w=P[:, 0], dimensions=1)
    np.testing.assert_array_equal(v1, H.hash_float_to_float(P[:, 0]))


def test_wave_profiles_closed_form():
    v = RNG.uniform(-1, 1, (300, 3)).astype(np.float32)
    p = (v.astype(np.float64) * 2.0 + 1e-6) * 0.999999
    n_bands = p[:, 1] * 20 + 0.7
    n_rings = np.linalg.norm(p, axis=1) * 20 + 0.7
    for kind, n in (("BANDS", n_bands), ("RINGS", n_rings)):
        for profile, want in (("SIN", 0.5 + 0.5 * np.sin(n - np.pi / 2)), ("SAW", np.mod(n / (2 * np.pi), 1)),
                              ("TRI", np.abs(n / (2 * np.pi) - np.floor(n / (2 * np.pi) + 0.5)) * 2)):
            fac, _ = T.wave_texture(v, scale=2.0, phase=0.7, kind=kind, bands_direction="Y",
                                    rings_direction="SPHERICAL", profile=profile)
            ok = np.abs(np.mod(n / (2 * np.pi) + 0.5, 1) - 0.5) > 1e-4 if profile != "SIN" else np.ones(len(n), bool)
            np.testing.assert_allclose(fac[ok], want[ok], atol=2e-4, err_msg=f"{kind} {profile}")


def test_magic_depth_zero_closed_form():
    v = RNG.uniform(-2, 2, (300, 3)).astype(np.float32)
    p = np.fmod(v.astype(np.float64), 2 * np.pi)
    d, s = 0.8, 1.3
    x = np.sin((p[:, 0] + p[:, 1] + p[:, 2]) * 5 * s) / (2 * d)
    y = np.cos((-p[:, 0] + p[:, 1] - p[:, 2]) * 5 * s) / (2 * d)
    z = -np.cos((-p[:, 0] - p[:, 1] + p[:, 2]) * 5 * s) / (2 * d)
    fac, col = T.magic_texture(v, scale=s, distortion=d, depth=0)
    np.testing.assert_allclose(col, np.stack([0.5 - x, 0.5 - y, 0.5 - z], 1), atol=2e-5)
    np.testing.assert_allclose(fac, col.mean(axis=1), atol=1e-6)


def _brick_noise_int(n: int) -> float:
    """svm/brick.h brick_noise on Python integers (uint32 wrap-around)."""
    n = (n + 1013) & 0x7FFFFFFF
    n = (n >> 13) ^ n
    nn = (n * ((n * n * 60493 + 19990303) & 0xFFFFFFFF) + 1376312589) & 0x7FFFFFFF
    return 0.5 * (nn / 1073741824.0)


def test_brick_rows_offsets_and_tints_by_hand():
    """Brick width 0.5, row height 0.25, every 2nd row offset by half a brick (scale 1): inside a
    brick (away from the mortar) the colour is mix(c1, c2, clamp(noise(row << 16 | brick) + bias))."""
    v = RNG.uniform(-2, 2, (2000, 3)).astype(np.float32)
    fac, col = T.brick_texture(v, (1, 0, 0), (0, 0, 1), (0, 1, 0), scale=1.0, mortar_size=0.02, bias=0.1)
    x, y = v[:, 0].astype(np.float64), v[:, 1].astype(np.float64)
    row = np.floor(y / 0.25).astype(int)
    off = np.where(row % 2 == 0, 0.25, 0.0)  # C's % is 0 for even rows, negative ones too
    brick = np.floor((x + off) / 0.5).astype(int)
    bx, by = x + off - 0.5 * brick, y - 0.25 * row
    inside = np.minimum(np.minimum(bx, by), np.minimum(0.5 - bx, 0.25 - by)) > 0.021
    tint = np.array([min(max(_brick_noise_int(((int(r) << 16) + (int(b) & 0xFFFF)) & 0xFFFFFFFF) + 0.1, 0), 1)
                     for r, b in zip(row, brick)])
    assert inside.sum() > 1000
    np.testing.assert_array_equal(fac[inside], 0)
    np.testing.assert_allclose(col[inside], np.stack([1 - tint, 0 * tint, tint], 1)[inside], atol=1e-6)
    mortar = np.minimum(np.minimum(bx, by), np.minimum(0.5 - bx, 0.25 - by)) < 0.001
    np.testing.assert_allclose(col[mortar], [[0, 1, 0]] * int(mortar.sum()), atol=1e-6)
