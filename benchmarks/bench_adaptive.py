"""Adaptive sampling: render time to a fixed error, with and without Cycles' Noise Threshold.

    .venv/bin/python benchmarks/bench_adaptive.py [--pixels 64] [--tile-size 32] [--reference-spp 1024]
                                                  [--threads 1] [--repeats 3]

The scene (tests/render/test_adaptive.py's): a diffuse plane over three quarters of a top-down view in
a uniform grey world, a long wall standing on it; the world seen directly has no noise, the open
plane little, the plane beside the wall a lot (half of its sky blocked). A non-adaptive render of
``--reference-spp`` samples is the reference; every other setting is rendered ``--repeats``
times (same seed, same image) and the fastest time is kept, since the machine may be shared. Non-adaptive renders at 16-256 samples and adaptive
ones at thresholds 0.05-0.005 (max 1024 samples, automatic minimum) give (time, error) curves;
the error is the image RMSE against the reference (the reference's own noise, estimated from two
half-sample references, is subtracted in quadrature). The time each curve needs for the error
the adaptive render at threshold 0.01 reaches is read off a log-log fit of the non-adaptive curve. Prints tables; the numbers go in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def wall_scene(pixels: int):
    from opal_diffraction.core.scene import primitives
    from opal_diffraction.core.scene.model import Camera, Materials, Scene

    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE", "color": (0.8, 0.8, 0.8)}]),
              world_color=np.array([0.5, 0.5, 0.5], np.float32))
    s.add_mesh(*primitives.quad((1.0, 0, 0), (2.0, 0, 0), (0, 4.0, 0)), material=0)
    s.add_mesh(*primitives.box((1.6, 0.0, 0.5), (0.4, 4.0, 1.0)), material=0)
    m = np.eye(4)
    m[:3, 3] = (0.0, 0.0, 10.0)
    s.camera = Camera(matrix=m, kind="ORTHO", ortho_scale=4.0, width=pixels, height=pixels)
    return s


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pixels", type=int, default=64)
    p.add_argument("--tile-size", type=int, default=32)
    p.add_argument("--repeats", type=int, default=3, help="renders per setting; the fastest is reported")
    p.add_argument("--reference-spp", type=int, default=1024)
    p.add_argument("--threads", type=int, default=1, help="1: steadier timings on a shared machine")
    args = p.parse_args(argv)

    from opal_diffraction.core.render.frame import render
    from opal_diffraction.core.scene.settings import RenderSettings

    scene = wall_scene(args.pixels)
    base = dict(round_samples=8, tile_size=args.tile_size, diffuse_bounces=1, wavelength_step=20.0,
                threads=args.threads)

    def run(repeats=args.repeats, **kw):
        best = math.inf
        for _ in range(repeats):  # the same seed: the same image; the fastest time (a shared machine)
            t0 = time.perf_counter()
            r = render(scene, RenderSettings(**base, **kw))
            best = min(best, time.perf_counter() - t0)
        return r, best

    half = args.reference_spp // 2
    ref_a, _ = run(samples=half, seed=1000, repeats=1)
    ref_b, _ = run(samples=half, seed=2000, repeats=1)
    ref = 0.5 * (ref_a.rgb.astype(np.float64) + ref_b.rgb)
    # the reference's own noise: Var(a - b) = 4 Var(ref) for the mean of two halves
    ref_var = float(np.mean((ref_a.rgb.astype(np.float64) - ref_b.rgb) ** 2)) / 4

    def error(img) -> float:
        return math.sqrt(max(float(np.mean((img.astype(np.float64) - ref) ** 2)) - ref_var, 0.0))

    print(f"scene: {args.pixels}x{args.pixels} px, tiles of {args.tile_size}, reference {args.reference_spp} spp "
          f"(its own RMSE {math.sqrt(ref_var):.5f}), {args.threads} threads")
    print("\nnon-adaptive:\n| spp | time (s) | RMSE |\n|---:|---:|---:|")
    plain = []
    for spp in (16, 32, 64, 128, 256):
        r, t = run(samples=spp, seed=spp)
        plain.append((t, error(r.rgb)))
        print(f"| {spp} | {t:.2f} | {plain[-1][1]:.5f} |")
    print("\nadaptive (max 1024 spp, automatic minimum):\n| threshold | time (s) | RMSE | spp min / mean / max |"
          "\n|---:|---:|---:|---|")
    adaptive = {}
    for thr in (0.05, 0.02, 0.01, 0.005):
        r, t = run(samples=1024, seed=int(thr * 1e4), adaptive_threshold=thr)
        adaptive[thr] = (t, error(r.rgb))
        st = r.stats
        print(f"| {thr} | {t:.2f} | {adaptive[thr][1]:.5f} | {st['samples_min']} / {st['samples_mean']:.1f} / "
              f"{st['samples_max']} |")

    target_t, target_e = adaptive[0.01]
    # non-adaptive: RMSE ~ time^(-1/2); a least-squares line in log-log reads off the time
    slope, icept = np.polyfit(np.log([e for _, e in plain]), np.log([t for t, _ in plain]), 1)
    t_plain = float(np.exp(icept + slope * np.log(target_e)))
    print(f"\ntime to RMSE {target_e:.5f} (log-log fit, slope {slope:.2f}): non-adaptive {t_plain:.2f} s, "
          f"adaptive (0.01) {target_t:.2f} s: {t_plain / target_t:.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
