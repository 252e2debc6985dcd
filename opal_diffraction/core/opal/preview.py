"""Preview colours for Blender's Solid mode.

Surface gratings (:func:`preview_colors`): hue = the direction's angle about the normal (an axis:
0 and 180 degrees share a hue), brightness = the period.

Volume (BRAGG) domains (:func:`bragg_colors`): each domain's Bragg colour at normal incidence on
its (111) planes, lambda = 2 d111 n_eff (Sanders 1964; docs/physics.md section 5.2), as a band of
relative width (4/pi) |n_s - n_void| / (n_s + n_void) (the stop band of a quarter-wave stack:
Macleod, *Thin-Film Optical Filters*, chapter 6 - an estimate, the transfer-matrix band is
the renderer's) under D65, through the project's spectral converter (core/spectral/spectrum.py: CIE 1931
observer, linear Rec.709), out-of-gamut parts clipped and scaled to a brightest channel of 1."""

from __future__ import annotations

import numpy as np

from .bragg import N_SILICA, N_VOID, period_from_sphere_diameter
from .editing import direction_angle

__all__ = [
    "preview_colors",
    "bragg_band_width",
    "bragg_colors",
]

_CONVERTER = []  # one SpectralConverter on a 380-780 nm, 5 nm grid, made on first use


def bragg_band_width(n_sphere: float = N_SILICA, n_void: float = N_VOID) -> float:
    """Relative width (FWHM / lambda) of the reflected band: (4/pi) |n_s - n_v| / (n_s + n_v), at least 1 %."""
    return max(4.0 / np.pi * abs(n_sphere - n_void) / (n_sphere + n_void), 0.01)


def bragg_colors(diameter, n_sphere: float = N_SILICA, n_void: float = N_VOID) -> np.ndarray:
    """RGBA (N, 4) float32 linear Rec.709: the Bragg colour at normal incidence of spheres of
    ``diameter`` (N,) nm (0 or less: grey)."""
    from ..spectral.spectrum import SpectralConverter, WavelengthGrid

    if not _CONVERTER:
        _CONVERTER.append(SpectralConverter(WavelengthGrid(380.0, 780.0, 5.0)))
    conv = _CONVERTER[0]
    d = np.asarray(diameter, np.float64).reshape(-1)
    lam = period_from_sphere_diameter(np.maximum(d, 1.0), n_sphere, n_void)
    sigma = bragg_band_width(n_sphere, n_void) * lam / 2.3548
    wl = conv.grid.wavelengths
    band = np.exp(-0.5 * ((wl[None, :] - lam[:, None]) / sigma[:, None]) ** 2)
    rgb = np.clip(conv.to_rgb(band * conv.white_illuminant[None, :]).astype(np.float64), 0.0, None)
    peak = rgb.max(axis=1, keepdims=True)
    rgb = np.where(peak > 0, rgb / np.where(peak > 0, peak, 1.0), 0.0)
    rgb[d <= 0] = 0.5
    out = np.ones((len(d), 4), np.float32)
    out[:, :3] = rgb
    return out


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
