"""World export: an Environment Texture (equirectangular) with a Mapping rotation against Cycles'
own background, pixel by pixel, and the warnings for what is approximated (docs/physics.md
section 7.9)."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

import blender_scenes as bs
from opal_diffraction.blender.export import export_scene
from opal_diffraction.blender.export.world import MISSING_IMAGE_RGB
from opal_diffraction.core.sampling.camera import generate_rays
from opal_diffraction.core.lights.environment import EnvironmentMap
from opal_diffraction.core.scene.validation import validate

W, H = 64, 32


def pattern_image(name="pattern"):
    """A 64 x 32 float image, row 0 at the bottom: red ramps with u, green with v, a blue 8 x 4
    checker, and a bright texel block: every direction is distinguishable."""
    jj, ii = np.meshgrid(np.arange(H), np.arange(W), indexing="ij")
    px = np.ones((H, W, 4), np.float32)
    px[..., 0] = 0.05 + ii / W
    px[..., 1] = 0.05 + jj / H
    px[..., 2] = 0.1 + 0.8 * (((ii // 8) + (jj // 8)) % 2)
    px[20:23, 40:44, :3] = (3.0, 2.0, 0.5)
    img = bpy.data.images.new(name, W, H, float_buffer=True)
    img.pixels.foreach_set(px.ravel())
    img.update()
    return img, px[..., :3]


def env_world(strength=1.7, vector_type="POINT", rotation=(0.3, -0.5, 1.2), scale=(1, 1, 1), coords="Generated",
              image=None):
    """A world: Texture Coordinate -> Mapping -> Environment Texture -> Background."""
    w = bpy.data.worlds.new("Env World")
    bpy.context.scene.world = w
    nt = w.node_tree
    bg = nt.nodes["Background"]
    bg.inputs["Strength"].default_value = strength
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = image
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    if vector_type is not None:
        tc = nt.nodes.new("ShaderNodeTexCoord")
        mp = nt.nodes.new("ShaderNodeMapping")
        mp.vector_type = vector_type
        mp.inputs["Rotation"].default_value = rotation
        mp.inputs["Scale"].default_value = scale
        nt.links.new(tc.outputs[coords], mp.inputs["Vector"])
        nt.links.new(mp.outputs["Vector"], env.inputs["Vector"])
    return w, env


VIEWS = [(math.radians(90), 0, 0), (math.radians(90), 0, math.radians(125)), (math.radians(90), 0, math.radians(245)),
         (math.radians(15), 0, math.radians(40)), (math.radians(165), 0, math.radians(-60))]


SUB = 12  # sub-pixel grid per axis for our side of the comparison


def _cycles_and_ours(tmp_path, views, width=48, height=32, samples=128):
    """Cycles' render of the world with its BOX pixel filter (measured: Cycles 5.0 averages a
    box filter over the whole pixel whatever its width) and our EnvironmentMap averaged over
    the same pixel box (SUB x SUB rays through each pixel from core/sampling/camera.py), per view."""
    sc = bpy.context.scene
    sc.render.resolution_x, sc.render.resolution_y = width, height
    sc.cycles.pixel_filter_type = "BOX"
    cam = bs.camera(location=(0, 0, 0), lens=14.0)
    out = []
    for k, rot in enumerate(views):  # loop over views (a few renders)
        cam.rotation_euler = rot
        bpy.context.view_layer.update()
        cycles = bs.render_to_array(str(tmp_path / f"cycles_{k}.exr"), "CYCLES", samples=samples)
        ex = export_scene(bpy.context.evaluated_depsgraph_get())
        s = ex.scene
        env = EnvironmentMap(s.world_image * s.world_color, s.world_rotation)
        offsets = (np.arange(SUB) + 0.5) / SUB
        ys, xs = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
        sy, sx = np.meshgrid(offsets, offsets, indexing="ij")
        x = (xs[..., None] + sx.ravel()).ravel()
        y = (ys[..., None] + sy.ravel()).ravel()
        _, d = generate_rays(s.camera, x, y)
        sub = env.radiance_rgb(d).astype(np.float64).reshape(height, width, SUB * SUB, 3)
        # the spread within each pixel bounds the noise of Cycles' `samples` positions in it
        noise = sub.std(axis=2) / math.sqrt(samples)
        out.append((cycles, sub.mean(axis=2), noise, ex))
    return out


def _compare(pairs, what):
    """Per pixel and channel: |ours - Cycles| within 5 standard errors of Cycles' pixel sampling
    (at most the within-pixel spread / sqrt(samples): Cycles' stratified samples do better) plus
    0.5 % (float32 lookups); a texel off, a half-texel shift, a flipped row order or another
    Euler order is tens of per cent on this pattern."""
    worst_z, worst_rel = 0.0, 0.0
    for cycles, ours, noise, _ in pairs:
        diff = np.abs(ours - cycles)
        z = diff / (noise + 0.005 * np.maximum(cycles, 0.05))
        rel = diff / np.maximum(cycles, 0.05)
        worst_z, worst_rel = max(worst_z, float(z.max())), max(worst_rel, float(np.percentile(rel, 99)))
        assert z.max() < 5, f"{what}: {diff.ravel()[np.argmax(z)]:.4f} off, {z.max():.1f} standard errors"
        assert np.median(rel) < 0.002
    print(f"{what}: largest z {worst_z:.2f}, 99th percentile relative error {worst_rel:.4f}")


def test_environment_texture_with_mapping_rotation_matches_cycles(tmp_path):
    """Five views (horizon, up to the zenith, down to the nadir) of a patterned map under a
    POINT Mapping rotation: Cycles' background per pixel = our lookup along our camera rays
    (core/sampling/camera.py) of the exported image, strength and rotation - the u/v convention, the row
    order, the Euler order and the Mapping all at once."""
    bs.empty_scene(48, 32, "CYCLES")
    img, px = pattern_image()
    env_world(image=img)
    pairs = _cycles_and_ours(tmp_path, VIEWS)
    s = pairs[0][3].scene
    np.testing.assert_allclose(s.world_image, px, rtol=1e-6)
    np.testing.assert_allclose(s.world_color, 1.7, rtol=1e-6)
    assert not any("world" in w for w in pairs[0][3].warnings), pairs[0][3].warnings
    _compare(pairs, "POINT")


@pytest.mark.parametrize("vector_type, rotation, scale", [
    ("TEXTURE", (0.3, -0.5, 1.2), (1, 1, 1)),
    ("VECTOR", (-0.4, 0.2, 2.0), (-1, -1, -1)),
    ("NORMAL", (0.0, 0.7, -0.3), (2, 2, -2)),
])
def test_mapping_types_match_cycles(tmp_path, vector_type, rotation, scale):
    bs.empty_scene(48, 32, "CYCLES")
    img, _ = pattern_image()
    env_world(image=img, vector_type=vector_type, rotation=rotation, scale=scale)
    _compare(_cycles_and_ours(tmp_path, VIEWS[:2]), vector_type)


def test_our_render_of_the_environment_matches_cycles(tmp_path):
    """The whole pipeline (export, prepare, the eye pass's background) against Cycles: the same
    view rendered by both engines with Cycles' default pixel filter (Blackman-Harris 1.5 px, which
    core/sampling/camera.py reproduces), 256 samples each: 2 x 2 pixel boxes within 3 % at the 99th
    percentile (the filter jitter's noise at the pattern's sharp edges), the median within
    0.5 % and the image mean within 0.5 % (the RGB -> spectrum -> RGB round trip adds < 0.1 %
    for these colours)."""
    sc = bs.empty_scene(48, 32, "CYCLES")
    img, _ = pattern_image()
    env_world(image=img)
    bs.camera(location=(0, 0, 0), rotation=(math.radians(70), 0, math.radians(30)), lens=14.0)
    cycles = bs.render_to_array(str(tmp_path / "cycles.exr"), "CYCLES", samples=256)
    sc.opal.wavelength_step = 5.0
    ours = bs.render_to_array(str(tmp_path / "opal.exr"), bs.ENGINE, samples=256)

    def binned(a):  # 2 x 2 boxes: the filter jitter's noise at the pattern's sharp edges halves
        return a.reshape(16, 2, 24, 2, 3).mean(axis=(1, 3))

    rel = np.abs(binned(ours) - binned(cycles)) / np.maximum(binned(cycles), 0.05)
    print(f"our render vs Cycles (2 x 2 boxes): median {np.median(rel):.4f}, 99th percentile "
          f"{np.percentile(rel, 99):.4f}, max {rel.max():.4f}, mean ratio {ours.mean(axis=(0, 1)) / cycles.mean(axis=(0, 1))}")
    assert np.percentile(rel, 99) < 0.03 and np.median(rel) < 0.005
    np.testing.assert_allclose(ours.mean(axis=(0, 1)), cycles.mean(axis=(0, 1)), rtol=0.005)


# ---------------------------------------------------------------------------------- warnings
def _export():
    return export_scene(bpy.context.evaluated_depsgraph_get())


def test_missing_image_is_magenta_with_a_warning_naming_world_and_image():
    bs.empty_scene(8, 8)
    bs.camera()
    img = bpy.data.images.new("gone.exr", 4, 4)
    img.source = "FILE"
    img.filepath = "/nonexistent/gone.exr"
    env_world(strength=2.0, image=img)
    ex = _export()
    assert ex.scene.world_image.size == 0
    np.testing.assert_allclose(ex.scene.world_color, 2.0 * np.array(MISSING_IMAGE_RGB))
    msg = [w for w in ex.warnings if "Env World" in w and "gone.exr" in w]
    assert len(msg) == 1 and "magenta" in msg[0], ex.warnings


def test_mirror_ball_is_averaged_with_a_warning():
    bs.empty_scene(8, 8)
    bs.camera()
    img, px = pattern_image()
    _, env = env_world(strength=1.0, image=img, vector_type=None)
    env.projection = "MIRROR_BALL"
    ex = _export()
    assert ex.scene.world_image.size == 0
    np.testing.assert_allclose(ex.scene.world_color, px.reshape(-1, 3).mean(axis=0), rtol=1e-4)
    assert any("mirror-ball" in w and "Env World" in w for w in ex.warnings), ex.warnings


def test_mapping_location_non_uniform_scale_and_interpolation_are_named():
    bs.empty_scene(8, 8)
    bs.camera()
    img, _ = pattern_image()
    w, env = env_world(image=img, scale=(1, 2, 1))
    w.node_tree.nodes["Mapping"].inputs["Location"].default_value = (1, 0, 0)
    env.interpolation = "Closest"
    ex = _export()
    text = " | ".join(ex.warnings)
    assert "location is ignored" in text and "non-uniform" in text and "'Closest' is rendered as Linear" in text
    np.testing.assert_allclose(ex.scene.world_rotation @ ex.scene.world_rotation.T, np.eye(3), atol=1e-9)


def test_a_mapped_world_is_a_light_and_no_lights_is_not_said(tmp_path):
    """A world-lit scene must not say 'no lights' (issue 10): the world map lights it."""
    bs.empty_scene(8, 8)
    bs.camera()
    bs.plane(mat=bs.material("grey"))
    img, _ = pattern_image()
    env_world(image=img)
    checked = validate(_export().scene)
    s, warns = checked.scene, checked.warnings
    assert s.world_image.shape == (H, W, 3)
    assert not any("no lights" in w for w in warns)


def test_emission_world_shader_and_an_unlinked_vector_export_the_map():
    """An Emission shader (instead of Background) with an Environment Texture whose Vector is
    not linked: the map, the strength as its multiplier and no rotation, without warnings."""
    bs.empty_scene(8, 8)
    bs.camera()
    img, px = pattern_image()
    w, env = env_world(strength=3.0, image=img, vector_type=None)
    nt = w.node_tree
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs["Strength"].default_value = 3.0
    nt.links.new(env.outputs["Color"], em.inputs["Color"])
    nt.links.new(em.outputs[0], nt.nodes["World Output"].inputs["Surface"])
    ex = _export()
    np.testing.assert_allclose(ex.scene.world_image, px, rtol=1e-6)
    np.testing.assert_allclose(ex.scene.world_color, 3.0)
    np.testing.assert_array_equal(ex.scene.world_rotation, np.eye(3))
    assert not any("Env World" in x for x in ex.warnings), ex.warnings
