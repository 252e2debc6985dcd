"""Opal volume domains (opal_diffraction.core.opal.volume; docs/physics.md section 5.4): the weighted
Voronoi lookup against brute force, seeds inside the volume (analytic solids), reproducibility,
the orientation distributions (chi-square), the world transform, and the Scene's domain columns."""

from __future__ import annotations

import numpy as np
import pytest

from chi2 import pearson
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.opal import cabochon
from opal_diffraction.core.opal.volume import (
    VolumeDomains,
    bragg_domains,
    cells_of,
    generate_volume_domains,
    inside_mesh,
    transform_domains,
)
from opal_diffraction.core.scene.model import Camera, Materials, Scene
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.npz import load_scene, save_scene
from opal_diffraction.core.scene.validation import validate

#: Chi-square tests in this file; each must pass at p > 1e-3 / TESTS (Bonferroni).
CHI2_TESTS = 4
SIGNIFICANCE = 1e-3 / CHI2_TESTS


def _brute(points, prim, tri_group, seeds, weight, group):
    """The cell of each point by the definition, over every seed of its triangle's group."""
    out = np.full(len(points), -1)
    for i, (p, t) in enumerate(zip(points, prim)):
        g = tri_group[t] if t >= 0 else -1
        if g < 0:
            continue
        members = np.flatnonzero(group == g)
        val = np.linalg.norm(seeds[members] - p, axis=1) - weight[members]
        out[i] = members[np.argmin(val)]
    return out


@pytest.mark.parametrize("weight_scale", [0.0, 0.05, 0.4])
def test_lookup_matches_brute_force_with_weights(weight_scale):
    rng = np.random.default_rng(11)
    s = 300
    seeds = rng.random((s, 3))
    seeds[150:] += 5.0  # group 1 elsewhere: a point must not take a nearer seed of another group
    group = np.r_[np.zeros(150), np.ones(150)].astype(np.int32)
    # large weights make the nearest seeds lose: the lookup must widen its search
    weight = weight_scale * rng.random(s) ** 4
    axis = rng.normal(size=(s, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    diameter = rng.uniform(150, 350, s)
    tri_group = np.array([0, 1, -1], np.int32)
    n = 3000
    prim = rng.integers(-1, 3, n)
    pts = rng.random((n, 3)) * 1.4 - 0.2
    pts[prim == 1] += 5.0
    pts[:200] = seeds[:200] + 1e-9  # on top of seeds
    prim[:150], prim[150:200] = 0, 1
    vd = VolumeDomains(seeds, weight, axis.astype(np.float32), diameter.astype(np.float32), group, tri_group)
    ax, d, found = vd.lookup(pts, prim)
    want = _brute(pts, prim, tri_group, seeds, weight, group)
    np.testing.assert_array_equal(vd.cell(pts, prim), want)
    np.testing.assert_array_equal(found, want >= 0)
    np.testing.assert_array_equal(ax[found], axis.astype(np.float32)[want[found]])
    np.testing.assert_array_equal(d[found], diameter.astype(np.float32)[want[found]])
    assert (ax[~found] == 0).all() and (d[~found] == 0).all()
    assert ax.dtype == np.float32 and d.dtype == np.float32 and found.dtype == bool
    if weight_scale == 0.0:  # plain Voronoi: the nearest seed
        sel = prim == 0
        near = np.argmin(np.linalg.norm(pts[sel, None] - seeds[None, :150], axis=2), axis=1)
        np.testing.assert_array_equal(want[sel], near)


def test_inside_mesh_matches_analytic_solids():
    rng = np.random.default_rng(2)
    v, t = primitives.box((0.1, 0.2, 0.3), (1.0, 2.0, 0.5))
    p = rng.uniform(-1.5, 1.5, (4000, 3))
    want = (np.abs(p - (0.1, 0.2, 0.3)) < (0.5, 1.0, 0.25)).all(axis=1)
    np.testing.assert_array_equal(inside_mesh(p, v, t), want)
    # a concave solid: two disjoint boxes (the gap between them is outside)
    v2, t2 = primitives.box((2.0, 0.2, 0.3), (1.0, 2.0, 0.5))
    vv, tt = np.vstack([v, v2]), np.vstack([t, t2 + len(v)])
    q = rng.uniform((-0.5, -1, 0), (2.6, 1.4, 0.6), (4000, 3))
    want2 = ((np.abs(q - (0.1, 0.2, 0.3)) < (0.5, 1.0, 0.25)).all(axis=1)
             | (np.abs(q - (2.0, 0.2, 0.3)) < (0.5, 1.0, 0.25)).all(axis=1))
    np.testing.assert_array_equal(inside_mesh(q, vv, tt), want2)


def test_seeds_lie_inside_the_cabochon_and_fill_it_uniformly():
    a, b, h = 0.009, 0.0065, 0.006
    v, t = cabochon(2 * a, 2 * b, h, rings=32)
    seeds, weight, axis, diameter = generate_volume_domains(v, t, 4000, seed=5)
    assert seeds.shape == (4000, 3) and weight.shape == (4000,)
    # inside the polyhedron, which is inscribed in the half ellipsoid
    assert ((seeds[:, 0] / a) ** 2 + (seeds[:, 1] / b) ** 2 + (seeds[:, 2] / h) ** 2 <= 1 + 1e-9).all()
    assert (seeds[:, 2] >= 0).all()
    # uniform in the volume: the fraction below z = h/2 of a half ellipsoid is 1 - (1/2)(1 - 1/4) ... exactly
    # V(z < c) / V = (3/2)(c/h) - (1/2)(c/h)^3 = 11/16 at c = h/2 (the polyhedron is within 1 % of it)
    frac = float(np.mean(seeds[:, 2] < h / 2))
    sigma = np.sqrt(11 / 16 * 5 / 16 / 4000)
    assert abs(frac - 11 / 16) < 4 * sigma + 0.01, (frac, sigma)


def test_generation_is_reproducible_and_its_streams_are_separate():
    v, t = cabochon(0.018, 0.013, 0.006, rings=16)
    one = generate_volume_domains(v, t, 200, seed=3, size_spread=0.8)
    two = generate_volume_domains(v, t, 200, seed=3, size_spread=0.8)
    for x, y in zip(one, two):
        np.testing.assert_array_equal(x, y)
    other = generate_volume_domains(v, t, 200, seed=4, size_spread=0.8)
    assert not np.allclose(one[0], other[0])
    # another diameter range or orientation keeps the layout
    three = generate_volume_domains(v, t, 200, seed=3, size_spread=0.8, diameter_range=(150, 160),
                                    orientation="LAYERED")
    np.testing.assert_array_equal(one[0], three[0])
    np.testing.assert_array_equal(one[1], three[1])
    assert (three[3] >= 150).all() and (three[3] <= 160).all()
    # the weights: uniform in [0, spread h), h = (volume / count)^(1/3)
    vol = np.pi * 0.009 * 0.0065 * 0.006 * 2 / 3
    hh = (vol / 200) ** (1 / 3)
    assert one[1].max() < 0.8 * hh * 1.02 and one[1].max() > 0.8 * hh * 0.8
    assert (generate_volume_domains(v, t, 50, seed=3)[1] == 0).all()


def _chi2_uniform(x, y, bins, rng_x, rng_y):
    h, _, _ = np.histogram2d(x, y, bins=bins, range=(rng_x, rng_y))
    return pearson(h, np.full(h.shape, len(x) / h.size))[0]


def test_layered_axes_lie_in_the_cap_uniformly():
    v, t = cabochon(0.018, 0.013, 0.006, rings=12)
    pref = np.array([0.3, -0.2, 0.9])
    pref /= np.linalg.norm(pref)
    spread = 20.0
    _, _, axis, _ = generate_volume_domains(v, t, 20000, seed=9, orientation="LAYERED", preferred_axis=pref,
                                            axis_spread_deg=spread)
    np.testing.assert_allclose(np.linalg.norm(axis, axis=1), 1.0, atol=1e-6)
    cos_t = axis.astype(np.float64) @ pref
    assert (cos_t >= np.cos(np.radians(spread)) - 1e-6).all()
    # uniform in the cap: cos theta uniform in [cos spread, 1], the azimuth uniform
    e1 = np.cross(pref, [1.0, 0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(pref, e1)
    phi = np.arctan2(axis @ e2, axis @ e1)
    p = _chi2_uniform(cos_t, phi, (10, 12), (np.cos(np.radians(spread)), 1.0), (-np.pi, np.pi))
    assert p > SIGNIFICANCE, p
    # the mean angle of a uniform cap: E[theta] = int theta sin theta / (1 - cos s) = (sin s - s cos s) / (1 - cos s)
    s = np.radians(spread)
    mean = (np.sin(s) - s * np.cos(s)) / (1 - np.cos(s))
    th = np.arccos(np.clip(cos_t, -1, 1))
    assert abs(th.mean() - mean) < 4 * th.std() / np.sqrt(len(th))


def test_random_axes_are_uniform_on_the_sphere():
    v, t = cabochon(0.018, 0.013, 0.006, rings=12)
    _, _, axis, _ = generate_volume_domains(v, t, 20000, seed=10, orientation="RANDOM")
    a = axis.astype(np.float64)
    p = _chi2_uniform(a[:, 2], np.arctan2(a[:, 1], a[:, 0]), (10, 12), (-1.0, 1.0), (-np.pi, np.pi))
    assert p > SIGNIFICANCE, p


def test_larger_weights_own_more_volume():
    """The additive weight grows a cell: over Monte Carlo volume samples, the cells of the heavier
    half of the seeds hold more of the volume than those of the lighter half (a binomial Z-test
    against the unweighted diagram's equal split would fail by far)."""
    v, t = cabochon(0.018, 0.013, 0.006, rings=12)
    seeds, weight, _, _ = generate_volume_domains(v, t, 100, seed=1, size_spread=1.0)
    pts, _, _, _ = generate_volume_domains(v, t, 20000, seed=2)
    cell = cells_of(pts, seeds, weight)
    heavy = weight > np.median(weight)
    frac = float(np.mean(heavy[cell]))
    assert frac > 0.5 + 5 * np.sqrt(0.25 / len(pts)), frac


def test_world_transform_keeps_the_cells_of_a_similarity():
    rng = np.random.default_rng(4)
    v, t = cabochon(0.018, 0.013, 0.006, rings=12)
    seeds, weight, axis, _ = generate_volume_domains(v, t, 150, seed=1, size_spread=1.0)
    c, s = np.cos(0.7), np.sin(0.7)
    m = np.eye(4)
    m[:3, :3] = 2.5 * np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, 0.6, -0.8], [0, 0.8, 0.6]])
    m[:3, 3] = (1.0, -2.0, 0.5)
    ws, ww, wa = transform_domains(m, seeds, weight, axis)
    pts = rng.uniform(-0.009, 0.009, (3000, 3))
    wp = pts @ m[:3, :3].T + m[:3, 3]
    np.testing.assert_array_equal(cells_of(wp, ws, ww), cells_of(pts, seeds, weight))
    np.testing.assert_allclose(wa, (axis.astype(np.float64) @ m[:3, :3].T) / 2.5, atol=1e-6)


def _scene():
    sc = Scene(materials=Materials.from_list([{"kind": "DIFFUSE"}]), camera=Camera.look_at((0, -1, 0), (0, 0, 0)))
    v, t = primitives.box((0, 0, 0), 0.1)
    sc.add_mesh(v, t, 0)
    sc.add_mesh(v + 1.0, t, 0)
    return sc


def test_scene_carries_domains_through_validation_and_the_npz(tmp_path):
    sc = _scene()
    rng = np.random.default_rng(0)
    seeds = rng.uniform(-0.05, 0.05, (20, 3))
    axis = rng.normal(size=(20, 3)) * 3.0  # not unit: validation normalises
    g = sc.add_domains(seeds, np.zeros(20), axis, np.full(20, 250.0), triangles=slice(12, 24))
    assert g == 0
    assert (sc.tri_domain_group[:12] == -1).all() and (sc.tri_domain_group[12:] == 0).all()
    clean = validate(sc).scene
    np.testing.assert_allclose(np.linalg.norm(clean.domain_axis, axis=1), 1.0, atol=1e-6)
    path = tmp_path / "s.npz"
    save_scene(sc, path)
    back = load_scene(path)
    for name in ("domain_seeds", "domain_weight", "domain_axis", "domain_diameter", "domain_group",
                 "tri_domain_group"):
        np.testing.assert_array_equal(getattr(back, name), getattr(sc, name), err_msg=name)
    vd = clean.volume_domains()
    ax, d, found = vd.lookup(seeds[:3] + 1e-6, np.array([12, 13, 0]))
    assert found.tolist() == [True, True, False] and (d[:2] == 250).all()
    assert Scene().volume_domains() is None


def test_scene_rejects_bad_domains():
    sc = _scene()
    sc.add_domains(np.zeros((2, 3)), np.zeros(2), np.array([[0, 0, 1.0], [0, 0, 0]]), np.full(2, 250.0),
                   triangles=slice(0, 12))
    with pytest.raises(SceneError, match="axis"):
        validate(sc)
    sc = _scene()
    sc.add_domains(np.zeros((2, 3)), np.zeros(2), np.ones((2, 3)), np.array([250.0, -1.0]), triangles=slice(0, 12))
    with pytest.raises(SceneError, match="diameter"):
        validate(sc)
    sc = _scene()
    sc.add_domains(np.zeros((2, 3)), np.array([0.0, np.nan]), np.ones((2, 3)), np.full(2, 250.0))
    with pytest.raises(SceneError, match="weight"):
        validate(sc)


def _hue(rgb):
    r, g, b = np.asarray(rgb, np.float64).T
    return np.degrees(np.arctan2(np.sqrt(3) * (g - b), 2 * r - g - b)) % 360


def test_bragg_preview_colour_is_the_hue_of_the_bragg_wavelength():
    """The preview of spheres D is the colour of lambda = 2 sqrt(2/3) D n_eff (docs/physics.md section
    5.2): its hue within 12 degrees of colour-science's monochromatic light at that wavelength
    (CIE 1931 -> linear sRGB, clipped as the preview clips), for water voids (a narrow band)."""
    import colour

    from opal_diffraction.core.opal import bragg_colors, bragg_wavelength

    d = np.array([195.0, 210.0, 225.0, 240.0, 255.0, 270.0])
    rgba = bragg_colors(d, 1.45, 1.33)
    assert rgba.shape == (6, 4) and (rgba[:, 3] == 1).all() and np.allclose(rgba[:, :3].max(axis=1), 1.0)
    lam = bragg_wavelength(d, 0.0, 1.45, 1.33)
    xyz = colour.wavelength_to_XYZ(lam)
    ref = np.clip(colour.XYZ_to_RGB(xyz, colour.RGB_COLOURSPACES["sRGB"], apply_cctf_encoding=False), 0, None)
    diff = np.abs((_hue(rgba[:, :3]) - _hue(ref) + 180) % 360 - 180)
    assert diff.max() < 12, (lam, _hue(rgba[:, :3]), _hue(ref))
    assert (bragg_colors(np.array([0.0]))[0, :3] == 0.5).all()  # no diameter: grey


def test_bragg_domains_take_the_cell_or_the_face_and_keep_the_normals_hemisphere():
    rng = np.random.default_rng(3)
    seeds = rng.random((30, 3))
    axis = rng.normal(size=(30, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    vd = VolumeDomains(seeds, np.zeros(30), axis.astype(np.float32), np.full(30, 260.0, np.float32),
                       np.zeros(30, np.int32), np.array([0, 0, -1], np.int32))
    tri_normal = np.array([[0, 0, 1.0], [0, 0, -1.0], [1.0, 0, 0]], np.float32)
    pts = rng.random((500, 3))
    prim = rng.integers(0, 3, 500)
    ax, dia = bragg_domains(vd, pts, prim, tri_normal, 240.0)
    cell = vd.cell(pts, prim)
    inside = prim < 2
    np.testing.assert_allclose(np.abs(np.sum(ax[inside] * axis[cell[inside]], axis=1)), 1.0, atol=1e-6)
    assert (np.sum(ax[inside] * tri_normal[prim[inside]], axis=1) >= 0).all()
    assert (dia[inside] == 260).all() and (dia[~inside] == 240).all()
    np.testing.assert_array_equal(ax[~inside], tri_normal[prim[~inside]])
    # no domains at all: every hit one domain parallel to its face
    ax0, dia0 = bragg_domains(None, pts, prim, tri_normal, np.full(500, 250.0))
    np.testing.assert_array_equal(ax0, tri_normal[prim])
    assert (dia0 == 250).all()


def test_prepared_scene_carries_the_domains():
    from opal_diffraction.core.render.prepare import prepare
    from opal_diffraction.core.scene.settings import RenderSettings

    st = RenderSettings(samples=1, light_paths=0)
    sc = _scene()
    assert prepare(sc, st).opal_domains is None
    sc.add_domains(np.zeros((3, 3)) + [0.01, 0, 0], np.zeros(3), np.tile([0, 0, 1.0], (3, 1)), np.full(3, 250.0),
                   triangles=slice(0, 12))
    vd = prepare(sc, st).opal_domains
    assert isinstance(vd, VolumeDomains) and len(vd) == 3
    assert (vd.tri_group[:12] == 0).all() and (vd.tri_group[12:] == -1).all()


@pytest.mark.parametrize("column, value, words", [
    ("sphere_diameter", 0.0, "sphere diameter"), ("void_ior", 0.9, "void ior"), ("sphere_ior", np.nan, "sphere ior"),
    ("mosaic_spread", 91.0, "mosaic spread"), ("layers", 0, "layers"),
])
def test_bragg_material_columns_are_validated(column, value, words):
    """The BRAGG lattice's material columns (the interface with the Bragg renderer): defaults
    250 nm, 1.45, 1.0, 40 layers, 3 degrees; impossible values are a one-line SceneError."""
    m = Materials.from_list([{"kind": "DIFFUSE", "grating": 1, "lattice": "BRAGG"}])
    assert (float(m.sphere_diameter[0]), float(m.sphere_ior[0]), float(m.void_ior[0]), int(m.layers[0]),
            float(m.mosaic_spread[0])) == pytest.approx((250.0, 1.45, 1.0, 40, 3.0))
    sc = _scene()
    sc.materials = Materials.from_list([{"kind": "DIFFUSE", "grating": 1, "lattice": "BRAGG", column: value}])
    with pytest.raises(SceneError, match=words):
        validate(sc)
