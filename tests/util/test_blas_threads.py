"""A render runs with one BLAS thread and gives BLAS its threads back (core/util/blas_threads.py)."""

import numpy as np
import pytest

from opal_diffraction.core.util.blas_threads import one_blas_thread
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.settings import RenderSettings

from scenes import plane_under_light

threadpoolctl = pytest.importorskip("threadpoolctl")


def _blas_threads() -> int:
    info = [i for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]
    if not info:
        pytest.skip("NumPy reports no BLAS library")
    return info[0]["num_threads"]


@pytest.fixture
def two_blas_threads():
    """BLAS at two threads or more before the test (else nothing to see: skip)."""
    if _blas_threads() < 2:
        pytest.skip("BLAS here runs one thread only")


def test_a_render_runs_with_one_blas_thread_and_restores_it(two_blas_threads):
    before = _blas_threads()
    seen = []
    scene = plane_under_light({"kind": "POINT", "position": (0, 0, 3), "power": 100.0}, pixels=16)
    res = render(scene, RenderSettings(light_paths=0, samples=2), progress=lambda f, m: seen.append(_blas_threads()))
    assert np.isfinite(res.rgb).all() and res.rgb.max() > 0
    assert seen and set(seen) == {1}
    assert _blas_threads() == before


def test_overlapping_renders_share_one_limit(two_blas_threads):
    """The first block in sets the limit and the last one out restores it, whichever order they
    leave in (the viewport's render and F12's can overlap)."""
    before = _blas_threads()
    a, b = one_blas_thread(), one_blas_thread()
    a.__enter__()
    b.__enter__()
    a.__exit__(None, None, None)  # the first one leaves while the second still runs
    assert _blas_threads() == 1
    b.__exit__(None, None, None)
    assert _blas_threads() == before
