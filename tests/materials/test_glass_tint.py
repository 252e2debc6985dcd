"""Tinted glass (docs/physics.md section 2.7): the tint per refraction is the square root of the
uplifted colour of one pass through a closed object - Base Color for Principled (glass_tint
PASS), Color^2 for the Glass BSDF (REFRACTION) - so one pass reproduces that colour's RGB.

Checked against closed forms: the spectra's round trip (two refractions' tint under white light
is the pass colour in RGB), grey REFRACTION tints unchanged to the bit, layered rows untouched,
and whole renders of a slab before a white emissive wall at normal incidence, whose pixels must
equal T = (1 - F)^2 t^2 / (1 - F^2 t^2) (all internal reflections summed, per wavelength) in RGB
to within the pixels' own noise (a Z-test of the mean) and 0.5 % - also for a dispersive (BK7)
slab, per wavelength - and the light pass's caustic flux under a tinted slab (the same closed
form, within the Fresnel choices' 1 %).
"""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.materials import bsdf
from opal_diffraction.core.materials.spectra import glass_tint_spectra, prepare_materials
from opal_diffraction.core.integrators.light.light_pass import run_light_pass
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.render.plan import plan_render
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.npz import load_scene, save_scene
from opal_diffraction.core.scene.validation import validate
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.spectral.optics import ior_spectrum
from opal_diffraction.core.spectral.spectrum import SpectralConverter
from opal_diffraction.core.util.enums import GlassTint

CONV = SpectralConverter()
W = CONV.white_illuminant
PASS, REFRACTION = int(GlassTint.PASS), int(GlassTint.REFRACTION)
#: in-gamut tints: grey, the issue's ruby, and saturated green, blue, amber
TINTS = {"white": (1.0, 1.0, 1.0), "grey": (0.5, 0.5, 0.5), "ruby": (0.8, 0.1, 0.1),
         "emerald": (0.1, 0.8, 0.2), "sapphire": (0.1, 0.2, 0.9), "amber": (0.9, 0.6, 0.1)}


def _rgb_under_white(spectrum):
    return CONV.to_rgb(np.asarray(spectrum, np.float64) * W).astype(np.float64)


@pytest.mark.parametrize("name", list(TINTS))
def test_two_refractions_give_the_pass_colour_in_rgb(name):
    c = np.array(TINTS[name])
    t = glass_tint_spectra([c, c], [PASS, REFRACTION], CONV)
    assert t.min() >= 0 and t.max() <= 1 + 1e-12  # white: 1 to float64 rounding
    np.testing.assert_allclose(_rgb_under_white(t[0] ** 2), c, atol=1e-6)       # Principled: Base Color
    np.testing.assert_allclose(_rgb_under_white(t[1] ** 2), c * c, atol=1e-6)   # Glass BSDF: Color^2


def test_the_rule_differs_from_the_uplifts_product_for_a_saturated_colour():
    """What the rule fixes: the square of the ruby's uplift is (0.596, 0.0047, 0.0021) in RGB, not
    the RGB product (0.64, 0.01, 0.01)."""
    ruby = np.array(TINTS["ruby"])
    old = _rgb_under_white(CONV.reflectance_from_rgb(ruby) ** 2)
    assert old[1] < 0.5 * 0.01 and old[2] < 0.25 * 0.01
    new = _rgb_under_white(glass_tint_spectra([ruby], [REFRACTION], CONV)[0] ** 2)
    np.testing.assert_allclose(new, ruby * ruby, atol=1e-6)


def test_grey_refraction_tints_are_unchanged_to_the_bit():
    greys = np.linspace(0.0, 1.0, 1001)
    rgb = np.repeat(greys[:, None], 3, axis=1)
    new = glass_tint_spectra(rgb, np.full(len(greys), REFRACTION), CONV).astype(np.float32)
    np.testing.assert_array_equal(new, CONV.reflectance_from_rgb(rgb).astype(np.float32))


def test_only_pure_glass_rows_take_the_rule():
    """Mirrors, diffuse rows and layered Principled (its row is also the base's albedo and the metal's
    F0) keep the uplift of their colour in the table, the layered rows' glass layer has the rule's
    tint of its own; older files (no glass_tint column) read REFRACTION."""
    ruby = TINTS["ruby"]
    rows = [{"kind": "DIELECTRIC", "color": ruby, "glass_tint": "PASS"},
            {"kind": "DIELECTRIC", "color": ruby},
            {"kind": "DIELECTRIC", "color": ruby, "glass_tint": "PASS", "transmission": 0.5},
            {"kind": "DIELECTRIC", "color": ruby, "glass_tint": "PASS", "metallic": 0.2},
            {"kind": "MIRROR", "color": ruby, "glass_tint": "PASS"},
            {"kind": "DIFFUSE", "color": ruby, "glass_tint": "PASS"}]
    m = Materials.from_list(rows)
    assert list(m.glass_tint) == [PASS, REFRACTION, PASS, PASS, PASS, PASS]
    refl = prepare_materials(m, CONV).reflectance
    uplift = CONV.reflectance_from_rgb(np.asarray(m.color[0], np.float64)).astype(np.float32)
    ruby32 = m.color[0]  # the table holds float32 colours
    np.testing.assert_array_equal(refl[0], glass_tint_spectra([ruby32], [PASS], CONV)[0].astype(np.float32))
    np.testing.assert_array_equal(refl[1], glass_tint_spectra([ruby32], [REFRACTION], CONV)[0].astype(np.float32))
    for i in range(2, 6):
        np.testing.assert_array_equal(refl[i], uplift)
    layered = prepare_materials(m, CONV).glass_tint
    for i in (2, 3):  # their glass layer follows the rule (bsdf.params_from_materials' glass lobe)
        np.testing.assert_array_equal(layered[i], refl[0])
    columns = {k: getattr(m, k) for k in ("kind", "color", "ior")}
    assert list(Materials.from_columns(columns, len(rows)).glass_tint) == [REFRACTION] * len(rows)


def test_the_glass_tint_column_round_trips_and_is_validated(tmp_path):
    """Saved and loaded with the scene; a file without the column loads as REFRACTION (what its
    colour meant: one refraction's); unknown names and codes are errors naming the column."""
    s = Scene(materials=Materials.from_list([{"kind": "DIELECTRIC", "color": TINTS["ruby"], "glass_tint": "PASS"}]))
    s.add_mesh(*primitives.box((0, 0, 0), (1.0, 1.0, 1.0)), material=0)
    s.camera = Camera.look_at((0, -4, 0), (0, 0, 0))
    save_scene(s, tmp_path / "new.npz")
    assert list(load_scene(tmp_path / "new.npz").materials.glass_tint) == [PASS]
    with np.load(tmp_path / "new.npz") as z:
        old = {k: z[k] for k in z.files if k != "material_glass_tint"}
    np.savez(tmp_path / "old.npz", **old)
    assert list(load_scene(tmp_path / "old.npz").materials.glass_tint) == [REFRACTION]
    with pytest.raises(SceneError, match="glass_tint"):
        Materials.from_list([{"kind": "DIELECTRIC", "glass_tint": "BOTH"}])
    s.materials.glass_tint[:] = 7
    with pytest.raises(SceneError, match="glass tint code 7"):
        validate(s)


def test_the_glass_lobe_of_a_layered_principled_takes_the_rule():
    """Principled with transmission 0.5: a hit that draws the glass layer is tinted by the rule's
    spectrum, one that draws the base by the uplifted Base Color; a colour-textured glass keeps
    the texture's colour (the base the caller passes)."""
    ruby = TINTS["ruby"]
    m = Materials.from_list([{"kind": "DIELECTRIC", "color": ruby, "glass_tint": "PASS", "transmission": 0.5,
                              "roughness": 0.3},
                             {"kind": "DIELECTRIC", "color": ruby, "glass_tint": "PASS", "roughness": 0.3,
                              "color_texture": 0}])
    pm = prepare_materials(m, CONV)
    mat, front = np.array([0, 0, 1]), np.ones(3, bool)
    given = pm.reflectance[mat].copy()
    given[2] = 0.25  # what a texture lookup would give
    p = bsdf.params_from_materials(pm, mat, front, base=given, u_layer=np.array([0.2, 0.8, 0.2]))
    assert list(p.lobe) == [bsdf.DIELECTRIC, bsdf.LAMBERT, bsdf.DIELECTRIC]
    np.testing.assert_array_equal(p.base[0], glass_tint_spectra([m.color[0]], [PASS], CONV)[0].astype(np.float32))
    np.testing.assert_array_equal(p.base[1], CONV.reflectance_from_rgb(np.asarray(m.color[0], np.float64)).astype(np.float32))
    np.testing.assert_array_equal(p.base[2], given[2])


# ---------------------------------------------------------------------------- through the renderer
def _slab_before_wall(color, glass_tint, pixels=12, dispersion="NONE"):
    """A glass slab (IOR 1.5, 0.4 thick) above a white emissive wall (radiance 1), seen straight
    down by an orthographic camera that frames the slab's middle; no world light."""
    glass = {"kind": "DIELECTRIC", "color": color, "ior": 1.5, "glass_tint": glass_tint, "dispersion": dispersion}
    wall = {"kind": "DIFFUSE", "color": (0.0, 0.0, 0.0), "emission": (1.0, 1.0, 1.0)}
    s = Scene(materials=Materials.from_list([glass, wall]))
    s.add_mesh(*primitives.box((0, 0, 0), (4.0, 4.0, 0.4)), material=0)
    s.add_mesh(*primitives.quad((0, 0, -1.0), (20.0, 0, 0), (0, 20.0, 0)), material=1)
    m = np.eye(4)
    m[:3, 3] = (0.0, 0.0, 5.0)
    s.camera = Camera(matrix=m, kind="ORTHO", ortho_scale=1.0, width=pixels, height=pixels)
    return s


def _slab_closed_form(color, glass_tint, ior=1.5):
    """RGB of T = (1 - F)^2 t^2 / (1 - F^2 t^2) per wavelength, times the wall's white spectrum
    (``ior``: a number, or the index per wavelength of a dispersive glass)."""
    f = ((np.asarray(ior) - 1) / (np.asarray(ior) + 1)) ** 2
    t2 = glass_tint_spectra([color], [int(GlassTint[glass_tint])], CONV)[0] ** 2
    return _rgb_under_white((1 - f) ** 2 * t2 / (1 - f * f * t2))


@pytest.mark.parametrize("glass_tint", ["PASS", "REFRACTION"])
@pytest.mark.parametrize("name", ["grey", "ruby", "sapphire"])
def test_a_slab_before_a_white_wall_renders_the_closed_form(name, glass_tint):
    color = TINTS[name]
    res = render(_slab_before_wall(color, glass_tint), RenderSettings(samples=64, threads=1, seed=2))
    px = res.rgb.reshape(-1, 3).astype(np.float64)
    expected = _slab_closed_form(color, glass_tint)
    mean, sem = px.mean(axis=0), px.std(axis=0, ddof=1) / np.sqrt(len(px))
    z = (mean - expected) / np.maximum(sem, 1e-9)
    print(name, glass_tint, "rendered", np.round(mean, 5), "closed form", np.round(expected, 5), "z", np.round(z, 2))
    assert np.all(np.abs(z) < 4.5)
    np.testing.assert_allclose(mean, expected, rtol=5e-3, atol=2e-5)
    # Cycles in RGB (F = 0.04): Principled's internal reflections are untinted, the Glass BSDF's
    # tinted by Color; ours differ from both by at most F^2 = 0.16 %
    c = np.array(color)
    cycles = 0.9216 * c / (1 - 0.0016) if glass_tint == "PASS" else 0.9216 * c * c / (1 - 0.0016 * c ** 4)
    np.testing.assert_allclose(mean, cycles, rtol=5e-3, atol=2e-5)


@pytest.mark.parametrize("glass_tint", ["PASS", "REFRACTION"])
def test_a_dispersive_slab_tints_each_wavelength_by_the_rule(glass_tint):
    """BK7: the white rays split into single wavelengths at the first hit (SAMPLE), each tinted by
    the rule's spectrum at its wavelength, with the Fresnel factor of its own index."""
    color = TINTS["ruby"]
    res = render(_slab_before_wall(color, glass_tint, dispersion="BK7"), RenderSettings(samples=256, threads=1, seed=2))
    px = res.rgb.reshape(-1, 3).astype(np.float64)
    expected = _slab_closed_form(color, glass_tint, ior_spectrum(CONV.grid.wavelengths, "BK7", 1.5, 64.0))
    mean, sem = px.mean(axis=0), px.std(axis=0, ddof=1) / np.sqrt(len(px))
    print(glass_tint, "rendered", np.round(mean, 5), "closed form", np.round(expected, 5))
    assert np.all(np.abs(mean - expected) < 4.5 * sem + 1e-3 * expected)


@pytest.mark.parametrize("glass_tint", ["PASS", "REFRACTION"])
def test_caustic_flux_through_a_tinted_slab_is_the_closed_form(glass_tint):
    """The light pass (caustics through tinted glass): a sun straight down on a 1 x 1 m tinted slab
    above a grey floor puts E A (1 - F)^2 t^2 / (1 - F^2 t^2) per wavelength on the floor, whose RGB
    is the pass colour times (1 - F)^2 / (1 - F^2) to within F^2."""
    color = TINTS["ruby"]
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
                                {"kind": "DIELECTRIC", "ior": 1.5, "color": color, "glass_tint": glass_tint}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (8, 0, 0), (0, 8, 0)), material=0)
    s.add_mesh(*primitives.box((0, 0, 1.0), (1.0, 1.0, 0.2)), material=1)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": (0, 0, -1), "power": 2.0}])
    s.camera = Camera.look_at((0, -4, 3), (0, 0, 0), width=16, height=16)
    ctx = prepare(s, RenderSettings(light_paths=200_000, max_bounces=32))
    flux = run_light_pass(ctx, plan=plan_render(ctx)).caustics.flux.sum(axis=0)
    f = 0.04
    t2 = glass_tint_spectra([mats.color[1]], [int(GlassTint[glass_tint])], CONV)[0] ** 2
    expected = ctx.lights.spectrum[0] * (1 - f) ** 2 * t2 / (1 - f * f * t2)
    # binomial noise of the Fresnel choices over ~N paths: well under 1 %
    np.testing.assert_allclose(flux, expected, rtol=0.01)
    c = np.array(color)
    np.testing.assert_allclose(CONV.to_rgb(flux.astype(np.float64)) / CONV.to_rgb(ctx.lights.spectrum[0]),
                               (c if glass_tint == "PASS" else c * c) * 0.9216 / 0.9984, rtol=0.012)
