"""Blender's Sky Texture (core/materials/sky_texture.py; docs/physics.md section 7.12) against
independent computations: the optical depths of both atmospheres by fine numerical integration
of their density profiles, Cycles' folding of the sun's position, the sun lamp's irradiance
against the closed form of a limb-darkened disc, an empty atmosphere, and the shader-program op.
(The tables themselves against Cycles' renders: tests/blender/test_world_nodes_cycles.py.)"""

from __future__ import annotations

import math

import numpy as np
import pytest

from opal_diffraction.core.materials import sky_texture as S
from opal_diffraction.core.materials.shader_eval import evaluate
from opal_diffraction.core.scene.shader_programs import ProgramBuilder, program_problems

try:
    _trapezoid = np.trapezoid
except AttributeError:  # NumPy 1
    _trapezoid = np.trapz


def params(sky_type="MULTIPLE_SCATTERING", **kw):
    base = dict(sun_disc=True, sun_size=0.009512, sun_intensity=1.0, sun_elevation=math.radians(30),
                sun_rotation=math.radians(40), altitude=100.0, air=1.0, aerosol=1.0, ozone=1.0)
    base.update(kw)
    return S.sky_params(sky_type, **base)


def test_sun_position_is_folded_as_cycles_simplify_settings():
    """Elevation 100 degrees is the sun 80 degrees up on the other side (rotation + pi); the
    rotation becomes 2 pi - rotation; rotation 0 puts the sun towards +Y (Blender's north)."""
    p = params(sun_elevation=math.radians(100), sun_rotation=0.3)
    assert p.elevation == pytest.approx(math.radians(80))
    assert p.rotation == pytest.approx(2 * math.pi - (0.3 + math.pi))
    q = params(sun_elevation=math.radians(20), sun_rotation=0.0)
    assert S.sun_direction(q) == pytest.approx([0.0, math.cos(math.radians(20)), math.sin(math.radians(20))], abs=1e-12)
    r = params(sun_elevation=math.radians(20), sun_rotation=math.radians(90))  # clockwise from north: +X
    assert S.sun_direction(r) == pytest.approx([math.cos(math.radians(20)), 0.0, math.sin(math.radians(20))], abs=1e-12)
    assert params(sun_size=0.0).sun_size == 0.0005  # get_sun_size's floor


def test_multiple_scattering_transmittance_is_the_optical_depth_of_its_profiles():
    """Straight up from sea level the transmittance is exp(-integral of the extinction over the
    100 km atmosphere). Molecules and ozone (smooth on the steps' 1.56 km): the model's 64-step
    midpoint rule against a 200 001-point trapezoid of the same profiles, relative 2e-3. The
    aerosols' 0.73 km scale height is coarser than the steps: their depth is the midpoint sum of
    an exponential in closed form, Delta e^(-Delta/2H) (1 - e^(-64 Delta/H)) / (1 - e^(-Delta/H))
    plus the constant background over 100 km, 17 % below the exact integral H: Blender's own
    quadrature, kept (Cycles renders it)."""
    h = np.linspace(0.0, 100.0, 200_001)
    for dens in ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)):
        ext = S._ms_coefficients(h, *dens)[0]
        expected = np.exp(-_trapezoid(ext, h, axis=0))
        got = S._ms_transmittance(np.array([1.0]), np.array([0.0]), dens)[0]
        assert got == pytest.approx(expected, rel=2e-3), dens
    step, scale = 100.0 / 64, S._MS_AER_HEIGHT
    midpoint = step * math.exp(-step / (2 * scale)) * (1 - math.exp(-64 * step / scale)) / (1 - math.exp(-step / scale))
    assert midpoint / scale == pytest.approx(0.832, abs=1e-3)
    column = S._MS_AER_BASE * midpoint + S._MS_AER_BACKGROUND * 100.0  # particles per km^2 (scaled)
    expected = np.exp(-(S._MS_AER_ABS + S._MS_AER_SCA) * column)
    got = S._ms_transmittance(np.array([1.0]), np.array([0.0]), (0.0, 1.0, 0.0))[0]
    assert got == pytest.approx(expected, rel=1e-9)
    # an empty atmosphere lets everything through
    assert S._ms_transmittance(np.array([0.3]), np.array([0.2]), (0.0, 0.0, 0.0)) == pytest.approx(1.0)


@pytest.mark.slow
def test_empty_atmosphere_is_a_black_sky():
    for t in S.SKY_TYPES:
        p = params(t, air=0.0, aerosol=0.0, ozone=0.0)
        table = S.sky_table(p.multiple, p.elevation, p.altitude, p.air, p.aerosol, p.ozone)
        assert np.abs(table).max() < 1e-12, t


def test_single_scattering_optical_depth_quadrature():
    """Nishita's 8-node Gauss-Laguerre optical depth towards the zenith from sea level against the
    closed forms: Rayleigh H (1 - exp(-60 km / H)), Mie likewise, ozone the 30 km-wide tent's
    area 15 km (relative 2 %: eight nodes for an exponential over a 60 km ray; the ozone tent
    is the roughest, 10 %)."""
    depth = S._ss_optical_depth(np.array([[0.0, 0.0, S._SS_EARTH]]), np.array([[0.0, 0.0, 1.0]]))[0]
    top = S._SS_ATMOS - S._SS_EARTH
    assert depth[0] == pytest.approx(8e3 * (1 - math.exp(-top / 8e3)), rel=0.02)
    assert depth[1] == pytest.approx(1.2e3 * (1 - math.exp(-top / 1.2e3)), rel=0.02)
    assert depth[2] == pytest.approx(15e3, rel=0.1)


def test_sun_irradiance_is_the_limb_darkened_disc_integral():
    """The lamp's irradiance against the closed form of a disc of angular radius h with radiance
    L0 (1 - 0.6 (1 - sqrt(1 - (a / h)^2))) and a colour linear from bottom to top:
    E = L_centre * 2 pi * integral_0^h (0.4 + 0.6 sqrt(1 - (a/h)^2)) sin a da (the linear
    term cancels over the disc), the integral by a 100 001-point trapezoid."""
    for t in S.SKY_TYPES:
        p = params(t, sun_intensity=1.7)
        h = p.sun_size / 2
        a = np.linspace(0, h, 100_001)
        radial = 2 * math.pi * _trapezoid((0.4 + 0.6 * np.sqrt(np.maximum(1 - (a / h) ** 2, 0))) * np.sin(a), a)
        bottom, top = S.sun_pixels(p)
        centre = np.maximum((0.5 * (bottom + top)) @ S.XYZ_TO_REC709.T, 0) * 1.7
        assert S.sun_irradiance(p) == pytest.approx(centre * radial, rel=2e-3), t
    # below the horizon the single-scattering sun is dark; behind the earth any sun is
    assert not S.sun_irradiance(params("SINGLE_SCATTERING", sun_elevation=-0.1)).any()
    assert not S.sun_irradiance(params("MULTIPLE_SCATTERING", sun_elevation=-0.2)).any()


@pytest.mark.slow
def test_sun_disc_is_in_the_radiance_only_with_the_sun():
    p = params()
    d = S.sun_direction(p)[None, :]
    with_sun, without = S.sky_radiance(p, d), S.sky_radiance(p, d, with_sun=False)
    assert (with_sun - without) == pytest.approx(S.sun_disc_radiance(p, d))
    assert (with_sun > 1e3 * without).all()  # the disc outshines the sky around it
    off = np.array([[0.0, 0.0, 1.0]])
    assert S.sky_radiance(p, off) == pytest.approx(S.sky_radiance(p, off, with_sun=False))


def test_sky_op_in_a_program():
    """The program's sky op evaluates sky_radiance at its vector (float32) and is checked."""
    p = params("SINGLE_SCATTERING")
    b = ProgramBuilder("world")
    vec = b.op("coord", kind="generated")[0]
    sky = b.op("sky", [vec], with_sun=False, **p._asdict())[0]
    b.outputs = {"emission": sky}
    program = b.finish()
    assert program_problems(program) is None
    rng = np.random.default_rng(3)
    d = rng.normal(size=(50, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    got = evaluate(program, "emission", {"generated": d.astype(np.float32)}, len(d))
    assert got == pytest.approx(S.sky_radiance(p, d.astype(np.float32), with_sun=False), rel=1e-5, abs=1e-6)
    bad = ProgramBuilder("world")
    v = bad.op("coord", kind="generated")[0]
    bad.outputs = {"emission": bad.op("sky", [v], with_sun=True, **dict(p._asdict(), altitude=float("nan")))[0]}
    assert "sky" in program_problems(bad.finish())


def test_preetham_zenith_is_the_papers_zenith_luminance_and_chromaticity():
    """Preetham, Shirley & Smits 1999 (appendix A.2): the Perez distributions are normalised so
    that the zenith sees Y_z = (4.0453 T - 4.9710) tan chi - 0.2155 T + 2.4192 (kcd/m^2; Cycles
    scales by 0.06), chi = (4/9 - T/120)(pi - 2 theta_s), and the zenith chromaticity x_z of the
    paper's cubic in theta_s; the radiance turned back into XYZ must give them."""
    t, theta_s = 3.0, 0.7
    sun = [math.sin(theta_s) * 0.6, math.sin(theta_s) * 0.8, math.cos(theta_s)]
    rgb = S.preetham_radiance(sun, t, np.array([[0.0, 0.0, 1.0]]))[0]
    xyz = np.linalg.solve(S.XYZ_TO_REC709, rgb)
    chi = (4 / 9 - t / 120) * (math.pi - 2 * theta_s)
    y_z = ((4.0453 * t - 4.9710) * math.tan(chi) - 0.2155 * t + 2.4192) * 0.06
    x_z = (np.array([t * t, t, 1]) @ np.array([[0.00166, -0.00375, 0.00209, 0],
                                                [-0.02903, 0.06377, -0.03202, 0.00394],
                                                [0.11693, -0.21196, 0.06052, 0.25886]])
           @ np.array([theta_s ** 3, theta_s ** 2, theta_s, 1]))
    assert xyz[1] == pytest.approx(y_z, rel=1e-9)
    assert xyz[0] / xyz.sum() == pytest.approx(x_z, rel=1e-9)
