"""Cancel latency on a large scene: seconds from the cancel request to render() returning, per stage.

    .venv/bin/python benchmarks/bench_cancel_latency.py [--triangles 10000000]

A wavy grid of ``--triangles`` triangles, half of them glass (so the light pass has casters to
group and aim at) under a point light. The preparation is timed alone first; then renders that
request cancel 10 %, 40 %, 70 %, 80 % and 90 % into the preparation, 1 s into the light pass and 1 s into
the eye pass (the progress callback says when each pass starts) measure how long render()
takes to return after the request. Prints the table for docs/benchmarks.md. Needs ~4 GB of
memory at 10 M triangles.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings


def big_scene(triangles: int) -> Scene:
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
    s.camera = Camera.look_at((0, -8, 5), (0, 0, 0), width=160, height=100)
    return s


SETTINGS = RenderSettings(samples=256, light_paths=20_000_000, threads=2)


def latency(scene, trigger) -> tuple[float, bool, str]:
    """Render with a cancel requested once ``trigger(elapsed, stage)`` is true; returns (seconds
    from the request to render() returning, whether the result says cancelled, the stage)."""
    t0 = time.perf_counter()
    state = {"stage": "preparation"}

    def progress(fraction, message):
        state["stage"] = "light pass" if message.startswith("light pass") else "eye pass"
        state.setdefault(state["stage"], time.perf_counter() - t0)

    def should_cancel():
        now = time.perf_counter() - t0
        if "asked" not in state and trigger(now, state):
            state["asked"] = now
        return "asked" in state

    res = render(scene, SETTINGS, progress=progress, should_cancel=should_cancel)
    done = time.perf_counter() - t0
    return done - state.get("asked", done), res.cancelled, state["stage"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--triangles", type=int, default=10_000_000)
    ap.add_argument("--prep-fractions", type=float, nargs="+", default=[0.1, 0.4, 0.7, 0.8, 0.9],
                    help="when to cancel, as fractions of the preparation's time")
    ap.add_argument("--no-passes", action="store_true", help="only the preparation cases")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    scene = big_scene(args.triangles)
    print(f"{len(scene.triangles) / 1e6:.1f} M triangles built in {time.perf_counter() - t0:.1f} s", flush=True)
    t0 = time.perf_counter()
    prepare(scene, SETTINGS)
    t_prep = time.perf_counter() - t0
    print(f"preparation alone: {t_prep:.1f} s", flush=True)
    print("\n| stage | cancel requested at (s) | latency (s) | cancelled |")
    print("|---|---|---|---|")
    cases = [(f"preparation, {int(100 * f)} % in", lambda now, st, f=f: now >= f * t_prep) for f in args.prep_fractions]
    if not args.no_passes:
        cases += [("light pass, 1 s in", lambda now, st: "light pass" in st and now >= st["light pass"] + 1.0),
                  ("eye pass, 1 s in", lambda now, st: "eye pass" in st and now >= st["eye pass"] + 1.0)]
    for name, trigger in cases:
        t0 = time.perf_counter()
        lat, ok, stage = latency(scene, trigger)
        print(f"| {name} ({stage}) | {time.perf_counter() - t0 - lat:.1f} | {lat:.2f} | {ok} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
