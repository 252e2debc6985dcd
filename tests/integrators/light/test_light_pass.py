"""The light pass (docs/physics.md section 4): caustic flux against closed forms."""

import numpy as np
import pytest

from opal_diffraction._scripts import load_example
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.transport.elements import ElementLayout, IlluminationMap
from opal_diffraction.core.integrators.light.light_pass import run_light_pass
from opal_diffraction.core.spectral.optics import ior_spectrum
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.render.plan import plan_render


def light_map(scene, **kw):
    st = RenderSettings(**kw)
    ctx = prepare(scene, st)
    lp = run_light_pass(ctx, plan=plan_render(ctx))
    return ctx, lp, lp.caustics, lp.stats


def element_positions(ctx, illum):
    tri, bu, bv = illum.layout.barycentric_centres()
    v = np.asarray(ctx.scene.vertices, np.float64)[np.asarray(ctx.scene.triangles)[tri]]
    return (1 - bu - bv)[:, None] * v[:, 0] + bu[:, None] * v[:, 1] + bv[:, None] * v[:, 2]


def test_element_index_is_a_bijection_with_equal_areas():
    v, t = primitives.quad((0, 0, 0), (2, 0, 0), (0, 1, 0))
    lay = ElementLayout.build(v, t, np.ones(2, bool), 0.01)
    tri, bu, bv = lay.barycentric_centres()
    front = np.arange(lay.total) % 2 == 0
    idx, ok = lay.index(tri, bu, bv, front)
    assert ok.all() and np.array_equal(np.sort(idx), np.arange(lay.total))
    assert np.allclose(lay.element_area * lay.k**2, 1.0)  # each triangle has area 1
    # random points land in the element whose centre is nearest in barycentric terms of that grid
    rng = np.random.default_rng(0)
    u, w = rng.random(1000), rng.random(1000)
    flip = u + w > 1
    u[flip], w[flip] = 1 - u[flip], 1 - w[flip]
    idx, ok = lay.index(np.zeros(1000, int), u, w, np.ones(1000, bool))
    k = lay.k[0]
    assert ok.all() and idx.max() < 2 * k * k and np.all(idx % 2 == 0)


def test_lit_triangles_are_exactly_those_holding_flux():
    """The eye pass looks the caustic map up only on lit triangles: every triangle with flux on
    any element (either side) is lit, none other, including triangles outside the map."""
    rng = np.random.default_rng(1)
    v, t = primitives.icosphere((0, 0, 0), 1.0, 2)
    receivers = rng.random(len(t)) < 0.7
    lay = ElementLayout.build(v, t, receivers, 0.002)
    illum = IlluminationMap.empty(lay, 3)
    tri, bu, bv = lay.barycentric_centres()
    pick = rng.random(lay.total) < 0.01  # a few elements of a few triangles, front or back
    idx, ok = lay.index(tri[pick], bu[pick], bv[pick], rng.random(pick.sum()) < 0.5)
    illum.deposit(idx[ok], np.ones((ok.sum(), 3), np.float32))
    expected = np.zeros(len(t), bool)
    expected[tri[pick]] = True
    assert expected.any() and not expected.all()
    assert np.array_equal(illum.lit_triangles(), expected)


def slab_scene(ior=1.5, dispersion="NONE"):
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
                                {"kind": "DIELECTRIC", "ior": ior, "dispersion": dispersion, "color": (1, 1, 1)}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (8, 0, 0), (0, 8, 0)), material=0)
    s.add_mesh(*primitives.box((0, 0, 1.0), (1.0, 1.0, 0.2)), material=1)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": (0, 0, -1), "power": 2.0}])
    s.camera = Camera.look_at((0, -4, 3), (0, 0, 0), width=16, height=16)
    return s


def test_flux_under_a_glass_slab_is_the_fresnel_transmitted_fraction():
    """Sun straight down on a 1 x 1 m slab: flux on the floor = E A (1 - R) / (1 + R) (two
    faces with all internal reflections; R = ((n - 1)/(n + 1))^2 at normal incidence)."""
    ctx, lp, illum, stats = light_map(slab_scene(), light_paths=200_000, max_bounces=32)
    r = ((1.5 - 1) / 2.5) ** 2
    expected = ctx.lights.spectrum[0] * 1.0 * (1 - r) / (1 + r)
    got = illum.flux.sum(axis=0)
    # binomial noise of the Fresnel choices over ~N paths: well under 1 %
    np.testing.assert_allclose(got, expected, rtol=0.01)
    pos = element_positions(ctx, illum)
    lit = illum.flux.sum(axis=1) > 0
    assert np.all(np.abs(pos[lit, :2]) <= 0.5 + 0.05)  # only under the slab


@pytest.mark.slow
def test_ball_lens_focuses_at_n_r_over_2_n_minus_1():
    """Paraxial rays (a stop with a 0.15 R hole above the ball) focus f = n R / (2 (n - 1)) from the centre."""
    n, radius = 1.5, 1.0
    f = n * radius / (2 * (n - 1))
    spreads = {}
    for depth in (f - 0.3, f - 0.15, f, f + 0.15, f + 0.3):
        mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)}, {"kind": "DIELECTRIC", "ior": n}])
        s = Scene(materials=mats)
        s.add_mesh(*primitives.quad((0, 0, -depth), (0.6, 0, 0), (0, 0.6, 0)), material=0)
        s.add_mesh(*primitives.icosphere((0, 0, 0), radius, 5), material=1)
        # the stop: an annulus, diffuse (paths that hit it end there)
        annulus = load_example("gratings").annulus
        v, t, _ = annulus(0.15 * radius, 3.0, segments=128, rings=4)
        s.add_mesh(v + [0, 0, 1.5], t, material=0)
        s.lights = Lights.from_list([{"kind": "SUN", "direction": (0, 0, -1), "power": 1.0}])
        s.camera = Camera(width=4, height=4)
        ctx, lp, illum, _ = light_map(s, light_paths=100_000, element_size=0.004)
        pos = element_positions(ctx, illum)
        on_floor = np.abs(pos[:, 2] + depth) < 1e-6
        w = illum.flux[on_floor].sum(axis=1)
        p = pos[on_floor]
        assert w.sum() > 0
        # encircled flux within 1 cm of the axis (robust to the few internally reflected paths)
        spreads[depth] = np.sum(w[np.hypot(p[:, 0], p[:, 1]) < 0.01]) / w.sum()
    best = max(spreads, key=spreads.get)
    assert best == pytest.approx(f, abs=0.01), spreads
    assert spreads[f] > 2 * spreads[f + 0.3] and spreads[f] > 2 * spreads[f - 0.3]


def prism_on_wall(mode):
    """A BK7 prism lit by a sun at its 550 nm minimum-deviation incidence; a wall 20 m away."""
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
                                {"kind": "DIELECTRIC", "dispersion": "BK7"}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.prism((0, 0, 0), side=0.3, length=0.3, axis="Y"), material=1)
    n550 = float(ior_spectrum(np.array([550.0]), "BK7")[0])
    th = np.arcsin(n550 * 0.5)
    normal = np.array([-np.cos(np.radians(30)), 0, np.sin(np.radians(30))])
    up = np.array([np.sin(np.radians(30)), 0, np.cos(np.radians(30))])
    d = -np.cos(th) * normal + np.sin(th) * up
    # an opaque card just under the base, so only light through the left face reaches the screen
    base_z = -0.3 * np.cos(np.radians(30)) / 3
    s.add_mesh(*primitives.quad((0.0, 0, base_z - 0.001), (0.298, 0, 0), (0, 1.0, 0)), material=0)
    # a 3 x 1 m screen at x = 20 facing -x, where the spectrum lands (about 20 deg below the prism)
    s.add_mesh(*primitives.quad((20.0, 0, -7.0), (0, 0, 3.0), (0, 1.0, 0)), material=0)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": d, "power": 1.0}])
    s.camera = Camera(width=4, height=4)
    return s, d, th


@pytest.fixture(scope="module")
def prism_maps():
    out = {}
    for mode in ("SPLIT", "SAMPLE"):
        s, d, th = prism_on_wall(mode)
        out[mode] = light_map(s, light_paths=60_000 if mode == "SPLIT" else 400_000,
                              dispersion_sampling=mode, element_size=0.01)
    return out, d, th


def test_prism_spreads_wavelengths_where_snell_puts_them(prism_maps):
    maps, d, th = prism_maps
    ctx, lp, illum, _ = maps["SPLIT"]
    pos = element_positions(ctx, illum)
    wall = np.abs(pos[:, 0] - 20.0) < 1e-6
    wl = ctx.grid.wavelengths
    n = ior_spectrum(wl, "BK7")
    a = np.radians(60)
    th_e = np.arcsin(n * np.sin(a - np.arcsin(np.sin(th) / n)))
    dev = th + th_e - a  # deviation of each wavelength from the incoming beam, in the x-z plane
    # exit directions: the incoming direction rotated by the deviation towards the base (-z side)
    ang_in = np.arctan2(d[2], d[0])
    ang_out = ang_in - dev
    z_pred = 20.0 * np.tan(ang_out)  # from near the origin, the prism is 0.3 m across
    got = []
    for k in range(0, len(wl), 10):
        w = illum.flux[wall, k]
        z = pos[wall, 2]
        # the main beam only: stray paths (internal reflections) land far away
        peak = z[np.argmax(w)]
        near = np.abs(z - peak) < 0.3
        got.append(np.sum(w[near] * z[near]) / w[near].sum())
    got = np.array(got)
    pred = z_pred[::10]
    # relative positions (the beam's offset inside the prism cancels): the spectrum's spread
    np.testing.assert_allclose(got - got[3], pred - pred[3], atol=0.03)
    assert got[0] < got[-1]  # violet deviates most (lower on the wall)


def test_split_and_sample_give_the_same_caustic(prism_maps):
    maps, _, _ = prism_maps
    s_split = maps["SPLIT"][2].flux.sum(axis=0)
    s_sample = maps["SAMPLE"][2].flux.sum(axis=0)
    assert s_split.sum() > 0
    np.testing.assert_allclose(s_sample.sum(), s_split.sum(), rtol=0.02)
    # per wavelength, within the SAMPLE estimate's noise (about 1/sqrt(paths per wavelength))
    np.testing.assert_allclose(s_sample, s_split, rtol=0.15)


def test_no_caster_no_light_pass():
    s = slab_scene()
    s.tri_material[:] = 0  # everything diffuse
    res = render(s, RenderSettings(samples=1))
    assert not res.plan.light_pass and "light pass skipped: no mirror or glass" in res.plan.summary()
    assert "light_paths" not in res.stats


def test_light_that_cannot_reach_the_caster_emits_nothing():
    s = slab_scene()
    s.lights = Lights.from_list([{"kind": "SPOT", "position": (3, 0, 3), "direction": (1, 0, 0),
                                  "spot_size": np.radians(30), "power": 100.0},
                                 {"kind": "AREA_RECT", "position": (0, 0, 3), "direction": (0, 0, 1), "power": 100.0}])
    res = render(s, RenderSettings(samples=1))
    assert not res.plan.light_pass and "no light reaches" in res.plan.summary()


def test_caustics_appear_in_the_render_and_its_pass():
    s = slab_scene()
    s.camera = Camera.look_at((0, 0, 6), (0, 0, 0), lens=35, width=32, height=32, )
    res = render(s, RenderSettings(samples=2, light_paths=50_000))
    assert res.plan.light_pass and res.stats["light_paths"] == 50_000
    c = res.passes["Caustics"]
    assert c.max() > 0
    np.testing.assert_allclose(res.passes["Direct"] + res.passes["Indirect"] + c + res.passes["Diffraction"], res.rgb,
                               atol=1e-5)


def grating_under_sun(via_mirror: bool):
    """A reflection grating lit by a sun from the upper left: directly, or by a sun shining
    upwards onto a ceiling mirror that reflects it down at the same angle."""
    mats = Materials.from_list([
        {"kind": "DIFFUSE", "color": (0, 0, 0), "grating": 1, "period": 1600.0, "slit_width": 600.0,
         "slit_count": 200, "coherence_length": 5.0},
        {"kind": "MIRROR", "color": (1, 1, 1)},
    ])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (1.0, 0, 0), (0, 1.0, 0)), material=0, tangent=(1, 0, 0))
    d_a = np.array([0.6, 0.0, -1.0]) / np.hypot(0.6, 1.0)
    if via_mirror:
        s.add_mesh(*primitives.quad((-1.2, 0, 2.0), (2.4, 0, 0), (0, -1.6, 0)), material=1)  # facing down
        d = d_a * [1, 1, -1]
    else:
        d = d_a
    s.lights = Lights.from_list([{"kind": "SUN", "direction": d, "power": 1.0}])
    s.camera = Camera.look_at((1.4, 0.0, 1.3), (0, 0, 0), lens=35, width=24, height=24)
    return s


def test_light_arriving_through_a_mirror_diffracts_like_direct_light():
    direct = render(grating_under_sun(False), RenderSettings(samples=4, light_paths=0))
    mirrored = render(grating_under_sun(True), RenderSettings(samples=4, light_paths=400_000, element_size=0.1))
    assert mirrored.plan.light_pass
    a, b = direct.passes["Diffraction"], mirrored.passes["Diffraction"]
    assert a.max() > 0
    # the records' Monte Carlo noise (about 1500 paths per 10 cm element) is ~1 % over the image
    assert b.sum() == pytest.approx(a.sum(), rel=0.03)
    # and the same pixels light up
    lit = a.sum(axis=2) > 0.05 * a.sum(axis=2).max()
    assert (b.sum(axis=2)[lit] > 0).mean() > 0.95


def test_light_pass_is_the_same_whatever_the_threads():
    maps = [light_map(slab_scene(), light_paths=3 * 32768, threads=t)[2].flux for t in (1, 2)]
    np.testing.assert_array_equal(maps[0], maps[1])


def _light_pass_outputs(scene, threads, **kw):
    ctx, lp, illum, stats = light_map(scene, threads=threads, **kw)
    rec = lp.grating_records
    return (illum.flux, None if rec is None else rec.flux, None if lp.splat is None else lp.splat.image,
            {k: stats[k] for k in ("light_paths", "light_deposits", "light_rays")})


@pytest.mark.parametrize("threads", [3, 4])
def test_more_threads_than_lanes_trace_batches_into_logs_with_the_same_bits(threads, monkeypatch):
    """With more threads than LANES every thread traces whole batches into logs replayed in lane
    order: the caustic map, the grating records and the camera splat are those of one thread, bit
    for bit, and the logged route really ran on several threads."""
    import threading
    from grating_record_scenes import two_mirror_scene
    from opal_diffraction.core.integrators.light import light_pass as lp_mod

    seen = set()
    traced = lp_mod.trace_logged

    def spy(*a, **k):
        seen.add(threading.get_ident())
        return traced(*a, **k)

    for scene, kw in ((load_example("prism").build_scene(64, 40), dict(light_paths=12 * 32768)),
                      (two_mirror_scene(), dict(light_paths=8 * 32768, element_size=0.05))):
        one = _light_pass_outputs(scene, 1, **kw)
        monkeypatch.setattr(lp_mod, "trace_logged", spy)
        many = _light_pass_outputs(scene, threads, **kw)
        monkeypatch.setattr(lp_mod, "trace_logged", traced)
        lit = 0
        for a, b in zip(one[:3], many[:3]):
            assert (a is None) == (b is None)
            if a is not None:
                lit += int(a.any())
                np.testing.assert_array_equal(a, b)
        assert lit >= 1  # the prism: its caustic map and splat; the mirrors: the grating records
        assert one[3] == many[3]
    assert one[1] is not None and one[1].any()  # the last scene's gratings hold records
    assert len(seen) >= 2


def test_a_too_fine_element_size_is_coarsened_with_a_warning():
    s = slab_scene()
    res = render(s, RenderSettings(samples=1, light_paths=10_000, element_size=1e-4))
    assert any("element size 0.1 mm needs more memory" in w for w in res.warnings)


def test_cancel_during_the_light_pass_stops_the_render():
    messages = []  # Esc once the light pass has begun (its first progress report)
    res = render(slab_scene(), RenderSettings(samples=4, light_paths=2_000_000),
                 progress=lambda f, m: messages.append(m),
                 should_cancel=lambda: any(m.startswith("light pass") for m in messages))
    assert res.cancelled and res.stats.get("cancelled") and res.stats["light_paths"] < 2_000_000


def test_more_receiving_triangles_than_the_map_can_hold_is_a_warning_not_a_hang():
    """At 1 nm (301 wavelengths) the map holds ~53 k element pairs: a floor of 80 k triangles
    under a glass box gets no caustic map and a warning, and the render finishes (the element
    search used to double the element size forever)."""
    n = 200
    x, y = np.meshgrid(np.linspace(-4, 4, n + 1), np.linspace(-4, 4, n + 1), indexing="ij")
    v = np.stack([x, y, np.zeros_like(x)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = (i * (n + 1) + j).ravel()
    t = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)])
    s = slab_scene()
    floor = Scene(materials=s.materials)
    floor.add_mesh(v, t, material=0)
    floor.add_mesh(*primitives.box((0, 0, 1.0), (1.0, 1.0, 0.2)), material=1)
    floor.lights, floor.camera = s.lights, s.camera
    res = render(floor, RenderSettings(samples=1, light_paths=20_000, wavelength_step=1.0), spectral_film=True)
    assert any("receiving triangles are too many for the caustic map" in w for w in res.warnings)
    assert np.isfinite(res.spectral).all() and res.rgb.mean() > 0


def test_automatic_light_paths_follow_the_image_size():
    """light_paths=None (the default) sizes the light pass to the image: 1 path per camera
    sample within 65 536 - 1 000 000 (settings.auto_light_paths); an explicit count is kept."""
    from dataclasses import replace as _replace

    from opal_diffraction.core.scene.settings import auto_light_paths

    assert RenderSettings().light_paths is None
    assert auto_light_paths(64, 64, 4) == 65_536 and auto_light_paths(64, 64, 32) == 131_072
    assert auto_light_paths(640, 400, 4) == 1_000_000 and auto_light_paths(640, 400, 1) == 256_000
    scene = slab_scene()
    for (w, h, spp), expected in (((64, 64, 1), 65_536), ((100, 50, 16), 80_000), ((800, 600, 16), 1_000_000)):
        s = _replace(scene, camera=_replace(scene.camera, width=w, height=h))
        assert prepare(s, RenderSettings(samples=spp)).settings.light_paths == expected
        assert prepare(s, RenderSettings(samples=spp, light_paths=1234)).settings.light_paths == 1234
