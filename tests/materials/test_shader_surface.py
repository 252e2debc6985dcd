"""Shader programs per hit (docs/physics.md section 13.6): a program bound to a material gives
its base colour, roughness and emission at each hit through the surface-parameter path
(core/materials/surface.py, textures.PreparedTextures.lookup), at the hit's interpolated Generated
/ Object coordinates; the scene file carries programs; validation names a bad one. A render of a
checker floor under a uniform world shows each cell's colour (radiance = albedo x L there)."""

from __future__ import annotations

import numpy as np
import pytest

from scenes import pixel_centres_world, top_down_camera
from test_textures import hits_at

from opal_diffraction.core.materials.shader_eval import evaluate
from opal_diffraction.core.materials.shader_textures import checker_texture, noise_texture
from opal_diffraction.core.materials.surface import surface_emission, surface_reflectance, surface_roughness
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.model import Materials, Scene
from opal_diffraction.core.scene.npz import load_scene, save_scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.scene.shader_programs import ProgramBuilder, ShaderProgram
from opal_diffraction.core.scene.validation import validate

RED, BLUE = (0.8, 0.1, 0.1), (0.1, 0.2, 0.9)


def checker_noise_program() -> ShaderProgram:
    """color: a Checker (scale 2) on Generated; roughness: Noise Fac on Object; emission: the
    checker's colour, through the same registers."""
    b = ProgramBuilder("checker")
    g, = b.op("coord", kind="generated")
    o, = b.op("coord", kind="object")
    fac, col = b.op("checker", [g, b.const(RED), b.const(BLUE), b.const(2.0)])
    k = [b.const(v) for v in (0.0, 5.0, 2.0, 0.5, 2.0, 0.0, 1.0, 0.0)]
    nfac, _ = b.op("noise", [o] + k, type="FBM", dimensions=3, normalize=True)
    b.outputs.update(color=col, roughness=nfac, emission=col)
    return b.finish()


def program_plane(size=8.0, emission_strength=1.0) -> Scene:
    """A [-size/2, size/2]^2 floor whose material runs checker_noise_program; Generated spans
    the floor ([0, 1] in x and y, z 1/2), Object is the position."""
    s = Scene(materials=Materials.from_list([{"color": (0.5, 0.5, 0.5), "shader_program": 0,
                                              "emission": (0.45, 0.15, 0.5), "emission_strength": emission_strength}]))
    v, t = primitives.quad((0, 0, 0), (size, 0, 0), (0, size, 0))
    s.add_mesh(v, t, 0)
    v = np.asarray(v, np.float64)
    gen = np.concatenate([(v[:, :2] + size / 2) / size, np.full((len(v), 1), 0.5)], axis=1)
    tris = np.asarray(t)
    s.corner_generated = gen[tris].astype(np.float32)
    s.corner_object = v[tris].astype(np.float32)
    s.shader_programs = [checker_noise_program()]
    s.camera = top_down_camera(4.0, 32)
    return s


def test_the_program_gives_each_hit_its_colour_roughness_and_emission():
    s = program_plane()
    p = prepare(s)
    xy = np.random.default_rng(1).uniform(-3.9, 3.9, (300, 2))
    hit = hits_at(p, xy)
    gen = np.concatenate([(xy + 4.0) / 8.0, np.full((len(xy), 1), 0.5)], axis=1).astype(np.float32)
    _, rgb = checker_texture(gen, RED, BLUE, 2.0)
    want = p.conv.reflectance_from_rgb(rgb.astype(np.float64))
    np.testing.assert_allclose(surface_reflectance(p, hit), want, rtol=1e-5, atol=1e-6)
    lam = np.arange(len(xy)) % p.grid.n
    np.testing.assert_allclose(surface_reflectance(p, hit, lam), want[np.arange(len(xy)), lam], rtol=1e-5, atol=1e-6)
    obj = np.concatenate([xy, np.zeros((len(xy), 1))], axis=1).astype(np.float32)
    fac, _ = noise_texture(obj, color=False)
    np.testing.assert_allclose(surface_roughness(p, hit), np.clip(fac, 0, 1), atol=2e-6)
    np.testing.assert_allclose(surface_emission(p, hit), p.conv.illuminant_from_rgb(rgb.astype(np.float64)),
                               rtol=1e-5, atol=1e-6)


def test_scene_files_carry_programs(tmp_path):
    s = program_plane()
    save_scene(s, tmp_path / "s.npz")
    t = load_scene(tmp_path / "s.npz")
    assert t.shader_programs == s.shader_programs
    np.testing.assert_array_equal(t.corner_generated, s.corner_generated)
    np.testing.assert_array_equal(t.materials.shader_program, [0])
    v = validate(t)
    assert v.scene.shader_programs[0].to_json() == s.shader_programs[0].to_json()


def test_validation_refuses_a_bad_program_in_one_line():
    s = program_plane()
    prog = s.shader_programs[0]
    s.shader_programs = [ShaderProgram(prog.ops[2:], prog.kinds, prog.outputs, prog.name)]
    with pytest.raises(SceneError, match=r"material 0 'material_0': its shader program \('checker'\): op \d+ "
                                         r"\(checker\): register 0 is read before it is written"):
        validate(s)
    s = program_plane()
    s.materials.shader_program[:] = 2
    with pytest.raises(SceneError, match="shader program 2 but the scene has 1 program"):
        validate(s)
    s = program_plane()
    s.corner_object = np.zeros((0, 3, 3), np.float32)
    assert any("reads object coordinates" in w for w in validate(s).warnings)


@pytest.mark.slow
def test_a_checker_program_floor_under_a_uniform_world_renders_its_cells():
    """Radiance albedo x L (a uniform white world over an unoccluded Lambertian floor): each
    cell's interior pixels show its colour through the spectral round trip."""
    s = program_plane()
    s.materials.emission[:] = 0
    s.world_color = np.ones(3, np.float32)
    r = render(s, RenderSettings(samples=4, wavelength_step=10.0, light_paths=0))
    x, y = pixel_centres_world(s.camera)
    g = np.stack([(x + 4) / 8, (y + 4) / 8, np.full(x.shape, 0.5)], axis=-1).reshape(-1, 3)
    cell = np.floor(g[:, :2] * 2 * (1 - 1e-6) + 1e-6)
    frac = g[:, :2] * 2 - cell
    interior = (np.abs(frac - 0.5) < 0.4).all(axis=1)
    _, want = checker_texture(g.astype(np.float32), RED, BLUE, 2.0)
    img = r.rgb.reshape(-1, 3)
    assert interior.sum() > 200
    np.testing.assert_allclose(img[interior], want[interior], rtol=0.02, atol=0.005)
    assert not r.warnings or all("program" not in w for w in r.warnings)


def test_evaluate_without_the_coordinates_reads_zero():
    prog = checker_noise_program()
    out = evaluate(prog, "color", {}, 4)
    _, want = checker_texture(np.zeros((4, 3), np.float32), RED, BLUE, 2.0)
    np.testing.assert_array_equal(out, want)


def test_a_scene_file_with_a_broken_program_is_one_scene_error(tmp_path):
    s = program_plane()
    save_scene(s, tmp_path / "s.npz")
    with np.load(tmp_path / "s.npz") as z:
        d = {k: z[k] for k in z.files}
    for text, words in (('{"ops": [["noise", [0], [1, 2], {}]], "kinds": "vff"', "not a valid program"),
                        ('[1, 2]', "not a valid program")):
        d["shader_programs"] = np.array([text])
        np.savez(tmp_path / "bad.npz", **d)
        with pytest.raises(SceneError, match=words):
            load_scene(tmp_path / "bad.npz")
    # valid JSON, bad program: validation names the material and the op
    prog = checker_noise_program()
    bad = prog.to_json().replace('["checker", ', '["chequer", ', 1)
    assert bad != prog.to_json()
    d["shader_programs"] = np.array([bad])
    np.savez(tmp_path / "bad.npz", **d)
    with pytest.raises(SceneError, match="unknown operation"):
        validate(load_scene(tmp_path / "bad.npz"))
