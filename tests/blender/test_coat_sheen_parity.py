"""Principled's coat and sheen against Cycles (issue 28; docs/physics.md section 14.10): a red
Principled sphere under a clear coat (Coat Weight 1, Coat Roughness 0.05 and 0.3) and a blue one
under a sheen (Sheen Weight 1, Sheen Roughness 0.5) on a grey floor, lit by an area light and a
grey world, rendered by Cycles and by OPAL_DIFFRACTION from the same scene in one bpy session.

The verdict is test_cycles_parity.py's (metrics: tools/cycles_parity.py): mean Rec.709 luminance
within 5 % and the box-filtered relative RMSE below 0.10, after asserting that the noise floor
(from each engine's two half renders) is below 0.03 and the mean ratio's standard error below
0.01, so that the verdict is about the renderer and not the dice. Before coat and sheen were
read, the exporter warned and dropped both layers (the coat's highlight and the sheen's rim
missing).
"""

from __future__ import annotations

import math
import os

import bpy
import numpy as np
import pytest

import blender_scenes as bs
from opal_diffraction._scripts import load_script

cp = load_script("tools/cycles_parity.py")
ps = load_script(os.path.join("tests", "blender", "parity_scenes.py"))

REF_SPP, OUR_SPP = 512, 64
MEAN_TOLERANCE, RMSE_TOLERANCE = 0.05, 0.10
MAX_NOISE_FLOOR, MAX_MEAN_SIGMA = 0.03, 0.01
OUT = os.environ.get("OPAL_COAT_PNG")  # a folder: side-by-side PNGs of each scene

#: case -> Principled inputs
CASES = {
    "COAT_005": {"Base Color": (0.8, 0.06, 0.04, 1.0), "Roughness": 0.5, "Coat Weight": 1.0, "Coat Roughness": 0.05},
    "COAT_03": {"Base Color": (0.8, 0.06, 0.04, 1.0), "Roughness": 0.5, "Coat Weight": 1.0, "Coat Roughness": 0.3},
    "SHEEN": {"Base Color": (0.05, 0.08, 0.35, 1.0), "Roughness": 0.5, "Sheen Weight": 1.0, "Sheen Roughness": 0.5},
    # a tinted coat (its absorption per wavelength here, per RGB channel in Cycles) over a grey base,
    # and a coloured sheen of low roughness over a dark one
    "COAT_TINT": {"Base Color": (0.6, 0.6, 0.6, 1.0), "Roughness": 0.4, "Coat Weight": 1.0, "Coat Roughness": 0.1,
                  "Coat IOR": 1.6, "Coat Tint": (0.9, 0.5, 0.2, 1.0)},
    "SHEEN_TINT": {"Base Color": (0.1, 0.1, 0.1, 1.0), "Roughness": 0.5, "Sheen Weight": 0.8, "Sheen Roughness": 0.2,
                   "Sheen Tint": (1.0, 0.5, 0.7, 1.0)},
}


def _principled(name: str, inputs: dict):
    mat = bpy.data.materials.new(name)
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    node = nt.nodes.new("ShaderNodeBsdfPrincipled")
    for k, v in inputs.items():
        node.inputs[k].default_value = v
    nt.links.new(node.outputs[0], out.inputs["Surface"])
    return mat


def build(case: str):
    sc = bs.empty_scene(64, 64)
    ps.match_engines(sc)
    ps._world_colour(sc, (0.2, 0.2, 0.2))
    bs.plane("floor", half=4.0, mat=bs.material("floor", "DIFFUSE", (0.5, 0.5, 0.5)))
    ps._smooth_sphere("sphere", 0.8, (0.0, 0.0, 0.8), _principled("layered", CASES[case]))
    bs.light("AREA", (-1.0, -1.5, 3.0), 400.0, shape="SQUARE", size=2.0,
             rotation=(math.radians(20), math.radians(-15), 0))
    ps.look_at((0.0, -4.0, 1.8), (0.0, 0.0, 0.7), lens=80.0)  # the sphere fills most of the frame
    return sc


@pytest.mark.slow
@pytest.mark.parametrize("case", list(CASES))
def test_coat_and_sheen_match_cycles(case, tmp_path):
    build(case)
    ref = cp.render_pair("CYCLES", REF_SPP, cp.REF_SEEDS, str(tmp_path))
    ours = cp.render_pair(cp.ENGINE, OUR_SPP, cp.OUR_SEEDS, str(tmp_path))
    c = cp.compare(f"layered {case}", ours, ref)
    print(cp.TABLE_HEAD)
    print(c.row(), f"bias {c.bias:.3f}")
    if OUT:
        os.makedirs(OUT, exist_ok=True)
        cp.side_by_side_png(os.path.join(OUT, f"layered_{case.lower()}.png"), ref.image, ours.image)
    assert cp.luminance(ref.image).mean() > 0.01, "Cycles renders it black: bad test scene"
    assert c.noise_floor < MAX_NOISE_FLOOR, f"noise floor {c.noise_floor:.3f}: raise the samples"
    assert c.mean_ratio_sigma < MAX_MEAN_SIGMA, f"mean ratio noise {c.mean_ratio_sigma:.3f}"
    assert abs(c.mean_ratio - 1) < MEAN_TOLERANCE and c.rel_rmse < RMSE_TOLERANCE, (
        f"mean ratio {c.mean_ratio:.3f} (+- {c.mean_ratio_sigma:.3f}), filtered rel. RMSE {c.rel_rmse:.3f} "
        f"(noise floor {c.noise_floor:.3f}, bias {c.bias:.3f})")


def test_principled_exports_coat_and_sheen():
    """The exported rows carry the coat's and the sheen's inputs, with no 'not rendered' warning."""
    from opal_diffraction.blender.export import export_scene

    for case, want in (("COAT_03", dict(coat_weight=1.0, coat_roughness=0.3, coat_ior=1.5, sheen_weight=0.0)),
                       ("SHEEN", dict(coat_weight=0.0, sheen_weight=1.0, sheen_roughness=0.5))):
        build(case)
        ex = export_scene(bpy.context.evaluated_depsgraph_get())
        assert not [w for w in ex.warnings if "coat" in w.lower() or "sheen" in w.lower()], ex.warnings
        m = ex.scene.materials
        row = [i for i, n in enumerate(m.name) if n == "layered"][0]
        for k, v in want.items():
            assert float(getattr(m, k)[row]) == pytest.approx(v, abs=1e-6), k
        np.testing.assert_allclose(m.coat_tint[row], (1, 1, 1))
        np.testing.assert_allclose(m.sheen_tint[row], (1, 1, 1))


def test_a_coat_on_one_side_of_a_mix_is_warned():
    """Mix(coated Principled, Glossy): the coat is rendered over the whole mix (weight Fac-mixed), warned."""
    from opal_diffraction.blender.export import export_scene

    build("COAT_03")
    mat = bpy.data.materials["layered"]
    nt = mat.node_tree
    principled = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    out = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    glossy = nt.nodes.new("ShaderNodeBsdfGlossy")
    mix = nt.nodes.new("ShaderNodeMixShader")
    mix.inputs["Fac"].default_value = 0.25
    nt.links.new(principled.outputs[0], mix.inputs[1])
    nt.links.new(glossy.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])
    ex = export_scene(bpy.context.evaluated_depsgraph_get())
    assert [w for w in ex.warnings if "coat is rendered over the whole mix" in w], ex.warnings
    m = ex.scene.materials
    row = [i for i, n in enumerate(m.name) if n == "layered"][0]
    assert float(m.coat_weight[row]) == pytest.approx(0.75)
    assert float(m.coat_roughness[row]) == pytest.approx(0.3)
