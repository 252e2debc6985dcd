"""Emissive meshes as lights (docs/physics.md sections 7.6 and 7.7): the power-proportional
triangle sampler against its pdf (chi-square over directions), irradiance against Lambert's
polygon formula, and the light pass's flux from a glowing panel through a glass slab against
the analytic value."""

from __future__ import annotations

import math

import numpy as np

from chi2 import chi2_directions
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.integrators.light.light_pass import run_light_pass
from opal_diffraction.core.lights.mesh_lights import MeshLights
from opal_diffraction.core.spectral.optics import fresnel_dielectric
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.validation import validate
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.render.plan import plan_render
from test_lights_sized import ALPHA, Z_MAX, polygon_irradiance

# three emitting triangles of different sizes, orientations and brightness, one dark one
V = np.array([[-1.0, -0.5, 1.0], [0.2, -0.6, 1.1], [-0.4, 0.4, 0.9],      # tri 0, material 0
              [0.5, 0.3, 0.8], [1.2, 0.2, 1.4], [0.7, 1.0, 1.0],          # tri 1, material 1 (tilted)
              [-0.2, 0.8, 1.6], [0.3, 1.2, 1.5], [-0.6, 1.3, 1.7],        # tri 2, material 2 (dark)
              [-1.5, -1.0, 0.6], [-1.1, -1.2, 0.7], [-1.3, -0.6, 0.5]])   # tri 3, material 0
T = np.arange(12).reshape(4, 3)
TM = np.array([0, 1, 2, 0])
EMISSION = np.array([[1.0, 2.0, 1.0], [3.0, 3.0, 3.0], [0.0, 0.0, 0.0]])  # (M, n) on a 3-bin grid


def build():
    return MeshLights.build(V, T, TM, EMISSION)


def ray_triangles(o, d, verts):
    """All hits of rays o + t d (t > 0) with triangles verts (K, 3, 3): (K, B) t or inf
    (Moller-Trumbore, float64: an independent intersection for the test)."""
    out = np.full((len(verts), len(d)), np.inf)
    for k, (a, b, c) in enumerate(verts):
        e1, e2 = b - a, c - a
        pv = np.cross(d, e2)
        det = pv @ e1
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            tv = o - a
            u = np.einsum("ij,ij->i", tv, pv) * inv
            qv = np.cross(tv, e1)
            v = np.einsum("ij,ij->i", d, qv) * inv
            t = (qv @ e2) * inv
        ok = (np.abs(det) > 1e-14) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        out[k] = np.where(ok, t, np.inf)
    return out


def light_density(ml, verts, p):
    """The solid-angle density of ``ml.sample`` at p in directions d: MeshLights.pdf of every
    emitter (corners ``verts`` (K, 3, 3), ml.tri's order) d crosses, by an independent
    ray-triangle test, summed."""

    def density(d):
        t = ray_triangles(np.broadcast_to(p, d.shape), d, verts)
        out = np.zeros(len(d))
        for k in range(len(ml.tri)):  # the emitters (a handful)
            hit = np.isfinite(t[k])
            if hit.any():
                q = p + t[k, hit, None] * d[hit]
                out[hit] += ml.pdf(np.full(hit.sum(), ml.tri[k]), np.broadcast_to(p, q.shape), q)
        return out
    return density


def test_build_selects_the_emitters_with_power_proportional_weights():
    ml = build()
    assert ml is not None and sorted(ml.tri.tolist()) == [0, 1, 3]
    area = 0.5 * np.linalg.norm(np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]]), axis=1)
    lum = EMISSION.mean(axis=1)
    np.testing.assert_allclose(ml.weight, (area * lum[TM])[ml.tri])
    np.testing.assert_allclose(ml.power, 2 * np.pi * np.sum((area * lum[TM])[[0, 1, 3]]))
    assert MeshLights.build(V, T, np.full(4, 2), EMISSION) is None


def test_triangle_sampler_matches_its_pdf_chi2():
    """Directions drawn from p against MeshLights.pdf summed over every emitter each direction
    crosses (found by an independent ray-triangle test)."""
    ml = build()
    p = np.array([0.0, 0.1, 0.0])
    n = 200_000
    wi, dist, g, prim, pdf = ml.sample(np.broadcast_to(p, (n, 3)), np.random.default_rng(5))
    # the pdf the sampler reports is MeshLights.pdf of the point it drew
    np.testing.assert_allclose(pdf, ml.pdf(prim, np.broadcast_to(p, (n, 3)), p + wi * dist[:, None].astype(np.float64)),
                               rtol=2e-3)
    density = light_density(ml, V[T[ml.tri]], p)

    axis = V[T[ml.tri]].mean(axis=(0, 1)) - p
    pval, info, total = chi2_directions(wi, density, axis, theta_max=1.4, n_theta=16, n_phi=32, sub=40)
    print(info)
    assert pval > ALPHA, info
    assert abs(total - 1) < 0.01


def test_irradiance_from_emitting_triangles_is_lamberts_formula():
    """E = sum_tri L_tri * (Lambert's polygon factor), each triangle wholly above the receiver's
    horizon; the MC estimate is g times the sampled triangle's emission (two-sided)."""
    ml = build()
    p, normal = np.array([0.1, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
    n = 400_000
    wi, _, g, prim, _ = ml.sample(np.broadcast_to(p, (n, 3)), np.random.default_rng(9))
    x = g.astype(np.float64) * np.maximum(wi @ normal, 0) * EMISSION[TM[prim], 1]
    expected = sum(EMISSION[TM[k], 1] * polygon_irradiance(p, normal, V[T[k]]) for k in (0, 1, 3))
    z = (x.mean() - expected) / (x.std() / math.sqrt(n))
    print(f"mesh irradiance MC {x.mean():.6f} analytic {expected:.6f} Z {z:.2f}")
    assert abs(z) < Z_MAX
    # seen from above the panel, its back emits the same (two-sided, as Cycles' Emission)
    p_up = np.array([0.0, 0.0, 3.0])
    wi, _, g, prim, _ = ml.sample(np.broadcast_to(p_up, (n, 3)), np.random.default_rng(10))
    x = g.astype(np.float64) * np.maximum(-wi[:, 2], 0) * EMISSION[TM[prim], 1]
    expected = sum(EMISSION[TM[k], 1] * polygon_irradiance(p_up, -normal, V[T[k]]) for k in (0, 1, 3))
    z = (x.mean() - expected) / (x.std() / math.sqrt(n))
    assert abs(z) < Z_MAX, z


def slab_transmission(cos_i, n=1.5):
    """Flux fraction through a clear slab at incidence cos_i with all internal reflections:
    (1 - R) / (1 + R), R the unpolarised Fresnel reflectance (the transport's, optics.py)."""
    r, _ = fresnel_dielectric(np.asarray(cos_i, np.float64), np.full(np.shape(cos_i), n))  # eta = n_t / n_i
    return (1 - r) / (1 + r)


def test_glowing_panel_throws_the_analytic_flux_through_a_glass_slab():
    """A 0.4 x 0.4 m panel (radiance L, two-sided) 0.5 m above a 12 x 12 x 0.05 m glass slab on a
    floor: the flux on the floor is L integrated over the panel and the directions that reach the
    slab's top, times the slab's transmission: Phi = L sum_panel dA int cos T(theta) dw (the
    panel's other side lights nothing below). Integrated by quadrature: the panel on a 6 x 6
    Gauss grid, directions in polar coordinates about the vertical up to the slab's edge."""
    L = 2.0
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
                                {"kind": "DIELECTRIC", "ior": 1.5, "color": (1, 1, 1)},
                                {"kind": "DIFFUSE", "color": (0, 0, 0), "emission": (L, L, L)}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (40, 0, 0), (0, 40, 0)), material=0)
    half, h_top, thick = 6.0, 0.3, 0.05
    s.add_mesh(*primitives.box((0, 0, h_top - thick / 2), (2 * half, 2 * half, thick)), material=1)
    h_panel = h_top + 0.5
    s.add_mesh(*primitives.quad((0, 0, h_panel), (0.4, 0, 0), (0, 0.4, 0)), material=2)
    s.lights = Lights()
    s.camera = Camera.look_at((0, -4, 3), (0, 0, 0), width=8, height=8)
    runs = []
    for seed in range(6):  # independent runs: their spread is the Monte Carlo error
        ctx = prepare(s, RenderSettings(light_paths=60_000, max_bounces=32, seed=seed, wavelength_step=20.0))
        assert ctx.mesh_lights is not None and len(ctx.mesh_lights) == 2
        lp = run_light_pass(ctx, plan=plan_render(ctx))
        tri, _, _ = lp.caustics.layout.barycentric_centres()
        on_floor = tri < 2  # the floor's two triangles (light reflected up onto the panel's back is not counted)
        runs.append(float(lp.caustics.flux[on_floor].sum(axis=0).mean()))
    emission = float(ctx.materials.emission[2].mean())  # the panel's radiance on the grid
    # quadrature: Gauss-Legendre over the panel, and for each point the directions below it that
    # reach the slab's top square: theta up to atan(rho_max(phi) / h) (rho_max: the square's edge)
    xg, wg = np.polynomial.legendre.leggauss(6)
    g_theta = np.linspace(0, np.pi / 2, 20001)
    mid = 0.5 * (g_theta[1:] + g_theta[:-1])
    f = np.cos(mid) * np.sin(mid) * slab_transmission(np.cos(mid))
    cum = np.concatenate([[0.0], np.cumsum(f * np.diff(g_theta))])  # int_0^theta cos sin T
    phi = (np.arange(4096) + 0.5) / 4096 * 2 * np.pi
    h = h_panel - h_top
    total = 0.0
    for xi, wx in zip(xg, wg):
        for yi, wy in zip(xg, wg):
            px, py = 0.2 * xi, 0.2 * yi
            with np.errstate(divide="ignore"):
                rx = np.where(np.cos(phi) > 0, (half - px) / np.cos(phi), (-half - px) / np.cos(phi))
                ry = np.where(np.sin(phi) > 0, (half - py) / np.sin(phi), (-half - py) / np.sin(phi))
            rho = np.minimum(np.abs(rx), np.abs(ry))
            inner = np.interp(np.arctan(rho / h), g_theta, cum).mean() * 2 * np.pi
            total += wx * wy * 0.04 * inner  # (0.2)^2 Jacobian: dA = 0.04 dxi dyi over [-1, 1]^2
    expected = emission * total
    mean = float(np.mean(runs))
    se = float(np.std(runs, ddof=1) / math.sqrt(len(runs)))
    z = (mean - expected) / se
    print(f"panel through slab: flux {mean:.5f} +- {se:.2g} W/bin, analytic {expected:.5f}, Z {z:.2f}")
    # Student t with 5 degrees of freedom: |t| > 6.87 has probability 1e-3
    assert abs(z) < 6.87
    assert se / expected < 0.01  # and the test is sharp: within a percent


def test_an_emitting_mesh_is_a_light_for_the_warnings():
    """'the scene has no lights' is for scenes that nothing lights: not when a mesh emits."""
    mats = Materials.from_list([{"kind": "DIFFUSE"}, {"kind": "DIFFUSE", "emission": (1.0, 1.0, 1.0)}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (4, 0, 0), (0, 4, 0)), material=0)
    s.camera = Camera.look_at((0, -4, 3), (0, 0, 0), width=8, height=8)
    warns = validate(s).warnings
    assert any("no lights" in w for w in warns)
    s.add_mesh(*primitives.quad((0, 0, 1), (1, 0, 0), (0, 1, 0)), material=1)
    warns = validate(s).warnings
    assert not any("no lights" in w for w in warns), warns
    ctx = prepare(s, RenderSettings(wavelength_step=20.0))
    assert ctx.mesh_lights is not None and sorted(ctx.mesh_lights.tri.tolist()) == [2, 3]
    assert prepare(Scene(materials=mats, camera=s.camera), RenderSettings(wavelength_step=20.0)).mesh_lights is None
