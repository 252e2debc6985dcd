"""Preview colours of a grating field for Blender's Solid mode: hue = the direction's angle about the
normal (an axis: 0 and 180 degrees share a hue), brightness = the period."""

from __future__ import annotations

import numpy as np

from .editing import direction_angle

__all__ = [
    "preview_colors",
]


def _hsv_to_rgb(h, s, v):
    h = np.mod(np.asarray(h, np.float64), 1.0) * 6.0
    i = np.floor(h).astype(np.int64) % 6
    f = h - np.floor(h)
    s, v = np.broadcast_to(s, h.shape), np.broadcast_to(v, h.shape)
    p, q, t = v * (1 - s), v * (1 - s * f), v * (1 - s * (1 - f))
    table = np.stack([np.stack(c, -1) for c in ((v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v), (v, p, q))])
    return table[i, np.arange(len(h))]


def preview_colors(direction, normals, period, period_range=None, reference=(1.0, 0.0, 0.0)) -> np.ndarray:
    """RGBA (F, 4) float32 in [0, 1]: hue = the direction's angle about the normal (an axis, so
    0 and 180 degrees share a hue), brightness = the period (darkest at the low end of
    ``period_range``, default the periods' own range). Faces without a period (0) are grey."""
    ang = direction_angle(direction, normals, reference)
    p = np.asarray(period, np.float64).reshape(-1)
    valid = p > 0
    if period_range is None:
        lo, hi = (p[valid].min(), p[valid].max()) if valid.any() else (0.0, 1.0)
    else:
        lo, hi = period_range
    x = np.clip((p - lo) / (hi - lo), 0.0, 1.0) if hi > lo else np.full_like(p, 0.5)
    rgb = _hsv_to_rgb(ang / np.pi, 0.85, 0.3 + 0.7 * x)
    rgb[~valid] = 0.5
    out = np.ones((len(p), 4), np.float32)
    out[:, :3] = rgb
    return out
