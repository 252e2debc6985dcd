"""The compile stage (core/util/jit.py ``warm_up``, core/render/frame.py ``compile_stage``): a
process's first render on the kernels reports "compiling kernels" before anything else and renders
the built-in tiny scene first; later renders, and renders on the NumPy reference, skip it.

Each test gives jit a fresh warm-up state (monkeypatch), as a new process has.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from opal_diffraction.core.render import frame
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.util import jit

from scenes import plane_under_light

needs_numba = pytest.mark.skipif(not jit.AVAILABLE, reason=f"no JIT: {jit.UNAVAILABLE_REASON}")


@pytest.fixture
def fresh(monkeypatch):
    """A warm-up state as in a process that has not rendered yet."""
    monkeypatch.setattr(jit, "_warm", {"started": False, "finished": False})


def small_scene():
    return plane_under_light({"kind": "POINT", "position": (0, 0, 2), "power": 100.0}, size_m=1.0, pixels=8)


@needs_numba
def test_first_render_reports_the_compile_stage_first_and_later_ones_do_not(fresh, monkeypatch):
    calls = []
    real = frame._warm_up_render
    monkeypatch.setattr(frame, "_warm_up_render", lambda: (calls.append(1), real())[1])
    messages = []
    res = frame.render(small_scene(), RenderSettings(samples=1, threads=1),
                       progress=lambda f, m: messages.append((f, m)))
    assert messages[0] == (0.0, jit.COMPILE_STAGE)
    assert sum(m == jit.COMPILE_STAGE for _, m in messages) == 1
    assert calls == [1] and jit.warm_up_done()
    assert "compile_error" not in res.stats and res.stats["compile_s"] > 0
    # how many it compiled or loaded depends on what this process ran before (the counts are deltas)
    assert isinstance(res.stats["kernels_compiled"], int) and isinstance(res.stats["kernels_loaded"], int)
    messages.clear()
    again = frame.render(small_scene(), RenderSettings(samples=1, threads=1),
                         progress=lambda f, m: messages.append((f, m)))
    assert messages and all(m != jit.COMPILE_STAGE for _, m in messages)
    assert calls == [1] and "compile_s" not in again.stats


@needs_numba
def test_render_prepared_has_the_stage_too(fresh, monkeypatch):
    """The CLI and the viewport call render_prepared after their own prepare."""
    from opal_diffraction.core.render.prepare import prepare

    monkeypatch.setattr(frame, "_warm_up_render", lambda: None)
    messages = []
    res = frame.render_prepared(prepare(small_scene(), RenderSettings(samples=1, threads=1)),
                                progress=lambda f, m: messages.append(m))
    assert messages[0] == jit.COMPILE_STAGE and "compile_s" in res.stats


@pytest.mark.parametrize("how", ["settings", "environment"])
def test_the_numpy_reference_skips_it(fresh, monkeypatch, how):
    monkeypatch.setattr(frame, "_warm_up_render", lambda: pytest.fail("warmed up on the reference"))
    settings = RenderSettings(samples=1, threads=1, kernels="numpy" if how == "settings" else "auto")
    if how == "environment":
        monkeypatch.setenv(jit.KERNELS_ENV, "numpy")
    messages = []
    res = frame.render(small_scene(), settings, progress=lambda f, m: messages.append(m))
    assert jit.COMPILE_STAGE not in messages and "compile_s" not in res.stats
    assert not jit.warm_up_done()  # the next render on the kernels still warms up


def test_without_numba_it_is_skipped(fresh, monkeypatch):
    monkeypatch.setattr(jit, "AVAILABLE", False)
    assert jit.warm_up(lambda: pytest.fail("ran"), None) is None and not jit.warm_up_done()


@needs_numba
def test_it_runs_once_and_a_render_starting_meanwhile_waits_for_it(fresh):
    runs, order = [], []

    def slow():
        runs.append(1)
        time.sleep(0.3)
        order.append("warm-up done")

    first = threading.Thread(target=jit.warm_up, args=(slow, None))
    first.start()
    while not runs:
        time.sleep(0.01)
    assert jit.warm_up(slow, None) is None  # waits for the other thread's warm-up
    order.append("second returned")
    first.join()
    assert runs == [1] and order == ["warm-up done", "second returned"]


@needs_numba
def test_a_failing_warm_up_does_not_fail_the_render(fresh, monkeypatch):
    def broken():
        raise RuntimeError("boom")

    monkeypatch.setattr(frame, "_warm_up_render", broken)
    res = frame.render(small_scene(), RenderSettings(samples=1, threads=1))
    assert res.stats["compile_error"] == "RuntimeError: boom" and jit.warm_up_done()
    assert np.isfinite(res.rgb).all() and res.rgb.mean() > 0


@needs_numba
def test_the_warm_up_scene_takes_the_kernels_paths():
    """The tiny scene renders (no error) with a light pass and light from every source."""
    res = frame.render(frame.warm_up_scene(), RenderSettings(samples=1, threads=1, light_paths=4096, seed=0))
    assert res.rgb.shape == (4, 4, 3) and np.isfinite(res.rgb).all() and res.rgb.mean() > 0
    assert res.stats["kernels"] == "numba" and res.stats.get("light_rays", 0) > 0


@needs_numba
def test_rough_surfaces_get_their_own_stage_once_and_only_scenes_with_them(fresh, monkeypatch):
    """The GGX kernels' stage (frame.rough_warm_up_scene) runs before the first render whose scene
    has a rough surface, once per process, reported as the compile stage; a scene without one
    does not run it."""
    monkeypatch.setattr(jit, "_stages", {})
    calls = []
    monkeypatch.setattr(frame, "_warm_up_render", lambda stopped=None: calls.append("core"))
    monkeypatch.setattr(frame, "_rough_warm_up_render", lambda stopped=None: calls.append("rough"))
    frame.render(small_scene(), RenderSettings(samples=1, threads=1))
    assert calls == ["core"]
    rough = small_scene()
    rough.materials.roughness[:] = 0.4
    rough.materials.metallic[:] = 1.0
    messages = []
    res = frame.render(rough, RenderSettings(samples=1, threads=1), progress=lambda f, m: messages.append(m))
    assert calls == ["core", "rough"] and messages[0] == jit.COMPILE_STAGE and "compile_s" in res.stats
    frame.render(rough, RenderSettings(samples=1, threads=1))
    assert calls == ["core", "rough"]


@needs_numba
def test_the_rough_stage_scene_takes_every_lobe():
    from opal_diffraction.core.materials import bsdf
    from opal_diffraction.core.render.prepare import prepare

    prepared = prepare(frame.rough_warm_up_scene(), RenderSettings(samples=1))
    assert prepared.microfacet[1:].all()
    m = prepared.materials
    params = bsdf.params_from_materials(m, np.arange(len(m.kind)), np.ones(len(m.kind), bool))
    assert {bsdf.CONDUCTOR, bsdf.PLASTIC, bsdf.DIELECTRIC, bsdf.GLOSSY} <= set(np.unique(params.lobe).tolist())
