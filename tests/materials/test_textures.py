"""Image textures and normal maps (docs/physics.md section 13): the texel lookup against
hand-computed texel values with Cycles' conventions (pixel centres, CLOSEST / LINEAR / CUBIC,
REPEAT / EXTEND / CLIP / MIRROR, sRGB decoded after interpolation), the per-hit surface
parameters against the converter's own RGB -> spectrum conversions of the texel, the normal map
against the analytic tilt, and the scene model (validation, degenerate triangles, .npz)."""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.util.enums import TextureEncoding, TextureExtension, TextureInterpolation
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Materials, Scene
from opal_diffraction.core.scene.checks import MAX_SIDE, SceneError
from opal_diffraction.core.scene.npz import load_scene, save_scene
from opal_diffraction.core.scene.validation import validate
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.materials.surface import (shading_normal, surface_emission, surface_metallic, surface_reflectance,
                                           surface_roughness)
from opal_diffraction.core.materials.textures import sample_texture, srgb_to_linear
from opal_diffraction.core.transport.walker import Hit

from scenes import pixel_centres_world, top_down_camera

C, L, CUB = TextureInterpolation.CLOSEST, TextureInterpolation.LINEAR, TextureInterpolation.CUBIC
REPEAT, EXTEND, CLIP, MIRROR = (TextureExtension.REPEAT, TextureExtension.EXTEND, TextureExtension.CLIP,
                                TextureExtension.MIRROR)
H, W = 3, 5


@pytest.fixture
def tex():
    return np.random.default_rng(7).random((H, W, 4)).astype(np.float32)


def centre(i, j):
    """UV of the centre of texel column i, row j."""
    return ((i + 0.5) / W, (j + 0.5) / H)


# ------------------------------------------------------------------------------ lookup conventions
def test_closest_picks_the_texel_containing_the_uv(tex):
    rng = np.random.default_rng(1)
    i, j = rng.integers(0, W, 200), rng.integers(0, H, 200)
    f = rng.uniform(0.001, 0.999, (200, 2))
    uv = np.stack([(i + f[:, 0]) / W, (j + f[:, 1]) / H], axis=1)
    for ext in (REPEAT, EXTEND, CLIP, MIRROR):
        np.testing.assert_array_equal(sample_texture(tex, uv, C, ext), tex[j, i])


def test_linear_returns_the_texel_at_its_centre_and_the_mean_midway(tex):
    uv = np.array([centre(i, j) for j in range(H) for i in range(W)])
    want = np.array([tex[j, i] for j in range(H) for i in range(W)])
    for ext in (REPEAT, EXTEND, CLIP, MIRROR):
        np.testing.assert_allclose(sample_texture(tex, uv, L, ext), want, rtol=0, atol=2e-7)
    # midway between texel (1, 1) and (2, 1): their mean; at the corner of four texels: the mean of four
    got = sample_texture(tex, [[2.0 / W, 1.5 / H], [2.0 / W, 2.0 / H]], L, EXTEND)
    np.testing.assert_allclose(got[0], (tex[1, 1] + tex[1, 2]) / 2, atol=2e-7)
    np.testing.assert_allclose(got[1], (tex[1, 1] + tex[1, 2] + tex[2, 1] + tex[2, 2]) / 4, atol=2e-7)
    # a quarter of the way from centre (1, 1) to centre (2, 1): 3/4 and 1/4
    got = sample_texture(tex, [[1.75 / W, 1.5 / H]], L, EXTEND)
    np.testing.assert_allclose(got[0], 0.75 * tex[1, 1] + 0.25 * tex[1, 2], atol=2e-7)


def test_extensions_at_and_beyond_the_border(tex):
    j = 1
    v = (j + 0.5) / H
    edge = [[0.0, v]]  # the left border, on row j's centre line
    # REPEAT: midway between the last and the first texel of the row; shifted by whole tiles, the same
    np.testing.assert_allclose(sample_texture(tex, edge, L, REPEAT)[0], (tex[j, 0] + tex[j, W - 1]) / 2, atol=2e-7)
    uv = np.array([centre(3, 2), centre(0, 0)])
    np.testing.assert_allclose(sample_texture(tex, uv + [[-7, 3], [2, -5]], L, REPEAT),
                               sample_texture(tex, uv, L, REPEAT), atol=1e-5)
    np.testing.assert_array_equal(sample_texture(tex, [[-0.5 / W + 0.001, v]], C, REPEAT)[0], tex[j, W - 1])
    # EXTEND: the border texel at the border and anywhere beyond it
    for u in (0.0, -0.3, -12.0):
        np.testing.assert_allclose(sample_texture(tex, [[u, v]], L, EXTEND)[0], tex[j, 0], atol=2e-7)
        np.testing.assert_array_equal(sample_texture(tex, [[u - 0.001, v]], C, EXTEND)[0], tex[j, 0])
    np.testing.assert_allclose(sample_texture(tex, [[1.0, v], [4.0, v]], L, EXTEND), [tex[j, W - 1]] * 2, atol=2e-7)
    # CLIP: transparent black outside; at the border LINEAR blends the texel with that black
    np.testing.assert_array_equal(sample_texture(tex, [[-0.001, v], [1.001, v], [0.5, 1.2]], C, CLIP), 0.0)
    np.testing.assert_allclose(sample_texture(tex, edge, L, CLIP)[0], tex[j, 0] / 2, atol=2e-7)
    np.testing.assert_array_equal(sample_texture(tex, [[-0.5 / W - 0.001, v], [-3.0, v]], L, CLIP), 0.0)
    # MIRROR: the image reflected about its borders
    np.testing.assert_array_equal(sample_texture(tex, [[-0.5 / W, v], [-1.5 / W, v], [1 + 0.5 / W, v]], C, MIRROR),
                                  [tex[j, 0], tex[j, 1], tex[j, W - 1]])


def test_cubic_is_the_uniform_b_spline(tex):
    # at a texel centre the B-spline taps weigh the texel and its neighbours 1/6, 2/3, 1/6 per axis
    w = np.array([1 / 6, 2 / 3, 1 / 6])
    i, j = 2, 1
    want = sum(w[a] * w[b] * tex[j - 1 + b, i - 1 + a] for a in range(3) for b in range(3))
    np.testing.assert_allclose(sample_texture(tex, [centre(i, j)], CUB, EXTEND)[0], want, atol=1e-6)
    # a constant image stays constant (the weights sum to 1) anywhere, for REPEAT and EXTEND
    const = np.full((H, W, 4), 0.37, np.float32)
    uv = np.random.default_rng(3).uniform(-2, 3, (50, 2))
    for ext in (REPEAT, EXTEND):
        np.testing.assert_allclose(sample_texture(const, uv, CUB, ext), 0.37, atol=1e-6)


def test_srgb_textures_are_decoded_after_interpolation():
    """Cycles keeps 8-bit sRGB images encoded and decodes the interpolated value: midway between
    encoded 0 and 1 is decode(0.5) = ((0.5 + 0.055) / 1.055)^2.4 = 0.21404, not 0.5."""
    t = np.zeros((1, 2, 4), np.float32)
    t[0, 1] = 1.0
    got = sample_texture(t, [[0.5, 0.5]], L, EXTEND, TextureEncoding.SRGB)[0]
    np.testing.assert_allclose(got[:3], 0.214041, atol=2e-6)
    assert got[3] == pytest.approx(0.5)  # alpha is never decoded
    np.testing.assert_allclose(srgb_to_linear([0.0, 0.04, 1.0]), [0.0, 0.04 / 12.92, 1.0], atol=1e-7)


# ------------------------------------------------------------------------------ surface parameters
def textured_plane(materials: list[dict], textures: dict, size=2.0, normal_map=False, flip_v=False) -> Scene:
    """Material m on quad m, [0, size]^2 shifted by m (size + 1) along x, with UV (x, y) / size
    (``flip_v``: V = 1 - y / size, a mirrored UV map)."""
    s = Scene(materials=Materials.from_list(materials))
    for name, (px, interp) in textures.items():
        s.add_texture(px, interp, "REPEAT")
    for m in range(len(materials)):
        x0 = m * (size + 1.0)
        v, t = primitives.quad((x0 + size / 2, size / 2, 0), (size, 0, 0), (0, size, 0))
        uv = (np.asarray(v)[:, :2] - (x0, 0.0)) / size
        if flip_v:
            uv[:, 1] = 1 - uv[:, 1]
        s.add_mesh(v, t, m, uvs=uv, uv_tangents=normal_map)
    s.camera = top_down_camera(4.0, 8)
    return s


def hits_at(prepared, xy, from_below=False) -> Hit:
    """Hits of vertical rays at world (x, y) through the ray caster (its barycentrics)."""
    xy = np.asarray(xy, np.float32)
    z = -5.0 if from_below else 5.0
    o = np.concatenate([xy, np.full((len(xy), 1), z, np.float32)], axis=1)
    d = np.tile(np.array([0, 0, 1.0 if from_below else -1.0], np.float32), (len(xy), 1))
    h = prepared.accel.intersect(o, d)
    assert (h.prim >= 0).all()
    ng = prepared.tri_normal[h.prim]
    cos = -np.einsum("ij,ij->i", d, ng)
    front = cos > 0
    ng = np.where(front[:, None], ng, -ng)
    p = o + h.t[:, None] * d
    ng = ng.astype(np.float32)
    return Hit(p.astype(np.float32), ng, ng, np.abs(cos), front, prepared.tri_material[h.prim],
               prepared.tri_offset[h.prim], h.prim, h.u, h.v)


def test_surface_reflectance_is_the_texels_spectrum():
    rng = np.random.default_rng(5)
    px = rng.random((4, 4, 4)).astype(np.float32)
    px[0, 0, :3] = (1.3, -0.2, 0.5)  # out of [0, 1]: clipped as reflectance_from_rgb clips
    s = textured_plane([{"color": (0.2, 0.3, 0.4), "color_texture": 0}, {"color": (0.6, 0.1, 0.1)}],
                       {"checker": (px, "CLOSEST")})
    p = prepare(s)
    i, j = rng.integers(0, 4, 40), rng.integers(0, 4, 40)
    xy_tex = np.stack([(i + 0.5) / 4 * 2.0, (j + 0.5) / 4 * 2.0], axis=1)  # texel centres on quad 0
    xy_plain = xy_tex + (3.0, 0.0)                                       # the same spots on quad 1
    hit = hits_at(p, np.concatenate([xy_tex, xy_plain, [[0.1, 0.1]]]))
    got = surface_reflectance(p, hit)
    want_tex = p.conv.reflectance_from_rgb(px[np.r_[j, 0], np.r_[i, 0], :3])
    np.testing.assert_allclose(got[:40], want_tex[:40], atol=2e-6)
    np.testing.assert_allclose(got[80], want_tex[40], atol=2e-6)
    np.testing.assert_array_equal(got[40:80], p.materials.reflectance[np.ones(40, int)])
    assert got.dtype == np.float32 and got.shape == (81, p.grid.n)
    lam = rng.integers(0, p.grid.n, 81)
    np.testing.assert_allclose(surface_reflectance(p, hit, lam), got[np.arange(81), lam], atol=1e-6)


def test_surface_emission_roughness_and_metallic_from_textures():
    px = np.zeros((2, 2, 4), np.float32)
    px[..., :3] = [[(0.2, 0.4, 0.6), (1.0, 0.5, 0.0)], [(0.0, 0.0, 0.0), (3.0, 2.0, 2.0)]]
    s = textured_plane([{"kind": "DIFFUSE", "emission": (1.0, 1.0, 1.0), "emission_texture": 0,
                         "emission_strength": 2.5, "roughness_texture": 0, "metallic_texture": 0}],
                       {"t": (px, "CLOSEST")})
    p = prepare(s)
    xy = np.array([[0.5, 0.5], [1.5, 0.5], [0.5, 1.5], [1.5, 1.5]])  # texels (0,0) (1,0) (0,1) (1,1)
    hit = hits_at(p, xy)
    texel = px.reshape(-1, 4)[:, :3]
    np.testing.assert_allclose(surface_emission(p, hit), p.conv.illuminant_from_rgb(2.5 * texel), rtol=1e-5,
                               atol=1e-6)
    y709 = texel @ [0.2126729, 0.7151522, 0.0721750]
    np.testing.assert_allclose(surface_roughness(p, hit), np.clip(y709, 0, 1), atol=1e-6)
    np.testing.assert_allclose(surface_metallic(p, hit), np.clip(y709, 0, 1), atol=1e-6)
    # untextured: the material's column (0 where the table has none)
    plain = prepare(textured_plane([{"emission": (0.5, 0.2, 0.1)}], {}))
    h = hits_at(plain, xy)
    np.testing.assert_array_equal(surface_emission(plain, h), plain.materials.emission[h.mat])
    want_r = getattr(plain.materials, "roughness", None)
    np.testing.assert_array_equal(surface_roughness(plain, h), 0.0 if want_r is None else want_r[h.mat])


def normal_map_scene(rgb, strength=1.0, flip_v=False):
    px = np.ones((2, 2, 4), np.float32)
    px[..., :3] = rgb
    return prepare(textured_plane([{"normal_texture": 0, "normal_strength": strength}], {"n": (px, "CLOSEST")},
                                  normal_map=True, flip_v=flip_v))


def angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1, 1)))


def test_a_flat_normal_map_leaves_the_normal_unchanged():
    p = normal_map_scene((0.5, 0.5, 1.0))
    hit = hits_at(p, [[0.3, 0.7], [1.2, 1.9]])
    np.testing.assert_allclose(shading_normal(p, hit), hit.ng, atol=1e-6)


@pytest.mark.parametrize("theta_deg", [10.0, 35.0, 60.0])
def test_a_tilted_normal_map_tilts_by_the_analytic_angle(theta_deg):
    """Plane z = 0 with U along +x: T = +x, B = N x T = +y. The texel (sin t, 0, cos t) / 2 + 1/2
    maps to N' = (sin t, 0, cos t): tilted by t towards +x; strength 1/2 blends to
    normalize(N + (N' - N) / 2), the half angle; seen from below (a back face) it is -N'."""
    t = np.radians(theta_deg)
    n_map = np.array([np.sin(t), 0.0, np.cos(t)])
    p = normal_map_scene(n_map / 2 + 0.5)
    hit = hits_at(p, [[0.3, 0.7], [1.6, 0.2]])
    n = shading_normal(p, hit)
    np.testing.assert_allclose(n, [n_map] * 2, atol=2e-6)
    np.testing.assert_allclose(angle_deg(n, hit.ng), theta_deg, atol=1e-3)
    half = shading_normal(normal_map_scene(n_map / 2 + 0.5, strength=0.5), hit)
    np.testing.assert_allclose(angle_deg(half, hit.ng), theta_deg / 2, atol=1e-3)
    below = hits_at(p, [[0.3, 0.7]], from_below=True)
    np.testing.assert_allclose(shading_normal(p, below), [-n_map], atol=2e-6)


@pytest.mark.parametrize("flip_v", [False, True])
def test_the_green_channel_tilts_along_the_bitangent(flip_v):
    """The texel (0, sin t, cos t) / 2 + 1/2 tilts N towards B = sign (N x T): +y for the UV map
    V = y, -y for the mirrored map V = 1 - y (MikkTSpace's bitangent sign -1)."""
    t = np.radians(25.0)
    p = normal_map_scene(np.array([0.0, np.sin(t), np.cos(t)]) / 2 + 0.5, flip_v=flip_v)
    assert (p.corner_tangents[..., 3] == (-1 if flip_v else 1)).all()
    n = shading_normal(p, hits_at(p, [[0.4, 1.3]]))
    np.testing.assert_allclose(n, [[0.0, -np.sin(t) if flip_v else np.sin(t), np.cos(t)]], atol=2e-6)


def test_a_normal_map_below_the_surface_is_kept_on_its_side():
    p = normal_map_scene((0.5, 0.5, 0.0))  # (0, 0, -1): straight into the surface
    hit = hits_at(p, [[0.5, 0.5]])
    n = shading_normal(p, hit)
    assert np.einsum("ij,ij->i", n, hit.ng)[0] > 0
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-6)


def test_untextured_hits_are_untouched():
    p = prepare(textured_plane([{"color": (0.3, 0.5, 0.7)}], {}))
    hit = hits_at(p, [[0.5, 0.5]] * 3)
    np.testing.assert_array_equal(surface_reflectance(p, hit), p.materials.reflectance[hit.mat])
    np.testing.assert_array_equal(shading_normal(p, hit), hit.ng)


# ------------------------------------------------------------------------------ render (eye pass)
def test_a_checker_floor_under_a_uniform_world_renders_its_texels():
    """A diffuse floor lit only by a uniform white world has radiance albedo x L (the eye pass's
    world estimator, one cosine-weighted shadow ray weighing albedo x L, is exact for an
    unoccluded plane), so with the base colour read per hit (docs/physics.md section 13.4) each
    checker cell's interior pixels show the cell's colour through the spectral round trip."""
    cells = np.array([[(0.8, 0.1, 0.1), (0.1, 0.7, 0.2)], [(0.2, 0.2, 0.9), (0.9, 0.9, 0.3)]], np.float32)
    px = np.ones((2, 2, 4), np.float32)
    px[..., :3] = cells
    s = Scene(materials=Materials.from_list([{"color": (0.5, 0.5, 0.5), "color_texture": 0}]))
    s.add_texture(px, "CLOSEST", "REPEAT")
    v, t = primitives.quad((0, 0, 0), (8.0, 0, 0), (0, 8.0, 0))
    s.add_mesh(v, t, 0, uvs=(np.asarray(v)[:, :2] + 4.0) / 4.0)  # two repeats across the floor
    s.camera = top_down_camera(4.0, 32)
    s.world_color = np.ones(3, np.float32)
    r = render(s, RenderSettings(samples=4, wavelength_step=10.0, light_paths=0))
    img = r.rgb
    x, y = pixel_centres_world(s.camera)
    u, v_ = (x + 4.0) / 4.0, (y + 4.0) / 4.0
    fu, fv = u * 2 % 1, v_ * 2 % 1
    interior = (np.abs(fu - 0.5) < 0.35) & (np.abs(fv - 0.5) < 0.35)
    ci, cj = (np.floor(u * 2) % 2).astype(int), (np.floor(v_ * 2) % 2).astype(int)
    want = cells[cj, ci]
    assert interior.sum() > 200
    np.testing.assert_allclose(img[interior], want[interior], rtol=0.02, atol=0.005)


# ------------------------------------------------------------------------------ the scene model
def scene_with_texture(**material):
    s = textured_plane([dict({"color_texture": 0}, **material)], {"t": (np.ones((2, 2, 4), np.float32), "LINEAR")})
    return s


def error_of(s: Scene) -> str:
    with pytest.raises(SceneError) as e:
        validate(s)
    return str(e.value)


def test_validation_names_bad_texture_data():
    s = scene_with_texture()
    s.materials.color_texture[:] = 3
    assert "color texture 3 but the scene has 1 texture" in error_of(s)
    s = scene_with_texture()
    s.materials.normal_texture[:] = -2
    assert "not a texture index" in error_of(s)
    s = scene_with_texture()
    s.textures[0][1, 0, 2] = np.nan
    assert "texture 0: pixel (0, 1) is NaN or infinite" in error_of(s)
    s = scene_with_texture()
    s.textures = [np.ones((2, 2, 3), np.float32)]
    assert "(height, width, 4)" in error_of(s)
    s = scene_with_texture()
    s.textures = [np.ones((1, MAX_SIDE + 1, 4), np.float32)]
    assert f"at most {MAX_SIDE}" in error_of(s)
    s = scene_with_texture()
    s.texture_extension = np.array([9], np.int32)
    assert "extension code 9" in error_of(s)
    s = scene_with_texture()
    s.corner_uvs = s.corner_uvs.copy()
    s.corner_uvs[1, 2, 0] = np.inf
    assert "corner_uvs: triangle 1" in error_of(s)
    s = scene_with_texture()
    s.corner_uvs = s.corner_uvs[:1]
    assert "one row of 3 corners per triangle" in error_of(s)


def test_textures_without_uvs_are_warned():
    s = scene_with_texture(normal_texture=0)
    s.corner_uvs = np.zeros((0, 3, 2), np.float32)
    warns = validate(s).warnings
    assert any("no UVs" in w for w in warns) and any("no tangents" in w for w in warns)


def test_dropped_degenerate_triangles_keep_the_corner_data_in_step():
    s = Scene(materials=Materials.from_list([{}]))
    s.add_mesh([(0, 0, 0), (1, 0, 0), (0, 1, 0), (2, 0, 0)], [(0, 1, 2), (0, 1, 3), (1, 3, 2)], 0,
               uvs=np.array([[[0, 0], [1, 0], [0, 1]], [[5, 5], [5, 5], [5, 5]], [[1, 0], [2, 0], [0, 1]]]),
               uv_tangents=True)
    s.camera = top_down_camera(2.0, 4)
    checked = validate(s)
    clean, warns = checked.scene, checked.warnings
    assert any("degenerate" in w for w in warns)
    np.testing.assert_array_equal(clean.corner_uvs, [[[0, 0], [1, 0], [0, 1]], [[1, 0], [2, 0], [0, 1]]])
    assert clean.corner_tangents.shape == (2, 3, 4)


def test_add_mesh_keeps_uvs_one_row_per_triangle():
    s = Scene()
    s.add_mesh(*primitives.quad((0, 0, 0), (1, 0, 0), (0, 1, 0)), 0)
    s.add_mesh(*primitives.quad((3, 0, 0), (1, 0, 0), (0, 1, 0)), 0, uvs=np.ones((4, 2)), uv_tangents=True)
    s.add_mesh(*primitives.quad((6, 0, 0), (1, 0, 0), (0, 1, 0)), 0)
    assert s.corner_uvs.shape == (6, 3, 2) and s.corner_tangents.shape == (6, 3, 4)
    np.testing.assert_array_equal(s.corner_uvs[:2], 0)
    np.testing.assert_array_equal(s.corner_uvs[2:4], 1)
    np.testing.assert_array_equal(s.corner_uvs[4:], 0)
    np.testing.assert_allclose(s.corner_tangents[2:4, :, :3], [[[1, 0, 0]] * 3] * 2, atol=1e-6)  # degenerate UVs: X


def test_npz_round_trip_and_older_files(tmp_path):
    s = scene_with_texture(normal_texture=0, normal_strength=0.5)
    s.add_texture(np.random.default_rng(0).random((3, 5, 4)), "CLOSEST", "CLIP", "SRGB")
    s.corner_tangents = np.random.default_rng(1).random((len(s.triangles), 3, 4)).astype(np.float32)
    save_scene(s, tmp_path / "s.npz")
    t = load_scene(tmp_path / "s.npz")
    assert len(t.textures) == 2
    for a, b in zip(s.textures, t.textures):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(t.texture_interpolation, [int(L), int(C)])
    np.testing.assert_array_equal(t.texture_extension, [int(REPEAT), int(CLIP)])
    np.testing.assert_array_equal(t.texture_encoding, [0, int(TextureEncoding.SRGB)])
    np.testing.assert_array_equal(t.corner_uvs, s.corner_uvs)
    np.testing.assert_array_equal(t.corner_tangents, s.corner_tangents)
    np.testing.assert_array_equal(t.materials.normal_strength, [0.5])
    validate(t)
    # a file written before textures existed: no texture arrays, no texture columns
    with np.load(tmp_path / "s.npz") as z:
        old = {k: z[k] for k in z.files if not k.startswith(("texture", "corner_"))
               and k not in {f"material_{c}" for c in ("color_texture", "roughness_texture", "metallic_texture",
                                                       "emission_texture", "normal_texture", "normal_strength",
                                                       "emission_strength")}}
    np.savez(tmp_path / "old.npz", **old)
    o = load_scene(tmp_path / "old.npz")
    assert o.textures == [] and o.corner_uvs.shape == (0, 3, 2)
    np.testing.assert_array_equal(o.materials.color_texture, [-1])
    validate(o)


def test_preparation_reuse_and_the_wire_format_carry_textures():
    """The light pass's key survives a re-preparation with the same textures and changes with a
    texel; the Dask wire format carries the texture list unchanged."""
    from opal_diffraction.core.render.distributed import from_wire, to_wire

    s = scene_with_texture()
    p = prepare(s)
    assert prepare(s, reuse=p).key == p.key
    t = Scene(**{**s.__dict__, "textures": [s.textures[0].copy()]})
    t.textures[0][0, 0, 0] = 0.5
    assert prepare(t, reuse=p).key != p.key
    back = from_wire(to_wire(s))
    assert len(back.textures) == 1
    np.testing.assert_array_equal(back.textures[0], s.textures[0])
    np.testing.assert_array_equal(back.corner_uvs, s.corner_uvs)
    assert p.textures.images[0].flags.writeable is False and p.corner_uvs.flags.writeable is False


def test_roughness_and_metallic_read_one_channel_where_the_material_says():
    """roughness_channel 1: the G channel (a Separate Color node's Green); metallic_channel 3:
    alpha; values clamped to [0, 1]."""
    px = np.zeros((2, 2, 4), np.float32)
    px[..., :] = [[(0.2, 0.4, 0.6, 0.9), (1.0, 1.5, 0.0, 0.1)], [(0.0, 0.3, 0.0, 0.5), (0.7, -0.2, 0.2, 1.0)]]
    s = textured_plane([{"roughness_texture": 0, "roughness_channel": 1, "metallic_texture": 0,
                         "metallic_channel": 3}], {"t": (px, "CLOSEST")})
    p = prepare(s)
    hit = hits_at(p, [[0.5, 0.5], [1.5, 0.5], [0.5, 1.5], [1.5, 1.5]])
    texel = px.reshape(-1, 4)
    np.testing.assert_allclose(surface_roughness(p, hit), np.clip(texel[:, 1], 0, 1), atol=1e-7)
    np.testing.assert_allclose(surface_metallic(p, hit), texel[:, 3], atol=1e-7)
    s.materials.roughness_channel[:] = 4
    with pytest.raises(SceneError, match="roughness channel 4"):
        validate(s)
