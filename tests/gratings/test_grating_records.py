"""Light-pass records at gratings (docs/physics.md section 3.5): they keep the direction
structure of the light that arrived, are found from the viewer's side of a transmission grating,
and sit on elements sized by where the grating flux lands.

The render tests compare a grating lit only through plane mirrors with the same grating lit by
point lights at the light's mirror images (mirrors removed, power x mirror reflectance): the law
of reflection, not our output. The reference has no Monte Carlo noise (point lights by shadow
ray, pixel centres, exact wavelength-bin averages); the noise of the mirror render is measured
from independent renders (seeds), and the per-block differences are t-tested with the number of
blocks accounted for (Bonferroni).
"""

import numpy as np
import pytest
from scipy import stats as sps

from grating_record_scenes import (mirror_transmission_scene, two_mirror_scene, two_virtual_lights_scene,
                                   virtual_transmission_scene)
from opal_diffraction.core.transport.elements import ElementLayout
from opal_diffraction.core.gratings.records import (DIRECTION_GRID, RECORD_DEPOSITS, GratingRecords,
                                                   layout_from_hits, octahedral_bin)
from opal_diffraction.core.integrators.light.light_pass import run_light_pass
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.render.plan import plan_render

PIXELS = 40
BLOCK = 4       # pixel blocks of BLOCK x BLOCK
BANDS = 4       # wavelength bands compared per block
SEEDS = 6       # independent mirror renders
LIGHT_PATHS = 150_000
ALPHA = 1e-3    # family-wise false-alarm rate of each test


def one_triangle_layout(k=1):
    area = np.array([0.5])
    return ElementLayout.from_areas(area, np.array([True]), area[0] / (k * k))


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def test_two_beams_into_one_element_come_back_as_two_lobes_with_their_flux():
    """docs/physics.md section 3.5: two directions into one element stay two sources."""
    n = 8
    layout = one_triangle_layout()
    rec = GratingRecords.empty(layout, n)
    rng = np.random.default_rng(1)
    d_a, d_b = unit([0.7, 0.0, 0.7]), unit([-0.4, 0.1, 0.9])
    fa = rng.random((300, n)).astype(np.float32)  # white paths, beam a (front side, element 0)
    fb = rng.random((200, n)).astype(np.float32)  # white paths, beam b
    for part in np.array_split(np.arange(300), 3):  # several calls, as the light pass makes them
        rec.deposit(np.zeros(len(part), np.int64), fa[part], towards_source=np.tile(d_a, (len(part), 1)))
    rec.deposit(np.zeros(200, np.int64), fb, towards_source=np.tile(d_b, (200, 1)))
    hit, irr, d = rec.lobes(np.array([0]), np.array([0.2]), np.array([0.3]))
    assert len(hit) == 2 and (hit == 0).all()
    area = layout.element_area[0]
    which = np.argmax(d @ np.stack([d_a, d_b]).T, axis=1)
    assert sorted(which) == [0, 1]
    for w, d_true, f in ((0, d_a, fa), (1, d_b, fb)):
        i = int(np.flatnonzero(which == w)[0])
        np.testing.assert_allclose(d[i], d_true, atol=1e-6)
        np.testing.assert_allclose(irr[i], f.astype(np.float64).sum(axis=0) / area, rtol=1e-5)


def test_dispersed_paths_keep_a_direction_per_wavelength_band():
    """Mono paths (after a prism) whose direction depends on the wavelength come back with each
    band's own direction, not the mean over the spectrum."""
    n = 32
    layout = one_triangle_layout()
    rec = GratingRecords.empty(layout, n)
    lam = np.repeat(np.arange(n), 10)
    angle = np.radians(30 + 0.1 * lam)  # 3 degrees across the spectrum, inside one direction bin
    d = np.stack([np.sin(angle), np.zeros_like(angle), np.cos(angle)], 1)
    rec.deposit(np.zeros(len(lam), np.int64), np.ones(len(lam), np.float32), lam, d)
    hit, irr, src = rec.lobes(np.array([0]), np.array([0.2]), np.array([0.3]))
    assert len(hit) == min(n, rec.bands)
    for i in range(len(hit)):
        lit = np.flatnonzero(irr[i] > 0)  # the band's wavelengths
        mean_angle = np.degrees(np.arctan2(src[i, 0], src[i, 2]))
        assert mean_angle == pytest.approx(30 + 0.1 * lit.mean(), abs=1e-3)
        np.testing.assert_allclose(irr[i, lit], 10 / layout.element_area[0], rtol=1e-5)


def test_adding_lanes_equals_one_map_and_compaction_keeps_the_sums():
    n = 4
    layout = one_triangle_layout(k=16)
    rng = np.random.default_rng(2)
    m = 200_000  # > the pending buffer: compaction happens mid-way
    el = rng.integers(0, layout.total, m)
    f = rng.random((m, n)).astype(np.float32)
    d = rng.normal(size=(m, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    one, a, b = (GratingRecords.empty(layout, n) for _ in range(3))
    one.deposit(el, f, towards_source=d)
    a.deposit(el[: m // 2], f[: m // 2], towards_source=d[: m // 2])
    b.deposit(el[m // 2:], f[m // 2:], towards_source=d[m // 2:])
    a += b
    np.testing.assert_array_equal(one.keys, a.keys)
    np.testing.assert_allclose(one.flux, a.flux, rtol=1e-5)
    np.testing.assert_array_equal(one.count, a.count)
    assert one.count.sum() == m
    # brute force: every (cell, direction bin) pair's flux
    key = (el >> 1) * one.stride + (el & 1) * (one.bands + 1) * DIRECTION_GRID**2 + octahedral_bin(d)
    u, inv = np.unique(key, return_inverse=True)
    np.testing.assert_array_equal(u, one.keys)
    ref = np.zeros((len(u), n))
    np.add.at(ref, inv, f.astype(np.float64))
    np.testing.assert_allclose(one.flux, ref, rtol=1e-5)


def test_octahedral_bins_cover_the_sphere():
    rng = np.random.default_rng(3)
    d = rng.normal(size=(100_000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    counts = np.bincount(octahedral_bin(d), minlength=DIRECTION_GRID**2)
    assert len(counts) == DIRECTION_GRID**2 and counts.min() > 0
    # the octahedral map is within a factor ~2 of equal-area: no bin is starved or bloated
    assert counts.max() / counts.min() < 4


def test_light_from_the_two_sides_never_shares_a_lobe():
    """Grazing light just above and just below the element's plane falls in one direction bin;
    it comes back as two lobes, each on its own side (what a transmission grating needs)."""
    n = 4
    rec = GratingRecords.empty(one_triangle_layout(), n)
    above, below = unit([1.0, 0.0, 0.02]), unit([1.0, 0.0, -0.02])
    assert octahedral_bin(above[None])[0] == octahedral_bin(below[None])[0]
    f = np.ones((10, n), np.float32)
    rec.deposit(np.zeros(10, np.int64), f, towards_source=np.tile(above, (10, 1)))  # front side
    rec.deposit(np.ones(10, np.int64), 3 * f, towards_source=np.tile(below, (10, 1)))  # back side
    hit, irr, d = rec.lobes(np.array([0]), np.array([0.2]), np.array([0.3]))
    assert len(hit) == 2
    up = d[:, 2] > 0
    np.testing.assert_allclose(d[up][0], above, atol=1e-6)
    np.testing.assert_allclose(d[~up][0], below, atol=1e-6)
    np.testing.assert_allclose(irr[~up][0] / irr[up][0], 3.0, rtol=1e-6)


def test_pilot_layout_puts_the_target_deposits_on_the_lit_part_of_a_triangle():
    """Hits in a small disc of a large triangle: the lit elements, not all elements, get about
    the target number of deposits (docs/physics.md section 3.5)."""
    area = np.array([0.5])
    rng = np.random.default_rng(4)
    target, full, pilot = 32, 400_000, 20_000

    def disc(m):
        r, phi = 0.05 * np.sqrt(rng.random(m)), 2 * np.pi * rng.random(m)
        return 0.3 + r * np.cos(phi), 0.3 + r * np.sin(phi)

    bu, bv = disc(pilot)
    layout = layout_from_hits(area, np.array([True]), np.zeros(pilot, np.int64), bu, bv, full / pilot, target)
    fu, fv = disc(full)
    idx, _ = layout.index(np.zeros(full, np.int64), fu, fv, np.ones(full, bool))
    per = np.bincount(idx >> 1)
    per = per[per > 0]
    assert 0.5 * target < per.mean() < 1.5 * target  # disc-edge elements are partly lit


def _blocks(img, k_bands):
    """(blocks, bands) sums of a (H, W, n) spectral image over BLOCK x BLOCK pixels and k_bands
    equal wavelength bands."""
    h, w, n = img.shape
    b = img.reshape(h // BLOCK, BLOCK, w // BLOCK, BLOCK, n).sum(axis=(1, 3))
    edges = np.linspace(0, n, k_bands + 1).astype(int)
    return np.stack([b[..., lo:hi].sum(axis=-1) for lo, hi in zip(edges[:-1], edges[1:])], -1).reshape(-1, k_bands)


def _compare_with_virtual_lights(mirror_scene, virtual_scene, element_size):
    base = RenderSettings(samples=1, filter_width=0.0, light_paths=LIGHT_PATHS, threads=1, element_size=element_size)
    # a plane mirror of reflectance R makes a virtual light of R times the power: R here is the
    # mirror material's reflectance spectrum (untinted: 1 at every wavelength)
    prepared = prepare(mirror_scene(PIXELS), base)
    refl = prepared.materials.reflectance[1]
    assert prepared.materials.clear[1] and np.all(refl == 1.0)
    ref = render(virtual_scene(PIXELS), RenderSettings(samples=1, filter_width=0.0, light_paths=0, threads=1), spectral_film=True)
    ref_b = _blocks(ref.spectral, BANDS)
    runs = []
    for seed in range(SEEDS):
        res = render(mirror_scene(PIXELS), RenderSettings(**{**base.__dict__, "seed": seed}), spectral_film=True)
        assert res.plan.light_pass
        runs.append(_blocks(res.spectral, BANDS))
    runs = np.array(runs)
    lit = ref_b > 0.05 * ref_b.max()  # the blocks the virtual lights light (from the reference)
    assert lit.sum() >= 20
    mean, se = runs.mean(axis=0)[lit], runs.std(axis=0, ddof=1)[lit] / np.sqrt(SEEDS)
    # the comparison must be able to see a 30 % error (phantom orders are several times that):
    # the records' noise per block, over the SEEDS renders, must be well below it
    noise_rms = np.sqrt(np.mean(se**2)) / ref_b[lit].mean()
    assert noise_rms < 0.12, noise_rms
    t = (mean - ref_b[lit]) / np.maximum(se, 1e-30)
    t_crit = sps.t.ppf(1 - ALPHA / (2 * lit.sum()), SEEDS - 1)
    assert np.abs(t).max() < t_crit, (np.abs(t).max(), t_crit)
    # the whole grating: total flux within 4 standard errors (one comparison)
    tot = runs[:, lit].sum(axis=1)
    assert abs(tot.mean() - ref_b[lit].sum()) < 4 * tot.std(ddof=1) / np.sqrt(SEEDS)
    # relative RMS over the lit blocks of the mean render: the noise's, not a bias's
    # (blocks are correlated through elements wider than a block: a loose factor, not a quantile)
    rel_rms = np.sqrt(np.mean((mean - ref_b[lit]) ** 2)) / ref_b[lit].mean()
    assert rel_rms < 2.0 * noise_rms + 1e-6, (rel_rms, noise_rms)
    return rel_rms, noise_rms


# element size: automatic (the pilot pass sizes the record elements), and a fixed 2 cm (the
# direction structure alone: one mean direction per element fails this at t > 100)
@pytest.mark.slow
@pytest.mark.parametrize("element_size", [0.0, 0.02])
def test_two_mirrors_onto_one_grating_equal_two_virtual_point_lights(element_size):
    _compare_with_virtual_lights(two_mirror_scene, two_virtual_lights_scene, element_size)


@pytest.mark.slow
@pytest.mark.parametrize("element_size", [0.0, 0.02])
def test_light_through_a_mirror_onto_a_transmission_grating_equals_the_virtual_light_behind_it(element_size):
    _compare_with_virtual_lights(mirror_transmission_scene, virtual_transmission_scene, element_size)


def test_record_elements_hold_the_target_deposits_whatever_the_path_count():
    """The pilot pass sizes the elements by where grating flux lands: the mean deposits per lit
    element stays near the target as the paths grow (so the records' noise falls with more
    paths, through finer elements), instead of being fixed by the whole grating's area."""
    for paths in (60_000, 240_000):
        prepared = prepare(two_mirror_scene(8), RenderSettings(light_paths=paths, threads=1))
        light = run_light_pass(prepared, plan=plan_render(prepared))
        st = light.stats
        assert st["pilot_grating_hits"] > 0
        assert 0.5 * RECORD_DEPOSITS < st["record_deposits_per_occupied"] < 2 * RECORD_DEPOSITS, (paths, dict(st))


def test_records_are_the_same_bits_whatever_the_threads():
    """The lanes' records add in lane order and the pilot runs once, so the thread count does not
    change a bit (docs/physics.md section 9.2)."""
    prepared = [prepare(two_mirror_scene(8), RenderSettings(light_paths=3 * 32768, threads=t)) for t in (1, 2)]
    maps = [run_light_pass(p, plan=plan_render(p)).grating_records for p in prepared]
    for name in ("keys", "flux", "direction", "count"):
        assert getattr(maps[0], name).tobytes() == getattr(maps[1], name).tobytes(), name
    assert maps[0].arrays()["moments"].tobytes() == maps[1].arrays()["moments"].tobytes()


def test_a_prism_before_the_grating_leaves_each_band_its_own_snell_direction():
    """Sun light through a glass wedge reaches the grating as one parallel beam per wavelength,
    turned by Snell's law at the tilted exit face (the entry face is at normal incidence). The
    records keep a direction per wavelength band: each band's lobe points along the flux-weighted
    mean of the Snell directions of its wavelengths, and the bands spread as the glass disperses
    (one mean direction per element would give every wavelength the same direction)."""
    from grating_record_scenes import WEDGE_ALPHA, sun_through_wedge_scene

    # three bounces: through the wedge (2) onto the grating, whose diffracted light (the light
    # pass scatters at gratings, docs/physics.md section 3.10) then stops before it can come back
    prepared = prepare(sun_through_wedge_scene(), RenderSettings(light_paths=60_000, threads=1, max_bounces=3))
    rec = run_light_pass(prepared, plan=plan_render(prepared)).grating_records
    n_glass = prepared.materials.ior[1].astype(np.float64)
    # Snell at the exit face: incidence alpha inside the glass, outward normal (sin a, 0, -cos a);
    # the direction of travel turns away from the normal to theta_t = asin(n sin a)
    theta_t = np.arcsin(n_glass * np.sin(WEDGE_ALPHA))
    # (the normal leans towards +x, so the ray, bent away from it, leaves at theta_t - alpha from
    # straight down towards -x)
    dev = theta_t - WEDGE_ALPHA
    towards_source = np.stack([np.sin(dev), np.zeros_like(dev), np.cos(dev)], 1)
    band = (rec.keys % rec.stride) // (DIRECTION_GRID**2)
    mono = (band >= 1) & (band <= rec.bands)  # front side, mono bands (the wedge disperses)
    flux, d = rec.flux[mono].astype(np.float64), rec.direction[mono].astype(np.float64)
    # the primary beam (no internal reflection): lobes within 2 degrees of the 550 nm direction
    k550 = int(np.argmin(np.abs(prepared.grid.wavelengths - 550)))
    d_unit = d / np.linalg.norm(d, axis=1, keepdims=True)
    primary = d_unit @ towards_source[k550] > np.cos(np.radians(2.0))
    assert primary.sum() > 50
    expected = flux[primary] @ towards_source  # per lobe: sum over wavelengths of flux x direction
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    err = np.degrees(np.arccos(np.clip(np.sum(expected * d_unit[primary], axis=1), -1, 1)))
    assert err.max() < 0.01, err.max()
    # and the bands do spread: the blue-most and red-most lobes differ as Snell says
    b = band[mono][primary]
    spread = np.degrees(np.arccos(np.clip(d_unit[primary][b == b.min()][0] @ d_unit[primary][b == b.max()][0], -1, 1)))
    lam_mean = [(flux[primary][b == x][0] * np.arange(len(n_glass))).sum() / flux[primary][b == x][0].sum()
                for x in (b.min(), b.max())]
    want = np.degrees(abs(np.interp(lam_mean[0], np.arange(len(dev)), dev) - np.interp(lam_mean[1], np.arange(len(dev)), dev)))
    assert want > 0.3 and spread == pytest.approx(want, rel=0.02), (spread, want)
