"""The light paths' adjoint shading-normal factor (core/integrators/light/adjoint_shading.py,
docs/physics.md section 4.6) against closed forms of radiance transport about a shading normal.

A collimated sun beam E (W/m^2) meets a 1 m^2 surface whose geometric normal n_g is +z and whose
shading normal n_s is tilted by ALPHA; every bounce about n_s. What a path tracer of that surface
(radiance, the eye pass's transport) puts on a diffuse receiver, as flux:
- a mirror: the reflected beam keeps the sun's perpendicular irradiance E (a mirror maps the
  sun's solid angle one to one about any normal), through a cross-section A |r . n_g|:
  flux E A |r . n_g|;
- glass entered from above: radiance (1 - F) (n_t/n_i)^2 L about n_s, solid angles
  dw_t cos_t n_t^2 = dw_i cos_i n_i^2 about n_s, so perpendicular irradiance (1 - F) E cos_i / cos_t
  (cosines about n_s) through the cross-section A |t . n_g|.
Light paths without the factor conserve the flux E A |w_l . n_g| of every bounce instead (the
old behaviour, within 23 % resp. 4 % of these): the tests tell the two apart by many sigma.
"""

import numpy as np
import pytest

from opal_diffraction.core.integrators.light.adjoint_shading import adjoint_factor, dielectric_normal_used
from opal_diffraction.core.integrators.light.light_pass import run_light_pass
from opal_diffraction.core.integrators.light.walker import LightWalker
from opal_diffraction.core.render.plan import plan_render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.spectral.optics import fresnel_dielectric

ALPHA = np.radians(20.0)
NS = np.array([0.0, np.sin(ALPHA), np.cos(ALPHA)])  # the tilted shading normal, n_g = +z
E = 2.0  # the sun's irradiance, W/m^2 (Lights "power" of a SUN)
PATHS = 200_000


def _caster(s, material, z):
    """A 1 x 1 m quad at height z, n_g = +z, both corners' normals NS (a flat-shaded triangle's
    shading normal is its corner normal)."""
    v, t = primitives.quad((0, 0, z), (1, 0, 0), (0, 1, 0))
    s.add_mesh(v, t, material=material, normals=np.tile(NS, (len(v), 1)))


def _flux_on_receivers(scene):
    ctx = prepare(scene, RenderSettings(light_paths=PATHS, max_bounces=16, wavelength_step=30.0))
    lp = run_light_pass(ctx, plan=plan_render(ctx))
    return lp.caustics.flux.sum(axis=0) / ctx.lights.spectrum[0]  # in units of E x 1 m^2 per wavelength


def mirror_scene():
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)}, {"kind": "MIRROR", "color": (1, 1, 1)}])
    s = Scene(materials=mats)
    _caster(s, 1, 0.0)
    # a tall wall at y = 3 facing -y catches the beam reflected up towards +y (2 ALPHA off vertical)
    s.add_mesh(*primitives.quad((0, 3.0, 6.0), (8, 0, 0), (0, 0, 12)), material=0)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": (0, 0, -1), "power": E}])
    s.camera = Camera.look_at((0, -6, 4), (0, 0, 0), width=8, height=8)
    return s


def glass_scene(ior=1.5):
    """A 1 x 1 x 1 m glass box whose top has the tilted shading normal; a diffuse receiver at
    half height inside it (and through its sides) catches everything that enters through the
    top: what crosses a side wall first lands on its outer part, so every transmitted path lands
    once with the top's factor (the flat walls' bounces conserve flux)."""
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
                                {"kind": "DIELECTRIC", "ior": ior, "color": (1, 1, 1)}])
    s = Scene(materials=mats)
    _caster(s, 1, 1.0)
    for c, u, w in (((0, 0, 0), (0, 1, 0), (1, 0, 0)), ((0.5, 0, 0.5), (0, 1, 0), (0, 0, 1)),
                    ((-0.5, 0, 0.5), (0, 0, 1), (0, 1, 0)), ((0, 0.5, 0.5), (0, 0, 1), (1, 0, 0)),
                    ((0, -0.5, 0.5), (1, 0, 0), (0, 0, 1))):
        s.add_mesh(*primitives.quad(c, u, w), material=1)
    s.add_mesh(*primitives.quad((0, 0, 0.5), (4, 0, 0), (0, 4, 0)), material=0)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": (0, 0, -1), "power": E}])
    s.camera = Camera.look_at((0, -6, 4), (0, 0, 0), width=8, height=8)
    return s


def _binomial_sigma(p, n=PATHS):
    return np.sqrt(p * (1 - p) / n)


def test_a_tilted_normal_mirror_reflects_the_radiance_transport_flux(monkeypatch):
    r = np.array([0.0, 0.0, -1.0]) + 2 * NS[2] * NS  # the sun's direction reflected about NS
    expected = abs(r[2])  # E A |r . n_g| / (E A): cos(2 ALPHA) = 0.766
    got = _flux_on_receivers(mirror_scene())
    # every path that meets the mirror lands on the wall with the same weight: the only noise
    # is which of the aimed paths meet the 1 m^2 (none missed here: the sun aims at the caster)
    np.testing.assert_allclose(got, expected, rtol=0.01)
    monkeypatch.setattr(LightWalker, "adjoint_shading", False)
    old = _flux_on_receivers(mirror_scene())
    np.testing.assert_allclose(old, 1.0, rtol=0.01)  # flux conserved: |w_l . n_g| = 1, 31 % too much


def test_glass_under_a_tilted_normal_transmits_the_radiance_transport_flux(monkeypatch):
    d = np.array([0.0, 0.0, -1.0])
    cos_i = -d @ NS
    eta = 1 / 1.5
    cos_t = np.sqrt(1 - eta**2 * (1 - cos_i**2))
    t = eta * d + (eta * cos_i - cos_t) * NS
    fr = float(fresnel_dielectric(np.array([cos_i], np.float32), np.float32(1.5))[0][0])
    expected = (1 - fr) * cos_i / cos_t * abs(t[2])  # (1 - F) E cos_i / cos_t through A |t . n_g|
    got = _flux_on_receivers(glass_scene())
    tol = 5 * _binomial_sigma(fr)  # the Fresnel choice is the only random part
    np.testing.assert_allclose(got, expected, atol=tol)
    monkeypatch.setattr(LightWalker, "adjoint_shading", False)
    old = _flux_on_receivers(glass_scene())
    np.testing.assert_allclose(old, 1 - fr, atol=tol)  # flux conserved: 4.3 % above the expected
    assert np.all(np.abs(old - expected) > 10 * tol)


def test_factor_is_one_for_flat_bounces_and_matches_reflection_cancellation():
    rng = np.random.default_rng(3)
    d_in = rng.normal(size=(50, 3))
    d_in /= np.linalg.norm(d_in, axis=1, keepdims=True)
    ng = np.tile([0.0, 0.0, 1.0], (50, 1))
    d_in[:, 2] = -np.abs(d_in[:, 2]) - 0.1
    d_in /= np.linalg.norm(d_in, axis=1, keepdims=True)
    d_r = d_in - 2 * (d_in @ [0, 0, 1.0])[:, None] * ng
    np.testing.assert_allclose(adjoint_factor(d_in, d_r, ng, ng), 1.0, rtol=1e-6)
    ns = np.tile(NS, (50, 1))
    r = d_in - 2 * np.einsum("ij,ij->i", d_in, ns)[:, None] * ns
    ok = r[:, 2] > 0.05
    np.testing.assert_allclose(adjoint_factor(d_in, r, ng, ns)[ok], (r[:, 2] / -d_in[:, 2])[ok], rtol=1e-5)
    used = dielectric_normal_used(d_in, r, ng, ns, np.full(50, 1 / 1.5), np.zeros(50, bool))
    assert used.all()  # every reflection bent about ns
