"""Multiple importance sampling of emitters seen along a grating's orders (issue 26;
docs/physics.md section 3.13).

A reflection grating on a black base (D = 740 nm, a = D/2, N = 300, L = 100 um) in a black world
under an emissive panel 0.5 m above it: a wide one (100 m) and a small one (10 cm, seen through
order -1 in part of the spectrum). The panel's light reaches the camera by two strategies: the
grating's next event of one mesh point (solid-angle pdf of core/lights/mesh_lights.py) and the
path continued along a sampled order (the order lobe, whose pdf is the finite-N pattern over its
propagating power, ``gratings.lobe.lobe_pdf``). Weighted by the power heuristic they must give
the same image as the partition that came before (each mesh by the next event alone,
``grating_hits.MIS = False``): a Z-test over independent pixels of the per-pixel means over
seeds. The per-pixel variance over seeds must drop where the next event alone is heavy-tailed
(the wide panel: a sharp order picks a sliver of it) and must not grow for the small one.
"""

import numpy as np
import pytest
from scipy.stats import norm

import opal_diffraction.core.integrators.eye.grating_hits as stage
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings

D, A, N = 740.0, 370.0, 300
HEIGHT = 0.5
EYE = (-0.12, 0.0, 0.1)
SEEDS = 4


def panel_scene(half: float) -> Scene:
    mats = [{"name": "grating", "kind": "DIFFUSE", "color": (0, 0, 0), "grating": 1, "grating_type": "REFLECTION",
             "period": D, "slit_width": A, "slit_count": N, "coherence_length": 100.0},
            {"name": "panel", "kind": "DIFFUSE", "color": (0, 0, 0), "emission": (0.5, 0.5, 0.5)}]
    s = Scene(materials=Materials.from_list(mats))
    s.add_mesh(*primitives.quad((0, 0, 0), (0.2, 0, 0), (0, 0.2, 0)), material=0, tangent=(1, 0, 0))
    s.add_mesh(*primitives.quad((0, 0, HEIGHT), (2 * half, 0, 0), (0, -2 * half, 0)), material=1)
    s.world_color = np.zeros(3, np.float32)
    s.camera = Camera.look_at(EYE, (0, 0, 0), lens=80, width=12, height=12)
    return s


def seeds_of(scene, mis: bool, monkeypatch) -> np.ndarray:
    """(SEEDS, pixels) the pixels' spectral means, one row per seed."""
    monkeypatch.setattr(stage, "MIS", mis)
    rows = []
    for seed in range(SEEDS):
        st = RenderSettings(samples=16, threads=1, filter_width=0.0, blue_noise=False, light_paths=0, seed=seed,
                            diffuse_bounces=0)
        rows.append(render(scene, st, spectral_film=True).spectral.mean(axis=-1).ravel().astype(np.float64))
    return np.array(rows)


@pytest.mark.slow
@pytest.mark.parametrize("half, gain", [(50.0, 10.0), (0.05, 1.0)])
def test_mis_keeps_the_mean_and_cuts_the_variance(half, gain, monkeypatch):
    scene = panel_scene(half)
    weighted, partition = seeds_of(scene, True, monkeypatch), seeds_of(scene, False, monkeypatch)
    lit = (partition.mean(axis=0) > 0) | (weighted.mean(axis=0) > 0)
    assert lit.sum() >= 40  # the orders see the panel in most pixels
    diff = weighted.mean(axis=0)[lit] - partition.mean(axis=0)[lit]
    z = diff.mean() / (diff.std(ddof=1) / np.sqrt(lit.sum()))
    var_w = weighted.var(axis=0, ddof=1)[lit].mean()
    var_p = partition.var(axis=0, ddof=1)[lit].mean()
    print(f"panel {2 * half:g} m: mean weighted {weighted[:, lit].mean():.6f}, partition {partition[:, lit].mean():.6f} "
          f"(z {z:.2f}); per-pixel variance over seeds weighted {var_w:.3e}, partition {var_p:.3e} "
          f"(ratio {var_p / var_w:.1f})")
    assert abs(z) < norm.isf(0.001 / 2)
    assert var_p >= gain * var_w


@pytest.mark.parametrize("slits, exclude_zeroth", [(4, False), (10, True), (300, False), (300, True)])
def test_finite_pattern_sampler_carries_the_pattern_cell_by_cell(slits, exclude_zeroth):
    """``sample_finite_pattern``'s weighted samples per cell of exit u against the plain pattern
    integrated over the cell by the trapezoid rule (the formula written here: (a/D)^2 (N D/lambda)
    sinc^2(pi a u/lambda) [sin(N eta) / (N sin eta)]^2, eta = pi D u/lambda, over the propagating
    range at the viewer's v; the spread along s negligible at L = 1 cm, its table's 0.04 % tail
    left out): the lobe estimates the next events' integrand, evanescent orders' tails inside
    the disk and missing orders included; the |eta| < pi/2 period left out where asked."""
    from opal_diffraction.core.gratings.lobe import sample_finite_pattern

    rng = np.random.default_rng(7)
    b, d, lam, ratio, length = 400_000, 740.0, 600.0, 0.5, 1e7
    th = np.radians(30.0)
    w = np.array([np.sin(th), 0.05, np.cos(th)])
    w /= np.linalg.norm(w)
    w_o = np.tile(w, (b, 1))
    t, s, n = (np.tile(v, (b, 1)) for v in ([1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]))
    direction, weight = sample_finite_pattern(w_o, n, t, s, np.full(b, d), ratio, slits, length, np.full(b, lam),
                                              False, rng, exclude_zeroth=exclude_zeroth)
    alpha, beta = w[0], w[1]
    r = np.sqrt(1 - beta * beta)
    ok = weight > 0
    assert np.allclose(np.linalg.norm(direction[ok], axis=1), 1.0) and (direction[ok, 2] > 0).all()
    u_src = direction[:, 0]
    edges = np.linspace(-r, r, 41)
    uu = np.linspace(-r, r, 2_000_001)
    eta = np.pi * d * (uu + alpha) / lam
    sin_eta = np.sin(eta)
    safe = np.abs(sin_eta) > 1e-12
    multi = np.where(safe, (np.sin(slits * eta) / (slits * np.where(safe, sin_eta, 1.0))) ** 2, 1.0)
    f = ratio ** 2 * (slits * d / lam) * np.sinc(ratio * eta / np.pi) ** 2 * multi
    if exclude_zeroth:
        f = np.where(np.abs(eta) < np.pi / 2, 0.0, f)
    cells = len(edges) - 1
    bound = norm.isf(0.001 / (2 * cells))
    quantum = 10 * weight[ok].mean() / b  # cells expecting a few samples (far tails): Poisson, not normal
    for i in range(cells):
        inside = (uu >= edges[i]) & (uu < edges[i + 1])
        expected = np.trapz(f[inside], uu[inside]) * 0.9996
        x = np.where((u_src >= edges[i]) & (u_src < edges[i + 1]) & ok, weight, 0.0)
        se = x.std() / np.sqrt(b)
        assert abs(x.mean() - expected) < bound * se + 1e-4 * expected + quantum, (i, x.mean(), expected, se)
