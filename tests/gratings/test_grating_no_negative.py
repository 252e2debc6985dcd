"""No negative pixel in the grating scenes (issue 26; docs/physics.md section 10.2).

The documented grating scenes (examples/gratings.py: Fig. 5, the CD under a lamp, the CD in a
studio, the CD in a room with an emissive monitor: its next event and order lobe weighted by
MIS) at a low resolution and sample count: the spectral film is never negative (radiance),
and the image and every colour pass have no negative channel, while the plain linear
conversion of the same spectra (computed here from the spectral film with the converter's
matrix) does have some (the orders' spectral colours are outside the gamut: the test sees
them). The mapped image keeps each pixel's luminance (Rec.709 Y of the plain conversion).
The passes still add up to the image.
"""

import numpy as np
import pytest

from opal_diffraction.core.render.film import into_gamut
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene.settings import RenderSettings

Y709 = np.array([0.2126729, 0.7151522, 0.0721750])


def _example():
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "examples" / "gratings.py"
    spec = importlib.util.spec_from_file_location("gratings_example", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.slow
@pytest.mark.parametrize("name", ["fig5", "cd", "cd_studio", "cd_room"])
def test_grating_scenes_have_no_negative_pixel(name):
    scene = _example().SCENES[name](64, 48)
    st = RenderSettings(samples=2, threads=1, seed=1, filter_width=0.0)
    res = render(scene, st, spectral_film=True)
    assert res.spectral.min() >= 0.0
    plain = res.spectral.astype(np.float64) @ prepare(scene, st).conv.rgb_weights.astype(np.float64)
    assert res.rgb.min() >= 0.0
    for k in ("Direct", "Indirect", "Caustics", "Diffraction"):
        assert res.passes[k].min() >= 0.0, (k, res.passes[k].min())
    mapped = (plain.min(axis=-1) < 0).sum()
    print(f"{name}: {mapped} pixels out of gamut, plain minimum {plain.min():.3g}")
    assert res.stats.get("out_of_gamut_pixels", 0) >= mapped  # (and where a pass alone was out of it)
    if name in ("fig5", "cd"):
        assert mapped > 0  # the plain conversion has negative channels here
    y_plain, y_got = plain @ Y709, res.rgb.astype(np.float64) @ Y709
    np.testing.assert_allclose(y_got, np.maximum(y_plain, 0), rtol=1e-4, atol=1e-5 * max(y_plain.max(), 1e-30))
    total = sum(res.passes[k] for k in ("Direct", "Indirect", "Caustics", "Diffraction"))
    assert np.all(total <= res.rgb + 1e-4 * max(float(res.rgb.max()), 1e-30))  # the rest is emission seen
    if name == "fig5":  # nothing but the grating's light: the passes are the image
        np.testing.assert_allclose(total, res.rgb, rtol=1e-4, atol=1e-5 * float(res.rgb.max()))


def test_into_gamut_keeps_luminance_and_hue_and_the_pass_sum():
    """Colours of non-negative spectra: ``a`` a few narrow bands (a grating's orders: often out
    of gamut), ``b`` broad ones; their RGB through the converter's matrix."""
    from opal_diffraction.core.spectral.spectrum import SpectralConverter

    m = SpectralConverter().rgb_weights.astype(np.float64)  # (n, 3)
    rng = np.random.default_rng(3)
    n = len(m)
    narrow = np.zeros((50, n))
    for i in range(50):
        narrow[i, rng.integers(0, n, 2)] = rng.random(2) * 5
    a = (narrow @ m).astype(np.float32)
    b = (rng.random((50, n)) * rng.random((50, 1)) * 0.05 @ m).astype(np.float32)
    rgb = a + b
    passes = {"Diffraction": a.copy(), "Direct": b.copy()}
    before = rgb.astype(np.float64).copy()
    count = into_gamut(rgb, passes)
    neg = before.min(axis=1) < 0
    touched = neg | (a.min(axis=1) < 0)
    assert count == touched.sum() > neg.sum() > 5
    np.testing.assert_allclose(passes["Diffraction"] + passes["Direct"], rgb, atol=1e-5)  # still the sum
    assert rgb.min() >= 0 and passes["Diffraction"].min() >= 0 and passes["Direct"].min() >= 0
    y0 = before @ Y709
    np.testing.assert_allclose(rgb @ Y709, np.maximum(y0, 0), atol=1e-5)
    np.testing.assert_array_equal(rgb[~touched], before[~touched].astype(np.float32))
    pos = touched & (y0 > 0)  # hue: the chroma (rgb - Y) keeps its direction, scaled by s in [0, 1]
    c0, c1 = before[pos] - y0[pos, None], rgb[pos] - y0[pos, None]
    s = np.sum(c0 * c1, axis=1) / np.sum(c0 * c0, axis=1)
    np.testing.assert_allclose(c1, s[:, None] * c0, atol=1e-5)
    assert ((s >= -1e-6) & (s <= 1 + 1e-6)).all()
    assert np.allclose(np.minimum(rgb[pos].min(axis=1), passes["Diffraction"][pos].min(axis=1)), 0, atol=1e-5)


def test_into_gamut_leaves_a_pixel_whose_rest_is_rounding_coloured():
    """The rest of the image (rgb less its passes: the emission seen) is 0 up to float32 rounding
    where nothing emissive is seen; a rest of -1e-9 must not grey its pixel (it did: s = 0 for a
    part of luminance <= 0). A pass's own rounding negatives are set to 0, nothing else changes."""
    rgb = np.array([[0.8, 0.3, 0.05], [0.2, 0.6, 0.1]], np.float32)
    direct = rgb.copy()
    direct[0, 1] += np.float32(2e-8)  # the rest rounds to -2e-8 in G
    direct[1, 2] = np.float32(-1e-9)  # a rounding negative in the pass itself
    passes = {"Direct": direct}
    out = rgb.copy()
    count = into_gamut(out, passes)
    assert count == 0
    np.testing.assert_array_equal(out, rgb)
    assert passes["Direct"][1, 2] == 0 and passes["Direct"][0, 1] == direct[0, 1]
    # while a real out-of-gamut part still maps its pixel
    spectral = {"Diffraction": np.array([[0.5, -0.2, 0.1]], np.float32)}
    img = spectral["Diffraction"] + np.float32(0.0)
    assert into_gamut(img, spectral) == 1 and img.min() >= 0
