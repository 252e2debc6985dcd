"""The camera splat of the light pass (docs/physics.md section 4.9) against independent estimates.

The scene: a sun shining up onto a ceiling mirror that throws its beam down onto a floor the
camera sees directly. The same radiance field is made without the mirror by the sun shining
down through a window of the mirror's shape in a black screen (the mirror plane is its own
image, and a white mirror reflects all): there the eye pass's next-event estimation renders it
as Direct light, deterministically in the patch (a delta light, no noise but the pixel
positions). The splat must match that image pixel block by pixel block, edges (the filter)
included, and must match the caustic map's estimate where the map is unbiased (inside the patch).
"""

import numpy as np
import pytest

from chi2 import chi2_normal_scores, pearson
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.sampling.camera import FilterSampler
from opal_diffraction.core.integrators.light.camera_splat import blackman_harris_density, filter_density
from opal_diffraction.core.integrators.light.light_pass import run_light_pass
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.frame import render, render_prepared
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.render.plan import plan_render

#: NumPy 2 renamed np.trapz to np.trapezoid (the same trapezoidal rule); NumPy 1.24-1.26 (Blender 4.2-5.0) has only trapz
_trapezoid = getattr(np, "trapezoid", None) or np.trapz

SUN_UP = np.array([-1.5, 0.0, 1.0]) / np.hypot(1.5, 1.0)  # travelling up to the mirror at z = 1
CAM = dict(eye=(-2.0, -3.0, 3.0), target=(0.5, 0.0, 0.0))


def _scene(mirror: bool, width=48, height=48) -> Scene:
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
                                {"kind": "MIRROR", "color": (1, 1, 1)},
                                {"kind": "DIFFUSE", "color": (0, 0, 0)}])
    s = Scene(materials=mats)
    # the floor, x in [-0.4, 1.5], y in [-1.5, 1.5]: all of it behind the screen but for the window
    s.add_mesh(*primitives.quad((0.55, 0, 0), (1.9, 0, 0), (0, 3.0, 0)), material=0)
    if mirror:
        s.add_mesh(*primitives.quad((2.0, 0, 1.0), (1.0, 0, 0), (0, -1.0, 0)), material=1)  # facing down
        d = SUN_UP
    else:  # a black screen at z = 1 around a window where the mirror was, the sun shining down
        for c, su, sv in (((1.25, 0, 1), 0.5, 8.0), ((4.75, 0, 1), 4.5, 8.0), ((2.0, 2.25, 1), 1.0, 3.5),
                          ((2.0, -2.25, 1), 1.0, 3.5)):
            s.add_mesh(*primitives.quad(c, (su, 0, 0), (0, sv, 0)), material=2)
        d = SUN_UP * [1, 1, -1]
    s.lights = Lights.from_list([{"kind": "SUN", "direction": d, "power": 2.0}])
    s.camera = Camera.look_at(CAM["eye"], CAM["target"], lens=120, width=width, height=height)
    return s


@pytest.fixture(scope="module")
def images():
    common = dict(samples=16, wavelength_step=20.0, diffuse_bounces=0)
    ref = render(_scene(False), RenderSettings(light_paths=0, **common))
    on = render(_scene(True), RenderSettings(light_paths=400_000, **common))
    off = render(_scene(True), RenderSettings(light_paths=400_000, caustic_splat=False, **common))
    return ref, on, off


def _blocks(img, k=4):
    """Means over k x k pixel blocks of an (H, W) image."""
    h, w = img.shape
    return img[: h // k * k, : w // k * k].reshape(h // k, k, w // k, k).mean(axis=(1, 3))


def test_the_filter_density_is_what_the_eye_pass_samples():
    """filter_density integrates to 1, has the Blackman-Harris window's mass within 1 % in 0.1 px
    cells over |t| < 1 (the table is coarse further out), and is the density of FilterSampler's offsets (chi-square over 40
    cells, 400 000 samples, cells with expected < 5 pooled; the tails included, where the
    table's linear interpolation makes the offsets uniform)."""
    width = 1.5
    filt = FilterSampler(width)
    t = np.linspace(-width - 0.1, width + 0.1, 200001)
    f = filter_density(t, filt)
    assert abs(_trapezoid(f, t) - 1.0) < 1e-4
    cells = np.linspace(-1.0, 1.0, 21)  # 0.1 px cells where the window is above 5 % of its peak
    mass = lambda dens: np.array([_trapezoid(dens(g), g) for g in (np.linspace(a, b, 4001)  # noqa: E731
                                                                  for a, b in zip(cells[:-1], cells[1:]))])
    np.testing.assert_allclose(mass(lambda g: filter_density(g, filt)), mass(lambda g: blackman_harris_density(g, width)),
                               rtol=0.01)
    n = 400_000
    x = filt.offsets(np.random.default_rng(1).random(n))
    edges = np.linspace(-width, width, 41)
    obs, _ = np.histogram(x, edges)
    exp = np.array([n * _trapezoid(filter_density(g, filt), g) for g in
                    (np.linspace(a, b, 2001) for a, b in zip(edges[:-1], edges[1:]))])
    p, info = pearson(obs, exp)
    assert p > 1e-3, info


def test_the_splat_of_a_mirrored_sun_is_the_direct_image_of_the_same_beam(images):
    """Chi-square over 4 x 4 pixel blocks of (splat - Direct reference), edges included, with
    the noise of a block mean from the spread of the patch's interior blocks (the splat's noise
    scales with its signal, so the edge blocks are tested conservatively)."""
    ref, on, _ = images
    want = ref.passes["Direct"].mean(axis=2)
    got = on.passes["Caustics"].mean(axis=2)
    lit = want > 0.02 * want.max()
    assert lit.sum() > 100, "the patch must be in view"
    b_ref, b_got = _blocks(want), _blocks(got)
    interior = _blocks((want > 0.999 * np.median(want[lit])).astype(float)) == 1.0  # blocks wholly inside
    assert interior.sum() >= 6
    sd = np.std(b_got[interior] - b_ref[interior], ddof=1)
    assert sd < 0.05 * b_ref[interior].mean()  # not so noisy the test says nothing
    region = _blocks(lit.astype(float)) > 0  # every block the patch touches
    z = (b_got[region] - b_ref[region]) / sd
    assert chi2_normal_scores(z) > 1e-3, np.round(z, 1)
    # the mean over the patch: Z-test on the interior blocks' mean
    z_mean = (b_got[interior].mean() - b_ref[interior].mean()) / (sd / np.sqrt(interior.sum()))
    assert abs(z_mean) < 4.0
    # nothing lands where the beam does not (the map sees the floor through the mirror as well)
    _, _, off = images
    dark = _blocks(((want == 0) & (off.passes["Caustics"].max(axis=2) == 0)).astype(float)) == 1.0
    assert dark.sum() > 20  # (a filter tail the reference's 16 samples missed may reach in: 1e-3 of the patch)
    assert np.abs(_blocks(got)[dark]).max() < 1e-3 * b_ref[interior].mean()


def test_the_splat_equals_the_maps_estimate_inside_the_patch(images):
    """The map (caustic_splat off) and the splat estimate the same radiance: Z-test on the
    mean over the interior blocks (the map is unbiased away from the patch's edges)."""
    ref, on, off = images
    want = ref.passes["Direct"].mean(axis=2)
    lit = want > 0
    inner = _blocks((want > 0.999 * np.median(want[lit])).astype(float), 8) == 1.0
    assert inner.sum() >= 2
    a = _blocks(on.passes["Caustics"].mean(axis=2), 8)[inner]
    b = _blocks(off.passes["Caustics"].mean(axis=2), 8)[inner]
    a4 = _blocks(on.passes["Caustics"].mean(axis=2))[_blocks((want > 0.999 * np.median(want[lit])).astype(float)) == 1.0]
    b4 = _blocks(off.passes["Caustics"].mean(axis=2))[_blocks((want > 0.999 * np.median(want[lit])).astype(float)) == 1.0]
    se = np.sqrt(np.var(a4, ddof=1) / len(a4) + np.var(b4, ddof=1) / len(b4))
    assert abs(a4.mean() - b4.mean()) < 4 * se, (a.mean(), b.mean(), se)


def test_combined_is_direct_indirect_caustics_diffraction_with_the_splat(images):
    _, on, _ = images
    p = on.passes
    np.testing.assert_allclose(p["Direct"] + p["Indirect"] + p["Caustics"] + p["Diffraction"], on.rgb, atol=1e-5)
    assert on.stats["light_paths"] == 400_000


def test_another_view_of_a_kept_light_pass_uses_the_map_everywhere():
    """with_view to another camera: the splat (made for the first camera) is not used, and the
    image is the one a render with the splat off makes from that camera, bit for bit (the light
    pass's random streams do not depend on the splat)."""
    st = RenderSettings(samples=4, light_paths=50_000, wavelength_step=20.0, diffuse_bounces=0)
    prepared = prepare(_scene(True, 24, 24), st)
    light = run_light_pass(prepared, plan=plan_render(prepared))
    assert light.splat is not None and light.splat.image.shape[:2] == (24, 24)
    cam2 = Camera.look_at((-2.5, -2.0, 3.2), CAM["target"], lens=35, width=24, height=24)
    moved = render_prepared(prepared.with_view(cam2), light)
    s2 = _scene(True, 24, 24)
    s2.camera = cam2
    expected = render(s2, RenderSettings(samples=4, light_paths=50_000, wavelength_step=20.0, diffuse_bounces=0,
                                         caustic_splat=False))
    np.testing.assert_array_equal(moved.rgb, expected.rgb)
    # the splat's own view uses it: a fresh render with the splat, not one without
    same = render_prepared(prepared, light)
    np.testing.assert_array_equal(same.rgb, render(_scene(True, 24, 24), st).rgb)
    off = render(_scene(True, 24, 24), RenderSettings(samples=4, light_paths=50_000, wavelength_step=20.0,
                                                      diffuse_bounces=0, caustic_splat=False))
    assert np.abs(same.passes["Caustics"] - off.passes["Caustics"]).max() > 0.01 * off.passes["Caustics"].max()


def test_a_region_is_the_crop_of_the_whole_image():
    st = RenderSettings(samples=2, light_paths=30_000, wavelength_step=20.0, diffuse_bounces=0)
    full = render(_scene(True, 24, 24), st)
    part = render(_scene(True, 24, 24), st, region=(4, 6, 20, 18))
    np.testing.assert_allclose(part.passes["Caustics"], full.passes["Caustics"][6:18, 4:20], rtol=1e-5, atol=1e-7)


def test_the_spectral_exr_gets_the_splat_in_its_spectrum(tmp_path, monkeypatch):
    """An RGB splat film (an image over the spectral cap, here the cap set to 0) and a spectral
    one (a spectral EXR asked) give the same RGB; the spectral image holds the splat."""
    from opal_diffraction.core.integrators.light import camera_splat

    st = dict(samples=2, light_paths=30_000, wavelength_step=20.0, diffuse_bounces=0)
    with monkeypatch.context() as m:
        m.setattr(camera_splat, "SPECTRAL_CAP", 0)
        rgb_only = render(_scene(True, 16, 16), RenderSettings(**st))
        assert rgb_only.passes["Caustics"].max() > 0
    spectral = render(_scene(True, 16, 16), RenderSettings(spectral_exr=str(tmp_path / "s.exr"), **st))
    np.testing.assert_allclose(spectral.rgb, rgb_only.rgb, rtol=1e-4, atol=1e-6)
    conv_rgb = spectral.rgb
    from opal_diffraction.core.spectral.spectrum import SpectralConverter

    conv = SpectralConverter(RenderSettings(**st).grid())
    np.testing.assert_allclose(conv.to_rgb(spectral.spectral), conv_rgb, rtol=1e-4, atol=1e-6)


def test_a_splat_lands_in_the_pixels_whose_eye_samples_would_see_it():
    """CameraConnection.footprint's weight of pixel (5, 7) at image points, integrated over
    0.25 px cells, against where that pixel's eye samples fall (FilterSampler offsets about its
    centre, 1 000 000 samples): chi-square, cells with expected < 5 pooled."""
    from opal_diffraction.core.integrators.light.camera_splat import CameraConnection

    prepared = prepare(_scene(True, 12, 12), RenderSettings(samples=1, light_paths=1000, wavelength_step=20.0))
    conn = CameraConnection.of(prepared)
    px, py = 5, 7
    rng = np.random.default_rng(3)
    n = 1_000_000
    x = px + 0.5 + conn.filt.offsets(rng.random(n))
    y = py + 0.5 + conn.filt.offsets(rng.random(n))
    edges_x = np.arange(px - 1.5, px + 2.75, 0.25)
    edges_y = np.arange(py - 1.5, py + 2.75, 0.25)
    obs, _, _ = np.histogram2d(x, y, [edges_x, edges_y])
    # expected: n * integral over each cell of the weight footprint() gives pixel (5, 7)
    sub = (np.arange(8) + 0.5) / 8 * 0.25
    cx = (edges_x[:-1, None] + sub[None, :]).ravel()
    cy = (edges_y[:-1, None] + sub[None, :]).ravel()
    gx, gy = np.meshgrid(cx, cy, indexing="ij")
    idx, w = conn.footprint(gx.ravel(), gy.ravel())
    mine = np.where(idx == py * conn.width + px, w, 0.0).sum(axis=1).reshape(len(cx), len(cy))
    exp = n * mine.reshape(len(edges_x) - 1, 8, len(edges_y) - 1, 8).mean(axis=(1, 3)) * 0.25**2
    assert abs(exp.sum() / n - 1) < 0.01  # the pixel's filter, whole
    p, info = pearson(obs, exp)
    assert p > 1e-3, info
