"""Light sources: emission spectra in Cycles' units and direct-lighting samples.

Units (the contract the Blender layer matches against Cycles, docs/physics.md section 1.5):
- point / spot of power P (W): radiant intensity I = P / (4 pi) W/sr times the light's
  Y-normalised spectrum; a spot is the same point light masked by a smoothstep cone
  (Blender's ``spot_size`` full angle and ``spot_blend``);
- sun of strength S: irradiance S W/m^2 on a surface facing it;
- area (rectangle or disk) of power P: one-sided Lambertian emitter of radiance P / (pi A).

For a light at a shading point p we return the direction to the light, its distance, and a
geometric factor g such that the irradiance arriving at p (before the receiver's cosine) is
``g * spectrum``: point / spot g = cone / d^2, sun g = 1, area g = A cos_l / d^2 for one uniform
sample on the emitter (the Monte Carlo estimator with pdf 1/A).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .enums import LightKind
from .geometry import orthonormal_basis
from .scene import Lights
from .spectrum import SpectralConverter

__all__ = ["PreparedLights", "prepare_lights", "sample_light"]

POINT, SPOT, SUN, AREA_RECT, AREA_DISK = (int(k) for k in LightKind)


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

    def __len__(self):
        return len(self.kind)


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
        spectrum=(spec * unit[:, None]).astype(np.float32),
    )


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def sample_light(pl: PreparedLights, index: int, p: np.ndarray, rng: np.random.Generator):
    """One sample of light ``index`` seen from points p (B, 3).

    Returns (wi, dist, g): unit directions towards the light (B, 3), distances (inf for the sun)
    and the geometric factor g (B,) described in the module docstring (0 where the point is
    outside a spot cone or behind an area light).
    """
    k = int(pl.kind[index])
    b = len(p)
    f32 = np.float32
    if k == SUN:
        wi = np.broadcast_to(-pl.direction[index].astype(f32), (b, 3))
        return wi, np.full(b, np.inf, f32), np.ones(b, f32)
    if k in (POINT, SPOT):
        target = pl.position[index].astype(f32)
    else:
        r1, r2 = rng.random(b, f32), rng.random(b, f32)
        if k == AREA_RECT:
            a, c = (r1 - 0.5) * pl.size_u[index], (r2 - 0.5) * pl.size_v[index]
        else:  # uniform on an ellipse: concentric-free polar mapping is fine for uniform density
            rad, phi = np.sqrt(r1), 2 * np.pi * r2
            a, c = 0.5 * pl.size_u[index] * rad * np.cos(phi), 0.5 * pl.size_v[index] * rad * np.sin(phi)
        target = (pl.position[index] + a[:, None] * pl.axis_u[index] + c[:, None] * pl.axis_v[index]).astype(f32)
    to_light = target - p
    d2 = np.maximum(np.einsum("ij,ij->i", to_light, to_light), f32(1e-30))
    dist = np.sqrt(d2)
    wi = to_light / dist[:, None]
    if k in (POINT, SPOT):
        g = f32(1.0) / d2
        if k == SPOT:
            cos_axis = -(wi @ pl.direction[index].astype(f32))
            ch, sm = pl.cos_half_spot[index], pl.spot_smooth[index]
            cone = np.where(cos_axis > ch, 1.0, 0.0)
            if f32(sm) > 0:  # a blend band that is 0 in float32 is a hard edge
                cone = cone * _smoothstep((cos_axis - ch) / f32(sm))
            g = g * cone
        return wi, dist, g
    cos_l = -(wi @ pl.direction[index].astype(f32))
    g = np.where(cos_l > 0, cos_l * f32(pl.area[index]) / d2, f32(0.0))
    return wi, dist, g
