"""Shader mixes of unlike BSDFs against Cycles (issue 28; docs/physics.md section 14.8): spheres of
a Mix Shader of a Diffuse and a Glossy BSDF - Fac 0.5, Fac from a Fresnel node, Fac from a Layer
Weight node's Facing output - on a grey floor under an area light in a dim world, rendered by
Cycles and by OPAL_DIFFRACTION from the same scene in one bpy session.

The verdict is test_cycles_parity.py's (metrics: tools/cycles_parity.py): mean Rec.709 luminance
within 5 % and the 8x8-box-filtered relative RMSE below 0.10, after asserting that the noise
floor (from each engine's two half renders) is below 0.03 and the mean ratio's standard error
below 0.01, so the verdict is about the renderer and not the dice. The same scene with the
Diffuse BSDF alone at Roughness 1 checks Oren-Nayar (docs/physics.md section 14.9). Before mixtures were read,
the Fac 0.5 sphere rendered as pure diffuse (all gloss lost) and a Fresnel Fac as 0.5.
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
OUT = os.environ.get("OPAL_MIXTURE_PNG")  # a folder: side-by-side PNGs of each scene


def _mix_material(name: str, fac: str):
    """Mix Shader(Diffuse (0.8, 0.25, 0.1), Glossy (0.9, 0.9, 0.9) roughness 0.25, Multiscatter
    GGX), its Fac 0.5 ('CONST'), a Fresnel node of IOR 1.5 ('FRESNEL') or a Layer Weight node's
    Facing output of Blend 0.3 ('FACING') or its Fresnel output of Blend 0.5 ('LAYER_FRESNEL'), or
    a Checker texture's Fac (scale 4, on Generated coordinates: 'CHECKER'); 'OREN_NAYAR': the
    Diffuse BSDF alone with Roughness 1."""
    mat = bpy.data.materials.new(name)
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (0.8, 0.25, 0.1, 1.0)
    if fac == "OREN_NAYAR":  # no mix: the Diffuse BSDF alone, Roughness 1 (docs/physics.md section 14.9)
        diffuse.inputs["Roughness"].default_value = 1.0
        nt.links.new(diffuse.outputs[0], out.inputs["Surface"])
        return mat
    glossy = nt.nodes.new("ShaderNodeBsdfGlossy")
    glossy.distribution = "MULTI_GGX"
    glossy.inputs["Color"].default_value = (0.9, 0.9, 0.9, 1.0)
    glossy.inputs["Roughness"].default_value = 0.25
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(diffuse.outputs[0], mix.inputs[1])
    nt.links.new(glossy.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])
    if fac == "CONST":
        mix.inputs["Fac"].default_value = 0.5
    elif fac == "CHECKER":  # a texture per hit: the shader program's 'mix' output
        node = nt.nodes.new("ShaderNodeTexChecker")
        node.inputs["Scale"].default_value = 4.0
        nt.links.new(node.outputs["Fac"], mix.inputs["Fac"])
    elif fac == "FRESNEL":
        node = nt.nodes.new("ShaderNodeFresnel")
        node.inputs["IOR"].default_value = 1.5
        nt.links.new(node.outputs["Fac"], mix.inputs["Fac"])
    else:
        node = nt.nodes.new("ShaderNodeLayerWeight")
        node.inputs["Blend"].default_value = 0.3 if fac == "FACING" else 0.5
        nt.links.new(node.outputs["Facing" if fac == "FACING" else "Fresnel"], mix.inputs["Fac"])
    return mat


def build(fac: str):
    sc = bs.empty_scene(64, 64)
    ps.match_engines(sc)
    ps._world_colour(sc, (0.05, 0.06, 0.08))
    bs.plane("floor", half=4.0, mat=bs.material("floor", "DIFFUSE", (0.5, 0.5, 0.5)))
    ps._smooth_sphere("sphere", 0.8, (0.0, 0.0, 0.8), _mix_material("mix", fac))
    bs.light("AREA", (-1.0, -1.5, 3.0), 400.0, shape="SQUARE", size=2.0,
             rotation=(math.radians(20), math.radians(-15), 0))
    ps.look_at((0.0, -4.0, 1.8), (0.0, 0.0, 0.7), lens=80.0)  # the sphere fills most of the frame
    return sc


@pytest.mark.slow
@pytest.mark.parametrize("fac", ["CONST", "FRESNEL", "FACING", "LAYER_FRESNEL", "CHECKER", "OREN_NAYAR"])
def test_mix_shader_matches_cycles(fac, tmp_path):
    build(fac)
    ref = cp.render_pair("CYCLES", REF_SPP, cp.REF_SEEDS, str(tmp_path))
    ours = cp.render_pair(cp.ENGINE, OUR_SPP, cp.OUR_SEEDS, str(tmp_path))
    c = cp.compare(f"mix {fac}", ours, ref)
    print(cp.TABLE_HEAD)
    print(c.row(), f"bias {c.bias:.3f}")
    if OUT:
        os.makedirs(OUT, exist_ok=True)
        cp.side_by_side_png(os.path.join(OUT, f"mix_{fac.lower()}.png"), ref.image, ours.image)
    assert cp.luminance(ref.image).mean() > 0.01, "Cycles renders it black: bad test scene"
    assert c.noise_floor < MAX_NOISE_FLOOR, f"noise floor {c.noise_floor:.3f}: raise the samples"
    assert c.mean_ratio_sigma < MAX_MEAN_SIGMA, f"mean ratio noise {c.mean_ratio_sigma:.3f}"
    assert abs(c.mean_ratio - 1) < MEAN_TOLERANCE and c.rel_rmse < RMSE_TOLERANCE, (
        f"mean ratio {c.mean_ratio:.3f} (+- {c.mean_ratio_sigma:.3f}), filtered rel. RMSE {c.rel_rmse:.3f} "
        f"(noise floor {c.noise_floor:.3f}, bias {c.bias:.3f})")


def test_mix_exports_a_lobe_mixture():
    """The exported rows: the Diffuse colour as the base, the Glossy's as the metal's, the weights
    (Fac 0.5: metallic 0.5; Fresnel: per hit, its hemispherical mean in the table), no
    'rendered as' warning."""
    from opal_diffraction.blender.export import export_scene

    for fac, code in (("CONST", 0), ("FRESNEL", 1), ("FACING", 3), ("CHECKER", 4)):
        build(fac)
        ex = export_scene(bpy.context.evaluated_depsgraph_get())
        m = ex.scene.materials
        assert not [w for w in ex.warnings if "mix" in w.lower()], ex.warnings
        row = [i for i, n in enumerate(m.name) if n == "mix"][0]
        np.testing.assert_allclose(m.color[row], (0.8, 0.25, 0.1), rtol=1e-5)
        np.testing.assert_allclose(m.metal_color[row], (0.9, 0.9, 0.9), rtol=1e-5)
        assert int(m.layer_fac[row]) == code
        assert m.conductor_fresnel[row] == 0  # the Glossy BSDF's constant Fresnel
        if code == 0:
            assert m.metallic[row] == pytest.approx(0.5)
        elif code == 4:  # the checker's program, its 'mix' output read per hit; the table: its average
            prog = ex.scene.shader_programs[int(m.shader_program[row])]
            assert "mix" in prog.outputs
            assert 0.3 < m.metallic[row] < 0.7
        else:
            assert (int(m.layer_fac_from[row]), int(m.layer_fac_to[row])) == (0, 1)
