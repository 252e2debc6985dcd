"""The glass sphere's eye-pass noise fixes: both Fresnel branches at the first glass hit
(core/integrators/eye/fresnel_split.py, docs/physics.md section 4.12) and the light paths' diffuse bounce to the
camera (core/integrators/light/splat_bounce.py, docs/physics.md section 4.11), against independent estimates."""

import dataclasses

import numpy as np

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.integrators.light import splat_bounce
from opal_diffraction.core.integrators.eye.eye_pass import EyePass, _TileTrace
from opal_diffraction.core.integrators.light.light_pass import run_light_pass
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.frame import render, render_prepared
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.transport.walker import Rays
from opal_diffraction.core.render.plan import plan_render


def _sphere_scene(res=48, subdivisions=3) -> Scene:
    """benchmarks/caustic_sphere.py's scene, smaller: a glass ball (IOR 1.5) on a grey floor
    under a point light."""
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5,) * 3},
                                {"kind": "DIELECTRIC", "ior": 1.5, "color": (1, 1, 1)}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (6, 0, 0), (0, 6, 0)), material=0)
    s.add_mesh(*primitives.icosphere((0, 0, 1.0), 1.0, subdivisions), material=1)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (-2.0, 3.0, 6.0), "power": 1500.0}])
    s.camera = Camera.look_at((0.0, -6.0, 4.0), (0.0, -0.4, 0.5), lens=50, width=res, height=res)
    return s


def _labels(prepared, material: int, margin: int = 2) -> np.ndarray:
    """(H, W) bool: pixels whose centre ray and the rays `margin` px around it all hit `material`."""
    from opal_diffraction.core.sampling.camera import generate_rays

    cam = prepared.scene.camera
    h, w = int(cam.height), int(cam.width)
    ys, xs = np.mgrid[0:h, 0:w]
    ok = np.ones((h, w), bool)
    for dx in (-margin, 0, margin):
        for dy in (-margin, 0, margin):
            o, d = generate_rays(cam, xs.ravel() + 0.5 + dx, ys.ravel() + 0.5 + dy)
            hit = prepared.accel.intersect(o.astype(np.float32), d.astype(np.float32))
            mat = np.where(hit.prim >= 0, prepared.tri_material[np.maximum(hit.prim, 0)], -1)
            ok &= (mat == material).reshape(h, w)
    return ok


def _fresnel_angles(theta_i, n1, n2):
    """Unpolarised Fresnel reflectance from the angles (Hecht, Optics, eq. 4.42-4.43):
    R_s = sin^2(ti - tt) / sin^2(ti + tt), R_p = tan^2(ti - tt) / tan^2(ti + tt)."""
    theta_t = np.arcsin(n1 / n2 * np.sin(theta_i))
    rs = (np.sin(theta_i - theta_t) / np.sin(theta_i + theta_t)) ** 2
    rp = (np.tan(theta_i - theta_t) / np.tan(theta_i + theta_t)) ** 2
    return 0.5 * (rs + rp), theta_t


def test_camera_rays_at_glass_take_both_branches_with_the_fresnel_weights():
    """Rays from above onto a glass plane at known angles: two children per camera ray, the
    mirror direction with weight R and Snell's direction with weight 1 - R (Hecht's angle form,
    an independent formula); deeper rays (depth 1) keep the one-sample choice."""
    mats = Materials.from_list([{"kind": "DIELECTRIC", "ior": 1.5, "color": (1, 1, 1)}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (100, 0, 0), (0, 100, 0)), material=0)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (0.0, 0.0, 5.0), "power": 10.0}])
    s.camera = Camera.look_at((0.0, -3.0, 3.0), (0.0, 0.0, 0.0), width=8, height=8)
    prepared = prepare(s, RenderSettings(light_paths=0, wavelength_step=50.0))
    theta = np.radians([5.0, 30.0, 60.0, 80.0])
    d = np.stack([np.sin(theta), np.zeros(4), -np.cos(theta)], axis=1).astype(np.float32)
    o = (np.array([0.0, 0.0, 1.0]) - d).astype(np.float32)
    tr = _TileTrace(EyePass(prepared, plan=plan_render(prepared)), 4, np.random.default_rng(1))
    n = prepared.grid.n
    for depth in (0, 1):
        rays = Rays(o, d, np.arange(4), None, None, np.full(4, depth, np.int32), np.zeros(4), tr._new_state(4))
        h = prepared.accel.intersect(o, d)
        hit = tr.hit_info(rays, h.t, h.prim, h.u, h.v)
        out, transmitted = tr.dielectric_bounce(rays, hit, np.random.default_rng(2))
        if depth == 1:
            assert len(out) == 4
            continue
        assert len(out) == 8 and transmitted.sum() == 4
        want_r, theta_t = _fresnel_angles(theta, 1.0, 1.5)
        for k in range(4):
            rows = np.flatnonzero(out.pix == k)
            refl, refr = rows[~transmitted[rows]], rows[transmitted[rows]]
            assert len(refl) == 1 and len(refr) == 1
            np.testing.assert_allclose(out.w[refl[0]], np.full(n, want_r[k]), rtol=1e-5)
            np.testing.assert_allclose(out.w[refr[0]], np.full(n, 1 - want_r[k]), rtol=1e-5)
            np.testing.assert_allclose(out.d[refl[0]], d[k] * [1, 1, -1], atol=1e-6)
            np.testing.assert_allclose(out.d[refr[0]], [np.sin(theta_t[k]), 0, -np.cos(theta_t[k])], atol=1e-6)


def test_splitting_keeps_the_sphere_and_lowers_its_noise():
    """The glass sphere's pixels with and without the split: the same mean (Z-test over pixels
    of two independent renders: each pixel's samples are its own, so pixels are independent), and
    a smaller per-pixel variance (F-test on the differences of two seeds of each, p < 1e-4)."""
    from scipy import stats

    scene = _sphere_scene()
    # per-pixel sequences: the Z- and F-tests count pixels as independent, which blue-noise
    # sampling (docs/physics.md section 6.6) makes them not
    st = dict(samples=16, light_paths=0, wavelength_step=20.0, blue_noise=False)
    sphere = _labels(prepare(scene, RenderSettings(**st)), 1)
    assert sphere.sum() > 150

    def runs(flag):
        return [render(scene, RenderSettings(seed=s, fresnel_split=flag, **st)).rgb.mean(axis=2)[sphere].astype(np.float64)
                for s in (11, 12)]

    split, chosen = runs(True), runs(False)
    diff = split[0] - chosen[0]
    z = diff.mean() / (diff.std(ddof=1) / np.sqrt(len(diff)))
    assert abs(z) < 4, (split[0].mean(), chosen[0].mean(), z)
    v_split, v_chosen = np.var(split[0] - split[1], ddof=1), np.var(chosen[0] - chosen[1], ddof=1)
    p = stats.f.sf(v_chosen / v_split, len(diff) - 1, len(diff) - 1)
    assert v_split < v_chosen and p < 1e-4, (v_split, v_chosen, p)


def test_the_light_paths_bounce_carries_what_the_eye_read_from_the_map():
    """On the floor the camera sees, the caustic after one diffuse bounce through the glass
    (E -> floor -> glass -> caustic): with the continuation (core/integrators/light/splat_bounce.py) the light
    paths splat it, without it the eye pass reads it from the map after its bounce. The light
    pass with the continuation draws the bounces after its walk, so its map and direct splats
    are those of the same seed without it, and each render's Caustics pass minus the direct
    splats (the one without the continuation: the same image) is that caustic alone. The two
    agree (Z-test over 4 x 4 pixel blocks of the floor, on their differences), the light's
    estimate is not zero (the test can fail) and it is less noisy."""
    scene = _sphere_scene(res=64)
    st = RenderSettings(samples=32, light_paths=300_000, wavelength_step=20.0, seed=5)
    floor = _labels(prepare(scene, st), 0)

    def run(flag):
        p = prepare(scene, dataclasses.replace(st, splat_bounce=flag))
        assert plan_render(p).splat_bounce is flag
        light = run_light_pass(p, plan=plan_render(p))
        splat_rgb = light.splat.images(p.conv)[0].mean(axis=2).astype(np.float64)
        return render_prepared(p, light).passes["Caustics"].mean(axis=2).astype(np.float64), light, splat_rgb

    on, light_on, splat_on = run(True)
    off, light_off, direct = run(False)
    np.testing.assert_array_equal(light_on.caustics.flux, light_off.caustics.flux)  # the same walk
    assert np.all(splat_on >= direct - 1e-6)  # the continuation only adds

    def blocks(img):
        h, w = img.shape
        v = np.where(floor, img, 0.0)[: h // 4 * 4, : w // 4 * 4].reshape(h // 4, 4, w // 4, 4).sum(axis=(1, 3))
        c = floor[: h // 4 * 4, : w // 4 * 4].reshape(h // 4, 4, w // 4, 4).sum(axis=(1, 3))
        return v[c == 16] / 16

    a, b = blocks(on - direct), blocks(off - direct)
    assert len(a) >= 50
    d = a - b
    se = d.std(ddof=1) / np.sqrt(len(d))
    assert abs(d.mean()) < 4 * se, (a.mean(), b.mean(), se)
    assert a.mean() > 4 * a.std(ddof=1) / np.sqrt(len(a)), (a.mean(), a.std())
    assert a.std() < b.std(), (a.std(), b.std())


def test_the_continued_light_paths_directions_are_cosine_distributed():
    """splat_bounce's bounce directions (bsdf.cosine_hemisphere, the eye pass's diffuse bounce
    too) against the cosine density cos(theta) / pi about the normal (tests/chi2.py, Mitsuba 3's
    chi2 test; two normals, threshold 0.01 / 2)."""
    from chi2 import chi2_directions

    rng = np.random.default_rng(7)
    for axis in ((0.0, 0.0, 1.0), (0.6, -0.48, 0.64)):
        a = np.asarray(axis, np.float64) / np.linalg.norm(axis)
        wi, _ = splat_bounce.cosine_hemisphere(np.tile(a.astype(np.float32), (200_000, 1)), rng)
        wi = wi.astype(np.float64)
        np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0, atol=1e-5)
        pval, info, total = chi2_directions(wi, lambda d: np.maximum(d @ a, 0.0) / np.pi, a, theta_max=np.pi / 2)
        assert abs(total - 1.0) < 1e-3
        assert pval > 0.01 / 2, info
