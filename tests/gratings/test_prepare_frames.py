"""The grating frames of prepare (core/gratings/radiance.py, core/gratings/directions.py) computed only
for grating triangles and with the vertex-sum shortcut give the values of the full versions.

- ``triangle_tangents(..., rows=)``: the rows asked for equal the all-rows version bit for bit,
  the others are zero;
- ``smooth_corner_tangents``' vertex sums (a smooth vertex: one bincount) equal the enumeration
  of every pair of corners at the vertex bit for bit, and both equal an independent per-corner
  loop over the definition (docs/physics.md section 3.1; the shortcut: docs/physics.md section 3.12);
- prepare's frames on the grating rows equal the frames computed over all triangles.
"""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.gratings import directions as gd
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.util.geometry import triangle_normals
from opal_diffraction.core.gratings.radiance import triangle_tangents

from grating_frames import corner_tangents_by_loop


def _mesh(seed=0):
    """Two icospheres (one smooth, one rough: jittered vertices), two grating materials with a
    material boundary, tangents along X with some rows jittered (creases) and some flipped."""
    rng = np.random.default_rng(seed)
    v1, t1 = primitives.icosphere((0, 0, 0), 1.0, 3)
    v2, t2 = primitives.icosphere((3, 0, 0), 1.0, 2)
    v2 = v2 + rng.normal(size=v2.shape) * 0.03
    v = np.concatenate([v1, v2]).astype(np.float32)
    t = np.concatenate([t1, t2 + len(v1)]).astype(np.int32)
    n = triangle_normals(v, t)
    given = np.tile([[1.0, 0.1, 0.0]], (len(t), 1))
    jit = rng.random(len(t)) < 0.05
    given[jit] = rng.normal(size=(jit.sum(), 3))
    given[::13] *= -1  # a grating is the same for t and -t: sign flips are aligned, not creases
    tt = triangle_tangents(n, given.astype(np.float32))
    centre = v[t].mean(axis=1)
    mat = np.where(centre[:, 2] > 0.3, 2, 1).astype(np.int32)  # a material boundary across sphere 1
    mat[rng.random(len(t)) < 0.1] = 0  # not gratings
    return v, t, n, tt, mat, mat != 0


def test_triangle_tangents_of_some_rows_equal_the_all_rows_values():
    rng = np.random.default_rng(1)
    n = rng.normal(size=(2000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n[:100] = (1, 0, 0)
    given = rng.normal(size=(2000, 3)).astype(np.float32)
    given[::3] = 0
    given[1::7] = n[1::7]
    rows = rng.random(2000) < 0.3
    for g in (given, np.zeros((0, 3), np.float32)):
        full = triangle_tangents(n, g)
        got = triangle_tangents(n, g, rows=rows)
        assert got.dtype == np.float32 and got.shape == full.shape
        assert np.array_equal(got[rows], full[rows])
        assert not got[~rows].any()


def test_vertex_sums_equal_the_pair_enumeration_bit_for_bit(monkeypatch):
    v, t, n, tt, mat, grating = _mesh()
    calls = []
    pair_sums = gd._pair_sums

    def counted(vid, *a):
        calls.append(len(vid))
        return pair_sums(vid, *a)

    monkeypatch.setattr(gd, "_pair_sums", counted)
    fast = gd.smooth_corner_tangents(v, t, n, tt, mat, grating)
    n_corners = 3 * int(grating.sum())
    # both paths ran: most corners by vertex sums, the creases and boundaries by pairs
    assert len(calls) == 1 and 0.05 * n_corners < calls[0] < 0.7 * n_corners
    monkeypatch.setattr(gd, "_FAST_MARGIN", 1e9)  # no vertex takes the shortcut
    calls.clear()
    pairs = gd.smooth_corner_tangents(v, t, n, tt, mat, grating)
    assert calls == [n_corners]
    assert np.array_equal(fast, pairs)
    assert np.array_equal(fast[~grating], np.repeat(tt[~grating, None, :], 3, axis=1))


def test_smooth_corner_tangents_match_a_per_corner_loop():
    v, t, n, tt, mat, grating = _mesh(2)
    got = gd.smooth_corner_tangents(v, t, n, tt, mat, grating)
    # the definition, corner by corner: the corner-angle-weighted, sign-aligned sum over the
    # grating corners at the vertex with the same material, tangent within 20 and normal within
    # 30 degrees, normalised (its own tangent when it vanishes)
    p = v.astype(np.float64)[t]
    ang = np.zeros(t.shape)
    for c in range(3):
        a, b = p[:, (c + 1) % 3] - p[:, c], p[:, (c + 2) % 3] - p[:, c]
        ang[:, c] = np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1))
    ref = corner_tangents_by_loop(t, n, tt, mat, grating, ang)
    assert np.allclose(got, ref.astype(np.float32), rtol=0, atol=2e-6)


def test_prepare_frames_of_the_grating_rows_equal_the_all_rows_frames():
    from opal_diffraction.core.render.prepare import prepare
    from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
    from opal_diffraction.core.scene.settings import RenderSettings

    v, t, n, _, mat, grating = _mesh(3)
    rng = np.random.default_rng(3)
    given = (rng.normal(size=(len(t), 3)) * 0.1 + [1, 0, 0]).astype(np.float32)
    mats = Materials.from_list([
        {"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
        {"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5), "grating": 1, "period": 1600.0, "slit_width": 800.0},
        {"kind": "MIRROR", "color": (0.9, 0.9, 0.9), "grating": 1, "period": 1000.0, "slit_width": 500.0},
    ])
    sc = Scene(vertices=v, triangles=t, tri_material=mat, materials=mats, tri_tangent=given)
    sc.lights = Lights.from_list([{"kind": "POINT", "position": (0, 0, 4), "power": 10.0}])
    sc.camera = Camera.look_at((0, -5, 2), (0, 0, 0), width=8, height=8)
    p = prepare(sc, RenderSettings(samples=1, light_paths=0))
    assert len(p.tri_material) == len(t)  # nothing dropped: rows line up
    nrm = triangle_normals(v, t)
    full = triangle_tangents(nrm, given)
    corner = gd.smooth_corner_tangents(v, t, nrm, full, mat, grating)
    assert np.array_equal(p.tri_grating_tangent[grating], full[grating])
    assert np.array_equal(p.corner_grating_tangent[grating], corner[grating])
    assert not p.tri_grating_tangent[~grating].any() and not p.corner_grating_tangent[~grating].any()


@pytest.mark.parametrize("n_groups", [1, 7, 300, 40000])
def test_group_extrema_equal_ufunc_at(n_groups):
    from opal_diffraction.core.util.geometry import group_extrema

    rng = np.random.default_rng(n_groups)
    label = rng.integers(0, n_groups, 5000)
    values = rng.normal(size=(5000, 3)) * 10 ** rng.uniform(-3, 3, (5000, 1))
    lo, hi = group_extrema(label, n_groups, values)
    ref_lo, ref_hi = np.full((n_groups, 3), np.inf), np.full((n_groups, 3), -np.inf)
    np.minimum.at(ref_lo, label, values)
    np.maximum.at(ref_hi, label, values)
    assert np.array_equal(lo, ref_lo) and np.array_equal(hi, ref_hi)  # empty groups too (+-inf)
    (m,) = group_extrema(label, n_groups, values[:, 0], ops=(np.maximum,))
    for g in rng.choice(n_groups, min(n_groups, 20), replace=False):  # by hand, group by group
        rows = values[label == g, 0]
        assert m[g] == (rows.max() if len(rows) else -np.inf)
