"""Shader programs (core/materials/shader_eval.py, core/scene/shader_programs.py): every Math operation against its formula
in float64, Mix blend modes, Map Range, Clamp, Mapping against rotation matrices built by hand,
the ColorRamp table lookup, dead-op elimination, the JSON round trip and the checks that refuse a
bad program with one line. Against Cycles: tests/blender/test_shader_nodes.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from opal_diffraction.core.materials.shader_eval import MATH_FUNCTIONS, MIX_FUNCTIONS, VECTOR_MATH_FUNCTIONS, evaluate
from opal_diffraction.core.scene.shader_programs import (MATH_OPERATIONS, MIX_BLEND_TYPES, VECTOR_MATH_OPERATIONS,
                                                         ProgramBuilder, ShaderProgram, program_problems)

RNG = np.random.default_rng(3)
N = 400
A = RNG.uniform(-3, 3, N).astype(np.float32)
B = RNG.uniform(-3, 3, N).astype(np.float32)
C = RNG.uniform(-1, 1, N).astype(np.float32)
A[:5] = [0, 1, -1, 2.5, 0]
B[:5] = [0, 0, 2, 0, -2]


def run_math(op, clamp=False):
    b = ProgramBuilder()
    g, = b.op("coord", kind="generated")
    x, y, z = b.op("separate", [g])
    r, = b.op("math", [x, y, z], operation=op, clamp=clamp)
    col, = b.op("to_vector", [r])
    b.outputs["color"] = col
    p = b.finish()
    assert program_problems(p) is None
    return evaluate(p, "color", {"generated": np.stack([A, B, C], 1)}, N)[:, 0]


def _sdiv(a, b):
    return np.where(b != 0, a / np.where(b != 0, b, 1), 0)


WANT = {
    "ADD": lambda a, b, c: a + b, "SUBTRACT": lambda a, b, c: a - b, "MULTIPLY": lambda a, b, c: a * b,
    "DIVIDE": lambda a, b, c: _sdiv(a, b), "MULTIPLY_ADD": lambda a, b, c: a * b + c,
    "POWER": lambda a, b, c: np.where((a < 0) & (b != np.trunc(b)), 0, np.abs(a) ** b * np.where((a < 0) & (np.trunc(b) % 2 == 1), -1, 1)),
    "LOGARITHM": lambda a, b, c: np.where((a > 0) & (b > 0), _sdiv(np.log(np.abs(a) + (a == 0)), np.log(np.abs(b) + (b == 0))), 0),
    "SQRT": lambda a, b, c: np.sqrt(np.maximum(a, 0)), "INVERSE_SQRT": lambda a, b, c: np.where(a > 0, 1 / np.sqrt(np.abs(a) + (a == 0)), 0),
    "ABSOLUTE": lambda a, b, c: np.abs(a), "EXPONENT": lambda a, b, c: np.exp(a),
    "MINIMUM": lambda a, b, c: np.minimum(a, b), "MAXIMUM": lambda a, b, c: np.maximum(a, b),
    "LESS_THAN": lambda a, b, c: (a < b) * 1.0, "GREATER_THAN": lambda a, b, c: (a > b) * 1.0,
    "SIGN": lambda a, b, c: np.sign(a),
    "COMPARE": lambda a, b, c: (np.abs(a - b) <= np.maximum(c, 2 ** -23)) * 1.0,
    "SMOOTH_MIN": lambda a, b, c: np.where(c != 0, np.minimum(a, b) - np.maximum(c - np.abs(a - b), 0) ** 3 / np.where(c != 0, c, 1) ** 2 / 6, np.minimum(a, b)),
    "SMOOTH_MAX": lambda a, b, c: np.where(c != 0, np.maximum(a, b) + np.maximum(c - np.abs(a - b), 0) ** 3 / np.where(c != 0, c, 1) ** 2 / 6, np.maximum(a, b)),
    "ROUND": lambda a, b, c: np.floor(a + 0.5), "FLOOR": lambda a, b, c: np.floor(a), "CEIL": lambda a, b, c: np.ceil(a),
    "TRUNC": lambda a, b, c: np.trunc(a), "FRACT": lambda a, b, c: a - np.floor(a),
    "MODULO": lambda a, b, c: np.where(b != 0, np.fmod(a, np.where(b != 0, b, 1)), 0),
    "FLOORED_MODULO": lambda a, b, c: np.where(b != 0, a - np.floor(_sdiv(a, b)) * b, 0),
    "WRAP": lambda a, b, c: np.where(b - c != 0, c + np.mod(a - c, np.where(b - c != 0, b - c, 1)), c),
    "SNAP": lambda a, b, c: np.floor(_sdiv(a, b)) * b,
    "PINGPONG": lambda a, b, c: np.where(b != 0, np.abs(np.mod(a - b, 2 * np.abs(b) + (b == 0)) * np.sign(b) - b) if False else np.abs(((a - b) / (2 * np.where(b != 0, b, 1)) - np.floor((a - b) / (2 * np.where(b != 0, b, 1)))) * 2 * b - b), 0),
    "SINE": lambda a, b, c: np.sin(a), "COSINE": lambda a, b, c: np.cos(a), "TANGENT": lambda a, b, c: np.tan(a),
    "ARCSINE": lambda a, b, c: np.arcsin(np.clip(a, -1, 1)), "ARCCOSINE": lambda a, b, c: np.arccos(np.clip(a, -1, 1)),
    "ARCTANGENT": lambda a, b, c: np.arctan(a), "ARCTAN2": lambda a, b, c: np.arctan2(a, b),
    "SINH": lambda a, b, c: np.sinh(a), "COSH": lambda a, b, c: np.cosh(a), "TANH": lambda a, b, c: np.tanh(a),
    "RADIANS": lambda a, b, c: a * math.pi / 180, "DEGREES": lambda a, b, c: a * 180 / math.pi,
}


def test_every_operation_is_implemented_and_tested():
    assert set(WANT) == set(MATH_OPERATIONS) == set(MATH_FUNCTIONS)
    assert set(MIX_BLEND_TYPES) == set(MIX_FUNCTIONS)
    assert {k: v[1] for k, v in VECTOR_MATH_FUNCTIONS.items()} == VECTOR_MATH_OPERATIONS


@pytest.mark.parametrize("op", sorted(MATH_OPERATIONS))
def test_math_operation_matches_its_formula(op):
    a, b, c = (x.astype(np.float64) for x in (A, B, C))
    with np.errstate(all="ignore"):
        want = WANT[op](a, b, c)
    got = run_math(op).astype(np.float64)
    ok = np.isfinite(want)
    scale = np.maximum(np.abs(want[ok]), 1)
    assert np.all(np.abs(got[ok] - want[ok]) <= 2e-5 * scale), op
    assert np.all(got[~ok] == 0)  # non-finite results become 0
    clamped = run_math(op, clamp=True)
    assert clamped.min() >= 0 and clamped.max() <= 1


def colour_program(blend, clamp_result=False):
    b = ProgramBuilder()
    g, = b.op("coord", kind="generated")
    o, = b.op("coord", kind="object")
    u, = b.op("coord", kind="uv")
    t, _, _ = b.op("separate", [u])
    r, = b.op("mix_color", [t, g, o], blend=blend, clamp_factor=True, clamp_result=clamp_result)
    b.outputs["color"] = r
    return b.finish()


@pytest.mark.parametrize("blend", sorted(MIX_BLEND_TYPES))
def test_mix_colour_blend_modes(blend):
    c1 = RNG.uniform(0, 1, (N, 3)).astype(np.float32)
    c2 = RNG.uniform(0, 1, (N, 3)).astype(np.float32)
    t = RNG.uniform(-0.2, 1.2, (N, 3)).astype(np.float32)
    got = evaluate(colour_program(blend), "color", {"generated": c1, "object": c2, "uv": t}, N).astype(np.float64)
    a, b, f = c1.astype(np.float64), c2.astype(np.float64), np.clip(t[:, :1].astype(np.float64), 0, 1)
    lerp = lambda x, y: (1 - f) * x + f * y  # noqa: E731
    with np.errstate(all="ignore"):
        want = {
            "MIX": lerp(a, b), "ADD": lerp(a, a + b), "MULTIPLY": lerp(a, a * b), "SUBTRACT": lerp(a, a - b),
            "SCREEN": 1 - (1 - f * b) * (1 - a), "DIVIDE": np.where(b != 0, lerp(a, a / b), a),
            "DIFFERENCE": lerp(a, np.abs(a - b)), "EXCLUSION": np.maximum(lerp(a, a + b - 2 * a * b), 0),
            "DARKEN": lerp(a, np.minimum(a, b)), "LIGHTEN": lerp(a, np.maximum(a, b)),
            "OVERLAY": np.where(a < 0.5, a * (1 - f + 2 * f * b), 1 - (1 - f + 2 * f * (1 - b)) * (1 - a)),
            "DODGE": np.where(a != 0, np.where(1 - f * b <= 0, 1, np.minimum(a / (1 - f * b), 1)), a),
            "BURN": np.where(1 - f + f * b <= 0, 0, np.clip(1 - (1 - a) / (1 - f + f * b), 0, 1)),
            "SOFT_LIGHT": (1 - f) * a + f * ((1 - a) * b * a + a * (1 - (1 - b) * (1 - a))),
            "LINEAR_LIGHT": a + f * (2 * b - 1),
        }[blend]
    np.testing.assert_allclose(got, want, atol=1e-5)
    clamped = evaluate(colour_program(blend, True), "color", {"generated": c1, "object": c2, "uv": t}, N)
    assert clamped.min() >= 0 and clamped.max() <= 1


def test_map_range_clamp_invert_and_ramp():
    b = ProgramBuilder()
    g, = b.op("coord", kind="generated")
    x, y, z = b.op("separate", [g])
    lin, = b.op("map_range", [x, b.const(0.2), b.const(0.8), b.const(-1.0), b.const(3.0), b.const(4.0)],
                interpolation="LINEAR", clamp=True)
    st, = b.op("map_range", [x, b.const(0.2), b.const(0.8), b.const(0.0), b.const(1.0), b.const(4.0)],
               interpolation="STEPPED", clamp=False)
    sm, = b.op("map_range", [x, b.const(0.8), b.const(0.2), b.const(0.0), b.const(1.0), b.const(4.0)],
               interpolation="SMOOTHSTEP", clamp=False)
    cl, = b.op("clamp", [y, b.const(0.7), b.const(0.3)], type="RANGE")
    b.outputs["roughness"] = cl
    table = np.zeros((256, 4), np.float32)
    table[:, 0] = np.linspace(0, 1, 256) ** 2
    table[:, 3] = 1
    rgb, alpha = b.op("ramp", [z], table=table.tolist())
    inv, = b.op("invert", [b.const(0.25), rgb])
    v, = b.op("combine", [lin, st, sm])
    b.outputs["color"] = v
    b.outputs["emission"] = inv
    p = b.finish()
    assert program_problems(p) is None
    pts = RNG.uniform(-0.2, 1.2, (N, 3)).astype(np.float32)
    got = evaluate(p, "color", {"generated": pts}, N).astype(np.float64)
    x = pts[:, 0].astype(np.float64)
    np.testing.assert_allclose(got[:, 0], np.clip(-1 + (x - 0.2) / 0.6 * 4, -1, 3), atol=1e-5)
    np.testing.assert_allclose(got[:, 1], np.floor((x - 0.2) / 0.6 * 5) / 4, atol=1e-5)
    t = np.clip((x - 0.2) / 0.6, 0, 1)
    np.testing.assert_allclose(got[:, 2], 1 - (3 - 2 * t) * t * t, atol=1e-5)
    rough = evaluate(p, "roughness", {"generated": pts}, N)
    np.testing.assert_allclose(rough, np.clip(pts[:, 1], 0.3, 0.7))
    em = evaluate(p, "emission", {"generated": pts}, N).astype(np.float64)
    f = np.clip(pts[:, 2], 0, 1) * 255
    i = np.minimum(f.astype(int), 255)
    ramp_r = table[i, 0] + (f - i) * (table[np.minimum(i + 1, 255), 0] - table[i, 0])
    np.testing.assert_allclose(em[:, 0], 0.75 * ramp_r + 0.25 * (1 - ramp_r), atol=1e-5)
    # the emission slot does not run the map-range ops (dead-op elimination)
    names = {p.ops[i].name for i in p.needed("emission")}
    assert "map_range" not in names and "ramp" in names


def _euler_xyz(r):
    cx, sx, cy, sy, cz, sz = math.cos(r[0]), math.sin(r[0]), math.cos(r[1]), math.sin(r[1]), math.cos(r[2]), math.sin(r[2])
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


@pytest.mark.parametrize("kind", ["POINT", "TEXTURE", "VECTOR", "NORMAL"])
def test_mapping_matches_rotation_matrices(kind):
    loc, rot, scale = (0.3, -0.2, 1.0), (0.4, -0.7, 1.1), (2.0, 0.5, 1.5)
    b = ProgramBuilder()
    g, = b.op("coord", kind="object")
    m, = b.op("mapping", [g, b.const(loc), b.const(rot), b.const(scale)], type=kind)
    b.outputs["color"] = m
    pts = RNG.uniform(-1, 1, (N, 3)).astype(np.float32)
    got = evaluate(b.finish(), "color", {"object": pts}, N).astype(np.float64)
    R, p, L, S = _euler_xyz(rot), pts.astype(np.float64), np.array(loc), np.array(scale)
    want = {"POINT": (p * S) @ R.T + L, "TEXTURE": ((p - L) @ R) / S, "VECTOR": (p * S) @ R.T,
            "NORMAL": None}[kind]
    if want is None:
        want = (p / S) @ R.T
        want /= np.linalg.norm(want, axis=1, keepdims=True)
    np.testing.assert_allclose(got, want, atol=2e-6)


def test_json_round_trip_and_checks():
    b = ProgramBuilder("noise floor")
    g, = b.op("coord", kind="generated")
    k = [b.const(v) for v in (0.0, 5.0, 2.0, 0.5, 2.0, 0.0, 1.0, 0.0)]
    fac, col = b.op("noise", [g] + k, type="FBM", dimensions=3, normalize=True)
    b.outputs["color"] = col
    p = b.finish()
    q = ShaderProgram.from_json(p.to_json())
    assert q == p and program_problems(q) is None and q.reads() == {"generated"}
    bad = [
        (ShaderProgram(p.ops, p.kinds, {"color": fac}), "output 'color'"),
        (ShaderProgram(p.ops[1:], p.kinds, p.outputs), "read before it is written"),
        (ShaderProgram(p.ops, p.kinds, {"colour": col}), "unknown output slot"),
        (ShaderProgram((p.ops[0].__class__("nope", (), (0,), {}),), p.kinds, {}), "unknown operation"),
        (ShaderProgram(tuple(o if o.name != "noise" else o.__class__("noise", o.args, o.out, {**o.params, "type": "X"})
                             for o in p.ops), p.kinds, p.outputs), "type 'X'"),
    ]
    for prog, words in bad:
        msg = program_problems(prog)
        assert msg is not None and words in msg, (msg, words)


def test_hsv_conversions_match_colorsys():
    import colorsys

    from opal_diffraction.core.materials.shader_eval import _hsv_to_rgb, _rgb_to_hsv

    rgb = RNG.uniform(0, 1.5, (500, 3)).astype(np.float32)
    rgb[:5] = [[0, 0, 0], [1, 1, 1], [1, 0, 0], [0.2, 0.2, 0.9], [0.5, 0.5, 0.5]]
    hsv = _rgb_to_hsv(rgb)
    want = np.array([colorsys.rgb_to_hsv(*map(float, c)) for c in rgb])
    np.testing.assert_allclose(hsv, want, atol=2e-6)
    back = _hsv_to_rgb(hsv)
    np.testing.assert_allclose(back, rgb, atol=4e-6)
    np.testing.assert_allclose(_hsv_to_rgb(want.astype(np.float32)),
                               np.array([colorsys.hsv_to_rgb(*c) for c in want]), atol=4e-6)
