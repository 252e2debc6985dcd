"""Cameras and film against Cycles (the [camera-world] issue's "Must show", issue 29): depth of
field (three spheres; and a lamp's bokeh, the aperture's own shape: a round, unturned or
unsqueezed aperture, or six blades for five, misses Cycles' image by 0.15-0.73 in the filtered
RMSE), clip start / end, Film > Transparent (and a Holdout in it) and panoramas (tests/blender/camera_scenes.py), each
built once and rendered by Cycles and by OPAL_DIFFRACTION in this bpy session. The images must
agree: mean Rec.709 luminance within 5 % and the 4x4-box-filtered relative RMSE below 0.10
(tools/cycles_parity.py's metrics at a 4-pixel block); with Film > Transparent the alpha
channels within 0.02 (the mean absolute difference over pixels, and every 4x4 block's mean).

Monte Carlo noise is accounted for as in tests/blender/test_cycles_parity.py: each image is the
mean of two renders with independent seeds at half the samples, their half difference gives the
noise floor, and the test first asserts the floor (< 0.03) and the mean ratio's standard error
(< 0.01) are small enough for the verdict to be about the renderer. The alpha's noise is
checked the same way: the 4x4 blocks' alpha noise (from the halves) must be below 0.005, a
quarter of the tolerance.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

import camera_scenes as cs
from opal_diffraction._scripts import load_script
from opal_diffraction.core.render.output import read_exr

cp = load_script("tools/cycles_parity.py")

REF_SPP = 512
OUR_SPP = 64
#: (reference, ours) samples where the defaults leave too much noise: the out-of-focus lamp of
#: ``bokeh`` is found by camera rays only (a lens sample must hit it), ~10 % of them per pixel
SCENE_SPP = {"bokeh": (4096, 1024)}
BLOCK = 4
MEAN_TOLERANCE = 0.05
RMSE_TOLERANCE = 0.10
ALPHA_TOLERANCE = 0.02
MAX_NOISE_FLOOR = 0.03
MAX_MEAN_SIGMA = 0.01


def _alpha(work, engine):
    """The alpha of the mean of the two halves cp.render_pair wrote, and its half difference."""
    a = read_exr(os.path.join(work, f"{engine}_a.exr"))["A"].astype(np.float64)
    b = read_exr(os.path.join(work, f"{engine}_b.exr"))["A"].astype(np.float64)
    return (a + b) / 2, (a - b) / 2


@pytest.mark.slow
@pytest.mark.parametrize("scene", list(cs.SCENES))
def test_camera_scene_matches_cycles(scene, tmp_path):
    work = str(tmp_path)
    sc = cs.build(scene)
    ref_spp, our_spp = SCENE_SPP.get(scene, (REF_SPP, OUR_SPP))
    ref = cp.render_pair("CYCLES", ref_spp, cp.REF_SEEDS, work)
    ref_alpha, ref_alpha_noise = _alpha(work, "CYCLES")
    ours = cp.render_pair(cp.ENGINE, our_spp, cp.OUR_SEEDS, work)
    our_alpha, our_alpha_noise = _alpha(work, cp.ENGINE)
    c = cp.compare(scene, ours, ref, block=BLOCK)
    cp.side_by_side_png(os.path.join(work, f"{scene}.png"), ref.image, ours.image)
    print(cp.TABLE_HEAD)
    print(c.row(), f"bias {c.bias:.3f}")
    assert cp.luminance(ref.image).mean() > 0.01, f"{scene}: Cycles renders it black: bad test scene"
    assert c.noise_floor < MAX_NOISE_FLOOR, f"{scene}: noise floor {c.noise_floor:.3f}: raise the samples"
    assert c.mean_ratio_sigma < MAX_MEAN_SIGMA, f"{scene}: mean ratio sigma {c.mean_ratio_sigma:.4f}"
    assert abs(c.mean_ratio - 1) < MEAN_TOLERANCE, c.row()
    assert c.rel_rmse < RMSE_TOLERANCE, c.row()
    d_alpha = cp.box_filter((our_alpha - ref_alpha)[..., None], BLOCK)
    noise = np.hypot(cp.box_filter(our_alpha_noise[..., None], BLOCK), cp.box_filter(ref_alpha_noise[..., None], BLOCK))
    print(f"alpha: mean |d| {np.abs(our_alpha - ref_alpha).mean():.4f}, 4x4 blocks max |d| {np.abs(d_alpha).max():.4f}, "
          f"block noise RMS {np.sqrt(np.mean(noise ** 2)):.4f}, mean alpha ref {ref_alpha.mean():.3f} ours "
          f"{our_alpha.mean():.3f}")
    if sc.render.film_transparent:
        assert 0.1 < ref_alpha.mean() < 0.9, "the transparent scene must show both objects and world"
        assert np.sqrt(np.mean(noise ** 2)) < ALPHA_TOLERANCE / 4
        assert np.abs(our_alpha - ref_alpha).mean() < ALPHA_TOLERANCE
        assert np.abs(d_alpha).max() < ALPHA_TOLERANCE
        assert (our_alpha >= 0).all() and (our_alpha <= 1).all()
    else:  # an opaque film: alpha 1 in both, whatever the camera sees (clipped away: the world)
        np.testing.assert_array_equal(our_alpha, 1.0)
        np.testing.assert_array_equal(ref_alpha, 1.0)
