"""Light-pass throughput (paths/s) on three scenes: benchmarks/caustic_sphere.py's white glass
sphere under a point light, examples/prism.py (a dispersive flint prism, a point light and a sky
map) and examples/gem.py (a diamond under a studio environment map).

    python benchmarks/bench_light_pass.py [--paths 1000000] [--repeats 3] [--threads 1 2]
                                          [--scenes sphere prism gem] [--trees A B] [--profile]

Times ``run_light_pass`` alone (the scene is prepared first, untimed) at a fixed path count,
best of ``--repeats`` (wall time, and CPU time of the process: on a shared machine the CPU time
is the steadier measure of the work; the wall time at threads=2 shows the parallel gain). ``--trees``: source trees to compare in the same run (each run in a
subprocess with that tree first on PYTHONPATH, the trees alternated within every repeat so they
see the same machine load); without it, the opal_diffraction on the path. ``--profile``: a
pyinstrument profile of one light pass per scene at threads=1 (top of the call tree).
Timings only: nothing here passes or fails.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
SCENES = ("sphere", "prism", "gem")


def build(name: str):
    """The scene ``name`` (a validated Scene)."""
    from opal_diffraction._scripts import load_example, load_script
    from opal_diffraction.core.scene.validation import validate

    if name == "sphere":
        cs = load_script(os.path.join("benchmarks", "caustic_sphere.py"))
        scene = cs.our_scene(cs.Spec())
    elif name in ("prism", "gem"):
        scene = load_example(name).build_scene()
    else:
        raise SystemExit(f"unknown scene {name!r} (one of {', '.join(SCENES)})")
    return validate(scene).scene


def prepared(name: str, paths: int, threads: int):
    from opal_diffraction.core.render.prepare import prepare
    from opal_diffraction.core.scene.settings import RenderSettings

    return prepare(build(name), RenderSettings(samples=1, light_paths=paths, threads=threads))


def time_once(name: str, paths: int, threads: int) -> dict:
    """One timed light pass: wall and CPU seconds (this process, all threads), paths, rays, deposits."""
    from opal_diffraction.core.integrators.light.light_pass import run_light_pass
    from opal_diffraction.core.render.plan import plan_render

    ctx = prepared(name, paths, threads)
    t0, c0 = time.perf_counter(), time.process_time()
    res = run_light_pass(ctx, paths, plan=plan_render(ctx))
    dt, cpu = time.perf_counter() - t0, time.process_time() - c0
    s = res.stats
    return {"s": dt, "cpu": cpu, "paths": int(s["light_paths"]), "rays": int(s["light_rays"]),
            "deposits": int(s["light_deposits"])}


def profile(name: str, paths: int, lines: int) -> None:
    from pyinstrument import Profiler

    from opal_diffraction.core.integrators.light.light_pass import LightWork
    from opal_diffraction.core.integrators.light.walker import trace_batch

    ctx = prepared(name, paths, 1)
    prof = Profiler(interval=0.002)
    prof.start()
    # run_light_pass's work on this thread (its lanes run on a pool, which pyinstrument does not see)
    work = LightWork.of(ctx, paths)
    illum, records = work.empty_maps(ctx.grid.n)
    for job in work.batches:
        trace_batch(ctx, job, illum, records)
    prof.stop()
    text = prof.output_text(unicode=False, color=False, show_all=False)
    print(f"--- profile: {name}, {paths} paths, threads=1")
    print("\n".join(text.splitlines()[:lines]))


def worker(args) -> int:
    out = {}
    for name in args.scenes:
        for th in args.threads:
            out[f"{name}/{th}"] = time_once(name, args.paths, th)
    print(json.dumps(out))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--scenes", nargs="+", default=list(SCENES))
    ap.add_argument("--trees", nargs="+", default=None, help="source trees to compare (alternated)")
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--profile-lines", type=int, default=60)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        return worker(args)
    if args.profile:
        for name in args.scenes:
            profile(name, args.paths, args.profile_lines)
        return 0
    trees = args.trees or [None]
    best: dict[tuple, dict] = {}
    for rep in range(args.repeats):
        for tree in trees:  # alternated: every tree sees the same load in each repeat
            env = dict(os.environ)
            if tree is not None:
                env["PYTHONPATH"] = os.path.abspath(tree) + os.pathsep + env.get("PYTHONPATH", "")
            cmd = [sys.executable, os.path.abspath(__file__), "--worker", "--paths", str(args.paths),
                   "--threads", *map(str, args.threads), "--scenes", *args.scenes]
            res = json.loads(subprocess.run(cmd, env=env, check=True, capture_output=True, text=True,
                                            cwd=os.path.abspath(tree) if tree else None).stdout.splitlines()[-1])
            for key, r in res.items():
                k = (tree, key)
                if k not in best:
                    best[k] = dict(r)
                best[k]["s"] = min(best[k]["s"], r["s"])  # best wall and best CPU time, each over the repeats
                best[k]["cpu"] = min(best[k]["cpu"], r["cpu"])
            print(f"repeat {rep + 1}/{args.repeats} {tree or '.'}: "
                  + ", ".join(f"{k} {r['s']:.2f} s ({r['cpu']:.2f} CPU)" for k, r in res.items()), flush=True)
    print(f"\nlight pass, {args.paths} paths, best of {args.repeats}")
    print("| scene | threads | tree | wall s | CPU s | paths/s (wall) | paths/s per CPU s | rays/s (wall) |")
    print("|---|---:|---|---:|---:|---:|---:|---:|")
    for name in args.scenes:
        for th in args.threads:
            for tree in trees:
                r = best[(tree, f"{name}/{th}")]
                print(f"| {name} | {th} | {tree or '.'} | {r['s']:.2f} | {r['cpu']:.2f} | "
                      f"{r['paths'] / r['s'] / 1e6:.3f} M | {r['paths'] / r['cpu'] / 1e6:.3f} M | "
                      f"{r['rays'] / r['s'] / 1e6:.2f} M |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
