"""Light units against Cycles: the same .blend rendered by Cycles and by OPAL_DIFFRACTION in the
same bpy session must agree within 3 % in mean over the lit area (issue 3; docs/physics.md
section 1.5).

The scene: a grey (albedo 0.5) Diffuse BSDF plane seen from above by an orthographic camera, one
light, no world light. Both renders are written as float EXR and read back.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import blender_scenes as bs

LUMA = np.array([0.2126, 0.7152, 0.0722])

CASES = {
    "point": ("POINT", {}),
    "spot": ("SPOT", {}),
    "spot_wide_soft": ("SPOT", dict(spot_size=math.radians(90), spot_blend=1.0)),
    "sun": ("SUN", {}),
    "area_square": ("AREA", {}),
    "area_rectangle": ("AREA", dict(shape="RECTANGLE", size=1.0, size_y=0.5)),
    "area_disk": ("AREA", dict(shape="DISK", size=1.2)),
    "area_ellipse_unnormalized": ("AREA", dict(shape="ELLIPSE", size=2.0, size_y=1.2, normalize=False)),
    "point_coloured": ("POINT", dict(color=(0.9, 0.4, 0.1))),
    "point_blackbody": ("POINT", dict(use_temperature=True, temperature=3000.0)),
    "spot_exposure": ("SPOT", dict(exposure=1.0)),
}


def _lit_means(kind, props, tmp_path):
    bs.lit_plane_scene(kind, **props)
    cycles = bs.render_to_array(str(tmp_path / "cycles.exr"), "CYCLES", samples=64)
    opal = bs.render_to_array(str(tmp_path / "opal.exr"), bs.ENGINE, samples=16)
    luma = cycles @ LUMA
    lit = luma > 0.05 * luma.max()
    assert lit.sum() > 50, "the light misses the plane: bad test scene"
    return cycles[lit].mean(axis=0), opal[lit].mean(axis=0)


@pytest.mark.parametrize("case", list(CASES))
def test_lit_plane_matches_cycles(case, tmp_path):
    kind, props = CASES[case]
    c, o = _lit_means(kind, props, tmp_path)
    ratio = o / c
    print(f"{case}: cycles {np.round(c, 5)} opal {np.round(o, 5)} ratio {np.round(ratio, 4)}")
    assert np.all(np.abs(ratio - 1.0) < 0.03), f"{case}: opal/cycles = {ratio}"


def test_point_light_matches_the_analytic_value(tmp_path):
    """Y = rho / pi * I cos / r^2 with I = P / (4 pi): the convention of docs/physics.md
    section 1.5."""
    bs.lit_plane_scene("POINT")
    img = bs.render_to_array(str(tmp_path / "opal.exr"), bs.ENGINE, samples=16)
    n = img.shape[0]
    c = (np.arange(n) + 0.5) / n * 4.0 - 2.0
    x, y = np.meshgrid(c, c)
    r2 = x * x + y * y + 4.0
    expected = 0.5 / math.pi * 100.0 / (4 * math.pi) * 2.0 / r2**1.5
    assert abs(img[..., 1].mean() / expected.mean() - 1.0) < 0.01
