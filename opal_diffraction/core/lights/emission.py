"""Emission of light paths, per light kind: where the light pass's paths start, which way they
go, what they carry, and how much power each emitter sends towards the casters.

The light pass (core/integrators/light/, docs/physics.md section 4.1) has L + 2 emitters: the
L lights, the emissive meshes (index L, mesh_lights.MeshLights) and the world (index L + 1).
``emit`` is the one interface: b path starts from one emitter, as origins, unit directions and
weights (coefficients over basis spectra). Every kind aims at the casters' bounding spheres
(core/lights/aiming.py):

- a point or spot light: a direction in the mixture of the casters' cones, the spot's
  smoothstep cone applied along it; with a radius, a uniform point on its sphere first
  (``_emit_sized_point``, docs/physics.md section 7.7);
- a sun: a point on the disk one caster's sphere casts across its beam, far out along it; with
  an angle, a direction uniform in its cone first (``_emit_sun_cone``, section 7.7);
- an area light (rectangle or disk): a uniform point on it, then a direction towards a caster;
- the emissive triangles: a point chosen by area x luminance, then a direction towards a caster,
  either side (``emit_mesh``, section 7.7);
- the world (a uniform colour or an environment map, core/lights/environment.py): a direction
  from its distribution, then a point on a caster's disk across it (``emit_world``, section 7.9).

Paths start with weight (emitted radiometric quantity / pdf; the light pass divides by the
emitter's path count), so the caustic map holds flux in W per wavelength sample. A lamp's or the
world's white paths carry their weight as coefficients over shared spectra (the lamp's
spectrum; the map's R, G, B spectra) until a tint or dispersion needs spectra
(transport.Rays.basis, docs/physics.md section 4.7). The emitters share the path budget in
proportion to the power they send towards the casters (``light_budgets``, ``mesh_light_budget``,
``world_budget``).

The samplers of core/lights/aiming.py have compiled twins (core/util/jit.py), and so has the
emissive meshes' spectral weights (``_scaled_rows_kernel``), on the random numbers the reference draws.
"""

from __future__ import annotations

import numpy as np

from .aiming import CasterObjects, caster_cones, caster_disk_points, sample_cones, sample_towards_casters
from .sources import AREA_DISK, AREA_RECT, POINT, SPOT, SUN, sample_cone, smoothstep, spot_mask
from ..util.jit import kernels_enabled, njit

__all__ = ["emit", "emit_light", "emit_mesh", "emit_world", "light_budgets", "mesh_light_budget",
           "world_luminance", "world_budget"]


def emit(prepared, source: int, b: int, rng):
    """b path starts from the light pass's emitter ``source`` (0 .. L - 1: the lights, L: the
    emissive meshes, L + 1: the world): origins (B, 3), unit directions (B, 3), coefficients
    (B, k) over basis spectra (k, n), or basis None: the coefficients are spectra (B, n)."""
    if source == len(prepared.lights):  # the emissive meshes: a spectrum per path
        o, d, coeff = emit_mesh(prepared, b, rng)
        basis = None
    elif source > len(prepared.lights):  # the world: coefficients over its basis spectra
        o, d, coeff, basis = emit_world(prepared, b, rng)
    else:  # a light: a scalar per path times the light's spectrum
        o, d, weight = emit_light(prepared, source, b, rng)
        coeff, basis = weight[:, None], prepared.lights.spectrum[source][None, :]
    return o, d, coeff, basis


def emit_light(prepared, li: int, b: int, rng):
    """b path starts from light li: origins, unit directions, scalar weights (1 / pdf, times
    the geometric terms; the light's spectrum is applied by the caller)."""
    lights, obj = prepared.lights, prepared.light_targets.objects
    k = int(lights.kind[li])
    if k == SUN and lights.sun_half[li] > 0:
        return _emit_sun_cone(prepared, li, b, rng)
    if k in (POINT, SPOT) and lights.radius[li] > 0:
        return _emit_sized_point(prepared, li, b, rng)
    if k == SUN:
        d = np.broadcast_to(lights.direction[li], (b, 3))
        pts, pdf = caster_disk_points(obj, d, rng)
        return pts - _far_distance(prepared) * d, d.copy(), np.where(pdf > 0, 1.0 / np.maximum(pdf, 1e-300), 0.0)
    if k in (POINT, SPOT):
        origin = np.broadcast_to(lights.position[li], (b, 3))
        axis, cos_max, omega = caster_cones(lights.position[li][None, :], obj)
        axis, cos_max, omega = (np.broadcast_to(x, (b,) + x.shape[1:]) for x in (axis, cos_max, omega))
        d, pdf = sample_cones(origin, omega, axis, cos_max, omega, rng)
        weight = 1.0 / np.maximum(pdf, 1e-300)  # intensity (in the spectrum) / pdf
        if k == SPOT:
            cos_axis = d @ lights.direction[li]
            ch, sm = lights.cos_half_spot[li], lights.spot_smooth[li]
            cone = (cos_axis > ch).astype(np.float64)
            if sm > 0:
                cone = cone * smoothstep((cos_axis - ch) / sm)
            weight = weight * cone
        return np.array(origin), d, weight
    # area lights: a uniform point on the emitter, then a direction towards an object
    r1, r2 = rng.random(b), rng.random(b)
    if k == AREA_RECT:
        a, c = (r1 - 0.5) * lights.size_u[li], (r2 - 0.5) * lights.size_v[li]
    else:
        rad, phi = np.sqrt(r1), 2 * np.pi * r2
        a, c = 0.5 * lights.size_u[li] * rad * np.cos(phi), 0.5 * lights.size_v[li] * rad * np.sin(phi)
    origin = lights.position[li] + a[:, None] * lights.axis_u[li] + c[:, None] * lights.axis_v[li]
    d, pdf = sample_towards_casters(origin, obj, rng)
    cos_l = d @ lights.direction[li]
    # radiance (in the spectrum) * cos * area / pdf(direction)   (pdf of the point: 1 / area)
    weight = np.where(cos_l > 0, cos_l * lights.area[li] / np.maximum(pdf, 1e-300), 0.0)
    return origin + prepared.offset_base * d, d, weight


def _far_distance(prepared) -> float:
    """Sun paths start this far from the origin: well outside the scene, in its own units (an
    absolute distance would swamp a millimetre scene's coordinates in float32)."""
    return 4.0 * (float(np.max(np.abs(prepared.scene.vertices))) + prepared.extent)


def _emit_sun_cone(prepared, li: int, b: int, rng):
    """A sun with an angle: a direction uniform in its cone (pdf 1 / (2 pi (1 - cos h))), then
    a point on the disk one caster's sphere casts across that direction (object chosen by its
    disk area), with the mixture pdf per unit area. Weight = (radiance / S) / (pdf_dir pdf_area)
    = g_sun / pdf_area with g_sun = 2 / (1 + cos h) (docs/physics.md section 7.7)."""
    lights, obj = prepared.lights, prepared.light_targets.objects
    omc = float(lights.sun_omc[li])
    d = sample_cone(lights.direction[li], omc, rng, b)  # travel directions (B, 3)
    pts, pdf = caster_disk_points(obj, d, rng)
    weight = np.where(pdf > 0, (2.0 / (2.0 - omc)) / np.maximum(pdf, 1e-300), 0.0)
    return pts - _far_distance(prepared) * d, d, weight


def _emit_sized_point(prepared, li: int, b: int, rng):
    """A point or spot light with a radius: a uniform point on its sphere (pdf 1 / (4 pi r^2)),
    then a direction towards a caster (the mixture cone pdf), outward only. Radiance I / (pi r^2)
    (in the spectrum: I), so weight = 4 cos_l / pdf_dir, times the spot mask along the direction
    (docs/physics.md section 7.7). A soft-falloff light (a disk facing each shading point) is
    emitted as the sphere of the same radius: the same intensity, and the same cone seen from a
    caster to first order in r / distance."""
    lights, obj = prepared.lights, prepared.light_targets.objects
    r = float(lights.radius[li])
    nrm = sample_cone(np.array([0.0, 0.0, 1.0]), 2.0, rng, b)  # uniform on the sphere
    q = lights.position[li] + r * nrm
    d, pdf = sample_towards_casters(q, obj, rng)
    cos_l = np.einsum("ij,ij->i", d, nrm)
    weight = np.where((cos_l > 0) & (pdf > 0), 4.0 * cos_l / np.maximum(pdf, 1e-300), 0.0)
    if int(lights.kind[li]) == SPOT:
        weight = weight * spot_mask(lights, li, d)
    return q + prepared.offset_base * d, d, weight


def emit_mesh(prepared, b: int, rng):
    """Paths from the emissive triangles (prepared.mesh_lights): a triangle by area x luminance
    and a uniform point on it (area pdf p_A), a direction towards a caster (mixture cone pdf,
    either side: the emitters are two-sided). Returns origins, directions and spectral weights
    (B, n) = L_e |cos_l| / (p_A pdf_dir) (docs/physics.md section 7.7)."""
    ml, obj = prepared.mesh_lights, prepared.light_targets.objects
    q, j, pa = ml.sample_points(rng, b)
    d, pdf = sample_towards_casters(q, obj, rng)
    n = ml.normal[j]
    cos_s = np.einsum("ij,ij->i", d, n)
    scalar = np.where((pdf > 0) & (cos_s != 0), np.abs(cos_s) / np.maximum(pa * pdf, 1e-300), 0.0)
    tri = ml.tri[j]
    eps = prepared.tri_offset[tri].astype(np.float64)
    origin = q + (np.sign(cos_s) * eps)[:, None] * n  # off the emitter, on the side the path leaves
    mat = prepared.tri_material[tri]
    if kernels_enabled():  # the (B, n) weights in one pass, without the gathered (B, n) spectra
        out = np.empty((b, prepared.materials.emission.shape[1]))
        _scaled_rows_kernel(np.ascontiguousarray(prepared.materials.emission), np.ascontiguousarray(mat, np.int64),
                            np.ascontiguousarray(scalar, np.float64), out)
        return origin, d, out
    emission = prepared.materials.emission[mat]
    return origin, d, emission * scalar[:, None]


@njit
def _scaled_rows_kernel(table, rows, scale, out):
    """out[i] = table[rows[i]] * scale[i] in float64 (emit_mesh's weights: NumPy's promotion, the same bits)."""
    for i in range(len(rows)):  # loop over paths
        for k in range(table.shape[1]):
            out[i, k] = np.float64(table[rows[i], k]) * scale[i]


def emit_world(prepared, b: int, rng):
    """b path starts from the world (docs/physics.md section 7.9): a direction w towards the sky
    from the map's distribution (uniform over the sphere for a uniform world), then a point on
    the disk one caster object's bounding sphere casts across w (the object chosen by disk
    area, as for a SUN), the path starting far out along w and travelling along -w. Returns
    origins, directions, and the spectral weights L(w) / pdf(w) / pdf_A(point) (the flux of the
    world's radiance through the disks, unbiased: no clamping, no cut-off) as coefficients
    (B, k) over basis spectra (k, n): a uniform world's spectrum (k = 1), or for a map the
    spectra of pure red, green and blue (k = 3), since the RGB-to-illuminant upsampling
    (spectrum.SpectralConverter.illuminant_from_rgb: max(rgb) times a basis combination of
    rgb / max(rgb)) is linear in non-negative RGB."""
    obj = prepared.light_targets.objects
    env = prepared.environment
    if env is None:  # uniform world: directions uniform on the sphere
        z = 1.0 - 2.0 * rng.random(b)
        phi = 2 * np.pi * rng.random(b)
        s = np.sqrt(np.maximum(0.0, 1.0 - z * z))
        towards_sky = np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)
        coeff = np.full((b, 1), 4 * np.pi)
        basis = prepared.world_spectrum.astype(np.float64)[None, :]
    else:
        towards_sky, pdf, rgb = env.sample(rng.random(b), rng.random(b))
        inv = np.where(pdf > 0, 1.0 / np.where(pdf > 0, pdf, 1.0), 0.0)
        coeff = np.maximum(rgb.astype(np.float64), 0.0) * inv[:, None]
        basis = prepared.conv.illuminant_from_rgb(np.eye(3))  # (3, n): pure R, G, B
    pts, pdf_a = caster_disk_points(obj, towards_sky, rng)
    o = pts + _far_distance(prepared) * towards_sky
    weight = np.where(pdf_a > 0, 1.0 / np.maximum(pdf_a, 1e-300), 0.0)
    return o, -towards_sky, coeff * weight[:, None], basis


def light_budgets(lights, obj: CasterObjects, conv) -> np.ndarray:
    """Estimated luminous power each light sends towards the casters (0: none)."""
    out = np.zeros(len(lights))
    if len(obj) == 0:
        return out
    lum = lights.spectrum @ conv.cmf_weights[:, 1].astype(np.float32)
    for li in range(len(lights)):  # loop over lights
        k = int(lights.kind[li])
        if k == SUN:
            out[li] = lum[li] * np.sum(np.pi * obj.radius**2)
            continue
        axis, cos_max, omega = caster_cones(lights.position[li][None, :], obj)
        omega = omega[0]
        if k == SPOT:  # objects entirely outside the spot's cone get nothing
            ang = np.arccos(np.clip(axis[0] @ lights.direction[li], -1, 1))
            half = np.arccos(np.clip(cos_max, -1, 1))
            omega = np.where(ang - half > np.arccos(lights.cos_half_spot[li]), 0.0, omega)
        if k in (AREA_RECT, AREA_DISK):
            front = (obj.centre - lights.position[li]) @ lights.direction[li] > -obj.radius
            extent = np.hypot(lights.size_u[li], lights.size_v[li])
            omega = np.where(front, omega, 0.0)
            out[li] = lum[li] * lights.area[li] * np.sum(omega) / np.pi if extent > 0 else 0.0
            continue
        out[li] = lum[li] * np.sum(omega)
    return out


def mesh_light_budget(mesh_lights, obj: CasterObjects, max_emitters: int = 16384) -> float:
    """Estimated luminous power the emissive triangles send towards the casters, as for area
    lights: sum over triangles of Y A Omega / pi (Omega: the casters' cones from the triangle's
    centroid). Over at most ``max_emitters`` triangles (an evenly spaced subset, rescaled)."""
    if mesh_lights is None or len(obj) == 0:
        return 0.0
    e = len(mesh_lights)
    step = max(1, -(-e // max_emitters))
    sel = np.arange(0, e, step)
    centroid = mesh_lights.v0[sel] + (mesh_lights.e1[sel] + mesh_lights.e2[sel]) / 3.0
    _, _, omega = caster_cones(centroid, obj)
    part = float(np.sum(mesh_lights.weight[sel] * omega.sum(axis=1)) / np.pi)
    return part * float(mesh_lights.weight.sum()) / max(float(mesh_lights.weight[sel].sum()), 1e-300)


def world_luminance(world_spectrum, conv) -> float:
    """The world's mean luminance, from ``world_spectrum`` (n,) its mean radiance (None: a black world)."""
    return 0.0 if world_spectrum is None else float(np.asarray(world_spectrum, np.float64) @ conv.cmf_weights[:, 1])


def world_budget(world_lum: float, obj: CasterObjects) -> float:
    """The world's power through the casters' disks: integral of L over the sphere x sum pi r^2."""
    return 4 * np.pi * world_lum * float(np.sum(np.pi * obj.radius**2)) if len(obj) else 0.0
