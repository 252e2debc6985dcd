"""Light sources: emission spectra in Cycles' units, direct-lighting samples, their pdfs, and
the lights a ray can see.

Units (the contract the Blender layer matches against Cycles, docs/physics.md sections 1.5, 7.5):
- point / spot of power P (W): radiant intensity I = P / (4 pi) W/sr times the light's
  Y-normalised spectrum; a spot is the same point light masked by a smoothstep cone
  (Blender's ``spot_size`` full angle and ``spot_blend``);
- a point / spot with a radius r > 0 keeps that intensity in total: it is a sphere of radiance
  L = I / (pi r^2) = P / (4 pi * pi r^2) (Cycles' scene/light.cpp: eval_fac = 1 / (pi * 4 pi r^2)),
  or, with ``soft_falloff`` (Blender's "Soft Falloff", Cycles' default: ``is_sphere`` false), a
  disk of radius r and the same radiance facing the shading point (kernel/light/point.h);
  a spot's cone mask is applied along each sampled ray's direction (kernel/light/spot.h), not
  inside a sphere;
- sun of strength S: irradiance S W/m^2 on a surface facing it; with an angle (full angular
  diameter 2 h) a cone of uniform radiance S / (pi sin^2 h) (Cycles: area = pi sin^2 h);
- area (rectangle or disk) of power P: one-sided Lambertian emitter of radiance P / (pi A).

For a light at a shading point p, ``sample_light`` returns the direction to the light, its
distance, and a geometric factor g such that the irradiance arriving at p (before the receiver's
cosine) is ``g * spectrum`` in expectation: g = (radiance / spectrum) / pdf(wi) for sized lights.
Sampling (pbrt-v4 section 12.2 SphereLight / Cycles' point.h and distant.h): a sphere seen from
outside is sampled uniformly in the cone it subtends (sin theta_max = r / d), from inside
uniformly over the sphere of directions (Cycles' choice for transmissive surfaces; its
cosine-hemisphere choice needs the normal, which this interface does not take); a soft-falloff
disk by a uniform point on it; a sun with an angle uniformly in its cone; a rectangle light
uniformly in the solid angle it subtends (Urena et al. 2013, core/lights/rect_light.py, as Cycles'
area.h), a disk light by a uniform point on it. ``light_pdf`` is the solid-angle density of
those samplers, ``intersect_lights`` and ``sun_radiance`` what a ray sees of the sized lights
(mirrors, glass, the camera, MIS).

Where the kernels run (core/util/jit.py), a point light of radius 0 is sampled in one compiled
pass (``_point_kernel``: the NumPy lines' float32 steps in their order, the same bits), a disk
light after NumPy's float32 sin and cos (``_disk_kernel``), a rectangle light as
core/lights/rect_light.py says. What a ray sees of the sized lights takes compiled passes too:
``intersect_lights`` one (``_hit_kernel``: every light per ray, nearest first), ``light_pdf`` of
an area light or a sized point / spot two (``_pdf_kernel``, after NumPy's arccos of a
rectangle's angles), and ``lights_met`` - the eye pass's emission stage: the lights its segments
pass and their pdfs for MIS - both at once, gathering only the rays that meet a light. They do
the NumPy lines' float64 operations in their order (no fastmath): the same bits
(tests/lights/test_light_sampling_kernels.py). The NumPy lines' dot products are written out
(rect_light.dot3), as the kernels sum them: a BLAS matmul's (and float64 einsum's) order and FMA
use are the library's and the CPU's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..util.enums import LightKind
from ..util.jit import kernels_enabled, njit
from . import rect_light
from .rect_light import dot3
from ..util.geometry import orthonormal_basis
from ..scene.model import Lights
from ..spectral.spectrum import SpectralConverter

__all__ = ["PreparedLights", "prepare_lights", "sample_light", "sample_light_pdf", "light_pdf", "is_delta",
           "intersect_lights", "lights_met", "sun_radiance", "smoothstep", "spot_mask", "sample_cone"]

POINT, SPOT, SUN, AREA_RECT, AREA_DISK = (int(k) for k in LightKind)

#: Radiance of a sized light stays below this (W/m^2/sr per spectral unit): a radius whose
#: radiance I / (pi r^2) would overflow float32 renders as the delta light it is indistinguishable from.
_MAX_RADIANCE_SCALE = 1e30
#: Directions handed back in float32 may land this far (in cosine) outside the cone they were
#: drawn in: light_pdf still counts them in.
_CONE_SLACK = 4e-7


@dataclass
class PreparedLights:
    kind: np.ndarray          # (L,) int
    position: np.ndarray      # (L, 3)
    direction: np.ndarray     # (L, 3) unit: spot axis, sun travel direction, area emission normal
    axis_u: np.ndarray        # (L, 3) unit, perpendicular to direction
    axis_v: np.ndarray        # (L, 3) unit
    size_u: np.ndarray        # (L,)
    size_v: np.ndarray        # (L,)
    area: np.ndarray          # (L,) m^2 for area lights, 0 otherwise
    cos_half_spot: np.ndarray  # (L,)
    spot_smooth: np.ndarray   # (L,) width of the blend band in cosine
    spectrum: np.ndarray      # (L, n) float32: intensity (W/sr), irradiance (W/m^2) or radiance per nm-bin
    radius: np.ndarray = None      # (L,) m: point / spot radius, 0 for delta points and other kinds
    sphere: np.ndarray = None      # (L,) bool: a sized point / spot is a sphere (else a facing disk)
    sun_half: np.ndarray = None    # (L,) rad: half the sun's angular diameter, 0 for delta suns and other kinds
    sun_omc: np.ndarray = None     # (L,) 1 - cos(sun_half), computed without cancellation
    camera_visible: np.ndarray = None  # (L,) bool: camera rays see this sun's disc (Lights.camera_visible)

    def __post_init__(self):
        n = len(self.kind)
        for name, dtype in (("radius", np.float64), ("sun_half", np.float64), ("sun_omc", np.float64),
                            ("sphere", bool), ("camera_visible", bool)):
            if getattr(self, name) is None:
                setattr(self, name, np.zeros(n, dtype))

    def __len__(self):
        return len(self.kind)


def _one_minus_cos_from_sin2(s2):
    """1 - sqrt(1 - s2) without cancellation (Cycles' sin_sqr_to_one_minus_cos)."""
    s2 = np.clip(s2, 0.0, 1.0)
    return s2 / (1.0 + np.sqrt(1.0 - s2))


def prepare_lights(lights: Lights, conv: SpectralConverter) -> PreparedLights:
    """Turn the scene's light table into unit vectors, areas and emission spectra on the grid."""
    n = len(lights)
    d = np.asarray(lights.direction, np.float64).reshape(n, 3)
    d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-30)
    u = np.asarray(lights.axis_u, np.float64).reshape(n, 3)
    u = u - np.sum(u * d, axis=1, keepdims=True) * d  # Gram-Schmidt against the normal
    un = np.linalg.norm(u, axis=1, keepdims=True)
    fallback, _ = orthonormal_basis(d)
    u = np.where(un > 1e-9, u / np.maximum(un, 1e-30), fallback)
    v = np.cross(d, u)
    kind = np.asarray(lights.kind, np.int32)
    su, sv = np.asarray(lights.size_u, np.float64), np.asarray(lights.size_v, np.float64)
    area = np.where(kind == AREA_RECT, su * sv, np.where(kind == AREA_DISK, np.pi * su * sv / 4, 0.0))

    spec = conv.illuminant_from_rgb(np.asarray(lights.color, np.float64).reshape(n, 3))
    temp = np.asarray(lights.temperature, np.float64)
    if (temp > 0).any():
        spec[temp > 0] = conv.blackbody(temp[temp > 0])
    power = np.asarray(lights.power, np.float64)
    unit = np.select(
        [np.isin(kind, [POINT, SPOT]), kind == SUN, np.isin(kind, [AREA_RECT, AREA_DISK])],
        [power / (4 * np.pi), power, power / (np.pi * np.maximum(area, 1e-30))],
        0.0,
    )
    half = 0.5 * np.asarray(lights.spot_size, np.float64)
    cos_half = np.where(kind == SPOT, np.cos(np.clip(half, 0, np.pi)), -1.0)
    smooth = np.clip(np.asarray(lights.spot_blend, np.float64), 0, 1) * (1 - cos_half)
    spectrum = (spec * unit[:, None]).astype(np.float32)

    pointlike = np.isin(kind, [POINT, SPOT])
    radius = np.where(pointlike, np.maximum(np.asarray(getattr(lights, "radius", np.zeros(n)), np.float64), 0.0), 0.0)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):  # a black light of radius 0: 0/0
        peak = spectrum.max(axis=1, initial=0.0).astype(np.float64) / (np.pi * radius**2)
    radius = np.where((radius > 0) & (peak <= _MAX_RADIANCE_SCALE), radius, 0.0)
    soft = np.asarray(getattr(lights, "soft_falloff", np.zeros(n)), np.int64) != 0
    sun_half = np.where(kind == SUN, 0.5 * np.clip(np.asarray(getattr(lights, "angle", np.zeros(n)), np.float64),
                                                   0.0, np.pi), 0.0)
    sun_omc = 2.0 * np.sin(0.5 * sun_half) ** 2
    sun_half = np.where(sun_omc > 1e-14, sun_half, 0.0)  # below this the cone is a delta in float64
    return PreparedLights(
        kind=kind,
        position=np.asarray(lights.position, np.float64).reshape(n, 3),
        direction=d,
        axis_u=u,
        axis_v=v,
        size_u=su,
        size_v=sv,
        area=area,
        cos_half_spot=cos_half,
        spot_smooth=smooth,
        spectrum=spectrum,
        radius=radius,
        sphere=(radius > 0) & ~soft,
        sun_half=sun_half,
        sun_omc=np.where(sun_half > 0, sun_omc, 0.0),
        camera_visible=(kind == SUN) & (np.asarray(getattr(lights, "camera_visible", np.zeros(n)), np.int64) != 0),
    )


def smoothstep(x):
    """3 x^2 - 2 x^3 of x clipped to [0, 1]: the spot cone's blend (Cycles' smoothstep)."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def spot_mask(pl: PreparedLights, index: int, travel: np.ndarray) -> np.ndarray:
    """The spot cone mask for light travelling along ``travel`` (B, 3) unit (Cycles' spot.h:
    smoothstep((cos - cos_half) / blend band), 0 outside)."""
    cos_axis = dot3(travel, pl.direction[index].astype(travel.dtype))
    # the cone's numbers in travel's precision, as the kernels take them (NumPy 1.x's value-based
    # casting did the same to these float64 scalars; NumPy 2 would compute in float64)
    ch, sm = travel.dtype.type(pl.cos_half_spot[index]), pl.spot_smooth[index]
    cone = np.where(cos_axis > ch, 1.0, 0.0).astype(travel.dtype)
    if np.float32(sm) > 0:  # a blend band that is 0 in float32 is a hard edge
        cone = cone * smoothstep((cos_axis - ch) / travel.dtype.type(sm))
    return cone


def is_delta(pl: PreparedLights, index: int) -> bool:
    """A light no ray can hit and no other sampler can find: point / spot of radius 0, sun of
    angle 0 (area lights have an area)."""
    k = int(pl.kind[index])
    if k in (POINT, SPOT):
        return not pl.radius[index] > 0
    if k == SUN:
        return not pl.sun_half[index] > 0
    return False


def _basis(ax, ay, az):
    """A branchless orthonormal basis about the unit vector (ax, ay, az), per component
    (Duff et al. 2017, "Building an orthonormal basis, revisited"): ((ux, uy, uz), (vx, vy, vz))."""
    sign = np.where(az >= 0, 1.0, -1.0).astype(ax.dtype)
    a = -1.0 / (sign + az)
    b = ax * ay * a
    return (1.0 + sign * ax * ax * a, sign * b, -sign * ax), (b, sign + ay * ay * a, -ay)


def sample_cone(axis: np.ndarray, omc, rng: np.random.Generator, b: int, dtype=np.float64) -> np.ndarray:
    """Directions uniform in the cone around unit ``axis`` ((3,) or (B, 3)) with 1 - cos(half
    angle) = ``omc`` (scalar or (B,)): cos = 1 - u omc, sin from u omc (2 - u omc), so narrow
    cones keep their precision. (B, 3) of ``dtype``."""
    axis = np.broadcast_to(np.asarray(axis, dtype), (b, 3))
    ax, ay, az = axis[:, 0], axis[:, 1], axis[:, 2]
    x = rng.random(b, dtype) * np.asarray(omc, dtype)
    cos_t = 1.0 - x
    sin_t = np.sqrt(np.maximum(x * (2.0 - x), 0.0))
    phi = dtype(2 * np.pi) * rng.random(b, dtype)
    cu, cv = sin_t * np.cos(phi), sin_t * np.sin(phi)
    (ux, uy, uz), (vx, vy, vz) = _basis(ax, ay, az)
    out = np.empty((b, 3), dtype)
    out[:, 0] = cos_t * ax + cu * ux + cv * vx
    out[:, 1] = cos_t * ay + cu * uy + cv * vy
    out[:, 2] = cos_t * az + cu * uz + cv * vz
    return out


def _sphere_geometry(pl, index, p):
    """(to_centre unit (B, 3), d (B,), r, omc (B,) of the cone the sphere subtends, inside (B,)),
    in the dtype of p."""
    dt = np.float32 if p.dtype == np.float32 else np.float64
    c = pl.position[index].astype(dt)
    r = float(pl.radius[index])
    to_c = c - p
    d = np.sqrt(dot3(to_c, to_c))
    inside = d <= r
    axis = to_c / np.maximum(d, dt(1e-30))[:, None]
    omc = np.where(inside, dt(2.0), _one_minus_cos_from_sin2((dt(r) / np.maximum(d, dt(1e-30))) ** 2)).astype(dt)
    return axis, d, r, omc, inside


def _distance_to_sphere(d, cos_t, r, inside):
    """Distance along a direction at angle acos(cos_t) from the centre direction to the sphere
    (law of cosines: the near root outside, the far root inside; Cycles' point.h)."""
    disc = np.sqrt(np.maximum(r * r - d * d * (1.0 - cos_t * cos_t), 0.0))
    return np.maximum(np.where(inside, d * cos_t + disc, d * cos_t - disc), 0.0)


def sample_light(pl: PreparedLights, index: int, p: np.ndarray, rng: np.random.Generator):
    """One sample of light ``index`` seen from points p (B, 3).

    Returns (wi, dist, g): unit directions towards the light (B, 3) float32, distances (B,) (inf
    for the sun) and the geometric factor g (B,) described in the module docstring (0 where the
    point is outside a spot cone or behind an area light). Delta lights are sampled exactly;
    sized ones with the pdf ``light_pdf`` returns for the same direction.
    """
    k = int(pl.kind[index])
    b = len(p)
    f32 = np.float32
    if k == SUN:
        if pl.sun_half[index] > 0:
            omc = float(pl.sun_omc[index])
            wi = sample_cone(-pl.direction[index], omc, rng, b, f32)
            # radiance / S = 1 / (pi sin^2 h), pdf = 1 / (2 pi omc), sin^2 h = omc (2 - omc)
            return wi, np.full(b, np.inf, f32), np.full(b, 2.0 / (2.0 - omc), f32)
        wi = np.broadcast_to(-pl.direction[index].astype(f32), (b, 3))
        return wi, np.full(b, np.inf, f32), np.ones(b, f32)
    if k in (POINT, SPOT) and pl.radius[index] > 0:
        return _sample_sized_point(pl, index, p, rng)
    if k == POINT and kernels_enabled() and p.dtype == f32 and p.ndim == 2:
        wi, dist, g = np.empty((b, 3), f32), np.empty(b, f32), np.empty(b, f32)
        _point_kernel(pl.position[index].astype(f32), p, wi, dist, g)
        return wi, dist, g
    if k in (POINT, SPOT):
        target = pl.position[index].astype(f32)
    else:
        r1, r2 = rng.random(b, f32), rng.random(b, f32)
        if k == AREA_RECT:  # by solid angle, as Cycles (core/lights/rect_light.py)
            return rect_light.sample_light_rect(pl, index, p, r1, r2)
        # a disk: uniform on the ellipse (a polar mapping is fine for a uniform density)
        rad, phi = np.sqrt(r1), 2 * np.pi * r2
        a, c = 0.5 * pl.size_u[index] * rad * np.cos(phi), 0.5 * pl.size_v[index] * rad * np.sin(phi)
        if kernels_enabled() and p.dtype == f32 and p.ndim == 2 and a.dtype == f32 and c.dtype == f32:
            wi, dist, g = np.empty((b, 3), f32), np.empty(b, f32), np.empty(b, f32)
            _disk_kernel(pl.position[index], pl.axis_u[index], pl.axis_v[index], pl.direction[index].astype(f32),
                         f32(pl.area[index]), a, c, np.ascontiguousarray(p), wi, dist, g)
            return wi, dist, g
        target = (pl.position[index] + a[:, None] * pl.axis_u[index] + c[:, None] * pl.axis_v[index]).astype(f32)
    to_light = target - p
    d2 = np.maximum(np.einsum("ij,ij->i", to_light, to_light), f32(1e-30))
    dist = np.sqrt(d2)
    wi = to_light / dist[:, None]
    if k in (POINT, SPOT):
        g = f32(1.0) / d2
        if k == SPOT:
            g = g * spot_mask(pl, index, -wi)
        return wi, dist, g
    cos_l = -dot3(wi, pl.direction[index].astype(f32))
    g = np.where(cos_l > 0, cos_l * f32(pl.area[index]) / d2, f32(0.0))
    return wi, dist, g


@njit
def _disk_kernel(pos, au, av, nrm, area, a, c, p, wi, dist, g):
    """sample_light of a disk light per row from the point's coordinates (a, c) on its axes
    (float32, by NumPy's sin and cos): the target in float64 rounded to float32, then the
    direction, distance and g = cos_l A / d^2 in float32."""
    tiny = np.float32(1e-30)
    zero = np.float32(0.0)
    for i in range(p.shape[0]):
        ai, ci = np.float64(a[i]), np.float64(c[i])
        x = np.float32(pos[0] + ai * au[0] + ci * av[0]) - p[i, 0]
        y = np.float32(pos[1] + ai * au[1] + ci * av[1]) - p[i, 1]
        z = np.float32(pos[2] + ai * au[2] + ci * av[2]) - p[i, 2]
        d2 = x * x + y * y + z * z
        if not d2 >= tiny:  # np.maximum: NaN stays NaN
            d2 = d2 if d2 != d2 else tiny
        d = np.sqrt(d2)
        wx, wy, wz = x / d, y / d, z / d
        wi[i, 0], wi[i, 1], wi[i, 2] = wx, wy, wz
        dist[i] = d
        cos_l = -(wx * nrm[0] + wy * nrm[1] + wz * nrm[2])
        g[i] = cos_l * area / d2 if cos_l > 0 else zero


@njit
def _point_kernel(target, p, wi, dist, g):
    """sample_light of a point light of radius 0 per row: the unit direction to ``target``
    (float32), the distance and g = 1 / d^2."""
    tiny = np.float32(1e-30)
    one = np.float32(1.0)
    for i in range(p.shape[0]):
        x, y, z = target[0] - p[i, 0], target[1] - p[i, 1], target[2] - p[i, 2]
        d2 = x * x + y * y + z * z
        if not d2 >= tiny:  # np.maximum: NaN stays NaN
            d2 = d2 if d2 != d2 else tiny
        d = np.sqrt(d2)
        wi[i, 0], wi[i, 1], wi[i, 2] = x / d, y / d, z / d
        dist[i] = d
        g[i] = one / d2


def _sample_sized_point(pl, index, p, rng):
    """sample_light for a point / spot with a radius, in float32 (p's own precision)."""
    b = len(p)
    f32 = np.float32
    p = np.asarray(p, f32)
    r = float(pl.radius[index])
    if pl.sphere[index] and kernels_enabled() and p.ndim == 2:
        u1, u2 = rng.random(b, f32), rng.random(b, f32)  # sample_cone's numbers, in its order
        phi = f32(2 * np.pi) * u2
        spot = int(pl.kind[index]) == SPOT
        wi, dist, g = np.empty((b, 3), f32), np.empty(b, f32), np.empty(b, f32)
        _sphere_kernel(pl.position[index].astype(f32), r, np.ascontiguousarray(p), u1, np.cos(phi), np.sin(phi),
                       spot, pl.direction[index].astype(f32), f32(pl.cos_half_spot[index]),
                       f32(pl.spot_smooth[index]), wi, dist, g)
        return wi, dist, g
    if pl.sphere[index]:
        axis, d, r, omc, inside = _sphere_geometry(pl, index, p)
        if inside.any():  # uniform over all directions there (pdf 1 / (4 pi)): omc = 2
            wi = sample_cone(axis, omc, rng, b, f32)
            g = np.where(inside, f32(4.0 / (r * r)), f32(2.0 / (r * r)) * omc)
        else:
            wi = sample_cone(axis, omc, rng, b, f32)
            g = f32(2.0 / (r * r)) * omc  # (1 / (pi r^2)) / (1 / (2 pi omc))
        cos_t = dot3(wi, axis)
        dist = _distance_to_sphere(d, cos_t, f32(r), inside)
        if int(pl.kind[index]) == SPOT:  # the cone mask along the ray, outside the sphere only (spot.h)
            g = np.where(inside, g, g * spot_mask(pl, index, -wi))
        return wi, dist.astype(f32), g.astype(f32)
    # soft falloff: a uniform point on the disk of radius r facing p; g = (1/(pi r^2)) / pdf with
    # pdf = t^2 / (pi r^2 cos_l) and cos_l = d / t (the disk is perpendicular to the centre direction)
    c = pl.position[index].astype(f32)
    to_p = p - c
    d = np.sqrt(np.einsum("ij,ij->i", to_p, to_p))
    n = to_p / np.maximum(d, f32(1e-30))[:, None]
    (ux, uy, uz), (vx, vy, vz) = _basis(n[:, 0], n[:, 1], n[:, 2])
    rad, phi = f32(r) * np.sqrt(rng.random(b, f32)), f32(2 * np.pi) * rng.random(b, f32)
    cu, cv = rad * np.cos(phi), rad * np.sin(phi)
    to_q = np.empty((b, 3), f32)  # q - p = (c - p) + cu u + cv v
    to_q[:, 0] = cu * ux + cv * vx - to_p[:, 0]
    to_q[:, 1] = cu * uy + cv * vy - to_p[:, 1]
    to_q[:, 2] = cu * uz + cv * vz - to_p[:, 2]
    t = np.maximum(np.sqrt(np.einsum("ij,ij->i", to_q, to_q)), f32(1e-30))
    wi = to_q / t[:, None]
    g = d / (t * t * t)
    if int(pl.kind[index]) == SPOT:
        g = g * spot_mask(pl, index, -wi)
    return wi, t, g.astype(f32)


@njit
def _sphere_kernel(c, r, p, u1, cos_phi, sin_phi, spot, nrm, ch, sm, wi, dist, g):
    """_sample_sized_point of a sphere light per row in float32: _sphere_geometry, sample_cone
    (from its first numbers ``u1`` and NumPy's cos / sin of its angles), g, the distance to the
    sphere and (``spot``) the cone mask outside it, as the NumPy lines do."""
    f32 = np.float32
    one, two, zero, tiny = f32(1.0), f32(2.0), f32(0.0), f32(1e-30)
    r32 = f32(r)
    g_in, g_out = f32(4.0 / (r * r)), f32(2.0 / (r * r))
    smooth = sm > 0
    for i in range(p.shape[0]):
        tx, ty, tz = c[0] - p[i, 0], c[1] - p[i, 1], c[2] - p[i, 2]
        d = np.sqrt(tx * tx + ty * ty + tz * tz)
        inside = d <= r32
        dm = d if (d >= tiny or d != d) else tiny
        ax, ay, az = tx / dm, ty / dm, tz / dm
        if inside:
            omc = two
        else:
            s2 = r32 / dm
            s2 = rect_light.np_clip(s2 * s2, zero, one)
            omc = s2 / (one + np.sqrt(one - s2))
        x = u1[i] * omc
        cos_t = one - x
        sin_t = x * (two - x)
        sin_t = np.sqrt(sin_t if (sin_t >= zero or sin_t != sin_t) else zero)
        cu, cv = sin_t * cos_phi[i], sin_t * sin_phi[i]
        sign = one if az >= zero else -one  # _basis
        a = -one / (sign + az)
        bb = ax * ay * a
        ux, uy, uz = one + sign * ax * ax * a, sign * bb, -sign * ax
        vx, vy, vz = bb, sign + ay * ay * a, -ay
        wx = cos_t * ax + cu * ux + cv * vx
        wy = cos_t * ay + cu * uy + cv * vy
        wz = cos_t * az + cu * uz + cv * vz
        wi[i, 0], wi[i, 1], wi[i, 2] = wx, wy, wz
        gg = g_in if inside else g_out * omc
        ct = wx * ax + wy * ay + wz * az
        disc = r32 * r32 - d * d * (one - ct * ct)  # _distance_to_sphere
        disc = np.sqrt(disc if (disc >= zero or disc != disc) else zero)
        t = d * ct + disc if inside else d * ct - disc
        dist[i] = t if (t >= zero or t != t) else zero
        if spot and not inside:  # spot_mask of -wi in float32
            cos_axis = (-wx) * nrm[0] + (-wy) * nrm[1] + (-wz) * nrm[2]
            cone = one if cos_axis > ch else zero
            if smooth:
                xx = rect_light.np_clip((cos_axis - ch) / sm, zero, one)
                cone = cone * (xx * xx * (f32(3) - two * xx))
            gg = gg * cone
        g[i] = gg


def sample_light_pdf(pl: PreparedLights, index: int, p: np.ndarray, rng: np.random.Generator):
    """``sample_light`` and the solid-angle pdf of each direction it drew (B,) float32 (None for
    a delta light), what ``light_pdf`` gives for it, from the sample's own g instead of a second
    intersection with the light: the sized lights' radiance is c times the spectrum with c = 1
    (area), 1 / (pi r^2) (spheres, facing disks) and 1 / (pi sin^2 h) (sun cones), and g = c /
    pdf (module docstring). A spot's cone mask is in its g, so its pdf is ``light_pdf``'s."""
    if int(pl.kind[index]) == AREA_RECT and kernels_enabled():  # sample and pdf in one kernel pass
        b = len(p)
        r1, r2 = rng.random(b, np.float32), rng.random(b, np.float32)  # sample_light's numbers
        return rect_light.sample_light_rect(pl, index, p, r1, r2, with_pdf=True)
    wi, dist, g = sample_light(pl, index, p, rng)
    if is_delta(pl, index):
        return wi, dist, g, None
    k = int(pl.kind[index])
    if k == SPOT:
        return wi, dist, g, light_pdf(pl, index, p, wi)
    if k == SUN:
        omc = float(pl.sun_omc[index])
        c = 1.0 / (np.pi * omc * (2.0 - omc))
    elif k == POINT:
        c = 1.0 / (np.pi * float(pl.radius[index]) ** 2)
    else:
        c = 1.0
    g = np.asarray(g, np.float32)
    with np.errstate(divide="ignore"):
        pdf = np.where(g > 0, np.float32(c) / g, np.float32(0.0)).astype(np.float32)
    return wi, dist, g, pdf


def light_pdf(pl: PreparedLights, index: int, p: np.ndarray, wi: np.ndarray) -> np.ndarray:
    """(B,) float32 solid-angle density with which ``sample_light`` draws direction ``wi`` (B, 3)
    unit from points ``p`` (B, 3); 0 for delta lights, for directions it cannot draw, and on the
    back of an area light (which emits nothing there)."""
    k = int(pl.kind[index])
    b = len(p)
    if k != SUN and not is_delta(pl, index) and kernels_enabled() and _fits(p) and _fits(wi):
        return _pdf_with_kernels(pl, np.full(b, index, np.int32), np.ascontiguousarray(p), np.ascontiguousarray(wi),
                                 np.arange(b))
    p = np.asarray(p, np.float64)
    wi = np.asarray(wi, np.float64)
    if is_delta(pl, index):
        return np.zeros(b, np.float32)
    if k == SUN:
        omc = float(pl.sun_omc[index])
        inside = wi @ (-pl.direction[index]) >= 1.0 - omc - _CONE_SLACK
        return np.where(inside, 1.0 / (2 * np.pi * omc), 0.0).astype(np.float32)
    if k in (POINT, SPOT):
        r = float(pl.radius[index])
        if pl.sphere[index]:
            axis, d, r, omc, inside = _sphere_geometry(pl, index, p)
            in_cone = dot3(wi, axis) >= 1.0 - omc - _CONE_SLACK
            return np.where(inside, 1.0 / (4 * np.pi), np.where(in_cone, 1.0 / (2 * np.pi * omc), 0.0)).astype(
                np.float32)
        to_p = p - pl.position[index]
        d = np.linalg.norm(to_p, axis=1)
        n = to_p / np.maximum(d, 1e-300)[:, None]
        t, ok = _plane_hit(p, wi, pl.position[index], n, np.inf)
        q = p + t[:, None] * wi
        ok &= np.sum((q - pl.position[index]) ** 2, axis=1) <= r * r
        cos_l = -dot3(wi, n)
        with np.errstate(divide="ignore", invalid="ignore"):
            pdf = t * t / (np.pi * r * r * cos_l)
        return np.where(ok & (cos_l > 0), pdf, 0.0).astype(np.float32)
    t, ok, cos_l = _area_hit(pl, index, p, wi, np.full(b, np.inf))
    if k == AREA_RECT:
        return rect_light.pdf_light_rect(pl, index, p, ok, t, cos_l).astype(np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        pdf = t * t / (pl.area[index] * cos_l)
    return np.where(ok, pdf, 0.0).astype(np.float32)


def _plane_hit(o, d, c, n, tmax):
    """Ray-plane distances t (B,) and whether 0 < t < tmax, for the plane through c with normal
    n ((3,) or (B, 3))."""
    denom = dot3(d, n)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = dot3(c - o, n) / denom
    ok = np.isfinite(t) & (t > 0) & (t < tmax)
    return np.where(ok, t, np.inf), ok


def _area_hit(pl, index, o, d, tmax):
    """Front-side hits of area light ``index``: (t, hit, cos_l) with cos_l = -d . normal > 0."""
    nrm = pl.direction[index]
    cos_l = -dot3(d, nrm)
    t, ok = _plane_hit(o, d, pl.position[index], nrm, tmax)
    q = o + np.where(ok, t, 0.0)[:, None] * d - pl.position[index]
    a, c = dot3(q, pl.axis_u[index]), dot3(q, pl.axis_v[index])
    hu, hv = 0.5 * pl.size_u[index], 0.5 * pl.size_v[index]
    if int(pl.kind[index]) == AREA_RECT:
        inside = (np.abs(a) <= hu) & (np.abs(c) <= hv)
    else:
        inside = (a / hu) ** 2 + (c / hv) ** 2 <= 1.0
    ok &= inside & (cos_l > 0)  # one-sided (Cycles' area.h: a ray through the back goes on)
    return t, ok, cos_l


def _sphere_hit(o, d, c, r, tmax):
    """Nearest ray-sphere distance in (0, tmax): the near root from outside, the far root from inside."""
    oc = o - c
    bq = dot3(d, oc)
    cq = dot3(oc, oc) - r * r
    disc = bq * bq - cq
    s = np.sqrt(np.maximum(disc, 0.0))
    t0, t1 = -bq - s, -bq + s
    t = np.where(t0 > 0, t0, t1)
    ok = (disc >= 0) & (t > 0) & (t < tmax)
    return np.where(ok, t, np.inf), ok, cq <= 0


def intersect_lights(pl: PreparedLights, o: np.ndarray, d: np.ndarray, tmax: np.ndarray):
    """The nearest sized light hit by rays o, d (B, 3) before tmax (B,): (index (B,) int32, -1 for
    none; t (B,) float32, inf for none; scale (B,) float32) with the radiance seen along the ray
    ``scale * pl.spectrum[index]``.

    Sized lights are area lights (one-sided: a ray through the back passes, as in Cycles), point
    and spot lights with a radius (spheres, or disks facing the ray origin with soft falloff).
    Suns are at infinity: ``sun_radiance`` for rays that leave the scene.
    """
    b = len(o)
    if kernels_enabled() and _fits(o) and _fits(d):
        idx, t, scale = np.empty(b, np.int32), np.empty(b, np.float32), np.empty(b, np.float32)
        kind, tab = _tables(pl)
        _hit_kernel(kind, tab, np.ascontiguousarray(o), np.ascontiguousarray(d),
                    np.ascontiguousarray(np.broadcast_to(np.asarray(tmax, np.float64), (b,))), _ALL_ROWS, False,
                    idx, t, scale, _NO_ROWS, _NO_COS)
        return idx, t, scale
    o = np.asarray(o, np.float64)
    d = np.asarray(d, np.float64)
    best_t = np.broadcast_to(np.asarray(tmax, np.float64), (b,)).copy()
    idx = np.full(b, -1, np.int32)
    scale = np.zeros(b, np.float64)
    for li in range(len(pl)):  # loop over lights (a handful), not rays
        k = int(pl.kind[li])
        if k in (AREA_RECT, AREA_DISK):
            t, ok, _ = _area_hit(pl, li, o, d, best_t)
            s = np.ones(b)
        elif k in (POINT, SPOT) and pl.radius[li] > 0:
            r, c = float(pl.radius[li]), pl.position[li]
            if pl.sphere[li]:
                t, ok, inside = _sphere_hit(o, d, c, r, best_t)
                if k == SPOT:  # one-sided towards the centre (spot.h), masked outside the sphere
                    ok &= dot3(d, o - c) < 0
                    s = np.where(inside, 1.0, spot_mask(pl, li, d))
                else:
                    s = np.ones(b)
            else:
                n = o - c
                n = n / np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]
                t, ok = _plane_hit(o, d, c, n, best_t)
                q = o + np.where(ok, t, 0.0)[:, None] * d
                ok &= np.sum((q - c) ** 2, axis=1) <= r * r
                s = spot_mask(pl, li, d) if k == SPOT else np.ones(b)
            s = s / (np.pi * r * r)  # intensity -> radiance
        else:
            continue
        ok &= t < best_t
        best_t = np.where(ok, t, best_t)
        idx = np.where(ok, li, idx)
        scale = np.where(ok, s, scale)
    t_out = np.where(idx >= 0, best_t, np.inf).astype(np.float32)
    return idx, t_out, scale.astype(np.float32)


def lights_met(pl: PreparedLights, o: np.ndarray, d: np.ndarray, tmax: np.ndarray, seen: np.ndarray):
    """``intersect_lights`` of the rays ``seen`` (B,) bool of o, d (B, 3) before tmax (B,), and
    ``light_pdf`` of the light each one meets along its direction (for MIS): (rows (M,) int64 of
    the rays that meet a light, in order; their light index (M,) int32, scale (M,) float32 and
    pdf (M,) float32)."""
    rows = np.flatnonzero(seen)
    if len(rows) == 0:
        return rows, np.zeros(0, np.int32), np.zeros(0, np.float32), np.zeros(0, np.float32)
    if kernels_enabled() and _fits(o) and _fits(d) and np.ndim(tmax) == 1:
        m_max = len(rows)
        out_rows, idx = np.empty(m_max, np.int64), np.empty(m_max, np.int32)
        scale, cosines = np.empty(m_max, np.float32), np.empty((m_max, 4), np.float64)
        kind, tab = _tables(pl)
        o, d = np.ascontiguousarray(o), np.ascontiguousarray(d)
        m = _hit_kernel(kind, tab, o, d, np.ascontiguousarray(tmax), rows, True, idx, _NO_T, scale, out_rows,
                        cosines)
        out_rows, idx, scale = out_rows[:m], idx[:m], scale[:m]
        if m == 0:
            return out_rows, idx, scale, np.zeros(0, np.float32)
        with np.errstate(invalid="ignore"):
            g = np.arccos(cosines[:m], out=cosines[:m])  # NumPy's arccos (rect_light.angles)
        pdf = np.empty(m, np.float32)
        _pdf_kernel(kind, tab, o, d, out_rows, idx, g, pdf)
        return out_rows, idx, scale, pdf
    idx, _, scale = intersect_lights(pl, o[rows], d[rows], np.asarray(tmax)[rows])
    met = idx >= 0
    rows, idx, scale = rows[met], idx[met], scale[met]
    pdf = np.zeros(len(rows), np.float32)
    for li in np.unique(idx):  # the few lights met
        sel = idx == li
        pdf[sel] = light_pdf(pl, int(li), o[rows[sel]], d[rows[sel]])
    return rows, idx, scale, pdf


def sun_radiance(pl: PreparedLights, d: np.ndarray, camera: bool = False) -> np.ndarray:
    """(B, n) float32 radiance of the suns with an angle seen along escaping directions d (B, 3):
    S / (pi sin^2 h) times the spectrum's shape inside each sun's cone, zero outside;
    ``camera``: only the suns camera rays see (``camera_visible``)."""
    d = np.asarray(d, np.float64)
    out = np.zeros((len(d), pl.spectrum.shape[1]), np.float32)
    suns = (pl.kind == SUN) & (pl.sun_half > 0)
    for li in np.flatnonzero(suns & pl.camera_visible if camera else suns):  # loop over suns
        omc = float(pl.sun_omc[li])
        inside = d @ (-pl.direction[li]) >= 1.0 - omc
        if inside.any():
            out[inside] += pl.spectrum[li] * np.float32(1.0 / (np.pi * omc * (2.0 - omc)))
    return out


# ------------------------------------------------------------------------------ kernels
# The compiled twins (core/util/jit.py) of intersect_lights (``_hit_kernel``: every light per
# ray, nearest first, as the loop over lights above) and of light_pdf for the sized lights
# (``_pdf_kernel``: per ray, the light given), in the NumPy lines' float64 operations and order:
# the same bits (tests/lights/test_light_sampling_kernels.py). A rectangle's solid angle needs
# four arccos, which NumPy computes between the two passes (core/lights/rect_light.py says why).

# columns of the lights' float64 table (_tables)
_P, _N, _U, _V, _SU, _SV, _AREA, _R, _SPH, _CH, _SM, _SM_ON, _CORNER, _EZ, _NCOL = (
    0, 3, 6, 9, 12, 13, 14, 15, 16, 17, 18, 19, 20, 23, 26)
_ALL_ROWS = np.zeros(0, np.int64)  # rows argument: every ray
_NO_ROWS = np.zeros(0, np.int64)
_NO_T = np.zeros(0, np.float32)
_NO_COS = np.zeros((0, 4), np.float64)


def _fits(a) -> bool:
    return isinstance(a, np.ndarray) and a.ndim == 2 and a.shape[1] == 3 and a.dtype.char in "fd"


_TABLE_FIELDS = ("kind", "position", "direction", "axis_u", "axis_v", "size_u", "size_v", "area", "radius", "sphere",
                 "cos_half_spot", "spot_smooth")


def _tables(pl: PreparedLights):
    """(kind (L,) int64, (L, _NCOL) float64): the prepared lights' numbers for the kernels, with
    each rectangle's frame (rect_light.RectFrame's corner and normal); made once per prepared
    lights (kept on them, for the arrays they were made from: they are not changed in place)."""
    refs = tuple(getattr(pl, f) for f in _TABLE_FIELDS)
    hit = pl.__dict__.get("_kernel_tables")
    if hit is not None and all(a is b for a, b in zip(hit[0], refs)):
        return hit[1]
    out = _make_tables(pl)
    pl.__dict__["_kernel_tables"] = (refs, out)
    return out


def _make_tables(pl: PreparedLights):
    n = len(pl)
    tab = np.zeros((n, _NCOL), np.float64)
    tab[:, _P:_P + 3] = pl.position
    tab[:, _N:_N + 3] = pl.direction
    tab[:, _U:_U + 3] = pl.axis_u
    tab[:, _V:_V + 3] = pl.axis_v
    tab[:, _SU], tab[:, _SV], tab[:, _AREA] = pl.size_u, pl.size_v, pl.area
    tab[:, _R], tab[:, _SPH] = pl.radius, pl.sphere
    tab[:, _CH], tab[:, _SM] = pl.cos_half_spot, pl.spot_smooth
    tab[:, _SM_ON] = np.asarray(pl.spot_smooth, np.float32) > 0  # spot_mask's float32 test of the band
    kind = np.asarray(pl.kind, np.int64)
    for li in np.flatnonzero(kind == AREA_RECT):
        rect = rect_light._frame_of(pl, int(li))
        tab[li, _CORNER:_CORNER + 3] = rect.corner
        tab[li, _EZ:_EZ + 3] = rect.ez
    return kind, tab


def _pdf_with_kernels(pl, li, p, wi, rows):
    """light_pdf by the kernels for the rays ``rows`` of p, wi, each towards light li[j]."""
    kind, tab = _tables(pl)
    g = np.ones((len(rows), 4), np.float64)
    _cosines_kernel(kind, tab, p, rows, li, g)
    with np.errstate(invalid="ignore"):
        np.arccos(g, out=g)
    pdf = np.empty(len(rows), np.float32)
    _pdf_kernel(kind, tab, p, wi, rows, li, g, pdf)
    return pdf


@njit
def _plane_row(ox, oy, oz, dx, dy, dz, cx, cy, cz, nx, ny, nz, tmax):
    """_plane_hit of one ray: (t, inf where missed; 0 < t < tmax)."""
    denom = dx * nx + dy * ny + dz * nz
    t = ((cx - ox) * nx + (cy - oy) * ny + (cz - oz) * nz) / denom
    ok = np.isfinite(t) and t > 0 and t < tmax
    return (t if ok else np.inf), ok


@njit
def _area_row(tab, li, rect, ox, oy, oz, dx, dy, dz, tmax):
    """_area_hit of one ray: (t, hit, cos_l)."""
    nx, ny, nz = tab[li, _N], tab[li, _N + 1], tab[li, _N + 2]
    px, py, pz = tab[li, _P], tab[li, _P + 1], tab[li, _P + 2]
    cos_l = -(dx * nx + dy * ny + dz * nz)
    t, ok = _plane_row(ox, oy, oz, dx, dy, dz, px, py, pz, nx, ny, nz, tmax)
    tt = t if ok else 0.0
    qx, qy, qz = ox + tt * dx - px, oy + tt * dy - py, oz + tt * dz - pz
    a = qx * tab[li, _U] + qy * tab[li, _U + 1] + qz * tab[li, _U + 2]
    c = qx * tab[li, _V] + qy * tab[li, _V + 1] + qz * tab[li, _V + 2]
    hu, hv = 0.5 * tab[li, _SU], 0.5 * tab[li, _SV]
    if rect:
        inside = abs(a) <= hu and abs(c) <= hv
    else:
        au, cv = a / hu, c / hv
        inside = au * au + cv * cv <= 1.0
    return t, ok and inside and cos_l > 0, cos_l


@njit
def _spot_row(tab, li, dx, dy, dz):
    """spot_mask of one float64 direction of travel."""
    cos_axis = dx * tab[li, _N] + dy * tab[li, _N + 1] + dz * tab[li, _N + 2]
    ch = tab[li, _CH]
    cone = 1.0 if cos_axis > ch else 0.0
    if tab[li, _SM_ON] != 0.0:
        x = rect_light.np_clip((cos_axis - ch) / tab[li, _SM], 0.0, 1.0)
        cone = cone * (x * x * (3 - 2 * x))
    return cone


@njit
def _hit_kernel(kind, tab, o, d, tmax, rows, compact, idx, t_out, scale, rows_out, cosines):
    """intersect_lights per ray (``rows``: the rays to trace, empty: all): the nearest sized light
    before tmax. Not ``compact``: idx, t_out, scale per ray; ``compact``: only the rays that meet
    one, their row in rows_out, and for those meeting a rectangle the cosines of its interior
    angles (rect_light.cosines_row) in ``cosines`` (1 otherwise); returns how many rays were written."""
    n = rows.shape[0] if rows.shape[0] > 0 else o.shape[0]
    m = 0
    for j in range(n):
        r = rows[j] if rows.shape[0] > 0 else j
        ox, oy, oz = np.float64(o[r, 0]), np.float64(o[r, 1]), np.float64(o[r, 2])
        dx, dy, dz = np.float64(d[r, 0]), np.float64(d[r, 1]), np.float64(d[r, 2])
        best = np.float64(tmax[r])
        best_i = -1
        best_s = 0.0
        for li in range(kind.shape[0]):  # the lights in order, as the NumPy loop
            k = kind[li]
            s = 1.0
            if k == AREA_RECT or k == AREA_DISK:
                t, ok, _ = _area_row(tab, li, k == AREA_RECT, ox, oy, oz, dx, dy, dz, best)
            elif (k == POINT or k == SPOT) and tab[li, _R] > 0:
                rad = tab[li, _R]
                cx, cy, cz = tab[li, _P], tab[li, _P + 1], tab[li, _P + 2]
                if tab[li, _SPH] != 0.0:  # _sphere_hit
                    ocx, ocy, ocz = ox - cx, oy - cy, oz - cz
                    bq = dx * ocx + dy * ocy + dz * ocz
                    cq = ocx * ocx + ocy * ocy + ocz * ocz - rad * rad
                    disc = bq * bq - cq
                    sq = np.sqrt(rect_light.np_maximum(disc, 0.0))
                    t0, t1 = -bq - sq, -bq + sq
                    t = t0 if t0 > 0 else t1
                    ok = disc >= 0 and t > 0 and t < best
                    if not ok:
                        t = np.inf
                    if k == SPOT:  # one-sided towards the centre, masked outside the sphere
                        ok = ok and bq < 0
                        s = 1.0 if cq <= 0 else _spot_row(tab, li, dx, dy, dz)
                else:  # a disk facing the ray origin
                    nx, ny, nz = ox - cx, oy - cy, oz - cz
                    nn = rect_light.np_maximum(np.sqrt(nx * nx + ny * ny + nz * nz), 1e-300)
                    nx, ny, nz = nx / nn, ny / nn, nz / nn
                    t, ok = _plane_row(ox, oy, oz, dx, dy, dz, cx, cy, cz, nx, ny, nz, best)
                    tt = t if ok else 0.0
                    qx, qy, qz = ox + tt * dx - cx, oy + tt * dy - cy, oz + tt * dz - cz
                    ok = ok and qx * qx + qy * qy + qz * qz <= rad * rad
                    if k == SPOT:
                        s = _spot_row(tab, li, dx, dy, dz)
                s = s / (np.pi * rad * rad)  # intensity -> radiance
            else:
                continue
            if ok and t < best:
                best, best_i, best_s = t, li, s
        if not compact:
            idx[j] = best_i
            t_out[j] = np.float32(best) if best_i >= 0 else np.float32(np.inf)
            scale[j] = np.float32(best_s)
        elif best_i >= 0:
            idx[m] = best_i
            scale[m] = np.float32(best_s)
            rows_out[m] = r
            if kind[best_i] == AREA_RECT:
                rect_light.cosines_row(tab[best_i, _CORNER:_CORNER + 3], tab[best_i, _U:_U + 3],
                                       tab[best_i, _V:_V + 3], tab[best_i, _EZ:_EZ + 3], tab[best_i, _SU],
                                       tab[best_i, _SV], ox, oy, oz, cosines, m)
            else:
                for q in range(4):
                    cosines[m, q] = 1.0
            m += 1
    return m


@njit
def _cosines_kernel(kind, tab, p, rows, li, cosines):
    """The rectangle lights' interior-angle cosines at p[rows[j]] for light li[j] (1 for others)."""
    for j in range(rows.shape[0]):
        lj = li[j]
        if kind[lj] == AREA_RECT:
            r = rows[j]
            rect_light.cosines_row(tab[lj, _CORNER:_CORNER + 3], tab[lj, _U:_U + 3], tab[lj, _V:_V + 3],
                                   tab[lj, _EZ:_EZ + 3], tab[lj, _SU], tab[lj, _SV], np.float64(p[r, 0]),
                                   np.float64(p[r, 1]), np.float64(p[r, 2]), cosines, j)


@njit
def _pdf_kernel(kind, tab, p, wi, rows, li, g, pdf):
    """light_pdf of the sized light li[j] for the ray rows[j] of p, wi (float32 out); ``g``: the
    rectangles' interior angles there."""
    inv_4pi = 1.0 / (4 * np.pi)
    for j in range(rows.shape[0]):
        r, lj = rows[j], li[j]
        k = kind[lj]
        px, py, pz = np.float64(p[r, 0]), np.float64(p[r, 1]), np.float64(p[r, 2])
        dx, dy, dz = np.float64(wi[r, 0]), np.float64(wi[r, 1]), np.float64(wi[r, 2])
        out = 0.0
        if k == AREA_RECT or k == AREA_DISK:
            t, ok, cos_l = _area_row(tab, lj, k == AREA_RECT, px, py, pz, dx, dy, dz, np.inf)
            if ok:
                area = tab[lj, _AREA]
                if k == AREA_RECT:
                    z0 = rect_light.frame_row(tab[lj, _CORNER:_CORNER + 3], tab[lj, _U:_U + 3], tab[lj, _V:_V + 3],
                                              tab[lj, _EZ:_EZ + 3], tab[lj, _SU], tab[lj, _SV], px, py, pz)[4]
                    s = rect_light.solid_angle_row(g[j, 0], g[j, 1], g[j, 2], g[j, 3], z0)[1]
                    out = t * t / (area * cos_l) if s < rect_light.MIN_SOLID_ANGLE else 1.0 / s
                else:
                    out = t * t / (area * cos_l)
        elif k == POINT or k == SPOT:
            rad = tab[lj, _R]
            cx, cy, cz = tab[lj, _P], tab[lj, _P + 1], tab[lj, _P + 2]
            if tab[lj, _SPH] != 0.0:  # _sphere_geometry and the cone test
                tx, ty, tz = cx - px, cy - py, cz - pz
                dd = np.sqrt(tx * tx + ty * ty + tz * tz)
                dm = rect_light.np_maximum(dd, 1e-30)
                if dd <= rad:
                    out = inv_4pi
                else:
                    s2 = rad / dm
                    s2 = rect_light.np_clip(s2 * s2, 0.0, 1.0)
                    omc = s2 / (1.0 + np.sqrt(1.0 - s2))
                    if dx * (tx / dm) + dy * (ty / dm) + dz * (tz / dm) >= 1.0 - omc - _CONE_SLACK:
                        out = 1.0 / (2 * np.pi * omc)
            else:  # the disk facing p
                tx, ty, tz = px - cx, py - cy, pz - cz
                dd = rect_light.np_maximum(np.sqrt(tx * tx + ty * ty + tz * tz), 1e-300)
                nx, ny, nz = tx / dd, ty / dd, tz / dd
                t, ok = _plane_row(px, py, pz, dx, dy, dz, cx, cy, cz, nx, ny, nz, np.inf)
                if ok:
                    qx, qy, qz = px + t * dx - cx, py + t * dy - cy, pz + t * dz - cz
                    cos_l = -(dx * nx + dy * ny + dz * nz)
                    if qx * qx + qy * qy + qz * qz <= rad * rad and cos_l > 0:
                        out = t * t / (np.pi * rad * rad * cos_l)
        pdf[j] = np.float32(out)
