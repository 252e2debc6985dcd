"""The grating as a lobe of the eye path (issue 26; docs/physics.md section 3.13).

A reflection grating on a black base (D = 740 nm, a = D/2: the first orders cross the horizon
inside the visible range) under a wide horizontal panel 0.5 m above it, in a black world; a
camera between them sees only the grating. Whatever the panel sends down arrives diffracted:
per pixel and wavelength bin the grating's radiance is

    L_o = sum over the propagating orders m whose source direction meets the panel of
          e_m K(w_src,m) L_panel,

e_m = (a/D)^2 sinc^2(pi m a/D) and K = (a/D) / (the propagating sum from w_src,m), enumerated
order by order here (``world_orders_reference`` of test_grating_radiometry.py, with the
panel's extent). L_panel is measured from our own render of the panel alone, seen from below
(uniform: a Lambertian panel lit by a sun from below, or an emissive panel). The emissive one
checks the multiple importance sampling of section 3.13: the grating's next event of one mesh
point and the continued path that meets the panel, each weighted by the power heuristic (before,
the next event alone: unbiased but heavy-tailed, 0.40-0.80 against 0.474).
"""

import numpy as np
import pytest

from opal_diffraction.core.render.frame import render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.sampling.camera import generate_rays
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from test_grating_radiometry import order_sum  # the plain loop over propagating orders

D, A, N = 740.0, 370.0, 300
HEIGHT, HALF = 0.5, 50.0  # the panel: 100 m square, 0.5 m above the grating
SUN_UP = np.array([0.0, 0.8, 0.6])  # the sun's light travels up onto the panel's underside
STRENGTH = 3.0
GRATING = 0.1  # the grating's half side
EYE = np.array([-0.12, 0.0, 0.1])


def panel_scene(panel: str, grating: bool = True) -> Scene:
    mats = [{"name": "grating", "kind": "DIFFUSE", "color": (0, 0, 0), "grating": 1, "grating_type": "REFLECTION",
             "period": D, "slit_width": A, "slit_count": N, "coherence_length": 100.0}]
    if panel == "lit":
        mats.append({"name": "panel", "kind": "DIFFUSE", "color": (0.8, 0.8, 0.8)})
    else:
        mats.append({"name": "panel", "kind": "DIFFUSE", "color": (0, 0, 0), "emission": (0.5, 0.5, 0.5)})
    s = Scene(materials=Materials.from_list(mats))
    if grating:  # 20 cm; its shadow on the panel lies at y > 0.5 m, where no order looks (t = x, viewer in x-z)
        s.add_mesh(*primitives.quad((0, 0, 0), (2 * GRATING, 0, 0), (0, 2 * GRATING, 0)), material=0, tangent=(1, 0, 0))
    s.add_mesh(*primitives.quad((0, 0, HEIGHT), (2 * HALF, 0, 0), (0, -2 * HALF, 0)), material=1)
    if panel == "lit":
        s.lights = Lights.from_list([{"kind": "SUN", "direction": tuple(SUN_UP), "power": STRENGTH}])
    s.world_color = np.zeros(3, np.float32)
    if grating:
        s.camera = Camera.look_at(tuple(EYE), (0, 0, 0), lens=80, width=8, height=8)
    else:  # the panel seen from below, away from where the grating would shade it
        s.camera = Camera.look_at((0.0, -0.3, 0.0), (0.0, -0.3, HEIGHT), lens=50, width=4, height=4)
    return s


def orders_reference(directions, at, edges, lit: bool, sub=6):
    """(P, K) sum over the propagating orders whose source direction from ``at`` (P, 2), the
    pixel's point on the grating, meets the panel (``lit``: outside the grating's shadow, the
    square shifted by the sun's travel) of e_m K(w_src,m) (t = x, s = y; K by an explicit loop
    over the orders from w_src,m), averaged over ``sub`` wavelengths per bin."""
    shadow = SUN_UP[:2] / SUN_UP[2] * HEIGHT
    rho = A / D

    w_o = -np.asarray(directions, np.float64)
    out = np.zeros((len(w_o), len(edges) - 1))
    for k in range(len(edges) - 1):
        lams = edges[k] + (np.arange(sub) + 0.5) / sub * (edges[k + 1] - edges[k])
        for i, w in enumerate(w_o):
            total = 0.0
            for lam in lams:
                for m in range(-12, 13):
                    u, v = m * lam / D - w[0], -w[1]  # the source direction's cosines
                    if u * u + v * v >= 1.0:
                        continue
                    z = np.sqrt(1.0 - u * u - v * v)
                    px, py = at[i, 0] + u * HEIGHT / z, at[i, 1] + v * HEIGHT / z
                    if max(abs(px), abs(py)) > HALF:  # misses the panel: the black world
                        continue
                    if lit and abs(px - shadow[0]) < GRATING and abs(py - shadow[1]) < GRATING:
                        continue
                    x = np.pi * m * rho
                    e = rho * rho * (1.0 if m == 0 else (np.sin(x) / x) ** 2)
                    total += e * rho / order_sum(D, A, u, v, lam)
            out[i, k] = total / sub
    return out


def measured_panel(panel: str) -> np.ndarray:
    """The panel's radiance spectrum (n,), from our own render of it seen from below."""
    res = render(panel_scene(panel, grating=False), RenderSettings(samples=16, threads=1, light_paths=0, seed=3),
                 spectral_film=True)
    spec = res.spectral.reshape(-1, res.spectral.shape[-1]).astype(np.float64)
    assert np.allclose(spec, spec.mean(axis=0), rtol=1e-3)  # uniform (a sun: no noise)
    return spec.mean(axis=0)


@pytest.mark.parametrize("panel", ["lit", "emissive"])
def test_grating_under_a_panel_gives_the_order_sum_of_its_radiance(panel):
    l_panel = measured_panel(panel)
    s = panel_scene(panel)
    # no diffuse bounce: the panel's light that the grating sends back up to it (panel -> grating ->
    # panel, ~1 %) is not in the panel alone's radiance
    st = RenderSettings(samples=64, threads=1, filter_width=0.0, blue_noise=False, light_paths=0, seed=5,
                        diffuse_bounces=0)
    res = render(s, st, spectral_film=True)
    ctx = prepare(s, st)
    n = ctx.grid.n
    px, py = np.meshgrid(np.arange(s.camera.width) + 0.5, np.arange(s.camera.height) + 0.5)
    _, d = generate_rays(s.camera, px.ravel(), py.ravel())
    at = EYE[None, :2] + EYE[2] * d[:, :2] / -d[:, 2:3]  # where the pixels' centre rays meet z = 0
    assert (d[:, 2] < 0).all() and (np.abs(at) < 0.9 * GRATING).all()  # every pixel sees the grating
    ratio = res.spectral.reshape(-1, n).astype(np.float64) / l_panel[None, :]
    expected = orders_reference(d.astype(np.float64), at, ctx.grid.bin_edges, lit=panel == "lit")
    diff = (ratio - expected).mean(axis=1)  # per pixel over the bins (independent pixels)
    sigma = diff.std(ddof=1) / np.sqrt(len(diff))
    z = diff.mean() / sigma
    print(f"{panel}: grating / panel {ratio.mean():.4f}, order sum {expected.mean():.4f}, z {z:.2f}")
    assert abs(z) < 4.0
    # the lit panel by the sun's next events at the panel; the emissive one by the grating's next
    # event of one mesh point and the continued path that meets the panel, weighted by the power
    # heuristic (section 3.13): both with little noise
    assert abs(diff.mean()) < 0.01 * expected.mean()
    assert expected.mean() > 0.3  # the orders see the panel
    # all of it is the Diffraction pass (the base is black, the world black)
    y709 = np.array([0.2126729, 0.7151522, 0.0721750])
    y_all, y_diff = res.rgb.reshape(-1, 3) @ y709, res.passes["Diffraction"].reshape(-1, 3) @ y709
    np.testing.assert_allclose(y_diff, y_all, rtol=1e-4, atol=1e-7)
