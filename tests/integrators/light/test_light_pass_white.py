"""White light as coefficients over a few basis spectra (core/transport/walker.py ``Rays.basis``,
docs/physics.md section 4.7): the caustic maps equal those of the dense-spectrum light pass.

The reference is the earlier dense path, kept here: every light path carries its full (B, n)
spectral weight from the start (the light's spectrum times the emission weight, or
``illuminant_from_rgb`` of the world map's colour), and a reference map adds every deposit in
float64 with ``np.add.at``. The paths themselves are the same (the random numbers do not depend
on how the weight is stored), so the maps agree to float32 rounding.
"""

import numpy as np
import pytest

from opal_diffraction.core.integrators.light import light_pass as lp
from opal_diffraction.core.integrators.light import walker
from opal_diffraction.core.lights import aiming, emission
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.transport.elements import IlluminationMap
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.validation import validate
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.transport.walker import Rays


class DenseReference:
    """A caustic map that only takes spectral deposits, summed in float64 (np.add.at)."""

    def __init__(self, layout, n):
        self.layout = layout
        self.flux = np.zeros((layout.total, n))
        self.calls = 0

    def deposit(self, elements, flux, lam=None, basis=None):
        assert basis is None, "the reference path carries spectra only"
        self.calls += 1
        if lam is None:
            np.add.at(self.flux, elements, np.asarray(flux, np.float64))
        else:
            np.add.at(self.flux, (elements, lam), np.asarray(flux, np.float64))


class Counting(IlluminationMap):
    """The light pass's map, counting the deposits that came as coefficients."""

    coefficient_calls = 0

    def deposit(self, elements, flux, lam=None, basis=None):
        if basis is not None:
            self.coefficient_calls += 1
        super().deposit(elements, flux, lam, basis=basis)


def reference_batch(ctx, job, sink):
    """light_pass.trace_batch as it was before coefficients: (B, n) weights from the emitter on."""
    rng = np.random.default_rng(np.random.SeedSequence([int(ctx.settings.seed), walker.LIGHT_PASS_STREAM, job.light,
                                                        job.batch]))
    b, n_lights = job.paths, len(ctx.lights)
    if job.light < n_lights:
        o, d, weight = emission.emit_light(ctx, job.light, b, rng)
        live = weight > 0
        w = (weight[live, None] / float(job.light_paths)) * ctx.lights.spectrum[job.light][None, :]
    else:
        assert job.light == n_lights + 1, "these scenes have no emissive meshes"
        o, d, coeff, _ = emission.emit_world(ctx, b, rng)
        live = coeff.max(axis=1) > 0
        # the map's colour times the emission weight, upsampled per path as the dense pass did
        w = ctx.conv.illuminant_from_rgb(coeff[live]) / float(job.light_paths)
    m = int(live.sum())
    rays = Rays(o[live].astype(np.float32), d[live].astype(np.float32), np.zeros(m, np.int64), w.astype(np.float32),
                None, np.zeros(m, np.int32), rng.random(m))
    tr = walker.LightWalker(ctx, rng, sink, None)
    tr.walk(rays, tr.empty_mono())


def maps(scene, paths, **kw):
    ctx = prepare(validate(scene).scene, RenderSettings(samples=1, light_paths=paths, **kw))
    work = lp.LightWork.of(ctx, paths)
    new = Counting.empty(work.layout, ctx.grid.n)
    ref = DenseReference(work.layout, ctx.grid.n)
    for job in work.batches:
        walker.trace_batch(ctx, job, new, None)
        reference_batch(ctx, job, ref)
    return ctx, new, ref


def assert_same_map(new, ref):
    assert ref.flux.max() > 0 and ref.calls > 0
    # float32 rounding: one rounding per deposit call and element (~1e-7 each, a few hundred calls)
    np.testing.assert_allclose(new.flux, ref.flux, rtol=3e-5, atol=3e-5 * ref.flux.max())
    np.testing.assert_allclose(new.flux.sum(axis=0, dtype=np.float64), ref.flux.sum(axis=0), rtol=1e-5)


def caustic_scene(dispersion="NONE", tinted=True):
    """A floor under a point light, with a colourless glass ball, a grey mirror (reflectance
    0.6 at every wavelength: a scalar on the coefficients), and (``tinted``) a tinted glass
    block (its spectral reflectance expands the weight to spectra)."""
    mats = Materials.from_list([
        {"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
        {"kind": "DIELECTRIC", "ior": 1.5, "color": (1, 1, 1), "dispersion": dispersion, "abbe": 20.0},
        {"kind": "MIRROR", "color": (0.6, 0.6, 0.6)},
        {"kind": "DIELECTRIC", "ior": 1.4, "color": (0.9, 0.5, 0.2)},
    ])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (6, 0, 0), (0, 6, 0)), material=0)
    s.add_mesh(*primitives.icosphere((0, 0, 1.0), 0.6, 3), material=1)
    s.add_mesh(*primitives.quad((1.5, 0, 1.5), (0.8, 0, 0.8), (0, 0.8, 0)), material=2)
    if tinted:
        s.add_mesh(*primitives.box((-1.4, 0.5, 0.8), (0.5, 0.5, 0.5)), material=3)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (-0.5, 1.0, 4.0), "power": 800.0}])
    s.camera = Camera.look_at((0, -5, 3), (0, 0, 0.5), width=16, height=16)
    return s


def test_colourless_glass_caustic_equals_the_dense_spectrum_map():
    _, new, ref = maps(caustic_scene(tinted=False), 120_000, max_bounces=12)
    assert new.coefficient_calls > 0  # the glass ball's and the grey mirror's light came as coefficients
    assert_same_map(new, ref)


def test_tinted_glass_caustic_equals_the_dense_spectrum_map():
    """A coloured glass block among the colourless casters: its tint expands the weights."""
    ctx, new, ref = maps(caustic_scene(), 120_000, max_bounces=12)
    assert_same_map(new, ref)
    # the tinted block coloured its caustic: the map is not a multiple of the light's spectrum
    ratio = ref.flux.sum(axis=0) / ctx.lights.spectrum[0]
    assert ratio.max() > 1.05 * ratio.min()


def test_dispersive_glass_caustic_equals_the_dense_spectrum_map():
    """White paths split at the dispersive ball (SAMPLE) into single-wavelength paths, whose
    deposits are summed per (element, wavelength) by bincount."""
    _, new, ref = maps(caustic_scene("ABBE"), 80_000, max_bounces=12)
    assert_same_map(new, ref)


@pytest.mark.parametrize("dispersion", ["NONE", "ABBE"])
def test_world_map_caustic_equals_the_dense_spectrum_map(dispersion):
    """A world map's paths carry 3 coefficients over the spectra of pure red, green and blue
    (through a dispersive ball they are expanded and split into wavelengths, core/transport/wavelengths.py)."""
    s = caustic_scene(dispersion, tinted=False)
    s.lights = Lights.from_list([])
    img = np.full((16, 32, 3), 0.05, np.float32)
    img[2:5, 10:14] = (40.0, 25.0, 8.0)  # a warm bright patch high in the sky
    img[3:6, 20:23] = (2.0, 6.0, 30.0)   # and a blue one
    s.world_image = img
    s.world_color = np.ones(3, np.float32)
    ctx, new, ref = maps(s, 80_000, max_bounces=12)
    if dispersion == "NONE":  # (a dispersive ball turns every path into wavelengths first)
        assert new.coefficient_calls > 0
    assert_same_map(new, ref)


def test_world_coefficients_reproduce_the_illuminant_upsampling():
    """The basis of the world's coefficients: illuminant_from_rgb is linear in non-negative RGB
    (its scale max(rgb) times a combination of rgb / max(rgb)), so coefficients @ basis equal
    the upsampled colour of every path."""
    s = caustic_scene()
    s.lights = Lights.from_list([])
    rng = np.random.default_rng(3)
    s.world_image = (rng.random((8, 16, 3)) ** 3 * 20).astype(np.float32)
    s.world_color = np.ones(3, np.float32)
    ctx = prepare(validate(s).scene, RenderSettings(samples=1, light_paths=1000))
    _, _, coeff, basis = emission.emit_world(ctx, 4000, np.random.default_rng(1))
    np.testing.assert_allclose(coeff @ basis, ctx.conv.illuminant_from_rgb(coeff), rtol=1e-9, atol=0)


@pytest.mark.parametrize("objects", [1, 40])
def test_chunked_cone_sampling_is_the_unchunked_sampling(objects):
    """Area-light path starts sample the casters' cones in chunks of CONE_CHUNK paths: the same
    directions and pdfs as one call over the whole batch (the numbers drawn for it first)."""
    rng = np.random.default_rng(objects)
    obj = aiming.CasterObjects(rng.normal(size=(objects, 3)) * 3, rng.random(objects) * 0.5 + 0.1)
    origin = rng.normal(size=(3 * aiming.CONE_CHUNK + 17, 3)) * 0.3 + np.array([0, 0, 8.0])
    d, pdf = aiming.sample_towards_casters(origin, obj, np.random.default_rng(7))
    axis, cos_max, omega = aiming.caster_cones(origin, obj)
    d0, pdf0 = aiming.sample_cones(origin, omega, axis, cos_max, omega, np.random.default_rng(7))
    np.testing.assert_array_equal(d, d0)
    np.testing.assert_array_equal(pdf, pdf0)
