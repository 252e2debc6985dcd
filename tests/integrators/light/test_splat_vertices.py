"""The camera splat's kept light-path vertices, splatted into another camera
(core/integrators/light/splat_vertices.py, docs/physics.md section 4.9).

A re-splat is checked against two independent things: the light pass run again for the new
camera with the same seed (the same landings: the film must be the same bit for bit, on the
kernels and on the NumPy reference, through the direct lanes and the logged path of more
threads than lanes), and light passes of other seeds (a Z-test over pixel blocks: the re-splat is
an estimate of the new view's splat, and the kept view's splat is not).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from chi2 import chi2_normal_scores
from opal_diffraction.core.integrators.light.light_pass import run_light_pass
from opal_diffraction.core.integrators.light.splat_vertices import resplat, resplat_note
from opal_diffraction.core.render.frame import light_reuse, render
from opal_diffraction.core.render.plan import plan_render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene.model import Camera
from opal_diffraction.core.util.jit import kernel_mode
from opal_diffraction.core.render.frame import warm_up_scene
from opal_diffraction.core.scene.settings import RenderSettings

MOVED = Camera.look_at((1.2, -3.6, 2.4), (0.0, 0.0, 0.4), lens=35.0, width=24, height=16)
SETTINGS = RenderSettings(samples=2, round_samples=1, light_paths=20_000, seed=5, threads=2, tile_size=8)
BIG = 1 << 30  # a cap nothing here reaches


def glass_scene(width=24, height=16):
    """The compile stage's scene (a diffuse floor, a gold mirror sphere, a diffuse sphere, a
    dispersive flint prism; a point light, an area light, an environment map) seen at width x height."""
    return replace(warm_up_scene(), camera=Camera.look_at((0.0, -4.0, 2.0), (0.0, 0.0, 0.5), lens=35.0,
                                                          width=width, height=height))


def _kept(settings, scene=None):
    p = prepare(glass_scene() if scene is None else scene, settings)
    plan = plan_render(p)
    assert plan.camera_splat and plan.splat_bounce  # direct landings and the splat bounce's
    return p, run_light_pass(p, plan=plan, keep_vertices=BIG)


@pytest.mark.parametrize("kernels,threads", [("auto", 2), ("auto", 3), ("numpy", 2)])
def test_a_resplat_is_the_light_pass_run_for_the_new_camera_bit_for_bit(kernels, threads):
    """White and mono landings (the flint prism splits white paths by wavelength), the splat bounce's
    landings, RGB or spectral films: the re-splat's film is the fresh light pass's, and keeping the
    vertices changes nothing the light pass makes."""
    s = replace(SETTINGS, kernels=kernels, threads=threads, light_paths=30_000)
    with kernel_mode(kernels):
        p, kept = _kept(s)
        plain = run_light_pass(p, plan=plan_render(p))
        np.testing.assert_array_equal(kept.splat.image, plain.splat.image)
        np.testing.assert_array_equal(kept.caustics.flux, plain.caustics.flux)
        assert plain.vertices is None and kept.vertices.usable and kept.vertices.vertices > 1000
        for cam in (MOVED, replace(MOVED, width=20, height=20)):
            p2 = p.with_view(cam)
            fresh = run_light_pass(p2, plan=plan_render(p2))
            again = resplat(p2, kept)
            assert again.splat.key == fresh.splat.key and again.splat.key != kept.splat.key
            np.testing.assert_array_equal(again.splat.image, fresh.splat.image)
            assert again.caustics is kept.caustics and again.vertices is kept.vertices
            assert again.resplat["resplat_vertices"] == kept.vertices.vertices
            assert 0 < again.resplat["resplat_rays"] <= kept.vertices.vertices
        # the kept view again: its own splat
        np.testing.assert_array_equal(resplat(p, kept).splat.image, kept.splat.image)


def test_a_spectral_exr_view_gets_a_spectral_resplat(tmp_path):
    """A kept pass whose film was RGB (the spectral cap set to 0) re-splats into a view asking for
    a spectral EXR as a spectrum: the vertices hold the spectra, not the film's RGB."""
    from opal_diffraction.core.integrators.light import camera_splat

    s = replace(SETTINGS, light_paths=20_000)
    with pytest.MonkeyPatch.context() as m:
        m.setattr(camera_splat, "SPECTRAL_CAP", 0)
        p, kept = _kept(s)
    assert not kept.splat.spectral
    p2 = p.with_view(MOVED, spectral_exr=str(tmp_path / "s.exr"))
    fresh = run_light_pass(p2, plan=plan_render(p2))
    again = resplat(p2, kept)
    assert again.splat.spectral and fresh.splat.spectral
    np.testing.assert_array_equal(again.splat.image, fresh.splat.image)


def _blocks(img, k=4):
    h, w = img.shape[:2]
    return img[: h // k * k, : w // k * k].reshape(h // k, k, w // k, k, -1).sum(axis=(1, 3, 4))


def test_a_resplat_agrees_with_light_passes_of_other_seeds():
    """Z-test over 4 x 4 pixel blocks: the re-splat of seed 5's vertices (direct landings and the
    splat bounce's) into a moved camera against 16 fresh light passes of other seeds for that
    camera (each block's mean and spread over the 16: Student's t with 15 degrees of freedom,
    turned into normal scores); the splat made for the first camera fails the same test (the
    test sees a wrong view)."""
    s = replace(SETTINGS, light_paths=20_000)
    cam = Camera.look_at((1.5, -4.5, 3.2), (0, 0, 0.5), width=32, height=24)
    p, kept = _kept(s, glass_scene(32, 24))
    again = _blocks(resplat(p.with_view(cam), kept).splat.image)
    others = []
    for i in range(16):
        q = prepare(glass_scene(32, 24), replace(s, seed=100 + i)).with_view(cam)
        others.append(_blocks(run_light_pass(q, plan=plan_render(q)).splat.image))
    others = np.stack(others)
    k = len(others)
    mean, sd = others.mean(axis=0), others.std(axis=0, ddof=1)
    lit = sd > 0
    assert lit.sum() >= 12

    def p_value(x):
        t = (x[lit] - mean[lit]) / (sd[lit] * np.sqrt(1 + 1 / k))
        return chi2_normal_scores(stats.norm.ppf(stats.t.cdf(t, k - 1)))

    assert p_value(again) > 1e-3, p_value(again)
    assert p_value(_blocks(kept.splat.image)) < 1e-6  # the first camera's splat


def test_the_vertices_are_counted_and_capped():
    """The store's bytes are its arrays' (each shared basis once); a cap below them keeps none,
    estimates the whole pass's bytes from the part counted, and makes light_reuse run the pass
    again with the reason."""
    s = replace(SETTINGS, light_paths=30_000)
    p, kept = _kept(s)
    store = kept.vertices
    chunks = [v for lane in store.lanes for batch in lane for piece in batch for v in piece]
    bases = {id(v.basis): v.basis.nbytes for v in chunks if v.basis is not None}
    assert store.nbytes == sum(v.nbytes for v in chunks) + sum(bases.values())
    assert store.vertices == sum(len(v) for v in chunks)
    assert kept.stats["splat_vertex_bytes"] == store.nbytes
    small = run_light_pass(p, plan=plan_render(p), keep_vertices=store.nbytes // 4)
    assert small.vertices.over_cap and small.vertices.lanes is None and not small.vertices.usable
    assert 0.5 < small.vertices.nbytes / store.nbytes < 2.0  # the estimate of the whole pass
    np.testing.assert_array_equal(small.splat.image, kept.splat.image)  # the light pass itself is the same
    p2 = p.with_view(MOVED)
    light, why = light_reuse(p2, small)
    assert light is None and "cap" in why and why == resplat_note(small.vertices)
    assert light_reuse(p2, kept) == (kept, "")
    assert light_reuse(p2, replace(kept, vertices=None))[1] == "the kept light pass kept no camera-splat vertices"


def test_a_render_from_a_kept_light_pass_resplats_and_matches_a_fresh_render():
    """render(..., reuse=, light=) through another camera: no light pass runs, ``on_light`` gets
    the re-splatted pass, and the image is a fresh render's of that camera, bit for bit."""
    keep = {}
    render(glass_scene(), SETTINGS, keep_splat=BIG, on_prepared=lambda q: keep.update(prepared=q),
           on_light=lambda lp: keep.update(light=lp))
    moved = replace(glass_scene(), camera=MOVED)
    got = []
    rr = render(moved, SETTINGS, reuse=keep["prepared"], light=keep["light"], keep_splat=BIG,
                on_light=got.append)
    assert len(got) == 1 and got[0].resplatted and got[0].caustics is keep["light"].caustics
    assert rr.stats["resplat_vertices"] == keep["light"].vertices.vertices and rr.stats["resplat_s"] > 0
    np.testing.assert_array_equal(rr.rgb, render(moved, SETTINGS).rgb)
    # the re-splatted pass serves its own view as it is (no second re-splat)
    again = []
    rr2 = render(moved, SETTINGS, reuse=keep["prepared"], light=got[0], on_light=again.append)
    assert again == [] and "resplat_s" not in rr2.stats
    np.testing.assert_array_equal(rr2.rgb, rr.rgb)


def test_a_cancel_during_the_resplat_stops_the_render():
    """Esc while the kept vertices are splatted into the new view: a cancelled render (as during a
    light pass), and nothing handed on to keep."""
    p, kept = _kept(replace(SETTINGS, light_paths=20_000))
    assert resplat(p.with_view(MOVED), kept, should_cancel=lambda: True) is None
    asked = []  # set once the render says it is re-splatting

    def progress(fraction, message):
        if message.startswith("re-splatting"):
            asked.append(message)

    got = []
    rr = render(replace(glass_scene(), camera=MOVED), SETTINGS, reuse=p, light=kept, progress=progress,
                should_cancel=lambda: bool(asked), on_light=got.append)
    assert asked and rr.cancelled and got == []


def _moving(cam: Camera, dx: float) -> Camera:
    """``cam`` moving ``dx`` along x during the shutter (three motion steps about its matrix)."""
    m = np.repeat(np.asarray(cam.matrix, np.float64)[None], 3, axis=0)
    m[:, 0, 3] += np.array([-dx / 2, 0.0, dx / 2])
    return replace(cam, motion=m)


def test_motion_blur_a_moving_camera_reads_the_map_and_a_still_one_needs_vertices():
    """A camera moving during the shutter has no splat (the eye pass looks the caustics up,
    docs/physics.md section 6.13): a kept pass serves it as it is (no re-splat), and the image is a
    fresh render's. A pass kept from a moving camera has no splat and so no vertices: a still
    camera after it runs the light pass again, with the reason."""
    keep = {}
    render(glass_scene(), SETTINGS, keep_splat=BIG, on_prepared=lambda q: keep.update(prepared=q),
           on_light=lambda lp: keep.update(light=lp))
    blurred = replace(glass_scene(), camera=_moving(MOVED, 0.4))
    got = []
    rr = render(blurred, SETTINGS, reuse=keep["prepared"], light=keep["light"], keep_splat=BIG, on_light=got.append)
    assert got == [] and "resplat_s" not in rr.stats  # reused as it is: the map everywhere
    np.testing.assert_array_equal(rr.rgb, render(blurred, SETTINGS).rgb)
    # kept from the moving camera: no splat, no vertices
    keep2 = {}
    render(blurred, SETTINGS, keep_splat=BIG, on_prepared=lambda q: keep2.update(prepared=q),
           on_light=lambda lp: keep2.update(light=lp))
    assert keep2["light"].splat is None and keep2["light"].vertices is None
    still = keep2["prepared"].with_view(MOVED)
    light, why = light_reuse(still, keep2["light"])
    assert light is None and why == "the kept light pass kept no camera-splat vertices"
