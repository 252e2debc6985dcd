"""How much of a render holds Python's GIL: the serial share that bounds thread scaling on many cores.

    python benchmarks/bench_gil.py [--scenes prism gem] [--size 640 400] [--spp 4] [--seconds 8]
    python benchmarks/bench_gil.py --child PASS SCENE W H SPP SECONDS   (internal: the sampled process)

The kernels (numba ``nogil``) and Embree release the GIL; the Python between them (the walker's
steps, row gathers, small NumPy calls) holds it. On T threads at most one thread runs Python at a
time, so if a render holds the GIL for a share g of its single-thread time, T threads cannot run
it faster than min(T, 1 / g) times one thread (Amdahl's law with the GIL as the serial part) - on
a 2-core machine the bound is invisible (1 / g > 2 for any g < 0.5), on an artist's 8-16 cores
it is the ceiling. Measured per pass (the eye pass after its light pass; the light pass alone) of
an example scene, one thread, by py-spy (`pip install -r benchmarks/requirements.txt`): a child
process repeats the pass for ``--seconds``, py-spy samples it at 200 Hz once with ``--gil`` (only
samples where a thread holds the GIL) and once without, and g = GIL samples / all samples of the
pass's thread. Also the top Python lines holding the GIL. Timings only: nothing passes or fails.
"""

from __future__ import annotations

import argparse
import collections
import os
import shutil
import subprocess
import sys
import tempfile
import time

RATE = 200


def child(which: str, scene_name: str, w: int, h: int, spp: int, seconds: float) -> None:
    """Prepare ``scene_name``, run its light pass once, then repeat ``which`` ('eye' or 'light')
    on one thread for ``seconds``, printing START before and STOP after the timed loop."""
    from opal_diffraction._scripts import load_example
    from opal_diffraction.core.integrators.light.light_pass import run_light_pass
    from opal_diffraction.core.render.frame import render, render_prepared
    from opal_diffraction.core.render.plan import plan_render
    from opal_diffraction.core.render.prepare import prepare
    from opal_diffraction.core.scene.settings import RenderSettings
    from opal_diffraction.core.scene.validation import validate
    from opal_diffraction.core.util.jit import kernel_mode

    example = load_example(scene_name)
    render(validate(example.build_scene(32, 20)).scene, RenderSettings(samples=1, threads=1))  # compile stage
    prepared = prepare(validate(example.build_scene(w, h)).scene, RenderSettings(samples=spp, threads=1))
    plan = plan_render(prepared)
    light = run_light_pass(prepared, plan=plan) if plan.light_pass else None
    render_prepared(prepared, light=light)  # a scene's first-use costs, untimed
    print("START", flush=True)
    t0, c0, n = time.perf_counter(), time.process_time(), 0
    with kernel_mode("auto"):  # as inside a render (kernels_enabled() then reads no environment)
        while time.perf_counter() - t0 < seconds:
            if which == "light":
                run_light_pass(prepared, plan=plan)
            else:
                render_prepared(prepared, light=light)
            n += 1
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    print(f"STOP {n} {wall:.3f} {cpu:.3f}", flush=True)


def _samples(path: str):
    """py-spy raw output -> (total samples, Counter of leaf frames)."""
    total, leaf = 0, collections.Counter()
    with open(path) as f:
        for line in f:
            line = line.rstrip()
            if not line:
                continue
            stack, n = line.rsplit(" ", 1)
            total += int(n)
            leaf[stack.split(";")[-1]] += int(n)
    return total, leaf


def measure(which: str, scene_name: str, size, spp: int, seconds: float, pyspy: str) -> dict:
    sample_s = max(2.0, seconds - 2.0)
    with tempfile.TemporaryDirectory() as tmp:
        proc = subprocess.Popen([sys.executable, __file__, "--child", which, scene_name, str(size[0]), str(size[1]),
                                 str(spp), str(seconds * 2 + 2)], stdout=subprocess.PIPE, text=True)
        assert proc.stdout is not None
        for line in proc.stdout:
            if line.startswith("START"):
                break
        time.sleep(0.5)
        raw = {}
        for mode in ("gil", "all"):
            out = os.path.join(tmp, mode)
            args = [pyspy, "record", "--pid", str(proc.pid), "--rate", str(RATE), "--duration", str(int(sample_s)),
                    "--format", "raw", "-o", out, "--nonblocking"]
            args += ["--gil"] if mode == "gil" else ["--idle"]
            subprocess.run(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
            raw[mode] = _samples(out)
        stop = proc.stdout.read()
        proc.wait()
    n, wall, cpu = stop.split("STOP", 1)[1].split()[:3]
    gil, leaf = raw["gil"]
    # samples of the thread running the pass: the light pass's lane threads, or the eye pass's tile thread
    busy = sum(v for k, v in raw["all"][1].items()
               if not any(s in k for s in ("wait (threading", "_wait_for_tstate_lock", "select (", "sleep")))
    return {"pass": which, "scene": scene_name, "runs": int(n), "wall": float(wall), "cpu": float(cpu),
            "gil_share": gil / max(busy, 1), "gil_of_wall": gil / (RATE * int(sample_s)), "top": leaf.most_common(8)}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "--child":
        which, scene, w, h, spp, seconds = argv[1:7]
        child(which, scene, int(w), int(h), int(spp), float(seconds))
        return 0
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["prism"])
    ap.add_argument("--size", type=int, nargs=2, default=(640, 400), metavar=("W", "H"))
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--seconds", type=float, default=8.0)
    a = ap.parse_args(argv)
    pyspy = shutil.which("py-spy") or os.path.join(os.path.dirname(sys.executable), "py-spy")
    if not os.path.exists(pyspy):
        print("bench_gil: py-spy is not installed (pip install -r benchmarks/requirements.txt)", file=sys.stderr)
        return 2
    rows = [measure(which, scene, a.size, a.spp, a.seconds, pyspy) for scene in a.scenes for which in ("eye", "light")]
    print(f"\n{a.size[0]}x{a.size[1]}, {a.spp} spp, one thread, py-spy at {RATE} Hz\n")
    print("| scene | pass | runs | CPU s / run | GIL held (share of the pass's samples) | bound on T threads: 1 / g |")
    print("|---|---|---:|---:|---:|---:|")
    for r in rows:
        g = r["gil_share"]
        print(f"| {r['scene']} | {r['pass']} | {r['runs']} | {r['cpu'] / max(r['runs'], 1):.2f} | {g:.1%} | "
              f"{1 / max(g, 1e-9):.1f}x |")
    for r in rows:
        print(f"\n{r['scene']} {r['pass']} pass: the lines holding the GIL most (share of GIL samples)")
        tot = sum(v for _, v in r["top"]) or 1
        for frame, v in r["top"]:
            print(f"  {v:5d}  {frame[:140]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
