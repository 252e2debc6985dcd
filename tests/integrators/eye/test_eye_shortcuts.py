"""The eye pass's shortcuts that must leave every estimate unchanged (docs/physics.md section
4.7): the Lambertian next events written out (``next_event.LambertLobe``) against the same samples
through core/materials/bsdf.py's LAMBERT lobe (``next_event.MicrofacetLobe``), and black (emission-only) surfaces,
which receive no caustics, so a scene whose only diffuse surfaces are black needs no light pass."""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.integrators.eye import next_event
from opal_diffraction.core.integrators.eye.eye_pass import EyePass, _TileTrace
from opal_diffraction.core.integrators.eye.surface_interaction import surface_params
from opal_diffraction.core.render.plan import plan_render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.materials.surface import surface_reflectance
from opal_diffraction.core.transport.walker import Rays


def _room():
    """A coloured floor under a tilted emissive panel and an environment map (the emitters the
    next events sample: the panel's two triangles, the map)."""
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.6, 0.4, 0.2)},
                                {"kind": "DIFFUSE", "color": (0, 0, 0), "emission": (2.0, 1.5, 1.0)}])
    sky = np.random.default_rng(4).uniform(0.1, 2.0, (8, 16, 3)).astype(np.float32)
    s = Scene(materials=mats, world_color=np.array([0.3, 0.4, 0.5], np.float32), world_image=sky,
              world_rotation=np.eye(3))
    s.add_mesh(*primitives.quad((0, 0, 0), (4, 0, 0), (0, 4, 0)), material=0)
    s.add_mesh(*primitives.quad((0.8, 0.3, 1.2), (0.6, 0, 0.3), (0, 0.7, 0)), material=1)
    s.lights = Lights()
    s.camera = Camera.look_at((0, -3, 2), (0, 0, 0), width=8, height=8)
    return s


@pytest.mark.parametrize("weights", ["unit", "spectral", "mono"])
def test_lambertian_next_events_equal_the_bsdf_modules_lambert_lobe(weights):
    s = _room()
    prepared = prepare(s, RenderSettings(samples=1, wavelength_step=20.0))
    assert prepared.mesh_lights is not None and prepared.environment is not None
    tr = _TileTrace(EyePass(prepared, plan=plan_render(prepared)), 16, np.random.default_rng(0))
    rng = np.random.default_rng(1)
    b = 4000
    o = np.column_stack([rng.uniform(-1.5, 1.5, b), rng.uniform(-1.5, 1.5, b), np.full(b, 3.0)]).astype(np.float32)
    d = rng.normal(size=(b, 3)) * 0.2
    d[:, 2] = -1.0
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    h = prepared.accel.intersect(o, d)
    on_floor = (h.prim >= 0) & (prepared.tri_material[np.maximum(h.prim, 0)] == 0)
    o, d = o[on_floor], d[on_floor]
    b = len(o)
    n = prepared.grid.n
    w = lam = None
    if weights == "spectral":
        w = rng.uniform(0.2, 1.0, (b, n)).astype(np.float32)
    elif weights == "mono":
        lam = rng.integers(0, n, b)
        w = rng.uniform(0.2, 1.0, b).astype(np.float32)
    rays = Rays(o, d, rng.integers(0, 16, b).astype(np.int64), w, lam, np.ones(b, np.int32), rng.random(b),
                tr._new_state(b))
    hh = prepared.accel.intersect(o, d)
    hit = tr.hit_info(rays, hh.t, hh.prim, hh.u, hh.v)
    c, out = tr.c, tr.out
    film_a, film_b = np.zeros(16 * n, np.float32), np.zeros(16 * n, np.float32)
    assert len(prepared.lights) == 0  # the emissive meshes and the world only
    next_event.lambert_next_events(c, out, rays, hit, np.random.default_rng(7), film_a,
                                   surface_reflectance(prepared, hit, rays.lam))
    params = surface_params(prepared, c.mixed_layers, rays, hit, np.random.default_rng(8))
    next_event.next_events(c, out, rays, hit, next_event.MicrofacetLobe(c, rays, hit, params), np.random.default_rng(7),
                           film_b, analytic=False)
    assert film_b.sum() > 0
    np.testing.assert_allclose(film_a, film_b, rtol=2e-5, atol=1e-6 * film_b.max())


def test_black_emitters_behind_glass_need_no_light_pass():
    """Glass in front of an emissive (black) panel: nothing can receive a caustic, so the plan
    skips the light pass; a grey floor added is a receiver, and the light pass runs."""
    mats = Materials.from_list([{"kind": "DIELECTRIC", "ior": 1.45, "color": (1, 1, 1)},
                                {"kind": "DIFFUSE", "color": (0, 0, 0), "emission": (3.0, 3.0, 3.0)},
                                {"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.icosphere((0, 0, 0.8), 0.7, 2), material=0)
    s.add_mesh(*primitives.quad((0, 1.5, 0.8), (5, 0, 0), (0, 0, 5)), material=1)
    s.lights = Lights()
    s.camera = Camera.look_at((0, -2.6, 0.9), (0, 0, 0.8), width=8, height=8)
    settings = RenderSettings(samples=1, wavelength_step=20.0, light_paths=10_000)
    p = prepare(s, settings)
    assert not p.light_targets.receiver_mask.any()
    assert not plan_render(p).light_pass
    s.add_mesh(*primitives.quad((0, 0, 0), (6, 0, 0), (0, 6, 0)), material=2)
    p = prepare(s, settings)
    assert plan_render(p).light_pass
