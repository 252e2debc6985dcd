"""Domain curvature (core/opal/volume.py, VolumeDomains.lattice_axis; docs/opal.md "Domain
curvature"): each domain's (111) normal bends across it, a(p) = normalize(a_s + (beta / h) P_s
B_s (p - seed_s)), B_s with N(0, 1/3) entries, h the mean seed spacing from the mean
nearest-neighbour distance. Checked against closed forms: the uniform-points nearest-neighbour
constant Gamma(4/3) (3 / (4 pi))^(1/3) (by its formula and by Monte Carlo away from the box's
faces), E[tan^2 tilt] = (2/3) (beta r / h)^2 (a Z-test over many domains), the seed's own
normal at the seed, the plain cell normal without bending."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from opal_diffraction.core.opal.volume import NN_PER_SPACING, VolumeDomains


def _domains(n, rng, box=1.0):
    seeds = rng.random((n, 3)) * box
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    return VolumeDomains(seeds, np.zeros(n), axis.astype(np.float32), np.full(n, 250.0, np.float32),
                         np.zeros(n, np.int32), np.zeros(1, np.int32))


def test_nearest_neighbour_constant_is_the_poisson_closed_form_and_matches_monte_carlo():
    assert NN_PER_SPACING == pytest.approx(math.gamma(4.0 / 3.0) * (3.0 / (4.0 * math.pi)) ** (1.0 / 3.0), rel=1e-9)
    rng = np.random.default_rng(11)
    n = 40000
    pts = rng.random((n, 3))  # unit box: spacing h = n^(-1/3)
    inner = np.all((pts > 0.15) & (pts < 0.85), axis=1)  # far from the faces (NN distances ~ 0.02)
    d, _ = cKDTree(pts).query(pts[inner], k=2)
    nn = d[:, 1] * n ** (1.0 / 3.0)
    z = (nn.mean() - NN_PER_SPACING) / (nn.std() / math.sqrt(len(nn)))
    assert abs(z) < 4.0, (nn.mean(), NN_PER_SPACING, z)


def test_spacing_is_the_mean_nearest_neighbour_distance_over_the_constant():
    rng = np.random.default_rng(3)
    vd = _domains(500, rng, box=0.01)
    d, _ = cKDTree(vd.seeds).query(vd.seeds, k=2)
    assert vd.spacing(0) == pytest.approx(d[:, 1].mean() / NN_PER_SPACING, rel=1e-12)
    one = VolumeDomains(np.zeros((1, 3)), np.zeros(1), np.array([[0, 0, 1.0]], np.float32), np.full(1, 250.0, np.float32),
                        np.zeros(1, np.int32), np.zeros(1, np.int32))
    assert one.spacing(0) == 0.0
    ax, _, found = one.lattice_axis(np.array([[0.3, 0.1, 0.0]]), np.array([0]), 10.0)  # one cell: not bent
    assert found.all() and np.allclose(ax, [[0, 0, 1.0]])


def test_unbent_axis_is_the_cells_and_the_seed_keeps_its_own():
    rng = np.random.default_rng(5)
    vd = _domains(300, rng)
    pts = rng.random((2000, 3))
    prim = np.zeros(2000, np.int64)
    ax0, d0, f0 = vd.lattice_axis(pts, prim, 0.0)
    ax, d, f = vd.lookup(pts, prim)
    np.testing.assert_allclose(ax0, ax, atol=1e-6)
    np.testing.assert_array_equal(d0, d)
    np.testing.assert_array_equal(f0, f)
    ax_s, _, _ = vd.lattice_axis(vd.seeds, np.zeros(300, np.int64), 20.0)
    np.testing.assert_allclose(ax_s, vd.axis, atol=1e-6)
    # prim -1 (a triangle without domains): not found
    _, _, f1 = vd.lattice_axis(pts[:3], np.array([-1, 0, 5]), 10.0)
    assert f1.tolist() == [False, True, False]


def test_tilt_statistics_follow_the_closed_form():
    """E[tan^2 tilt] = (2/3) (beta r / h)^2 at distance r from the seed, any direction: a Z-test
    of the mean of tan^2 / (beta r / h)^2 (its variance 4/9 per domain: (1/3) chi^2_2) over the
    domains whose offset point stays in their own cell."""
    rng = np.random.default_rng(7)
    n = 6000
    vd = _domains(n, rng)
    h = vd.spacing(0)
    r = 0.05 * h
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    pts = vd.seeds + r * u
    prim = np.zeros(n, np.int64)
    keep = vd.cell(pts, prim) == np.arange(n)
    beta_deg = 12.0
    ax, _, found = vd.lattice_axis(pts[keep], prim[keep], beta_deg)
    assert found.all()
    a = vd.axis.astype(np.float64)[keep]
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    c = np.abs(np.sum(ax * a, axis=1))
    tan2 = (1.0 - c * c) / (c * c)
    x = tan2 / (math.radians(beta_deg) * r / h) ** 2
    z = (x.mean() - 2.0 / 3.0) / (math.sqrt(4.0 / 9.0) / math.sqrt(len(x)))
    assert keep.mean() > 0.95 and abs(z) < 4.0, (x.mean(), z)
    # the tilt is across the normal only: unit vectors, tilt grows linearly with r (a = 2 r)
    ax2, _, _ = vd.lattice_axis(vd.seeds[keep] + 2 * r * u[keep], prim[keep], beta_deg)
    c2 = np.abs(np.sum(ax2 * a, axis=1))
    ok = vd.cell(vd.seeds[keep] + 2 * r * u[keep], prim[keep]) == np.flatnonzero(keep)
    np.testing.assert_allclose(np.linalg.norm(ax2, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.sqrt((1 - c2[ok] ** 2) / c2[ok] ** 2), 2 * np.sqrt(tan2[ok]), rtol=1e-6)


def test_the_opal_shading_takes_the_bent_axis():
    """BraggShading.lobe's (111) axis at a hit is lattice_axis(p, prim, DOMAIN_BEND_DEG), turned to
    the shading normal's side (an axis: m and -m are the same planes), not the cell's flat one."""
    from types import SimpleNamespace

    from opal_diffraction.core.integrators.bragg_shading import BraggShading
    from opal_diffraction.core.opal.volume import DOMAIN_BEND_DEG
    from opal_diffraction.core.scene.model import Materials

    rng = np.random.default_rng(9)
    vd = _domains(200, rng)
    mats = Materials.from_list([{"kind": "DIFFUSE", "grating": 1, "lattice": "BRAGG", "void_ior": 1.33}])
    prepared = SimpleNamespace(scene=SimpleNamespace(materials=mats), opal_domains=vd,
                               grid=SimpleNamespace(bin_edges=np.linspace(380.0, 780.0, 41)))
    shading = BraggShading(prepared)
    n = 500
    ns = rng.normal(size=(n, 3))
    ns /= np.linalg.norm(ns, axis=1, keepdims=True)
    hit = SimpleNamespace(mat=np.zeros(n, np.int64), ns=ns, p=rng.random((n, 3)), prim=np.zeros(n, np.int64))
    lobe = shading.lobe(hit)
    want, dia, found = vd.lattice_axis(hit.p, hit.prim, DOMAIN_BEND_DEG)
    assert found.all() and DOMAIN_BEND_DEG > 0
    want[np.sum(want * ns, axis=1) < 0] *= -1
    np.testing.assert_allclose(lobe.axis, want, atol=1e-12)
    np.testing.assert_array_equal(lobe.diameter, dia)
    flat, _, _ = vd.lookup(hit.p, hit.prim)
    assert np.median(np.abs(np.sum(flat * lobe.axis, axis=1))) < 1 - 1e-5  # bent: not the cell's own normal
