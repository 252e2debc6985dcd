"""Benchmark (not a test): ours against Cycles CPU at equal samples on the README example, as a
user sees it (the [kernels] issue's side-by-side table).

The README example's scene (examples/render_example.py ``build_scene``: the dense-flint prism
before the striped wall, a point light and a daylight sky) is rendered through
``bpy.ops.render.render`` at the same size and samples per pixel by three renderers, interleaved
round after round so machine load falls on all of them alike: ours with the compiled kernels
(``core/util/jit.py``), ours with the NumPy reference forced (``jit.kernel_mode('numpy')``), and
Cycles on the CPU (denoising and adaptive sampling off, every core). Each renderer renders once
first, untimed (imports, kernel compilation, Cycles' kernel load). Per render: wall seconds
(``time.perf_counter``) and CPU seconds of the whole process (``time.process_time``: every
thread of both engines runs in it), and their ratio, the cores kept busy. Prints a Markdown
table of the medians and ours / Cycles.

    python benchmarks/bench_equal_samples.py [--size 640 400] [--spp 32] [--rounds 3]
"""

from __future__ import annotations

import argparse
import statistics
import time

from opal_diffraction._scripts import load_example


def render_timed(engine: str, spp: int) -> tuple[float, float]:
    """One render of the current scene: (wall s, process CPU s)."""
    import bpy

    sc = bpy.context.scene
    sc.render.engine = engine
    if engine == "CYCLES":
        sc.cycles.device = "CPU"
        sc.cycles.samples = spp
        sc.cycles.use_adaptive_sampling = False
        sc.cycles.use_denoising = False
        sc.render.threads_mode = "AUTO"
    else:
        sc.opal.samples = spp
    t0, c0 = time.perf_counter(), time.process_time()
    bpy.ops.render.render()
    return time.perf_counter() - t0, time.process_time() - c0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, nargs=2, default=(640, 400), metavar=("W", "H"))
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args(argv)

    import opal_diffraction
    from opal_diffraction.core.util import jit

    opal_diffraction.register()
    try:
        load_example("render_example").build_scene(*args.size, spp=args.spp)

        def ours(mode):
            def run():
                with jit.kernel_mode(mode):
                    return render_timed("OPAL_DIFFRACTION", args.spp)
            return run

        runners = {"ours (kernels)": ours("auto"), "ours (NumPy reference)": ours("numpy"),
                   "Cycles CPU": lambda: render_timed("CYCLES", args.spp)}
        for run in runners.values():  # warm-up: imports, compilation, kernel loading
            run()
        times = {name: [] for name in runners}
        for _ in range(args.rounds):
            for name, run in runners.items():
                times[name].append(run())
    finally:
        opal_diffraction.unregister()

    cyc_wall = statistics.median(t[0] for t in times["Cycles CPU"])
    cyc_cpu = statistics.median(t[1] for t in times["Cycles CPU"])
    print(f"README example {args.size[0]}x{args.size[1]}, {args.spp} spp, {args.rounds} interleaved rounds "
          f"(medians), kernels: {jit.kernels_path('auto')}")
    print("| renderer | wall s | CPU s | cores busy | wall / Cycles | CPU / Cycles |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, ts in times.items():
        wall = statistics.median(t[0] for t in ts)
        cpu = statistics.median(t[1] for t in ts)
        print(f"| {name} | {wall:.2f} | {cpu:.2f} | {cpu / wall:.2f} | {wall / cyc_wall:.2f} | {cpu / cyc_cpu:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
