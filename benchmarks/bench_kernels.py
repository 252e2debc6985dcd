"""The compiled kernels (core/util/jit.py) against their NumPy references, and a render with each path.

    .venv/bin/python benchmarks/bench_kernels.py [--rows 10000 100000 1000000] [--repeats 3]
                                                 [--resolution 160 100] [--spp 16] [--no-render]

1. Each kernel through its public function, kernels on ('auto') and forced off ('numpy'), at each
   row count: Fresnel over (B,) float32 (the walker's) and (B, 1) x (B, n) float64 (the SPLIT
   wavelength step's), the RGB -> spectrum uplift of (B, 3) float32 environment colours, the
   environment lookup of (B,) directions, Sobol-Burley points, and the run sums of (B, n) spectra
   into 4096 film rows (core/util/row_sums.py), GGX reflection terms (core/materials/ggx.py; the
   (B, n) cases up to MAX_SPECTRAL_ROWS rows). The best of ``--repeats``
   runs after one warm-up call (which also compiles, or loads from the cache).
2. The README example's scene (examples/prism.py ``build_scene``: the core-side copy of
   examples/render_example.py's Blender scene) at ``--resolution`` and ``--spp``: wall and CPU
   seconds of a whole render (light pass and eye pass) with kernels 'auto' and 'numpy', runs
   interleaved (auto, numpy, auto, ...) so a change of machine load hits both; then threads=1
   against threads=2 (kernels on), interleaved too.

Prints Markdown tables (docs/benchmarks.md, "Compiled kernels (numba)").
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from opal_diffraction._scripts import load_example
from opal_diffraction.core.lights.environment import EnvironmentMap
from opal_diffraction.core.materials.ggx import reflection_terms
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.sampling.sampler import sobol_owen_2d
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.spectral.optics import fresnel_dielectric
from opal_diffraction.core.spectral.spectrum import SpectralConverter
from opal_diffraction.core.util import jit
from opal_diffraction.core.util.row_sums import add_row_sums


#: (B, n) cases stop at this many rows: at 1e6 rows one (B, 61) float64 array is 488 MB, and the
#: NumPy reference's temporaries take several GB (the tile batches are far smaller).
MAX_SPECTRAL_ROWS = 200_000


def best_of(fn, repeats: int) -> float:
    fn()  # warm-up (the kernel compiles or loads from the cache here)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def kernel_cases(rows: int, rng):
    """(name, call) of each kernel's public function at ``rows`` rows."""
    conv = SpectralConverter()
    n = conv.grid.n
    cos32 = rng.uniform(0, 1, rows).astype(np.float32)
    eta32 = rng.uniform(0.5, 1.8, rows).astype(np.float32)
    cos64 = rng.uniform(0, 1, (min(rows, MAX_SPECTRAL_ROWS), 1))
    eta64 = rng.uniform(0.5, 1.8, (min(rows, MAX_SPECTRAL_ROWS), n))
    rgb = rng.uniform(0, 3, (rows, 3)).astype(np.float32)
    env = EnvironmentMap(load_example("environments").sky(256, 128))
    d = rng.normal(size=(rows, 3)).astype(np.float32)
    pixel, sample, pair = rng.integers(0, 1 << 18, rows), rng.integers(0, 1 << 20, rows), rng.integers(0, 64, rows)
    wo, wi = (np.abs(rng.normal(size=(rows, 3))).astype(np.float32) for _ in range(2))
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    alpha = rng.uniform(0.05, 1.0, rows).astype(np.float32)
    film = np.zeros((4096, n), np.float32)
    spectral_rows = min(rows, MAX_SPECTRAL_ROWS)
    pix, contrib = rng.integers(0, len(film), spectral_rows), rng.random((spectral_rows, n)).astype(np.float32)
    cases = [
        ("fresnel_dielectric (B,) float32", lambda: fresnel_dielectric(cos32, eta32)),
        ("EnvironmentMap.radiance_rgb (B, 3)", lambda: env.radiance_rgb(d)),
        ("sobol_owen_2d (B,)", lambda: sobol_owen_2d(pixel, sample, pair, 3)),
    ]
    if rows <= MAX_SPECTRAL_ROWS:
        cases += [
            (f"fresnel_dielectric (B, {n}) float64", lambda: fresnel_dielectric(cos64, eta64)),
            (f"illuminant_from_rgb (B, 3) -> (B, {n})", lambda: conv.illuminant_from_rgb(rgb)),
            (f"reflectance_from_rgb (B, 3) -> (B, {n})", lambda: conv.reflectance_from_rgb(rgb)),
            (f"add_row_sums (B, {n}) into 4096 rows", lambda: add_row_sums(film, pix, contrib)),
        ]
    cases.append(("GGX reflection_terms (B,) float32", lambda: reflection_terms(alpha, wo, wi)))
    return cases


def bench_kernels(rows_list, repeats: int) -> None:
    print("| kernel | rows | NumPy ms | kernel ms | speed-up |")
    print("|---|---:|---:|---:|---:|")
    for rows in rows_list:
        for name, call in kernel_cases(rows, np.random.default_rng(0)):
            with jit.kernel_mode("numpy"):
                ref = best_of(call, repeats)
            ker = best_of(call, repeats)
            print(f"| {name} | {rows:.0e} | {ref * 1e3:.2f} | {ker * 1e3:.2f} | {ref / ker:.1f}x |", flush=True)


def timed_render(scene, settings) -> tuple[float, float, dict]:
    t, c = time.perf_counter(), time.process_time()
    r = render(scene, settings)
    return time.perf_counter() - t, time.process_time() - c, r.stats


def bench_render(resolution, spp: int, repeats: int) -> None:
    scene = load_example("prism").build_scene(*resolution)
    base = dict(samples=spp, seed=1, light_paths=None)
    render(scene, RenderSettings(**dict(base, samples=1)))  # compile / load the kernels once
    print(f"\nREADME example scene (examples/prism.py build_scene) {resolution[0]} x {resolution[1]}, {spp} spp, "
          f"automatic light paths, {repeats} interleaved runs each")
    for label, variants in (("kernels, threads=2", [("auto", dict(kernels="auto", threads=2)),
                                                    ("numpy", dict(kernels="numpy", threads=2))]),
                            ("threads, kernels auto", [("threads=1", dict(kernels="auto", threads=1)),
                                                       ("threads=2", dict(kernels="auto", threads=2))])):
        runs = {name: [] for name, _ in variants}
        for _ in range(repeats):
            for name, extra in variants:
                wall, cpu, stats = timed_render(scene, RenderSettings(**base, **extra))
                runs[name].append((wall, cpu))
                print(f"  {label}: {name}: wall {wall:.2f} s, CPU {cpu:.2f} s ({stats['kernels']} kernels)", flush=True)
        print(f"\n| {label} | wall s (median) | CPU s (median) |")
        print("|---|---:|---:|")
        for name, vals in runs.items():
            w, c = np.median(np.array(vals), axis=0)
            print(f"| {name} | {w:.2f} | {c:.2f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--resolution", type=int, nargs=2, default=(160, 100))
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--no-render", action="store_true")
    args = ap.parse_args()
    if not jit.AVAILABLE:
        raise SystemExit(f"no JIT to measure: {jit.UNAVAILABLE_REASON}")
    print(f"numba kernels cached in {jit.cache_dir()}; {os.cpu_count()} CPUs, load average "
          f"{os.getloadavg()[0]:.1f}\n")
    bench_kernels(args.rows, args.repeats)
    if not args.no_render:
        bench_render(args.resolution, args.spp, args.repeats)


if __name__ == "__main__":
    main()
