"""Environment maps (docs/physics.md section 7.9): the equirectangular convention, the sampling
density against a chi-square test and quadrature, irradiance by importance sampling against
quadrature, and the world as an emitter of the light pass against a SUN light and closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from chi2 import pearson
from opal_diffraction.core.lights.environment import EnvironmentMap, direction_to_uv, uv_to_direction


def rotation_xyz(ax, ay, az) -> np.ndarray:
    """Blender's XYZ Euler rotation matrix Rz Ry Rx."""
    cx, sx, cy, sy, cz, sz = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay), math.cos(az), math.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def structured_map(w=32, h=16) -> np.ndarray:
    """A gradient in both directions, a bright 2 x 2 patch and a black band: (H, W, 3)."""
    jj, ii = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    img = np.zeros((h, w, 3), np.float32)
    img[..., 0] = 0.2 + ii / w
    img[..., 1] = 0.1 + jj / h
    img[..., 2] = 0.3
    img[h // 2 + 2: h // 2 + 4, 5:7] = (40.0, 30.0, 20.0)
    img[2:4] = 0.0  # a black band: zero density there
    return img


ROT = rotation_xyz(0.3, -0.7, 1.1)


# ------------------------------------------------------------------------------ convention
def test_cycles_equirectangular_convention():
    """u = 0.5 - atan2(y, x) / 2 pi, v = 1 - acos(z) / pi (Cycles' direction_to_equirectangular):
    -X at u = 0, +Y at u = 0.25, +X at 0.5, -Y at 0.75; up at v = 1, down at v = 0."""
    dirs = np.array([[-1, 1e-12, 0], [0, 1, 0], [1, 0, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    u, v = direction_to_uv(dirs)
    np.testing.assert_allclose(u[:4] % 1.0, [0.0, 0.25, 0.5, 0.75], atol=1e-9)
    np.testing.assert_allclose(v, [0.5, 0.5, 0.5, 0.5, 1.0, 0.0], atol=1e-9)
    rng = np.random.default_rng(1)
    uu, vv = rng.random(100), rng.random(100)
    back_u, back_v = direction_to_uv(uv_to_direction(uu, vv))
    np.testing.assert_allclose(back_u % 1.0, uu, atol=1e-9)
    np.testing.assert_allclose(back_v, vv, atol=1e-9)


@pytest.mark.parametrize("interpolation", ["LINEAR", "CLOSEST"])
def test_texel_centres_return_their_texels(interpolation):
    """At each texel centre's world direction (through the rotation) the lookup is that texel."""
    img = np.random.default_rng(2).random((8, 12, 3)).astype(np.float32)
    env = EnvironmentMap(img, ROT, interpolation)
    jj, ii = np.meshgrid(np.arange(8), np.arange(12), indexing="ij")
    m = uv_to_direction((ii.ravel() + 0.5) / 12, (jj.ravel() + 0.5) / 8)
    world = m @ ROT  # R^T m: the world direction that maps to m
    np.testing.assert_allclose(env.radiance_rgb(world), img.reshape(-1, 3), rtol=1e-4, atol=1e-6)


def test_rotation_moves_the_map():
    """A map rotated by R shows at world direction R^T m what the unrotated map shows at m; a
    90 degree turn about Z moves the +X texel to +Y."""
    img = structured_map()
    rng = np.random.default_rng(3)
    m = rng.normal(size=(500, 3))
    m /= np.linalg.norm(m, axis=1, keepdims=True)
    plain, turned = EnvironmentMap(img), EnvironmentMap(img, ROT)
    np.testing.assert_allclose(turned.radiance_rgb(m @ ROT), plain.radiance_rgb(m), rtol=1e-5, atol=1e-6)
    quarter = rotation_xyz(0, 0, math.pi / 2)  # world -> map: world +Y maps to map +X
    np.testing.assert_allclose(EnvironmentMap(img, quarter.T).radiance_rgb([[0, 1, 0]]),
                               plain.radiance_rgb([[1, 0, 0]]), rtol=1e-5)


# ------------------------------------------------------------------------------ sampling
def _cell_integrals(env, n_theta, n_phi, sub=24):
    """The pdf integrated over each (theta, phi) cell by the midpoint rule in (cos theta, phi)
    with sub x sub points per cell (the density is piecewise constant, so this converges)."""
    out = np.zeros((n_theta, n_phi))
    t_edges = np.linspace(0, np.pi, n_theta + 1)
    p_edges = np.linspace(0, 2 * np.pi, n_phi + 1)
    for a in range(n_theta):  # loop over theta rows of cells (a few dozen)
        z0, z1 = np.cos(t_edges[a + 1]), np.cos(t_edges[a])
        z = z0 + (np.arange(sub) + 0.5) / sub * (z1 - z0)
        phi = (np.arange(n_phi * sub) + 0.5) / (n_phi * sub) * 2 * np.pi
        zz, pp = np.meshgrid(z, phi, indexing="ij")
        s = np.sqrt(1 - zz**2)
        d = np.stack([s * np.cos(pp), s * np.sin(pp), zz], axis=-1).reshape(-1, 3)
        pdf = env.pdf(d).reshape(sub, n_phi, sub)
        cell_area = (z1 - z0) * (p_edges[1] - p_edges[0])
        out[a] = pdf.mean(axis=(0, 2)) * cell_area
    return out


@pytest.mark.parametrize("interpolation", ["LINEAR", "CLOSEST"])
def test_sample_matches_pdf_chi_square(interpolation):
    """Histogram of 400 k samples over a 30 x 60 (theta, phi) grid against the pdf integrated over
    each cell; one of two tests, so the threshold is 0.01 / 2 (Mitsuba 3's chi2 test)."""
    env = EnvironmentMap(structured_map(), ROT, interpolation)
    n, n_theta, n_phi = 400_000, 30, 60
    rng = np.random.default_rng(4)
    d, pdf, rgb = env.sample(rng.random(n), rng.random(n))
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-9)
    # the returned pdf and radiance are pdf(d) and radiance_rgb(d) (texel edges aside)
    agree = np.isclose(pdf, env.pdf(d), rtol=1e-9)
    assert agree.mean() > 0.999
    np.testing.assert_allclose(rgb, env.radiance_rgb(d), rtol=1e-4, atol=1e-5)
    theta = np.arccos(np.clip(d[:, 2], -1, 1))
    phi = np.arctan2(d[:, 1], d[:, 0]) % (2 * np.pi)
    hist, _, _ = np.histogram2d(theta, phi, bins=[n_theta, n_phi], range=[[0, np.pi], [0, 2 * np.pi]])
    expected = _cell_integrals(env, n_theta, n_phi) * n
    assert abs(expected.sum() / n - 1) < 1e-3
    p, info = pearson(hist, expected)
    print(f"{interpolation}: {info}")
    assert p > 0.01 / 2, info


def test_pdf_integrates_to_one_and_follows_the_radiance():
    """Quadrature over the sphere (1024 x 2048 points, uniform in cos theta and phi) of pdf is 1;
    the density is zero on the black band and proportional to the luminance elsewhere."""
    env = EnvironmentMap(structured_map(), ROT, "CLOSEST")
    nz, nphi = 1024, 2048
    z = -1 + 2 * (np.arange(nz) + 0.5) / nz
    phi = (np.arange(nphi) + 0.5) / nphi * 2 * np.pi
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    s = np.sqrt(1 - zz**2)
    d = np.stack([s * np.cos(pp), s * np.sin(pp), zz], axis=-1).reshape(-1, 3)
    pdf = env.pdf(d)
    integral = pdf.mean() * 4 * np.pi
    assert abs(integral - 1) < 2e-3, integral
    lum = env.radiance_rgb(d).astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    ratio = pdf[lum > 0] / lum[lum > 0]
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-5)  # CLOSEST: pdf exactly proportional
    assert np.all(pdf[lum == 0] == 0)


def test_linear_lookup_never_has_radiance_where_the_density_is_zero():
    """Bilinear lookups blend into the black band's edge: the density must cover them (the
    distribution uses each texel's cell mean), else an estimator would lose that light."""
    env = EnvironmentMap(structured_map(), ROT, "LINEAR")
    rng = np.random.default_rng(5)
    d = rng.normal(size=(200_000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    lit = env.radiance_rgb(d).max(axis=1) > 0
    assert np.all(env.pdf(d)[lit] > 0)
    assert (~lit).sum() > 1000  # the band is there


def test_black_map_samples_the_sphere_uniformly():
    env = EnvironmentMap(np.zeros((4, 8, 3), np.float32))
    rng = np.random.default_rng(6)
    d, pdf, rgb = env.sample(rng.random(10_000), rng.random(10_000))
    assert env.black and np.all(rgb == 0)
    np.testing.assert_allclose(pdf, 1 / (4 * np.pi), rtol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-9)
    # uniform on the sphere: z uniform in [-1, 1] (Kolmogorov-Smirnov)
    assert stats.kstest(d[:, 2], "uniform", args=(-1, 2)).pvalue > 1e-3


def test_poles_and_one_texel_maps():
    """A 1 x 1 map is a constant world: density 1 / 4 pi everywhere, the poles included."""
    env = EnvironmentMap(np.full((1, 1, 3), 2.0, np.float32))
    poles = np.array([[0, 0, 1.0], [0, 0, -1.0], [1, 0, 0]])
    np.testing.assert_allclose(env.pdf(poles), 1 / (4 * np.pi))
    np.testing.assert_allclose(env.radiance_rgb(poles), 2.0)
    u = np.array([0.0, 0.999999, 0.5])
    d, pdf, rgb = env.sample(u, u[::-1])
    assert np.isfinite(d).all() and np.all(pdf > 0) and np.allclose(rgb, 2.0)
    np.testing.assert_allclose(env.integral_rgb(), 8 * np.pi)


def test_bad_maps_are_refused():
    with pytest.raises(ValueError, match="finite and non-negative"):
        EnvironmentMap(np.full((2, 2, 3), np.nan, np.float32))
    with pytest.raises(ValueError, match="orthogonal"):
        EnvironmentMap(np.ones((2, 2, 3), np.float32), np.diag([1.0, 2.0, 1.0]))
    with pytest.raises(ValueError, match="interpolation"):
        EnvironmentMap(np.ones((2, 2, 3), np.float32), None, "CUBIC")


def test_importance_sampled_irradiance_matches_quadrature():
    """E = integral over the hemisphere of L cos: the estimator mean(L cos+ / pdf) over 200 k
    samples against a 1024 x 1024 quadrature of the lookup in (cos theta, phi) about the normal;
    a Z-test with the samples' own standard error (plus the quadrature's error bound)."""
    env = EnvironmentMap(structured_map(), ROT, "LINEAR")
    n_plane = np.array([0.3, -0.5, 0.81])
    n_plane /= np.linalg.norm(n_plane)
    rng = np.random.default_rng(7)
    n = 200_000
    d, pdf, rgb = env.sample(rng.random(n), rng.random(n))
    cos = np.maximum(d @ n_plane, 0)
    f = rgb * np.where(pdf > 0, cos / np.where(pdf > 0, pdf, 1), 0.0)[:, None]
    est, se = f.mean(axis=0), f.std(axis=0) / math.sqrt(n)
    # quadrature in a frame about the normal: dE = L cos dcos dphi
    t = np.cross(n_plane, [1.0, 0, 0])
    t /= np.linalg.norm(t)
    b = np.cross(n_plane, t)
    m = 1024
    c = (np.arange(m) + 0.5) / m
    ph = (np.arange(m) + 0.5) / m * 2 * np.pi
    cc, pp = np.meshgrid(c, ph, indexing="ij")
    s = np.sqrt(1 - cc**2)
    dirs = (s * np.cos(pp))[..., None] * t + (s * np.sin(pp))[..., None] * b + cc[..., None] * n_plane
    lum = env.radiance_rgb(dirs.reshape(-1, 3)).astype(np.float64)
    quad = (lum * cc.reshape(-1, 1)).mean(axis=0) * 2 * np.pi
    z = (est - quad) / se
    print(f"irradiance: estimate {est} +- {se}, quadrature {quad}, z {z}")
    assert np.all(np.abs(z) < 4.0)
    assert np.all(se / quad < 0.01)  # the test has power: 1 % noise


# ------------------------------------------------------------------------------ the light pass
from opal_diffraction.core.scene import primitives  # noqa: E402
from opal_diffraction.core.transport.elements import IlluminationMap  # noqa: E402
from opal_diffraction.core.integrators.light.light_pass import LightWork  # noqa: E402
from opal_diffraction.core.integrators.light.walker import BATCH_PATHS, trace_batch  # noqa: E402
from opal_diffraction.core.render.prepare import prepare  # noqa: E402
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene  # noqa: E402
from opal_diffraction.core.scene.settings import RenderSettings  # noqa: E402

IOR = 1.5
SLAB_HALF, SLAB_BOTTOM, SLAB_T, RECEIVER_HALF = 1.0, 0.15, 0.02, 0.2


def slab_over_receiver(**world) -> Scene:
    """A thin 2 x 2 m glass slab (bottom face at z = 0.15) over a 0.4 x 0.4 m diffuse receiver at
    z = 0, nothing else: every deposit on the receiver came through the slab."""
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)}, {"kind": "DIELECTRIC", "ior": IOR}])
    s = Scene(materials=mats, **world)
    s.add_mesh(*primitives.quad((0, 0, 0), (2 * RECEIVER_HALF, 0, 0), (0, 2 * RECEIVER_HALF, 0)), material=0)
    s.add_mesh(*primitives.box((0, 0, SLAB_BOTTOM + SLAB_T / 2), (2 * SLAB_HALF, 2 * SLAB_HALF, SLAB_T)), material=1)
    s.camera = Camera(width=4, height=4)
    return s


def batch_fluxes(scene, n_paths, seed=0):
    """Per-batch total flux (B, n) on the receivers, per light index (the world is the last):
    the batches are independent, so their spread gives the estimate's standard error."""
    prepared = prepare(scene, RenderSettings(light_paths=n_paths, max_bounces=32, seed=seed, wavelength_step=20.0))
    work = LightWork.of(prepared)
    out = {}
    for job in work.batches:  # loop over batches (a few dozen)
        illum = IlluminationMap.empty(work.layout, prepared.grid.n)
        trace_batch(prepared, job, illum, None)
        out.setdefault(job.light, []).append(illum.flux.sum(axis=0))
    return prepared, {k: np.array(v) for k, v in out.items()}


def total_and_error(per_batch):
    """Sum of the batches and its standard error (batches of equal size)."""
    b = len(per_batch)
    return per_batch.sum(axis=0), np.sqrt(b * per_batch.var(axis=0, ddof=1))


def slab_transmittance(cos_t):
    """(1 - R) / (1 + R): a non-absorbing slab with every internal reflection (unpolarised
    Fresnel per interface, as the tracer; docs/physics.md section 2.3)."""
    cos_t = np.clip(cos_t, 0, 1)
    sin_t = np.sqrt(1 - cos_t**2)
    cos_r = np.sqrt(1 - (sin_t / IOR) ** 2)
    rs = ((cos_t - IOR * cos_r) / (cos_t + IOR * cos_r)) ** 2
    rp = ((cos_r - IOR * cos_t) / (cos_r + IOR * cos_t)) ** 2
    r = 0.5 * (rs + rp)
    return (1 - r) / (1 + r)


def test_uniform_world_caustic_under_a_slab_matches_the_closed_form():
    """The world as a light of the light pass: flux through the slab onto the receiver =
    integral over receiver points and over the directions whose line meets the slab's bottom
    face of L cos(theta) (T(theta) from above, plus R(theta) = 1 - T from the lower half of the
    world mirrored in the slab where the receiver does not hide it) (quadrature, 16 x 16 points
    x 600 x 600 directions), against
    1.3 M world paths; a Z-test on the batches' spread."""
    scene = slab_over_receiver(world_color=np.array([1.0, 1.0, 1.0], np.float32))
    prepared, per = batch_fluxes(scene, 40 * BATCH_PATHS)
    assert list(per) == [1]  # no lights: the world is light-pass index L + 1 = 1 (0: the emissive meshes)
    got, err = total_and_error(per[1])
    # quadrature: directions in (cos theta, phi) over the upper hemisphere
    m = 600
    c = (np.arange(m) + 0.5) / m
    phi = (np.arange(m) + 0.5) / m * 2 * np.pi
    cc, pp = np.meshgrid(c, phi, indexing="ij")
    tan = np.sqrt(1 - cc**2) / cc
    g = (np.arange(16) + 0.5) / 16 * 2 * RECEIVER_HALF - RECEIVER_HALF
    t_slab = slab_transmittance(cc)
    seen = np.zeros_like(cc)
    for x in g:  # loop over receiver points (16 x 16)
        for y in g:
            hx, hy = x + SLAB_BOTTOM * tan * np.cos(pp), y + SLAB_BOTTOM * tan * np.sin(pp)
            through = (np.abs(hx) < SLAB_HALF) & (np.abs(hy) < SLAB_HALF)
            # the slab also reflects the lower half of the world (R_slab = 1 - T), unless the
            # mirrored line comes from the receiver's own (unlit) underside
            bx, by = x + 2 * SLAB_BOTTOM * tan * np.cos(pp), y + 2 * SLAB_BOTTOM * tan * np.sin(pp)
            blocked = (np.abs(bx) < RECEIVER_HALF) & (np.abs(by) < RECEIVER_HALF)
            seen += through * (t_slab + (1 - t_slab) * ~blocked)
    seen /= 16 * 16
    integral = np.mean(seen * cc) * 2 * np.pi  # per unit L and area
    expected = prepared.world_spectrum * integral * (2 * RECEIVER_HALF) ** 2
    z = (got - expected) / err
    print(f"uniform world: flux {got[10]:.5f} +- {err[10]:.5f}, closed form {expected[10]:.5f}; "
          f"|z| max {np.abs(z).max():.2f}, relative error {err[10] / got[10]:.4f}")
    assert np.all(np.abs(z) < 4.5)
    assert np.all(err / expected < 0.02)


def _patch_map(w=256, h=128):
    """Black except a 2 x 2 texel patch around (u, v) = (0.3, 0.8) of radiance 5000."""
    img = np.zeros((h, w, 3), np.float32)
    i, j = int(0.3 * w), int(0.8 * h)
    img[j:j + 2, i:i + 2] = 5000.0
    return img


def test_a_bright_patch_throws_the_caustic_of_a_sun_of_its_irradiance():
    """A map black but for a small bright patch and a SUN light of the same irradiance (the
    patch's integral of L cos about its centroid direction, by quadrature) and direction throw
    the same flux through the slab (two independent estimates, a Z-test), and both the closed
    form E cos(theta) T(theta) A."""
    rot = rotation_xyz(0.2, 0.0, 0.5)
    img = _patch_map()
    env = EnvironmentMap(img, rot)
    # the patch's irradiance and centroid direction by quadrature over its neighbourhood (u, v)
    n = 400
    uu, vv = np.meshgrid(0.3 + (np.arange(n) + 0.5) / n * 0.03 - 0.01, 0.8 + (np.arange(n) + 0.5) / n * 0.06 - 0.02)
    m = uv_to_direction(uu.ravel(), vv.ravel())
    d_world = m @ rot
    lum = env.radiance_rgb(d_world)[:, 1].astype(np.float64)
    domega = (0.03 * 2 * np.pi / n) * (0.06 * np.pi / n) * np.sin(np.pi * (1 - vv.ravel()))
    vec = (lum * domega) @ d_world
    centre = vec / np.linalg.norm(vec)
    irradiance = float(np.sum(lum * domega * (d_world @ centre)))
    assert centre[2] > 0.5, "the patch must be above the slab"
    world_scene = slab_over_receiver(world_color=np.ones(3, np.float32), world_image=img, world_rotation=rot)
    sun_scene = slab_over_receiver()
    sun_scene.lights = Lights.from_list([{"kind": "SUN", "direction": -centre, "power": irradiance}])
    p_world, per_world = batch_fluxes(world_scene, 30 * BATCH_PATHS, seed=1)
    p_sun, per_sun = batch_fluxes(sun_scene, 30 * BATCH_PATHS, seed=2)
    fw, ew = total_and_error(per_world[1])  # the world: light-pass index L + 1 (no lights)
    fs, es = total_and_error(per_sun[0])
    white = p_world.conv.illuminant_from_rgb(np.ones(3))
    np.testing.assert_allclose(p_sun.lights.spectrum[0], irradiance * white, rtol=1e-5)  # the sun's units
    z = (fw - fs) / np.hypot(ew, es)
    expected = irradiance * centre[2] * slab_transmittance(centre[2]) * (2 * RECEIVER_HALF) ** 2 * white
    print(f"patch {fw[10]:.5f} +- {ew[10]:.5f}, sun {fs[10]:.5f} +- {es[10]:.5f}, closed form {expected[10]:.5f}; "
          f"|z| max {np.abs(z).max():.2f}")
    assert np.all(np.abs(z) < 4.5)
    assert np.all(np.abs(fs - expected) < 4.5 * es)
    assert np.all(np.abs(fw - expected) < 4.5 * ew + 0.002 * expected)  # the patch spans ~1.5 degrees
    assert np.all(ew / fw < 0.02)


# ------------------------------------------------------------------------------ scene, prepare, eye pass
from opal_diffraction.core.sampling.camera import generate_rays  # noqa: E402
from opal_diffraction.core.render.frame import render  # noqa: E402
from opal_diffraction.core.scene.checks import MAX_SIDE, SceneError  # noqa: E402
from opal_diffraction.core.scene.npz import load_scene, save_scene  # noqa: E402
from opal_diffraction.core.scene.validation import validate  # noqa: E402


def _world_scene(**kw) -> Scene:
    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE"}]), **kw)
    s.add_mesh(*primitives.quad((0, 0, 0), (1, 0, 0), (0, 1, 0)), material=0)
    s.camera = Camera.look_at((0, -3, 1), (0, 0, 0), width=8, height=8)
    return s


def test_world_map_saves_loads_and_older_files_have_none(tmp_path):
    img = structured_map(8, 4)
    s = _world_scene(world_color=np.array([2.0, 1.0, 0.5], np.float32), world_image=img, world_rotation=ROT)
    save_scene(s, tmp_path / "a.npz")
    t = load_scene(tmp_path / "a.npz")
    np.testing.assert_array_equal(t.world_image, img)
    np.testing.assert_array_equal(t.world_rotation, ROT)
    # a file written before world maps existed
    with np.load(tmp_path / "a.npz") as z:
        old = {k: z[k] for k in z.files if k not in ("world_image", "world_rotation")}
    np.savez(tmp_path / "old.npz", **old)
    o = load_scene(tmp_path / "old.npz")
    assert o.world_image.shape == (0, 0, 3) and np.array_equal(o.world_rotation, np.eye(3))
    clean = validate(o).scene
    assert clean.world_image.size == 0


@pytest.mark.parametrize("image, rotation, message", [
    (np.full((2, 4, 3), np.nan, np.float32), np.eye(3), "NaN or infinite"),
    (-np.ones((2, 4, 3), np.float32), np.eye(3), "negative"),
    (np.ones((2, 4), np.float32), np.eye(3), r"shape \(H, W, 3\)"),
    (np.ones((1, MAX_SIDE + 1, 3), np.float32), np.eye(3), "at most"),
    (np.ones((2, 4, 3), np.float32), np.diag([1.0, 1.0, 2.0]), "not orthonormal"),
    (np.ones((2, 4, 3), np.float32), np.full((3, 3), np.inf), "NaN or infinite"),
    (np.ones((2, 4, 3), np.float32), np.eye(2), "3x3"),
    (np.full((2, 4, 3), 1e30, np.float32), np.eye(3), "renderable limit"),
])
def test_bad_world_maps_are_clear_errors(image, rotation, message):
    s = _world_scene(world_color=np.ones(3, np.float32), world_image=image, world_rotation=rotation)
    with pytest.raises(SceneError, match=message):
        validate(s)


def test_a_mapped_world_lights_the_scene_a_black_one_does_not():
    lit = _world_scene(world_color=np.ones(3, np.float32), world_image=structured_map(8, 4))
    assert not any("no lights" in w for w in validate(lit).warnings)
    dark = _world_scene(world_color=np.ones(3, np.float32), world_image=np.zeros((4, 8, 3), np.float32))
    assert any("no lights" in w for w in validate(dark).warnings)
    mirror = np.diag([-1.0, 1.0, 1.0])  # a mirrored map (a Mapping node's negative scale) is allowed
    validate(_world_scene(world_color=np.ones(3, np.float32), world_image=structured_map(8, 4), world_rotation=mirror))


def test_prepare_builds_the_map_and_keys_the_light_pass_on_it():
    settings = RenderSettings(wavelength_step=20.0)
    uniform = prepare(_world_scene(world_color=np.full(3, 0.5, np.float32)), settings)
    assert uniform.environment is None
    img = structured_map(8, 4)
    s = _world_scene(world_color=np.array([2.0, 1.0, 1.0], np.float32), world_image=img, world_rotation=ROT)
    first = prepare(s, settings)
    env = first.environment
    assert isinstance(env, EnvironmentMap)
    np.testing.assert_allclose(env.rgb, img * np.array([2.0, 1.0, 1.0], np.float32))  # colour x image
    np.testing.assert_allclose(first.world_spectrum, first.conv.illuminant_from_rgb(env.mean_rgb()), rtol=1e-5)
    same = prepare(s, settings, reuse=first)
    assert same.key == first.key and same.environment is env
    s2 = _world_scene(world_color=np.array([2.0, 1.0, 1.0], np.float32), world_image=img, world_rotation=np.eye(3))
    turned = prepare(s2, settings, reuse=first)
    assert turned.key != first.key and turned.environment is not env


def test_the_background_is_the_map_along_each_camera_ray():
    """No geometry: every pixel shows the map at its camera ray (pixel centres, filter 0), after
    the RGB -> spectrum -> RGB round trip (Mallett-Yuksel under the white illuminant, docs/physics.md
    section 1.4: within 1 % for these colours)."""
    img = structured_map(32, 16)
    world = np.array([1.5, 1.0, 0.8], np.float32)
    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE"}]), world_color=world, world_image=img,
              world_rotation=ROT)
    s.camera = Camera.look_at((0, 0, 0), (1, 0.3, 0.4), width=24, height=16, lens=12)
    r = render(s, RenderSettings(samples=1, filter_width=0.0, wavelength_step=5.0))
    ys, xs = np.meshgrid(np.arange(16) + 0.5, np.arange(24) + 0.5, indexing="ij")
    _, d = generate_rays(s.camera, xs.ravel(), ys.ravel())
    expected = EnvironmentMap(img * world, ROT).radiance_rgb(d).reshape(16, 24, 3)
    np.testing.assert_allclose(r.rgb, expected, rtol=0.01, atol=2e-3)
    assert expected.std() > 0.1  # the view shows structure


@pytest.mark.parametrize("sampling", ["SAMPLE", "SPLIT"])
def test_the_map_through_dispersive_glass_matches_non_dispersive_glass(sampling):
    """Monochromatic rays (after a dispersive interface) see the map too: a BK7 slab in front of
    the camera against a non-dispersive slab of BK7's d-line index. A flat slab keeps directions,
    so the two images differ only by BK7's index spread (1.511-1.527 over the visible: < 0.3 %
    in the slab's transmittance) and the rays' noise: a t-test (p = 0.001) on the image means
    over four seeds of 64 samples per pixel each."""
    from opal_diffraction.core.spectral.optics import ior_spectrum

    img = structured_map(32, 16)
    n_d = float(ior_spectrum(np.array([587.6]), "BK7")[0])
    means = {}
    for name, mat in (("bk7", {"kind": "DIELECTRIC", "dispersion": "BK7"}), ("plain", {"kind": "DIELECTRIC", "ior": n_d})):
        s = Scene(materials=Materials.from_list([mat]), world_color=np.ones(3, np.float32), world_image=img,
                  world_rotation=ROT)
        s.add_mesh(*primitives.box((0, 1.0, 0), (4.0, 0.1, 4.0)), material=0)  # a slab across the view
        s.camera = Camera.look_at((0, 0, 0), (0, 1, 0.1), width=16, height=12, lens=35)
        means[name] = np.array([render(s, RenderSettings(samples=64, wavelength_step=10.0, seed=seed, max_bounces=16,
                                                         dispersion_sampling=sampling)).rgb.mean(axis=(0, 1))
                                for seed in range(4)])
    diff = means["bk7"].mean(axis=0) - means["plain"].mean(axis=0)
    se = np.sqrt(means["bk7"].var(axis=0, ddof=1) / 4 + means["plain"].var(axis=0, ddof=1) / 4)
    scale = means["plain"].mean(axis=0)
    print(f"{sampling}: BK7 - plain {diff / scale} of the mean, standard error {se / scale}")
    t_crit = stats.t.ppf(1 - 0.001 / 2, df=6)  # two samples of four: the variance has 6 degrees of freedom
    assert np.all(np.abs(diff) < t_crit * se + 0.003 * scale)
    assert np.all(scale > 0.1)  # the map is seen through the slab
