"""Sampling emissive triangles (docs/physics.md section 7.11): the triangle pick with its
rescaled number, Heitz's square-to-triangle map, Arvo's solid-angle sampling of nearby
triangles, each against its density by a chi-square test (Mitsuba 3 style, Bonferroni over the
tests of this file), and the irradiance of nearby and distant triangles against Lambert's
polygon formula (Z-tests)."""

from __future__ import annotations

import math

import numpy as np

from chi2 import chi2_directions, pearson
from opal_diffraction.core.lights.mesh_lights import MeshLights, heitz_triangle, sample_spherical_triangle, solid_angle
from test_lights_sized import Z_MAX, polygon_irradiance
from test_mesh_lights import light_density, ray_triangles

#: chi-square tests in this file (Bonferroni)
CHI2_TESTS = 5
ALPHA = 0.01 / CHI2_TESTS

# a large panel (two triangles), a small far triangle and a tilted one with another emission
V = np.array([[-1.0, -1.0, 1.0], [1.0, -1.0, 1.0], [1.0, 1.0, 1.0], [-1.0, 1.0, 1.0],   # panel z = 1
              [2.0, 2.0, 3.0], [2.2, 2.0, 3.0], [2.0, 2.3, 3.1],                          # small, far
              [-1.5, 0.0, 0.2], [-1.5, 0.8, 0.3], [-1.2, 0.4, 1.2]])                       # tilted
T = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [7, 8, 9]])
TM = np.array([0, 0, 1, 2])
EMISSION = np.array([[1.0, 1.0], [5.0, 3.0], [0.5, 2.0]])


def build():
    return MeshLights.build(V, T, TM, EMISSION)


def test_pick_rescales_its_number_uniformly_and_independently_of_the_choice():
    """(j, u0') over a 4 x 16 grid: each cell expects N P(j) / 16."""
    ml = build()
    n = 400_000
    j, r = ml.pick(np.random.default_rng(1).random(n))
    assert r.min() >= 0 and r.max() < 1
    obs = np.zeros((len(ml), 16))
    np.add.at(obs, (j, np.minimum((r * 16).astype(int), 15)), 1)
    area = 0.5 * np.linalg.norm(np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]]), axis=1)
    w = area * EMISSION[TM].mean(axis=1)
    expected = np.repeat((n * w / w.sum() / 16)[:, None], 16, axis=1)
    pval, info = pearson(obs, expected)
    print(info)
    assert pval > ALPHA, info


def test_heitz_map_is_uniform_on_the_triangle():
    """(b1, b2) over a 20 x 20 grid of the unit square: each cell expects N times twice its area
    below b1 + b2 = 1 (exact: the cells are cut by the diagonal along their own diagonal)."""
    n = 400_000
    rng = np.random.default_rng(2)
    b1, b2 = heitz_triangle(rng.random(n), rng.random(n))
    assert (b1 >= 0).all() and (b2 >= 0).all() and (b1 + b2 <= 1 + 1e-12).all()
    k = 20
    obs = np.zeros((k, k))
    np.add.at(obs, (np.minimum((b1 * k).astype(int), k - 1), np.minimum((b2 * k).astype(int), k - 1)), 1)
    i, jj = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    frac = np.where(i + jj < k - 1, 1.0, np.where(i + jj == k - 1, 0.5, 0.0))  # share of each cell below
    pval, info = pearson(obs, n * 2 * frac / k**2)
    print(info)
    assert pval > ALPHA, info


def test_spherical_triangle_directions_are_uniform_in_its_solid_angle():
    """Arvo's sampler alone, for a wide triangle seen from close by: chi-square against 1 / Omega
    inside the triangle (found by ray casting), and the mean of the directions against the
    triangle's vector solid angle (its flux through any plane: Lambert's formula)."""
    p = np.array([0.1, -0.2, 0.0])
    tri = np.array([[-1.0, -1.0, 0.3], [2.0, -0.5, 0.25], [0.0, 1.5, 0.35]])
    a, b, c = ((tri[i] - p) / np.linalg.norm(tri[i] - p) for i in range(3))
    n = 300_000
    rng = np.random.default_rng(3)
    rep = lambda x: np.broadcast_to(x, (n, 3))  # noqa: E731
    w = sample_spherical_triangle(rep(a), rep(b), rep(c), rng.random(n), rng.random(n))
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1, atol=1e-9)
    omega = float(solid_angle(a[None], b[None], c[None])[0])

    def density(d):
        t = ray_triangles(np.broadcast_to(p, d.shape), d, tri[None])
        return np.where(np.isfinite(t[0]), 1 / omega, 0.0)

    pval, info, total = chi2_directions(w, density, tri.mean(axis=0) - p, theta_max=1.5, n_theta=16, n_phi=32, sub=40)
    print(info)
    assert pval > ALPHA, info
    assert abs(total - 1) < 0.01
    # E[cos to the normal n] = (irradiance factor of the triangle for a receiver facing it) / Omega
    normal = np.array([0.0, 0.0, 1.0])
    x = w @ normal
    expected = polygon_irradiance(p, normal, tri) / omega
    z = (x.mean() - expected) / (x.std() / math.sqrt(n))
    assert abs(z) < Z_MAX, z


def test_sampler_matches_its_pdf_near_and_far_chi2():
    """ml.sample from a point under the panel's corner (solid-angle sampling of both panel
    triangles, area sampling of the far one, the tilted one near) against MeshLights.pdf summed
    over every emitter a direction crosses."""
    ml = build()
    p = np.array([0.6, -0.7, 0.55])
    plane = np.einsum("ij,ij->i", p - ml.v0, ml.normal)
    near = ml.longest2 > plane ** 2
    assert near.sum() >= 2 and not near.all()  # both strategies are exercised
    n = 300_000
    wi, dist, g, prim, pdf = ml.sample(np.broadcast_to(p, (n, 3)), np.random.default_rng(4))
    q = p + wi.astype(np.float64) * dist[:, None]
    np.testing.assert_allclose(pdf, ml.pdf(prim, np.broadcast_to(p, (n, 3)), q), rtol=2e-3)
    np.testing.assert_allclose(g * pdf, 1, rtol=1e-5)
    pval, info, total = chi2_directions(wi, light_density(ml, V[T[ml.tri]], p), np.array([0.0, 0.0, 1.0]), theta_max=np.pi / 2,
                                        n_theta=20, n_phi=32, sub=40)
    print(info)
    assert pval > ALPHA, info
    assert abs(total - 1) < 0.01


def test_sampler_matches_its_pdf_from_below_the_tilted_triangle_chi2():
    """Another point, closer to the tilted triangle (near) and far from the small one."""
    ml = build()
    p = np.array([-1.0, 0.4, 0.4])
    n = 300_000
    wi, dist, g, prim, pdf = ml.sample(np.broadcast_to(p, (n, 3)), np.random.default_rng(5))
    pval, info, total = chi2_directions(wi, light_density(ml, V[T[ml.tri]], p), np.array([-0.3, 0.0, 1.0]), theta_max=2.2,
                                        n_theta=20, n_phi=32, sub=40)
    print(info)
    assert pval > ALPHA, info
    assert abs(total - 1) < 0.01


def test_irradiance_near_and_far_is_lamberts_formula():
    """E = sum_tri L_tri (Lambert's polygon factor) at points near the panel (solid-angle
    sampling) and far from it (area sampling), every triangle above the receiver's horizon."""
    ml = build()
    normal = np.array([0.0, 0.0, 1.0])
    n = 400_000
    for p in (np.array([0.3, 0.2, 0.9]), np.array([0.9, 0.9, 0.8]), np.array([0.0, 0.0, -4.0])):
        wi, _, g, prim, _ = ml.sample(np.broadcast_to(p, (n, 3)), np.random.default_rng(6))
        up = [k for k in range(4) if (V[T[k]][:, 2] > p[2]).all()]
        lam = 1
        x = g.astype(np.float64) * np.maximum(wi @ normal, 0) * EMISSION[TM[ml.tri[np.searchsorted(ml.tri, prim)]], lam]
        x = np.where(np.isin(prim, up), x, 0.0)
        expected = sum(EMISSION[TM[k], lam] * polygon_irradiance(p, normal, V[T[k]]) for k in up)
        z = (x.mean() - expected) / (x.std() / math.sqrt(n))
        print(f"p {p}: MC {x.mean():.6f} analytic {expected:.6f} Z {z:.2f}")
        assert abs(z) < Z_MAX, (p, z)


def test_sample_light_pdf_is_light_pdf_of_its_directions():
    """lights.sample_light_pdf's pdf (from the sample's g) against light_pdf (a second, float64
    intersection with the light) for every kind of sized light, and None for delta lights."""
    from opal_diffraction.core.lights.sources import SPOT, light_pdf, sample_light_pdf
    from test_lights_sized import prepared
    pl = prepared({"kind": "AREA_RECT", "position": (0, 0, 2), "direction": (0.2, 0, -1), "size_u": 1.0,
                   "size_v": 0.6},
                  {"kind": "AREA_DISK", "position": (0.5, 0, 1.5), "direction": (0, 0, -1), "size_u": 0.8,
                   "size_v": 0.8},
                  {"kind": "POINT", "position": (1, 1, 1), "radius": 0.3},
                  {"kind": "POINT", "position": (0.1, 0.1, 0.2), "radius": 0.4, "soft_falloff": 1},
                  {"kind": "POINT", "position": (0.1, 0.0, 0.1), "radius": 0.5},  # some points inside
                  {"kind": "SPOT", "position": (0, 1, 2), "direction": (0, -0.3, -1), "radius": 0.2,
                   "spot_size": 1.0},
                  {"kind": "SUN", "direction": (0.3, 0.2, -1), "angle": 0.2},
                  {"kind": "POINT", "position": (0, 0, 1)})
    p = np.random.default_rng(7).uniform(-1, 1, (2000, 3)).astype(np.float32) * np.float32(0.5)
    for li in range(len(pl)):
        wi, dist, g, pdf = sample_light_pdf(pl, li, p, np.random.default_rng(li))
        if li == len(pl) - 1:
            assert pdf is None
            continue
        ref = light_pdf(pl, li, p, wi)
        live = (g > 0) & (ref > 0)
        assert live.mean() > 0.3, li
        np.testing.assert_allclose(pdf[live], ref[live], rtol=2e-3, err_msg=f"light {li}")
        if int(pl.kind[li]) != SPOT:  # a spot's g holds its cone mask; its pdf is the sampler's density
            assert (pdf[g <= 0] == 0).all()
