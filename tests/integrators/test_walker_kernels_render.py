"""Whole renders of the README's prism (a dispersive flint prism over stripes, a diffuse floor)
on the walker's compiled kernels against the NumPy reference: equal within noise (a Z-test over
pixel blocks, the noise measured between two seeds of the reference)."""

import numpy as np
import pytest
from scipy import stats

from opal_diffraction._scripts import load_example
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.util.jit import AVAILABLE

pytestmark = pytest.mark.skipif(not AVAILABLE, reason="numba is not installed")


def _blocks(img, k=8):
    h, w = img.shape[0] // k * k, img.shape[1] // k * k
    return img[:h, :w].reshape(h // k, k, w // k, k, -1).sum(axis=(1, 3)).reshape(-1).astype(np.float64)


def test_prism_on_the_kernels_matches_the_reference_within_noise():
    scene = load_example("prism").build_scene(96, 64)
    img = {}
    for mode in ("numpy", "auto"):
        for seed in (1, 2):
            r = render(scene, RenderSettings(samples=4, seed=seed, threads=1, kernels=mode))
            img[mode, seed] = _blocks(r.rgb)
    noise = np.abs(img["numpy", 1] - img["numpy", 2]) / np.sqrt(2)  # one render's error per block, roughly
    sigma = np.sqrt(np.mean(noise ** 2)) + 1e-12
    for seed in (1, 2):
        z = (img["auto", seed] - img["numpy", seed]) / sigma
        assert np.abs(z).max() < stats.norm.isf(0.01 / (2 * len(z))), np.abs(z).max()
    # and across seeds (independent noise): the mean image agrees within its error
    d = img["auto", 1] - img["numpy", 2]
    assert abs(d.mean()) < 4 * d.std(ddof=1) / np.sqrt(len(d))
