"""Alias-free gratings in space (docs/physics.md section 3.7): the footprint mean of the
Fraunhofer pattern against brute-force quadrature, ray differentials against the analytic pixel
footprint, smooth grating directions on a faceted disc, and the CD through the renderer."""

import numpy as np
import pytest

from opal_diffraction._scripts import load_example
from opal_diffraction.core.sampling import footprint
from opal_diffraction.core.gratings.kernel import fraunhofer_pattern_footprint, multislit, sinc2
from opal_diffraction.core.gratings.directions import smooth_corner_tangents, tangents_at
from opal_diffraction.core.gratings.radiance import triangle_tangents
from opal_diffraction.core.scene.model import Camera

D, A = 1600.0, 800.0
LAM0, LAM1 = 550.0, 555.0


def brute_box_mean(u, v, du, dv, n, length, per_peak=8):
    """Mean of P over u in [u - du/2, u + du/2], v likewise and lambda in [LAM0, LAM1] (uniform in
    lambda), by midpoint quadrature on grids of ``per_peak`` points per peak width of each factor
    (P is separable in u and v at fixed lambda, so the 3-D mean is the lambda-mean of the product
    of the u- and v-means). Also returns the largest u-mean x v-mean over the bin's wavelengths
    (the brightest the box gets in this bin: the scale an absolute error is judged against)."""
    def count(arg_range, width, lo=64, hi=60000):
        return int(np.clip(per_peak * arg_range / width, lo, hi))
    dk = 1 / LAM0 - 1 / LAM1
    nl = count(np.pi * D * (abs(u) + du) * dk * n / np.pi + np.pi * length * (abs(v) + dv) * dk / np.pi, 1.0, 400, 8000)
    nu = count(np.pi * D * du / LAM0, np.pi / n) if du else 1
    nv = count(np.pi * length * dv / LAM0, np.pi) if dv else 1
    lam = LAM0 + (np.arange(nl) + 0.5) / nl * (LAM1 - LAM0)
    uu = u + du * ((np.arange(nu) + 0.5) / nu - 0.5)
    vv = v + dv * ((np.arange(nv) + 0.5) / nv - 0.5)
    prod = np.empty(nl)
    step = max(1, int(4e6 // (nu + nv)))
    for i in range(0, nl, step):  # chunks of wavelengths (memory), not rays
        lc = lam[i:i + step, None]
        um = (sinc2(np.pi * A * uu[None] / lc) * multislit(np.pi * D * uu[None] / lc, n)).mean(axis=1)
        vm = sinc2(np.pi * length * vv[None] / lc).mean(axis=1)
        prod[i:i + step] = um * vm
    return prod.mean(), prod.max()


# (N, L nm, u, du, v, dv): the zeroth order (u = 0) under a footprint much wider than it, the
# first order (u = lambda / D) and its edge, between orders, the slit-length peak and its tails
CASES = [
    (1000, 1e6, 0.0, 1e-3, 0.0, 1e-3),
    (1000, 1e6, 1e-4, 2e-4, 2e-4, 5e-4),
    (1000, 1e6, 550 / 1600, 1e-3, 0.0, 1e-3),
    (1000, 1e7, 550 / 1600 + 3e-4, 2e-5, 1e-3, 1e-5),
    (1000, 1e7, 0.2, 5e-4, 2e-4, 5e-4),
    (100000, 1e6, 0.0, 1e-3, 2e-4, 5e-4),
    (100000, 1e7, 550 / 1600 + 3e-4, 2e-5, 0.0, 1e-3),
    (100000, 1e4, 0.2, 1e-4, 0.0, 1e-3),
    (1000000, 1e7, 0.0, 2e-4, 1e-4, 2e-4),
    (1000000, 1e6, 1e-4, 2e-4, 0.0, 1e-3),
    (1000000, 1e7, 550 / 1600 + 1e-4, 1e-6, 2e-4, 5e-4),
    (10, 1e7, 0.1, 1e-3, 1e-3, 1e-5),
]


@pytest.mark.parametrize("n, length, u, du, v, dv", CASES)
def test_footprint_mean_matches_brute_force_quadrature(n, length, u, du, v, dv):
    """docs/physics.md section 3.7: the closed-form footprint mean equals brute-force 3-D
    quadrature of P over the box (u, v, lambda).

    - With 32 parts per bin (the footprint integral alone: closed form in the wider direction,
      2 midpoint nodes in the narrower): within 0.5 % of the value plus 1e-3 of the bin's
      brightest box mean.
    - As the renderer calls it (2 parts per bin): within 1.5 % of the value plus 3 % of the
      bin's brightest box mean. The second term covers the sinc^2 tails, where the N-slit and
      slit-length factors both vary within a part and the product of their means is not the
      mean of the product (fraunhofer_pattern_binned's approximation, docs/physics.md section
      3.6; measured: 2.2 % of the brightest, at 1e-4 of the pattern's peak)."""
    ref, top = brute_box_mean(u, v, du, dv, n, length)
    args = (np.array([u]), np.array([v]), np.array([du]), np.array([dv]), np.array([LAM0, LAM1]), A, D, n, length)
    fine = fraunhofer_pattern_footprint(*args, subdivisions=32)[0, 0]
    assert abs(fine - ref) <= 0.005 * ref + 1e-3 * top, (fine, ref, top)
    got = fraunhofer_pattern_footprint(*args)[0, 0]
    assert abs(got - ref) <= 0.015 * ref + 0.03 * top, (got, ref, top)


# ------------------------------------------------------------------ ray differentials
def _camera(w=64, h=48, lens=35.0):
    return Camera(matrix=np.eye(4), lens=lens, sensor_width=36.0, width=w, height=h)  # at 0, looking down -z


def _plane_hits(o, d, p0, n):
    t = np.einsum("ij,j->i", p0 - o, n) / np.einsum("ij,j->i", d, n)
    return o + t[:, None] * d


def test_camera_footprint_on_a_parallel_plane_is_the_projected_pixel():
    """docs/physics.md section 3.7: a plane parallel to the image plane at distance Z sees every
    pixel as a Z * (sensor / lens) / width square: the position differentials are exactly that,
    at the centre and at the corners."""
    from opal_diffraction.core.sampling.camera import generate_rays
    cam = _camera()
    xs = np.array([0.5, 32.0, 63.5, 10.25])
    ys = np.array([0.5, 24.0, 47.5, 40.0])
    o, d = generate_rays(cam, xs, ys)
    rd = footprint.camera_differentials(cam, d)
    z = 2.5
    n = np.tile([0.0, 0.0, 1.0], (4, 1))
    p = _plane_hits(o.astype(np.float64), d.astype(np.float64), np.array([0, 0, -z]), n[0])
    dpx, dpy = footprint.transfer(rd, o, d, p, n)
    pixel = z * (36.0 / 35.0) / 64
    np.testing.assert_allclose(dpx, np.tile([pixel, 0, 0], (4, 1)), atol=1e-6 * pixel)
    np.testing.assert_allclose(dpy, np.tile([0, -pixel, 0], (4, 1)), atol=1e-6 * pixel)


def test_camera_footprint_on_a_tilted_plane_matches_finite_differences():
    """The footprint on a plane at 60 degrees equals the difference of neighbouring rays' hits
    (core/sampling/camera.py's projection of x + h and y + h, h = 1e-3 px) divided by h, within 1e-3."""
    from opal_diffraction.core.sampling.camera import generate_rays
    cam = _camera()
    rng = np.random.default_rng(3)
    xs, ys = rng.uniform(0, 64, 50), rng.uniform(0, 48, 50)
    n = np.array([0.0, np.sin(np.radians(60)), np.cos(np.radians(60))])
    p0 = np.array([0.0, 0.0, -3.0])
    o, d = generate_rays(cam, xs, ys)
    p = _plane_hits(o.astype(np.float64), d.astype(np.float64), p0, n)
    dpx, dpy = footprint.transfer(footprint.camera_differentials(cam, d), o, d, p, np.tile(n, (50, 1)))
    h = 0.05  # central differences: O(h^2) error, well above float32 rounding
    for dx, dy, got in ((h, 0, dpx), (0, h, dpy)):
        hits = []
        for sgn in (1, -1):
            o2, d2 = generate_rays(cam, xs + sgn * dx, ys + sgn * dy)
            hits.append(_plane_hits(o2.astype(np.float64), d2.astype(np.float64), p0, n))
        fd = (hits[0] - hits[1]) / (2 * h)
        np.testing.assert_allclose(got, fd, rtol=0, atol=1e-3 * np.abs(fd).max())


def test_flat_mirror_keeps_the_spread():
    """A flat mirror 1 m in front of the camera folds the path: the footprint on a plane 2 m
    back from the mirror (parallel to the image plane) is the pixel projected to 3 m, as if the
    mirror were not there (its x and y components unchanged)."""
    from opal_diffraction.core.sampling.camera import generate_rays
    from opal_diffraction.core.spectral.optics import reflect
    cam = _camera()
    xs, ys = np.array([0.5, 32.0, 63.5]), np.array([0.5, 24.0, 30.0])
    o, d = generate_rays(cam, xs, ys)
    rd = footprint.camera_differentials(cam, d)
    nz = np.tile([0.0, 0.0, 1.0], (3, 1))
    pm = _plane_hits(o.astype(np.float64), d.astype(np.float64), np.array([0, 0, -1.0]), nz[0])
    d2 = reflect(d, nz.astype(np.float32))
    rd2 = footprint.reflect_differentials(rd, o, d, pm, nz)
    pt = _plane_hits(pm, d2.astype(np.float64), np.array([0, 0, 1.0]), nz[0])
    dpx, dpy = footprint.transfer(rd2, pm, d2, pt, nz)
    pixel = 3.0 * (36.0 / 35.0) / 64
    np.testing.assert_allclose(dpx, np.tile([pixel, 0, 0], (3, 1)), atol=1e-5 * pixel)
    np.testing.assert_allclose(dpy, np.tile([0, -pixel, 0], (3, 1)), atol=1e-5 * pixel)


def test_refraction_differentials_match_finite_differences():
    """Refraction into glass (eta = 1 / 1.5) at a tilted plane: the direction and position
    differentials equal finite differences of Snell's law applied to neighbouring camera rays."""
    from opal_diffraction.core.sampling.camera import generate_rays
    from opal_diffraction.core.spectral.optics import refract
    cam = _camera()
    rng = np.random.default_rng(5)
    xs, ys = rng.uniform(0, 64, 40), rng.uniform(0, 48, 40)
    n = np.array([0.0, np.sin(np.radians(35)), np.cos(np.radians(35))])
    p0 = np.array([0.0, 0.0, -2.0])
    eta = np.full(40, 1 / 1.5)

    def through(x, y):
        o, d = generate_rays(cam, x, y)
        p = _plane_hits(o.astype(np.float64), d.astype(np.float64), p0, n)
        t, _ = refract(d.astype(np.float64), np.tile(n, (len(x), 1)), eta)
        return o, d, p, t

    o, d, p, t = through(xs, ys)
    rd = footprint.refract_differentials(footprint.camera_differentials(cam, d), o, d, p, np.tile(n, (40, 1)), t, eta)
    h = 0.05  # central differences
    for dx, dy, j in ((h, 0, 0), (0, h, 2)):
        _, _, p2, t2 = through(xs + dx, ys + dy)
        _, _, p1, t1 = through(xs - dx, ys - dy)
        np.testing.assert_allclose(rd[:, j], (p2 - p1) / (2 * h), atol=2e-3 * np.abs(rd[:, j]).max())
        np.testing.assert_allclose(rd[:, j + 1], (t2 - t1) / (2 * h), atol=2e-3 * np.abs(rd[:, j + 1]).max())


def test_grating_footprint_matches_finite_differences_of_u_and_v():
    """(du, dv) at a grating plane lit by a point light 0.3 m away: the hypot of the finite
    differences of u = (w_o + w_i).t and v = (w_o + w_i).s between neighbouring camera rays
    (w_i recomputed at each hit), within 1 %; and the shift to the footprint's centre is the
    change of (u, v) to the ray through the pixel centre (up to 1.5 px away) within 5 % of the
    largest change (first order)."""
    from opal_diffraction.core.sampling.camera import generate_rays
    cam = Camera.look_at((0.0, -0.3, 0.4), (0.0, 0.0, 0.0), lens=50.0, width=64, height=48)
    rng = np.random.default_rng(7)
    xs, ys = rng.uniform(5, 59, 30), rng.uniform(5, 43, 30)
    n = np.array([0.0, 0.0, 1.0])
    tt = np.tile([np.cos(0.3), np.sin(0.3), 0.0], (30, 1))
    ss = np.cross(np.tile(n, (30, 1)), tt)
    light = np.array([-0.2, 0.1, 0.2])

    def uv(x, y):
        o, d = generate_rays(cam, x, y)
        p = _plane_hits(o.astype(np.float64), d.astype(np.float64), np.zeros(3), n)
        wi = light - p
        dist = np.linalg.norm(wi, axis=1)
        wi /= dist[:, None]
        hv = -d + wi
        return o, d, p, wi, dist, np.einsum("ij,ij->i", hv, tt), np.einsum("ij,ij->i", hv, ss)

    o, d, p, wi, dist, u, v = uv(xs, ys)
    off = (rng.uniform(-1.5, 1.5, 30), rng.uniform(-1.5, 1.5, 30))  # the samples' offsets from their pixel centres
    du, dv, su, sv = footprint.grating_footprint(footprint.camera_differentials(cam, d, off), o, d, p,
                                                 np.tile(n, (30, 1)), tt, ss, wi, dist)
    # the footprint's centre: the (u, v) of the ray through the pixel centre, to first order
    _, _, _, _, _, uc, vc = uv(xs - off[0], ys - off[1])
    np.testing.assert_allclose(u + su, uc, atol=0.05 * np.abs(uc - u).max())  # second order: 3 % measured
    np.testing.assert_allclose(v + sv, vc, atol=0.05 * np.abs(vc - v).max())
    h = 0.05  # central differences
    _, _, _, _, _, ux, vx = uv(xs + h, ys)
    _, _, _, _, _, uy, vy = uv(xs, ys + h)
    _, _, _, _, _, ux1, vx1 = uv(xs - h, ys)
    _, _, _, _, _, uy1, vy1 = uv(xs, ys - h)
    np.testing.assert_allclose(du, np.hypot((ux - ux1) / (2 * h), (uy - uy1) / (2 * h)), rtol=1e-2)
    np.testing.assert_allclose(dv, np.hypot((vx - vx1) / (2 * h), (vy - vy1) / (2 * h)), rtol=1e-2)


# ------------------------------------------------------------------ smooth grating directions
def _faceted_disc(segments=64, rings=24, r_in=0.0075, r_out=0.06):
    from opal_diffraction.core.util.geometry import triangle_normals
    annulus = load_example("gratings").annulus
    v, t, tangent = annulus(r_in, r_out, segments=segments, rings=rings)
    nrm = triangle_normals(v.astype(np.float32), t)
    tri_t = triangle_tangents(nrm, tangent)
    return v, t, nrm, tri_t


def test_interpolated_tangents_are_continuous_across_facet_edges():
    """docs/physics.md section 3.1: on a 64-segment disc with radial (circular-track) tangents
    per facet, the per-triangle direction jumps by the facet angle (5.6 degrees) across every
    radial edge; the interpolated one is continuous (max jump < 1e-4 of the facet angle) and
    within 0.15 facet angles of the true radial direction at the edge points (the example CD's
    mesh: 24 rings from 7.5 to 60 mm), where the facets are off by up to half a facet angle."""
    segments = 64
    v, t, nrm, tri_t = _faceted_disc(segments)
    corner = smooth_corner_tangents(v, t, nrm, tri_t, np.zeros(len(t), np.int32), np.ones(len(t), bool))
    # every edge shared by two triangles: a point on it from each side (barycentrics per side)
    edges = {}
    for tri in range(len(t)):  # test set-up only
        for c in range(3):
            a, b = int(t[tri, c]), int(t[tri, (c + 1) % 3])
            edges.setdefault((min(a, b), max(a, b)), []).append((tri, c))
    prim, bu, bv, pts, side = [], [], [], [], []
    for (a, b), owners in edges.items():
        if len(owners) != 2:
            continue
        for k, (tri, c) in enumerate(owners):
            for f in (0.3, 0.7):
                w = np.zeros(3)
                ia = list(t[tri]).index(a)
                ib = list(t[tri]).index(b)
                w[ia], w[ib] = 1 - f, f
                prim.append(tri)
                bu.append(w[1])
                bv.append(w[2])
                pts.append((1 - f) * v[a] + f * v[b])
                side.append(k)
    prim, bu, bv, pts = np.array(prim), np.array(bu), np.array(bv), np.array(pts)
    n = np.tile(np.float32([0, 0, 1]), (len(prim), 1))
    smooth = tangents_at(corner, tri_t, prim, bu, bv, n).reshape(-1, 2, 2, 3)  # edge, side, f
    flat = tri_t[prim].reshape(-1, 2, 2, 3)
    facet = 2 * np.pi / segments

    def angle(x, y):  # between grating directions (t and -t alike), in float64
        x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
        return np.arctan2(np.linalg.norm(np.cross(x, y), axis=-1), np.abs(np.sum(x * y, axis=-1)))

    jump_flat = angle(flat[:, 0], flat[:, 1])
    jump_smooth = angle(smooth[:, 0], smooth[:, 1])
    radial_edges = jump_flat > 0.5 * facet
    assert radial_edges.sum() > segments  # the faceted directions do jump there
    assert jump_smooth.max() < 1e-4 * facet
    radial = pts[:, :2] / np.linalg.norm(pts[:, :2], axis=1, keepdims=True)
    radial = np.concatenate([radial, np.zeros((len(radial), 1))], 1).reshape(-1, 2, 2, 3)
    # what remains is smooth: the corner values average the facets' (centroid) directions around
    # a vertex with unequal corner angles, and linear interpolation between corners at different
    # radii errs by ~ facet * dr / (4 r); measured 0.11 facet angles at most (inner ring)
    assert angle(smooth, radial).max() < 0.15 * facet


def test_creases_keep_their_own_directions():
    """Two coplanar triangles whose directions differ by 60 degrees (two opal domains) are not
    blended: each keeps its own tangent at every corner."""
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float64)
    t = np.array([[0, 1, 2], [0, 2, 3]])
    nrm = np.tile([0.0, 0.0, 1.0], (2, 1))
    tri_t = np.array([[1.0, 0, 0], [0.5, np.sqrt(3) / 2, 0]])
    corner = smooth_corner_tangents(v, t, nrm, tri_t, np.zeros(2, np.int32), np.ones(2, bool))
    np.testing.assert_allclose(corner, np.repeat(tri_t[:, None], 3, axis=1), atol=1e-6)


# ------------------------------------------------------------------ the CD through the renderer
# main before this work (commit e4f69cb), the same measurement for the example's L = 10 um CD
# (80 x 60 px, 20 nm bins, no light pass, seed 1 at 16 spp against seed 99 at 256 spp):
# per-pixel RMSE / mean 20.0 (a sub-pixel zeroth-order glint holds 80 % of the image's light)
MAIN_RMSE_L10 = 20.0


def _cd_render(length_um, spp, seed, grating_footprint=True):
    cd_scene = load_example("gratings").cd_scene
    from opal_diffraction.core.render.frame import render
    from opal_diffraction.core.scene.settings import RenderSettings
    s = cd_scene(80, 60)
    s.materials.coherence_length[1] = length_um
    st = RenderSettings(samples=spp, seed=seed, light_paths=0, wavelength_step=20.0, threads=2,
                        grating_footprint=grating_footprint)
    return render(s, st).rgb.astype(np.float64)


@pytest.mark.slow
def test_cd_with_millimetre_tracks_renders_clean():
    """The issue's criterion (docs/physics.md section 3.7): a CD with L = 1000 um at 16 spp has a
    per-pixel RMSE against a converged render (256 spp, another seed) no larger than main's
    L = 10 um CD had (MAIN_RMSE_L10), and its image mean is within 3 % of the converged one.
    Point-sampling the pattern (footprint integration off) fails both by far."""
    ref = _cd_render(1000.0, 256, 99)
    img = _cd_render(1000.0, 16, 1)
    rel = np.sqrt(np.mean((img - ref) ** 2)) / ref.mean()
    assert rel <= MAIN_RMSE_L10, rel
    assert abs(img.mean() / ref.mean() - 1) < 0.03, img.mean() / ref.mean()
    point = _cd_render(1000.0, 16, 1, grating_footprint=False)
    assert np.sqrt(np.mean((point - ref) ** 2)) / ref.mean() > 5 * rel
