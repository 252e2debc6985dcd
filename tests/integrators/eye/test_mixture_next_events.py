"""Next events over the whole lobe mixture in the eye pass (core/materials/mixtures.py LobeMixture,
core/integrators/eye/next_event.py MicrofacetLobe, continuation.py microfacet_bounce; docs/physics.md
section 14.8): a Diffuse + Glossy (0.5 / 0.5, roughness 0.25) sphere under a small area light,
black world. Rendered with every lobe evaluated at the next events and the mixture's f / p at the
bounce, and with the one-lobe-per-hit estimate (the mixture dropped: what the eye pass did
before), over independent seeds: the sphere's mean radiance agrees (a Z-test over the seeds'
sums) and the per-pixel variance is lower.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import norm

from opal_diffraction.core.integrators.eye import eye_pass
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings

Z = norm.isf(1e-3 / 2)
LUM = np.array([0.2126, 0.7152, 0.0722])


def _scene() -> Scene:
    mats = Materials.from_list([dict(name="mix", kind="DIFFUSE", color=(0.8, 0.3, 0.1), metal_color=(0.9, 0.9, 0.9),
                                     metallic=0.5, roughness=0.25)])
    s = Scene(materials=mats, world_color=np.zeros(3, np.float32))
    s.add_mesh(*primitives.icosphere((0, 0, 0), 1.0, 3), material=0)
    s.lights = Lights.from_list([{"kind": "AREA_RECT", "position": (1.5, -1.5, 2.5), "direction": (-0.4, 0.4, -0.8),
                                  "size_u": 0.3, "size_v": 0.3, "power": 100.0}])
    s.camera = Camera.look_at((0.0, -4.0, 0.5), (0, 0, 0), lens=50, width=32, height=32)
    return s


def _renders(seeds, monkeypatch, whole: bool) -> np.ndarray:
    if not whole:
        lobes = eye_pass.surface_lobes
        monkeypatch.setattr(eye_pass, "surface_lobes", lambda *a, **k: (lobes(*a, **k)[0], None))
    out = []
    for seed in seeds:
        r = render(_scene(), RenderSettings(samples=4, light_paths=0, threads=1, wavelength_step=20.0, seed=seed,
                                            max_bounces=2))
        assert not r.warnings
        assert np.isfinite(r.rgb).all() and r.rgb.min() >= 0
        out.append(r.rgb @ LUM)
    monkeypatch.undo()
    return np.array(out)


def test_whole_mixture_next_events_keep_the_mean_and_lower_the_variance(monkeypatch):
    seeds = range(16)
    a = _renders(seeds, monkeypatch, whole=True)
    b = _renders(seeds, monkeypatch, whole=False)
    sphere = (a.mean(0) > 0.01) | (b.mean(0) > 0.01)
    assert sphere.sum() > 150
    sa, sb = a[:, sphere].sum(1), b[:, sphere].sum(1)
    n = len(sa)
    z = (sa.mean() - sb.mean()) / np.sqrt(sa.var(ddof=1) / n + sb.var(ddof=1) / n)
    ratio = a.var(0, ddof=1)[sphere].sum() / b.var(0, ddof=1)[sphere].sum()
    print(f"sphere sum {sa.mean():.3f} vs one lobe {sb.mean():.3f} (z {z:.2f}); pixel variance ratio {ratio:.3f}")
    assert abs(z) < Z
    assert ratio < 0.6
