"""A cancel (or render_prepared's time limit) during the compile stage (core/util/jit.py
``warm_up``, core/render/frame.py ``compile_stage``): the render returns within a few polls with
a result that says so, the warm-up stops at its next check, and the stage is not marked done, so
the next render runs it again. The warm-up render is replaced by one that takes seconds and
checks its ``stopped`` (as the real one does between its stages, units and ray casts)."""

from __future__ import annotations

import threading
import time

import pytest

from opal_diffraction.core.render import frame
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.util import jit
from opal_diffraction.core.util.cancel import POLL_S

pytestmark = pytest.mark.skipif(not jit.AVAILABLE or not jit.kernels_enabled(),
                                reason="the compile stage runs only on the kernels")


def _scene():
    s = Scene(materials=Materials.from_list([{"color": (0.5, 0.5, 0.5)}]))
    s.add_mesh(*primitives.quad((-1, -1, 0), (2, 0, 0), (0, 2, 0)), material=0)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (0, 0, 2), "power": 100.0}])
    s.camera = Camera.look_at((0, -3, 3), (0, 0, 0), width=8, height=8)
    return s


class SlowWarmUp:
    """A warm-up of ``seconds`` in steps of 20 ms, stopping when ``stopped()`` says so."""

    def __init__(self, seconds=3.0):
        self.seconds, self.runs, self.stopped_after = seconds, 0, None
        self.threads = []  # the thread each run ran on, and whether it had a check

    def __call__(self, stopped=None):
        self.runs += 1
        self.threads.append((threading.get_ident(), stopped is not None))
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < self.seconds:
            if stopped is not None and stopped():
                self.stopped_after = time.perf_counter() - t0
                return
            time.sleep(0.02)


@pytest.fixture
def slow(monkeypatch):
    monkeypatch.setattr(jit, "_warm", {"started": False, "finished": False, "runner": None})
    warm = SlowWarmUp()
    monkeypatch.setattr(frame, "_warm_up_render", warm)
    return warm


def test_a_cancel_during_the_compile_stage_returns_at_once_and_the_stage_runs_again(slow):
    t0 = time.perf_counter()
    res = frame.render(_scene(), RenderSettings(samples=1, light_paths=0, wavelength_step=40.0),
                       should_cancel=lambda: time.perf_counter() - t0 > 0.3)
    took = time.perf_counter() - t0
    assert took < 0.3 + 3 * POLL_S + 0.2, took
    assert res.cancelled and res.samples == 0 and "cancelled while compiling the kernels" in res.warnings
    time.sleep(0.1)
    assert slow.stopped_after is not None and slow.stopped_after < 0.3 + 0.2  # it stopped too
    assert not jit.warm_up_done()
    slow.seconds = 0.1
    res = frame.render(_scene(), RenderSettings(samples=1, light_paths=0, wavelength_step=40.0))
    assert slow.runs == 2 and jit.warm_up_done() and res.samples == 1 and "compile_s" in res.stats
    assert slow.threads[0][0] != threading.get_ident() and slow.threads[0][1]  # polled from here


def test_render_prepared_counts_the_compile_stage_against_its_time_limit(slow):
    prepared = prepare(_scene(), RenderSettings(samples=1, light_paths=0, wavelength_step=40.0, time_limit=0.4))
    t0 = time.perf_counter()
    res = frame.render_prepared(prepared, started_at=t0)
    took = time.perf_counter() - t0
    assert took < 0.4 + 3 * POLL_S + 0.2, took
    assert not res.cancelled and res.samples == 0
    assert any("time limit (0.4 s) reached while compiling the kernels" in w for w in res.warnings), res.warnings
    assert not jit.warm_up_done()


def test_without_a_cancel_check_the_stage_runs_in_the_calling_thread(slow):
    slow.seconds = 0.05
    res = frame.render(_scene(), RenderSettings(samples=1, light_paths=0, wavelength_step=40.0))
    assert slow.runs == 1 and slow.stopped_after is None and jit.warm_up_done() and res.samples == 1
    assert slow.threads == [(threading.get_ident(), False)]
