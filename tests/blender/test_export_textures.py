"""Image textures from Blender (docs/physics.md section 13): what the exporter reads (images,
bindings, per-corner UVs and tangents) and how the core samples it, against Cycles rendering
the same .blend in this bpy session.

The Cycles comparisons render an Emission plane (or a normal-mapped diffuse plane under a sun)
seen straight down by an orthographic camera with a near-zero pixel filter (``filter_width``
0.01 px), so each pixel is the surface at its centre; the expected values come from the
exported scene alone: the core's ray caster finds each pixel centre's triangle, the exported
corner UVs are interpolated there and the exported texture is sampled with
``core.textures.sample_texture``."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

import blender_scenes as bs
from opal_diffraction.blender.export import export_scene
from opal_diffraction.core.util.enums import TextureEncoding, TextureExtension, TextureInterpolation
from opal_diffraction.core.util.geometry import interpolate_corners
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.materials.surface import shading_normal
from opal_diffraction.core.materials.textures import sample_texture
from opal_diffraction.core.transport.walker import Hit
from opal_diffraction.core.scene.validation import validate

N = 8        # texels per side
PIXELS = 48  # render size: 6 pixels per texel


def checker_pixels(n=N, seed=0) -> np.ndarray:
    """(n, n, 4) RGBA byte values / 255: a two-tone checker with a random tint per texel."""
    rng = np.random.default_rng(seed)
    i, j = np.meshgrid(np.arange(n), np.arange(n))
    base = np.where((i + j) % 2 == 0, 230, 25)[..., None]
    tint = rng.integers(-20, 21, (n, n, 3))
    px = np.concatenate([np.clip(base + tint, 0, 255), np.full((n, n, 1), 255)], axis=2)
    return (px / 255.0).astype(np.float32)


def image(name: str, px: np.ndarray, colorspace: str = "sRGB", float_buffer: bool = False, path=None):
    h, w = px.shape[:2]
    img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=float_buffer)
    img.colorspace_settings.name = colorspace
    img.pixels.foreach_set(px.astype(np.float32).ravel())
    if path is not None:  # saved as a PNG file and loaded from it, as a user's image is
        img.filepath_raw = str(path)
        img.file_format = "PNG"
        img.save()
        img = bpy.data.images.load(str(path), check_existing=False)
        img.colorspace_settings.name = colorspace
    return img


def textured_material(name: str, img, socket="emission", interpolation="Closest", extension="REPEAT",
                      coords=None, mapping=None):
    """A material whose Emission colour (socket 'emission', strength 1) or Principled Base Color
    ('base') is the image texture; ``coords`` 'GENERATED' or 'UV' adds a Texture Coordinate node,
    ``mapping`` (location, rotation, scale) a Mapping node between."""
    mat = bpy.data.materials.new(name)
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.name = f"{name} texture"
    tex.image, tex.interpolation, tex.extension = img, interpolation, extension
    if socket == "emission":
        shader = nt.nodes.new("ShaderNodeEmission")
        shader.inputs["Strength"].default_value = 1.0
        nt.links.new(tex.outputs["Color"], shader.inputs["Color"])
    else:
        shader = nt.nodes.new("ShaderNodeBsdfPrincipled")
        nt.links.new(tex.outputs["Color"], shader.inputs["Base Color"])
    nt.links.new(shader.outputs[0], out.inputs["Surface"])
    vec = tex.inputs["Vector"]
    if mapping is not None:
        m = nt.nodes.new("ShaderNodeMapping")
        for k, v in zip(("Location", "Rotation", "Scale"), mapping):
            m.inputs[k].default_value = v
        nt.links.new(m.outputs["Vector"], vec)
        vec = m.inputs["Vector"]
    if coords is not None:
        tc = nt.nodes.new("ShaderNodeTexCoord")
        nt.links.new(tc.outputs["Generated" if coords == "GENERATED" else "UV"], vec)
    return mat


def uv_plane(mat, half=1.0, uvs=((0, 0), (1, 0), (1, 1), (0, 1)), name="plane"):
    ob = bs.plane(name, half=half, mat=mat)
    layer = ob.data.uv_layers.new(name="UVMap")
    layer.uv.foreach_set("vector", np.asarray(uvs, np.float32).ravel())
    return ob


def top_down_scene(pixels=PIXELS):
    sc = bs.empty_scene(pixels, pixels, "CYCLES")
    bs.camera(location=(0, 0, 5), ortho_scale=2.0)
    sc.cycles.filter_width = 0.01  # point samples at pixel centres
    return sc


def export():
    return export_scene(bpy.context.evaluated_depsgraph_get())


def pixel_hits(prepared, pixels=PIXELS, size=2.0) -> Hit:
    """The exported scene's hits at every pixel centre of the top-down camera (image row 0 at
    the top), through the core's ray caster."""
    c = (np.arange(pixels) + 0.5) / pixels * size - size / 2
    x, y = np.meshgrid(c, -c)
    o = np.stack([x.ravel(), y.ravel(), np.full(x.size, 5.0)], axis=1).astype(np.float32)
    d = np.tile(np.array([0, 0, -1], np.float32), (len(o), 1))
    h = prepared.accel.intersect(o, d)
    assert (h.prim >= 0).all()
    ng = prepared.tri_normal[h.prim]
    return Hit(o + h.t[:, None] * d, ng, ng, np.ones(len(o), np.float32), np.ones(len(o), bool),
               prepared.tri_material[h.prim], prepared.tri_offset[h.prim], h.prim, h.u, h.v)


def expected_colours(scene, hits) -> np.ndarray:
    """The exported texture 0 at the exported UVs of each hit, (P, 3) linear."""
    uv = interpolate_corners(np.asarray(scene.corner_uvs, np.float32), hits.prim, hits.bu, hits.bv)
    return sample_texture(scene.textures[0], uv, scene.texture_interpolation[0], scene.texture_extension[0],
                          scene.texture_encoding[0])[:, :3]


def render_cycles(tmp_path, name="cycles.exr", samples=4) -> np.ndarray:
    return bs.render_to_array(str(tmp_path / name), "CYCLES", samples=samples).reshape(-1, 3)


# ------------------------------------------------------------------------------------ export
def test_a_checker_plane_exports_its_uvs_texture_and_binding_exactly(tmp_path):
    top_down_scene()
    px = checker_pixels()
    mat = textured_material("checker", image("checker", px, path=tmp_path / "checker.png"), socket="base")
    uvs = np.array([(0.1, 0.2), (0.9, 0.1), (1.0, 0.8), (0.05, 1.0)], np.float32)
    ob = uv_plane(mat, uvs=uvs)
    ex = export()
    s = ex.scene
    assert len(s.textures) == 1 and ex.stats["textures"] == 1
    np.testing.assert_array_equal(s.textures[0], px)  # the PNG's bytes / 255, still sRGB-encoded
    assert s.texture_encoding[0] == TextureEncoding.SRGB
    assert s.texture_interpolation[0] == TextureInterpolation.CLOSEST
    assert s.texture_extension[0] == TextureExtension.REPEAT
    m = s.materials
    assert m.color_texture[0] == 0 and m.roughness_texture[0] == -1 and m.normal_texture[0] == -1
    # the colour column keeps the decoded average for what reads one colour per material
    lin = np.where(px[..., :3] <= 0.04045, px[..., :3] / 12.92, ((px[..., :3] + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(m.color[0], lin.reshape(-1, 3).mean(axis=0), rtol=1e-5)
    # corner UVs: the mesh's UV of each triangle corner (loop triangles index the loops)
    me = ob.data
    me.calc_loop_triangles()
    loops = np.array([tuple(t.loops) for t in me.loop_triangles])
    np.testing.assert_array_equal(s.corner_uvs, uvs[loops])
    assert len(s.corner_tangents) == 0  # no normal map
    assert not any("average" in w for w in ex.warnings), ex.warnings


def test_each_image_is_read_once_and_shared(tmp_path):
    top_down_scene()
    img = image("shared", checker_pixels())
    a = textured_material("a", img)
    b = textured_material("b", img, interpolation="Linear")
    c = textured_material("c", img)
    uv_plane(a, name="pa")
    ob_b = uv_plane(b, name="pb")
    ob_b.location.x = 3
    ob_c = uv_plane(c, name="pc")
    ob_c.location.x = -3
    s = export().scene
    assert len(s.textures) == 2  # (image, Closest) and (image, Linear)
    assert s.textures[0] is s.textures[1]  # one array for both settings
    np.testing.assert_array_equal(sorted(s.materials.emission_texture.tolist()), [0, 0, 1])


# ------------------------------------------------------------------------------------ against Cycles
# beyond the image on every side: 4 pixels per texel, texel edges on pixel edges (Cycles' point
# samples still stray by a fraction of a pixel now and then: pixel centres stay clear of edges)
WIDE_UVS = ((-0.25, -0.25), (1.25, -0.25), (1.25, 1.25), (-0.25, 1.25))


@pytest.mark.parametrize("colorspace,interpolation,extension,uvs", [
    ("sRGB", "Closest", "REPEAT", None), ("sRGB", "Linear", "REPEAT", None),
    ("Non-Color", "Closest", "REPEAT", None), ("Non-Color", "Linear", "REPEAT", None),
    ("float", "Linear", "REPEAT", None),
    ("sRGB", "Linear", "CLIP", WIDE_UVS), ("Non-Color", "Closest", "EXTEND", WIDE_UVS),
    ("Non-Color", "Linear", "MIRROR", WIDE_UVS), ("Non-Color", "Cubic", "REPEAT", WIDE_UVS),
    ("sRGB", "Smart", "EXTEND", WIDE_UVS),
])
def test_decoded_texels_match_cycles(colorspace, interpolation, extension, uvs, tmp_path):
    """An Emission plane with an 8x8 image: Cycles' pixels equal the exported texture sampled by
    the core at the exported UVs within 1 % (+0.002 for the darkest texels), for each colour
    space, interpolation and extension (UVs beyond [0, 1] where the extension matters). For sRGB
    with Linear interpolation this holds only because both decode after interpolating: decoding
    the texels first is off by far more between texels (checked too). 64 Cycles samples (see
    below)."""
    top_down_scene()
    px = checker_pixels(seed=3)
    if colorspace == "float":
        # HDR colour (over 1), alpha kept at 1: with the alpha scaled to 1.7 too, Blender 5.2's
        # Cycles (bpy 5.2.3) rendered 1.700x the texels the exporter reads, 5.0's rendered them as read
        img = image("img", px * np.float32([1.7, 1.7, 1.7, 1.0]), colorspace="Linear Rec.709", float_buffer=True)
    else:
        img = image("img", px, colorspace=colorspace, path=tmp_path / "img.png")
    mat = textured_material("emit", img, interpolation=interpolation, extension=extension)
    uv_plane(mat) if uvs is None else uv_plane(mat, uvs=uvs)
    ex = export()
    s = ex.scene
    assert s.texture_extension[0] == TextureExtension[extension]
    want = expected_colours(s, pixel_hits(prepare(s)))
    # Cycles' samples of an interpolated lookup scatter about its value (4 samples: a few pixels
    # 5 % off); at 64 the mean is within 0.002 of it
    got = render_cycles(tmp_path, samples=64)
    np.testing.assert_allclose(got, want, rtol=0.01, atol=0.002)
    if colorspace == "sRGB" and interpolation == "Linear" and extension == "REPEAT":
        decoded_first = np.where(px[..., :3] <= 0.04045, px[..., :3] / 12.92, ((px[..., :3] + 0.055) / 1.055) ** 2.4)
        alt = np.concatenate([decoded_first, px[..., 3:]], axis=2)
        s2_want = expected_colours(type(s)(**{**s.__dict__, "textures": [alt],
                                              "texture_encoding": np.zeros(1, np.int32)}), pixel_hits(prepare(s)))
        assert np.abs(s2_want - got).max() > 0.05


def test_generated_coordinates_through_a_mapping_node_match_cycles(tmp_path):
    """Texture Coordinate Generated (object space over the bounding box) through a Mapping node
    (rotation about Z, scale, location), exported as per-corner UVs: Cycles agrees at all but
    the pixels within float noise of a texel edge."""
    top_down_scene()
    mapping = ((0.1, 0.2, 0.0), (0.0, 0.0, math.radians(30)), (2.0, 1.5, 1.0))
    mat = textured_material("gen", image("gen", checker_pixels(seed=5)), coords="GENERATED", mapping=mapping)
    ob = bs.plane("plane", half=1.0, mat=mat)  # no UV map at all
    ob.scale = (1.0, 1.0, 1.0)
    s = export().scene
    hits = pixel_hits(prepare(s))
    # the exported UVs are the Generated coordinates ((x + 1) / 2, (y + 1) / 2) through the Mapping
    p = hits.p.astype(np.float64)
    g = np.stack([(p[:, 0] + 1) / 2, (p[:, 1] + 1) / 2, np.full(len(p), 0.5)], axis=1)
    c, sn = math.cos(math.radians(30)), math.sin(math.radians(30))
    rot = np.array([[c, -sn, 0], [sn, c, 0], [0, 0, 1]])
    want_uv = (g * [2.0, 1.5, 1.0]) @ rot.T + [0.1, 0.2, 0.0]
    uv = interpolate_corners(np.asarray(s.corner_uvs, np.float32), hits.prim, hits.bu, hits.bv)
    np.testing.assert_allclose(uv, want_uv[:, :2], atol=1e-5)
    got = render_cycles(tmp_path)
    want = expected_colours(s, hits)
    close = np.isclose(got, want, rtol=0.01, atol=0.002).all(axis=1)
    assert close.mean() > 0.98, f"{(~close).sum()} of {len(close)} pixels differ"


def normal_map_image(n=4, seed=2):
    """(n, n, 4) Non-Color normal map: random unit normals within 50 degrees of +z, tilted every
    way (so the red and green channels, the tangent and the bitangent, both matter)."""
    rng = np.random.default_rng(seed)
    theta = np.radians(rng.uniform(0, 50, (n, n)))
    phi = rng.uniform(0, 2 * np.pi, (n, n))
    v = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)
    rgb = np.rint((v / 2 + 0.5) * 255) / 255
    return np.concatenate([rgb, np.ones((n, n, 1))], axis=2).astype(np.float32)


@pytest.mark.parametrize("strength,mirror_v", [(1.0, False), (0.6, True)])
def test_a_normal_mapped_plane_under_a_sun_matches_cycles(strength, mirror_v, tmp_path):
    """A white diffuse plane with a tangent-space normal map (Normal Map node, strength),
    rotated about Z, lit by a sun: Cycles' radiance is E rho cos(N', L) / pi with the mapped
    normal N'; the expected N' comes from the exported tangents and ``core.surface.shading_normal``.
    A mirrored UV map (V flipped) makes MikkTSpace's bitangent sign -1."""
    sc = top_down_scene()
    img = image("normals", normal_map_image(), colorspace="Non-Color")
    mat = bpy.data.materials.new("bumpy")
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    bsdf = nt.nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (1, 1, 1, 1)
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = img, "Closest"
    nmap = nt.nodes.new("ShaderNodeNormalMap")
    nmap.inputs["Strength"].default_value = strength
    nt.links.new(tex.outputs["Color"], nmap.inputs["Color"])
    nt.links.new(nmap.outputs["Normal"], bsdf.inputs["Normal"])
    nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
    uvs = ((0, 1), (1, 1), (1, 0), (0, 0)) if mirror_v else ((0, 0), (1, 0), (1, 1), (0, 1))
    ob = uv_plane(mat, uvs=uvs)
    ob.rotation_euler.z = math.radians(35)
    ob.scale = (1.5, 1.5, 1.0)  # covers the view when turned; non-uniform: Cycles maps in object space
    sun = bs.light("SUN", (0, 0, 3), 3.0, rotation=(math.radians(30), 0, math.radians(20)))
    bpy.context.view_layer.update()
    ex = export()
    s = ex.scene
    assert s.materials.normal_texture[0] == 0 and s.materials.normal_strength[0] == pytest.approx(strength)
    assert s.corner_tangents.shape == (len(s.triangles), 3, 4)
    np.testing.assert_array_equal(s.corner_tangents[..., 3], -1.0 if mirror_v else 1.0)
    # U runs along the object's X: turned 35 degrees, and 1 / 1.5 long against the unit normal
    # (the normal matrix of the scale (1.5, 1.5, 1))
    t = s.corner_tangents[..., :3].reshape(-1, 3)
    np.testing.assert_allclose(t, [[math.cos(math.radians(35)) / 1.5, math.sin(math.radians(35)) / 1.5, 0]] * len(t),
                               atol=1e-5)
    p = prepare(s)
    hits = pixel_hits(p)
    n = shading_normal(p, hits)
    to_sun = np.array(sun.matrix_world)[:3, :3] @ [0.0, 0.0, 1.0]  # a sun shines along its local -Z
    to_sun /= np.linalg.norm(to_sun)
    want = 3.0 / np.pi * np.clip(n @ to_sun, 0, None)
    got = render_cycles(tmp_path, samples=16) @ [0.2126, 0.7152, 0.0722]
    np.testing.assert_allclose(got, want, rtol=0.01, atol=0.003)
    sc.render.engine = bs.ENGINE


# ------------------------------------------------------------------------------------ robustness
@pytest.mark.parametrize("case", ["missing file", "no image"])
def test_a_missing_image_file_warns_naming_it_and_renders_magenta_as_cycles(case, tmp_path):
    top_down_scene(16)
    img = bpy.data.images.new("lost image", 4, 4)
    img.source = "FILE"
    img.filepath = str(tmp_path / "does_not_exist.png")
    mat = textured_material("lost material", img)
    if case == "no image":
        mat.node_tree.nodes["lost material texture"].image = None
    uv_plane(mat)
    ex = export()
    msgs = [w for w in ex.warnings if ("lost image" if case == "missing file" else "has no image") in w]
    assert msgs and all("lost material" in w for w in msgs), ex.warnings
    assert len(ex.scene.textures) == 0
    np.testing.assert_allclose(ex.scene.materials.emission[0], (1, 0, 1))
    validate(ex.scene)
    got = render_cycles(tmp_path)
    np.testing.assert_allclose(got, [(1, 0, 1)] * len(got), atol=1e-3)


def test_uv_and_generated_on_one_material_warn_and_use_the_uv_map(tmp_path):
    top_down_scene(16)
    img = image("both", checker_pixels())
    mat = textured_material("both", img, socket="base")
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    rough = nt.nodes.new("ShaderNodeTexImage")
    rough.image = img
    tc = nt.nodes.new("ShaderNodeTexCoord")
    nt.links.new(tc.outputs["Generated"], rough.inputs["Vector"])
    nt.links.new(rough.outputs["Color"], bsdf.inputs["Roughness"])
    uv_plane(mat, uvs=((0.5, 0.5), (0.6, 0.5), (0.6, 0.6), (0.5, 0.6)))
    ex = export()
    assert any("different coordinates" in w for w in ex.warnings), ex.warnings
    s = ex.scene
    assert s.materials.color_texture[0] == 0 and s.materials.roughness_texture[0] == 1  # Closest, Linear
    np.testing.assert_allclose([s.corner_uvs.min(), s.corner_uvs.max()], [0.5, 0.6], atol=1e-6)  # the UV map's


def test_a_procedural_texture_is_compiled_not_averaged(tmp_path):
    """A Noise texture on Base Color becomes the material's shader program (docs/physics.md
    section 13.6; tests/blender/test_shader_nodes.py), with no image texture and no warning."""
    top_down_scene(16)
    mat = bs.material("noisy", "PRINCIPLED")
    nt = mat.node_tree
    noise = nt.nodes.new("ShaderNodeTexNoise")
    noise.name = "My Noise"
    nt.links.new(noise.outputs["Color"], nt.nodes["Principled BSDF"].inputs["Base Color"])
    uv_plane(mat)
    ex = export()
    assert not any("My Noise" in w for w in ex.warnings), ex.warnings
    assert len(ex.scene.textures) == 0 and ex.scene.materials.color_texture[0] == -1
    assert ex.scene.materials.shader_program[0] == 0 and ex.scene.shader_programs[0].reads() == {"generated"}
    assert ex.scene.corner_generated.shape == (2, 3, 3)



# ------------------------------------------------------------------------------------ whole render
def test_a_sunlit_checker_floor_renders_as_in_cycles(tmp_path):
    """The issue's image-textured floor: an 8x8 sRGB checker PNG on a Diffuse BSDF floor, one sun,
    seen from above. Our engine (the eye pass reads the base colour per hit) against Cycles in
    this session: mean within 2 % and the 4x4-box-filtered relative RMSE within 3 % (a sun is a
    delta light: both renders are noise-free but for the pixel filter's samples at cell edges)."""
    sc = bs.empty_scene(64, 64, "CYCLES")
    bs.camera(location=(0, 0, 5), ortho_scale=2.0)
    img = image("floor", checker_pixels(seed=9), path=tmp_path / "floor.png")
    mat = bpy.data.materials.new("floor")
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    bsdf = nt.nodes.new("ShaderNodeBsdfDiffuse")
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = img, "Closest"
    nt.links.new(tex.outputs["Color"], bsdf.inputs["Color"])
    nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
    uv_plane(mat, half=1.5, uvs=((-0.25, -0.25), (1.25, -0.25), (1.25, 1.25), (-0.25, 1.25)))
    bs.light("SUN", (0, 0, 3), 3.0, rotation=(math.radians(25), 0, 0))
    sc.opal.filter_width = sc.cycles.filter_width = 1.5
    cycles = bs.render_to_array(str(tmp_path / "cycles.exr"), "CYCLES", samples=64)
    ours = bs.render_to_array(str(tmp_path / "opal.exr"), bs.ENGINE, samples=64)

    def box(a, k=4):
        return a.reshape(a.shape[0] // k, k, a.shape[1] // k, k, 3).mean(axis=(1, 3))

    c, o = box(cycles), box(ours)
    ratio = o.mean() / c.mean()
    rmse = np.sqrt(np.mean((o - c) ** 2)) / c.mean()
    print(f"mean ratio {ratio:.4f}, 4x4-box relative RMSE {rmse:.4f}")
    assert abs(ratio - 1) < 0.02 and rmse < 0.03


def test_separate_color_channels_bind_roughness_and_metallic(tmp_path):
    """A glTF-style packed texture: Separate Color (RGB) Green -> Roughness, Blue -> Metallic,
    Alpha -> nothing; the material's columns keep each channel's average."""
    top_down_scene(16)
    px = checker_pixels(seed=4)
    img = image("orm", px, colorspace="Non-Color")
    mat = bs.material("packed", "PRINCIPLED")
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    sep = nt.nodes.new("ShaderNodeSeparateColor")
    nt.links.new(tex.outputs["Color"], sep.inputs["Color"])
    nt.links.new(sep.outputs["Green"], bsdf.inputs["Roughness"])
    nt.links.new(sep.outputs["Blue"], bsdf.inputs["Metallic"])
    uv_plane(mat)
    ex = export()
    m = ex.scene.materials
    assert m.roughness_texture[0] == 0 and m.metallic_texture[0] == 0 and m.color_texture[0] == -1
    assert m.roughness_channel[0] == 1 and m.metallic_channel[0] == 2
    assert not any("not supported" in w for w in ex.warnings), ex.warnings
