"""Cancel latency on a large scene: seconds from the cancel request to render() returning, per stage.

    .venv/bin/python benchmarks/bench_cancel_latency.py [--triangles 10000000]

A wavy grid of ``--triangles`` triangles, half of them glass (so the light pass has casters to
group and aim at) under a point light. First one render with cancel never requested records
when each stage starts (preparation, light pass, eye pass: the progress callback and the
prepared scene's timing say so); then, for each stage, a render that requests cancel half-way
into that stage and measures how long render() takes to return after the request. Prints the
table for docs/benchmarks.md. Needs ~6 GB of memory at 10 M triangles.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from opal_diffraction.core.render import render
from opal_diffraction.core.scene import Camera, Lights, Materials, Scene
from opal_diffraction.core.settings import RenderSettings


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


SETTINGS = RenderSettings(samples=16, light_paths=1_000_000, threads=2)


def timeline(scene):
    """(stage, start, end) seconds from the call, from one uncancelled render."""
    marks = {}
    t0 = time.perf_counter()

    def progress(fraction, message):
        stage = "light pass" if message.startswith("light pass") else "eye pass"
        marks.setdefault(stage, time.perf_counter() - t0)

    res = render(scene, SETTINGS, progress=progress)
    total = time.perf_counter() - t0
    prep = res.stats["prepare_s"]
    lp_end = marks.get("eye pass", total)
    return [("preparation (validation, normals, Embree build, light targets)", 0.0, prep),
            ("light pass", marks.get("light pass", prep), lp_end), ("eye pass", lp_end, total)]


def latency(scene, at: float) -> tuple[float, bool]:
    t0 = time.perf_counter()
    asked = {}

    def should_cancel():
        now = time.perf_counter() - t0
        if now >= at:
            asked.setdefault("t", now)
            return True
        return False

    res = render(scene, SETTINGS, should_cancel=should_cancel)
    done = time.perf_counter() - t0
    return done - asked.get("t", done), res.cancelled


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--triangles", type=int, default=10_000_000)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    scene = big_scene(args.triangles)
    print(f"{len(scene.triangles) / 1e6:.1f} M triangles built in {time.perf_counter() - t0:.1f} s")
    stages = timeline(scene)
    for name, a, b in stages:
        print(f"  {name}: {a:.1f} - {b:.1f} s", flush=True)
    print("\n| stage | cancel requested at (s) | latency (s) | cancelled |")
    print("|---|---|---|---|")
    for name, a, b in stages:
        for frac in (0.25, 0.75):
            at = a + frac * (b - a)
            lat, ok = latency(scene, at)
            print(f"| {name} | {at:.1f} | {lat:.2f} | {ok} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
