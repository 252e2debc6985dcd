"""A grating diffracts every emitter (issue 26; docs/physics.md section 3.13).

An emissive quad and the area light it is equivalent to (same rectangle, facing the grating,
radiance power / (pi A) = the quad's emission, docs/physics.md section 1.5) above a reflection
grating on a black base: their Diffraction passes agree (Z-test over independent pixels);
before, the quad's was exactly 0.
"""

import numpy as np
import pytest
from scipy.stats import norm

from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings

SIDE, HEIGHT, POWER = 0.2, 0.5, 5.0
CENTRE = (-0.25, 0.0, HEIGHT)


def grating_scene(emitter: str) -> Scene:
    radiance = POWER / (np.pi * SIDE * SIDE)
    mats = [{"name": "grating", "kind": "DIFFUSE", "color": (0, 0, 0), "grating": 1, "grating_type": "REFLECTION",
             "period": 1600.0, "slit_width": 800.0, "slit_count": 4, "coherence_length": 3.0}]
    if emitter == "quad":
        mats.append({"name": "panel", "kind": "DIFFUSE", "color": (0, 0, 0), "emission": (radiance,) * 3})
    s = Scene(materials=Materials.from_list(mats))
    s.add_mesh(*primitives.quad((0, 0, 0), (1.0, 0, 0), (0, 1.0, 0)), material=0, tangent=(1, 0, 0))
    if emitter == "quad":
        s.add_mesh(*primitives.quad(CENTRE, (SIDE, 0, 0), (0, -SIDE, 0)), material=1)  # (normal -z, either way)
    else:
        s.lights = Lights.from_list([{"kind": "AREA_RECT", "position": CENTRE, "direction": (0, 0, -1.0),
                                      "power": POWER, "size_u": SIDE, "size_v": SIDE, "axis_u": (1, 0, 0)}])
    s.camera = Camera.look_at((0.45, 0.0, 0.35), (0.0, 0.0, 0.0), lens=35, width=24, height=24)
    return s


@pytest.mark.slow
def test_emissive_quad_and_equivalent_area_light_give_the_same_diffraction():
    st = dict(samples=64, threads=1, filter_width=0.0, blue_noise=False, light_paths=0)
    area = render(grating_scene("area"), RenderSettings(seed=1, **st)).passes["Diffraction"]
    quad = render(grating_scene("quad"), RenderSettings(seed=2, **st)).passes["Diffraction"]
    a, q = area.mean(axis=-1).ravel().astype(np.float64), quad.mean(axis=-1).ravel().astype(np.float64)
    lit = (a > 0) | (q > 0)
    assert lit.sum() > 50 and a.mean() > 0
    diff = q[lit] - a[lit]
    z = diff.mean() / (diff.std(ddof=1) / np.sqrt(lit.sum()))
    print(f"Diffraction pass: area light {a.mean():.5f}, emissive quad {q.mean():.5f} (z {z:.2f}, {lit.sum()} pixels)")
    assert abs(z) < norm.isf(0.001 / 2)
    assert abs(q.mean() / a.mean() - 1) < 0.1  # (before: the quad gave exactly 0)
