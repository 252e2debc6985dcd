"""Blender's Sky Texture (Blender 5.0): the Single and Multiple Scattering atmosphere models,
their precomputed sky tables and the kernel's lookup with the sun disc (docs/physics.md
section 7.12).

Ported from Blender 5.0's ``intern/sky/source/sky_multiple_scattering.cpp`` (Fernando García
Liñán's spectral sky: four wavelengths 630, 560, 490, 430 nm, molecular and aerosol scattering,
ozone absorption, a transmittance table of 256 x 64 cosines and heights, 64-step in-scattering
march with Hillaire's energy-conserving step integral, the fitted multiple-scattering and
ground terms), ``sky_single_scattering.cpp`` (Nishita's single scattering: 21 wavelengths
380-780 nm, Rayleigh, Mie and ozone, 32 steps, 8-node Gauss-Laguerre optical depth to the sun),
``sky_math.h`` (the ray-sphere distance) and Cycles' ``kernel/svm/sky.h`` (``sky_radiance``: the
sun disc with limb darkening 0.6 between the bottom and top pixels, the ground fade of the
single-scattering model, the table lookup with the horizon-dense elevation mapping) with
``scene/shader_nodes.cpp`` (``SkyTextureNode::simplify_settings``: the sun's elevation folded
into [-pi/2, pi/2] and its rotation into 2 pi - rotation; ``get_sun_size``; the 512 x 256 table of
``scene/image_sky.cpp``, read LINEAR with EXTEND). Arithmetic is float64 here where Blender
uses float32: the tables agree to ~1e-6 relative, far below the renders' noise.

The tables are XYZ; ``XYZ_TO_REC709`` turns them into linear Rec.709 as Cycles'
``xyz_to_rgb_clamped`` does for a Rec.709 working space, negative channels clamped to 0.
Preetham (Preetham, Shirley & Smits 1999, "A Practical Analytic Model for Daylight": Perez
distributions of x, y and Y with turbidity-linear coefficients, the zenith values of
``sky_texture_precompute_preetham`` in Cycles' scene/shader_nodes.cpp and the kernel's
``sky_radiance_preetham``) is ported too; Hosek / Wilkie (its fitted data tables) is not (the
caller warns).
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import numpy as np

__all__ = ["SKY_TYPES", "TABLE_WIDTH", "TABLE_HEIGHT", "XYZ_TO_REC709", "SkyParams", "sky_params",
           "sky_table", "sun_pixels", "earth_intersection_angle", "sky_radiance", "sun_direction",
           "sun_disc_radiance", "sun_irradiance", "preetham_radiance"]

#: The sky types read here (Blender 5.0 enum names).
SKY_TYPES = ("SINGLE_SCATTERING", "MULTIPLE_SCATTERING")
#: Cycles' sky table (scene/image_sky.cpp, Blender 5.0).
TABLE_WIDTH, TABLE_HEIGHT = 512, 256

#: CIE XYZ -> linear Rec.709 (D65), the matrix of Blender's default configuration.
XYZ_TO_REC709 = np.array([[3.2404542, -1.5371385, -0.4985314],
                          [-0.9692660, 1.8760108, 0.0415560],
                          [0.0556434, -0.2040259, 1.0572252]])

_PI_2 = np.pi / 2
_TWO_PI = 2 * np.pi

# ------------------------------------------------------------------ multiple scattering constants
_MS_EARTH = 6371.0          # km
_MS_THICK = 100.0           # km
_MS_ATMOS = _MS_EARTH + _MS_THICK
_MS_GROUND_ALBEDO = 0.3
_MS_G = 0.8
_MS_T_STEPS = 64
_MS_S_STEPS = 64
_MS_LUT_X, _MS_LUT_Y = 256, 64
_MS_SUN_IRR = np.array([1.679, 1.828, 1.986, 1.307])
_MS_MOL_SCAT = np.array([6.605e-3, 1.067e-2, 1.842e-2, 3.156e-2])
_MS_OZONE_CS = np.array([3.472e-25, 3.914e-25, 1.349e-25, 11.03e-27])
_MS_OZONE_DOBSON = 334.5
_MS_AER_ABS = np.array([2.8722e-24, 4.6168e-24, 7.9706e-24, 1.3578e-23])
_MS_AER_SCA = np.array([1.5908e-22, 1.7711e-22, 2.0942e-22, 2.4033e-22])
_MS_AER_BASE = 1.3681e20
_MS_AER_BACKGROUND = 2e6
_MS_AER_HEIGHT = 0.73
#: The four wavelengths' spectral radiance -> XYZ (rows: wavelengths).
_MS_SPECTRAL_XYZ = np.array([[53.386917738564668023, 22.981337506691024754, 0.0],
                             [43.904844466369358263, 71.347795700053393866, 0.102506867965741307],
                             [1.6137278251608962005, 18.422960591455485011, 31.742921188390805758],
                             [20.762668673810577145, 2.3614213523314368527, 110.48009643252140334]])


def _ray_sphere(pos, d, radius):
    """sky_math.h ``ray_sphere_intersection`` for origins pos (..., 3) and directions d (..., 3):
    the distance to the sphere, -1 when it is missed or behind."""
    b = np.sum(pos * d, axis=-1)
    c = np.sum(pos * pos, axis=-1) - radius * radius
    disc = b * b - c
    root = np.sqrt(np.maximum(disc, 0.0))
    t = np.where(disc >= b * b, -b + root, -b - root)
    return np.where(((c > 0) & (b > 0)) | (disc < 0), -1.0, t)


def _ms_coefficients(h, air, aerosol, ozone):
    """(extinction, molecular scattering, aerosol scattering) (..., 4) at altitudes h (km)."""
    h = np.asarray(h, np.float64)[..., None]
    aer = _MS_AER_BASE * (np.exp(-h / _MS_AER_HEIGHT) + _MS_AER_BACKGROUND / _MS_AER_BASE) * aerosol
    log_h = np.log(np.maximum(h, 1e-4))
    o3 = 3.78547397e20 * np.exp(-(log_h - 3.22261) ** 2 * 5.55555555 - log_h)
    mol_abs = _MS_OZONE_CS * _MS_OZONE_DOBSON * o3 * ozone
    mol_sca = _MS_MOL_SCAT * np.exp(-0.07771971 * np.power(h, 1.16364243)) * air
    aer_sca = _MS_AER_SCA * aer
    return _MS_AER_ABS * aer + aer_sca + mol_abs + mol_sca, mol_sca, aer_sca


def _sun_dir(cos_theta):
    """sky_math.h ``sun_direction``: (-sin, 0, cos) (..., 3)."""
    c = np.asarray(cos_theta, np.float64)
    return np.stack([-np.sqrt(np.maximum(1.0 - c * c, 0.0)), np.zeros_like(c), c], axis=-1)


def _ms_transmittance(cos_theta, norm_alt, dens):
    """Transmittance (..., 4) to the sun at zenith cosine cos_theta from normalised altitude."""
    cos_theta, norm_alt = np.broadcast_arrays(np.asarray(cos_theta, np.float64), np.asarray(norm_alt, np.float64))
    sd = _sun_dir(cos_theta)
    r0 = _MS_EARTH + norm_alt * (_MS_ATMOS - _MS_EARTH)
    origin = np.stack([np.zeros_like(r0), np.zeros_like(r0), r0], axis=-1)
    t_step = _ray_sphere(origin, sd, _MS_ATMOS) / _MS_T_STEPS
    depth = np.zeros(cos_theta.shape + (4,))
    for step in range(_MS_T_STEPS):
        x = origin + sd * ((step + 0.5) * t_step)[..., None]
        alt = np.maximum(np.linalg.norm(x, axis=-1) - _MS_EARTH, 0.0)
        depth += _ms_coefficients(alt, *dens)[0] * t_step[..., None]
    return np.exp(-depth)


def _lut_lookup(lut, cos_theta, norm_alt):
    """``lookup_transmittance``: bilinear in the (cos, altitude) table, indices truncated."""
    u = np.clip(cos_theta * 0.5 + 0.5, 0.0, 1.0)
    v = np.clip(norm_alt, 0.0, 1.0)
    x, y = (_MS_LUT_X - 1) * u, (_MS_LUT_Y - 1) * v
    x1, y1 = x.astype(np.int64), y.astype(np.int64)
    x2, y2 = np.minimum(x1 + 1, _MS_LUT_X - 1), np.minimum(y1 + 1, _MS_LUT_Y - 1)
    fx, fy = (x - x1)[..., None], (y - y1)[..., None]
    bottom = lut[y1, x1] + fx * (lut[y1, x2] - lut[y1, x1])
    top = lut[y2, x1] + fx * (lut[y2, x2] - lut[y2, x1])
    return bottom + fy * (top - bottom)


@lru_cache(maxsize=4)
def _ms_lut(air: float, aerosol: float, ozone: float) -> np.ndarray:
    """The (64, 256, 4) transmittance table (``precompute_lut``)."""
    u = np.arange(_MS_LUT_X) / (_MS_LUT_X - 1)
    v = np.arange(_MS_LUT_Y) / (_MS_LUT_Y - 1)
    lut = _ms_transmittance(u[None, :] * 2 - 1, v[:, None], (air, aerosol, ozone))
    lut.flags.writeable = False
    return lut


def _ms_inscattering(lut, sun, origin, d, t_d, dens):
    """``get_inscattering`` for rays (N, 3) from ``origin`` (3,) over distances t_d (N,): (N, 4)."""
    cos_theta = -(d @ sun)
    mol_phase = (3.0 / 16.0) / np.pi * (1 + cos_theta * cos_theta)
    den = 1 + _MS_G * _MS_G + 2 * _MS_G * cos_theta
    aer_phase = (1 / (4 * np.pi)) * (1 - _MS_G * _MS_G) / (den * np.sqrt(den))
    dt = t_d / _MS_S_STEPS
    radiance = np.zeros((len(d), 4))
    trans = np.ones((len(d), 4))
    ms_colour = 0.02 * np.array([0.217, 0.347, 0.594, 1.0])
    to_sun_ground = _lut_lookup(lut, np.ones(1), np.zeros(1))  # x = last column, y = 0
    for i in range(_MS_S_STEPS):
        x = origin + d * ((i + 0.5) * dt)[:, None]
        r = np.linalg.norm(x, axis=1)
        alt = np.maximum(r - _MS_EARTH, 0.0)
        nh = alt / _MS_THICK
        mu = (x @ sun) / r
        ext, mol_sca, aer_sca = _ms_coefficients(alt, *dens)
        t_sun = _lut_lookup(lut, mu, nh)
        # lookup_multiscattering: ground bounce (2nd order) + the fitted multiple scattering
        omega = _TWO_PI * (1 - np.sqrt(1 - (_MS_EARTH / r) ** 2))
        t_ground = _lut_lookup(lut, mu, np.zeros_like(mu))
        t_ground_to_sample = to_sun_ground / _lut_lookup(lut, np.ones_like(nh), nh)
        l_ground = ((1 / (4 * np.pi)) * omega)[:, None] * (_MS_GROUND_ALBEDO / np.pi) * t_ground \
            * t_ground_to_sample * mu[:, None]
        l_ms = ms_colour * (1 / (1 + 5 * np.exp(-17.92 * mu)))[:, None]
        ms = l_ms + l_ground
        s = _MS_SUN_IRR * (mol_sca * (mol_phase[:, None] * t_sun + ms) + aer_sca * (aer_phase[:, None] * t_sun + ms))
        step_t = np.exp(-dt[:, None] * ext)
        radiance += trans * (s - s * step_t) / np.maximum(ext, 1e-7)
        trans *= step_t
    return radiance


def _ms_table(elevation, altitude, air, aerosol, ozone, width, height):
    lut = _ms_lut(air, aerosol, ozone)
    alt_km = min(max(altitude, 1.0), 99999.0) / 1000.0
    sun = _sun_dir(np.cos(_PI_2 - elevation))
    half = width // 2
    x = (np.arange(half) + 0.5) / width
    y = (np.arange(height) + 0.5) / height
    az = _TWO_PI * x[None, :]
    ll = y[:, None] * 2 - 1
    elev = np.copysign(ll * ll, ll) * _PI_2
    d = np.stack(np.broadcast_arrays(np.cos(elev) * np.cos(az), np.cos(elev) * np.sin(az), np.sin(elev)),
                 axis=-1).reshape(-1, 3)
    origin = np.array([0.0, 0.0, _MS_EARTH + alt_km])
    o = np.broadcast_to(origin, d.shape)
    atmos, ground = _ray_sphere(o, d, _MS_ATMOS), _ray_sphere(o, d, _MS_EARTH)
    t_d = np.where(ground < 0, atmos, ground)
    xyz = _ms_inscattering(lut, sun, origin, d, t_d, (air, aerosol, ozone)) @ _MS_SPECTRAL_XYZ
    left = xyz.reshape(height, half, 3)
    return np.concatenate([left, left[:, ::-1]], axis=1)


def _ms_sun(elevation, diameter, altitude, air, aerosol, ozone):
    alt_km = min(max(altitude, 1.0), 99999.0) / 1000.0
    half = diameter / 2
    solid = _TWO_PI * (1 - np.cos(half))
    cos = np.cos(_PI_2 - np.array([elevation - half, elevation + half]))
    t = _ms_transmittance(cos, np.full(2, alt_km / _MS_THICK), (air, aerosol, ozone))
    return (_MS_SUN_IRR * t / solid) @ _MS_SPECTRAL_XYZ


# ------------------------------------------------------------------ single scattering constants
_SS_RAYLEIGH_SCALE, _SS_MIE_SCALE, _SS_MIE_COEFF, _SS_MIE_G = 8e3, 1.2e3, 2e-5, 0.76
_SS_EARTH, _SS_ATMOS, _SS_STEPS = 6360e3, 6420e3, 32
_SS_STEP_LAMBDA = 20.0
_SS_IRRADIANCE = np.array([
    1.45756829855592995315, 1.56596305559738380175, 1.65148449067670455293, 1.71496242737209314555,
    1.75797983805020541226, 1.78256407885924539336, 1.79095108475838560302, 1.78541550133410664714,
    1.76815554864306845317, 1.74122069647250410362, 1.70647127164943679389, 1.66556087452739887134,
    1.61993437242451854274, 1.57083597368892080581, 1.51932335059305478886, 1.46628494965214395407,
    1.41245852740172450623, 1.35844961970384092709, 1.30474913844739281998, 1.25174963272610817455,
    1.19975998755420620867])
_SS_RAYLEIGH = np.array([
    5.424820087636473e-05, 4.418549866505454e-05, 3.635151910165377e-05, 3.017929012024763e-05,
    2.526320226989157e-05, 2.130859310621843e-05, 1.809838025320633e-05, 1.547057129129042e-05,
    1.330284977336850e-05, 1.150184784075764e-05, 9.99557429990163e-06, 8.72799973630707e-06,
    7.65513700977967e-06, 6.74217203751443e-06, 5.96134125832052e-06, 5.29034598065810e-06,
    4.71115687557433e-06, 4.20910481110487e-06, 3.77218381260133e-06, 3.39051255477280e-06,
    3.05591531679811e-06])
_SS_OZONE = np.array([
    3.25126849861e-09, 5.85395365047e-09, 1.977191155085e-08, 7.309568762914e-08, 2.0084561514287e-07,
    4.0383958096161e-07, 6.3551335912363e-07, 9.6707041180970e-07, 1.54797400424410e-06,
    2.09038647223331e-06, 2.46128056164565e-06, 2.73551299461512e-06, 2.15125863128643e-06,
    1.59051840791988e-06, 1.12356197979857e-06, 7.3527551487574e-07, 4.6450130357806e-07,
    3.3096079921048e-07, 2.2512612292678e-07, 1.4879129266490e-07, 1.6828623364192e-07])
#: CIE 1931 colour matching functions at 380, 400, ..., 780 nm (rows).
_SS_CMF = np.array([
    [0.00136800000, 0.00003900000, 0.00645000100], [0.01431000000, 0.00039600000, 0.06785001000],
    [0.13438000000, 0.00400000000, 0.64560000000], [0.34828000000, 0.02300000000, 1.74706000000],
    [0.29080000000, 0.06000000000, 1.66920000000], [0.09564000000, 0.13902000000, 0.81295010000],
    [0.00490000000, 0.32300000000, 0.27200000000], [0.06327000000, 0.71000000000, 0.07824999000],
    [0.29040000000, 0.95400000000, 0.02030000000], [0.59450000000, 0.99500000000, 0.00390000000],
    [0.91630000000, 0.87000000000, 0.00165000100], [1.06220000000, 0.63100000000, 0.00080000000],
    [0.85444990000, 0.38100000000, 0.00019000000], [0.44790000000, 0.17500000000, 0.00002000000],
    [0.16490000000, 0.06100000000, 0.00000000000], [0.04677000000, 0.01700000000, 0.00000000000],
    [0.01135916000, 0.00410200000, 0.00000000000], [0.00289932700, 0.00104700000, 0.00000000000],
    [0.00069007860, 0.00024920000, 0.00000000000], [0.00016615050, 0.00006000000, 0.00000000000],
    [0.00004150994, 0.00001499000, 0.00000000000]])
#: Gauss-Laguerre (8 nodes, scaled to the last node inside the atmosphere), weights times e^x.
_SS_NODES = np.array([0.006811185292, 0.03614807107, 0.09004346519, 0.1706680068, 0.2818362161,
                      0.4303406404, 0.6296271457, 0.9145252695])
_SS_WEIGHTS = np.array([0.01750893642, 0.04135477391, 0.06678839063, 0.09507698807, 0.1283416365,
                        0.1707430204, 0.2327233347, 0.3562490486])


def _ss_density(h):
    """(..., 3) Rayleigh, Mie and ozone density factors at heights h (m)."""
    return np.stack([np.exp(-h / _SS_RAYLEIGH_SCALE), np.exp(-h / _SS_MIE_SCALE),
                     np.maximum(0.0, 1.0 - np.abs(h - 25000.0) / 15000.0)], axis=-1)


def _ss_atmosphere_distance(pos, d):
    b = -2.0 * np.sum(d * -pos, axis=-1)
    c = np.sum(pos * pos, axis=-1) - _SS_ATMOS ** 2
    return (-b + np.sqrt(b * b - 4 * c)) / 2


def _ss_optical_depth(pos, d):
    """``ray_optical_depth``: (..., 3) optical depth factors from pos along d to the atmosphere's edge."""
    length = _ss_atmosphere_distance(pos, d)
    depth = 0.0
    for node, weight in zip(_SS_NODES, _SS_WEIGHTS):
        p = pos + (node * length)[..., None] * d
        depth = depth + _ss_density(np.linalg.norm(p, axis=-1) - _SS_EARTH) * weight
    return depth * length[..., None]


def _ss_spectrum(d, sun, origin, dens):
    """``single_scattering`` for rays d (N, 3): (N, 21) spectral radiance."""
    scale = np.asarray(dens, np.float64)
    length = _ss_atmosphere_distance(np.broadcast_to(origin, d.shape), d)
    seg_len = length / _SS_STEPS
    mu = d @ sun
    g2 = _SS_MIE_G ** 2
    ph_r = (0.1875 / np.pi) * (1 + mu * mu)
    ph_m = (3 * (1 - g2) * (1 + mu * mu)) / (8 * np.pi * (2 + g2) * np.power(1 + g2 - 2 * _SS_MIE_G * mu, 1.5))
    spectrum = np.zeros((len(d), len(_SS_IRRADIANCE)))
    depth = np.zeros((len(d), 3))
    p = origin + 0.5 * seg_len[:, None] * d
    ext_coeff = np.stack([_SS_RAYLEIGH, np.full_like(_SS_RAYLEIGH, 1.11 * _SS_MIE_COEFF), _SS_OZONE], axis=1)  # (21, 3)
    for _ in range(_SS_STEPS):
        h = np.linalg.norm(p, axis=1) - _SS_EARTH
        density = scale * _ss_density(h)
        depth += seg_len[:, None] * density
        # surface_intersection(P, sun): the earth between the point and the sun
        bq = -2.0 * np.sum(sun * -p, axis=1)
        cq = np.sum(p * p, axis=1) - _SS_EARTH ** 2
        lit = ~((sun[2] < 0) & (bq * bq - 4 * cq >= 0))
        light_depth = scale * _ss_optical_depth(p, np.broadcast_to(sun, p.shape))
        atten = np.exp(-(depth + light_depth) @ ext_coeff.T)  # (N, 21)
        scat = ph_r[:, None] * density[:, :1] * _SS_RAYLEIGH + (ph_m * density[:, 1] * _SS_MIE_COEFF)[:, None]
        spectrum += np.where(lit[:, None], atten * scat * _SS_IRRADIANCE * seg_len[:, None], 0.0)
        p = p + seg_len[:, None] * d
    return spectrum


def _geo_dir(lat, lon):
    lat, lon = np.broadcast_arrays(np.asarray(lat, np.float64), np.asarray(lon, np.float64))
    return np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], axis=-1)


def _ss_table(elevation, altitude, air, aerosol, ozone, width, height):
    alt = min(max(altitude, 1.0), 59999.0)
    half_w, half_h = width // 2, height // 2
    origin = np.array([0.0, 0.0, _SS_EARTH + alt])
    sun = _geo_dir(elevation, 0.0)
    out = np.zeros((height, width, 3))
    rows = np.arange(half_h + 1, height)
    lat = _PI_2 * (rows / half_h - 1.0) ** 2
    lon = _TWO_PI / width * np.arange(half_w) - np.pi
    d = _geo_dir(lat[:, None], lon[None, :]).reshape(-1, 3)
    xyz = (_ss_spectrum(d, sun, origin, (air, aerosol, ozone)) @ _SS_CMF) * _SS_STEP_LAMBDA
    left = xyz.reshape(len(rows), half_w, 3)
    out[half_h + 1:, :half_w] = left
    out[half_h + 1:, half_w:] = left[:, ::-1]  # the mirrored half
    return out


def _ss_sun(elevation, diameter, altitude, air, aerosol):
    alt = min(max(altitude, 1.0), 59999.0)
    half = diameter / 2
    solid = _TWO_PI * (1 - np.cos(half))
    lo, hi = max(elevation - half, 0.0), max(elevation + half, 0.0)
    if hi <= 0:
        return np.zeros((2, 3))
    origin = np.array([[0.0, 0.0, _SS_EARTH + alt]] * 2)
    depth = _ss_optical_depth(origin, _geo_dir(np.array([lo, hi]), 0.0))
    tr = _SS_RAYLEIGH * (depth[:, :1] * air) + 1.11 * _SS_MIE_COEFF * (depth[:, 1:2] * aerosol)
    return ((_SS_IRRADIANCE * np.exp(-tr) / solid) @ _SS_CMF) * _SS_STEP_LAMBDA


# ------------------------------------------------------------------ the node
class SkyParams(NamedTuple):
    """The node's parameters as the kernel reads them (see :func:`sky_params`); hashable."""

    multiple: bool
    sun_disc: bool
    sun_size: float
    sun_intensity: float
    elevation: float
    rotation: float
    altitude: float
    air: float
    aerosol: float
    ozone: float


def sky_params(sky_type: str, sun_disc: bool, sun_size: float, sun_intensity: float, sun_elevation: float,
               sun_rotation: float, altitude: float, air: float, aerosol: float, ozone: float) -> SkyParams:
    """The node's settings as the kernel reads them: the elevation folded into [-pi/2, pi/2]
    (the rotation turned by pi when it folds), the rotation r -> 2 pi - (r mod 2 pi)
    (``SkyTextureNode::simplify_settings``), the sun size at least 0.0005 rad (``get_sun_size``)."""
    if sky_type not in SKY_TYPES:
        raise ValueError(f"sky type {sky_type!r} is not one of {SKY_TYPES}")
    e, r = float(np.fmod(sun_elevation, _TWO_PI)), float(sun_rotation)
    if abs(e) >= np.pi:
        e -= np.copysign(2.0, e) * np.pi
    if e >= _PI_2 or e <= -_PI_2:
        e = np.copysign(np.pi, e) - e
        r += np.pi
    r = float(np.fmod(r, _TWO_PI))
    if r < 0:
        r += _TWO_PI
    r = _TWO_PI - r
    return SkyParams(*(sky_type == "MULTIPLE_SCATTERING", bool(sun_disc), max(float(sun_size), 0.0005),
                      float(sun_intensity), e, r, float(altitude), float(air), float(aerosol), float(ozone)))


@lru_cache(maxsize=8)
def sky_table(multiple: bool, elevation: float, altitude: float, air: float, aerosol: float,
              ozone: float) -> np.ndarray:
    """The (256, 512, 3) XYZ sky table Cycles precomputes (row 0 the lowest elevation), read-only."""
    fn = _ms_table if multiple else _ss_table
    t = fn(elevation, altitude, air, aerosol, ozone, TABLE_WIDTH, TABLE_HEIGHT)
    t.flags.writeable = False
    return t


def sun_pixels(p: SkyParams) -> np.ndarray:
    """(2, 3) XYZ radiance of the sun disc's bottom and top points (``precompute_sun``)."""
    if p.multiple:
        return _ms_sun(p.elevation, p.sun_size, p.altitude, p.air, p.aerosol, p.ozone)
    return _ss_sun(p.elevation, p.sun_size, p.altitude, p.air, p.aerosol)


def earth_intersection_angle(altitude: float) -> float:
    """The depression below the horizon at which the earth hides the sky (radians),
    ``SKY_earth_intersection_angle``."""
    return _PI_2 - float(np.arcsin(_MS_EARTH / (_MS_EARTH + altitude / 1000.0)))


def sun_direction(p: SkyParams) -> np.ndarray:
    """The unit direction towards the sun's centre (Cycles' spherical_to_direction(elevation -
    pi/2, rotation - pi/2))."""
    theta, phi = p.elevation - _PI_2, p.rotation - _PI_2
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def _table_lookup(table, x, y):
    """Bilinear lookup, texel centres at (i + 1/2) / N, EXTEND (indices clamped): (N, 3)."""
    h, w = table.shape[:2]
    fx, fy = x * w - 0.5, y * h - 0.5
    i0, j0 = np.floor(fx), np.floor(fy)
    tx, ty = (fx - i0)[:, None], (fy - j0)[:, None]
    i0, j0 = i0.astype(np.int64), j0.astype(np.int64)
    i1, j1 = np.clip(i0 + 1, 0, w - 1), np.clip(j0 + 1, 0, h - 1)
    i0, j0 = np.clip(i0, 0, w - 1), np.clip(j0, 0, h - 1)
    return (table[j0, i0] * (1 - tx) + table[j0, i1] * tx) * (1 - ty) + (table[j1, i0] * (1 - tx)
                                                                         + table[j1, i1] * tx) * ty


def _xyz_to_rgb(xyz):
    return np.maximum(xyz @ XYZ_TO_REC709.T, 0.0)


def _angle_between(a, b):
    """Cycles' precise_angle: 2 atan2(|a - b|, |a + b|)."""
    return 2 * np.arctan2(np.linalg.norm(a - b, axis=-1), np.linalg.norm(a + b, axis=-1))


def sun_disc_radiance(p: SkyParams, d: np.ndarray) -> np.ndarray:
    """(N, 3) linear Rec.709 radiance of the sun disc alone towards unit directions d (N, 3)
    (zero outside it, behind the earth, and below the horizon for single scattering), times
    the sun intensity: the kernel's disc branch."""
    d = np.asarray(d, np.float64).reshape(-1, 3)
    out = np.zeros((len(d), 3))
    if not p.sun_disc:
        return out
    sun = sun_direction(p)
    ang = _angle_between(d, sun[None, :])
    half = p.sun_size / 2
    elev_d = _PI_2 - np.arccos(np.clip(d[:, 2], -1, 1))
    inside = (ang < half) & (elev_d > -earth_intersection_angle(p.altitude))
    if not p.multiple:
        inside &= d[:, 2] >= 0
    if not inside.any():
        return out
    bottom, top = sun_pixels(p)
    y = ((elev_d[inside] - p.elevation) / p.sun_size) + 0.5
    xyz = bottom + y[:, None] * (top - bottom)
    limb = 1 - 0.6 * (1 - np.sqrt(np.maximum(1 - (ang[inside] / half) ** 2, 0.0)))
    out[inside] = _xyz_to_rgb(xyz) * limb[:, None] * p.sun_intensity
    return out


def sun_irradiance(p: SkyParams, rings: int = 48, sectors: int = 96) -> np.ndarray:
    """(3,) linear Rec.709 irradiance of the sun disc on a surface facing it: the kernel's disc
    radiance (:func:`sun_disc_radiance`: limb darkening, the bottom-to-top colour, hidden behind
    the earth) integrated over the disc, a midpoint rule in the angle from the centre and the
    azimuth about it, dω = sin α dα dψ. A sun lamp of this irradiance and the disc's angular
    diameter stands for the disc (the caller's)."""
    s = sun_direction(p)
    e1 = np.cross(s, [0.0, 0.0, 1.0]) if abs(s[2]) < 0.999 else np.array([1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(s, e1)
    half = p.sun_size / 2
    da, dp = half / rings, _TWO_PI / sectors
    a, psi = np.meshgrid((np.arange(rings) + 0.5) * da, (np.arange(sectors) + 0.5) * dp, indexing="ij")
    d = (np.cos(a)[..., None] * s + np.sin(a)[..., None] * (np.cos(psi)[..., None] * e1
                                                            + np.sin(psi)[..., None] * e2)).reshape(-1, 3)
    weight = (np.sin(a) * da * dp).reshape(-1)
    return (sun_disc_radiance(p, d) * weight[:, None]).sum(axis=0)


def sky_radiance(p: SkyParams, d: np.ndarray, with_sun: bool = True) -> np.ndarray:
    """(N, 3) float64 linear Rec.709 radiance of the Sky Texture towards directions d (N, 3) (the
    kernel's ``sky_radiance``); ``with_sun`` False leaves the sun disc out (it is then a lamp)."""
    d = np.asarray(d, np.float64).reshape(-1, 3)
    table = sky_table(p.multiple, p.elevation, p.altitude, p.air, p.aerosol, p.ozone)
    theta = np.arccos(np.clip(d[:, 2], -1, 1))
    phi = np.arctan2(d[:, 1], d[:, 0])
    elev_d = _PI_2 - theta
    x = (-phi - _PI_2 + p.rotation) / _TWO_PI
    x = x - np.floor(x)
    y = np.sqrt(np.abs(elev_d) / _PI_2) * np.copysign(1.0, elev_d) * 0.5 + 0.5
    rgb = _xyz_to_rgb(_table_lookup(table, x, y))
    if not p.multiple:
        below = d[:, 2] < 0
        if below.any():
            fade = np.where(d[:, 2] < -0.4, 0.0, np.power(np.maximum(1 + d[:, 2] * 2.5, 0.0), 3))
            ground = _xyz_to_rgb(_table_lookup(table, x, np.full(len(d), 0.508))) * fade[:, None]
            rgb = np.where(below[:, None], ground, rgb)
    if with_sun:
        rgb = rgb + sun_disc_radiance(p, d)
    return rgb


# ------------------------------------------------------------------ Preetham
def _perez(lam, theta, gamma):
    """Perez's sky distribution (1 + A e^(B / cos theta)) (1 + C e^(D gamma) + E cos^2 gamma)."""
    return (1 + lam[0] * np.exp(lam[1] / np.cos(theta))) * (1 + lam[2] * np.exp(lam[3] * gamma)
                                                            + lam[4] * np.cos(gamma) ** 2)


def _preetham_setup(sun_direction, turbidity):
    """(sun theta, sun phi, zenith (Y, x, y) over Perez at the zenith, Perez coefficients (3, 5))."""
    sx, sy, sz = (float(c) for c in sun_direction)
    theta, phi = float(np.arccos(np.clip(sz, -1, 1))), float(np.arctan2(sx, sy))
    t = float(turbidity)
    t2, th2, th3 = t * t, theta * theta, theta ** 3
    chi = (4.0 / 9.0 - t / 120.0) * (np.pi - 2 * theta)
    zen_y = ((4.0453 * t - 4.9710) * np.tan(chi) - 0.2155 * t + 2.4192) * 0.06
    zen_x = ((0.00166 * th3 - 0.00375 * th2 + 0.00209 * theta) * t2
             + (-0.02903 * th3 + 0.06377 * th2 - 0.03202 * theta + 0.00394) * t
             + (0.11693 * th3 - 0.21196 * th2 + 0.06052 * theta + 0.25886))
    zen_yy = ((0.00275 * th3 - 0.00610 * th2 + 0.00317 * theta) * t2
              + (-0.04214 * th3 + 0.08970 * th2 - 0.04153 * theta + 0.00516) * t
              + (0.15346 * th3 - 0.26756 * th2 + 0.06670 * theta + 0.26688))
    cfg = np.array([[0.1787 * t - 1.4630, -0.3554 * t + 0.4275, -0.0227 * t + 5.3251, 0.1206 * t - 2.5771,
                     -0.0670 * t + 0.3703],
                    [-0.0193 * t - 0.2592, -0.0665 * t + 0.0008, -0.0004 * t + 0.2125, -0.0641 * t - 0.8989,
                     -0.0033 * t + 0.0452],
                    [-0.0167 * t - 0.2608, -0.0950 * t + 0.0092, -0.0079 * t + 0.2102, -0.0441 * t - 1.6537,
                     -0.0109 * t + 0.0529]])
    zen = np.array([zen_y, zen_x, zen_yy]) / np.array([_perez(c, 0.0, theta) for c in cfg])
    return theta, phi, zen, cfg


def preetham_radiance(sun_direction, turbidity: float, d: np.ndarray) -> np.ndarray:
    """(N, 3) linear Rec.709 radiance of the Preetham sky (no sun disc) towards directions d (N, 3):
    Y, x, y from Perez's distribution of the view's zenith angle (clamped 0.001 rad above the
    horizon) and its angle gamma to the sun, xyY -> XYZ -> Rec.709 clamped at 0."""
    d = np.asarray(d, np.float64).reshape(-1, 3)
    s_theta, s_phi, zen, cfg = _preetham_setup(sun_direction, turbidity)
    theta = np.arccos(np.clip(d[:, 2], -1, 1))
    phi = -np.arctan2(d[:, 1], d[:, 0]) + _PI_2
    cos_psi = np.sin(theta) * np.sin(s_theta) * np.cos(s_phi - phi) + np.cos(theta) * np.cos(s_theta)
    gamma = np.arccos(np.clip(cos_psi, -1, 1))
    theta = np.minimum(theta, _PI_2 - 0.001)
    big_y = zen[0] * _perez(cfg[0], theta, gamma)
    x = zen[1] * _perez(cfg[1], theta, gamma)
    y = zen[2] * _perez(cfg[2], theta, gamma)
    safe_y = np.where(y != 0, y, 1.0)
    xx = np.where(y != 0, x / safe_y * big_y, 0.0)
    zz = np.where((y != 0) & (big_y != 0), (1 - x - y) / safe_y * big_y, 0.0)
    return _xyz_to_rgb(np.stack([xx, big_y, zz], axis=1))
