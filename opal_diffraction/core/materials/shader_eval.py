"""Shader programs evaluated per batch of hits in NumPy, float32 (docs/physics.md section 13.6):
the operations of core/scene/shader_programs.py as Cycles' SVM computes them
(``intern/cycles/kernel/svm/``, Apache-2.0, ported):

- ``const`` (a float or a colour), ``coord`` (Texture Coordinate: Generated, Object, UV),
  ``attribute`` (Attribute / Color Attribute: a mesh attribute interpolated at the hit, RGBA;
  a mesh without it reads zeros, as Cycles' ``svm_node_attr`` does);
- ``math`` (the Math node: every operation of ``svm_math`` in math_util.h with its safe_ variants,
  and the Clamp option), ``vector_math`` (``svm_vector_math``), ``mix_float``, ``mix_vector``,
  ``mix_color`` (svm/color_util.h ``svm_mix`` blend modes), ``map_range`` (svm/map_range.h, float),
  ``clamp`` (MINMAX / RANGE), ``invert``, ``gamma`` (svm_math_gamma_color), ``bright_contrast``
  (svm/brightness.h), ``hue_saturation`` (svm/hsv.h), ``separate`` / ``combine`` (XYZ, RGB, HSV or HSL), ``mapping``
  (svm/mapping_util.h, Euler XYZ as ``euler_to_transform``), ``ramp`` (svm/ramp.h
  ``rgb_ramp_lookup``: Cycles' table of 257 entries of Blender's own ColorRamp evaluation, read
  linearly or as a step, so every interpolation mode renders as in Cycles), ``curves`` /
  ``float_curve`` (RGB / Float Curves: ramp.h ``svm_node_curves`` / ``svm_node_curve``, a table
  of Blender's own curve evaluation over the curves' x range, read with Cycles' extrapolation
  and mixed by Fac; the lookup's compiled twin is shader_kernels.py ``curve_lookup_kernel``),
  ``wavelength`` (svm/wavelength.h) and ``blackbody`` (svm/blackbody.h, Cycles' fitted
  colour), the implicit
  conversions (svm/convert.h: colour -> float is the Rec.709 luminance, vector -> float the
  average, float -> colour grey);
- the textures of :mod:`.shader_textures`: ``noise``, ``voronoi``, ``checker``, ``gradient``,
  ``white_noise``, ``wave``, ``magic``, ``brick``; ``image``: a scene image (core/materials/textures.py ``sample_texture``) at
  the (x, y) of its vector, as Cycles reads an Image Texture's Vector; ``sky``: Blender's Sky
  Texture (:mod:`.sky_texture`, single and multiple scattering) towards its vector;
  ``sky_preetham``: its Preetham type; ``equirect``: an Environment Texture's equirectangular
  (u, v) of a direction (then read by ``image``).

:func:`evaluate` runs only the ops a slot needs (``ShaderProgram.needed``); its inputs are the hits'
texture coordinates ('generated', 'object', 'uv', each (B, 3) float32) and attributes
('attribute:NAME', (B, 4) float32).
"""

from __future__ import annotations

import numpy as np

from ..scene.shader_programs import Op, ShaderProgram
from . import shader_textures as T
from ..util.jit import kernels_enabled
from .shader_kernels import curve_lookup_kernel
from .sky_texture import SkyParams, preetham_radiance, sky_radiance

__all__ = ["evaluate", "MATH_FUNCTIONS", "VECTOR_MATH_FUNCTIONS", "MIX_FUNCTIONS", "curve_lookup",
           "curve_lookup_reference", "wavelength_rgb", "blackbody_rgb"]

F = np.float32
_LUMA = np.array([0.2126729, 0.7151522, 0.0721750], np.float32)


def _safe_divide(a, b):
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(b != 0, a / np.where(b != 0, b, F(1)), F(0)).astype(F)


def _safe_modulo(a, b):
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(b != 0, np.fmod(a, np.where(b != 0, b, F(1))), F(0)).astype(F)


def _floored_modulo(a, b):
    with np.errstate(divide="ignore", invalid="ignore"):
        bb = np.where(b != 0, b, F(1))
        return np.where(b != 0, a - np.floor(a / bb) * bb, F(0)).astype(F)


def _wrapf(v, hi, lo):
    rng = hi - lo
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(rng != 0, rng, F(1))
        return np.where(rng != 0, v - rng * np.floor((v - lo) / r), lo).astype(F)


def _pingpong(a, b):
    with np.errstate(divide="ignore", invalid="ignore"):
        bb = np.where(b != 0, b, F(1))
        x = (a - bb) / (bb * F(2))
        return np.where(b != 0, np.abs((x - np.floor(x)) * bb * F(2) - bb), F(0)).astype(F)


def _smoothmin(a, b, k):
    with np.errstate(divide="ignore", invalid="ignore"):
        kk = np.where(k != 0, k, F(1))
        h = np.maximum(kk - np.abs(a - b), F(0)) / kk
        return np.where(k != 0, np.minimum(a, b) - h * h * h * kk * F(1 / 6), np.minimum(a, b)).astype(F)


def _safe_pow(a, b):
    bad = (a < 0) & (b != np.trunc(b))
    with np.errstate(all="ignore"):
        return np.where(bad, F(0), np.power(a, b)).astype(F)


def _safe_log(a, b):
    ok = (a > 0) & (b > 0)
    with np.errstate(all="ignore"):
        return _safe_divide(np.log(np.where(ok, a, F(1))), np.log(np.where(ok, b, F(2)))) * ok


def _trig(fn):
    def g(a, b, c):
        with np.errstate(all="ignore"):
            return fn(a)
    return g


MATH_FUNCTIONS = {
    "ADD": lambda a, b, c: a + b,
    "SUBTRACT": lambda a, b, c: a - b,
    "MULTIPLY": lambda a, b, c: a * b,
    "DIVIDE": lambda a, b, c: _safe_divide(a, b),
    "MULTIPLY_ADD": lambda a, b, c: a * b + c,
    "POWER": lambda a, b, c: _safe_pow(a, b),
    "LOGARITHM": lambda a, b, c: _safe_log(a, b),
    "SQRT": lambda a, b, c: np.sqrt(np.maximum(a, F(0))),
    "INVERSE_SQRT": lambda a, b, c: _safe_divide(F(1), np.sqrt(np.maximum(a, F(0)))) * (a > 0),
    "ABSOLUTE": lambda a, b, c: np.abs(a),
    "EXPONENT": _trig(np.exp),
    "MINIMUM": lambda a, b, c: np.fmin(a, b),
    "MAXIMUM": lambda a, b, c: np.fmax(a, b),
    "LESS_THAN": lambda a, b, c: (a < b).astype(F),
    "GREATER_THAN": lambda a, b, c: (a > b).astype(F),
    "SIGN": lambda a, b, c: np.sign(a),
    "COMPARE": lambda a, b, c: ((a == b) | (np.abs(a - b) <= np.maximum(c, F(np.finfo(F).eps)))).astype(F),
    "SMOOTH_MIN": lambda a, b, c: _smoothmin(a, b, c),
    "SMOOTH_MAX": lambda a, b, c: -_smoothmin(-a, -b, c),
    "ROUND": lambda a, b, c: np.floor(a + F(0.5)),
    "FLOOR": lambda a, b, c: np.floor(a),
    "CEIL": lambda a, b, c: np.ceil(a),
    "TRUNC": lambda a, b, c: np.where(a >= 0, np.floor(a), np.ceil(a)),
    "FRACT": lambda a, b, c: a - np.floor(a),
    "MODULO": lambda a, b, c: _safe_modulo(a, b),
    "FLOORED_MODULO": lambda a, b, c: _floored_modulo(a, b),
    "WRAP": lambda a, b, c: _wrapf(a, b, c),
    "SNAP": lambda a, b, c: np.floor(_safe_divide(a, b)) * b,
    "PINGPONG": lambda a, b, c: _pingpong(a, b),
    "SINE": _trig(np.sin),
    "COSINE": _trig(np.cos),
    "TANGENT": _trig(np.tan),
    "ARCSINE": lambda a, b, c: np.arcsin(np.clip(a, F(-1), F(1))),
    "ARCCOSINE": lambda a, b, c: np.arccos(np.clip(a, F(-1), F(1))),
    "ARCTANGENT": _trig(np.arctan),
    "ARCTAN2": lambda a, b, c: np.arctan2(a, b),
    "SINH": _trig(np.sinh),
    "COSH": _trig(np.cosh),
    "TANH": _trig(np.tanh),
    "RADIANS": lambda a, b, c: a * F(np.pi / 180),
    "DEGREES": lambda a, b, c: a * F(180 / np.pi),
}


def _dot(a, b):
    return (a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]).astype(F)


def _len(a):
    return np.sqrt(_dot(a, a))


def _safe_normalize(a):
    n = _len(a)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((n != 0)[:, None], a / np.where(n != 0, n, F(1))[:, None], a).astype(F)


def _vm(fn_vec=None, fn_val=None):
    return fn_vec, fn_val


def _project(a, b):
    bb = _dot(b, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((bb != 0)[:, None], b * (_dot(a, b) / np.where(bb != 0, bb, F(1)))[:, None], F(0)).astype(F)


def _reflect(a, b):
    n = _safe_normalize(b)
    return (a - F(2) * _dot(n, a)[:, None] * n).astype(F)


def _refract(a, b, eta):
    n = _safe_normalize(b)
    d = _dot(n, a)
    k = F(1) - eta * eta * (F(1) - d * d)
    with np.errstate(invalid="ignore"):
        r = eta[:, None] * a - (eta * d + np.sqrt(np.maximum(k, F(0))))[:, None] * n
    return np.where((k < 0)[:, None], F(0), r).astype(F)


def _faceforward(a, b, c):
    return np.where((_dot(c, b) < 0)[:, None], a, -a).astype(F)


#: Vector Math: name -> (function of (a, b, c, scale), the kind of its result).
VECTOR_MATH_FUNCTIONS = {
    "ADD": (lambda a, b, c, s: a + b, "v"),
    "SUBTRACT": (lambda a, b, c, s: a - b, "v"),
    "MULTIPLY": (lambda a, b, c, s: a * b, "v"),
    "DIVIDE": (lambda a, b, c, s: _safe_divide(a, b), "v"),
    "MULTIPLY_ADD": (lambda a, b, c, s: a * b + c, "v"),
    "CROSS_PRODUCT": (lambda a, b, c, s: np.cross(a, b).astype(F), "v"),
    "PROJECT": (lambda a, b, c, s: _project(a, b), "v"),
    "REFLECT": (lambda a, b, c, s: _reflect(a, b), "v"),
    "REFRACT": (lambda a, b, c, s: _refract(a, b, s), "v"),
    "FACEFORWARD": (lambda a, b, c, s: _faceforward(a, b, c), "v"),
    "DOT_PRODUCT": (lambda a, b, c, s: _dot(a, b), "f"),
    "DISTANCE": (lambda a, b, c, s: _len(a - b), "f"),
    "LENGTH": (lambda a, b, c, s: _len(a), "f"),
    "SCALE": (lambda a, b, c, s: a * s[:, None], "v"),
    "NORMALIZE": (lambda a, b, c, s: _safe_normalize(a), "v"),
    "SNAP": (lambda a, b, c, s: np.floor(_safe_divide(a, b)) * b, "v"),
    "FLOOR": (lambda a, b, c, s: np.floor(a), "v"),
    "CEIL": (lambda a, b, c, s: np.ceil(a), "v"),
    "MODULO": (lambda a, b, c, s: _safe_modulo(a, b), "v"),
    "WRAP": (lambda a, b, c, s: _wrapf(a, b, c), "v"),
    "FRACTION": (lambda a, b, c, s: a - np.floor(a), "v"),
    "ABSOLUTE": (lambda a, b, c, s: np.abs(a), "v"),
    "MINIMUM": (lambda a, b, c, s: np.fmin(a, b), "v"),
    "MAXIMUM": (lambda a, b, c, s: np.fmax(a, b), "v"),
    "SINE": (lambda a, b, c, s: np.sin(a), "v"),
    "COSINE": (lambda a, b, c, s: np.cos(a), "v"),
    "TANGENT": (lambda a, b, c, s: np.tan(a), "v"),
}


def _interp(a, b, t):
    return a + t * (b - a)


def _dodge(t, c1, c2):
    tmp = F(1) - t * c2
    with np.errstate(divide="ignore", invalid="ignore"):
        q = c1 / np.where(tmp > 0, tmp, F(1))
    out = np.where(tmp <= 0, F(1), np.where(q > 1, F(1), q))
    return np.where(c1 != 0, out, c1)


def _burn(t, c1, c2):
    tmp = (F(1) - t) + t * c2
    with np.errstate(divide="ignore", invalid="ignore"):
        q = F(1) - (F(1) - c1) / np.where(tmp > 0, tmp, F(1))
    return np.where(tmp <= 0, F(0), np.clip(q, F(0), F(1)))


def _overlay(t, c1, c2):
    tm = F(1) - t
    lo = c1 * (tm + F(2) * t * c2)
    hi = F(1) - (tm + F(2) * t * (F(1) - c2)) * (F(1) - c1)
    return np.where(c1 < F(0.5), lo, hi)


def _soft_light(t, c1, c2):
    scr = F(1) - (F(1) - c2) * (F(1) - c1)
    return (F(1) - t) * c1 + t * ((F(1) - c1) * c2 * c1 + c1 * scr)


#: Mix (colour) blend modes of svm/color_util.h: name -> f(t (B, 1), c1, c2).
MIX_FUNCTIONS = {
    "MIX": lambda t, a, b: _interp(a, b, t),
    "ADD": lambda t, a, b: _interp(a, a + b, t),
    "MULTIPLY": lambda t, a, b: _interp(a, a * b, t),
    "SUBTRACT": lambda t, a, b: _interp(a, a - b, t),
    "SCREEN": lambda t, a, b: F(1) - ((F(1) - t) + t * (F(1) - b)) * (F(1) - a),
    "DIVIDE": lambda t, a, b: np.where(b != 0, (F(1) - t) * a + t * _safe_divide(a, b), a),
    "DIFFERENCE": lambda t, a, b: _interp(a, np.abs(a - b), t),
    "EXCLUSION": lambda t, a, b: np.maximum(_interp(a, a + b - F(2) * a * b, t), F(0)),
    "DARKEN": lambda t, a, b: _interp(a, np.minimum(a, b), t),
    "LIGHTEN": lambda t, a, b: _interp(a, np.maximum(a, b), t),
    "OVERLAY": _overlay,
    "DODGE": _dodge,
    "BURN": _burn,
    "SOFT_LIGHT": _soft_light,
    "LINEAR_LIGHT": lambda t, a, b: a + t * (F(2) * b - F(1)),
}


def _euler(rot):
    """(B, 3, 3) rotation matrices of Euler XYZ angles (Cycles' ``euler_to_transform``)."""
    cx, cy, cz = np.cos(rot[:, 0]), np.cos(rot[:, 1]), np.cos(rot[:, 2])
    sx, sy, sz = np.sin(rot[:, 0]), np.sin(rot[:, 1]), np.sin(rot[:, 2])
    m = np.empty((len(rot), 3, 3), F)
    m[:, 0, 0], m[:, 0, 1], m[:, 0, 2] = cy * cz, sy * sx * cz - cx * sz, sy * cx * cz + sx * sz
    m[:, 1, 0], m[:, 1, 1], m[:, 1, 2] = cy * sz, sy * sx * sz + cx * cz, sy * cx * sz - sx * cz
    m[:, 2, 0], m[:, 2, 1], m[:, 2, 2] = -sy, cy * sx, cy * cx
    return m


def _rotate(m, v):
    return (m[:, :, 0] * v[:, 0:1] + m[:, :, 1] * v[:, 1:2] + m[:, :, 2] * v[:, 2:3]).astype(F)


def _rotate_t(m, v):
    return (m[:, 0, :] * v[:, 0:1] + m[:, 1, :] * v[:, 1:2] + m[:, 2, :] * v[:, 2:3]).astype(F)


def _mapping(kind, v, loc, rot, scale):
    m = _euler(rot)
    if kind == "POINT":
        return _rotate(m, v * scale) + loc
    if kind == "TEXTURE":
        return _safe_divide(_rotate_t(m, v - loc), scale)
    if kind == "VECTOR":
        return _rotate(m, v * scale)
    return _safe_normalize(_rotate(m, _safe_divide(v, scale)))


def _smoothstep(e0, e1, x):
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (x - e0) / (e1 - e0)
    return np.where(x < e0, F(0), np.where(x >= e1, F(1), (F(3) - F(2) * t) * (t * t))).astype(F)


def _smootherstep(e0, e1, x):
    x = np.clip(_safe_divide(x - e0, e1 - e0), F(0), F(1))
    return (x * x * x * (x * (x * F(6) - F(15)) + F(10))).astype(F)


def _map_range(kind, value, fmin, fmax, tmin, tmax, steps, clamp):
    same = fmax == fmin
    with np.errstate(divide="ignore", invalid="ignore"):
        den = np.where(same, F(1), fmax - fmin)
        if kind == "STEPPED":
            f = (value - fmin) / den
            f = np.where(steps > 0, np.floor(f * (steps + F(1))) / np.where(steps > 0, steps, F(1)), F(0))
        elif kind == "SMOOTHSTEP":
            f = np.where(fmin > fmax, F(1) - _smoothstep(fmax, fmin, value), _smoothstep(fmin, fmax, value))
        elif kind == "SMOOTHERSTEP":
            f = np.where(fmin > fmax, F(1) - _smootherstep(fmax, fmin, value), _smootherstep(fmin, fmax, value))
        else:
            f = (value - fmin) / den
    out = np.where(same, F(0), tmin + f * (tmax - tmin)).astype(F)
    if clamp and kind in ("LINEAR", "STEPPED"):
        out = np.clip(out, np.minimum(tmin, tmax), np.maximum(tmin, tmax))
    return out.astype(F)


def _ramp(table, fac, constant):
    """svm/ramp.h ``rgb_ramp_lookup`` (no extrapolation): (B, 4)."""
    n = len(table)
    f = np.clip(np.nan_to_num(fac, nan=0.0), F(0), F(1)) * F(n - 1)
    i = np.clip(f.astype(np.int32), 0, n - 1)
    t = f - i.astype(F)
    a = table[i]
    if constant:
        return a
    b = table[np.minimum(i + 1, n - 1)]
    return np.where((t > 0)[:, None], (F(1) - t)[:, None] * a + t[:, None] * b, a).astype(F)


def curve_lookup_reference(table, rel, extrapolate: bool) -> np.ndarray:
    """RGB / Float Curves' table lookup, Cycles svm/ramp.h ``rgb_ramp_lookup`` /
    ``float_ramp_lookup`` (interpolated; Apache-2.0, ported): column c of ``table`` (n, C) at
    ``rel[:, c]`` (the input relative to the table's x range, (B, C) float32). Past [0, 1] with
    ``extrapolate`` the end segment continues (t0 + (t0 - t1) |f'| (n - 1)), else the end value
    holds; NaN reads the first entry. float32 in Cycles' order of operations."""
    table = np.asarray(table, F)
    rel = np.asarray(rel, F)
    n = len(table)
    cols = np.arange(rel.shape[1])[None, :]
    scale = F(n - 1)
    with np.errstate(invalid="ignore"):
        f = np.clip(np.where(np.isnan(rel), F(0), rel), F(0), F(1)) * scale
        i = np.clip(f.astype(np.int32), 0, n - 1)
        t = (f - i.astype(F)).astype(F)
        a = table[i, cols]
        b = table[np.minimum(i + 1, n - 1), cols]
        out = np.where(t > 0, (F(1) - t) * a + t * b, a).astype(F)
        if extrapolate:
            lo, hi = rel < 0, rel > 1
            below = table[0][None, :] + (table[0] - table[1])[None, :] * (-rel) * scale
            above = table[-1][None, :] + (table[-1] - table[-2])[None, :] * (rel - F(1)) * scale
            out = np.where(lo, below, np.where(hi, above, out)).astype(F)
    return out


def curve_lookup(table, rel, extrapolate: bool) -> np.ndarray:
    """:func:`curve_lookup_reference`, through the compiled kernel (core/materials/shader_kernels.py
    ``curve_lookup_kernel``) when kernels are enabled (core/util/jit.py)."""
    if not kernels_enabled():
        return curve_lookup_reference(table, rel, extrapolate)
    rel = np.ascontiguousarray(rel, F)
    out = np.empty_like(rel)
    curve_lookup_kernel(np.ascontiguousarray(table, F), rel, bool(extrapolate), out)
    return out


def _curve(table, minmax, fac, value, extrapolate):
    """svm/ramp.h ``svm_node_curves`` / ``svm_node_curve``: the input relative to the table's
    x range, looked up per channel, mixed with the input by Fac: (B, C)."""
    lo, hi = F(minmax[0]), F(minmax[1])
    rel = ((value - lo) / (hi - lo)).astype(F)
    looked = curve_lookup(table, rel, extrapolate)
    return ((F(1) - fac)[:, None] * value + fac[:, None] * looked).astype(F)


#: CIE 1931 colour matching functions x, y, z from 380 to 780 nm in 5 nm steps (81 rows) as
#: Cycles tabulates them for the Wavelength node (intern/cycles/kernel/tables.h
#: ``cie_color_match``, 4 decimals).
_CIE_XYZ = np.array([
    0.0014, 0.0000, 0.0065, 0.0022, 0.0001, 0.0105, 0.0042, 0.0001, 0.0201, 0.0076, 0.0002, 0.0362,
    0.0143, 0.0004, 0.0679, 0.0232, 0.0006, 0.1102, 0.0435, 0.0012, 0.2074, 0.0776, 0.0022, 0.3713,
    0.1344, 0.0040, 0.6456, 0.2148, 0.0073, 1.0391, 0.2839, 0.0116, 1.3856, 0.3285, 0.0168, 1.6230,
    0.3483, 0.0230, 1.7471, 0.3481, 0.0298, 1.7826, 0.3362, 0.0380, 1.7721, 0.3187, 0.0480, 1.7441,
    0.2908, 0.0600, 1.6692, 0.2511, 0.0739, 1.5281, 0.1954, 0.0910, 1.2876, 0.1421, 0.1126, 1.0419,
    0.0956, 0.1390, 0.8130, 0.0580, 0.1693, 0.6162, 0.0320, 0.2080, 0.4652, 0.0147, 0.2586, 0.3533,
    0.0049, 0.3230, 0.2720, 0.0024, 0.4073, 0.2123, 0.0093, 0.5030, 0.1582, 0.0291, 0.6082, 0.1117,
    0.0633, 0.7100, 0.0782, 0.1096, 0.7932, 0.0573, 0.1655, 0.8620, 0.0422, 0.2257, 0.9149, 0.0298,
    0.2904, 0.9540, 0.0203, 0.3597, 0.9803, 0.0134, 0.4334, 0.9950, 0.0087, 0.5121, 1.0000, 0.0057,
    0.5945, 0.9950, 0.0039, 0.6784, 0.9786, 0.0027, 0.7621, 0.9520, 0.0021, 0.8425, 0.9154, 0.0018,
    0.9163, 0.8700, 0.0017, 0.9786, 0.8163, 0.0014, 1.0263, 0.7570, 0.0011, 1.0567, 0.6949, 0.0010,
    1.0622, 0.6310, 0.0008, 1.0456, 0.5668, 0.0006, 1.0026, 0.5030, 0.0003, 0.9384, 0.4412, 0.0002,
    0.8544, 0.3810, 0.0002, 0.7514, 0.3210, 0.0001, 0.6424, 0.2650, 0.0000, 0.5419, 0.2170, 0.0000,
    0.4479, 0.1750, 0.0000, 0.3608, 0.1382, 0.0000, 0.2835, 0.1070, 0.0000, 0.2187, 0.0816, 0.0000,
    0.1649, 0.0610, 0.0000, 0.1212, 0.0446, 0.0000, 0.0874, 0.0320, 0.0000, 0.0636, 0.0232, 0.0000,
    0.0468, 0.0170, 0.0000, 0.0329, 0.0119, 0.0000, 0.0227, 0.0082, 0.0000, 0.0158, 0.0057, 0.0000,
    0.0114, 0.0041, 0.0000, 0.0081, 0.0029, 0.0000, 0.0058, 0.0021, 0.0000, 0.0041, 0.0015, 0.0000,
    0.0029, 0.0010, 0.0000, 0.0020, 0.0007, 0.0000, 0.0014, 0.0005, 0.0000, 0.0010, 0.0004, 0.0000,
    0.0007, 0.0002, 0.0000, 0.0005, 0.0002, 0.0000, 0.0003, 0.0001, 0.0000, 0.0002, 0.0001, 0.0000,
    0.0002, 0.0001, 0.0000, 0.0001, 0.0000, 0.0000, 0.0001, 0.0000, 0.0000, 0.0001, 0.0000, 0.0000,
    0.0000, 0.0000, 0.0000], np.float32).reshape(81, 3)
#: CIE XYZ (D65 white) -> linear Rec.709: Cycles' xyz_to_rgb for a Rec.709 scene-linear space
#: (intern/cycles/scene/shader.cpp ``init_xyz_transforms``, its Rec.709 default).
_XYZ_TO_709 = np.array([[3.2404542, -1.5371385, -0.4985314], [-0.9692660, 1.8760108, 0.0415560],
                        [0.0556434, -0.2040259, 1.0572252]], np.float32)


def wavelength_rgb(nm) -> np.ndarray:
    """svm/wavelength.h ``svm_node_wavelength`` (BSD-3, from OSL; ported): the CIE matching
    functions linearly interpolated at ``nm`` (0 outside [380, 780) nm), to linear Rec.709,
    divided by 2.52 and clamped at 0: (B, 3) float32."""
    nm = np.asarray(nm, F)
    with np.errstate(invalid="ignore"):
        ii = (nm - F(380)) * F(1 / 5)
        i = np.where(np.isfinite(ii), np.trunc(ii), F(-1)).astype(np.int64)
    ok = (i >= 0) & (i < 80)
    j = np.clip(i, 0, 79)
    t = (ii - j.astype(F)).astype(F)[:, None]
    xyz = np.where(ok[:, None], (F(1) - t) * _CIE_XYZ[j] + t * _CIE_XYZ[j + 1], F(0)).astype(F)
    return np.maximum(xyz @ _XYZ_TO_709.T * F(1 / 2.52), F(0)).astype(F)


#: svm/math_util.h ``svm_math_blackbody_color_rec709``'s fit (intern/cycles/kernel/tables.h
#: ``blackbody_table_r/g/b``): per temperature band, R and G as a/T + bT + c, B as ((aT + b)T + c)T + d.
_BB_EDGES = np.array([965.0, 1167.0, 1449.0, 1902.0, 3315.0, 6365.0], np.float32)
_BB_R = np.array([[1.61919106e+03, -2.05010916e-03, 5.02995757e+00], [2.48845471e+03, -1.11330907e-03, 3.22621544e+00],
                  [3.34143193e+03, -4.86551192e-04, 1.76486769e+00], [4.09461742e+03, -1.27446582e-04, 7.25731635e-01],
                  [4.67028036e+03, 2.91258199e-05, 1.26703442e-01], [4.59509185e+03, 2.87495649e-05, 1.50345020e-01],
                  [3.78717450e+03, 9.35907826e-06, 3.99075871e-01]], np.float32)
_BB_G = np.array([[-4.88999748e+02, 6.04330754e-04, -7.55807526e-02], [-7.55994277e+02, 3.16730098e-04, 4.78306139e-01],
                  [-1.02363977e+03, 1.20223470e-04, 9.36662319e-01], [-1.26571316e+03, 4.87340896e-06, 1.27054498e+00],
                  [-1.42529332e+03, -4.01150431e-05, 1.43972784e+00], [-1.17554822e+03, -2.16378048e-05, 1.30408023e+00],
                  [-5.00799571e+02, -4.59832026e-06, 1.09098763e+00]], np.float32)
_BB_B = np.array([[5.96945309e-11, -4.85742887e-08, -9.70622247e-05, -4.07936148e-03],
                  [2.40430366e-11, 5.55021075e-08, -1.98503712e-04, 2.89312858e-02],
                  [-1.40949732e-11, 1.89878968e-07, -3.56632824e-04, 9.10767778e-02],
                  [-3.61460868e-11, 2.84822009e-07, -4.93211319e-04, 1.56723440e-01],
                  [-1.97075738e-11, 1.75359352e-07, -2.50542825e-04, -2.22783266e-02],
                  [-1.61997957e-13, -1.64216008e-08, 3.86216271e-04, -7.38077418e-01],
                  [6.72650283e-13, -2.73078809e-08, 4.24098264e-04, -7.52335691e-01]], np.float32)
_BB_HOT = np.array([0.8262954810464208, 0.9945080501520986, 1.566307710274283], np.float32)    # T >= 12000 K
_BB_COLD = np.array([5.413294490189271, -0.20319390035873933, -0.0822535242887164], np.float32)  # T < 800 K


def blackbody_rgb(temperature) -> np.ndarray:
    """svm/blackbody.h ``svm_node_blackbody`` (BSD-3, from OSL; ported): Cycles' fitted linear
    Rec.709 colour of a black body at ``temperature`` K (800 to 12000 K fitted per band, constant
    outside), clamped at 0: (B, 3) float32."""
    t = np.asarray(temperature, F)
    band = np.searchsorted(_BB_EDGES, np.nan_to_num(t, nan=0.0), side="right")
    r, g, b = _BB_R[band], _BB_G[band], _BB_B[band]
    with np.errstate(all="ignore"):
        ti = F(1) / t
        col = np.stack([r[:, 0] * ti + r[:, 1] * t + r[:, 2], g[:, 0] * ti + g[:, 1] * t + g[:, 2],
                        ((b[:, 0] * t + b[:, 1]) * t + b[:, 2]) * t + b[:, 3]], axis=1).astype(F)
    col = np.where((t >= 12000)[:, None], _BB_HOT, np.where((t < 800)[:, None], _BB_COLD, col))
    return np.maximum(col, F(0)).astype(F)


def _run(op: Op, a: list, n: int, inputs: dict, need: frozenset = frozenset(), images=None) -> tuple:
    p = op.params
    name = op.name
    if name == "const":
        v = np.asarray(p["value"], F)
        return (np.broadcast_to(v, (n, 3) if v.ndim else (n,)),)
    if name == "coord":
        c = inputs.get(p["kind"])
        return (np.zeros((n, 3), F) if c is None else np.asarray(c, F).reshape(n, 3),)
    if name == "attribute":  # a mesh attribute interpolated at the hit: (B, 4) RGBA, missing: zeros (Cycles)
        c = inputs.get("attribute:" + str(p.get("attribute", "")))
        if c is None:
            return np.zeros((n, 3), F), np.zeros(n, F)
        c = np.asarray(c, F).reshape(n, 4)
        return np.ascontiguousarray(c[:, :3]), np.ascontiguousarray(c[:, 3])
    if name == "math":
        with np.errstate(all="ignore"):
            r = np.asarray(MATH_FUNCTIONS[p["operation"]](*a), F)
        if p.get("clamp"):
            r = np.clip(r, F(0), F(1))
        return (np.broadcast_to(r, (n,)),)
    if name == "vector_math":
        fn, kind = VECTOR_MATH_FUNCTIONS[p["operation"]]
        with np.errstate(all="ignore"):
            r = np.asarray(fn(*a), F)
        return (np.broadcast_to(r, (n, 3) if kind == "v" else (n,)),)
    if name == "mix_float":
        t, x, y = a
        if p.get("clamp_factor", True):
            t = np.clip(t, F(0), F(1))
        return ((x * (F(1) - t) + y * t).astype(F),)
    if name in ("mix_vector", "mix_vector_nonuniform"):
        t, x, y = a
        t = t if name == "mix_vector_nonuniform" else t[:, None]
        if p.get("clamp_factor", True):
            t = np.clip(t, F(0), F(1))
        return ((x * (F(1) - t) + y * t).astype(F),)
    if name == "mix_color":
        t, x, y = a
        if p.get("clamp_factor", True):
            t = np.clip(t, F(0), F(1))
        with np.errstate(all="ignore"):
            r = np.asarray(MIX_FUNCTIONS[p["blend"]](t[:, None], x, y), F)
        if p.get("clamp_result"):
            r = np.clip(r, F(0), F(1))
        return (np.broadcast_to(r, (n, 3)),)
    if name == "map_range":
        return (_map_range(p["interpolation"], *a, bool(p.get("clamp", True))),)
    if name == "clamp":
        v, lo, hi = a
        if p["type"] == "RANGE":
            lo, hi = np.where(lo > hi, hi, lo), np.where(lo > hi, lo, hi)
        return (np.minimum(np.maximum(v, lo), hi).astype(F),)
    if name == "invert":
        fac, col = a
        return ((fac[:, None] * (F(1) - col) + (F(1) - fac[:, None]) * col).astype(F),)
    if name == "separate":  # Separate Color's HSV / HSL modes: util/color.h's conversions first
        v = _FROM_RGB.get(p.get("mode", "RGB"), _same)(a[0])
        return tuple(np.ascontiguousarray(v[:, i]) for i in range(3))
    if name == "combine":
        return (_TO_RGB.get(p.get("mode", "RGB"), _same)(np.stack(a, axis=1).astype(F)).astype(F),)
    if name == "mapping":
        return (_mapping(p["type"], *a).astype(F),)
    if name == "ramp":
        rgba = _ramp(np.asarray(p["table"], F), a[0], bool(p.get("constant")))
        return np.ascontiguousarray(rgba[:, :3]), np.ascontiguousarray(rgba[:, 3])
    if name == "curves":  # RGB Curves: each channel through its own column
        fac, col = a
        return (_curve(p["table"], (p["min_x"], p["max_x"]), fac, col, bool(p["extrapolate"])),)
    if name == "float_curve":
        fac, v = a
        return (_curve(np.asarray(p["table"], F)[:, None], (p["min_x"], p["max_x"]), fac, v[:, None],
                       bool(p["extrapolate"]))[:, 0],)
    if name == "wavelength":
        return (wavelength_rgb(a[0]),)
    if name == "blackbody":
        return (blackbody_rgb(a[0]),)
    if name == "to_float":
        v = a[0]
        if p["from"] == "color":
            return ((v @ _LUMA).astype(F),)
        return (((v[:, 0] + v[:, 1] + v[:, 2]) * F(1 / 3)).astype(F),)
    if name == "to_vector":
        return (np.repeat(a[0][:, None], 3, axis=1).astype(F),)
    if name == "noise":
        vec, w, scale, detail, rough, lac, offset, gain, dist = a
        want_colour = op.out[1] in need  # the Color output costs two more fractal sums
        fac, col = T.noise_texture(vec, w, scale, detail, rough, lac, offset, gain, dist,
                                   dimensions=int(p.get("dimensions", 3)), kind=p["type"],
                                   normalize=bool(p.get("normalize", True)), color=want_colour)
        return fac, (col if want_colour else np.zeros((n, 3), F))
    if name == "voronoi":
        vec, w, scale, detail, rough, lac, smooth, expo, rnd = a
        out = T.voronoi_texture(vec, w, scale, detail, rough, lac, smooth, expo, rnd,
                                dimensions=int(p.get("dimensions", 3)), feature=p["feature"], metric=p["metric"],
                                normalize=bool(p.get("normalize", False)))
        return out["Distance"], out["Color"], out["Position"], out["W"]
    if name == "checker":
        vec, c1, c2, scale = a
        fac, col = T.checker_texture(vec, c1, c2, scale)
        return fac, col
    if name == "gradient":
        return T.gradient_texture(a[0], p["type"])
    if name == "white_noise":
        vec, w = a
        return T.white_noise_texture(vec, w, int(p.get("dimensions", 3)))
    if name == "wave":
        vec, scale, dist, detail, dscale, drough, phase = a
        return T.wave_texture(vec, scale, dist, detail, dscale, drough, phase, kind=p["type"],
                              bands_direction=p["bands_direction"], rings_direction=p["rings_direction"],
                              profile=p["profile"])
    if name == "magic":
        fac, col = T.magic_texture(a[0], a[1], a[2], int(p["depth"]))
        return col, fac
    if name == "brick":
        vec, c1, c2, mortar, scale, msize, msmooth, bias, width, height = a
        return T.brick_texture(vec, c1, c2, mortar, scale, msize, msmooth, bias, width, height,
                               float(p.get("offset", 0.5)), int(p.get("offset_frequency", 2)),
                               float(p.get("squash", 1.0)), int(p.get("squash_frequency", 2)))
    if name == "gamma":  # svm/math_util.h svm_math_gamma_color: positive channels raised to gamma
        col, g = a
        g = g[:, None]
        with np.errstate(all="ignore"):
            out = np.where(col > 0, np.power(np.where(col > 0, col, F(1)), g), col)
        return (np.where(g == 0, F(1), out).astype(F),)
    if name == "bright_contrast":  # svm/brightness.h
        col, bright, contrast = a
        ca = (F(1) + contrast)[:, None]
        cb = (bright - contrast * F(0.5))[:, None]
        return (np.maximum(ca * col + cb, F(0)).astype(F),)
    if name == "hue_saturation":  # svm/hsv.h with util/color.h rgb_to_hsv / hsv_to_rgb
        hue, sat, val, fac, col = a
        hsv = _rgb_to_hsv(col)
        h = hsv[:, 0] + hue + F(0.5)
        hsv = np.stack([h - np.floor(h), np.clip(hsv[:, 1] * sat, F(0), F(1)), hsv[:, 2] * val], axis=1)
        out = fac[:, None] * _hsv_to_rgb(hsv) + (F(1) - fac)[:, None] * col
        return (np.maximum(out, F(0)).astype(F),)
    if name == "image":  # an Image Texture inside the program: its (x, y) as the UV
        if images is None:
            return np.zeros((n, 3), F), np.zeros(n, F)
        rgba = images(int(p["texture"]), np.ascontiguousarray(a[0][:, :2]))
        return np.ascontiguousarray(rgba[:, :3]), np.ascontiguousarray(rgba[:, 3])
    if name == "sky":  # Blender's Sky Texture (sky_texture.py), its Vector the direction
        sp = SkyParams(*(p[k] for k in SkyParams._fields))
        return (sky_radiance(sp, a[0], with_sun=bool(p.get("with_sun", True))).astype(F),)
    if name == "equirect":  # an Environment Texture's (u, v, 0) of a direction (kernel/camera/projection.h)
        v = a[0].astype(np.float64)
        ln = np.sqrt(np.einsum("ij,ij->i", v, v))
        z = np.clip(v[:, 2] / np.where(ln > 0, ln, 1.0), -1.0, 1.0)
        u = 0.5 - np.arctan2(v[:, 1], v[:, 0]) / (2 * np.pi)
        return (np.stack([u, 1.0 - np.arccos(z) / np.pi, np.zeros_like(u)], axis=1).astype(F),)
    if name == "sky_preetham":
        return (preetham_radiance(p["sun_direction"], float(p["turbidity"]), a[0]).astype(F),)
    raise ValueError(f"unknown shader op {name!r}")


def _rgb_to_hsv(rgb):
    """util/color.h ``rgb_to_hsv``, float32."""
    r, g, b = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    cmax = np.maximum(r, np.maximum(g, b))
    cmin = np.minimum(r, np.minimum(g, b))
    delta = cmax - cmin
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(cmax != 0, delta / np.where(cmax != 0, cmax, F(1)), F(0))
        dd = np.where(delta != 0, delta, F(1))
        cr, cg, cb = (cmax - r) / dd, (cmax - g) / dd, (cmax - b) / dd
    h = np.where(r == cmax, cb - cg, np.where(g == cmax, F(2) + cr - cb, F(4) + cg - cr)) / F(6)
    h = np.where(h < 0, h + F(1), h)
    h = np.where(s != 0, h, F(0))
    return np.stack([h, s, cmax], axis=1).astype(F)


def _hsv_to_rgb(hsv):
    """util/color.h ``hsv_to_rgb``, float32."""
    h, s, v = hsv[:, 0], hsv[:, 1], hsv[:, 2]
    h = np.where(h == 1, F(0), h) * F(6)
    i = np.floor(h)
    f = h - i
    p = v * (F(1) - s)
    q = v * (F(1) - s * f)
    t = v * (F(1) - s * (F(1) - f))
    choices = [np.stack(c, axis=1) for c in ((v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v), (v, p, q))]
    idx = np.clip(i, 0, 5).astype(np.int64)
    rgb = np.choose(idx[:, None], choices)
    rgb = np.where((i > 5)[:, None], choices[5], rgb)
    return np.where((s != 0)[:, None], rgb, np.stack([v, v, v], axis=1)).astype(F)


def _rgb_to_hsl(rgb):
    """util/color.h ``rgb_to_hsl``, float32: lightness min(1, (max + min) / 2), the hue of the
    largest channel, the saturation over 2 - max - min above lightness 1/2."""
    r, g, b = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    cmax = np.maximum(r, np.maximum(g, b))
    cmin = np.minimum(r, np.minimum(g, b))
    lum = np.minimum(F(1), (cmax + cmin) / F(2))
    chromatic = cmax != cmin
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where(chromatic, cmax - cmin, F(1))
        s = np.where(lum > F(0.5), d / (F(2) - cmax - cmin), d / (cmax + cmin))
        h = np.where(r == cmax, (g - b) / d + np.where(g < b, F(6), F(0)),
                     np.where(g == cmax, (b - r) / d + F(2), (r - g) / d + F(4)))
    h, s = np.where(chromatic, h, F(0)), np.where(chromatic, s, F(0))
    return np.stack([h / F(6), s, lum], axis=1).astype(F)


def _hsl_to_rgb(hsl):
    """util/color.h ``hsl_to_rgb``, float32."""
    h, s, lum = hsl[:, 0], hsl[:, 1], hsl[:, 2]
    nr = np.clip(np.abs(h * F(6) - F(3)) - F(1), F(0), F(1))
    ng = np.clip(F(2) - np.abs(h * F(6) - F(2)), F(0), F(1))
    nb = np.clip(F(2) - np.abs(h * F(6) - F(4)), F(0), F(1))
    chroma = (F(1) - np.abs(F(2) * lum - F(1))) * s
    return np.stack([(n - F(0.5)) * chroma + lum for n in (nr, ng, nb)], axis=1).astype(F)


def _same(v):
    return v


#: Separate / Combine Color's modes: to and from RGB (Cycles' svm_node_separate_color / combine_color)
_FROM_RGB = {"HSV": _rgb_to_hsv, "HSL": _rgb_to_hsl}
_TO_RGB = {"HSV": _hsv_to_rgb, "HSL": _hsl_to_rgb}


def evaluate(program: ShaderProgram, slot: str, inputs: dict, n: int, images=None) -> np.ndarray:
    """The value of ``slot`` ('color' (n, 3), 'roughness' (n,), ...) for n hits, float32; inputs:
    'generated' / 'object' / 'uv' (n, 3) float32 (a missing one reads (0, 0, 0)); ``images``:
    f(texture index, uv (n, 2)) -> (n, 4) RGBA, the scene's image lookup (None: black). Only the ops
    the slot depends on run. Non-finite results (a division's Inf, a power's NaN) are 0, as
    nothing downstream may see them."""
    regs: dict = {}
    order = program.needed(slot)
    need = frozenset([program.outputs[slot]]).union(*(program.ops[i].args for i in order))
    for i in order:
        op = program.ops[i]
        outs = _run(op, [regs[r] for r in op.args], n, inputs, need, images)
        for r, v in zip(op.out, outs):
            regs[r] = v
    out = np.asarray(regs[program.outputs[slot]], F)
    return np.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0).astype(F, copy=False)


