"""Films in RGB unless a spectral image is asked (core/render/film.py): no (H, W, n) spectral film
without a spectral EXR, the RGB image equal to the conversion of the spectral one within float32
rounding, and the spectral EXR still written from the spectral film."""

import os
import tracemalloc

import numpy as np
import pytest

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.render.film import Film
from opal_diffraction.core.render.output import read_exr, spectral_channel_name, write_spectral_exr
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.settings import RenderSettings, film_bytes
from opal_diffraction.core.spectral.spectrum import SpectralConverter
from stripe_scenes import prism_and_stripes


def prism_scene(width=32, height=24):
    """Stripes under a sun seen through a dispersive prism: colours the RGB image mixes from
    very different spectra (a grey scene would hide a wrong conversion)."""
    return prism_and_stripes(width, height, colors=((0.9, 0.6, 0.2), (0.05, 0.2, 0.6)))


def plane_scene(width, height):
    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE", "color": (0.8, 0.4, 0.1)}]))
    s.add_mesh(*primitives.quad((0, 0, 0), (10, 0, 0), (0, 10, 0)), material=0)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": (0.2, 0.1, -1.0), "power": 3.0}])
    s.camera = Camera.look_at((0, -3, 3), (0, 0, 0), width=width, height=height)
    return s


# several rounds, several tiles, so the film adds each pixel several times (rounding can show)
SETTINGS = RenderSettings(samples=4, round_samples=1, tile_size=16, light_paths=0, seed=5, threads=1)


def test_no_spectral_film_unless_a_spectral_image_is_asked():
    s = prism_scene()
    rgb_only = render(s, SETTINGS)
    assert rgb_only.spectral is None and rgb_only.rgb.shape == (24, 32, 3) and rgb_only.rgb.mean() > 0
    asked = render(s, SETTINGS, spectral_film=True)
    by_setting = render(s, RenderSettings(**{**SETTINGS.__dict__, "spectral_exr": "unused.exr"}))
    n = SETTINGS.grid().n
    assert asked.spectral.shape == by_setting.spectral.shape == (24, 32, n)
    np.testing.assert_array_equal(asked.spectral, by_setting.spectral)
    # the RGB image is summed the same way whether or not the spectral film is kept
    for r in (asked, by_setting):
        np.testing.assert_array_equal(r.rgb, rgb_only.rgb)
        for k in rgb_only.passes:
            np.testing.assert_array_equal(r.passes[k], rgb_only.passes[k], err_msg=k)
    assert render(s, SETTINGS, spectral_film=False).spectral is None


def test_rgb_is_the_conversion_of_the_spectral_image_within_float32_rounding():
    """docs/physics.md section 10.1: rgb = sum over tiles of to_rgb(tile) / N against the float64
    to_rgb(sum of spectra / N):
    equal up to float32 rounding of the (4 adds + 61-term dot product) per pixel, bounded by
    (adds + n) * eps32 * (|s| @ |W|) (the standard bound for a recursive sum)."""
    res = render(prism_scene(), SETTINGS, spectral_film=True)
    conv = SpectralConverter(SETTINGS.grid())
    w = conv.rgb_weights.astype(np.float64)
    s = res.spectral.astype(np.float64)
    ref = s @ w
    bound = (SETTINGS.samples + conv.grid.n + 4) * np.finfo(np.float32).eps * (np.abs(s) @ np.abs(w))
    err = np.abs(res.rgb - ref)
    # pixels out of the Rec.709 gamut (the prism's spectral colours, or one of their passes) were
    # desaturated towards their luminance (section 10.2, film.into_gamut): there the luminance is
    # the spectrum's and the chroma (rgb - Y) the plain one's times s in [0, 1]
    mapped = ~(err <= bound + 1e-30).all(axis=-1)
    assert mapped.sum() <= res.stats.get("out_of_gamut_pixels", 0)
    if mapped.any():
        y709 = np.array([0.2126729, 0.7151522, 0.0721750])
        y = ref[mapped] @ y709
        tol = bound[mapped].max(axis=-1) * 4 + 1e-7
        assert (np.abs(res.rgb[mapped] @ y709 - y) <= tol).all()
        c0, c1 = ref[mapped] - y[:, None], res.rgb[mapped] - y[:, None]
        k = np.sum(c0 * c1, axis=1) / np.sum(c0 * c0, axis=1)
        assert ((k > -1e-6) & (k < 1 + 1e-6)).all()
        assert (np.abs(c1 - k[:, None] * c0).max(axis=1) <= tol).all()
    err = err[~mapped]
    assert (err <= bound[~mapped] + 1e-30).all(), f"worst excess {(err - bound[~mapped]).max()}"
    assert err.max() > 0 or np.allclose(ref, 0)  # the comparison is not vacuous: rounding differs somewhere
    assert np.abs(ref).max() > 0.05


def test_the_rgb_film_allocates_no_spectral_image():
    """tracemalloc (NumPy reports its buffers to it): the RGB render of a 160 x 120 image at 121
    wavelengths never holds one (H, W, n) float32 array (9.3 MB; the RGB film and passes take
    about half of that), while the spectral one holds at least one (the measurement can tell
    them apart)."""
    s = plane_scene(160, 120)  # a diffuse plane under the sun: cheap to trace with tracemalloc on
    settings = RenderSettings(**{**SETTINGS.__dict__, "samples": 1, "tile_size": 32, "wavelength_step": 2.5})
    n = settings.grid().n
    assert n == 121
    one_image = 160 * 120 * n * 4
    render(plane_scene(16, 16), settings)  # imports and colour tables first
    peaks = {}
    for spectral in (False, True):
        tracemalloc.start()
        try:
            render(s, settings, spectral_film=spectral)
            peaks[spectral] = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    print(f"traced peak: RGB film {peaks[False] / 2**20:.1f} MB, spectral film {peaks[True] / 2**20:.1f} MB, "
          f"one (H, W, n) image {one_image / 2**20:.1f} MB")
    assert peaks[False] < one_image
    assert peaks[True] > one_image


@pytest.mark.parametrize("spectral", [False, True])
def test_film_bytes_bounds_what_the_film_allocates(spectral):
    """settings.film_bytes (the CLI's memory check) against the traced allocations of a film
    with adaptive sampling, one tile added, and its final result."""
    w, h = 96, 80
    conv = SpectralConverter(RenderSettings().grid())
    n = conv.grid.n

    class Tile:
        film = np.ones((w * h, n), np.float32)
        background = indirect = diffraction = caustics = None
        albedo = normal = np.ones((w * h, 3), np.float32)

    from opal_diffraction.core.render.plan import RenderPlan

    tile = Tile()
    tracemalloc.start()
    try:
        film = Film(w, h, conv, adaptive=True, spectral=spectral)
        film.add_tile(0, 0, w, h, tile, 1, half_a=True)
        res = film.result(RenderPlan(), False, [], {}, final=True)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert (res.spectral is not None) == spectral
    estimate = film_bytes(w, h, n, spectral)
    tile_bytes = 2 * w * h * n * 4  # the tile itself and its RGB conversion's temporary
    assert peak <= estimate + tile_bytes
    assert peak >= 0.5 * estimate - tile_bytes


def test_the_spectral_exr_is_written_from_the_spectral_film(tmp_path):
    path = str(tmp_path / "spectral.exr")
    settings = RenderSettings(**{**SETTINGS.__dict__, "spectral_exr": path})
    res = render(prism_scene(), settings)
    write_spectral_exr(path, res.spectral, res.wavelengths, res.rgb)  # OpenEXR's import first
    tracemalloc.start()
    try:
        write_spectral_exr(path, res.spectral, res.wavelengths, res.rgb)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # the film's (n, H, W) planes are the EXR's channels: no copy of the spectral image
    assert peak < 0.5 * res.spectral.nbytes, (peak, res.spectral.nbytes)
    ch = read_exr(path)
    assert len(res.wavelengths) == settings.grid().n
    for i, wl in enumerate(res.wavelengths):
        np.testing.assert_array_equal(ch[spectral_channel_name(wl)], res.spectral[..., i])
    for i, c in enumerate("RGB"):
        np.testing.assert_array_equal(ch[c], res.rgb[..., i])


def test_a_spectral_exr_of_an_rgb_only_result_is_a_readable_error(tmp_path):
    res = render(prism_scene(16, 16), SETTINGS)
    path = tmp_path / "s.exr"
    with pytest.raises(SceneError, match="no spectral film.*spectral_film=True"):
        write_spectral_exr(str(path), res.spectral, res.wavelengths, res.rgb)
    assert not os.listdir(tmp_path)  # nothing written, not even a temporary file


def test_a_spectral_film_refuses_a_tile_without_its_spectra():
    conv = SpectralConverter(RenderSettings().grid())
    film = Film(8, 8, conv, spectral=True)
    with pytest.raises(ValueError, match="spectral sums"):
        film.add_converted(0, 0, 8, 8, np.zeros((64, 3), np.float32), {}, 1)
