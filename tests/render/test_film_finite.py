"""The film's last finite check (core/render/film.py black_non_finite): a NaN or an infinity that
reaches the film is never a silent success, and a finite film is left bit for bit as it was."""

import numpy as np

from opal_diffraction.core.render.film import Film
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.spectral.spectrum import SpectralConverter


def film_with(values):
    conv = SpectralConverter(RenderSettings(wavelength_step=50.0).grid())
    film = Film(4, 2, conv, spectral=True)
    n = conv.grid.n
    spec = np.full((8, n), 0.25, np.float32)
    for pixel, value in values:
        spec[pixel, 0] = value
    film.add_converted(0, 0, 4, 2, conv.to_rgb(spec), {}, 1, spectral=spec)
    return film


def result(film):
    return film.result(None, False, ["earlier"], {}, final=True)


def test_non_finite_pixels_are_black_and_counted_in_a_warning():
    res = result(film_with([(1, np.inf), (6, np.nan)]))
    assert res.warnings[0] == "earlier"
    assert len(res.warnings) == 2 and res.warnings[1].startswith("2 pixels of 8 had a non-finite value"), res.warnings
    assert res.stats["non_finite_pixels"] == 2
    for arr in [res.rgb, res.spectral, *res.passes.values()]:
        assert np.isfinite(arr).all()
        assert (arr.reshape(8, -1)[[1, 6]] == 0).all()
    assert (res.rgb.reshape(8, 3)[0] > 0).all()  # the other pixels keep their value


def test_a_finite_film_is_untouched_and_warns_nothing():
    a, b = result(film_with([])), film_with([])
    assert a.warnings == ["earlier"] and "non_finite_pixels" not in a.stats
    # the same means as computed without the check
    np.testing.assert_array_equal(a.rgb, b.rgb / np.maximum(b.counts, 1)[..., None])
    assert (a.spectral == 0.25).all()
