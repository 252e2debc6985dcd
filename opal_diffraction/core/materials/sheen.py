"""Principled's sheen: Zeltner, Burley & Chiang's microfiber sheen as a linearly transformed cosine (docs/physics.md section 14.10).

The method of Zeltner, Burley & Chiang 2022 ("Practical Multiple-Scattering Sheen Using Linearly
Transformed Cosines"), as Cycles renders it (``intern/cycles/kernel/closure/bsdf_sheen.h``; the
math ported, not the code): in the frame whose x axis is wo's tangential direction (Cycles'
``make_orthonormals_tangent(N, wi)``), a light direction w = (x, y, z) has

    f cos = z a^2 / (pi L^2),   L = (a x + b z)^2 + (a y)^2 + z^2,

the clamped cosine pulled back through the inverse transform [[a, 0, b], [0, a, 0], [0, 0, 1]]
(a density over the sphere, so it is also its own sampling pdf), and the lobe's weight is the
fitted directional albedo R. a, b and R come from the paper's 32 x 32 table over (sheen
roughness, cos theta_o) (core/materials/sheen_ltc_table.py), read bilinearly as Cycles'
``lookup_table_read_2D`` reads it, the roughness clamped to [1e-3, 1]. Sampling maps a uniform
disk point lifted to the cosine hemisphere, (d_x, d_y, d_z), through the transform:
w = normalize((d_x - d_z b) / a, d_y / a, d_z).

Everything is float32 NumPy over a batch of local directions; no compiled twin (bsdf.py sends
batches holding the SHEEN lobe through its NumPy lines, as it does OREN_NAYAR).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["ltc_coefficients", "sheen_eval", "sheen_sample"]

_F32 = np.float32
_N = 32


@lru_cache(maxsize=None)
def _table() -> np.ndarray:
    """(3, 32, 32) float32: a, b, albedo over (roughness row, cos column)."""
    from .sheen_ltc_table import A, ALBEDO, B

    return np.asarray([A, B, ALBEDO], _F32).reshape(3, _N, _N)


def _read1(rows, x):
    """Cycles' lookup_table_read along the last axis of ``rows`` (B, 32) at x in [0, 1] (B,)."""
    f = np.clip(x, 0.0, 1.0) * _F32(_N - 1)
    i = np.minimum(f.astype(np.int64), _N - 1)
    j = np.minimum(i + 1, _N - 1)
    t = (f - i).astype(_F32)
    b = np.arange(len(i))
    return (_F32(1) - t) * rows[b, i] + t * rows[b, j]


def ltc_coefficients(cos_o, roughness) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(a, b, albedo) (B,) float32 at cos theta_o and the sheen roughness (B,): the table read as
    ``lookup_table_read_2D(cos, roughness)`` reads it (module docstring)."""
    cos_o = np.asarray(cos_o, _F32)
    r = np.clip(np.asarray(roughness, _F32), _F32(1e-3), _F32(1))
    f = r * _F32(_N - 1)
    i = np.minimum(f.astype(np.int64), _N - 1)
    j = np.minimum(i + 1, _N - 1)
    t = (f - i).astype(_F32)
    tab = _table()
    out = []
    for plane in tab:
        lo, hi = _read1(plane[i], cos_o), _read1(plane[j], cos_o)
        out.append(((_F32(1) - t) * lo + t * hi).astype(_F32))
    return tuple(out)


def _azimuth(wo):
    """(cos, sin) (B,) of wo's azimuth in the local frame (1, 0 at normal incidence)."""
    s = np.sqrt(wo[:, 0] * wo[:, 0] + wo[:, 1] * wo[:, 1])
    ok = s > _F32(1e-7)
    safe = np.where(ok, s, _F32(1))
    return np.where(ok, wo[:, 0] / safe, _F32(1)), np.where(ok, wo[:, 1] / safe, _F32(0))


def _density(a, b, x, y, z):
    """The LTC's f cos (= pdf) at local (x, y, z) of wo's frame; 0 at or below the horizon."""
    lensq = (a * x + b * z) ** 2 + (a * y) ** 2 + z * z
    with np.errstate(divide="ignore", invalid="ignore"):
        val = z * (a / lensq) ** 2 * _F32(1.0 / np.pi)
    return np.where((z > 0) & (a > 0) & np.isfinite(val), val, _F32(0)).astype(_F32)


def sheen_eval(wo, wi, roughness) -> tuple[np.ndarray, np.ndarray]:
    """(f cos, pdf) (B,) of the unit-albedo sheen lobe for local wo, wi (B, 3) (wo.z > 0) and the
    sheen roughness (B,); the caller weighs f cos by ``ltc_coefficients``' albedo."""
    wo, wi = np.asarray(wo, _F32), np.asarray(wi, _F32)
    a, b, _ = ltc_coefficients(wo[:, 2], roughness)
    c, s = _azimuth(wo)
    x = wi[:, 0] * c + wi[:, 1] * s
    y = wi[:, 1] * c - wi[:, 0] * s
    val = _density(a, b, x, y, wi[:, 2])
    return val, val


def sheen_sample(wo, roughness, u1, u2) -> tuple[np.ndarray, np.ndarray]:
    """(local wi (B, 3), pdf (B,)) drawn from the unit-albedo sheen lobe for local wo (B, 3) with
    uniforms u1, u2 (B,): a uniform disk point (polar map), lifted and transformed (module
    docstring); pdf 0 where the lobe is empty (a = 0)."""
    wo = np.asarray(wo, _F32)
    a, b, _ = ltc_coefficients(wo[:, 2], roughness)
    r = np.sqrt(np.asarray(u1, _F32))
    phi = _F32(2 * np.pi) * np.asarray(u2, _F32)
    dx, dy = r * np.cos(phi), r * np.sin(phi)
    dz = np.sqrt(np.maximum(_F32(1) - dx * dx - dy * dy, _F32(0)))
    safe_a = np.where(a > 0, a, _F32(1))
    x, y, z = (dx - dz * b) / safe_a, dy / safe_a, dz
    n = np.sqrt(x * x + y * y + z * z)
    x, y, z = x / n, y / n, z / n
    c, s = _azimuth(wo)
    wi = np.stack([x * c - y * s, x * s + y * c, z], axis=1).astype(_F32)
    pdf = np.where(a > 0, _density(a, b, x, y, z), _F32(0))
    return wi, pdf.astype(_F32)
