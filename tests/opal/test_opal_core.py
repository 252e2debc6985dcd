"""The opal model without Blender: Bragg law (docs/physics.md section 5.3), cabochon mesh, Voronoi
grating domains, editing functions and preview colours (opal_diffraction.core.opal)."""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core import opal


# ---------------------------------------------------------------------------- physics
def test_effective_index_and_bragg_numbers_of_physics_md():
    assert opal.effective_index() == pytest.approx(1.3475, abs=1e-4)
    assert opal.d111_spacing(250.0) == pytest.approx(204.124, abs=1e-3)
    assert opal.bragg_wavelength(250.0) == pytest.approx(550.0, abs=0.5)
    assert opal.bragg_wavelength(250.0, np.radians(45.0)) == pytest.approx(468.0, abs=0.5)
    # the equivalent period is the normal-incidence Bragg wavelength; 150-350 nm spheres span the visible
    assert opal.period_from_sphere_diameter(250.0) == pytest.approx(550.0, abs=0.5)
    lo, hi = opal.period_from_sphere_diameter(np.array(opal.SPHERE_DIAMETER_RANGE))
    assert lo == pytest.approx(330.1, abs=0.5) and hi == pytest.approx(770.2, abs=0.5)


# ---------------------------------------------------------------------------- cabochon
def test_cabochon_is_a_closed_outward_dome_of_the_requested_size():
    v, t = opal.cabochon(2.0, 1.5, 0.5, rings=12)
    assert t.shape == (6 * 12 * 12 + 6 * 12, 3)
    np.testing.assert_allclose(v.min(axis=0), [-1.0, -0.75, 0.0], atol=1e-9)
    np.testing.assert_allclose(v.max(axis=0), [1.0, 0.75, 0.5], atol=1e-9)
    # closed: every edge is shared by exactly two triangles, in opposite directions
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    directed = {tuple(x) for x in e.tolist()}
    assert len(directed) == len(e)
    assert all((b, a) in directed for a, b in directed)
    # outward: positive volume, close to a half ellipsoid's (2/3) pi a b h
    p = v[t]
    vol = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6
    assert vol == pytest.approx(2 / 3 * np.pi * 1.0 * 0.75 * 0.5, rel=0.03)
    geo = opal.face_geometry(v, t)
    assert geo.area.min() > 0.2 * np.median(geo.area)  # no slivers near the top: rings of 6 i vertices


def test_face_geometry_merges_triangles_into_faces():
    v = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0], [0, 0, 1]], float)
    t = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4]])
    geo = opal.face_geometry(v, t, tri_face=[0, 0, 1], n_faces=2)
    np.testing.assert_allclose(geo.area, [2.0, 0.5])
    np.testing.assert_allclose(geo.normal, [[0, 0, 1], [1, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(geo.center[0], [1.0, 0.5, 0.0])


# ---------------------------------------------------------------------------- domains
def _dome(rings=16):
    v, t = opal.cabochon(2.0, 1.5, 0.5, rings=rings)
    return v, t, opal.face_geometry(v, t)


def test_surface_points_are_area_weighted():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [3, 0, 0], [3, 1.5, 0]], float)  # areas 0.5 and 1.5
    t = np.array([[0, 1, 2], [1, 3, 4]])
    pts, tri = opal.sample_surface_points(v, t, 40000, np.random.default_rng(0))
    assert np.mean(tri == 1) == pytest.approx(0.75, abs=0.01)
    inside0 = pts[tri == 0]
    assert (inside0[:, 0] >= -1e-12).all() and (inside0[:, 1] >= -1e-12).all() and (inside0[:, :2].sum(1) <= 1 + 1e-12).all()
    # uniform inside a triangle: the mean is the centroid
    np.testing.assert_allclose(inside0.mean(axis=0), [1 / 3, 1 / 3, 0], atol=0.01)


def test_nearest_seed_matches_brute_force():
    rng = np.random.default_rng(1)
    pts, seeds = rng.random((500, 3)), rng.random((17, 3))
    brute = np.argmin(((pts[:, None] - seeds[None]) ** 2).sum(-1), axis=1)
    np.testing.assert_array_equal(opal.nearest_seed(pts, seeds), brute)


def test_domains_cover_every_face_with_unit_tangent_directions_and_ranged_periods():
    v, t, geo = _dome()
    f = opal.generate_domains(v, t, 40, seed=3, low=180.0, high=320.0)
    assert len(f) == len(t) and f.domain.dtype == np.int32
    ids = np.unique(f.domain)
    np.testing.assert_array_equal(ids, np.arange(len(ids)))  # 0..K-1, every id used
    assert 30 <= len(ids) <= 40
    np.testing.assert_allclose(np.linalg.norm(f.direction, axis=1), 1.0, atol=1e-6)
    assert np.abs(np.einsum("ij,ij->i", f.direction, geo.normal)).max() < 1e-5
    lo, hi = opal.period_from_sphere_diameter(np.array([180.0, 320.0]))
    assert f.period.min() >= lo - 1e-3 and f.period.max() <= hi + 1e-3
    # one period per domain
    for d in ids:
        assert np.ptp(f.period[f.domain == d]) == 0


def _adjacent_pairs(t):
    """Pairs of triangles sharing an edge."""
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    fi = np.tile(np.arange(len(t)), 3)
    key = np.sort(e, axis=1)
    order = np.lexsort(key.T[::-1])
    k = key[order]
    same = (k[1:] == k[:-1]).all(axis=1)
    return fi[order][:-1][same], fi[order][1:][same]


def test_domain_directions_are_consistent_within_a_domain():
    """A domain is one crystal: its direction is one 3D vector projected onto its faces, so
    neighbouring faces of a domain agree (up to the change of their planes)."""
    v, t, geo = _dome(24)
    f = opal.generate_domains(v, t, 60, seed=5)
    a, b = _adjacent_pairs(t)
    inside = f.domain[a] == f.domain[b]
    smooth = np.einsum("ij,ij->i", geo.normal[a], geo.normal[b]) > np.cos(np.radians(20))
    dots = np.abs(np.einsum("ij,ij->i", f.direction[a], f.direction[b]))
    assert np.median(dots[inside]) > 0.999
    assert dots[inside & smooth].min() > 0.9
    # across domain borders they do not (random directions)
    assert np.median(dots[~inside]) < 0.9


def test_faces_belong_to_their_nearest_seed():
    v, t, geo = _dome()
    ss_pos = np.random.SeedSequence(11).spawn(3)[0]
    seeds, _ = opal.sample_surface_points(v, t, 25, np.random.default_rng(ss_pos))
    f = opal.generate_domains(v, t, 25, seed=11)
    raw = opal.voronoi_domains(geo.center, seeds)
    _, expected = np.unique(raw, return_inverse=True)
    np.testing.assert_array_equal(f.domain, expected)


def test_the_seed_reproduces_domains_and_a_new_seed_changes_them():
    v, t, _ = _dome()
    a = opal.generate_domains(v, t, 30, seed=7)
    b = opal.generate_domains(v, t, 30, seed=7)
    c = opal.generate_domains(v, t, 30, seed=8)
    np.testing.assert_array_equal(a.domain, b.domain)
    np.testing.assert_array_equal(a.direction, b.direction)
    np.testing.assert_array_equal(a.period, b.period)
    assert (a.domain != c.domain).any()
    # the period range is its own random stream: changing it keeps the layout and the directions
    d = opal.generate_domains(v, t, 30, seed=7, period_mode="PERIOD", low=400.0, high=500.0)
    np.testing.assert_array_equal(a.domain, d.domain)
    np.testing.assert_array_equal(a.direction, d.direction)
    assert d.period.min() >= 400.0 and d.period.max() <= 500.0


def test_aligned_directions_are_the_papers_model():
    v, t, geo = _dome()
    f = opal.generate_domains(v, t, 1, direction_mode="ALIGNED", period_mode="PERIOD", low=600.0, high=600.0)
    assert (f.domain == 0).all() and np.allclose(f.period, 600.0)
    x = np.array([1.0, 0.0, 0.0])
    proj = x - (geo.normal @ x)[:, None] * geo.normal
    ok = np.linalg.norm(proj, axis=1) > 1e-3
    np.testing.assert_allclose(f.direction[ok], proj[ok] / np.linalg.norm(proj[ok], axis=1)[:, None], atol=1e-6)


def test_seed_mask_keeps_seeds_off_the_base_but_covers_every_face():
    v, t, geo = _dome()
    dome = geo.normal[:, 2] > -0.5
    f = opal.generate_domains(v, t, 30, seed=2, seed_mask=dome)
    assert len(f) == len(t) and (f.domain >= 0).all()
    # every domain reaches the dome (its seed lies there)
    assert all(dome[f.domain == d].any() for d in np.unique(f.domain))


# ---------------------------------------------------------------------------- editing
def test_direction_from_vector_and_angle_lie_in_each_face():
    _, _, geo = _dome()
    n = geo.normal
    d = opal.direction_from_vector(n, (0.0, 1.0, 0.3))
    assert np.abs(np.einsum("ij,ij->i", d, n)).max() < 1e-5
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-6)
    a0 = opal.direction_from_angle(n, 0.0)
    a90 = opal.direction_from_angle(n, np.pi / 2)
    assert np.abs(np.einsum("ij,ij->i", a0, a90)).max() < 1e-6
    np.testing.assert_allclose(opal.direction_angle(a90, n), np.pi / 2, atol=1e-6)


def test_rotate_and_assign_change_exactly_the_selected_faces():
    v, t, geo = _dome()
    f = opal.generate_domains(v, t, 20, seed=1)
    sel = np.zeros(len(f), bool)
    sel[::7] = True
    rot = opal.rotate_directions(f.direction, geo.normal, sel, np.pi / 2)
    np.testing.assert_array_equal(rot[~sel], f.direction[~sel])
    np.testing.assert_allclose(np.einsum("ij,ij->i", rot[sel], f.direction[sel]), 0.0, atol=1e-5)
    out = opal.assign_grating(f, geo.normal, sel, direction=(0.0, 1.0, 0.0), period=612.0)
    changed = (out.domain != f.domain) | (out.period != f.period) | (out.direction != f.direction).any(1)
    np.testing.assert_array_equal(changed, sel)
    assert (out.domain[sel] == f.domain.max() + 1).all() and np.all(out.period[sel] == np.float32(612.0))
    assert np.abs(np.einsum("ij,ij->i", out.direction, geo.normal)).max() < 1e-5
    keep = opal.assign_grating(f, geo.normal, sel, new_domain=False)
    np.testing.assert_array_equal(keep.domain, f.domain)


def test_set_and_jitter_period():
    v, t, _ = _dome()
    f = opal.generate_domains(v, t, 20, seed=4)
    sel = f.domain < 5
    p = opal.set_period(f.period, sel, 500.0)
    assert np.all(p[sel] == 500.0) and np.array_equal(p[~sel], f.period[~sel])
    j = opal.jitter_period(p, f.domain, sel, 40.0, seed=3)
    np.testing.assert_array_equal(j[~sel], p[~sel])
    assert np.abs(j[sel] - 500.0).max() <= 40.0 + 1e-3 and np.ptp(j[sel]) > 1.0
    for d in range(5):  # one offset per domain
        assert np.ptp(j[f.domain == d]) == 0
    np.testing.assert_array_equal(j, opal.jitter_period(p, f.domain, sel, 40.0, seed=3))
    per_face = opal.jitter_period(p, f.domain, sel, 40.0, seed=3, per_domain=False)
    assert max(np.ptp(per_face[f.domain == d]) for d in range(5)) > 1.0


def test_split_and_merge_domains():
    v, t, geo = _dome()
    f = opal.generate_domains(v, t, 10, seed=9)
    sel = f.domain == 0
    s = opal.split_domains(f, geo, sel, parts=3, seed=1)
    new = np.unique(s.domain[sel])
    assert 1 <= len(new) <= 3 and new.min() > f.domain.max()
    np.testing.assert_array_equal(s.domain[~sel], f.domain[~sel])
    np.testing.assert_array_equal(s.direction[~sel], f.direction[~sel])
    assert np.abs(np.einsum("ij,ij->i", s.direction, geo.normal)).max() < 1e-5
    # merge: one face of domain 1 and one of domain 2 selected -> both whole domains become the active's
    sel2 = np.zeros(len(f), bool)
    a, b = np.flatnonzero(f.domain == 1)[0], np.flatnonzero(f.domain == 2)[0]
    sel2[[a, b]] = True
    m = opal.merge_domains(f, geo.normal, sel2, active=b)
    both = (f.domain == 1) | (f.domain == 2)
    assert (m.domain[both] == f.domain[b]).all() and (m.period[both] == f.period[b]).all()
    np.testing.assert_array_equal(m.domain[~both], f.domain[~both])
    assert np.abs(np.einsum("ij,ij->i", m.direction, geo.normal)).max() < 1e-5


def test_preview_colours_hue_is_direction_axis_brightness_is_period():
    _, _, geo = _dome(8)
    n = geo.normal
    d = opal.direction_from_angle(n, 0.7)
    period = np.linspace(300.0, 800.0, len(n)).astype(np.float32)
    c = opal.preview_colors(d, n, period)
    assert c.shape == (len(n), 4) and c.dtype == np.float32
    assert c.min() >= 0.0 and c.max() <= 1.0 and np.all(c[:, 3] == 1.0)
    np.testing.assert_allclose(opal.preview_colors(-d, n, period), c, atol=1e-6)  # an axis: t and -t alike
    value = c[:, :3].max(axis=1)
    assert np.all(np.diff(value) >= -1e-6) and value[-1] > 2 * value[0]  # brighter with the period
    other = opal.preview_colors(opal.direction_from_angle(n, 0.7 + np.pi / 3), n, period)
    assert np.abs(other - c).max() > 0.2  # another direction, another hue
    period[:3] = 0.0
    assert np.allclose(opal.preview_colors(d, n, period)[:3, :3], 0.5)  # no period: grey
