"""Rectangular area lights sampled by solid angle: Urena, Fajardo & King 2013, "An
Area-Preserving Parametrization for Spherical Rectangles" (EGSR 2013), the sampler Cycles uses
for rectangle lights (intern/cycles/kernel/light/area.h, ``area_light_rect_sample``).

A rectangle seen from a point o projects onto a spherical rectangle of solid angle S; the map
(u, v) in [0, 1)^2 -> a point on the rectangle is area-preserving on the sphere, so the sampled
directions are uniform in solid angle (pdf 1 / S): no 1 / distance^2 or light-cosine variation
is left in the estimate (docs/physics.md section 7.10). Everything is computed in float64 (the
solid angle is a difference of angles near 2 pi), per point, vectorised.

In the rectangle's frame (x, y its unit edges, z their normal turned away from o) with o at the
origin, the corner nearest (x0, y0) and x1 = x0 + |x edge|, y1 = y0 + |y edge|, z0 < 0:
the four edge-plane normals n0 .. n3, the interior angles g_i = acos(-n_i . n_(i+1)), and
S = g0 + g1 + g2 + g3 - 2 pi. Sampling: au = u S + 2 pi - g2 - g3, fu = (cos(au) b0 - b1) /
sin(au) with b0 = n0.z, b1 = n2.z; cu = sign(fu) / sqrt(fu^2 + b0^2); xu = -cu z0 / sqrt(1 -
cu^2) (clamped to [x0, x1]); then y along the edge by h0 = y0 / sqrt(d^2 + y0^2), h1 = y1 /
sqrt(d^2 + y1^2), hv = h0 + v (h1 - h0), yv = hv d / sqrt(1 - hv^2), d = sqrt(xu^2 + z0^2).
"""

from __future__ import annotations


import numpy as np

__all__ = ["RectFrame", "solid_angle", "sample"]

#: Below this solid angle (sr) the spherical-rectangle map loses precision: callers sample the
#: rectangle's area there instead (a choice that depends on the shading point only).
MIN_SOLID_ANGLE = 1e-9


class RectFrame:
    """A rectangle of centre ``c``, unit edge directions ``ex``, ``ey`` and side lengths ``lx``,
    ``ly`` (all float64)."""

    def __init__(self, c, ex, ey, lx: float, ly: float):
        self.ex = np.asarray(ex, np.float64)
        self.ey = np.asarray(ey, np.float64)
        self.lx, self.ly = float(lx), float(ly)
        self.corner = np.asarray(c, np.float64) - 0.5 * self.lx * self.ex - 0.5 * self.ly * self.ey
        self.ez = np.cross(self.ex, self.ey)


def _setup(rect: RectFrame, o: np.ndarray):
    """Per point: (x0, x1, y0, y1, z0, z sign, b0, b1, k, S)."""
    d = rect.corner - np.asarray(o, np.float64)
    x0, y0 = d @ rect.ex, d @ rect.ey
    z0 = d @ rect.ez
    zs = np.where(z0 > 0, -1.0, 1.0)  # z turned away from o: z0 <= 0
    z0 = z0 * zs
    x1, y1 = x0 + rect.lx, y0 + rect.ly
    # The edge planes' unit normals n0 = (0, z0, -y0) / ry0, n1 = (-z0, 0, x1) / rx1,
    # n2 = (0, -z0, y1) / ry1, n3 = (z0, 0, -x0) / rx0 (cross products of neighbouring corner
    # vectors), so their dot products and z components reduce to these four lengths.
    zz = z0 * z0
    rx0, rx1, ry0, ry1 = np.sqrt(zz + x0 * x0), np.sqrt(zz + x1 * x1), np.sqrt(zz + y0 * y0), np.sqrt(zz + y1 * y1)
    with np.errstate(divide="ignore", invalid="ignore"):
        g0 = np.arccos(np.clip(y0 * x1 / (ry0 * rx1), -1.0, 1.0))    # acos(-n0 . n1)
        g1 = np.arccos(np.clip(-x1 * y1 / (rx1 * ry1), -1.0, 1.0))   # acos(-n1 . n2)
        g2 = np.arccos(np.clip(x0 * y1 / (ry1 * rx0), -1.0, 1.0))    # acos(-n2 . n3)
        g3 = np.arccos(np.clip(-x0 * y0 / (rx0 * ry0), -1.0, 1.0))   # acos(-n3 . n0)
        b0, b1 = -y0 / ry0, y1 / ry1                                 # n0.z, n2.z
    k = 2 * np.pi - g2 - g3
    s = g0 + g1 - k
    s = np.where(np.isfinite(s) & (z0 < 0), np.maximum(s, 0.0), 0.0)  # o in the light's plane: nothing seen
    return x0, x1, y0, y1, z0, zs, b0, b1, k, s


def solid_angle(rect: RectFrame, o: np.ndarray) -> np.ndarray:
    """(B,) the solid angle the rectangle subtends at the points ``o`` (B, 3)."""
    return _setup(rect, o)[-1]


def sample(rect: RectFrame, o: np.ndarray, u: np.ndarray, v: np.ndarray):
    """Points on the rectangle (B, 3) float64 uniform in the solid angle seen from ``o``, for the
    numbers ``u``, ``v`` (B,) in [0, 1); and that solid angle S (B,) (the pdf is 1 / S)."""
    x0, x1, y0, y1, z0, zs, b0, b1, k, s = _setup(rect, o)
    u = np.asarray(u, np.float64)
    v = np.asarray(v, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        au = u * s + k
        fu = (np.cos(au) * b0 - b1) / np.sin(au)
        cu = np.clip(np.where(fu > 0, 1.0, -1.0) / np.sqrt(fu * fu + b0 * b0), -1.0, 1.0)
        xu = np.clip(-(cu * z0) / np.sqrt(np.maximum(1.0 - cu * cu, 1e-300)), x0, x1)
        d = np.sqrt(xu * xu + z0 * z0)
        h0 = y0 / np.sqrt(d * d + y0 * y0)
        h1 = y1 / np.sqrt(d * d + y1 * y1)
        hv = h0 + v * (h1 - h0)
        hv2 = hv * hv
        yv = np.where(hv2 < 1 - 1e-12, hv * d / np.sqrt(np.maximum(1 - hv2, 1e-300)), y1)
    xu = np.where(np.isfinite(xu), xu, x0)
    yv = np.clip(np.where(np.isfinite(yv), yv, y0), y0, y1)
    # back to world space: o + xu x + yv y + z0 z (z0 measured along the turned z)
    pts = (np.asarray(o, np.float64) + xu[:, None] * rect.ex + yv[:, None] * rect.ey
           + (z0 * zs)[:, None] * rect.ez)
    return pts, s


def _frame_of(pl, index: int) -> RectFrame:
    return RectFrame(pl.position[index], pl.axis_u[index], pl.axis_v[index], pl.size_u[index], pl.size_v[index])


def sample_light_rect(pl, index: int, p: np.ndarray, r1: np.ndarray, r2: np.ndarray):
    """lights.sample_light for the rectangle light ``index`` of the prepared lights ``pl``: (wi
    (B, 3) float32, distance (B,), g (B,)) with g = S, the solid angle (radiance / spectrum over
    the pdf 1 / S), 0 behind the one-sided light; where S < MIN_SOLID_ANGLE a uniform point on
    the area, g = cos_l A / d^2, as before."""
    f32 = np.float32
    rect = _frame_of(pl, index)
    p64 = np.asarray(p, np.float64)
    target, s = sample(rect, p64, r1, r2)
    tiny = s < MIN_SOLID_ANGLE
    if tiny.any():
        a, c = (np.asarray(r1, np.float64) - 0.5) * rect.lx, (np.asarray(r2, np.float64) - 0.5) * rect.ly
        flat = pl.position[index] + a[:, None] * rect.ex + c[:, None] * rect.ey
        target = np.where(tiny[:, None], flat, target)
    to_light = target - p64
    d2 = np.maximum(np.einsum("ij,ij->i", to_light, to_light), 1e-30)
    dist = np.sqrt(d2)
    wi = to_light / dist[:, None]
    cos_l = -(wi @ np.asarray(pl.direction[index], np.float64))
    g = np.where(cos_l > 0, np.where(tiny, cos_l * float(pl.area[index]) / d2, s), 0.0)
    wi32 = wi.astype(f32)
    return wi32, dist.astype(f32), g.astype(f32)


def pdf_light_rect(pl, index: int, p: np.ndarray, hit: np.ndarray, t: np.ndarray, cos_l: np.ndarray) -> np.ndarray:
    """(B,) float64 solid-angle pdf of ``sample_light_rect`` for directions that reach the light's
    front at distance ``t`` with cosine ``cos_l`` (``hit``), 0 elsewhere."""
    s = solid_angle(_frame_of(pl, index), np.asarray(p, np.float64))
    tiny = s < MIN_SOLID_ANGLE
    with np.errstate(divide="ignore", invalid="ignore"):
        pdf = np.where(tiny, t * t / (float(pl.area[index]) * cos_l), 1.0 / s)
    return np.where(hit, pdf, 0.0)
