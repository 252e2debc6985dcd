"""Dispersion through the tracer: a 60-degree N-BK7 prism's minimum deviation
(docs/physics.md section 2.5).

Rays are traced by the eye pass's own transport code (Fresnel choice, Snell per wavelength,
the acceleration structure), not by the formula alone.
"""

import numpy as np
import pytest

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.integrators.eye.eye_pass import EyePass
from opal_diffraction.core.spectral.optics import ior_spectrum
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene.model import Camera, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.render.plan import plan_render


def prism_context(dispersion="BK7", dispersion_sampling="SAMPLE"):
    s = Scene(materials=Materials.from_list([{"kind": "DIELECTRIC", "color": (1, 1, 1), "dispersion": dispersion}]))
    s.add_mesh(*primitives.prism((0, 0, 0), side=2.0, length=4.0, axis="Y"), material=0)
    s.camera = Camera()
    return prepare(s, RenderSettings(dispersion_sampling=dispersion_sampling))


def deviation_through_prism(ctx, lam_index, incidence_deg, n_rays=4000):
    """Shoot a beam at the prism's left face at a given incidence; return the deviation (deg)
    of the rays that left after exactly two refractions."""
    # left face normal: the prism (apex up, in the x-z plane) has faces tilted 30 deg from vertical
    normal = np.array([-np.cos(np.radians(30)), 0, np.sin(np.radians(30))])
    tangent_down = np.array([np.sin(np.radians(30)), 0, np.cos(np.radians(30))])  # along the face, upwards
    th = np.radians(incidence_deg)
    # incoming direction makes angle th with -normal, coming from below the normal (towards the base)
    d = -np.cos(th) * normal + np.sin(th) * tangent_down
    rng = np.random.default_rng(3)
    face_centre = np.array([-0.5, 0, 0.0])  # a point on the left face (x = -sin30 * (z-offset))
    face_centre = face_centre + tangent_down * 0.15
    o = face_centre + rng.uniform(-0.05, 0.05, (n_rays, 1)) * tangent_down + rng.uniform(-0.5, 0.5, (n_rays, 1)) * [0, 1, 0]
    o = o - 5.0 * d
    esc = EyePass(ctx, plan=plan_render(ctx)).trace_escapes(o, np.tile(d, (n_rays, 1)), rng, wavelength_index=lam_index)
    two = esc["depth"] == 2
    out = esc["direction"][two]
    assert two.sum() > 0.8 * n_rays  # Fresnel: about 9 % are reflected at one of the faces
    dev = np.degrees(np.arccos(np.clip(out @ d, -1, 1)))
    assert np.ptp(dev) < 1e-3  # a parallel beam stays parallel
    return float(np.mean(dev))


@pytest.mark.parametrize("lam_index,wavelength,expected", [(0, 400.0, 39.89), (60, 700.0, 38.32)])
def test_bk7_prism_minimum_deviation_through_tracer(lam_index, wavelength, expected):
    ctx = prism_context()
    assert ctx.grid.wavelengths[lam_index] == wavelength
    n = float(ior_spectrum(np.array([wavelength]), "BK7")[0])
    theta_min = np.degrees(np.arcsin(n * np.sin(np.radians(30))))  # symmetric passage
    dev = deviation_through_prism(ctx, lam_index, theta_min)
    assert dev == pytest.approx(expected, abs=0.01)
    # and it is a minimum: other incidences deviate more
    assert deviation_through_prism(ctx, lam_index, theta_min - 4) > dev
    assert deviation_through_prism(ctx, lam_index, theta_min + 4) > dev


def test_white_ray_splits_into_a_fan_ordered_by_wavelength():
    """SPLIT: one white ray becomes one ray per wavelength; blue deviates most."""
    ctx = prism_context(dispersion_sampling="SPLIT")
    n = float(ior_spectrum(np.array([550.0]), "BK7")[0])
    th = np.radians(np.degrees(np.arcsin(n * 0.5)))
    normal = np.array([-np.cos(np.radians(30)), 0, np.sin(np.radians(30))])
    up = np.array([np.sin(np.radians(30)), 0, np.cos(np.radians(30))])
    d = -np.cos(th) * normal + np.sin(th) * up
    o = np.array([-0.5, 0, 0]) + 0.15 * up - 5 * d
    rng = np.random.default_rng(0)
    esc = EyePass(ctx, plan=plan_render(ctx)).trace_escapes(np.tile(o, (200, 1)), np.tile(d, (200, 1)), rng)
    two = esc["depth"] == 2
    lam, out = esc["lam"][two], esc["direction"][two]
    dev = np.degrees(np.arccos(np.clip(out @ d, -1, 1)))
    per_lam = np.array([dev[lam == k].mean() for k in range(ctx.grid.n)])
    assert np.all(np.diff(per_lam) < 0)
    # each wavelength leaves where Snell's law at both faces puts it: delta = th_i + th_e - A
    n_l = ior_spectrum(ctx.grid.wavelengths, "BK7")
    a = np.radians(60)
    th_e = np.arcsin(n_l * np.sin(a - np.arcsin(np.sin(th) / n_l)))
    np.testing.assert_allclose(per_lam, np.degrees(th + th_e - a), atol=0.01)
