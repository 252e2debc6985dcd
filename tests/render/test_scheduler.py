"""The scheduler's rules (core/render/scheduler.py) with a fake clock and fake units of work: units
enter the film in order whatever order they finish in, the time limit is honoured between units
(never before every pixel has round 0), a cancel stops at once and drops what is pending,
progress increases and reaches 1, adaptive sampling skips converged tiles and ends the render
when none is left. One small render checks that render_prepared runs on the injected clock, and
the viewport reaches the passes only through render/. The local executor with real units: a cancel
or time limit acts within POLL_S while a unit that takes seconds is running (it is dropped and stops
at its next ray cast), and the image is the same bits whether units run in the calling thread or on
the pollable pool."""

from __future__ import annotations

import ast
import os
import threading
import time
from dataclasses import replace

import numpy as np
import pytest

from opal_diffraction.core.render.frame import compile_stage, render_prepared
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.scheduler import POLL_S, RenderControl, eye_window, run_eye_pass
from opal_diffraction.core.render.tiles import EyeWork
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.util.cancel import RenderCancelled, StoppableAccel

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

# 3 rounds of 2 samples over 2 tiles of 4 x 4 pixels: units 0..5, unit i = round i // 2, tile i % 2
WORK = EyeWork(rounds=(2, 2, 2), tiles=((0, 0, 4, 4, 0), (4, 0, 8, 4, 1)), region=(0, 0, 8, 4), seed=0)


class FakeClock:
    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


class FakeFilm:
    """Which (round, tile) units were added, in order; a tile converges after ``rounds_to_converge``
    of its rounds (adaptive sampling): its active pixels are then none."""

    def __init__(self, rounds_to_converge=None):
        self.added: list[tuple[int, int]] = []
        self.rounds_to_converge = rounds_to_converge

    def rounds_of(self, t_index: int) -> int:
        return sum(1 for _, t in self.added if t == t_index)

    def active_pixels(self, x0, y0, x1, y1):
        if self.rounds_to_converge is None:
            return None
        t_index = [t[:4] for t in WORK.tiles].index((x0, y0, x1, y1))
        if self.rounds_of(t_index) >= self.rounds_to_converge[t_index]:
            return np.zeros(0, np.int64)
        return np.arange(16)

    def update_active(self, x0, y0, x1, y1, threshold, min_spp):
        return 0


class FakeExecutor:
    """Runs nothing: each unit takes ``seconds`` on the fake clock; ``finished`` returns the
    pending units one at a time, newest first (the film must still add them in order) or oldest
    first, after ``idle`` calls that return none (waiting for a slow unit)."""

    def __init__(self, clock: FakeClock, seconds: float = 1.0, threads: int = 2, newest_first: bool = True,
                 idle: int = 0):
        self.clock, self.seconds, self.threads = clock, seconds, threads
        self.newest_first, self.idle = newest_first, idle
        self.pending: dict[int, tuple] = {}
        self.submitted: list[tuple[int, int, int]] = []  # (key, round, tile)
        self.dropped: list[int] = []
        self.film: FakeFilm | None = None

    def submit(self, key, r_index, t_index, pixels):
        if self.film is not None and r_index > 0:  # adaptive: a tile's round waits for its previous one
            assert (r_index - 1, t_index) in self.film.added
        self.pending[key] = (r_index, t_index)
        self.submitted.append((key, r_index, t_index))

    def finished(self, timeout):
        if self.idle > 0:
            self.idle -= 1
            self.clock.now += timeout
            return []
        if not self.pending:
            return []
        key = max(self.pending) if self.newest_first else min(self.pending)
        self.clock.now += self.seconds
        return [(key, self.pending.pop(key))]

    def add(self, film, tile, samples, pixels, half_a, result):
        film.added.append(result)
        return 10

    def cancel_pending(self):
        self.dropped += sorted(self.pending)
        self.pending.clear()

    def note(self):
        return ""


def _run(film=None, time_limit=0.0, should_cancel=None, threads=2, adaptive=None, progress_from=0.0,
         newest_first=True, idle=0):
    clock = FakeClock()
    film = FakeFilm() if film is None else film
    executor = FakeExecutor(clock, 1.0, threads, newest_first, idle)
    if adaptive is not None:  # the executor checks that a tile's rounds are submitted in turn
        executor.film = film
    reports, rounds = [], []
    control = RenderControl(should_cancel, lambda f, m: reports.append((f, m)), time_limit, clock=clock)
    outcome = run_eye_pass(WORK, film, executor, control, adaptive, lambda: rounds.append(len(film.added)),
                           progress_from)
    return outcome, film, executor, reports, rounds


def test_units_enter_the_film_in_order_whatever_order_they_finish_in():
    outcome, film, executor, reports, rounds = _run()
    assert film.added == [(r, t) for r in range(3) for t in range(2)]
    assert outcome.stop == "" and outcome.rays == 60 and outcome.submitted == 6
    assert rounds == [2, 4, 6]  # on_round after each round, once its tiles are in


def test_time_limit_is_checked_after_every_unit_in_any_round():
    # 1 s per unit. A limit of 0.5 s: the first unit of round 0 ends past it: the render stops there
    outcome, film, executor, _, rounds = _run(time_limit=0.5, newest_first=False)
    assert outcome.stop == "time" and film.added == [(0, 0)] and rounds == []
    assert executor.dropped == [1, 2, 3, 4, 5]  # the units submitted ahead were cancelled
    # 1.5 s: round 0 completes at 2 s, past the limit: no round 1
    outcome, film, executor, _, rounds = _run(time_limit=1.5, newest_first=False)
    assert outcome.stop == "time" and film.added == [(0, 0), (0, 1)] and rounds == [2]
    # 2.5 s: the first unit of round 1 ends at 3 s, past the limit: the round stops midway
    outcome, film, _, _, rounds = _run(time_limit=2.5, newest_first=False)
    assert outcome.stop == "time" and film.added == [(0, 0), (0, 1), (1, 0)] and rounds == [2]
    # 10 s: every unit runs
    outcome, film, _, _, _ = _run(time_limit=10.0, newest_first=False)
    assert outcome.stop == "" and len(film.added) == 6


def test_cancel_stops_after_the_unit_in_hand_and_drops_the_pending_ones():
    film = FakeFilm()
    outcome, film, executor, reports, rounds = _run(film=film, should_cancel=lambda: len(film.added) >= 3,
                                                    newest_first=False)
    assert outcome.stop == "cancel" and len(film.added) == 3 and rounds == [2]
    assert executor.dropped == [3, 4, 5] and len(executor.submitted) == 6
    assert reports[-1][0] < 1.0  # a cancelled render does not claim to be done


def test_cancel_is_polled_while_waiting_for_a_unit():
    """A first unit that takes long: the cancel is seen while waiting for it, not after it."""
    asked = []

    def should_cancel():
        asked.append(1)
        return len(asked) > 2

    outcome, film, executor, *_ = _run(should_cancel=should_cancel, idle=100)
    assert outcome.stop == "cancel" and film.added == [] and executor.idle == 98
    assert executor.dropped == [0, 1, 2, 3, 4, 5]


@pytest.mark.parametrize("progress_from", [0.0, 0.25])
def test_progress_increases_and_reaches_one(progress_from):
    _, _, _, reports, _ = _run(progress_from=progress_from)
    fractions = [f for f, _ in reports]
    assert len(fractions) == 6 and np.all(np.diff(fractions) > 0)
    assert fractions[0] == pytest.approx(progress_from + (1 - progress_from) / 6) and fractions[-1] == 1.0
    assert all(m.startswith("eye pass: round") for _, m in reports)


def test_adaptive_sampling_skips_converged_tiles_and_stops_when_none_is_left():
    film = FakeFilm(rounds_to_converge=(2, 1))  # tile 1 converges after its first round, tile 0 after two
    outcome, film, executor, reports, rounds = _run(film=film, adaptive=(0.01, 4), threads=8)
    assert [(r, t) for _, r, t in executor.submitted] == [(0, 0), (0, 1), (1, 0)]
    assert film.added == [(0, 0), (0, 1), (1, 0)]
    assert outcome.stop == "converged" and outcome.submitted == 3
    assert rounds == [2, 3]  # round 2 added nothing: no image for it
    fractions = [f for f, _ in reports]
    assert np.all(np.diff(fractions) > 0) and fractions[-1] == 1.0
    assert reports[-1][1] == "eye pass: every pixel has converged"


def test_the_window_keeps_threads_busy_and_adaptive_rounds_in_order():
    assert eye_window(2, 100, False) == 16 and eye_window(8, 100, False) == 32
    assert eye_window(8, 10, True) == 10 and eye_window(2, 100, True) == 16


def test_the_control_keeps_a_cancel_maps_stages_and_never_goes_back():
    answers = iter([False, True, False])
    clock = FakeClock()
    seen = []
    control = RenderControl(lambda: next(answers), lambda f, m: seen.append(f), time_limit=5.0, started_at=1.0,
                            clock=clock)
    assert not control.cancelled() and control.cancelled() and control.cancelled()  # once asked, it stays
    stage = control.stage(0.0, 0.25)
    stage(0.0, "a")
    stage(0.5, "b")
    stage(0.5, "c")  # the same fraction again: not passed on
    control.report(0.1, "d")  # backwards: not passed on
    control.report(0.5, "e")
    assert seen == [0.0, 0.125, 0.5]
    clock.now = 6.0
    assert not control.out_of_time()
    clock.now = 6.5
    assert control.out_of_time()
    assert RenderControl(time_limit=0.0, clock=clock).perf_deadline() is None
    before = time.perf_counter()
    clock.now = 2.0  # 4 s left on the fake clock: the light pass gets 4 s from now
    assert before + 4.0 <= control.perf_deadline() <= time.perf_counter() + 4.0


def test_the_time_limit_is_polled_while_waiting_for_a_unit_in_round_0():
    """A unit that takes long (the executor answers nothing for 100 polls): the limit stops the
    render within one POLL_S of it, before any unit is in, and every unit is dropped."""
    outcome, film, executor, *_ = _run(time_limit=0.55, idle=100)
    assert outcome.stop == "time" and film.added == []
    assert executor.dropped == [0, 1, 2, 3, 4, 5]
    waited = (100 - executor.idle) * POLL_S
    assert 0.55 <= waited <= 0.55 + POLL_S + 1e-9


def test_render_prepared_measures_its_time_limit_on_the_injected_clock():
    """A clock that advances 1 s per reading: the render stops at its 12 s limit whatever the real
    time (after a number of readings, not of real seconds), and says so."""
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)}])
    scene = Scene(materials=mats)
    scene.add_mesh(*primitives.quad((0, 0, 0), (4, 0, 0), (0, 4, 0)), material=0)
    scene.lights = Lights.from_list([{"kind": "POINT", "position": (0, 0, 2), "power": 100.0}])
    scene.camera = Camera.look_at((0, -3, 3), (0, 0, 0), width=8, height=8)
    prepared = prepare(scene, RenderSettings(samples=64, round_samples=2, tile_size=4, light_paths=0, threads=1,
                                             wavelength_step=40.0, time_limit=12.0))
    compile_stage(prepared.settings.kernels)  # the process's compile stage first (it counts real time)
    readings = []

    def clock():
        readings.append(1)
        return float(len(readings))

    res = render_prepared(prepared, clock=clock)
    assert not res.cancelled and res.samples < 64
    assert any(w.startswith("time limit reached after") for w in res.warnings), res.warnings
    assert len(readings) < 40  # it stopped at the limit's reading, not after every unit


def test_the_viewport_reaches_the_passes_only_through_render():
    path = os.path.join(ROOT, "opal_diffraction", "blender", "viewport.py")
    tree = ast.parse(open(path, encoding="utf-8").read())
    targets = [node.module or "" for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)]
    assert any(t.startswith("core.render") for t in targets)
    assert not [t for t in targets if t.startswith("core.integrators")], targets


# ------------------------------------------------------------------ the local executor, real units
def _small_prepared(**kw):
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)}, {"kind": "MIRROR", "color": (0.9, 0.9, 0.9)}])
    scene = Scene(materials=mats)
    scene.add_mesh(*primitives.quad((0, 0, 0), (4, 0, 0), (0, 4, 0)), material=0)
    scene.add_mesh(*primitives.uv_sphere((0, 0, 0.6), 0.5, 12, 6)[:2], material=1)
    scene.lights = Lights.from_list([{"kind": "POINT", "position": (0, 0, 2), "power": 100.0}])
    scene.camera = Camera.look_at((0, -3, 3), (0, 0, 0), width=16, height=8)
    settings = dict(samples=4, round_samples=2, tile_size=8, light_paths=2000, threads=1, wavelength_step=40.0)
    settings.update(kw)
    return prepare(scene, RenderSettings(**settings))


class SlowAccel:
    """The prepared accelerator, each ray cast ``seconds`` slower (sleeping: no CPU), counting its calls."""

    def __init__(self, accel, seconds):
        self.accel, self.seconds, self.calls = accel, seconds, []

    def intersect(self, o, d, tmax=None):
        self.calls.append(time.perf_counter())
        time.sleep(self.seconds)
        return self.accel.intersect(o, d, tmax)

    def occluded(self, o, d, tmax):
        self.calls.append(time.perf_counter())
        time.sleep(self.seconds)
        return self.accel.occluded(o, d, tmax)

    def __getattr__(self, name):
        return getattr(self.accel, name)


def test_the_image_is_the_same_bits_on_the_calling_thread_the_pollable_pool_and_two_threads():
    prepared = _small_prepared()
    inline = render_prepared(prepared)  # one thread, nothing to poll: the calling thread
    pooled = render_prepared(prepared, should_cancel=lambda: False)  # a pool of one, StoppableAccel
    two = render_prepared(_small_prepared(threads=2), should_cancel=lambda: False)
    assert inline.samples == pooled.samples == two.samples == 4
    for other in (pooled, two):
        assert np.array_equal(inline.rgb, other.rgb)
        for k, a in inline.passes.items():
            assert np.array_equal(a, other.passes[k]), k


@pytest.mark.parametrize("how", ["cancel", "time"])
def test_a_cancel_or_time_limit_acts_within_a_poll_while_a_slow_unit_runs(how):
    """Each ray cast takes 0.25 s, so a tile-round takes seconds: the render returns within about
    POLL_S of the cancel (or of the time limit) with no unit in, and the dropped unit stops at its
    next ray cast instead of running on."""
    compile_stage("auto")  # done before: the stop must come in the eye pass
    prepared = _small_prepared(light_paths=0, time_limit=0.6 if how == "time" else 0.0)
    slow = SlowAccel(prepared.accel, 0.25)
    prepared = replace(prepared, accel=slow)
    t0 = time.perf_counter()
    asked = lambda: time.perf_counter() - t0 > 0.6  # noqa: E731
    res = render_prepared(prepared, should_cancel=asked if how == "cancel" else None, started_at=t0)
    took = time.perf_counter() - t0
    assert took < 0.6 + 0.25 + 2 * POLL_S + 0.3, took  # the stop, one ray cast in flight, the polls, slack
    assert res.samples == 0 and res.cancelled == (how == "cancel")
    if how == "time":
        assert any(w.startswith("time limit reached after 0 of 4") for w in res.warnings), res.warnings
    n = len(slow.calls)
    time.sleep(0.6)
    assert len(slow.calls) == n  # nothing traces on after the render returned
    assert all(c <= t0 + took for c in slow.calls)


def test_stoppable_accel_raises_once_stopped_and_is_the_accelerator_otherwise():
    prepared = _small_prepared()
    flag = []
    acc = StoppableAccel(prepared.accel, lambda: bool(flag))
    o = np.zeros((3, 3), np.float32) + np.float32([0, -3, 3])
    d = np.tile(np.float32([0, 0.7071068, -0.7071068]), (3, 1))
    h, ref = acc.intersect(o, d), prepared.accel.intersect(o, d)
    assert np.array_equal(h.t, ref.t) and np.array_equal(h.prim, ref.prim) and acc.name == prepared.accel.name
    assert np.array_equal(acc.occluded(o, d, np.full(3, 1e9, np.float32)),
                          prepared.accel.occluded(o, d, np.full(3, 1e9, np.float32)))
    flag.append(1)
    with pytest.raises(RenderCancelled):
        acc.intersect(o, d)
    with pytest.raises(RenderCancelled):
        acc.occluded(o, d, np.full(3, 1e9, np.float32))


def test_a_cancel_in_a_slow_light_pass_batch_returns_at_once_and_callbacks_stay_on_the_calling_thread():
    """Each ray cast takes 0.6 s, so one light-pass batch takes seconds: a cancel 0.4 s in returns
    within a few polls (the lanes stop at their next batch in the background), and the cancel
    check and the progress are only called from the calling thread."""
    compile_stage("auto")  # done before: the cancel must come in the light pass
    prepared = _small_prepared(light_paths=5000)
    slow = SlowAccel(prepared.accel, 0.6)
    prepared = replace(prepared, accel=slow)
    me, threads, stages = threading.get_ident(), set(), []
    t0 = time.perf_counter()

    def should_cancel():
        threads.add(threading.get_ident())
        return time.perf_counter() - t0 > 0.4

    def progress(f, m):
        threads.add(threading.get_ident())
        stages.append(m)

    res = render_prepared(prepared, should_cancel=should_cancel, progress=progress)
    took = time.perf_counter() - t0
    assert took < 0.4 + 3 * POLL_S + 0.3, took
    assert res.cancelled and res.samples == 0 and threads == {me}
    assert slow.calls and min(slow.calls) < t0 + 0.4  # the light pass was casting rays when cancelled
    assert not any(m.startswith("eye pass") for m in stages)
