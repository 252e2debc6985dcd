"""core/lights/sources.py's point-light kernel (``_point_kernel``) against the NumPy lines of
``sample_light``: the same float32 steps in the same order, so the same bits."""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.lights import sources
from opal_diffraction.core.scene.model import Lights
from opal_diffraction.core.spectral.spectrum import SpectralConverter
from opal_diffraction.core.util.jit import AVAILABLE

pytestmark = pytest.mark.skipif(not AVAILABLE, reason="numba is not available")


def _sample(pl, p, on, monkeypatch):
    with monkeypatch.context() as m:
        m.setattr(sources, "kernels_enabled", lambda: on)
        return sources.sample_light_pdf(pl, 0, p, np.random.default_rng(1))


def test_the_point_light_kernel_is_sample_lights_numpy_lines(monkeypatch):
    pl = sources.prepare_lights(Lights.from_list([{"kind": "POINT", "position": (0.3, -1.2, 2.5), "power": 50.0}]),
                                SpectralConverter())
    rng = np.random.default_rng(2)
    p = (rng.random((5000, 3)) * 6 - 3).astype(np.float32)
    p[0] = pl.position[0].astype(np.float32)  # at the light: d^2 clamped to 1e-30
    got = _sample(pl, p, True, monkeypatch)
    ref = _sample(pl, p, False, monkeypatch)
    assert got[3] is None and ref[3] is None  # a delta light: no pdf
    for a, b in zip(got[:3], ref[:3]):
        assert a.dtype == b.dtype == np.float32
        np.testing.assert_array_equal(a, b)
