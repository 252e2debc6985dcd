"""Readable errors and the limits of what the tracer computes: SceneError, the renderable limits
(the tracer traces and accumulates in float32) and the checks that name a bad value in one line.

Every check raises SceneError with a one-line message naming the value, the row and the rule, so a
user reads what to fix (never a traceback). Scene validation (validation.py), the builders
(model.py), the scene file (npz.py) and the render settings (settings.py) share them.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SceneError", "FLOAT32_MAX", "COORD_LIMIT", "EMISSION_LIMIT", "MIN_TRIANGLE_AREA", "MAX_SIDE", "MAX_PIXELS",
           "TEMPERATURE_MIN", "TEMPERATURE_MAX", "IOR_MAX", "PERIOD_MAX", "COHERENCE_MAX", "SLIT_COUNT_MAX",
           "FOV_TAN_MAX", "SHIFT_MAX", "DTYPE_WORDS", "number_text", "one_line", "as_number", "as_column", "first_row",
           "within", "check_range"]


class SceneError(ValueError):
    """A scene that cannot be rendered; the message (always one line) names the problem for the user."""

    def __init__(self, message="", *args):
        super().__init__(" ".join(str(message).split()), *args)


# The limits of what the tracer can compute (it traces and accumulates in float32).

#: Largest finite float32 (3.4e38): any value above it becomes inf when the tracer reads it.
FLOAT32_MAX = float(np.finfo(np.float32).max)
#: Positions (vertices, lights, the camera) and lengths stay within this many metres: float32
#: ray-triangle tests multiply three coordinates (differences to the ray origin), which
#: overflows beyond ~1e12 m.
COORD_LIMIT = 1e12
#: Emitted quantities (a light's intensity W/sr, irradiance W/m^2 or radiance W/m^2/sr, an
#: emission or world colour) stay below this, leaving float32 room for spectra, distances and sums.
EMISSION_LIMIT = 1e25
#: Triangles below this area (m^2) cannot be intersected in float32 (their edge products
#: underflow); they are dropped with a warning.
MIN_TRIANGLE_AREA = 1e-30
#: Image size: each side, and the pixel count (checked before anything is allocated).
MAX_SIDE = 65536
MAX_PIXELS = 1 << 28
#: Blackbody temperatures (K); 0 means "no temperature: use the colour". Below 100 K Planck's
#: law underflows on parts of the 360-830 nm observer range.
TEMPERATURE_MIN, TEMPERATURE_MAX = 100.0, 1e9
#: Refractive indices, grating lengths and counts the tracer handles without overflow.
IOR_MAX = 1000.0
PERIOD_MAX = 1e7            # nm (1 cm)
COHERENCE_MAX = 1e6         # um (1 m)
SLIT_COUNT_MAX = 10_000_000
#: Camera: the tangent of the half field of view (persp) at most this, shifts at most this.
FOV_TAN_MAX = 1e6
SHIFT_MAX = 1000.0


def number_text(x) -> str:
    """A number for a message: 3 significant digits."""
    try:
        return f"{float(x):.3g}"
    except (TypeError, ValueError, OverflowError):
        return repr(x)


def one_line(e: BaseException) -> str:
    """An exception's message for a SceneError: its first line, at most 200 characters."""
    text = str(e).strip().splitlines()
    return text[0][:200] if text else type(e).__name__


#: NumPy dtype kinds that are not numbers, in words for a message.
DTYPE_WORDS = {"U": "strings", "S": "bytes", "c": "complex numbers", "b": "booleans", "O": "Python objects",
               "M": "dates", "m": "time spans", "V": "raw records"}


def as_column(value, what: str, tail: tuple = (), rows: int | None = None, kind: str = "float",
            allow_empty: bool = False) -> np.ndarray:
    """``value`` as an array of numbers of shape (rows,) + tail (rows None: any count), or a
    SceneError naming ``what``, the dtype or the shape. kind: 'float' (integers and floats),
    'int' (integers only), 'flag' (integers or booleans). ``allow_empty``: any empty array
    stands for zero rows."""
    try:
        a = np.asarray(value)
    except Exception:  # ragged nested lists, objects numpy cannot hold
        raise SceneError(f"{what} is not a regular array of numbers") from None
    k = a.dtype.kind
    if k not in "iuf" and not (kind == "flag" and k == "b"):
        words = DTYPE_WORDS.get(k, str(a.dtype))
        want = "numbers" if kind == "float" else "integers"
        raise SceneError(f"{what} must hold {want}, got {words} ({a.dtype})")
    if kind != "float" and k == "f":
        raise SceneError(f"{what} must hold integers, got {a.dtype}")
    ok = a.ndim == 1 + len(tail) and a.shape[1:] == tuple(tail) and (rows is None or a.shape[0] == rows)
    if not ok:
        if allow_empty and a.size == 0 and rows in (None, 0):
            return a.reshape((0,) + tuple(tail))
        want = "(" + ", ".join([str(rows) if rows is not None else "N"] + [str(x) for x in tail]) + \
               ("," if not tail else "") + ")"
        raise SceneError(f"{what} must have shape {want}, got {a.shape}")
    if kind != "float" and a.size and k in "iu":
        lo, hi = int(a.min()), int(a.max())
        if lo < -(2**31) or hi >= 2**31:
            raise SceneError(f"{what} holds {hi if hi >= 2**31 else lo}, outside the 32-bit integer range")
    return a


def first_row(mask: np.ndarray) -> int:
    """The first row of ``mask`` (rows, ...) with any True."""
    m = mask.reshape(len(mask), -1).any(axis=1) if mask.ndim > 1 else mask
    return int(np.argmax(m))


def within(a, limit: float | None = None, nonneg: bool = False) -> bool:
    """True when every value of ``a`` (any real dtype) is finite, within float32 and ``limit``
    (and >= 0 with ``nonneg``): two reductions and no float64 copy (a NaN propagates through
    min and max). False: the caller's full check finds and names the first bad row."""
    a = np.asarray(a)
    if a.size == 0:
        return True
    lo, hi = float(np.min(a)), float(np.max(a))
    mag = max(-lo, hi)
    return bool(np.isfinite(lo) and np.isfinite(hi) and mag <= FLOAT32_MAX and (limit is None or mag <= limit)
                and (not nonneg or lo >= 0))


def check_range(a64: np.ndarray, label, name: str, unit: str, limit: float | None = None,
                 finite_text: str | None = None, nonneg: bool = False) -> None:
    """Finite, within float32, |x| <= limit (and >= 0 with ``nonneg``), per row; ``label(i)``
    names row i ("light 2"). Empty arrays pass."""
    if a64.size == 0 or within(a64, limit, nonneg):
        return
    a64 = np.asarray(a64, np.float64)
    bad = ~np.isfinite(a64)
    if bad.any():
        i = first_row(bad)
        if finite_text:
            raise SceneError(finite_text)
        raise SceneError(f"{label(i)}: {name} is NaN or infinite")
    mag = np.abs(a64)
    over = mag > FLOAT32_MAX
    if over.any():
        i = first_row(over)
        raise SceneError(f"{label(i)}: {name} {number_text(np.max(mag.reshape(len(mag), -1)[i]))}{unit} overflows float32 "
                         f"(max 3.4e38)")
    if limit is not None:
        big = mag > limit
        if big.any():
            i = first_row(big)
            raise SceneError(f"{label(i)}: {name} {number_text(np.max(mag.reshape(len(mag), -1)[i]))}{unit} is beyond "
                             f"the renderable limit {limit:g}{unit}")
    if nonneg and (a64 < 0).any():
        i = first_row(a64 < 0)
        raise SceneError(f"{label(i)}: {name} must be >= 0, got {number_text(np.min(a64.reshape(len(a64), -1)[i]))}{unit}")


def as_number(value, what: str, integer: bool = False):
    """A scalar setting as a Python int/float, or a SceneError (strings, complex, bool, arrays)."""
    if isinstance(value, (bool, np.bool_)) or isinstance(value, (str, bytes, complex, np.complexfloating)):
        raise SceneError(f"{what} must be a number, got {value!r}")
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()
        if isinstance(value, (bool, str, bytes, complex)):
            raise SceneError(f"{what} must be a number, got {value!r}")
    if not isinstance(value, (int, float, np.integer, np.floating)):
        raise SceneError(f"{what} must be a number, got {type(value).__name__}")
    if integer:
        if isinstance(value, (int, np.integer)):
            return int(value)
        f = float(value)
        if not np.isfinite(f) or f != int(f):
            raise SceneError(f"{what} must be a whole number, got {number_text(f)}")
        return int(f)
    f = float(value)
    if not np.isfinite(f):
        raise SceneError(f"{what} must be a finite number, got {f}")
    return f
