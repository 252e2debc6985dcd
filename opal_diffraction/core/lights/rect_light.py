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

Where the kernels run (core/util/jit.py), ``sample_light_rect`` (the frame, the sample, the
direction, distance and g, and sample_light_pdf's pdf 1 / g) and ``solid_angle`` take two compiled
passes per call instead of NumPy's chain of (B,) temporaries: ``_args_kernel`` forms the four
interior angles' cosines (B, 4), NumPy's ``arccos`` turns them into angles (one call: NumPy's
float64 arccos is not the C library's where NumPy has SIMD (SVML) for it, a few ulps apart, so
the kernels leave it to NumPy), and ``_sample_kernel`` / ``_solid_angle_kernel`` do the rest per
point. They do the NumPy lines' float64 operations in their order, so they give the same bits
(tests/lights/test_rect_light_kernels.py); the dot products are written out (``dot3``) in both,
since a BLAS matmul's or einsum's order and FMA use are the library's and the CPU's.
core/lights/sources.py's light kernels use the same row functions for a rectangle's solid angle
(its pdf for MIS).
"""

from __future__ import annotations


import numpy as np

from ..util.jit import kernels_enabled, njit

__all__ = ["RectFrame", "solid_angle", "sample", "sample_light_rect", "pdf_light_rect", "MIN_SOLID_ANGLE", "dot3", "angles"]

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


def dot3(a: np.ndarray, v) -> np.ndarray:
    """(B,) a . v for a (B, 3) and v (3,) or (B, 3): the three products summed in order (the kernels' sum)."""
    v = np.asarray(v)
    if v.ndim == 1:
        return a[:, 0] * v[0] + a[:, 1] * v[1] + a[:, 2] * v[2]
    return a[:, 0] * v[:, 0] + a[:, 1] * v[:, 1] + a[:, 2] * v[:, 2]


def _setup(rect: RectFrame, o: np.ndarray):
    """Per point: (x0, x1, y0, y1, z0, z sign, b0, b1, k, S)."""
    d = rect.corner - np.asarray(o, np.float64)
    x0, y0 = dot3(d, rect.ex), dot3(d, rect.ey)
    z0 = dot3(d, rect.ez)
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
    if kernels_enabled() and _fits(o):
        o = np.ascontiguousarray(o)
        g = angles(rect.corner, rect.ex, rect.ey, rect.ez, rect.lx, rect.ly, o)
        s = np.empty(len(o), np.float64)
        _solid_angle_kernel(rect.corner, rect.ex, rect.ey, rect.ez, rect.lx, rect.ly, o, g, s)
        return s
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
    """The frame of rectangle light ``index``, made once per prepared lights (kept on them, for
    the arrays it was made from: the prepared lights are not changed in place)."""
    refs = (pl.position, pl.axis_u, pl.axis_v, pl.size_u, pl.size_v)
    cache = getattr(pl, "__dict__", {}).setdefault("_rect_frames", {})
    hit = cache.get(index)
    if hit is not None and all(a is b for a, b in zip(hit[0], refs)):
        return hit[1]
    frame = RectFrame(pl.position[index], pl.axis_u[index], pl.axis_v[index], pl.size_u[index], pl.size_v[index])
    cache[index] = (refs, frame)
    return frame


def _fits(p) -> bool:
    """Points the kernels take: (B, 3) float32 / float64."""
    return isinstance(p, np.ndarray) and p.ndim == 2 and p.shape[1] == 3 and p.dtype.char in "fd"


def sample_light_rect(pl, index: int, p: np.ndarray, r1: np.ndarray, r2: np.ndarray, with_pdf: bool = False):
    """lights.sample_light for the rectangle light ``index`` of the prepared lights ``pl``: (wi
    (B, 3) float32, distance (B,), g (B,)) with g = S, the solid angle (radiance / spectrum over
    the pdf 1 / S), 0 behind the one-sided light; where S < MIN_SOLID_ANGLE a uniform point on
    the area, g = cos_l A / d^2, as before. ``with_pdf``: and sample_light_pdf's pdf (B,)
    float32, 1 / g where g > 0, else 0."""
    f32 = np.float32
    rect = _frame_of(pl, index)
    if kernels_enabled() and _fits(p) and np.ndim(r1) == 1 and np.ndim(r2) == 1:
        p = np.ascontiguousarray(p)
        b = len(p)
        g_ang = angles(rect.corner, rect.ex, rect.ey, rect.ez, rect.lx, rect.ly, p)
        wi, dist, g = np.empty((b, 3), f32), np.empty(b, f32), np.empty(b, f32)
        pdf = np.empty(b if with_pdf else 0, f32)
        _sample_kernel(rect.corner, rect.ex, rect.ey, rect.ez, rect.lx, rect.ly,
                       np.asarray(pl.position[index], np.float64), np.asarray(pl.direction[index], np.float64),
                       float(pl.area[index]), p, np.ascontiguousarray(r1), np.ascontiguousarray(r2), g_ang,
                       wi, dist, g, pdf)
        return (wi, dist, g, pdf) if with_pdf else (wi, dist, g)
    p64 = np.asarray(p, np.float64)
    target, s = sample(rect, p64, r1, r2)
    tiny = s < MIN_SOLID_ANGLE
    if tiny.any():
        a, c = (np.asarray(r1, np.float64) - 0.5) * rect.lx, (np.asarray(r2, np.float64) - 0.5) * rect.ly
        flat = pl.position[index] + a[:, None] * rect.ex + c[:, None] * rect.ey
        target = np.where(tiny[:, None], flat, target)
    to_light = target - p64
    d2 = np.maximum(dot3(to_light, to_light), 1e-30)
    dist = np.sqrt(d2)
    wi = to_light / dist[:, None]
    cos_l = -dot3(wi, np.asarray(pl.direction[index], np.float64))
    g = np.where(cos_l > 0, np.where(tiny, cos_l * float(pl.area[index]) / d2, s), 0.0)
    wi32, g32 = wi.astype(f32), g.astype(f32)
    if not with_pdf:
        return wi32, dist.astype(f32), g32
    with np.errstate(divide="ignore"):
        pdf = np.where(g32 > 0, f32(1.0) / g32, f32(0.0)).astype(f32)
    return wi32, dist.astype(f32), g32, pdf


def pdf_light_rect(pl, index: int, p: np.ndarray, hit: np.ndarray, t: np.ndarray, cos_l: np.ndarray) -> np.ndarray:
    """(B,) float64 solid-angle pdf of ``sample_light_rect`` for directions that reach the light's
    front at distance ``t`` with cosine ``cos_l`` (``hit``), 0 elsewhere."""
    s = solid_angle(_frame_of(pl, index), np.asarray(p, np.float64))
    tiny = s < MIN_SOLID_ANGLE
    with np.errstate(divide="ignore", invalid="ignore"):
        pdf = np.where(tiny, t * t / (float(pl.area[index]) * cos_l), 1.0 / s)
    return np.where(hit, pdf, 0.0)


# ------------------------------------------------------------------------------ kernels
# The NumPy lines above per point, in their float64 operations and order (no fastmath): np.clip,
# np.maximum and np.where written out with NumPy's NaN rules (``np_clip``, ``np_maximum``).


@njit
def np_clip(x, lo, hi):
    """np.clip(x, lo, hi) of floats: min(max(x, lo), hi), a NaN x stays NaN."""
    if x != x:
        return x
    x = x if x > lo else lo
    if x != x:
        return x
    return x if x < hi else hi


@njit
def np_maximum(x, lo):
    """np.maximum(x, lo) for a number lo: a NaN x stays NaN."""
    return x if (x >= lo or x != x) else lo


@njit
def frame_row(corner, ex, ey, ez, lx, ly, px, py, pz):
    """_setup's frame of one point: (x0, x1, y0, y1, z0, z sign, rx0, rx1, ry0, ry1)."""
    dx, dy, dz = corner[0] - px, corner[1] - py, corner[2] - pz
    x0 = dx * ex[0] + dy * ex[1] + dz * ex[2]
    y0 = dx * ey[0] + dy * ey[1] + dz * ey[2]
    z0 = dx * ez[0] + dy * ez[1] + dz * ez[2]
    zs = -1.0 if z0 > 0 else 1.0
    z0 = z0 * zs
    x1, y1 = x0 + lx, y0 + ly
    zz = z0 * z0
    return x0, x1, y0, y1, z0, zs, np.sqrt(zz + x0 * x0), np.sqrt(zz + x1 * x1), np.sqrt(zz + y0 * y0), \
        np.sqrt(zz + y1 * y1)


@njit
def cosines_row(corner, ex, ey, ez, lx, ly, px, py, pz, out, i):
    """The four interior angles' cosines of _setup (clipped to [-1, 1]) of one point into out[i]."""
    x0, x1, y0, y1, z0, zs, rx0, rx1, ry0, ry1 = frame_row(corner, ex, ey, ez, lx, ly, px, py, pz)
    out[i, 0] = np_clip(y0 * x1 / (ry0 * rx1), -1.0, 1.0)
    out[i, 1] = np_clip(-x1 * y1 / (rx1 * ry1), -1.0, 1.0)
    out[i, 2] = np_clip(x0 * y1 / (ry1 * rx0), -1.0, 1.0)
    out[i, 3] = np_clip(-x0 * y0 / (rx0 * ry0), -1.0, 1.0)


@njit
def solid_angle_row(g0, g1, g2, g3, z0):
    """(k, S) of _setup from the four interior angles."""
    k = 2 * np.pi - g2 - g3
    s = g0 + g1 - k
    if np.isfinite(s) and z0 < 0:
        return k, (s if s >= 0.0 else 0.0)
    return k, 0.0


@njit
def _args_kernel(corner, ex, ey, ez, lx, ly, p, out):
    for i in range(p.shape[0]):
        cosines_row(corner, ex, ey, ez, lx, ly, np.float64(p[i, 0]), np.float64(p[i, 1]), np.float64(p[i, 2]),
                    out, i)


def angles(corner, ex, ey, ez, lx, ly, p) -> np.ndarray:
    """(B, 4) float64 the interior angles g0 .. g3 of the spherical rectangle seen from p (B, 3):
    the cosines by ``_args_kernel``, the arccos by NumPy (in place)."""
    g = np.empty((len(p), 4), np.float64)
    _args_kernel(corner, ex, ey, ez, float(lx), float(ly), p, g)
    with np.errstate(invalid="ignore"):
        return np.arccos(g, out=g)


@njit
def _solid_angle_kernel(corner, ex, ey, ez, lx, ly, p, g, s):
    for i in range(p.shape[0]):
        z0 = frame_row(corner, ex, ey, ez, lx, ly, np.float64(p[i, 0]), np.float64(p[i, 1]), np.float64(p[i, 2]))[4]
        s[i] = solid_angle_row(g[i, 0], g[i, 1], g[i, 2], g[i, 3], z0)[1]


@njit
def _sample_kernel(corner, ex, ey, ez, lx, ly, pos, nrm, area, p, r1, r2, g_ang, wi, dist, g, pdf):
    """sample_light_rect per point (sample's map, the area fallback below MIN_SOLID_ANGLE, the
    direction, distance and g; pdf 1 / g when ``pdf`` has rows), from the angles ``g_ang``."""
    want_pdf = pdf.shape[0] > 0
    f32 = np.float32
    for i in range(p.shape[0]):
        px, py, pz = np.float64(p[i, 0]), np.float64(p[i, 1]), np.float64(p[i, 2])
        x0, x1, y0, y1, z0, zs, rx0, rx1, ry0, ry1 = frame_row(corner, ex, ey, ez, lx, ly, px, py, pz)
        b0, b1 = -y0 / ry0, y1 / ry1
        k, s = solid_angle_row(g_ang[i, 0], g_ang[i, 1], g_ang[i, 2], g_ang[i, 3], z0)
        u, v = np.float64(r1[i]), np.float64(r2[i])
        if s < MIN_SOLID_ANGLE:  # a uniform point on the area
            a, c = (u - 0.5) * lx, (v - 0.5) * ly
            tx, ty, tz = pos[0] + a * ex[0] + c * ey[0], pos[1] + a * ex[1] + c * ey[1], pos[2] + a * ex[2] + c * ey[2]
        else:
            au = u * s + k
            fu = (np.cos(au) * b0 - b1) / np.sin(au)
            cu = np_clip((1.0 if fu > 0 else -1.0) / np.sqrt(fu * fu + b0 * b0), -1.0, 1.0)
            xu = np_clip(-(cu * z0) / np.sqrt(np_maximum(1.0 - cu * cu, 1e-300)), x0, x1)
            d = np.sqrt(xu * xu + z0 * z0)
            h0 = y0 / np.sqrt(d * d + y0 * y0)
            h1 = y1 / np.sqrt(d * d + y1 * y1)
            hv = h0 + v * (h1 - h0)
            hv2 = hv * hv
            yv = hv * d / np.sqrt(np_maximum(1 - hv2, 1e-300)) if hv2 < 1 - 1e-12 else y1
            if not np.isfinite(xu):
                xu = x0
            if not np.isfinite(yv):
                yv = y0
            yv = np_clip(yv, y0, y1)
            zz = z0 * zs
            tx = px + xu * ex[0] + yv * ey[0] + zz * ez[0]
            ty = py + xu * ex[1] + yv * ey[1] + zz * ez[1]
            tz = pz + xu * ex[2] + yv * ey[2] + zz * ez[2]
        lx_, ly_, lz_ = tx - px, ty - py, tz - pz
        d2 = np_maximum(lx_ * lx_ + ly_ * ly_ + lz_ * lz_, 1e-30)
        dd = np.sqrt(d2)
        wx, wy, wz = lx_ / dd, ly_ / dd, lz_ / dd
        cos_l = -(wx * nrm[0] + wy * nrm[1] + wz * nrm[2])
        gg = 0.0
        if cos_l > 0:
            gg = cos_l * area / d2 if s < MIN_SOLID_ANGLE else s
        wi[i, 0], wi[i, 1], wi[i, 2] = f32(wx), f32(wy), f32(wz)
        dist[i] = f32(dd)
        g32 = f32(gg)
        g[i] = g32
        if want_pdf:
            pdf[i] = f32(1.0) / g32 if g32 > 0 else f32(0.0)
