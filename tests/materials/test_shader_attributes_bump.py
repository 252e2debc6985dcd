"""Mesh attributes and the Bump node in the core (docs/physics.md sections 13.6 and 13.7),
without Blender: a shader program's ``attribute`` op reads ``Scene.corner_attributes``
interpolated at the hit (closed form: the attribute is affine over each triangle); a missing
attribute reads zeros with a validation warning; scene files carry the attributes; the Bump
node's normal for a linear height is the closed form normalize(N - d grad h) at any step, and
for a quadratic height it converges to it as the step shrinks."""

from __future__ import annotations

import numpy as np
import pytest

from scenes import top_down_camera
from test_textures import hits_at

from opal_diffraction.core.materials import surface as surface_mod
from opal_diffraction.core.materials.surface import shading_normal, surface_reflectance
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.model import Materials, Scene
from opal_diffraction.core.scene.npz import load_scene, save_scene
from opal_diffraction.core.scene.shader_programs import ProgramBuilder
from opal_diffraction.core.scene.validation import validate

SIZE = 8.0


def plane(program) -> Scene:
    """A [-4, 4]^2 floor (two triangles) running ``program``; Object coordinates = position."""
    s = Scene(materials=Materials.from_list([{"color": (0.5, 0.5, 0.5), "shader_program": 0}]))
    v, t = primitives.quad((0, 0, 0), (SIZE, 0, 0), (0, SIZE, 0))
    s.add_mesh(v, t, 0)
    s.corner_object = np.asarray(v, np.float64)[np.asarray(t)].astype(np.float32)
    s.shader_programs = [program]
    s.camera = top_down_camera(4.0, 32)
    return s


def attribute_program(name="paint"):
    b = ProgramBuilder("attr")
    col, alpha = b.op("attribute", attribute=name)
    b.outputs.update(color=col)
    return b.finish()


def corner_colours(s: Scene, seed=3) -> np.ndarray:
    """Per-vertex colours as face-corner data (T, 3, 4): (r, g, b, a) of each corner's vertex."""
    rng = np.random.default_rng(seed)
    per_vertex = np.concatenate([rng.uniform(0.1, 0.9, (len(s.vertices), 3)), np.ones((len(s.vertices), 1))], 1)
    return per_vertex[np.asarray(s.triangles)].astype(np.float32), per_vertex


def test_an_attribute_is_read_at_the_hit_as_the_barycentric_blend_of_its_corners():
    s = plane(attribute_program())
    s.corner_attributes["paint"], per_vertex = corner_colours(s)
    p = prepare(s)
    xy = np.random.default_rng(1).uniform(-3.9, 3.9, (200, 2))
    hit = hits_at(p, xy)
    # by hand: the barycentrics of each point in its triangle from the positions alone
    tri = np.asarray(p.scene.triangles)[hit.prim]
    v = np.asarray(p.scene.vertices, np.float64)[:, :2]
    a, b, c = v[tri[:, 0]], v[tri[:, 1]], v[tri[:, 2]]
    m = np.stack([b - a, c - a], axis=2)
    uv = np.linalg.solve(m, (xy - a)[..., None])[..., 0]
    w = np.stack([1 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]], axis=1)
    vid = np.asarray(p.scene.triangles)[hit.prim]
    rgb = np.einsum("bk,bkc->bc", w, per_vertex[vid][:, :, :3])
    want = p.conv.reflectance_from_rgb(rgb)
    np.testing.assert_allclose(surface_reflectance(p, hit), want, rtol=2e-5, atol=2e-6)


def test_a_missing_attribute_reads_black_with_a_warning():
    s = plane(attribute_program("nowhere"))
    v = validate(s)
    assert any("'nowhere'" in w and "(0, 0, 0)" in w for w in v.warnings), v.warnings
    p = prepare(s)
    hit = hits_at(p, np.zeros((4, 2)) + 0.3)
    np.testing.assert_allclose(surface_reflectance(p, hit), p.conv.reflectance_from_rgb(np.zeros((4, 3))),
                               atol=1e-7)


def test_scene_files_carry_attributes_and_validation_names_bad_ones(tmp_path):
    s = plane(attribute_program())
    s.corner_attributes["paint"], _ = corner_colours(s)
    save_scene(s, tmp_path / "s.npz")
    t = load_scene(tmp_path / "s.npz")
    np.testing.assert_array_equal(t.corner_attributes["paint"], s.corner_attributes["paint"])
    assert validate(t).scene.corner_attributes.keys() == {"paint"}
    bad = plane(attribute_program())
    bad.corner_attributes["paint"] = np.zeros((1, 3, 4), np.float32)
    with pytest.raises(SceneError, match=r"corner attribute 'paint' must have one row of 3 corners per triangle"):
        validate(bad)
    bad.corner_attributes["paint"], _ = corner_colours(bad)
    bad.corner_attributes["paint"][1, 2, 0] = np.nan
    with pytest.raises(SceneError, match=r"corner attribute 'paint': triangle 1 has a NaN"):
        validate(bad)


# ------------------------------------------------------------------------------------ bump
def bump_program(a, distance, strength=1.0, square=False):
    """height h = a . x_object (or (a . x)^2), the Bump's strength and distance as constants."""
    b = ProgramBuilder("bump")
    o, = b.op("coord", kind="object")
    h, = b.op("vector_math", [o, b.const(list(a)), b.const([0.0, 0.0, 0.0]), b.const(1.0)],
              operation="DOT_PRODUCT")
    if square:
        h, = b.op("math", [h, h, b.const(0.0)], operation="MULTIPLY", clamp=False)
    b.outputs.update(bump_height=h, bump_strength=b.const(strength), bump_distance=b.const(distance))
    return b.finish()


def closed_form(grad, distance, strength, up=(0.0, 0.0, 1.0)):
    n = np.asarray(up, np.float64)
    g = np.asarray(grad, np.float64) - (np.asarray(grad, np.float64) @ n)[..., None] * n
    n1 = n - distance * g
    n1 /= np.linalg.norm(n1, axis=-1, keepdims=True)
    n2 = strength * n1 + (1 - strength) * n
    return n2 / np.linalg.norm(n2, axis=-1, keepdims=True)


@pytest.mark.parametrize("distance, strength", [(0.5, 1.0), (-0.3, 0.6), (2.0, 0.25)])
def test_bump_of_a_linear_height_is_the_closed_form_on_both_faces(distance, strength):
    """Finite differences of a linear height are exact: N' = normalize(N - d grad h) with N the
    normal facing the ray; from below, N is -z and grad h the same, as in Cycles (the bump's
    relief reads inverted from the back). Tolerance: the heights are float32 at coordinates up to
    4 m (ulp 4.8e-7) over a 2.5 cm step: 2e-5 relative in the slope."""
    a = (0.6, -0.8, 0.4)
    p = prepare(plane(bump_program(a, distance, strength)))
    assert p.textures.uses("normal") and p.textures.bound("normal").all()
    xy = np.random.default_rng(2).uniform(-3.5, 3.5, (50, 2))
    top = shading_normal(p, hits_at(p, xy))
    np.testing.assert_allclose(top, np.broadcast_to(closed_form(a, distance, strength), top.shape), atol=5e-5)
    below = shading_normal(p, hits_at(p, xy, from_below=True))
    np.testing.assert_allclose(below, np.broadcast_to(closed_form(a, distance, strength, (0, 0, -1)), below.shape),
                               atol=5e-5)


def test_bump_of_a_quadratic_height_converges_to_its_gradient():
    """h = (a . x)^2: the one-sided difference over a step delta errs by O(delta) (the curvature
    term delta (a . t)^2); at the camera's footprint (8 m / 32 pixels x 0.1 = 2.5 cm) the normal is
    within 0.3 degree of the analytic one, and halving the step halves the error."""
    a = np.array([0.6, -0.8, 0.0])
    d = 0.2
    p = prepare(plane(bump_program(a, d, square=True)))
    xy = np.random.default_rng(4).uniform(-3.0, 3.0, (40, 2))
    hit = hits_at(p, xy)
    pos = np.concatenate([xy, np.zeros((len(xy), 1))], axis=1)
    want = closed_form(2 * (pos @ a)[:, None] * a, d, 1.0)
    err = []
    for width in (surface_mod.BUMP_FILTER_WIDTH, surface_mod.BUMP_FILTER_WIDTH / 2):
        old = surface_mod.BUMP_FILTER_WIDTH
        surface_mod.BUMP_FILTER_WIDTH = width
        try:
            got = shading_normal(p, hit).astype(np.float64)
        finally:
            surface_mod.BUMP_FILTER_WIDTH = old
        err.append(np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", got, want), -1, 1))).max())
    assert err[0] < 0.3
    assert err[1] == pytest.approx(err[0] / 2, rel=0.15)
