"""Benchmark (not a test): the source paper's Fig. 5 grating scene (Kobayashi & Kawai,
docs/physics.md), error against wall time.

For slit counts N = 10, 1000 and 1e5, renders the scene at several samples per pixel and
wavelength steps and compares with a reference image: 1 nm wavelength bins (each bin already
the exact closed-form average of the Fraunhofer pattern) at many samples per pixel, which
integrates the pattern over each pixel's footprint. The zeroth order is the point light seen
through the grating, a sub-pixel spot some 10^4 times brighter than the orders, so a linear
RMSE measures only that spot; the error reported is what a viewer sees: the RMSE of the sRGB
display values (exposure set so the reference's 99th percentile is white, clipped), in [0, 1].
The reference's own noise is printed too (the same reference with another seed).

``--footprint on off`` renders each case with pixel-footprint integration of the pattern
(docs/physics.md section 3.7) and without it (point samples), each against its own reference
(the footprint widens the expected image by the filter's box: a reference per mode).
``--cd`` adds the example CD with L = 1000 um tracks (linear per-pixel RMSE / mean and the image
mean against a 256 spp reference, 20 nm bins, no light pass).

    python benchmarks/bench_diffraction.py [--threads 2] [--res 120 60] [--ref-spp 32]
        [--steps 5 10 20] [--footprint on off] [--cd]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from opal_diffraction._scripts import load_example
from opal_diffraction.core.render.output import srgb_encode
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.settings import RenderSettings


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--res", type=int, nargs=2, default=(120, 60))
    ap.add_argument("--ref-spp", type=int, default=32)
    ap.add_argument("--n", type=int, nargs="+", default=[10, 1000, 100000])
    ap.add_argument("--steps", type=float, nargs="+", default=[5.0, 10.0, 20.0])
    ap.add_argument("--spp", type=int, nargs="+", default=[1, 4, 16])
    ap.add_argument("--footprint", nargs="+", default=["on"], choices=["on", "off"])
    ap.add_argument("--cd", action="store_true", help="also the example CD with L = 1000 um")
    args = ap.parse_args()
    ex = load_example("gratings")
    fig5_scene = ex.fig5_scene

    render(fig5_scene(8, 4), RenderSettings(samples=1))  # warm-up
    print(f"{'N':>7s} {'fp':>3s} {'step nm':>7s} {'spp':>4s} {'time s':>7s} {'display RMSE':>12s}")
    for n in args.n:
        scene = fig5_scene(*args.res, slit_count=n)
        for mode in args.footprint:
            fp = mode == "on"
            t0 = time.perf_counter()
            ref = render(scene, RenderSettings(samples=args.ref_spp, wavelength_step=1.0, threads=args.threads, seed=123,
                                               grating_footprint=fp)).rgb
            print(f"{n:7d} {mode:>3s} {1:7.0f} {args.ref_spp:4d} {time.perf_counter() - t0:7.2f} {'(reference)':>12s}",
                  flush=True)
            scale = 1.0 / max(float(np.percentile(ref.max(axis=2), 99)), 1e-12)
            shown = lambda img: srgb_encode(img * scale)  # noqa: E731
            ref2 = render(scene, RenderSettings(samples=args.ref_spp, wavelength_step=1.0, threads=args.threads, seed=7,
                                                grating_footprint=fp)).rgb
            noise = np.sqrt(np.mean((shown(ref2) - shown(ref)) ** 2))
            print(f"{n:7d} {mode:>3s} {1:7.0f} {args.ref_spp:4d} {'':7s} {noise:12.4f}   (reference noise: another seed)",
                  flush=True)
            for step in args.steps:
                for spp in args.spp:
                    t0 = time.perf_counter()
                    img = render(scene, RenderSettings(samples=spp, wavelength_step=step, threads=args.threads,
                                                       grating_footprint=fp)).rgb
                    t = time.perf_counter() - t0
                    err = np.sqrt(np.mean((shown(img) - shown(ref)) ** 2))
                    print(f"{n:7d} {mode:>3s} {step:7.0f} {spp:4d} {t:7.2f} {err:12.4f}", flush=True)
    if args.cd:
        print("\nCD, L = 1000 um, 80 x 60 px, 20 nm bins: per-pixel RMSE / mean and image mean vs 256 spp")
        print(f"{'fp':>3s} {'spp':>4s} {'time s':>7s} {'RMSE/mean':>10s} {'mean ratio':>10s}")
        scene = ex.cd_scene(80, 60)
        scene.materials.coherence_length[1] = 1000.0
        for mode in args.footprint:
            fp = mode == "on"
            st = lambda spp, seed: RenderSettings(samples=spp, seed=seed, light_paths=0, wavelength_step=20.0,  # noqa: E731
                                                  threads=args.threads, grating_footprint=fp)
            ref = render(scene, st(256, 99)).rgb.astype(np.float64)
            for spp in (4, 16, 64):
                t0 = time.perf_counter()
                img = render(scene, st(spp, 1)).rgb.astype(np.float64)
                t = time.perf_counter() - t0
                rel = np.sqrt(np.mean((img - ref) ** 2)) / ref.mean()
                print(f"{mode:>3s} {spp:4d} {t:7.2f} {rel:10.3f} {img.mean() / ref.mean():10.3f}", flush=True)


if __name__ == "__main__":
    main()
