"""Property-based fuzzing of the whole render input space: scenes and settings, valid and not.

Every generated case must end in one of two ways:
- ``render()`` raises SceneError with a clean one-line message (no other exception type), or
- it returns a finite, non-negative spectral image of shape (H, W, n), finite RGB and finite passes.
A case that runs past the per-case time bound is a hang (a failure too).

The generator builds a renderable scene (1x1..8x8 pixels, 1-2 samples, a few hundred light paths,
5-60 nm wavelength steps, so a case costs ~0.1 s) from random primitives, materials of every kind
(dispersion, gratings), lights of every kind (none to many) and a random camera, then applies zero
to a few mutations anywhere in the input: NaN / inf / huge / tiny / negative values, wrong per-row
shapes, wrong dtypes (strings, complex, bool, objects), empty tables, out-of-range indices and codes,
bad settings.

CI runs a small number of cases (deterministic); more with the environment:
    OPAL_FUZZ_EXAMPLES=3000   cases (random exploration instead of the fixed CI sequence)
    OPAL_FUZZ_COLLECT=1       record every failure and keep going (the report lists them all)
    OPAL_FUZZ_REPORT=path     write the counts and failures as JSON there
    OPAL_FUZZ_CASE_SECONDS=60 the per-case time bound (hang detection)
"""

from __future__ import annotations

import json
import math
import os
import signal
import time
import traceback
from collections import Counter
from dataclasses import fields, replace

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings, strategies as st  # noqa: E402

from opal_diffraction.core.scene import primitives  # noqa: E402
from opal_diffraction.core.render.frame import render  # noqa: E402
from opal_diffraction.core.scene.checks import SceneError  # noqa: E402
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene  # noqa: E402
from opal_diffraction.core.scene.validation import validate  # noqa: E402
from opal_diffraction.core.scene.settings import RenderSettings  # noqa: E402

EXAMPLES = int(os.environ.get("OPAL_FUZZ_EXAMPLES", "0") or 0)
CI = EXAMPLES <= 0
MAX_EXAMPLES = 150 if CI else EXAMPLES  # ~20 s on 2 cores
COLLECT = os.environ.get("OPAL_FUZZ_COLLECT", "") not in ("", "0")
REPORT = os.environ.get("OPAL_FUZZ_REPORT", "")
CASE_SECONDS = float(os.environ.get("OPAL_FUZZ_CASE_SECONDS", "60"))

NAN, INF = float("nan"), float("inf")
#: values that have broken renderers: non-finite, float32 overflow and underflow, signs, extremes
SPECIAL = [0.0, -0.0, 5e-324, 1e-45, 1e-38, 1e-30, 1e-20, 1e-12, 1e-9, 1e-6, 1e-3, 0.5, 1.0, 2.0, 1e3, 1e6, 1e9,
           1e12, 1e15, 1e20, 1e25, 1e30, 1e38, 3.4028235e38, 3.5e38, 1e39, 1e300, -1.0, -1e-30, -1e30, -1e39,
           NAN, INF, -INF]
SPECIAL_INTS = [-(2**63), -(2**31) - 1, -(2**31), -1000, -1, 0, 1, 2, 3, 7, 64, 65, 1000, 10**6, 10**7 + 1,
                2**31 - 1, 2**31, 2**63 - 1]


# ----------------------------------------------------------------------------------- strategies
def mostly(valid, weird, percent_valid: int = 85):
    """``valid`` most of the time, otherwise ``weird``."""
    return st.tuples(st.integers(0, 99), valid, weird).map(lambda t: t[1] if t[0] < percent_valid else t[2])


special = st.sampled_from(SPECIAL)
unit = st.floats(0.0, 1.0)


def coord(lo=-5.0, hi=5.0):
    return mostly(st.floats(lo, hi), special, 97)


def vec3(lo=-5.0, hi=5.0):
    return st.tuples(coord(lo, hi), coord(lo, hi), coord(lo, hi))


@st.composite
def meshes(draw):
    """(vertices, triangles) of one primitive at a random place, scale and shape."""
    kind = draw(st.sampled_from(["quad", "box", "ico", "prism", "tri", "uv"]))
    scale = draw(mostly(st.sampled_from([0.3, 1.0, 2.0, 4.0]), st.sampled_from([1e-9, 1e-6, 1e-3, 1e3, 1e6, 1e9])))
    c = draw(vec3(-2, 2))
    if kind == "quad":
        v, t = primitives.quad(c, (scale * 4, 0, 0), draw(st.sampled_from([(0, scale * 4, 0), (0, 0, scale * 4)])))
    elif kind == "box":
        v, t = primitives.box(c, (scale, scale * draw(st.sampled_from([1.0, 0.1, 2.0])), scale))
    elif kind == "ico":
        v, t = primitives.icosphere(c, scale * 0.5, draw(st.integers(0, 1)))
    elif kind == "uv":
        v, t = primitives.uv_sphere(c, scale * 0.5, segments=6, rings=4)
    elif kind == "prism":
        v, t = primitives.prism(c, side=scale, length=scale * 2, axis=draw(st.sampled_from(["X", "Y"])),
                                rotation_deg=draw(st.floats(0, 360)))
    else:  # one random triangle, possibly degenerate or tiny
        pts = draw(st.lists(vec3(), min_size=3, max_size=3))
        v, t = np.array(pts, np.float64) * scale, np.array([[0, 1, 2]])
    return np.asarray(v, np.float64), np.asarray(t, np.int64)


@st.composite
def material_rows(draw):
    kind = draw(st.sampled_from(["DIFFUSE", "DIFFUSE", "MIRROR", "DIELECTRIC"]))
    row = {"kind": kind, "color": draw(st.tuples(unit, unit, unit))}
    if kind == "DIELECTRIC":
        row["ior"] = draw(mostly(st.floats(1.0, 2.5), st.sampled_from([1.0, 4.0, 10.0, 999.0])))
        row["dispersion"] = draw(st.sampled_from(["NONE", "ABBE", "BK7", "FUSED_SILICA", "DIAMOND"]))
        row["abbe"] = draw(mostly(st.floats(10.0, 90.0), st.sampled_from([1.0, 2.0, 1e3, 1e6])))
    if draw(st.integers(0, 9)) == 0:
        row["emission"] = draw(st.tuples(st.floats(0, 5), st.floats(0, 5), st.floats(0, 5)))
    if draw(st.integers(0, 3)) == 0:
        period = draw(mostly(st.floats(200.0, 5000.0), st.sampled_from([1e-3, 1.0, 10.0, 1e5, 1e7])))
        row.update(grating=1, grating_type=draw(st.sampled_from(["REFLECTION", "TRANSMISSION"])),
                   lattice=draw(st.sampled_from(["LINES", "HEXAGONAL"])), period=period,
                   slit_width=period * draw(st.floats(0.01, 1.0)),
                   slit_count=draw(mostly(st.integers(1, 3000), st.sampled_from([1, 2, 64, 65, 10**5, 10**7]))),
                   coherence_length=draw(mostly(st.floats(0.1, 100.0), st.sampled_from([1e-6, 1e3, 1e6]))),
                   grating_direction=draw(st.sampled_from(["UV", "OBJECT_X", "ATTRIBUTE"])),
                   rotation=draw(mostly(st.floats(-7, 7), st.sampled_from([1e3, 1e9, -1e6]))))
    return row


@st.composite
def light_rows(draw):
    kind = draw(st.sampled_from(["POINT", "SPOT", "SUN", "AREA_RECT", "AREA_DISK"]))
    row = {"kind": kind, "position": draw(vec3(-4, 4)), "direction": draw(vec3(-1, 1)),
           "color": draw(st.tuples(st.floats(0, 2), st.floats(0, 2), st.floats(0, 2))),
           "power": draw(mostly(st.floats(0.0, 2000.0), st.sampled_from([0.0, 1e-30, 1e6, 1e12, 1e20, 1e26])))}
    if draw(st.integers(0, 3)) == 0:
        row["temperature"] = draw(mostly(st.floats(1000.0, 12000.0), st.sampled_from([100.0, 500.0, 1e5, 1e9])))
    if kind == "SPOT":
        row["spot_size"] = draw(st.floats(0.0, math.pi))
        row["spot_blend"] = draw(unit)
    if kind.startswith("AREA"):
        row["size_u"] = draw(mostly(st.floats(0.01, 3.0), st.sampled_from([1e-12, 1e-6, 1e3])))
        row["size_v"] = draw(mostly(st.floats(0.01, 3.0), st.sampled_from([1e-12, 1e-6, 1e3])))
        if draw(st.booleans()):
            row["axis_u"] = draw(vec3(-1, 1))
    return row


@st.composite
def cameras(draw):
    eye = draw(st.tuples(st.floats(-8, 8), st.floats(-8, 8), st.floats(0.5, 10)))
    target = draw(st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)))
    kind = draw(st.sampled_from(["PERSP", "PERSP", "ORTHO"]))
    kw = dict(kind=kind, width=draw(st.integers(1, 8)), height=draw(st.integers(1, 8)),
              lens=draw(mostly(st.floats(10.0, 200.0), st.sampled_from([1.0, 1e-3, 1e4]))),
              sensor_fit=draw(st.sampled_from(["AUTO", "HORIZONTAL", "VERTICAL"])),
              ortho_scale=draw(mostly(st.floats(0.5, 20.0), st.sampled_from([1e-6, 1e6]))),
              shift_x=draw(mostly(st.floats(-0.5, 0.5), st.sampled_from([10.0, -100.0]))),
              shift_y=draw(st.floats(-0.5, 0.5)))
    if np.linalg.norm(np.subtract(eye, target)) < 1e-3:
        target = (0.0, 0.0, -1.0)
    return Camera.look_at(eye, target, **kw)


@st.composite
def scenes(draw):
    mats = draw(st.lists(material_rows(), min_size=1, max_size=4))
    s = Scene(materials=Materials.from_list(mats))
    for _ in range(draw(st.integers(0, 4))):
        v, t = draw(meshes())
        tangent = draw(st.sampled_from([None, (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)]))
        period = draw(st.sampled_from([None, 0.0, 500.0]))
        s.add_mesh(v, t, material=draw(st.integers(0, len(mats) - 1)), tangent=tangent, period=period)
    s.lights = Lights.from_list(draw(mostly(st.lists(light_rows(), min_size=1, max_size=6), st.just([]), 90)))
    s.camera = draw(cameras())
    if len(s.lights) and len(s.vertices) and draw(st.integers(0, 5)) == 0:  # a light on the geometry
        i = draw(st.integers(0, len(s.lights) - 1))
        s.lights.position[i] = s.vertices[draw(st.integers(0, len(s.vertices) - 1))]
    if draw(st.integers(0, 3)) == 0:  # the whole scene scaled: the image should not change (scale-free)
        scale = draw(st.sampled_from([1e-9, 1e-6, 1e-3, 1e3, 1e6, 1e9]))
        s.vertices = (s.vertices.astype(np.float64) * scale).astype(np.float32)
        s.lights.position = s.lights.position * scale
        s.lights.size_u, s.lights.size_v = s.lights.size_u * scale, s.lights.size_v * scale
        point_or_area = s.lights.kind != 2
        s.lights.power = np.where(point_or_area, s.lights.power * scale**2, s.lights.power)
        m = s.camera.matrix.copy()
        m[:3, 3] *= scale
        s.camera = replace(s.camera, matrix=m, ortho_scale=s.camera.ortho_scale * scale)
    s.world_color = np.array(draw(st.sampled_from([(0, 0, 0), (0.05, 0.05, 0.05), (1, 1, 1), (0.2, 0.5, 1.0)])),
                             np.float32)
    return s


@st.composite
def render_settings(draw):
    lo = draw(mostly(st.floats(360.0, 500.0), st.sampled_from([360.0, 829.0])))
    step = draw(st.floats(5.0, 60.0))
    hi = draw(st.floats(min(lo + step, 830.0), 830.0))
    return RenderSettings(
        samples=draw(st.integers(1, 2)), light_paths=draw(st.sampled_from([0, 0, 200, 1000, 3000])),
        element_size=draw(mostly(st.just(0.0), st.sampled_from([0.01, 0.3, 1e-6, 1e3]), 80)),
        wavelength_min=lo, wavelength_max=hi, wavelength_step=step,
        max_bounces=draw(st.integers(0, 8)), seed=draw(st.integers(0, 2**32)),
        dispersion_sampling=draw(st.sampled_from(["SPLIT", "SAMPLE"])),
        time_limit=draw(mostly(st.just(0.0), st.sampled_from([1e-9, 0.05]), 90)),
        threads=draw(st.sampled_from([1, 1, 2])), backend=draw(st.sampled_from(["auto", "numpy", "embree", "brute"])),
        tile_size=draw(st.integers(1, 16)), round_samples=draw(st.integers(1, 3)),
        filter_width=draw(st.sampled_from([0.0, 0.5, 1.5, 3.0])),
    )


# ---------------------------------------------------------------------------------- mutations
_MATERIAL_FIELDS = [f.name for f in fields(Materials)]
_LIGHT_FIELDS = [f.name for f in fields(Lights)]
_CAMERA_FIELDS = [f.name for f in fields(Camera)]
_SCENE_ARRAYS = ["vertices", "triangles", "tri_material", "world_color", "tri_tangent", "tri_period"]
_SETTINGS_FIELDS = [f.name for f in fields(RenderSettings)]


def _weird_array(draw, a):
    """A malformed replacement for array ``a``: other shapes, dtypes, or a bad element."""
    try:
        a = np.asarray(a)
    except ValueError:  # an earlier mutation made it ragged
        a = np.zeros(3)
    if a.dtype.kind not in "iufbU" or a.ndim == 0:
        a = np.zeros(a.shape if a.ndim else 3)
    how = draw(st.sampled_from(["element", "element", "element", "shape", "dtype", "empty", "scalar", "ragged"]))
    if how == "element" and a.size:
        b = a.astype(np.float64) if a.dtype.kind in "iub" else a.copy()
        if b.dtype.kind == "U":
            return np.zeros(b.shape)
        idx = draw(st.integers(0, a.size - 1))
        if b.dtype.kind == "f":
            b.reshape(-1)[idx] = draw(special)
        if draw(st.booleans()) and a.dtype.kind in "iu":  # an integer column: an odd integer instead
            b = a.astype(np.int64)
            b.reshape(-1)[idx] = draw(st.sampled_from(SPECIAL_INTS))
        return b
    if how == "shape":
        shape = list(a.shape) or [1]
        axis = draw(st.integers(0, len(shape)))
        if axis == len(shape):
            shape.append(draw(st.integers(1, 3)))
        else:
            shape[axis] = max(0, shape[axis] + draw(st.sampled_from([-1, 1, 2])))
        return np.zeros(shape, a.dtype if a.dtype.kind != "U" else np.float32)
    if how == "dtype":
        kind = draw(st.sampled_from(["bool", "complex", "str", "object", "int", "float16", "bytes"]))
        if kind == "str":
            return a.astype(str)
        if kind == "bytes":
            return a.astype("S8")
        if kind == "object":
            return a.astype(object)
        if a.dtype.kind == "U":
            return np.zeros(a.shape, kind if kind != "int" else np.int64)
        with np.errstate(all="ignore"):
            return a.astype({"bool": bool, "complex": complex, "int": np.int64, "float16": np.float16}[kind])
    if how == "empty":
        return np.zeros((0,) + a.shape[1:], a.dtype)
    if how == "scalar":
        return draw(st.sampled_from([0.0, 1.0, NAN, "x", None]))
    return [[1.0, 2.0], [3.0]]  # ragged


def _weird_scalar(draw, value):
    if isinstance(value, str):
        return draw(st.sampled_from(["", "PERSP ", "persp", "XYZ", 3, None]))
    return draw(st.one_of(special, st.sampled_from(SPECIAL_INTS), st.sampled_from(["8", None, True, 2.5, 1j,
                                                                                   np.array([1, 2])])))


@st.composite
def mutated(draw):
    """(scene, settings, description of the mutations)."""
    s, rs = draw(scenes()), draw(render_settings())
    notes = []
    for _ in range(draw(st.sampled_from([0, 0, 0, 1, 1, 2, 3]))):
        try:
            target = draw(st.sampled_from(["scene", "materials", "lights", "camera", "settings", "table"]))
            if target in ("materials", "lights") and not isinstance(getattr(s, target), (Materials, Lights)):
                continue  # an earlier mutation replaced the table itself
            if target == "scene":
                name = draw(st.sampled_from(_SCENE_ARRAYS))
                setattr(s, name, _weird_array(draw, getattr(s, name)))
            elif target == "materials":
                name = draw(st.sampled_from(_MATERIAL_FIELDS))
                setattr(s.materials, name, _weird_array(draw, getattr(s.materials, name)))
            elif target == "lights":
                if not np.size(s.lights.kind):
                    continue
                name = draw(st.sampled_from(_LIGHT_FIELDS))
                setattr(s.lights, name, _weird_array(draw, getattr(s.lights, name)))
            elif target == "camera":
                if not isinstance(s.camera, Camera):
                    continue
                name = draw(st.sampled_from(_CAMERA_FIELDS))
                val = getattr(s.camera, name)
                if name == "matrix":
                    new = _weird_array(draw, val)
                elif name in ("width", "height"):
                    new = draw(st.sampled_from([0, -1, 1, 65536, 65537, 10**9, 2.0, 2.5, "8", None, True, NAN]))
                else:
                    new = _weird_scalar(draw, val)
                s.camera = replace(s.camera, **{name: new})
            elif target == "table":
                name = draw(st.sampled_from(["no materials", "no lights", "no camera", "many lights", "not a table"]))
                if name == "no materials":
                    s.materials = Materials()
                elif name == "no lights":
                    s.lights = Lights()
                elif name == "no camera":
                    s.camera = None
                elif name == "not a table":
                    setattr(s, draw(st.sampled_from(["materials", "lights", "camera"])),
                            draw(st.sampled_from([None, 3, "x", [1, 2], np.zeros(3)])))
                else:
                    s.lights = Lights.from_list([{"kind": k, "position": (i * 0.3, 0, 2), "power": 10.0}
                                                 for i, k in enumerate(["POINT", "SPOT", "SUN", "AREA_RECT", "AREA_DISK"] * 4)])
            else:
                name = draw(st.sampled_from(_SETTINGS_FIELDS))
                val = getattr(rs, name)
                if name == "backend":
                    new = draw(st.sampled_from(["cuda", "", "NUMPY", " numpy", None, 1]))
                elif name == "dispersion_sampling":
                    new = draw(st.sampled_from(["split", "", None, 0]))
                elif name in ("wavelength_step", "wavelength_min", "wavelength_max"):
                    new = draw(st.one_of(special, st.sampled_from([0.001, 0.075, 0.1, 300.0, 359.0, 831.0, 1.0, "5"])))
                else:
                    new = _weird_scalar(draw, val)
                rs = replace(rs, **{name: new})
        except (TypeError, ValueError, AttributeError, IndexError):
            continue  # the generator itself cannot apply this mutation to an already-broken case
        notes.append(f"{target}.{name}")
    return s, rs, notes


# ---------------------------------------------------------------------------------- the check
class _Hang(BaseException):
    """Raised by the watchdog inside a case that runs too long (BaseException: no except catches it)."""


def _on_alarm(signum, frame):
    raise _Hang()


COUNTS: Counter = Counter()
FAILURES: list[dict] = []


def _scene_summary(s: Scene, rs: RenderSettings, notes) -> str:
    """A compact description of a case, to reproduce it from a report."""
    def arr(a):
        a = np.asarray(a)
        if a.dtype.kind in "iufb" and a.size <= 12:
            return a.tolist()
        return f"<{a.dtype} {a.shape}>"
    parts = [f"mutations={notes}", f"settings={rs!r}"]
    try:
        parts.append(f"vertices={arr(s.vertices)} triangles={arr(s.triangles)}")
        parts.append("materials={" + ", ".join(f"{f}: {arr(getattr(s.materials, f))}" for f in _MATERIAL_FIELDS
                                            if f != "name") + "}")
        parts.append("lights={" + ", ".join(f"{f}: {arr(getattr(s.lights, f))}" for f in _LIGHT_FIELDS) + "}")
        parts.append(f"camera={s.camera!r} world_color={arr(s.world_color)}")
    except Exception as e:  # a malformed table the summary itself cannot show
        parts.append(f"(scene not printable: {e!r})")
    return "\n".join(parts)


def check_case(s: Scene, rs: RenderSettings, notes) -> str:
    """Render one case; returns 'error', 'ok' or raises AssertionError describing the failure."""
    old = signal.signal(signal.SIGALRM, _on_alarm)
    signal.setitimer(signal.ITIMER_REAL, CASE_SECONDS)
    t0 = time.perf_counter()
    try:
        try:
            res = render(s, rs, spectral_film=True)
        except SceneError as e:
            msg = str(e)
            assert msg and "\n" not in msg and "Traceback" not in msg, f"unclean SceneError message {msg!r}"
            return "error"
        except _Hang:
            raise AssertionError(f"hang: still running after {CASE_SECONDS:g} s")
        except Exception as e:
            raise AssertionError(f"uncaught {type(e).__name__}: {e}\n{traceback.format_exc()}") from None
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    dt = time.perf_counter() - t0
    COUNTS["slowest_ms"] = max(COUNTS["slowest_ms"], int(dt * 1000))
    clean = validate(s).scene
    h, w = int(clean.camera.height), int(clean.camera.width)
    n = rs.grid().n
    assert res.spectral.shape == (h, w, n), f"spectral shape {res.spectral.shape} != {(h, w, n)}"
    assert res.rgb.shape == (h, w, 3)
    bad = [name for name, a in [("spectral", res.spectral), ("rgb", res.rgb)] + list(res.passes.items())
           if not np.isfinite(a).all()]
    assert not bad, f"non-finite output in {bad}"
    assert (res.spectral >= 0).all(), f"negative spectral radiance (min {res.spectral.min()})"
    return "ok"


def _record(s, rs, notes):
    COUNTS["cases"] += 1
    try:
        outcome = check_case(s, rs, notes)
    except AssertionError as e:
        text = str(e)
        kind = ("hang" if text.startswith("hang") else "uncaught" if text.startswith("uncaught")
                else "nonfinite" if "non-finite" in text or "negative" in text else "other")
        COUNTS[kind] += 1
        FAILURES.append({"kind": kind, "error": text, "case": _scene_summary(s, rs, notes)})
        if not COLLECT:
            raise AssertionError(text + "\n" + _scene_summary(s, rs, notes)) from None
        return
    COUNTS["scene_errors" if outcome == "error" else "renders"] += 1


@settings(max_examples=MAX_EXAMPLES, deadline=None, derandomize=CI, database=None, print_blob=True,
          suppress_health_check=list(HealthCheck))
@given(case=mutated())
def _fuzz(case):
    s, rs, notes = case
    _record(s, rs, notes)


def test_fuzz_render_input_space():
    COUNTS.clear()
    FAILURES.clear()
    t0 = time.perf_counter()
    try:
        _fuzz()
    finally:
        summary = {k: COUNTS.get(k, 0) for k in ("cases", "scene_errors", "renders", "uncaught", "nonfinite", "hang",
                                                   "other", "slowest_ms")}
        summary["seconds"] = round(time.perf_counter() - t0, 1)
        print("\nfuzz:", json.dumps(summary))
        if REPORT:
            with open(REPORT, "w") as f:
                json.dump({"summary": summary, "failures": FAILURES}, f, indent=1)
    assert not FAILURES, f"{len(FAILURES)} failing case(s); first:\n{FAILURES[0]['error']}\n{FAILURES[0]['case']}"
    # the generator must reach both outcomes, or it tests nothing
    assert COUNTS["renders"] > 0 and COUNTS["scene_errors"] > 0, dict(COUNTS)
