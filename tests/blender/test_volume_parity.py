"""Volumes against Cycles (issue 31's "Must show"): homogeneous fog lit by a spot and an absorbing
medium inside glass (tests/blender/volume_scenes.py), rendered by Cycles and by OPAL_DIFFRACTION
in this bpy session: mean Rec.709 luminance within 5 % and the 8x8-box-filtered relative RMSE
below 0.10 (issue 31 asks 4x4 below 0.10 too: checked as well), with the noise accounted for as
tests/blender/test_cycles_parity.py does (tools/cycles_parity.py: each image the mean of two
half-sample renders, their half difference the noise; the noise floor must be below 0.03 and the
mean ratio's standard error below 0.01 for the verdict to be about the renderer).

Measured (2-core machine, 64 x 64, Cycles at 512 spp): fog_spot at 256 spp mean ratio
0.994 +- 0.004, filtered RMSE 0.024 (noise floor 0.029; 4x4: 0.052, floor 0.054); at 384 spp
(the margin on the floor) 0.997 +- 0.003, RMSE 0.022 (floor 0.026; 4x4: 0.053, floor 0.052);
glass_absorption at 32 spp mean ratio 0.997, filtered RMSE
0.010 (noise floor 0.003; 4x4: 0.011).
"""

from __future__ import annotations

import tempfile

import numpy as np
import pytest

import volume_scenes as vs
from opal_diffraction._scripts import load_script

cp = load_script("tools/cycles_parity.py")

REF_SPP = 512
OUR_SPP = {"fog_spot": 384, "glass_absorption": 32}


@pytest.mark.slow
@pytest.mark.parametrize("scene", list(vs.SCENES))
def test_volume_scene_matches_cycles(scene):
    with tempfile.TemporaryDirectory(prefix="volume_parity_") as work:
        vs.build(scene, work)
        ref = cp.render_pair("CYCLES", REF_SPP, cp.REF_SEEDS, work)
        ours = cp.render_pair(cp.ENGINE, OUR_SPP[scene], cp.OUR_SEEDS, work)
    assert np.isfinite(ours.image).all() and (ours.image >= 0).all(), "negative or non-finite radiance"
    c = cp.compare(scene, ours, ref)
    c4 = cp.compare(scene, ours, ref, block=4)
    print(cp.TABLE_HEAD)
    print(c.row(), f"bias {c.bias:.3f}; 4x4: rmse {c4.rel_rmse:.3f} floor {c4.noise_floor:.3f}")
    assert cp.luminance(ref.image).mean() > 0.01, f"{scene}: Cycles renders it black: bad test scene"
    assert c.noise_floor < 0.03, f"{scene}: noise floor {c.noise_floor:.3f}: raise the samples"
    assert c.mean_ratio_sigma < 0.01, f"{scene}: mean ratio sigma {c.mean_ratio_sigma:.3f}: raise the samples"
    assert abs(c.mean_ratio - 1) < 0.05, c.row()
    assert c.rel_rmse < 0.10, c.row()
    assert c4.rel_rmse < 0.10, (c4.rel_rmse, c4.noise_floor)  # the 4x4 filter
