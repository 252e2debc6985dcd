"""The preparation's faster code paths give the results of the ones they replace.

- geometry.compact_indices equals np.unique(..., return_inverse=True) (the sort it replaces in
  caster_objects and the Embree build);
- the direct Embree fill (core/accel/embree_direct.py: Embree's C API through ctypes) builds a
  scene that answers every ray exactly as embreex's own TriangleMesh does (t, prim, u, v and
  occlusion bit for bit, rays through vertices and edges included), in one piece and in several;
- MeshLights.build, which no longer forms a (T, n) array of spectra, selects the emitters an
  independent per-triangle check selects;
- caster_objects' groups equal those of a brute-force union-find over the shared vertices.
"""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.util.geometry import compact_indices
from opal_diffraction.core.lights.aiming import caster_objects
from opal_diffraction.core.lights.mesh_lights import MeshLights

embree_direct = pytest.importorskip("opal_diffraction.core.accel.embree_direct")


@pytest.mark.parametrize("seed", range(5))
def test_compact_indices_equals_np_unique(seed):
    rng = np.random.default_rng(seed)
    lo = int(rng.integers(0, 1000))
    ids = rng.integers(lo, lo + int(rng.integers(1, 5000)), size=(int(rng.integers(1, 3000)), 3))
    used, local = compact_indices(ids)
    u_ref, inv_ref = np.unique(ids, return_inverse=True)
    assert np.array_equal(used, u_ref)
    assert np.array_equal(local, inv_ref.reshape(ids.shape))
    assert np.array_equal(used[local], ids)


def _rays(v, n, rng):
    """Random rays at the mesh, and rays aimed exactly at vertices and edge midpoints (ties
    between the triangles sharing them)."""
    o = rng.normal(size=(n, 3)) * 3
    d = rng.normal(size=(n, 3)) * 0.3 - o
    tgt = v[rng.integers(0, len(v), n // 2)]
    mid = 0.5 * (v[rng.integers(0, len(v), n // 2)] + v[rng.integers(0, len(v), n // 2)])
    o2 = np.full((n, 3), 2.5) + rng.normal(size=(n, 3)) * 0.01
    d2 = np.concatenate([tgt, mid]) - o2
    o = np.concatenate([o, o2]).astype(np.float32)
    d = np.concatenate([d, d2])
    return o, (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)


@pytest.mark.parametrize("chunk", [None, 5000])
def test_direct_embree_fill_answers_as_embreex(monkeypatch, chunk):
    pytest.importorskip("embreex")
    from opal_diffraction.core.accel import embree_backend

    assert embree_direct.available(), "the ctypes path to embreex's Embree should work with this embreex"
    if chunk is not None:  # several geometries (the large-mesh path), each with compacted vertices
        monkeypatch.setattr(embree_backend, "_GEOMETRY_CHUNK", chunk)
    v, t = primitives.icosphere((0.1, -0.2, 0.3), 1.0, 4)
    v2, t2 = primitives.box((0, 0, -1.2), (3, 3, 0.2))
    v = np.concatenate([v, v2]).astype(np.float32)
    t = np.concatenate([t, t2 + len(v) - len(v2)]).astype(np.int32)
    rng = np.random.default_rng(3)
    o, d = _rays(v, 20000, rng)
    tmax = rng.uniform(0.5, 6.0, len(o)).astype(np.float32)
    out = {}
    for direct in (True, False):
        monkeypatch.setitem(embree_direct._state, "ok", direct)
        acc = embree_backend.EmbreeAccelerator(v, t, threads=1)
        assert (len(acc._geom_start) > 1) == (chunk is not None)
        out[direct] = (acc.intersect(o, d), acc.occluded(o, d, tmax))
    (h1, o1), (h2, o2) = out[True], out[False]
    assert h1.hit.mean() > 0.5 and 0 < o1.mean() < 1
    for k in ("t", "prim", "u", "v"):
        assert np.array_equal(getattr(h1, k), getattr(h2, k)), k
    assert np.array_equal(o1, o2)


def test_mesh_lights_select_the_emitting_triangles():
    rng = np.random.default_rng(0)
    v = rng.normal(size=(300, 3))
    t = rng.integers(0, 300, size=(500, 3))
    t[:5, 1] = t[:5, 0]  # zero area: never emitters
    n = 7
    em = np.zeros((4, n))
    em[1, 2] = 3.0   # emits in one bin
    em[3] = 0.5      # emits everywhere
    em[2, 4] = -1.0  # negative luminance: not an emitter
    tm = rng.integers(0, 4, 500)
    ml = MeshLights.build(v, t, tm, em)
    p = v[t]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    expect = [i for i in range(500) if em[tm[i]].mean() > 0 and (em[tm[i]] > 0).any() and area[i] > 0]
    assert np.array_equal(ml.tri, expect)
    assert ml.weight == pytest.approx(area[expect] * em[tm[expect]].mean(axis=1))


def test_caster_objects_match_union_find():
    # 12 small separate spheres (<= MAX_OBJECTS: one group each), half of them casters
    rng = np.random.default_rng(1)
    vs, ts, off = [], [], 0
    for k in range(12):
        c = rng.uniform(-5, 5, 3)
        v, t = primitives.icosphere(c, rng.uniform(0.2, 0.6), 1)
        vs.append(v)
        ts.append(t + off)
        off += len(v)
    v, t = np.concatenate(vs), np.concatenate(ts)
    mask = np.repeat(np.arange(12) % 2 == 0, len(ts[0]))
    obj = caster_objects(v, t, mask)
    # independent: union-find over the vertices the caster triangles share
    parent = list(range(len(v)))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a
    for tri in t[mask]:
        for a, b in ((tri[0], tri[1]), (tri[1], tri[2])):
            parent[find(a)] = find(b)
    groups = {}
    for i in np.unique(t[mask]):
        groups.setdefault(find(i), []).append(i)
    expect = []
    for ids in groups.values():
        p = v[ids]
        c = 0.5 * (p.min(0) + p.max(0))
        expect.append((tuple(c), np.sqrt(((p - c) ** 2).sum(1).max())))
    assert len(obj) == len(expect) == 6
    got = sorted(zip(map(tuple, obj.centre), obj.radius))
    for (cg, rg), (ce, re) in zip(got, sorted(expect)):
        assert np.allclose(cg, ce, rtol=0, atol=1e-12)
        assert rg == pytest.approx(re, rel=2e-6)


def _old_triangle_cross(v, t):
    p = np.asarray(v, np.float64)[np.asarray(t, np.int64)]
    return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_triangle_cross_is_np_cross_bit_for_bit(dtype):
    from opal_diffraction.core.util.geometry import triangle_cross

    rng = np.random.default_rng(2)
    v = (rng.normal(size=(400, 3)) * 10 ** rng.uniform(-6, 6, (400, 1))).astype(dtype)
    t = rng.integers(0, 400, size=(40000, 3)).astype(np.int32)  # several chunks
    assert np.array_equal(triangle_cross(v, t), _old_triangle_cross(v, t))
    assert np.array_equal(triangle_cross(v, t.astype(np.float64)), _old_triangle_cross(v, t))
    cross, norm = triangle_cross(v, t, with_norm=True)
    assert np.array_equal(cross, _old_triangle_cross(v, t))
    assert np.array_equal(norm, np.linalg.norm(_old_triangle_cross(v, t), axis=1))


def test_triangle_offsets_are_the_per_triangle_maxima():
    from opal_diffraction.core.render.prepare import triangle_offsets

    rng = np.random.default_rng(4)
    v = (rng.normal(size=(500, 3)) * 100).astype(np.float32)
    t = rng.integers(0, 500, size=(2000, 3)).astype(np.int32)
    ref = (1e-5 + 4e-7 * np.abs(v[t]).max(axis=(1, 2))).astype(np.float32)  # the formula it replaces
    assert np.array_equal(triangle_offsets(v, t, 1e-5), ref)


def test_chunked_corner_normals_equal_the_whole_array_formula(monkeypatch):
    from opal_diffraction.core.scene import validation as scene_mod
    from opal_diffraction.core.util.geometry import triangle_normals

    rng = np.random.default_rng(5)
    v = rng.normal(size=(300, 3)).astype(np.float32)
    t = rng.integers(0, 300, size=(1000, 3)).astype(np.int32)
    cn = rng.normal(size=(1000, 3, 3)).astype(np.float32)
    cn[::7, 1] = 0  # zero normals: the face normal is used
    # the formula over the whole array (what the chunked loop replaced)
    c64 = cn.astype(np.float64)
    length = np.linalg.norm(c64, axis=2, keepdims=True)
    zero = ~(length > 1e-30)
    face = triangle_normals(v, t)
    ref = (np.where(zero, face[:, None, :], c64) / np.where(zero, 1.0, length)).astype(np.float32)
    monkeypatch.setattr(scene_mod, "_ROWS_PER_CHUNK", 97)
    warns = []
    got = scene_mod._validate_corner_normals(cn, v, t, warns)
    assert np.array_equal(got, ref)
    # degenerate triangles (a repeated vertex) have no face normal and are not counted
    n_zero = sum(1 for i in range(0, 1000, 7) if len(set(t[i])) == 3)
    assert warns == [f"{n_zero} zero shading normal(s): their triangles' face normals are used there"]


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf, 1e39, -5e20, -1e-3])
def test_fast_range_check_agrees_with_the_full_one(bad):
    from opal_diffraction.core.scene.checks import FLOAT32_MAX, within as _within

    rng = np.random.default_rng(6)
    a = rng.normal(size=(1000, 3))
    assert _within(a) and _within(a.astype(np.float32))
    a[617, 2] = bad
    full = bool(np.isfinite(a).all() and np.abs(a).max() <= FLOAT32_MAX)
    assert _within(a) == full
    assert _within(a, limit=1e20) == (full and np.abs(a).max() <= 1e20)
    assert _within(a, nonneg=True) is False  # normal samples are negative somewhere
    assert _within(np.abs(a), nonneg=True) == (np.isfinite(a).all() and np.abs(a).max() <= FLOAT32_MAX)


def _old_triangle_tangents(tri_normal, tri_tangent):
    """gratings.triangle_tangents as it was: every candidate over all rows."""
    n = np.asarray(tri_normal, np.float64)
    given = np.asarray(tri_tangent, np.float64).reshape(-1, 3)
    if len(given) != len(n):
        given = np.zeros((len(n), 3))
    out = np.zeros((len(n), 3))
    todo = np.ones(len(n), bool)
    for cand in (given, np.array([[1.0, 0, 0]]), np.array([[0.0, 1, 0]])):
        c = np.broadcast_to(cand, (len(n), 3))
        proj = c - np.sum(c * n, axis=1, keepdims=True) * n
        norm = np.linalg.norm(proj, axis=1)
        ok = todo & (norm > 1e-6)
        out[ok] = proj[ok] / norm[ok, None]
        todo &= ~ok
    return out.astype(np.float32)


def test_triangle_tangents_equal_the_all_rows_version():
    from opal_diffraction.core.gratings.radiance import triangle_tangents

    rng = np.random.default_rng(7)
    n = rng.normal(size=(3000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n[:200] = (1, 0, 0)        # normal along X: X projects to zero, Y is used
    n[200:300] = (0, 0, 1)
    given = rng.normal(size=(3000, 3)).astype(np.float32)
    given[::3] = 0             # no tangent given
    given[1::7] = n[1::7]      # given along the normal: falls back to X (then Y)
    for g in (given, np.zeros((0, 3), np.float32)):
        got = triangle_tangents(n, g)
        assert got.dtype == np.float32
        assert np.array_equal(got, _old_triangle_tangents(n, g))


def test_smooth_corner_tangents_equal_the_float64_version():
    from opal_diffraction.core.gratings import directions as gd
    from opal_diffraction.core.util.geometry import triangle_normals
    from opal_diffraction.core.gratings.radiance import triangle_tangents
    from grating_frames import corner_tangents_by_loop

    v, t = primitives.icosphere((0, 0, 0), 1.0, 3)
    n = triangle_normals(v, t)
    tt = triangle_tangents(n, np.tile([[1.0, 0.2, 0]], (len(t), 1)))
    mat = (np.arange(len(t)) % 3).astype(np.int32)
    grating = mat != 0
    got = gd.smooth_corner_tangents(v, t, n, tt, mat, grating)
    # independently: the corner-angle-weighted, sign-aligned mean over the same-material
    # grating corners at each vertex within the tangent and normal angles (one loop per corner)
    ang = gd._corner_angles(np.asarray(v, np.float64), np.asarray(t, np.int64))
    ref = corner_tangents_by_loop(t, n, tt, mat, grating, ang)
    assert got.dtype == np.float32
    assert np.allclose(got, ref.astype(np.float32), rtol=0, atol=1e-6)
    assert np.array_equal(got[~grating], np.repeat(tt[~grating, None, :], 3, axis=1))


def test_prepare_uses_validations_cross_products_for_its_normals():
    from opal_diffraction.core.util.geometry import triangle_normals
    from opal_diffraction.core.render.prepare import prepare
    from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
    from opal_diffraction.core.scene.validation import validate
    from opal_diffraction.core.scene.settings import RenderSettings

    v, t = primitives.icosphere((0, 0, 1), 1.0, 2)
    v = np.concatenate([v, [[5, 5, 5]]])
    t = np.concatenate([t, [[0, 1, 1], [len(v) - 1, 2, 2]]])  # two degenerate triangles, dropped
    sc = Scene(vertices=v.astype(np.float32), triangles=t.astype(np.int32), tri_material=np.zeros(len(t), np.int32),
               materials=Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)}]))
    sc.lights = Lights.from_list([{"kind": "POINT", "position": (0, 0, 4), "power": 10.0}])
    sc.camera = Camera.look_at((0, -5, 2), (0, 0, 1), width=8, height=8)
    checked = validate(sc)  # the products are returned, not attached to the clean scene
    assert checked.triangle_cross.shape == (len(t) - 2, 3) and checked.triangle_cross_norm.shape == (len(t) - 2,)
    p = prepare(sc, RenderSettings(samples=1, light_paths=0))
    assert np.array_equal(p.tri_normal, triangle_normals(p.scene.vertices, p.scene.triangles).astype(np.float32))
    assert len(p.tri_normal) == len(t) - 2
