"""Grating scenes that overflowed to Inf / NaN pixels reported as success (issue 27): a light on
the grating's own surface makes the incident direction grazing, where float rounding put its
tangential part just outside the unit disk, every order (the specular one too) evanescent and
the Harvey-Shack factor 1 / 1e-300. Fixed in kernel._in_unit_disk; the film's last finite check
(core/render/film.py black_non_finite) is tested in tests/render/test_film_finite.py."""

import numpy as np
import pytest

from opal_diffraction.core.gratings.kernel import harvey_shack_factor, hexagonal_harvey_shack_factor
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings

SETTINGS = RenderSettings(samples=1, wavelength_step=20, threads=1, light_paths=0)


def all_finite(res) -> dict:
    """Non-finite values per output (empty: all finite)."""
    arrays = [("rgb", res.rgb), ("spectral", res.spectral)] + list(res.passes.items())
    return {k: int((~np.isfinite(a)).sum()) for k, a in arrays if not np.isfinite(a).all()}


@pytest.mark.parametrize("grating_type", ["REFLECTION", "TRANSMISSION"])
def test_hexagonal_grating_on_a_bk7_box_with_a_light_on_its_corner_is_finite(grating_type):
    s = Scene(materials=Materials.from_list([{
        "kind": "DIELECTRIC", "dispersion": "BK7", "grating": 1, "grating_type": grating_type,
        "lattice": "HEXAGONAL", "period": 400.0, "slit_width": 400.0, "slit_count": 64, "coherence_length": 0.001}]))
    s.add_mesh(*primitives.box((0, 0, 0), (1, 1, 1)), material=0)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (0.5, 0.5, 0.5), "power": 100.0}])  # a corner
    s.camera = Camera.look_at((0, -4, 3), (0, 0, 0), width=8, height=8)
    res = render(s, RenderSettings(samples=2, wavelength_step=20, threads=1), spectral_film=True)
    assert not all_finite(res), all_finite(res)  # the base gave 3 Inf pixels (TRANSMISSION)
    assert not any("non-finite" in w for w in res.warnings), res.warnings
    assert res.passes["Diffraction"].max() > 0  # the grating is seen


@pytest.mark.parametrize("grating_type", ["TRANSMISSION", "REFLECTION"])
def test_lines_grating_on_a_mirror_sphere_with_a_light_on_its_surface_is_finite(grating_type):
    s = Scene(materials=Materials.from_list([{
        "kind": "MIRROR", "grating": 1, "grating_type": grating_type, "lattice": "LINES", "period": 1.0,
        "slit_width": 1e-6, "slit_count": 1, "coherence_length": 20.0}]))
    v, t = primitives.icosphere((0, 0, 0), 1.0, subdivisions=1)
    s.add_mesh(v, t, material=0)
    light = tuple(v[4]) if grating_type == "TRANSMISSION" else (0.0, 0.0, 1.0)  # vertices (NaN / Inf on the base)
    assert np.min(np.linalg.norm(v - np.array(light), axis=1)) < 1e-6
    s.lights = Lights.from_list([{"kind": "POINT", "position": light, "power": 100.0}])
    s.camera = Camera.look_at((0, -4, 3), (0, 0, 0), width=16, height=16)
    res = render(s, SETTINGS, spectral_film=True)
    assert not all_finite(res), all_finite(res)
    assert not any("non-finite" in w for w in res.warnings), res.warnings


def grazing(n=200):
    """Unit tangential directions (alpha, beta) nudged so alpha^2 + beta^2 > 1 by rounding."""
    phi = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    a, b = np.cos(phi) * (1 + 1e-15), np.sin(phi) * (1 + 1e-15)  # 1 + 2e-15: as rounding gives
    assert (a * a + b * b > 1.0).all()
    return a, b


@pytest.mark.parametrize("ratio, d", [(1e-6, 1.0), (0.3, 1600.0), (1.0, 400.0)])
def test_harvey_shack_factor_at_grazing_incidence_is_bounded_by_the_zeroth_order(ratio, d):
    """The specular order always propagates: LINES carries at least (a/D)^2 sinc^2(0), so
    K = (a/D) / power <= D / a; HEXAGONAL at least f [2 J1(0)/0]^2 = f, so K <= 1 / f."""
    a, b = grazing()
    lam = np.full_like(a, 550.0)
    k = harvey_shack_factor(a, b, lam, ratio, d)
    assert np.isfinite(k).all() and (k >= 1 - 1e-12).all() and (k <= 1 / ratio * (1 + 1e-9)).all(), k.max()
    kh = hexagonal_harvey_shack_factor(a, b, lam, ratio, d)
    fill = np.pi * ratio**2 / (2 * np.sqrt(3))
    assert np.isfinite(kh).all() and (kh <= 1 / fill * (1 + 1e-9)).all(), kh.max()
    # just inside the disk the factor is the same (continuity: the nudge is rounding, not physics)
    s = 1 - 1e-12
    np.testing.assert_allclose(harvey_shack_factor(a * s, b * s, lam, ratio, d), k, rtol=1e-9)
    np.testing.assert_allclose(hexagonal_harvey_shack_factor(a * s, b * s, lam, ratio, d), kh, rtol=1e-9)
