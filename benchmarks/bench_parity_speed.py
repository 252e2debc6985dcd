"""Benchmark (not a test): ours against Cycles CPU at equal samples and equal resolution, side by
side, on the README example and the Cycles parity scenes (the [kernels] issue's "Must show", issue 24).

Three parts, each printing a Markdown table:

1. **Speed.** Every scene (``readme``: examples/render_example.py ``build_scene``, the dense-flint
   prism before the striped wall under a point light and a daylight sky; and each scene of
   tests/blender/parity_scenes.py, as tools/cycles_parity.py builds them) is rendered through
   ``bpy.ops.render.render``, as F12 does, by three renderers at the same size and samples per
   pixel: ours with the compiled kernels (RenderSettings.kernels 'auto', core/util/jit.py), ours on
   the NumPy reference (``jit.kernel_mode('numpy')``), and Cycles on the CPU (denoising and
   adaptive sampling off, no time limit). Both engines get the same threads: every core (Blender's
   threads 'AUTO') or ``--threads N``. Each renderer first renders once untimed (imports, ours'
   compile stage, Cycles' kernel loading), and once more per scene at 1 sample, untimed (what a
   scene's first render pays once in a session: image loading, ours' GGX tables and the kernels
   of paths the first scene did not take); then per scene ``--rounds`` rounds, each rendering the
   scene once with every renderer, the order rotated each round, so machine load falls on all of
   them alike. Per render: wall seconds (``time.perf_counter``), the process's CPU seconds
   (``time.process_time``: the threads of both engines run in this process) and their ratio, the
   cores kept busy. The table gives the medians and ours / Cycles in wall time per scene. Ours'
   seconds include the export from Blender, preparation and the light pass, as a user waits for them.
2. **Thread scaling** (``readme``, ours with the kernels): threads 1 and 2 (FIXED), interleaved,
   the median wall seconds and their ratio, and whether the images of the two thread counts are
   the same bits (printed, not asserted; the tests assert it: tests/system/test_kernels_render.py).
3. **Eye pass against raw Embree on its own rays** (examples/prism.py, the README example's
   scene built in code, through the core): the scene is prepared and its light pass run first;
   then the eye pass alone (``render_prepared`` with that light pass) is timed in process CPU
   seconds, and its rays per CPU-second are compared with the backend's own on the very batches
   that eye pass cast (recorded in a second, identical render; replayed on one thread:
   ``intersect`` and ``occluded`` with the same origins, directions and lengths). The issue's
   goal: the eye pass at 40 % or more of the raw rate.

    python benchmarks/bench_parity_speed.py [--size 640 400] [--spp 32] [--rounds 3] [--threads 0]
        [--scenes readme world_only ...] [--parity-size W H] [--eye-size 320 200] [--eye-spp 4]
        [--skip-speed] [--skip-scaling] [--skip-eye]

The machine should be idle: the run takes a while at the default size (at 640 x 400, 32 spp, about
an hour and a half on 2 cores, the NumPy reference being the slow one).
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import tempfile
import time

import numpy as np

from opal_diffraction._scripts import load_example, load_script

ENGINE = "OPAL_DIFFRACTION"
README = "readme"
RENDERERS = ("ours (kernels)", "ours (NumPy reference)", "Cycles CPU")


def parity_scenes():
    return load_script("tools/cycles_parity.py").scenes_module()


# ---------------------------------------------------------------------------- bpy renders
def set_threads(sc, threads: int) -> None:
    """Both engines' threads: Blender's render threads (ours reads them too; blender/settings.py)."""
    if threads > 0:
        sc.render.threads_mode = "FIXED"
        sc.render.threads = threads
    else:
        sc.render.threads_mode = "AUTO"


def setup_scene(name: str, size, spp: int, threads: int, work: str):
    """Build ``name`` in the session and set both engines alike: resolution, samples, a fixed
    seed, no denoising, no adaptive sampling, no time limit, the threads."""
    import bpy

    if name == README:
        sc = load_example("render_example").build_scene(*size, spp=spp)
    else:
        parity_scenes().build(name, work)
        sc = bpy.context.scene
    sc.render.resolution_x, sc.render.resolution_y = int(size[0]), int(size[1])
    sc.render.resolution_percentage = 100
    sc.render.use_border = False
    sc.cycles.device = "CPU"
    sc.cycles.samples = spp
    sc.cycles.seed = 7
    sc.cycles.use_animated_seed = False
    sc.cycles.use_adaptive_sampling = False
    sc.cycles.use_denoising = False
    sc.cycles.time_limit = 0.0
    sc.opal.samples = spp
    sc.opal.seed = 7
    sc.opal.use_animated_seed = False
    sc.opal.use_adaptive_sampling = False
    sc.opal.use_denoising = False
    sc.opal.time_limit = 0.0
    set_threads(sc, threads)
    return sc


def render_timed(renderer: str) -> tuple[float, float]:
    """One render of the current scene by ``renderer`` (a RENDERERS name): (wall s, process CPU s)."""
    import bpy

    from opal_diffraction.core.util import jit

    sc = bpy.context.scene
    sc.render.engine = "CYCLES" if renderer == "Cycles CPU" else ENGINE
    mode = "numpy" if renderer == "ours (NumPy reference)" else "auto"
    with jit.kernel_mode(mode):
        t0, c0 = time.perf_counter(), time.process_time()
        bpy.ops.render.render()
        return time.perf_counter() - t0, time.process_time() - c0


def our_image() -> np.ndarray | None:
    """The RGB image of our last render (blender/engine.py's last_render)."""
    from opal_diffraction.blender import engine

    rgb = engine.last_render.get("rgb")
    return None if rgb is None else np.array(rgb)


def median(xs):
    return statistics.median(xs) if xs else float("nan")


def speed(names, size, parity_size, spp, rounds, threads) -> list[str]:
    """Part 1: the table's lines."""
    lines = []
    with tempfile.TemporaryDirectory(prefix="bench_speed_") as work:
        setup_scene(names[0], size if names[0] == README else parity_size, 1, threads, work)
        for r in RENDERERS:  # one untimed warm-up each
            render_timed(r)
        lines.append(f"{spp} spp, threads {'all' if threads <= 0 else threads}, {rounds} interleaved rounds "
                     f"(medians); wall s / CPU s / cores busy (CPU / wall)\n")
        lines.append("| scene | size | " + " | ".join(f"{r}: wall s | CPU s | cores" for r in RENDERERS)
                     + " | kernels / Cycles (wall) | NumPy / Cycles (wall) | kernels / Cycles (CPU) |")
        lines.append("|---|---|" + "---:|" * (3 * len(RENDERERS) + 3))
        print("\n".join(lines), flush=True)
        for name in names:
            sz = size if name == README else parity_size
            sc = setup_scene(name, sz, 1, threads, work)
            for r in RENDERERS:  # untimed, 1 spp: what a scene's first render pays once (images, tables, kernels)
                render_timed(r)
            sc.cycles.samples = sc.opal.samples = spp
            times = {r: [] for r in RENDERERS}
            for k in range(rounds):
                order = RENDERERS[k % len(RENDERERS):] + RENDERERS[:k % len(RENDERERS)]
                for r in order:
                    times[r].append(render_timed(r))
            med = {r: (median([t[0] for t in ts]), median([t[1] for t in ts])) for r, ts in times.items()}
            cells = []
            for r in RENDERERS:
                wall, cpu = med[r]
                cells += [f"{wall:.2f}", f"{cpu:.2f}", f"{cpu / max(wall, 1e-9):.2f}"]
            cyc_wall, cyc_cpu = med["Cycles CPU"]
            line = (f"| {name} | {sz[0]}x{sz[1]} | " + " | ".join(cells) +
                    f" | {med[RENDERERS[0]][0] / cyc_wall:.2f} | {med[RENDERERS[1]][0] / cyc_wall:.2f} | "
                    f"{med[RENDERERS[0]][1] / max(cyc_cpu, 1e-9):.2f} |")
            lines.append(line)
            print(line, flush=True)
            print("    per render (wall s, CPU s): " + "; ".join(
                f"{r}: " + ", ".join(f"({w:.2f}, {c:.2f})" for w, c in ts) for r, ts in times.items()),
                file=sys.stderr, flush=True)
    return lines


def scaling(size, spp, rounds) -> list[str]:
    """Part 2: ours (kernels) on the README example at 1 and 2 threads."""
    import bpy

    with tempfile.TemporaryDirectory(prefix="bench_scaling_") as work:
        setup_scene(README, size, spp, 1, work)
        sc = bpy.context.scene
        render_timed(RENDERERS[0])  # warm-up
        walls, cpus, images = {1: [], 2: []}, {1: [], 2: []}, {}
        for k in range(rounds):
            for n in ((1, 2) if k % 2 == 0 else (2, 1)):
                set_threads(sc, n)
                wall, cpu = render_timed(RENDERERS[0])
                walls[n].append(wall)
                cpus[n].append(cpu)
                images.setdefault(n, our_image())
    same = images[1] is not None and images[2] is not None and np.array_equal(images[1], images[2])
    w1, w2 = median(walls[1]), median(walls[2])
    lines = [f"README example {size[0]}x{size[1]}, {spp} spp, ours with the kernels, {rounds} interleaved rounds "
             "(medians)\n",
             "| threads | wall s | CPU s | cores busy |", "|---:|---:|---:|---:|"]
    for n in (1, 2):
        lines.append(f"| {n} | {median(walls[n]):.2f} | {median(cpus[n]):.2f} | "
                     f"{median(cpus[n]) / max(median(walls[n]), 1e-9):.2f} |")
    lines.append(f"\n2 threads: {w1 / max(w2, 1e-9):.2f}x one thread (wall); images of 1 and 2 threads "
                 f"bit-identical: {'yes' if same else 'NO'}")
    print("\n".join(lines), flush=True)
    return lines


# ---------------------------------------------------------------------------- the eye pass, core only
class RecordingAccel:
    """An accelerator that passes every call on and keeps a copy of each batch it was given."""

    def __init__(self, accel):
        self._accel = accel
        self.batches = []  # ('intersect' | 'occluded', origins, directions, tmax)

    def __getattr__(self, name):
        return getattr(self._accel, name)

    def intersect(self, origins, directions, tmax=None):
        self.batches.append(("intersect", np.array(origins), np.array(directions),
                             None if tmax is None else np.array(tmax)))
        return self._accel.intersect(origins, directions, tmax)

    def occluded(self, origins, directions, tmax):
        self.batches.append(("occluded", np.array(origins), np.array(directions), np.array(tmax)))
        return self._accel.occluded(origins, directions, tmax)


def eye_pass(size, spp, threads) -> list[str]:
    """Part 3: the eye pass's rays per CPU-second against the backend's on the same batches."""
    from opal_diffraction.core.integrators.light.light_pass import run_light_pass
    from opal_diffraction.core.render.frame import render, render_prepared
    from opal_diffraction.core.render.plan import plan_render
    from opal_diffraction.core.render.prepare import prepare
    from opal_diffraction.core.scene.settings import RenderSettings

    scene = load_example("prism").build_scene(*size)
    st = RenderSettings(samples=spp, threads=threads, seed=3)
    render(scene, dataclasses.replace(st, samples=1))  # warm-up: imports, the compile stage
    prepared = prepare(scene, st)
    plan = plan_render(prepared)
    light = run_light_pass(prepared, plan=plan) if plan.light_pass else None
    light_rays = 0 if light is None else light.stats.get("light_rays", 0)
    rows = []
    for mode in ("auto", "numpy"):
        st_mode = dataclasses.replace(prepared.settings, kernels=mode)  # prepare resolved its light paths
        p = dataclasses.replace(prepared, settings=st_mode)
        c0, t0 = time.process_time(), time.perf_counter()
        res = render_prepared(p, light)
        cpu, wall = time.process_time() - c0, time.perf_counter() - t0
        rays = res.stats["rays"] - light_rays
        rec = RecordingAccel(prepared.accel)
        again = render_prepared(dataclasses.replace(p, accel=rec), light)
        same = np.array_equal(again.rgb, res.rgb)
        n_rays = sum(len(b[1]) for b in rec.batches)
        c0 = time.process_time()
        for kind, o, d, tmax in rec.batches:
            if kind == "intersect":
                prepared.accel.intersect(o, d, tmax)
            else:
                prepared.accel.occluded(o, d, tmax)
        raw_cpu = time.process_time() - c0
        eye_rate, raw_rate = rays / max(cpu, 1e-9) / 1e6, n_rays / max(raw_cpu, 1e-9) / 1e6
        rows.append(f"| {res.stats['kernels']} | {rays / 1e6:.2f} | {wall:.2f} | {cpu:.2f} | {eye_rate:.2f} | "
                    f"{len(rec.batches)} batches, {n_rays / 1e6:.2f} M rays{'' if same else ' (NOT the same image)'}"
                    f" | {raw_rate:.2f} | {eye_rate / max(raw_rate, 1e-9):.1%} |")
    lines = [f"The prism example (examples/prism.py, the README scene) {size[0]}x{size[1]}, {spp} spp, eye pass on "
             f"{threads or 'all'} threads after its light pass; backend {prepared.accel.name}, replayed on one "
             "thread\n",
             "| kernels | eye-pass rays (M) | wall s | CPU s | eye pass M rays / CPU s | its batches | raw M rays / "
             "CPU s | eye / raw |", "|---|---:|---:|---:|---:|---|---:|---:|"] + rows
    print("\n".join(lines), flush=True)
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, nargs=2, default=(640, 400), metavar=("W", "H"))
    ap.add_argument("--parity-size", type=int, nargs=2, default=None, metavar=("W", "H"),
                    help="the parity scenes' size (default: --size)")
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--threads", type=int, default=0, help="both engines' threads (0: every core)")
    ap.add_argument("--scenes", nargs="+", default=None,
                    help=f"'{README}' and/or parity scene names (default: all)")
    ap.add_argument("--eye-size", type=int, nargs=2, default=(320, 200), metavar=("W", "H"))
    ap.add_argument("--eye-spp", type=int, default=4)
    ap.add_argument("--skip-speed", action="store_true")
    ap.add_argument("--skip-scaling", action="store_true")
    ap.add_argument("--skip-eye", action="store_true")
    args = ap.parse_args(argv)

    import bpy

    import opal_diffraction
    from opal_diffraction.core.util import jit

    names = args.scenes or [README] + list(parity_scenes().SCENES)
    unknown = [n for n in names if n != README and n not in parity_scenes().SCENES]
    if unknown:
        ap.error(f"unknown scene(s) {unknown}; known: {[README] + list(parity_scenes().SCENES)}")
    print(f"Blender {bpy.app.version_string}; ours' kernels: {jit.kernels_path('auto')}\n")
    opal_diffraction.register()
    try:
        if not args.skip_speed:
            speed(names, tuple(args.size), tuple(args.parity_size or args.size), args.spp, args.rounds, args.threads)
            print()
        if not args.skip_scaling:
            scaling(tuple(args.size), args.spp, args.rounds)
            print()
    finally:
        opal_diffraction.unregister()
    if not args.skip_eye:
        eye_pass(tuple(args.eye_size), args.eye_spp, args.threads)
    return 0


if __name__ == "__main__":
    sys.exit(main())
