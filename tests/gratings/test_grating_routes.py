"""One order distribution for both passes (docs/physics.md sections 3.2, 3.10; issue 26).

A transmission grating (D = 740 nm, a/D = 0.3: the Harvey-Shack factor is ~1.4 where only the
orders 0, +-1 propagate) under a sun, a white screen 10 cm behind it, seen by a camera between
them. The screen's light reaches the camera by two routes: eye-only (screen -> bounce -> grating:
the eye pass's finite-N radiance, renormalised) and through the light pass (sun -> grating
order -> caustic map on the screen; the eye pass then leaves diffuse -> grating -> light out).
They must agree (Z-test: the eye route's noise from its independent pixels, the light route's
from the spread of 4 seeds). Before the light pass renormalised, its screen was 1/K = 0.74 of
the eye-only one. Both must also give the screen lit by a sun of power a/D (the grating sends
a/D forward), less the slit-length spread's evanescent tail (2 lambda / (pi^2 L) ~ 2 % at
L = 5 um; both routes lose it): within 5 %.
"""

import numpy as np
import pytest
from scipy.stats import norm

from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings

GAP, SIZE, RATIO = 0.1, 1.2, 0.3


def screen_scene(grating=True):
    mats = [{"name": "screen", "kind": "DIFFUSE", "color": (0.8, 0.8, 0.8)}]
    if grating:
        mats.append({"name": "grating", "kind": "DIFFUSE", "color": (0, 0, 0), "grating": 1,
                     "grating_type": "TRANSMISSION", "period": 740.0, "slit_width": 740.0 * RATIO, "slit_count": 5,
                     "coherence_length": 5.0})
    s = Scene(materials=Materials.from_list(mats))
    if grating:
        s.add_mesh(*primitives.quad((0, 0, 0), (SIZE, 0, 0), (0, SIZE, 0)), material=1, tangent=(1, 0, 0))
    s.add_mesh(*primitives.quad((0, 0, -GAP), (SIZE, 0, 0), (0, SIZE, 0)), material=0)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": (0, 0, -1.0), "power": 1.0 if grating else RATIO}])
    s.camera = Camera.look_at((0, -0.01, -GAP / 3), (0, 0, -GAP), lens=50, width=32, height=32)
    return s


@pytest.mark.slow
def test_eye_only_and_light_pass_routes_agree():
    ref = float(render(screen_scene(False), RenderSettings(samples=4, light_paths=0, threads=1, filter_width=0.0),
                       spectral_film=True).spectral.mean())
    st = dict(threads=1, filter_width=0.0, blue_noise=False)  # independent pixels
    eye = render(screen_scene(), RenderSettings(samples=64, light_paths=0, seed=3, **st), spectral_film=True)
    px = eye.spectral.mean(axis=2).ravel().astype(np.float64) / ref
    eye_mean, eye_sigma = px.mean(), px.std(ddof=1) / np.sqrt(px.size)
    assert eye.passes["Caustics"].max() == 0 and eye.passes["Diffraction"].mean() > 0
    seeds = []
    for seed in range(4):
        res = render(screen_scene(), RenderSettings(samples=1, light_paths=500_000, seed=seed, **st), spectral_film=True)
        assert res.passes["Diffraction"].max() == 0 and res.passes["Caustics"].mean() > 0  # the light pass's route only
        seeds.append(float(res.spectral.mean()) / ref)
    light_mean, light_sigma = np.mean(seeds), np.std(seeds, ddof=1) / np.sqrt(len(seeds))
    z = (eye_mean - light_mean) / np.hypot(eye_sigma, light_sigma)
    print(f"screen / (sun of power a/D): eye-only {eye_mean:.4f} +- {eye_sigma:.4f}, "
          f"light pass {light_mean:.4f} +- {light_sigma:.4f} (z {z:.2f})")
    assert abs(z) < norm.isf(0.001 / 2)
    for mean, sigma in ((eye_mean, eye_sigma), (light_mean, light_sigma)):
        assert abs(mean - 1.0) < 0.05 + 4 * sigma
