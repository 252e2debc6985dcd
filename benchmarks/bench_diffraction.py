"""Benchmark (not a test): the paper's Fig. 5 grating scene, error against wall time.

For slit counts N = 10, 1000 and 1e5, renders the scene at several samples per pixel and
wavelength steps and compares with a reference image: 1 nm wavelength bins (each bin already
the exact closed-form average of the Fraunhofer pattern) at many samples per pixel, which
integrates the pattern over each pixel's footprint. Error is the RMSE of linear RGB relative
to the reference's mean.

    python benchmarks/bench_diffraction.py [--threads 2] [--res 120 60] [--ref-spp 32]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, os.path.join(HERE, "..", "examples"))

from opal_diffraction.core.render import render  # noqa: E402
from opal_diffraction.core.settings import RenderSettings  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--res", type=int, nargs=2, default=(120, 60))
    ap.add_argument("--ref-spp", type=int, default=32)
    ap.add_argument("--n", type=int, nargs="+", default=[10, 1000, 100000])
    args = ap.parse_args()
    from gratings import fig5_scene

    render(fig5_scene(8, 4), RenderSettings(samples=1))  # warm-up
    print(f"{'N':>7s} {'step nm':>7s} {'spp':>4s} {'time s':>7s} {'rel RMSE':>9s}")
    for n in args.n:
        scene = fig5_scene(*args.res, slit_count=n)
        t0 = time.perf_counter()
        ref = render(scene, RenderSettings(samples=args.ref_spp, wavelength_step=1.0, threads=args.threads, seed=123)).rgb
        print(f"{n:7d} {1:7.0f} {args.ref_spp:4d} {time.perf_counter() - t0:7.2f} {'(reference)':>9s}", flush=True)
        for step in (5.0, 10.0, 20.0):
            for spp in (1, 4, 16):
                t0 = time.perf_counter()
                img = render(scene, RenderSettings(samples=spp, wavelength_step=step, threads=args.threads)).rgb
                t = time.perf_counter() - t0
                err = np.sqrt(np.mean((img - ref) ** 2)) / ref.mean()
                print(f"{n:7d} {step:7.0f} {spp:4d} {t:7.2f} {err:9.4f}", flush=True)


if __name__ == "__main__":
    main()
