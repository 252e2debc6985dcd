"""Cycles' procedural textures (core/materials/shader_textures.py, docs/physics.md section 13.6)
against Cycles rendering them in this bpy session: an Emission plane (strength 1) whose colour
is the texture, seen straight down by an orthographic camera with a near-zero pixel filter, one
sample, so each pixel is the texture at its centre. The expected values are the core's textures
at the Generated coordinates of the pixel centres, ((x + 1) / 2, (y + 1) / 2, 1/2) on the
2 x 2 plane, computed here from the camera alone, shifted in z by a Mapping node (so no octave's
lattice face lies at the plane, where float rounding of the interpolated z picks either cell)."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

import blender_scenes as bs
from opal_diffraction.core.materials import shader_textures as T

P = 48
Z_SHIFT = 0.113


def render(build) -> np.ndarray:
    """Cycles' (P * P, 3) pixels of the plane whose Emission colour is ``build(nt, generated)``."""
    sc = bs.empty_scene(P, P, "CYCLES")
    bs.camera(location=(0, 0, 5), ortho_scale=2.0)
    sc.cycles.filter_width = 0.01  # point samples at pixel centres
    mat = bpy.data.materials.new("tex")
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs["Strength"].default_value = 1.0
    nt.links.new(em.outputs[0], out.inputs["Surface"])
    tc = nt.nodes.new("ShaderNodeTexCoord")
    shift = nt.nodes.new("ShaderNodeMapping")  # z off the lattice's faces (a flat plane's z is 1/2)
    shift.inputs["Location"].default_value = (0.0, 0.0, Z_SHIFT)
    nt.links.new(tc.outputs["Generated"], shift.inputs["Vector"])
    nt.links.new(build(nt, shift.outputs["Vector"]), em.inputs["Color"])
    bs.plane("plane", half=1.0, mat=mat)
    return bs.render_to_array(str(_TMP / "cycles.exr"), "CYCLES", samples=1).reshape(-1, 3)


_TMP = None


@pytest.fixture(autouse=True)
def _tmp(tmp_path):
    global _TMP
    _TMP = tmp_path


def generated() -> np.ndarray:
    c = (np.arange(P) + 0.5) / P * 2 - 1
    x, y = np.meshgrid(c, -c)
    g = np.stack([(x.ravel() + 1) / 2, (y.ravel() + 1) / 2, np.full(x.size, 0.5)], 1).astype(np.float32)
    return g + np.float32([0, 0, Z_SHIFT])


def socket(node, name):
    return next(s for s in node.inputs if s.name == name)


def test_white_noise_equals_cycles_bit_for_bit():
    """White Noise of floor(8 g) (x and y; z 0): Cycles hashes the same float bits, so every
    pixel is equal exactly (the coordinates are whole numbers, so no rounding enters)."""
    def build(nt, g):
        vm = nt.nodes.new("ShaderNodeVectorMath")
        vm.operation = "MULTIPLY"
        vm.inputs[1].default_value = (8, 8, 0)
        fl = nt.nodes.new("ShaderNodeVectorMath")
        fl.operation = "FLOOR"
        w = nt.nodes.new("ShaderNodeTexWhiteNoise")
        nt.links.new(g, vm.inputs[0])
        nt.links.new(vm.outputs[0], fl.inputs[0])
        nt.links.new(fl.outputs[0], socket(w, "Vector"))
        return w.outputs["Color"]

    got = render(build)
    _, want = T.white_noise_texture(np.floor(generated() * np.float32([8, 8, 0])))
    assert np.array_equal(got.astype(np.float32), want)


NOISE_CASES = [("FBM", "3D", 2.0, 0.0), ("FBM", "2D", 3.5, 0.7), ("FBM", "4D", 2.0, 0.0), ("FBM", "1D", 2.0, 0.0),
               ("RIDGED_MULTIFRACTAL", "3D", 2.0, 0.0), ("MULTIFRACTAL", "3D", 2.5, 0.0),
               ("HETERO_TERRAIN", "2D", 2.3, 0.0), ("HYBRID_MULTIFRACTAL", "4D", 2.3, 0.3)]


@pytest.mark.parametrize("kind,dims,detail,distortion", NOISE_CASES)
def test_noise_matches_cycles(kind, dims, detail, distortion):
    def build(nt, g):
        n = nt.nodes.new("ShaderNodeTexNoise")
        n.noise_type, n.noise_dimensions = kind, dims
        socket(n, "Detail").default_value = detail
        socket(n, "Distortion").default_value = distortion
        socket(n, "W").default_value = 0.3
        if dims != "1D":
            nt.links.new(g, socket(n, "Vector"))
        return n.outputs["Color"]

    got = render(build)
    _, want = T.noise_texture(generated(), w=0.3, detail=detail, distortion=distortion, kind=kind,
                              dimensions=int(dims[0]))
    assert want.std() > 0.02  # a textured image, not a constant
    # float32 rounding of the interpolated coordinates (about 1e-7), times the texture's slope
    # (up to ~100 with distortion): a few ulps of the texture, under 5e-5 on bpy 5.0.1 (Python
    # 3.11); bpy 5.2.3's fractals differ from it by up to 6.3e-5 on values up to 2.2 (3e-5 relative)
    print(f"{kind} {dims}: max |difference| {np.abs(got - want).max():.2e}")
    np.testing.assert_allclose(got, want, rtol=5e-5, atol=5e-5)


VORONOI_CASES = [(f, d, det, norm, m) for f in ("F1", "F2", "SMOOTH_F1") for d in ("3D", "2D")
                 for det, norm, m in ((0.0, False, "EUCLIDEAN"), (2.5, True, "EUCLIDEAN"), (1.0, False, "MANHATTAN"))]
VORONOI_CASES += [("DISTANCE_TO_EDGE", d, det, norm, "EUCLIDEAN") for d in ("3D", "2D")
                  for det, norm in ((0.0, False), (2.5, True))]


@pytest.mark.parametrize("feature,dims,detail,normalize,metric", VORONOI_CASES)
def test_voronoi_matches_cycles(feature, dims, detail, normalize, metric):
    outputs = ("Distance", "Color", "Position") if feature != "DISTANCE_TO_EDGE" else ("Distance",)
    want = T.voronoi_texture(generated(), detail=detail, randomness=0.8, dimensions=int(dims[0]), feature=feature,
                             metric=metric, normalize=normalize)
    for name in outputs:
        def build(nt, g):
            n = nt.nodes.new("ShaderNodeTexVoronoi")
            n.feature, n.voronoi_dimensions, n.distance, n.normalize = feature, dims, metric, normalize
            socket(n, "Detail").default_value = detail
            socket(n, "Randomness").default_value = 0.8
            nt.links.new(g, socket(n, "Vector"))
            return n.outputs[name]

        got = render(build)
        w = want[name] if want[name].ndim == 2 else np.repeat(want[name][:, None], 3, axis=1)
        print(f"{feature} {dims} {name}: max |difference| {np.abs(got - w).max():.2e}")
        np.testing.assert_allclose(got, w, atol=5e-5, err_msg=name)


def test_checker_and_gradients_match_cycles():
    def checker(nt, g):
        n = nt.nodes.new("ShaderNodeTexChecker")
        socket(n, "Scale").default_value = 3.0
        socket(n, "Color1").default_value = (0.9, 0.2, 0.1, 1)
        socket(n, "Color2").default_value = (0.1, 0.3, 0.7, 1)
        nt.links.new(g, socket(n, "Vector"))
        return n.outputs["Color"]

    got = render(checker)
    _, want = T.checker_texture(generated(), (0.9, 0.2, 0.1), (0.1, 0.3, 0.7), 3.0)
    assert np.array_equal(got.astype(np.float32), want)
    for kind in ("LINEAR", "QUADRATIC", "EASING", "DIAGONAL", "SPHERICAL", "QUADRATIC_SPHERE", "RADIAL"):
        def gradient(nt, g):
            n = nt.nodes.new("ShaderNodeTexGradient")
            n.gradient_type = kind
            m = nt.nodes.new("ShaderNodeMapping")
            m.inputs["Location"].default_value = (-0.5, -0.5, -0.5)
            m.inputs["Scale"].default_value = (1.3, 1.3, 1.3)
            nt.links.new(g, m.inputs["Vector"])
            nt.links.new(m.outputs[0], socket(n, "Vector"))
            return n.outputs["Color"]

        got = render(gradient)
        _, want = T.gradient_texture(generated() * np.float32(1.3) - np.float32(0.5), kind)
        np.testing.assert_allclose(got, want, atol=1e-6, err_msg=kind)


@pytest.mark.parametrize("kind,direction,profile,distortion", [
    ("BANDS", "X", "SIN", 0.0), ("BANDS", "DIAGONAL", "SAW", 3.0), ("RINGS", "SPHERICAL", "TRI", 0.0),
    ("RINGS", "Z", "SIN", 2.0)])
def test_wave_matches_cycles(kind, direction, profile, distortion):
    def build(nt, g):
        n = nt.nodes.new("ShaderNodeTexWave")
        n.wave_type, n.wave_profile = kind, profile
        if kind == "BANDS":
            n.bands_direction = direction
        else:
            n.rings_direction = direction
        socket(n, "Distortion").default_value = distortion
        socket(n, "Scale").default_value = 1.5
        nt.links.new(g, socket(n, "Vector"))
        return n.outputs["Color"]

    got = render(build)
    _, want = T.wave_texture(generated(), scale=1.5, distortion=distortion, kind=kind, bands_direction=direction,
                             rings_direction=direction, profile=profile)
    print(f"wave {kind} {direction} {profile}: max |difference| {np.abs(got - want).max():.2e}")
    # SAW and TRI jump at their period: a pixel within float rounding of a jump may take either side
    close = np.isclose(got, want, rtol=1e-4, atol=1e-4).all(axis=1)
    assert close.mean() > 0.998, f"{(~close).sum()} pixels differ"


@pytest.mark.parametrize("depth,distortion", [(0, 1.0), (2, 1.0), (5, 2.5), (10, 0.7)])
def test_magic_matches_cycles(depth, distortion):
    def build(nt, g):
        n = nt.nodes.new("ShaderNodeTexMagic")
        n.turbulence_depth = depth
        socket(n, "Distortion").default_value = distortion
        nt.links.new(g, socket(n, "Vector"))
        return n.outputs["Color"]

    got = render(build)
    _, want = T.magic_texture(generated(), distortion=distortion, depth=depth)
    print(f"magic {depth} {distortion}: max |difference| {np.abs(got - want).max():.2e}")
    # each turbulence level takes sin / cos of the last times the distortion: float rounding (a sinf
    # ulp) grows by up to the distortion per level, so the tolerance is 1e-5 distortion^depth
    tol = max(1e-4, 1e-5 * distortion ** depth)
    np.testing.assert_allclose(got, want, atol=tol)


@pytest.mark.parametrize("offset,offset_frequency,squash,squash_frequency,smooth", [
    (0.5, 2, 1.0, 2, 0.1), (0.3, 3, 0.6, 2, 0.0), (0.0, 1, 1.4, 3, 0.5)])
def test_brick_matches_cycles(offset, offset_frequency, squash, squash_frequency, smooth):
    def build(nt, g):
        n = nt.nodes.new("ShaderNodeTexBrick")
        n.offset, n.offset_frequency, n.squash, n.squash_frequency = offset, offset_frequency, squash, squash_frequency
        socket(n, "Mortar Smooth").default_value = smooth
        socket(n, "Bias").default_value = 0.1
        socket(n, "Color1").default_value = (0.8, 0.2, 0.1, 1)
        socket(n, "Color2").default_value = (0.3, 0.4, 0.2, 1)
        nt.links.new(g, socket(n, "Vector"))
        return n.outputs["Color"]

    got = render(build)
    _, want = T.brick_texture(generated(), (0.8, 0.2, 0.1), (0.3, 0.4, 0.2), (0.0, 0.0, 0.0), bias=0.1,
                              mortar_smooth=smooth, offset_amount=offset, offset_frequency=offset_frequency,
                              squash_amount=squash, squash_frequency=squash_frequency)
    print(f"brick: max |difference| {np.abs(got - want).max():.2e}")
    # a pixel within float rounding of a brick or mortar edge may take either side
    close = np.isclose(got, want, atol=1e-5).all(axis=1)
    assert close.mean() > 0.995, f"{(~close).sum()} pixels differ"
