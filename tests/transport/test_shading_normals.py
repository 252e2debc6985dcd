"""Shading normals (docs/physics.md section 4.6): the scene model, the specular fix-ups, and a
smooth-shaded glass ball's caustic against exact ray tracing through an ideal sphere.

The caustic test is the physics one: parallel light through a tessellated 64 x 32 UV sphere
(n = 1.5) onto a floor at the paraxial focus f = n R / (2 (n - 1)) (docs/physics.md section 4.3).
The reference traces parallel rays through an analytic sphere in NumPy (Snell's law and the
unpolarised Fresnel equations at both interfaces, with the internal reflections), independently
of the renderer's optics; it is bracketed by the same computation for the sphere of the mesh's
smallest facet distance (a tessellated surface lies between the two), widened by the Monte Carlo
noise of the path count. The flat-faceted sphere falls outside that bracket.
"""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.util.geometry import triangle_normals
from opal_diffraction.core.integrators.light.light_pass import run_light_pass
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.npz import load_scene, save_scene
from opal_diffraction.core.scene.validation import validate
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.transport.walker import Rays, SpecularWalker, valid_specular_normal
from opal_diffraction.core.render.plan import plan_render


def smooth_sphere(center, radius, segments, rings):
    v, t = primitives.uv_sphere(center, radius, segments, rings)
    return v, t, (v - np.asarray(center, np.float64)) / radius


def base_scene(*rows):
    s = Scene(materials=Materials.from_list(list(rows)))
    s.camera = Camera(width=4, height=4)
    return s


# ============================================================================ the scene model
def test_add_mesh_per_vertex_and_per_corner_normals_and_flat_meshes_in_between():
    s = base_scene({})
    s.add_mesh(*primitives.box((0, 0, 0), 1.0), 0)                       # flat, before
    v, t, nrm = smooth_sphere((0, 0, 3), 1.0, 8, 4)
    s.add_mesh(v, t, 0, normals=nrm)                                      # per vertex
    s.add_mesh(*primitives.quad((0, 0, -2), (1, 0, 0), (0, 1, 0)), 0)     # flat, after
    tilted = np.tile(np.array([0.0, 0.6, 0.8], np.float32), (2, 3, 1))
    s.add_mesh(*primitives.quad((0, 0, -3), (1, 0, 0), (0, 1, 0)), 0, normals=tilted)  # per corner
    cn = s.corner_normals
    assert cn.shape == (len(s.triangles), 3, 3) and cn.dtype == np.float32
    face = triangle_normals(s.vertices, s.triangles)
    np.testing.assert_allclose(cn[:12], np.repeat(face[:12, None], 3, axis=1), atol=1e-6)
    np.testing.assert_allclose(cn[12:12 + len(t)], nrm[t], atol=1e-6)
    np.testing.assert_allclose(cn[12 + len(t):14 + len(t)], [[[0, 0, 1]] * 3] * 2, atol=1e-6)
    np.testing.assert_allclose(cn[-2:], tilted)
    with pytest.raises(SceneError, match="normals must have shape"):
        s.add_mesh(v, t, 0, normals=np.zeros((5, 3)))


def test_a_flat_scene_has_no_corner_normals_and_prepares_to_none():
    s = base_scene({})
    s.add_mesh(*primitives.box((0, 0, 0), 1.0), 0)
    assert s.corner_normals.shape == (0, 3, 3)
    assert prepare(s).corner_normals is None


def test_validation_normalises_falls_back_to_the_face_normal_and_keeps_step_with_dropped_triangles():
    s = base_scene({})
    v, t = primitives.quad((0, 0, 0), (1, 0, 0), (0, 1, 0))
    s.add_mesh(v, t, 0, normals=np.array([[0, 0, 2.0], [0, 1, 1], [0, 0, 0], [1, 0, 1]]))
    # a degenerate triangle (dropped) between two good ones, with its own normals
    s.vertices = np.concatenate([s.vertices, [[5, 5, 5]]]).astype(np.float32)
    s.triangles = np.array([[0, 1, 2], [4, 4, 4], [0, 2, 3]], np.int32)
    s.tri_material = np.zeros(3, np.int32)
    s.corner_normals = np.stack([s.corner_normals[0], np.full((3, 3), 7.0), s.corner_normals[1]])
    checked = validate(s)
    clean, warns = checked.scene, checked.warnings
    assert len(clean.triangles) == 2 and clean.corner_normals.shape == (2, 3, 3)
    np.testing.assert_allclose(np.linalg.norm(clean.corner_normals, axis=2), 1, atol=1e-6)
    np.testing.assert_allclose(clean.corner_normals[0, 0], [0, 0, 1])
    np.testing.assert_allclose(clean.corner_normals[0, 1], [0, 2**-0.5, 2**-0.5], atol=1e-6)
    np.testing.assert_allclose(clean.corner_normals[0, 2], [0, 0, 1])  # the zero normal: face normal
    np.testing.assert_allclose(clean.corner_normals[1, 0], [0, 0, 1])
    assert sum("zero shading normal" in w for w in warns) == 1
    assert prepare(s).corner_normals.shape == (2, 3, 3)


@pytest.mark.parametrize("bad, message", [
    (np.full((2, 3, 3), np.nan), "NaN or infinite"),
    (np.full((2, 3, 3), 1e39), "NaN or infinite|overflows"),
    (np.ones((3, 3, 3)), "one \\(3, 3\\) entry per triangle"),
    (np.ones((2, 3)), "shape"),
    (np.array([["a"] * 3] * 3 * 2).reshape(2, 3, 3), "must hold numbers"),
])
def test_bad_corner_normals_are_one_line_scene_errors(bad, message):
    s = base_scene({})
    s.add_mesh(*primitives.quad((0, 0, 0), (1, 0, 0), (0, 1, 0)), 0)
    s.corner_normals = bad
    with pytest.raises(SceneError, match=message) as e:
        validate(s)
    assert "\n" not in str(e.value)


def test_corner_normals_survive_the_npz_and_older_files_load_flat(tmp_path):
    s = base_scene({})
    v, t, nrm = smooth_sphere((0, 0, 0), 1.0, 8, 4)
    s.add_mesh(v, t, 0, normals=nrm)
    save_scene(s, tmp_path / "a.npz")
    back = load_scene(tmp_path / "a.npz")
    np.testing.assert_array_equal(back.corner_normals, s.corner_normals)
    with np.load(tmp_path / "a.npz") as z:  # a file written before shading normals existed
        old = {k: z[k] for k in z.files if k != "corner_normals"}
    np.savez(tmp_path / "old.npz", **old)
    flat = load_scene(tmp_path / "old.npz")
    assert flat.corner_normals.shape == (0, 3, 3)
    assert prepare(flat).corner_normals is None


def test_prepared_corner_normals_are_read_only_and_part_of_the_reuse_identity():
    s = base_scene({}, {"kind": "DIELECTRIC"})
    s.add_mesh(*primitives.quad((0, 0, -2), (4, 0, 0), (0, 4, 0)), 0)
    v, t, nrm = smooth_sphere((0, 0, 0), 1.0, 8, 4)
    s.add_mesh(v, t, 1, normals=nrm)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": (0, 0, -1), "power": 1.0}])
    a = prepare(s)
    assert not a.corner_normals.flags.writeable
    same = prepare(s, reuse=a)
    assert same.key == a.key and same.corner_normals is a.corner_normals
    other = Scene(**{**s.__dict__, "corner_normals": s.corner_normals[:, [1, 2, 0]]})
    b = prepare(other, reuse=a)
    assert b.key != a.key            # the light pass bends light with them: its result is stale
    assert b.accel is a.accel        # the ray caster does not depend on them
    np.testing.assert_array_equal(b.corner_normals, np.asarray(validate(other).scene.corner_normals))


# ============================================================================ transport
def one_bounce(scene, o, d, **kw):
    """(prepared, rays after one specular interaction, the hits, the incoming directions of the
    rays that hit) for rays (o, d): SpecularWalker's own step, one material kind (order kept)."""
    prepared = prepare(scene, RenderSettings(**kw))
    walker = SpecularWalker(prepared, np.random.default_rng(1))
    b = len(o)
    rays = Rays(np.asarray(o, np.float32), np.asarray(d, np.float32), np.arange(b), None, None,
                np.zeros(b, np.int32), np.zeros(b))
    h = prepared.accel.intersect(rays.o, rays.d)
    keep = h.prim >= 0
    hit = walker.hit_info(rays.take(keep), h.t[keep], h.prim[keep], h.u[keep], h.v[keep])
    out, _, _ = walker._step(rays, None, walker.rng)
    return prepared, out, hit, rays.d[keep].astype(np.float64)


def tilted_mirror(flat=False):
    """A mirror triangle in z = 0 whose corner normals lean 20 deg towards -x, +x and +y."""
    s = base_scene({"kind": "MIRROR", "color": (1, 1, 1)})
    v = np.array([[-1, -1, 0], [1, -1, 0], [0, 1, 0]], np.float64)
    a = np.radians(20)
    nrm = np.array([[-np.sin(a), 0, np.cos(a)], [np.sin(a), 0, np.cos(a)], [0, np.sin(a), np.cos(a)]])
    s.add_mesh(v, [[0, 1, 2]], 0, normals=None if flat else nrm)
    return s, v, nrm


def test_a_mirror_with_tilted_corner_normals_reflects_about_the_interpolated_normal():
    s, v, nrm = tilted_mirror()
    rng = np.random.default_rng(0)
    # points inside the triangle, rays coming down steeply (no fix-up needed: checked below)
    w = rng.dirichlet((2, 2, 2), 200)
    p = w @ v
    d = np.stack([rng.normal(0, 0.1, 200), rng.normal(0, 0.1, 200), -np.ones(200)], 1)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    _, out, hit, _ = one_bounce(s, p - 3 * d, d)
    n = w @ nrm  # Phong interpolation of the corner normals at the hit point
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    expected = d - 2 * np.sum(d * n, axis=1, keepdims=True) * n
    assert np.all(expected[:, 2] > 0.05)  # all well above the surface: the plain law of reflection
    np.testing.assert_allclose(out.d, expected, atol=2e-5)
    np.testing.assert_allclose(hit.ns, n, atol=2e-5)
    np.testing.assert_array_equal(hit.ng, np.tile([0, 0, 1], (200, 1)))
    # the same triangle shaded flat reflects about its face
    _, out_flat, hit_flat, _ = one_bounce(tilted_mirror(flat=True)[0], p - 3 * d, d)
    assert hit_flat.ns is hit_flat.ng
    np.testing.assert_allclose(out_flat.d, d * [1, 1, -1], atol=1e-6)


def test_ns_faces_the_incoming_ray_with_ng_from_either_side():
    s, v, nrm = tilted_mirror()
    p = np.array([[0.0, -0.2, 0.0]] * 2)
    d = np.array([[0, 0, -1.0], [0, 0, 1.0]])
    _, _, hit, _ = one_bounce(s, p - 2 * d, d)
    assert list(hit.front) == [True, False]
    assert np.all(np.sum(hit.ns * hit.ng, axis=1) > 0.9)
    np.testing.assert_allclose(hit.ns[0], -hit.ns[1], atol=1e-6)
    assert hit.ns.dtype == np.float32 and hit.ns.shape == (2, 3)


def test_a_bad_custom_normal_pointing_inwards_is_put_on_the_surfaces_side():
    s = base_scene({"kind": "MIRROR"})
    s.add_mesh(*primitives.quad((0, 0, 0), (2, 0, 0), (0, 2, 0)), 0, normals=np.tile([0.0, 0.0, -1.0], (4, 1)))
    _, out, hit, _ = one_bounce(s, [[0.1, 0.2, 1.0]], [[0, 0, -1.0]])
    np.testing.assert_allclose(hit.ns, [[0, 0, 1]])
    np.testing.assert_allclose(out.d, [[0, 0, 1]], atol=1e-6)


def test_valid_specular_normal_lifts_the_reflection_just_above_the_surface():
    """Cycles' rule: R . ng >= t = min(0.9 wo . ng, 0.01); where it bends, R . ng = t exactly,
    the new normal lies between ns and ng in their plane, and a valid ns is left alone."""
    rng = np.random.default_rng(3)
    b = 20000
    ng = np.tile([0.0, 0.0, 1.0], (b, 1))
    wo = rng.normal(size=(b, 3))
    wo[:, 2] = np.abs(wo[:, 2]) * rng.random(b) ** 3  # many grazing
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    ns = rng.normal(size=(b, 3)) * [1, 1, 0.3]
    ns[:, 2] = np.abs(ns[:, 2]) + 0.05
    ns /= np.linalg.norm(ns, axis=1, keepdims=True)
    fixed = valid_specular_normal(wo, ng, ns)
    r = 2 * np.sum(fixed * wo, axis=1, keepdims=True) * fixed - wo
    t = np.minimum(0.9 * wo[:, 2], 0.01)
    r0 = 2 * np.sum(ns * wo, axis=1, keepdims=True) * ns - wo
    bent = r0[:, 2] < t
    assert 0.2 < bent.mean() < 0.9  # the test exercises both branches
    np.testing.assert_allclose(np.linalg.norm(fixed, axis=1), 1, atol=1e-6)
    np.testing.assert_array_equal(fixed[~bent], ns[~bent])
    np.testing.assert_allclose(r[bent, 2], t[bent], atol=2e-6)
    assert np.all(np.sum(fixed * wo, axis=1) > -1e-7)  # the incoming ray is in front of the new normal
    # in the plane of ns and ng, between them (rotated towards ng, not past it)
    plane = np.cross(ns[bent], ng[bent])
    assert np.abs(np.sum(fixed[bent] * plane, axis=1)).max() < 1e-6
    assert np.all(fixed[bent, 2] >= ns[bent, 2] - 1e-7)


def test_glass_with_bent_normals_never_leaks_nor_kills_a_ray():
    """A coarse smooth glass ball, rays from all sides at all angles: each ray leaves its
    interaction on the side its new direction points to (reflected rays stay, refracted rays
    cross the geometric surface), and none is dropped by the fix-ups."""
    s = base_scene({"kind": "DIELECTRIC", "ior": 1.8})
    v, t, nrm = smooth_sphere((0, 0, 0), 1.0, 6, 3)  # very coarse: normals far from the faces'
    s.add_mesh(v, t, 0, normals=nrm)
    rng = np.random.default_rng(5)
    b = 40000
    target = rng.normal(size=(b, 3)) * 0.4
    d = rng.normal(size=(b, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = target - 4 * d
    _, out, hit, d_in = one_bounce(s, o, d)
    assert len(out) == len(hit.p) > 0.5 * b
    ng = hit.ng.astype(np.float64)
    leaves = np.sum(out.d * ng, axis=1)
    offset = np.sum((out.o - hit.p) * ng, axis=1)
    assert np.all(np.abs(leaves) > 0) and np.all(np.sign(leaves) == np.sign(offset))
    assert np.all(np.sum(hit.ns * ng, axis=1) > 0)
    # the fix-ups were exercised: about ns itself, some mirror directions point below the surface
    naive = d_in - 2 * np.sum(d_in * hit.ns, axis=1, keepdims=True) * hit.ns
    assert np.mean(np.sum(naive * ng, axis=1) < 0) > 0.01


# ============================================================================ the caustic
N_IOR, RADIUS = 1.5, 1.0
FOCUS = N_IOR * RADIUS / (2 * (N_IOR - 1))  # the paraxial focus from the centre
RADII = (0.01, 0.02, 0.05)
CAUSTIC_PATHS = 1_000_000


def fresnel_unpolarised(cos_i, n1, n2):
    """(R, cos_t): the Fresnel equations (s and p amplitudes squared, averaged) and Snell's law."""
    sin2_t = (n1 / n2) ** 2 * (1 - cos_i**2)
    cos_t = np.sqrt(np.maximum(1 - sin2_t, 0))
    rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    rp = (n2 * cos_i - n1 * cos_t) / (n2 * cos_i + n1 * cos_t)
    return np.where(sin2_t >= 1, 1.0, 0.5 * (rs**2 + rp**2)), cos_t


def ideal_sphere_landings(n, radius, z_floor, m=1_000_000, internal=8):
    """Parallel rays (irradiance 1, travelling -z) through an analytic sphere at the origin:
    where on the floor z = z_floor they land, with what flux. Exact tracing in the meridional
    plane of each ray (height h area-uniform over the disk), rotated to a golden-angle azimuth;
    every exit after 0..internal-1 internal reflections that heads down is kept."""
    h = radius * np.sqrt((np.arange(m) + 0.5) / m)
    w = np.full(m, np.pi * radius**2 / m)
    p = np.stack([h, np.sqrt(radius**2 - h**2)], 1)   # (x, z) entry points
    d = np.tile([0.0, -1.0], (m, 1))
    nrm = p / radius
    cos_i = -np.sum(d * nrm, axis=1)
    refl, cos_t = fresnel_unpolarised(cos_i, 1.0, n)
    d = d / n + (cos_i / n - cos_t)[:, None] * nrm
    w = w * (1 - refl)
    xs, ws = [], []
    for _ in range(internal):  # loop over internal reflections (a handful)
        p = p - 2 * np.sum(p * d, axis=1)[:, None] * d  # the chord to the next interface
        nrm = p / radius
        cos_i = np.sum(d * nrm, axis=1)
        refl, cos_t = fresnel_unpolarised(cos_i, n, 1.0)
        out = n * d + (cos_t - n * cos_i)[:, None] * nrm
        down = out[:, 1] < 0
        s = (z_floor - p[down, 1]) / out[down, 1]
        xs.append(p[down, 0] + s * out[down, 0])
        ws.append((w * (1 - refl))[down])
        w = w * refl
        d = d - 2 * cos_i[:, None] * nrm
    x, wt = np.concatenate(xs), np.concatenate(ws)
    phi = 2 * np.pi * ((np.arange(len(x)) * 0.6180339887498949) % 1.0)
    return np.stack([x * np.cos(phi), x * np.sin(phi)], 1), wt


def ball_lens_scene(smooth):
    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
                                             {"kind": "DIELECTRIC", "ior": N_IOR}]))
    s.add_mesh(*primitives.quad((0, 0, -FOCUS), (0.6, 0, 0), (0, 0.6, 0)), material=0)
    v, t, nrm = smooth_sphere((0, 0, 0), RADIUS, 64, 32)
    s.add_mesh(v, t, material=1, normals=nrm if smooth else None)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": (0, 0, -1), "power": 1.0}])
    s.camera = Camera(width=4, height=4)
    return s


def encircled(ctx, illum, points, weights):
    """Flux within each of RADII of the axis, counted by element (an element is in when its
    centre is): ours from the map, and the reference's landings binned into the same elements."""
    tri, bu, bv = illum.layout.barycentric_centres()
    corners = np.asarray(ctx.scene.vertices, np.float64)[np.asarray(ctx.scene.triangles)]
    centre = np.einsum("e,ej->ej", 1 - bu - bv, corners[tri, 0]) + bu[:, None] * corners[tri, 1] + bv[:, None] * corners[tri, 2]
    dist = np.hypot(centre[:, 0], centre[:, 1])
    ours = illum.flux[:, 0] / ctx.lights.spectrum[0][0]  # no dispersion: every wavelength alike
    # the reference's points on the floor's two triangles (0 and 1): barycentrics, then elements
    elem = np.full(len(points), -1)
    for prim in (0, 1):
        a, b, c = corners[prim, :, :2]
        m = np.stack([b - a, c - a], 1)
        uv = np.linalg.solve(m, (points - a).T).T
        inside = (uv >= 0).all(axis=1) & (uv.sum(axis=1) <= 1) & (elem < 0)
        idx, ok = illum.layout.index(np.full(inside.sum(), prim), uv[inside, 0], uv[inside, 1], np.ones(inside.sum(), bool))
        elem[np.flatnonzero(inside)[ok]] = idx[ok]
    hit = elem >= 0
    ref = np.bincount(elem[hit], weights=weights[hit], minlength=illum.layout.total)
    return (np.array([ours[dist < r].sum() for r in RADII]), np.array([ref[dist < r].sum() for r in RADII]))


@pytest.fixture(scope="module")
def caustics():
    out = {}
    for smooth in (True, False):
        ctx = prepare(ball_lens_scene(smooth), RenderSettings(light_paths=CAUSTIC_PATHS, element_size=0.002,
                                                              wavelength_step=100.0, max_bounces=16))
        out[smooth] = ctx, run_light_pass(ctx, plan=plan_render(ctx))
    return out


@pytest.mark.slow
def test_smooth_glass_ball_caustic_matches_exact_tracing_through_an_ideal_sphere(caustics):
    ctx, lp = caustics[True]
    v = np.asarray(ctx.scene.vertices, np.float64)[np.asarray(ctx.scene.triangles)[ctx.tri_material == 1]]
    # the facets' smallest distance from the centre: the tessellated ball lies between the spheres
    # of this radius and RADIUS (its normals are exactly radial: Phong interpolation of v / R)
    fn = triangle_normals(v.reshape(-1, 3), np.arange(len(v) * 3).reshape(-1, 3))
    r_in = float(np.min(np.abs(np.sum(fn * v[:, 0], axis=1))))
    assert 0.99 < r_in < RADIUS
    ours, outer = encircled(ctx, lp.caustics, *ideal_sphere_landings(N_IOR, RADIUS, -FOCUS))
    _, inner = encircled(ctx, lp.caustics, *ideal_sphere_landings(N_IOR, r_in, -FOCUS))
    # Monte Carlo noise: each path carries E * pi R_b^2 / N (R_b: the caster's bounding sphere),
    # the count landing within r is Poisson: sigma = sqrt(flux * weight)
    r_b = float(ctx.light_targets.objects.radius[0])
    sigma = np.sqrt(ours * np.pi * r_b**2 / lp.stats["light_paths"])
    z = 4.0  # three radii, two tests each: 4 sigma keeps the false-alarm rate far below 1e-3
    lo, hi = np.minimum(inner, outer) - z * sigma, np.maximum(inner, outer) + z * sigma
    print("ideal sphere R", outer, "r_in", inner, "smooth", ours, "sigma", sigma)
    assert np.all((ours >= lo) & (ours <= hi)), (ours, inner, outer, sigma)
    # and within 3 % of the ideal ball itself
    np.testing.assert_allclose(ours, outer, rtol=0.03)


@pytest.mark.slow
def test_the_flat_faceted_ball_does_not_match(caustics):
    ctx, lp = caustics[False]
    ours, outer = encircled(ctx, lp.caustics, *ideal_sphere_landings(N_IOR, RADIUS, -FOCUS))
    smooth_ctx, smooth_lp = caustics[True]
    smooth, _ = encircled(smooth_ctx, smooth_lp.caustics, *ideal_sphere_landings(N_IOR, RADIUS, -FOCUS, m=1000))
    print("flat", ours, "smooth", smooth, "ideal", outer)
    # the facets smear the focus: far less flux near the axis (measured: 60 % less within 1 cm)
    assert ours[0] < 0.6 * outer[0] and ours[1] < 0.85 * outer[1] and ours[2] < 0.97 * outer[2]
    assert np.all(smooth > ours)


# ============================================================================ the eye pass
def glass_ball_before_stripes(smooth):
    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE", "color": (0.9, 0.9, 0.9)},
                                             {"kind": "DIFFUSE", "color": (0.05, 0.05, 0.05)},
                                             {"kind": "DIELECTRIC", "ior": 1.5}]))
    for i in range(-4, 4):  # a striped wall behind the ball
        s.add_mesh(*primitives.quad((i * 0.5 + 0.25, 3, 0), (0.5, 0, 0), (0, 0, 4)), material=i % 2)
    v, t, nrm = smooth_sphere((0, 0, 0), 1.0, 24, 12)
    s.add_mesh(v, t, material=2, normals=nrm if smooth else None)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": (0, 1, 0), "power": 3.0}])
    s.camera = Camera.look_at((0, -6, 0), (0, 0, 0), kind="ORTHO", ortho_scale=2.4, width=24, height=24)
    return s


@pytest.mark.slow
def test_a_smooth_glass_ball_renders_differently_from_the_flat_one():
    st = dict(samples=64, light_paths=0, threads=1, wavelength_step=20.0)
    smooth = render(glass_ball_before_stripes(True), RenderSettings(seed=0, **st)).rgb
    flat = render(glass_ball_before_stripes(False), RenderSettings(seed=0, **st)).rgb
    flat2 = render(glass_ball_before_stripes(False), RenderSettings(seed=1, **st)).rgb
    # E[(smooth - flat)^2] = (their difference)^2 + 2 sigma^2, E[(flat - flat2)^2] = 2 sigma^2
    # (sigma: the per-pixel Monte Carlo noise; flat2 is flat with another seed)
    noise = np.mean((flat - flat2) ** 2)
    diff = np.mean((smooth - flat) ** 2)
    print("mean squared difference smooth - flat", diff, "flat - flat (two seeds)", noise)
    assert diff > 4 * noise > 0


def diffuse_ball(smooth, sun=(0.3, 1.0, -0.4)):
    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)}]))
    v, t, nrm = smooth_sphere((0, 0, 0), 1.0, 32, 16)
    s.add_mesh(v, t, material=0, normals=nrm if smooth else None)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": sun, "power": 2.0}])
    s.camera = Camera.look_at((0, -6, 0), (0, 0, 0), kind="ORTHO", ortho_scale=2.2, width=64, height=64)
    return s


def scanline_luminance(scene):
    rgb = render(scene, RenderSettings(samples=16, light_paths=0, threads=1, wavelength_step=20.0)).rgb
    y = rgb @ np.array([0.2126, 0.7152, 0.0722])
    return y[32]  # the row through the centre (z = 0): the sphere spans x in [-1, 1]


def test_a_smooth_diffuse_ball_shows_no_facets():
    """Lambert under a sun: L = rho / pi * E * max(0, n . l). Along the middle row n = (x, -sqrt(1
    - x^2), 0); where n . l > 0.2 and |x| < 0.8 its second difference over a pixel step dx is
    bounded by max |L''| dx^2 (about (rho E / pi) dx^2 / (1 - x^2)^1.5). The flat ball's facets
    make steps an order of magnitude above that."""
    sun = np.array([0.3, 1.0, -0.4])
    l = -sun / np.linalg.norm(sun)
    dx = 2.2 / 64
    x = (np.arange(64) + 0.5) * dx - 1.1
    nx, ny = x, -np.sqrt(np.maximum(1 - x * x, 0))
    cos = nx * l[0] + ny * l[1]
    ok = (np.abs(x) < 0.8) & (cos > 0.2)
    ok = ok & np.roll(ok, 1) & np.roll(ok, -1)
    scale = 0.5 / np.pi * 2.0  # rho E / pi (the film's units may differ by a constant: fitted below)
    smooth = scanline_luminance(diffuse_ball(True, sun))
    flat = scanline_luminance(diffuse_ball(False, sun))
    # the luminance follows Lambert's law (so the bound is in the right units)
    expected = scale * np.maximum(cos, 0)
    ratio = smooth[ok] / expected[ok]
    assert np.ptp(ratio) < 0.05 * ratio.mean()
    bound = ratio.mean() * scale * dx**2 / (1 - 0.8**2) ** 1.5
    d2_smooth = np.abs(smooth[2:] - 2 * smooth[1:-1] + smooth[:-2])[ok[1:-1]]
    d2_flat = np.abs(flat[2:] - 2 * flat[1:-1] + flat[:-2])[ok[1:-1]]
    print("max second difference: smooth", d2_smooth.max(), "flat", d2_flat.max(), "bound", bound)
    assert d2_smooth.max() < 2 * bound
    assert d2_flat.max() > 10 * bound
