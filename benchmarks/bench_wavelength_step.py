"""Benchmark (not a test): render time against colour error for the wavelength step.

Renders two scenes at 5, 10 and 20 nm steps and compares with a 1 nm reference (RMSE of linear
RGB relative to the reference's mean, and the worst pixel):
- "colour chart": 24 saturated diffuse patches under a 2700 K blackbody point light and a
  coloured light. Point lights and one sample per pixel make it deterministic, so the error is
  the grid's alone.
- "prism": the README example (dispersion, SPLIT mode so each wavelength is traced), at
  160x100. Its Monte Carlo noise is measured too (two 1 nm renders with different seeds): an
  error at that level is noise, not the grid.

    python benchmarks/bench_wavelength_step.py [--threads 2]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from opal_diffraction._scripts import load_example
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings


def colour_chart(pixels=192) -> Scene:
    rng = np.random.default_rng(5)
    cols = rng.random((24, 3)) ** 2  # saturated-ish
    s = Scene(materials=Materials.from_list([{"color": tuple(c)} for c in cols]))
    for i in range(24):
        x, y = i % 6, i // 6
        s.add_mesh(*primitives.quad((x - 2.5, y - 1.5, 0), (0.95, 0, 0), (0, 0.95, 0)), material=i)
    s.lights = Lights.from_list([
        {"kind": "POINT", "position": (-2, -2, 4), "power": 800.0, "temperature": 2700.0},
        {"kind": "POINT", "position": (3, 2, 3), "power": 300.0, "color": (0.2, 0.5, 1.0)},
    ])
    m = np.eye(4)
    m[:3, 3] = (0, 0, 10)
    s.camera = Camera(matrix=m, kind="ORTHO", ortho_scale=6.2, width=pixels, height=pixels)
    return s


def rmse(a, ref):
    return float(np.sqrt(np.mean((a - ref) ** 2)) / ref.mean()), float(np.abs(a - ref).max() / ref.mean())


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    build_scene = load_example("prism").build_scene

    cases = [
        ("colour chart", colour_chart(), dict(samples=1)),
        ("prism (SPLIT)", build_scene(160, 100), dict(samples=16, dispersion_sampling="SPLIT")),
    ]
    render(colour_chart(16), RenderSettings(samples=1))  # warm-up: imports, tables
    print(f"{'scene':16s} {'step nm':>7s} {'n':>4s} {'time s':>7s} {'rel RMSE':>9s} {'rel max':>8s}")
    for name, scene, kw in cases:
        t0 = time.perf_counter()
        ref = render(scene, RenderSettings(wavelength_step=1.0, threads=args.threads, **kw)).rgb
        t_ref = time.perf_counter() - t0
        print(f"{name:16s} {1:7.0f} {301:4d} {t_ref:7.2f} {'(reference)':>9s}")
        if kw.get("samples", 1) > 1:
            ref2 = render(scene, RenderSettings(wavelength_step=1.0, threads=args.threads, seed=99, **kw)).rgb
            e, mx = rmse(ref2, ref)
            print(f"{name:16s} {'noise':>7s} {301:4d} {'':7s} {e:9.4f} {mx:8.3f}   (1 nm, another seed)")
        for step in (5.0, 10.0, 20.0):
            t0 = time.perf_counter()
            res = render(scene, RenderSettings(wavelength_step=step, threads=args.threads, **kw))
            t = time.perf_counter() - t0
            e, mx = rmse(res.rgb, ref)
            print(f"{name:16s} {step:7.0f} {len(res.wavelengths):4d} {t:7.2f} {e:9.4f} {mx:8.3f}")


if __name__ == "__main__":
    main()
