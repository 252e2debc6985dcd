"""Principled Thin Film through the exporter, and beside Cycles' thin film in the same bpy session
(docs/physics.md section 2.8).

- The Principled BSDF's Thin Film Thickness and Thin Film IOR reach the material columns; a
  linked thickness is warned about (read as the socket's value), an IOR below 1 is clamped with
  a warning; no film (thickness 0) leaves the columns at their defaults.
- Cycles in the same session: a large smooth plane seen at 45 degrees by an orthographic camera
  under a uniform white world reflects the world once, so each image is the film's reflectance
  at 45 degrees in RGB. Cycles evaluates the film with Belcour & Barla's spectral integration of
  RGB sensitivities, we evaluate it exactly per wavelength: the per-channel means agree within
  the project's 5 % (measured within 3 %) plus 4.5 standard errors of both renders' noise
  (the glass's reflect / refract choice), for a filmed metal, glass over a black floor and a
  black dielectric (Principled's specular layer), two thicknesses each.
"""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

import blender_scenes as bs
from opal_diffraction.blender.export import export_scene


def _white_world(strength: float = 1.0):
    w = bpy.data.worlds.new("white")
    if bpy.app.version < (5, 0, 0):
        w.use_nodes = True
    nt = w.node_tree
    bg = nt.nodes.get("Background") or nt.nodes.new("ShaderNodeBackground")
    bg.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    bg.inputs["Strength"].default_value = strength
    out = nt.nodes.get("World Output") or nt.nodes.new("ShaderNodeOutputWorld")
    nt.links.new(bg.outputs[0], out.inputs["Surface"])
    bpy.context.scene.world = w


def _filmed_plane(kind: str, thickness: float, film_ior: float = 1.33, pixels: int = 8):
    bs.empty_scene(pixels, pixels)
    _white_world()
    inputs = {"Roughness": 0.0, "Thin Film Thickness": thickness, "Thin Film IOR": film_ior}
    if kind == "metal":
        inputs["Metallic"] = 1.0
        color = (0.9, 0.75, 0.5)
    elif kind == "glass":
        inputs.update({"Transmission Weight": 1.0, "IOR": 1.5})
        color = (1.0, 1.0, 1.0)
    else:  # a black base under Principled's specular layer
        inputs["IOR"] = 1.5
        color = (0.0, 0.0, 0.0)
    mat = bs.material("filmed", "PRINCIPLED", color, **inputs)
    bs.plane("filmed", half=20.0, mat=mat)
    if kind == "glass":  # what the glass transmits dies here
        bs.plane("floor", half=20.0, z=-1.0, mat=bs.material("black", "DIFFUSE", (0.0, 0.0, 0.0)))
    bs.camera(location=(0, -5, 5), rotation=(math.radians(45), 0, 0), ortho_scale=1.0)
    return mat


def test_principled_thin_film_exports_its_columns():
    mat = _filmed_plane("glass", 420.0, 1.45)
    m = export_scene(bpy.context.evaluated_depsgraph_get()).scene.materials
    i = list(m.name).index("filmed")
    assert m.thin_film_thickness[i] == pytest.approx(420.0) and m.thin_film_ior[i] == pytest.approx(1.45)
    j = list(m.name).index("black")
    assert m.thin_film_thickness[j] == 0.0  # a Diffuse BSDF has no film
    # a film IOR below 1: clamped with a warning; thickness 0: no film
    node = mat.node_tree.nodes["Principled BSDF"]
    node.inputs["Thin Film IOR"].default_value = 0.8
    ex = export_scene(bpy.context.evaluated_depsgraph_get())
    assert ex.scene.materials.thin_film_ior[i] == pytest.approx(1.0)
    assert any("thin film IOR 0.8" in w for w in ex.warnings)
    node.inputs["Thin Film Thickness"].default_value = 0.0
    assert export_scene(bpy.context.evaluated_depsgraph_get()).scene.materials.thin_film_thickness[i] == 0.0


def test_a_linked_thickness_is_warned_about():
    mat = _filmed_plane("metal", 300.0)
    nt = mat.node_tree
    noise = nt.nodes.new("ShaderNodeTexNoise")
    nt.links.new(noise.outputs[0], nt.nodes["Principled BSDF"].inputs["Thin Film Thickness"])
    ex = export_scene(bpy.context.evaluated_depsgraph_get())
    i = list(ex.scene.materials.name).index("filmed")
    assert ex.scene.materials.thin_film_thickness[i] == pytest.approx(300.0)  # the socket's own value
    assert any("Thin Film Thickness" in w and "not supported" in w for w in ex.warnings)


def _mean_and_error(img):
    px = img.reshape(-1, 3)
    return px.mean(axis=0), px.std(axis=0, ddof=1) / math.sqrt(len(px))


@pytest.mark.parametrize("kind", ["metal", "glass", "plastic"])
def test_thin_film_beside_cycles(kind, tmp_path):
    for thickness in (250.0, 500.0):
        _filmed_plane(kind, thickness)
        ours = bs.render_to_array(str(tmp_path / f"{kind}_ours.exr"), "OPAL_DIFFRACTION", 16)
        cycles = bs.render_to_array(str(tmp_path / f"{kind}_cycles.exr"), "CYCLES", 256)
        mo, eo = _mean_and_error(ours)
        mc, ec = _mean_and_error(cycles)
        print(f"{kind} {thickness:g} nm: ours {np.round(mo, 4)} Cycles {np.round(mc, 4)} ratio {np.round(mo / mc, 3)}")
        assert np.all(np.abs(mo - mc) <= 0.05 * mc + 4.5 * np.hypot(eo, ec)), (kind, thickness, mo, mc)
        # the film colours the image (a plain Fresnel would give equal channels for white / black bases)
        if kind != "metal":
            assert np.ptp(mc) > 0.1 * mc.max()


@pytest.mark.slow  # a subprocess that imports bpy and renders with both engines
def test_thin_film_example_runs_headless(tmp_path):
    import os
    import subprocess
    import sys

    root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
    out = tmp_path / "thin_film.png"
    res = subprocess.run([sys.executable, os.path.join(root, "examples", "thin_film.py"), "--spp", "2", "--cycles-spp", "4",
                          "--resolution", "48", "27", "--out", str(out)], capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stdout + res.stderr
    assert out.exists() and "Traceback" not in res.stderr
    assert res.stdout.count("  Cycles [") == 3  # one line per sphere, both renders' colours
