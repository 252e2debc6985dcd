"""Cancel and time-limit latency per stage: seconds from the request (or the limit) to render() returning.

    .venv/bin/python benchmarks/bench_cancel_latency.py --scene grid --triangles 10000000
    .venv/bin/python benchmarks/bench_cancel_latency.py --scene prism --resolution 1920 1080
    .venv/bin/python benchmarks/bench_cancel_latency.py --compile   # the compile stage, cold (a fresh numba cache)

Scenes: ``grid``, a wavy grid of ``--triangles`` triangles, half of them glass (so the light pass
has casters to group and aim at) under a point light, 160x100 by default; ``prism``, the README
example (tools/example_images.py's prism) at ``--resolution``. Per stage, one render is cancelled at a moment inside it (latency: the request to render()
returning a cancelled result; the stages are told by the progress and on_round callbacks), then
one render is given a time limit ending at that moment (latency: the limit's end to render()
returning; the row says which stage that render was in by then). The stages:

    preparation   half the time a lone preparation took (validation, normals, offsets, the
                  Embree build in pieces, light targets)
    light pass    0.5 s after its first progress report
    first round   0.3 s after the eye pass's first report (its first unit in), before round 0 ends
    later rounds  0.3 s after round 0 ended
    compile       (--compile) 2 s into the compile stage of a process with an empty kernel cache

Prints the table for docs/benchmarks.md. Needs ~4 GB of memory at 10 M triangles.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace

import numpy as np

from opal_diffraction.core.render.frame import render, render_prepared
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))


def big_scene(triangles: int, width: int = 160, height: int = 100) -> Scene:
    n = int(np.sqrt(triangles / 2))
    x, y = np.meshgrid(np.linspace(-5, 5, n + 1), np.linspace(-5, 5, n + 1), indexing="ij")
    z = 0.05 * np.sin(3 * x) * np.cos(2 * y)
    v = np.stack([x, y, z], -1).reshape(-1, 3).astype(np.float32)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = (i * (n + 1) + j).ravel()
    b, c = a + 1, a + n + 1
    t = np.concatenate([np.stack([a, b, c + 1], 1), np.stack([a, c + 1, c], 1)]).astype(np.int32)
    mat = np.zeros(len(t), np.int32)
    mat[: len(t) // 2] = 1
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
                                {"kind": "DIELECTRIC", "ior": 1.5, "color": (1, 1, 1)}])
    s = Scene(vertices=v, triangles=t, tri_material=mat, materials=mats)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (0, 0, 4), "power": 500.0}])
    s.camera = Camera.look_at((0, -8, 5), (0, 0, 0), width=width, height=height)
    return s


def prism_scene(width: int, height: int) -> Scene:
    from opal_diffraction._scripts import load_example

    return load_example("prism").build_scene(width, height)


RESULT_S: list = []  # (start, seconds) of every Film.result call: the image made at the end


def _timed_film_result():
    """Time Film.result (the mean image and its passes, made once when a render stops: at full
    HD it is a good part of the latency)."""
    from opal_diffraction.core.render import film

    real = film.Film.result

    def timed(self, *a, **k):
        t = time.perf_counter()
        try:
            return real(self, *a, **k)
        finally:
            RESULT_S.append((t, time.perf_counter() - t))

    film.Film.result = timed


def image_s(since: float) -> float:
    """Seconds spent in Film.result since ``since`` (a perf_counter time)."""
    return sum(d for t, d in RESULT_S if t >= since)


class Watch:
    """A render's stage times (seconds from its start) from its progress and on_round callbacks,
    and a request that turns on once ``trigger(now, watch)`` is true."""

    def __init__(self, trigger=None):
        self.t0 = time.perf_counter()
        self.trigger = trigger
        self.starts: dict[str, float] = {}
        self.rounds_done = 0
        self.asked: float | None = None
        self.stage_at_request = ""
        self.prepared_from = False  # (no progress report tells when the compile stage ends)

    def now(self) -> float:
        return time.perf_counter() - self.t0

    def stage(self) -> str:
        for name in ("later rounds", "first round", "light pass"):
            if name in self.starts:
                return name
        return "preparation" if "compile" not in self.starts or self.prepared_from else "compile"

    def progress(self, fraction, message):
        now = self.now()
        if message.startswith("compiling"):
            self.starts.setdefault("compile", now)
        elif message.startswith("light pass"):
            self.starts.setdefault("light pass", now)
        elif message.startswith("eye pass"):
            self.starts.setdefault("first round", now)

    def on_round(self, _result):
        self.rounds_done += 1
        self.starts.setdefault("later rounds", self.now())

    def should_cancel(self) -> bool:
        if self.asked is None and self.trigger is not None and self.trigger(self.now(), self):
            self.asked = self.now()
            self.stage_at_request = self.stage()
        return self.asked is not None


def run(scene, settings, trigger=None, prepared=None):
    """One render (``prepared``: render_prepared on it, the CLI's path); (watch, result, seconds)."""
    w = Watch(trigger)
    if prepared is None:
        res = render(scene, settings, progress=w.progress, should_cancel=w.should_cancel, on_round=w.on_round)
    else:
        res = render_prepared(prepared, progress=w.progress, should_cancel=w.should_cancel, on_round=w.on_round,
                              started_at=w.t0)
    return w, res, w.now()


def triggers(t_prep: float) -> dict:
    """When to cancel in each stage, relative to the stage's start in that render; a render that
    left the stage before the moment is cancelled at once (the row names the stage it was in)."""
    order = ("compile", "preparation", "light pass", "first round", "later rounds")

    def past(w, stage):
        return order.index(w.stage()) > order.index(stage)

    return {
        "preparation": lambda now, w: now >= 0.5 * t_prep or past(w, "preparation"),
        "light pass": lambda now, w: ("light pass" in w.starts and now >= w.starts["light pass"] + 0.5)
        or past(w, "light pass"),
        "first round": lambda now, w: ("first round" in w.starts and now >= w.starts["first round"] + 0.3)
        or past(w, "first round"),
        "later rounds": lambda now, w: "later rounds" in w.starts and now >= w.starts["later rounds"] + 0.3,
    }


def bench(scene, settings, label: str, stages=None) -> list[str]:
    render(scene, replace(settings, samples=1, light_paths=1000))  # the compile stage and one-time costs first
    prepare(scene, settings)
    t0 = time.perf_counter()
    prepare(scene, settings)
    t_prep = time.perf_counter() - t0
    print(f"{label}: preparation alone {t_prep:.1f} s", flush=True)
    rows = []
    for stage, trigger in triggers(t_prep).items():
        if stages and stage not in stages:
            continue
        w, res, done = run(scene, settings, trigger)
        if w.asked is None:
            rows.append(f"| {label} | {stage} | cancel | - | - | - | the render ended ({done:.1f} s) before the moment |")
            print(rows[-1], flush=True)
            continue
        lat = done - w.asked
        img = image_s(w.t0 + w.asked)
        rows.append(f"| {label} | {stage} | cancel | {w.asked:.1f} ({w.stage_at_request}) | {lat:.2f} | {img:.2f} | "
                    f"{'cancelled' if res.cancelled else 'NOT cancelled'}, {res.samples} spp |")
        print(rows[-1], flush=True)
        # a time limit ending where this render was cancelled (the next render's stages may shift:
        # the row says which stage it was in when the limit ran out)
        at = w.asked
        w, res, done = run(scene, replace(settings, time_limit=at))
        at_stage = "preparation"
        for name in ("light pass", "first round", "later rounds"):
            if name in w.starts and w.starts[name] <= at:
                at_stage = name
        why = next((x for x in res.warnings if "time limit" in x), "no time-limit warning")
        if done < at:
            rows.append(f"| {label} | {stage} | time limit {at:.1f} s | - | - | - | finished in {done:.1f} s |")
        else:
            rows.append(f"| {label} | {stage} | time limit {at:.1f} s | {at:.1f} ({at_stage}) | {done - at:.2f} | "
                        f"{image_s(w.t0 + at):.2f} | {why}; {res.samples} spp |")
        print(rows[-1], flush=True)
    return rows


def compile_case(seconds_in: float) -> list[str]:
    """In a child process with an empty numba cache: cancel ``seconds_in`` into the compile stage,
    then a render_prepared whose time limit ends that far into it."""
    rows = []
    for how in ("cancel", "time"):
        with tempfile.TemporaryDirectory(prefix="opal_cold_cache_") as cache:
            env = {**os.environ, "NUMBA_CACHE_DIR": cache, "PYTHONPATH": ROOT}
            out = subprocess.run([sys.executable, __file__, "--compile-child", how, str(seconds_in)], env=env,
                                 capture_output=True, text=True, timeout=1800)
            line = [ln for ln in out.stdout.splitlines() if ln.startswith("|")]
            rows += line or [f"| compile | {how} | failed: {out.stderr[-300:]!r} |"]
            print(rows[-1], flush=True)
    return rows


def compile_child(how: str, seconds_in: float) -> None:
    from opal_diffraction.core.render.frame import warm_up_scene

    scene = warm_up_scene()
    if how == "cancel":
        w, res, done = run(scene, RenderSettings(samples=4, threads=2),
                           lambda now, w: "compile" in w.starts and now >= w.starts["compile"] + seconds_in)
        lat = done - (w.asked if w.asked is not None else done)
        print(f"| cold cache | compile | cancel | {w.asked or 0:.1f} ({w.stage_at_request}) | {lat:.2f} | - | "
              f"{'cancelled' if res.cancelled else 'NOT cancelled'}: {'; '.join(res.warnings)} |")
        return
    prepared = prepare(scene, RenderSettings(samples=4, threads=2, time_limit=seconds_in))
    t0 = time.perf_counter()
    res = render_prepared(prepared, started_at=t0)
    done = time.perf_counter() - t0
    print(f"| cold cache | compile | time limit {seconds_in:.1f} s | {seconds_in:.1f} (compile) | "
          f"{done - seconds_in:.2f} | - | {'; '.join(res.warnings)} |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", choices=("grid", "prism"), default="grid")
    ap.add_argument("--triangles", type=int, default=10_000_000)
    ap.add_argument("--resolution", type=int, nargs=2, default=None, help="width height")
    ap.add_argument("--samples", type=int, default=256)
    ap.add_argument("--light-paths", type=int, default=20_000_000)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--stages", nargs="+", default=None, help="only these stages (e.g. preparation 'light pass')")
    ap.add_argument("--compile", action="store_true", help="only the compile stage, cold")
    ap.add_argument("--compile-seconds", type=float, default=2.0)
    ap.add_argument("--compile-child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    _timed_film_result()
    if args.compile_child:
        compile_child(args.compile_child[0], float(args.compile_child[1]))
        return 0
    header = ["| scene | stage | how | at (s) (stage then) | latency (s) | of which the image (s) | result |",
              "|---|---|---|---|---|---|---|"]
    if args.compile:
        rows = compile_case(args.compile_seconds)
    else:
        t0 = time.perf_counter()
        if args.scene == "grid":
            w, h = args.resolution or (160, 100)
            scene = big_scene(args.triangles, w, h)
            label = f"{len(scene.triangles) / 1e6:.1f} M triangles, {w}x{h}"
        else:
            w, h = args.resolution or (1920, 1080)
            scene = prism_scene(w, h)
            label = f"prism {w}x{h}"
        print(f"{label}: scene built in {time.perf_counter() - t0:.1f} s", flush=True)
        settings = RenderSettings(samples=args.samples, light_paths=args.light_paths, threads=args.threads)
        rows = bench(scene, settings, label, args.stages)
    print("\n" + "\n".join(header + rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
