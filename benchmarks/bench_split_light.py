"""Benchmark (not a test): the light pass's SPLIT dispersion in chunks, memory and time (issue 14).

With ``dispersion_sampling = 'SPLIT'`` a white light path becomes one mono path per wavelength
sample (n = 61) at the first dispersive glass it meets (core/transport/walker.py ``SpecularWalker.split_white``): a batch
of 2^15 paths (light_pass.BATCH_PATHS) becomes up to 2 M mono rays, each with its hit and path
state. ``light_pass.trace_batch`` now walks a batch's white paths in pieces of
``wavelengths.SPLIT_CHUNK_RAYS / n`` paths (the eye pass's bound, docs/physics.md section 2.6),
one after another with the batch's random stream. This script measures the light pass alone
(prepare, then ``run_light_pass``) on the prism and the gem examples with SPLIT, chunked against
one piece per batch (``SPLIT_CHUNK_RAYS`` set huge: the code before), and SAMPLE for scale,
each configuration in a fresh process:

- time: wall and CPU seconds of ``run_light_pass`` (tracemalloc off), the run of least CPU of ``--repeats``,
  the configurations alternating;
- memory: the peak of the traced allocations during ``run_light_pass`` (tracemalloc on,
  ``reset_peak`` after preparing; NumPy reports its buffers to tracemalloc) in a separate run,
  and the process's peak RSS (``ru_maxrss``) of the timed run;
- the caustic map's total flux (W summed over elements and wavelengths) and the splat's sum,
  which must agree between chunked and unchunked within the Monte Carlo noise (the test is
  tests/integrators/light/test_split_light_chunks.py).

    .venv/bin/python benchmarks/bench_split_light.py [--scenes prism gem] [--light-paths 131072]
        [--threads 1] [--repeats 2] [--width 320 --height 200]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
HUGE = 1 << 40


def probe(scene_name: str, mode: str, chunk: int, paths: int, threads: int, width: int, height: int,
          trace: bool) -> dict:
    """One configuration, in this (fresh) process."""
    import numpy as np

    if trace:
        import tracemalloc

        tracemalloc.start(1)
    from opal_diffraction._scripts import load_example
    from opal_diffraction.core.transport import wavelengths
    from opal_diffraction.core.integrators.light.light_pass import run_light_pass
    from opal_diffraction.core.render.plan import plan_render
    from opal_diffraction.core.render.prepare import prepare
    from opal_diffraction.core.scene.settings import RenderSettings

    wavelengths.SPLIT_CHUNK_RAYS = chunk
    scene = load_example(scene_name).build_scene(width, height)
    settings = RenderSettings(samples=1, light_paths=paths, dispersion_sampling=mode, threads=threads, seed=0)
    prepared = prepare(scene, settings)
    if trace:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
    t, c = time.perf_counter(), time.process_time()
    light = run_light_pass(prepared, plan=plan_render(prepared))
    wall, cpu = time.perf_counter() - t, time.process_time() - c
    out = {"scene": scene_name, "mode": mode, "chunk": chunk, "wall_s": wall, "cpu_s": cpu,
           "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
           "flux": float(np.sum(light.caustics.flux, dtype=np.float64)) if light.caustics is not None else 0.0,
           "rays": int(light.stats.get("light_rays", 0))}
    if trace:
        out["traced_peak_mb"] = (tracemalloc.get_traced_memory()[1] - base) / 2**20
    return out


def run_probe(*args) -> dict:
    env = dict(os.environ, PYTHONPATH=REPO + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, os.path.abspath(__file__), "--probe", json.dumps(args)],
                          capture_output=True, text=True, env=env)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"probe {args} failed:\n{proc.stderr[-3000:]}")
    return json.loads(lines[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["prism", "gem"])
    ap.add_argument("--light-paths", type=int, default=1 << 17)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=200)
    ap.add_argument("--no-sample", action="store_true", help="skip the SAMPLE row")
    ap.add_argument("--probe", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.probe is not None:
        print(json.dumps(probe(*json.loads(args.probe))))
        return 0

    from opal_diffraction.core.transport import wavelengths

    chunk = wavelengths.SPLIT_CHUNK_RAYS
    configs = [("SPLIT", HUGE), ("SPLIT", chunk)] + ([] if args.no_sample else [("SAMPLE", chunk)])
    print(f"light pass only, {args.light_paths} light paths, {args.threads} thread(s), {args.width}x{args.height} "
          f"camera; load average {os.getloadavg()[0]:.1f} at the start\n", flush=True)
    rows = []
    for name in args.scenes:
        best: dict = {}
        for _ in range(args.repeats):  # alternating, best of the repeats
            for mode, c in configs:
                r = run_probe(name, mode, c, args.light_paths, args.threads, args.width, args.height, False)
                print("   ", json.dumps(r), flush=True)
                if (mode, c) not in best or r["cpu_s"] < best[(mode, c)]["cpu_s"]:  # CPU: the machine is shared
                    best[(mode, c)] = r
        for mode, c in configs:
            tr = run_probe(name, mode, c, args.light_paths, args.threads, args.width, args.height, True)
            print("   ", json.dumps(tr), flush=True)
            rows.append((name, mode, c, best[(mode, c)], tr))
    print("\n| scene | mode | mono rays per piece | wall s | CPU s | traced peak MB | peak RSS MB | map flux (W) | rays |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, mode, c, r, tr in rows:
        piece = "one piece per batch" if c >= HUGE else f"{c}"
        if mode == "SAMPLE":
            piece = "(no split)"
        print(f"| {name} | {mode} | {piece} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} | {tr['traced_peak_mb']:.0f} | "
              f"{r['maxrss_mb']:.0f} | {r['flux']:.6g} | {r['rays']} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
