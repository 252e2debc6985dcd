"""The next-event and caustic-map kernels (core/integrators/eye/next_event.py ``_direct_fused``,
``_lambert_fused``, ``_caustic_fused``; core/transport/elements.py ``_irradiance_kernel``) against
their NumPy reference.

The kernels do the reference's float32 / float64 operations in its order (dot products as
x0 y0 + x1 y1 + x2 y2, the film's per-pixel run sums as TileOutput.accumulate's reduceat), so
with one analytic light they give the reference's bits. With several lights, the reference's
irradiance of white rays is a BLAS product (B, L) @ (L, n) whose summation order (and FMA use) is
the library's, the kernel's a sequential sum over lights: equal to float32 rounding of a sum of
L terms, a relative 1e-6 at most per film entry (the film sums non-negative terms, so no
cancellation amplifies it): rtol 1e-5.

Each render-level test switches only these routines (the module's ``_*_fused``) so that every
other stage takes the same path, and the numbers drawn are the same: the images are comparable
pixel for pixel. A last test renders the whole scene on the kernels and on the reference
(RenderSettings.kernels) and compares them with a Z-test.
"""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.integrators.eye import next_event, next_event_kernels
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.transport import elements
from opal_diffraction.core.transport.elements import ElementLayout, IlluminationMap
from opal_diffraction.core.util.jit import AVAILABLE

pytestmark = pytest.mark.skipif(not AVAILABLE, reason="numba is not available")

ONE_LIGHT = [{"kind": "POINT", "position": (1.0, -1.5, 3.0), "power": 400.0}]
MANY_LIGHTS = ONE_LIGHT + [
    {"kind": "SPOT", "position": (-1.0, -1.0, 2.5), "direction": (0.3, 0.4, -1.0), "power": 300.0,
     "spot_size": 1.0, "spot_blend": 0.3, "color": (1.0, 0.6, 0.3)},
    {"kind": "AREA_RECT", "position": (0.0, 0.5, 2.8), "direction": (0.0, 0.1, -1.0), "size_u": 0.8,
     "size_v": 0.5, "power": 200.0},
    {"kind": "AREA_DISK", "position": (1.5, 1.0, 2.0), "direction": (-0.4, -0.2, -1.0), "size_u": 0.6,
     "size_v": 0.6, "power": 150.0, "color": (0.4, 0.7, 1.0)},
    {"kind": "POINT", "position": (-1.5, 0.5, 1.5), "power": 100.0, "radius": 0.2},
    {"kind": "SUN", "direction": (0.2, 0.5, -1.0), "power": 1.5, "angle": 0.1},
]


def lit_room(lights, world: bool = True, pixels: int = 24, textured: bool = False) -> Scene:
    """A grey and a coloured floor (``textured``: a colour checker on it), a coloured wall with an emitting strip, a dispersive glass
    ball throwing a caustic, a rough gold ball, ``lights`` and (``world``) a small environment map."""
    mats = Materials.from_list([
        {"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
        {"kind": "DIFFUSE", "color": (0.8, 0.3, 0.2), "color_texture": 0 if textured else -1},
        {"kind": "DIELECTRIC", "color": (1, 1, 1), "ior": 1.6, "dispersion": "ABBE", "abbe": 30.0},
        {"kind": "DIFFUSE", "color": (0.2, 0.2, 0.2), "emission": (3.0, 2.0, 1.0)},
        {"kind": "MIRROR", "color": (1.0, 0.78, 0.34), "metallic": 1.0, "roughness": 0.4},
    ])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((-1.5, 0.0, 0.0), (3.0, 0.0, 0.0), (0.0, 4.0, 0.0)), material=0)
    v, t = primitives.quad((1.5, 0.0, 0.0), (3.0, 0.0, 0.0), (0.0, 4.0, 0.0))
    s.add_mesh(v, t, 1, uvs=np.asarray(v)[:, :2] * 2.0 if textured else None)
    if textured:
        tex = np.zeros((4, 4, 3), np.float32)
        tex[::2, ::2] = (0.9, 0.2, 0.1)
        tex[1::2, 1::2] = (0.1, 0.5, 0.9)
        s.add_texture(tex, "CLOSEST")
    s.add_mesh(*primitives.quad((0.0, 2.0, 1.0), (6.0, 0.0, 0.0), (0.0, 0.0, 2.0)), material=1)
    s.add_mesh(*primitives.quad((0.0, 1.9, 2.3), (2.0, 0.0, 0.0), (0.0, 0.0, 0.2)), material=3)
    s.add_mesh(*primitives.icosphere((0.0, 0.3, 0.6), 0.5, 2), material=2)
    s.add_mesh(*primitives.icosphere((-1.0, 0.8, 0.4), 0.4, 2), material=4)  # a rough metal: MicrofacetLobe
    s.lights = Lights.from_list(lights)
    s.camera = Camera.look_at((0.0, -3.0, 2.0), (0.0, 0.5, 0.4), lens=30.0, width=pixels, height=pixels)
    if world:
        rng = np.random.default_rng(5)
        s.world_image = (rng.random((16, 32, 3)) * np.linspace(0.2, 2.0, 16)[:, None, None]).astype(np.float32)
        s.world_color = np.full(3, 0.3, np.float32)
    return s


def _settings(**kw):
    base = dict(samples=4, light_paths=20000, threads=1, wavelength_step=20.0, seed=11)
    base.update(kw)
    return RenderSettings(**base)


FUSED = ("_direct_fused", "_lambert_fused", "_caustic_fused", "_LobeAdd")


def _switch_off(m, name):
    if name == "_LobeAdd":  # next_events' microfacet film add
        m.setattr(next_event._LobeAdd, "of", classmethod(lambda cls, rays: None))
    else:
        m.setattr(next_event, name, lambda *a: False)


def _render(scene, monkeypatch, on=FUSED, **kw) -> np.ndarray:
    """The scene's RGB with the kernels on and the fused routines ``on`` only (the others: the
    NumPy lines)."""
    with monkeypatch.context() as m:
        for name in FUSED:
            if name not in on:
                _switch_off(m, name)
        return np.asarray(render(scene, _settings(**kw)).rgb, np.float64)


def _used(monkeypatch, scene, name) -> int:
    """How often the routine ``name`` did the work (returned True) in a render."""
    calls = []
    obj, attr = (next_event._LobeAdd, "add") if name == "_LobeAdd" else (next_event, name)
    fn = getattr(obj, attr)

    def counted(*a):
        done = fn(*a)
        calls.append(bool(done))
        return done

    with monkeypatch.context() as m:
        m.setattr(obj, attr, counted)
        render(scene, _settings())
    return sum(calls)


@pytest.mark.parametrize("name", FUSED)
def test_each_fused_routine_gives_the_references_bits_with_one_light(monkeypatch, name):
    scene = lit_room(ONE_LIGHT)
    assert _used(monkeypatch, scene, name) > 0  # the kernel path ran
    reference = _render(scene, monkeypatch, on=())
    kernel = _render(scene, monkeypatch, on=(name,))
    assert reference.max() > 0
    np.testing.assert_array_equal(kernel, reference)


@pytest.mark.parametrize("world,textured", [(False, False), (True, True)])
def test_all_fused_routines_give_the_references_bits(monkeypatch, world, textured):
    scene = lit_room(ONE_LIGHT, world=world, textured=textured)
    np.testing.assert_array_equal(_render(scene, monkeypatch), _render(scene, monkeypatch, on=()))


def test_the_fused_routines_match_the_reference_with_every_light_kind(monkeypatch):
    scene = lit_room(MANY_LIGHTS)
    reference = _render(scene, monkeypatch, on=())
    kernel = _render(scene, monkeypatch)
    assert reference.max() > 0
    # a sum over lights in another order (BLAS vs sequential): float32 rounding (module docstring)
    np.testing.assert_allclose(kernel, reference, rtol=1e-5, atol=1e-7 * reference.max())


def test_kernels_and_reference_renders_agree_within_noise():
    """The whole render on the kernels and on the reference: equal within noise (a Z-test on
    the image mean, independent seeds so that the test measures the estimators, not the stream)."""
    scene = lit_room(MANY_LIGHTS, pixels=20)
    a = np.asarray(render(scene, _settings(samples=8, seed=1)).rgb, np.float64).mean(axis=2).ravel()
    b = np.asarray(render(scene, _settings(samples=8, seed=2, kernels="numpy")).rgb,
                   np.float64).mean(axis=2).ravel()
    err = np.sqrt(a.var(ddof=1) / len(a) + b.var(ddof=1) / len(b))
    z = (a.mean() - b.mean()) / err
    assert abs(z) < 4.5, f"kernels {a.mean():.5f} vs reference {b.mean():.5f} (z = {z:+.2f})"
    assert err < 0.05 * b.mean()  # tight enough to mean something


@pytest.mark.parametrize("jitter", [False, True])
def test_the_irradiance_kernel_is_the_references_lookup(monkeypatch, jitter):
    rng = np.random.default_rng(3)
    t = 40
    area = rng.random(t) * 2.0
    receivers = rng.random(t) > 0.2  # some triangles hold no elements: zero irradiance there
    lay = ElementLayout.from_areas(area, receivers, 0.01)
    cmap = IlluminationMap(lay, rng.random((lay.total, 7)).astype(np.float32))
    b = 3000
    prim = rng.integers(0, t, b)
    bu = rng.random(b)
    bv = rng.random(b) * (1 - bu)
    bu[:20], bv[:20] = 0.0, 1.0  # on the edges and corners
    bu[20:40], bv[20:40] = 1.0, 0.0
    front = rng.random(b) > 0.5
    out = {}
    for on in (True, False):
        with monkeypatch.context() as m:
            m.setattr(elements, "kernels_enabled", lambda on=on: on)
            out[on] = cmap.irradiance(prim, bu.astype(np.float32), bv.astype(np.float32), front,
                                      np.random.default_rng(9) if jitter else None)
    assert (out[False] > 0).any() and (out[False] == 0).any()
    np.testing.assert_array_equal(out[True], out[False])


def test_element_of_is_the_layouts_index():
    rng = np.random.default_rng(4)
    lay = ElementLayout.from_areas(rng.random(12), np.ones(12, bool), 0.02)
    prim = rng.integers(0, 12, 500)
    bu, bv = rng.random(500), rng.random(500)
    front = rng.random(500) > 0.5
    idx, valid = lay.index(prim, bu, bv, front)
    got = [elements.element_of(lay.k, lay.offset, prim[i], bu[i], bv[i], front[i], 0.0, 0.0, False)
           for i in range(500)]
    assert valid.all()
    np.testing.assert_array_equal([g[0] for g in got], idx)


@pytest.mark.parametrize("length", [1, 2, 3, 7, 8, 9, 17, 128, 129, 130, 300, 1000, 5000])
def test_a_runs_film_add_is_reduceats_sum(length):
    """flush_run adds a pixel's rows as TileOutput.accumulate's np.add.reduceat does (its first
    row plus NumPy's pairwise sum of the rest), to the bit."""
    rng = np.random.default_rng(length)
    rows = (rng.random((length, 5)) * rng.random((length, 1)) * 10).astype(np.float32)
    film = rng.random(3 * 5).astype(np.float32)
    expected = film.copy()
    expected.reshape(3, 5)[1] += np.add.reduceat(rows, [0], axis=0)[0]
    next_event_kernels.flush_run(film, 5, 1, rows, length)
    np.testing.assert_array_equal(film, expected)
