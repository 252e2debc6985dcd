"""Peak memory (RSS) of a full-HD render, with and without a spectral EXR.

    .venv/bin/python benchmarks/bench_memory.py [--scene prism|gem] [--width 1920 --height 1080]
        [--spp 8 16] [--tree /path/to/another/checkout] [--tracemalloc] [--timeline 10] [--keep DIR]

Each configuration runs in a fresh subprocess that renders the scene through the command line
(``opal_diffraction.cli render``: prepare, light pass, eye pass, the RGB EXR and PNG, and with
``--spectral-exr`` the spectral EXR) and then reports its peak resident set size,
``resource.getrusage(RUSAGE_SELF).ru_maxrss`` (Linux: kB). A fresh process per configuration,
because the peak only ever grows within a process.

The film does not grow with the samples: the eye pass runs in rounds of ``round_samples`` (8)
samples per pixel, one tile at a time per thread, so a render of 64 spp holds what a render of 8
holds and loops eight times longer. ``--spp 8 16`` shows it (one round and two). ``--tree``
also runs every configuration with another checkout's ``opal_diffraction`` first on the path
(``git worktree add /tmp/base 5d742db`` for the state before the RGB films), in turns.
``--parallel N`` runs N configurations at once (each is its own process, so its peak RSS is its
own; only the time changes). ``--tracemalloc`` prints, for each configuration, the ten biggest allocation sites alive at the
peak of the traced Python allocations (NumPy reports its buffers to tracemalloc).

``--timeline S`` samples each child's peak RSS every S seconds (wall, CPU, ru_maxrss) into
``run<i>/stderr.txt`` as it runs (readable before a long render ends) and summarises it;
``--keep DIR`` keeps the runs' folders there instead of a temporary one.

The scene is examples/prism.py (dense flint, dispersion, 1 M automatic light paths at full HD)
or examples/gem.py (a diamond under an environment map). Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)

CHILD = r"""
import os, resource, sys, json
trace = os.environ.get("BENCH_TRACEMALLOC") == "1"
if trace:
    import tracemalloc
    tracemalloc.start(8)
from opal_diffraction.cli import main
import opal_diffraction
timeline = []
if os.environ.get("BENCH_TIMELINE"):  # (wall s, CPU s, peak RSS kB) every few seconds, to stderr
    import threading, time
    t0 = time.perf_counter()
    def sample():
        while True:
            row = (round(time.perf_counter() - t0, 1), round(time.process_time(), 1),
                   resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
            timeline.append(row)
            print("BENCH_TIMELINE " + json.dumps(row), file=sys.stderr, flush=True)
            time.sleep(float(os.environ["BENCH_TIMELINE"]))
    threading.Thread(target=sample, daemon=True).start()
args = json.loads(sys.argv[1])
code = main(args)
out = {"code": code, "maxrss_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
       "package": os.path.dirname(opal_diffraction.__file__), "timeline": timeline}
if trace:
    cur, peak = tracemalloc.get_traced_memory()
    out["traced_peak_mb"] = peak / 2**20
print("BENCH_RESULT " + json.dumps(out))
"""

# with --tracemalloc: sample the allocations alive at the traced peak by snapshotting every round
CHILD_TRACE = r"""
import os, resource, sys, json, tracemalloc, threading
tracemalloc.start(12)
import opal_diffraction
from opal_diffraction.core import film as _film
best = {"peak": 0, "snap": None}
lock = threading.Lock()
def watch():
    cur, peak = tracemalloc.get_traced_memory()
    with lock:
        if cur > best["peak"]:
            best["peak"], best["snap"] = cur, tracemalloc.take_snapshot()
_orig = _film.Film.add_tile
def add_tile(self, *a, **k):
    _orig(self, *a, **k)
    watch()
_film.Film.add_tile = add_tile
from opal_diffraction.core import output as _out
for name in ("write_spectral_exr", "write_rgb_exr"):
    f = getattr(_out, name)
    def wrapped(*a, _f=f, **k):
        watch()
        return _f(*a, **k)
    setattr(_out, name, wrapped)
import OpenEXR
_File = OpenEXR.File
class File(_File):
    def write(self, *a, **k):
        watch()
        return super().write(*a, **k)
OpenEXR.File = File
from opal_diffraction.cli import main
args = json.loads(sys.argv[1])
code = main(args)
stats = best["snap"].statistics("traceback") if best["snap"] is not None else []
top = [{"mb": s.size / 2**20, "where": [f"{fr.filename.split('opal_diffraction/')[-1]}:{fr.lineno}"
                                        for fr in list(s.traceback)[-4:]]} for s in stats[:10]]
print("BENCH_RESULT " + json.dumps({"code": code, "maxrss_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
                                    "package": os.path.dirname(opal_diffraction.__file__),
                                    "snapshot_mb": best["peak"] / 2**20, "top": top}))
"""


def run_one(tree: str, scene_path: str, spp: int, spectral: bool, workdir: str, trace: bool) -> dict:
    import json

    out = os.path.join(workdir, "out.exr")
    args = ["render", scene_path, "-o", out, "--spp", str(spp), "-q"]
    if spectral:
        args += ["--spectral-exr", os.path.join(workdir, "spectral.exr")]
    env = dict(os.environ, PYTHONPATH=tree)
    # the child's stderr (its --timeline samples) goes to a file beside its outputs, readable while it runs
    with open(os.path.join(workdir, "stderr.txt"), "w") as err:
        proc = subprocess.run([sys.executable, "-c", CHILD_TRACE if trace else CHILD, json.dumps(args)],
                              env=env, stdout=subprocess.PIPE, stderr=err, text=True, cwd=workdir)
    with open(os.path.join(workdir, "stderr.txt")) as err:
        proc.stderr = err.read()
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("BENCH_RESULT ")]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"child failed ({proc.returncode}):\n{proc.stdout[-2000:]}\n{proc.stderr[-4000:]}")
    res = json.loads(lines[-1][len("BENCH_RESULT "):])
    if res["code"] != 0:
        raise RuntimeError(f"render failed: {proc.stderr[-2000:]}")
    res["spectral_bytes"] = os.path.getsize(os.path.join(workdir, "spectral.exr")) if spectral else 0
    return res


class _Keep:
    """A folder that stays (``--keep``), used like TemporaryDirectory."""

    def __init__(self, path):
        self.path = os.path.abspath(path)

    def __enter__(self):
        os.makedirs(self.path, exist_ok=True)
        return self.path

    def __exit__(self, *exc):
        return False


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", choices=["prism", "gem"], default="prism")
    ap.add_argument("--width", type=int, default=1920)
    ap.add_argument("--height", type=int, default=1080)
    ap.add_argument("--spp", type=int, nargs="+", default=[8])
    ap.add_argument("--tree", default="", help="another checkout to measure too (e.g. a worktree of main)")
    ap.add_argument("--only", choices=["rgb", "spectral"], default=None, help="one of the two outputs only")
    ap.add_argument("--tracemalloc", action="store_true")
    ap.add_argument("--parallel", type=int, default=1, help="configurations run at once (peak RSS is per process, "
                                                               "so this changes only the time)")
    ap.add_argument("--timeline", type=float, default=0.0,
                    help="seconds between peak-RSS samples in each child (printed as it runs, and summarised)")
    ap.add_argument("--keep", default="", help="a folder for the runs' outputs and logs (default: a temporary one)")
    args = ap.parse_args(argv)
    if args.timeline > 0:
        os.environ["BENCH_TIMELINE"] = str(args.timeline)

    from opal_diffraction._scripts import load_example
    from opal_diffraction.core.scene.npz import save_scene
    from opal_diffraction.core.scene.settings import film_bytes

    trees = [("this tree", REPO)] + ([("--tree", os.path.abspath(args.tree))] if args.tree else [])
    rows = []
    with (tempfile.TemporaryDirectory() if not args.keep else _Keep(args.keep)) as tmp:
        scene = load_example(args.scene).build_scene(args.width, args.height)
        scene_path = os.path.join(tmp, "scene.npz")
        save_scene(scene, scene_path)
        outputs = [False, True] if args.only is None else [args.only == "spectral"]
        configs = [(label, tree, spp, spectral) for spp in args.spp for spectral in outputs
                   for label, tree in trees]  # in turns

        def one(i):
            label, tree, spp, spectral = configs[i]
            work = os.path.join(tmp, f"run{i}")  # each its own output files
            os.makedirs(work)
            res = run_one(tree, scene_path, spp, spectral, work, args.tracemalloc)
            print(f"{label} ({res['package']}): {spp} spp, spectral EXR {spectral}: peak RSS "
                  f"{res['maxrss_kb'] / 2**20:.2f} GiB", flush=True)
            tl = res.get("timeline") or []
            if tl:
                print(f"    timeline: {len(tl)} samples over {tl[-1][0]:.0f} s wall, {tl[-1][1]:.0f} s CPU; peak RSS "
                      f"{', '.join(f'{r[2] / 2**20:.2f}' for r in tl[::max(1, len(tl) // 12)])} GiB", flush=True)
            for t in res.get("top", []):
                print(f"    {t['mb']:8.1f} MB  {' <- '.join(reversed(t['where']))}", flush=True)
            return res

        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=max(1, args.parallel)) as pool:
            results = list(pool.map(one, range(len(configs))))
        rows = [(label, spp, spectral, res) for (label, _, spp, spectral), res in zip(configs, results)]
    n = 61
    print(f"\n{args.scene} example, {args.width}x{args.height}, {n} wavelengths; film estimate "
          f"(settings.film_bytes) {film_bytes(args.width, args.height, n, False) / 2**30:.2f} GiB without, "
          f"{film_bytes(args.width, args.height, n, True) / 2**30:.2f} GiB with a spectral EXR\n")
    print("| code | spp | spectral EXR | peak RSS (GiB) |")
    print("|---|---|---|---|")
    for label, spp, spectral, res in rows:
        print(f"| {label} | {spp} | {'yes' if spectral else 'no'} | {res['maxrss_kb'] / 2**20:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
