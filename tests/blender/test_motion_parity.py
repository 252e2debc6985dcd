"""Motion blur against Cycles (the [camera-world] issue's "Must show", issue 29; docs/physics.md
section 6.13): a moving camera and a moving cube (tests/blender/camera_scenes.py MOTION_SCENES),
each built once and rendered by Cycles and by OPAL_DIFFRACTION in this bpy session, compared as
tests/blender/test_camera_parity.py compares its scenes: mean Rec.709 luminance within 5 %, the
4x4-box-filtered relative RMSE below 0.10, after checking that the noise floor (< 0.03) and the
mean ratio's standard error (< 0.01) leave the verdict to the renderer.

The same scene rendered by us without blur (Render > Motion Blur off: the frame's own time)
must miss Cycles' blurred image by more than the tolerance, so the comparison can see the blur.
The blurred render's report carries no motion-blur warning where the motion is supported.

Object motion is rendered in 16 time bins of the shutter (blender/export/motion.py), the cube
at each bin's centre time: a cube moving 1.6 m is at most 5 cm from its place.
"""

from __future__ import annotations

import os

import pytest

import camera_scenes as cs
from opal_diffraction._scripts import load_script

cp = load_script("tools/cycles_parity.py")

REF_SPP = 512
OUR_SPP = 64
BLOCK = 4
MEAN_TOLERANCE = 0.05
RMSE_TOLERANCE = 0.10
MAX_NOISE_FLOOR = 0.03
MAX_MEAN_SIGMA = 0.01


@pytest.mark.slow
@pytest.mark.parametrize("scene", list(cs.MOTION_SCENES))
def test_motion_blur_matches_cycles(scene, tmp_path, last_render):
    work = str(tmp_path)
    sc = cs.build(scene)
    ref = cp.render_pair("CYCLES", REF_SPP, cp.REF_SEEDS, work)
    ours = cp.render_pair(cp.ENGINE, OUR_SPP, cp.OUR_SEEDS, work)
    warnings = list(last_render.get("warnings", []))
    c = cp.compare(scene, ours, ref, block=BLOCK)
    cp.side_by_side_png(os.path.join(work, f"{scene}.png"), ref.image, ours.image)
    sc.render.use_motion_blur = False
    still = cp.render_pair(cp.ENGINE, OUR_SPP, cp.OUR_SEEDS, work)
    c_still = cp.compare(scene + "_still", still, ref, block=BLOCK)
    cp.side_by_side_png(os.path.join(work, f"{scene}_still.png"), ref.image, still.image)
    print(cp.TABLE_HEAD)
    print(c.row(), f"bias {c.bias:.3f}")
    print(c_still.row(), "(ours without blur against Cycles' blur)")
    print("warnings:", warnings)
    assert cp.luminance(ref.image).mean() > 0.01, f"{scene}: Cycles renders it black: bad test scene"
    assert c.noise_floor < MAX_NOISE_FLOOR, f"{scene}: noise floor {c.noise_floor:.3f}: raise the samples"
    assert c.mean_ratio_sigma < MAX_MEAN_SIGMA, f"{scene}: mean ratio sigma {c.mean_ratio_sigma:.4f}"
    assert c_still.rel_rmse > RMSE_TOLERANCE, f"{scene}: the blur is too small for the test to see it: {c_still.row()}"
    assert not any("motion" in w for w in warnings), warnings
    assert abs(c.mean_ratio - 1) < MEAN_TOLERANCE, c.row()
    assert c.rel_rmse < RMSE_TOLERANCE, c.row()

