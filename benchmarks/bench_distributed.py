"""One frame on Dask: speed-up with 1 and 2 local worker processes against the single-process
render, the bytes each task sends, and a model of the same frame on 64 machines.

    .venv/bin/python benchmarks/bench_distributed.py [--width 640 --height 400 --spp 16]
        [--workers 1 2] [--machines 64 --cores 8 --bandwidth 117] [--spectral] [--sizes-only]

``--spectral``: the frame writes a spectral EXR, so tiles send their spectral sums too (the
default sends RGB; the bytes table shows both either way). ``--sizes-only``: no cluster and no
frame timings, only the bytes and the per-task times in this process.

The scene is the prism example (examples/prism.py: dense flint, 1 M light paths, caustics).
Renders it in this process with 1 thread and with all threads (the reference image), and on a
LocalCluster of N worker processes with one thread each: the first frame includes every worker
preparing the scene (its ray caster cannot be sent), the next ones reuse that preparation (the
next frame of an unchanged scene). The configurations take turns ``--repeat`` times and the
best time of each is reported (the machine may be shared). Every distributed image is compared
with the reference (it must be equal: max |difference| 0). BLAS runs one thread per process,
as on a Dask worker.

Then, in this process, it measures what crosses the wire, as pickled bytes (protocol 5): the
job scattered once (scene + settings), the light-pass maps scattered once, each task's
arguments, each light batch's result (its deposits) and each tile's result; and the client's
serial work per result (replaying a batch's deposits into its lane, adding a tile to the film).
The 64-machine model combines them (docs/distributed.md explains it). Prints Markdown tables.
"""

from __future__ import annotations

import os

# one core per thread, as on a Dask worker (its nanny sets these): a multithreaded BLAS in this
# process would borrow the other cores and make "1 thread" mean more than one
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import pickle  # noqa: E402
import time  # noqa: E402
from contextlib import ExitStack  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from opal_diffraction._scripts import load_example  # noqa: E402
from opal_diffraction.core.render import distributed as dist  # noqa: E402
from opal_diffraction.core.render.film import Film  # noqa: E402
from opal_diffraction.core.integrators.light.light_pass import LANES, LightWork, run_light_pass  # noqa: E402
from opal_diffraction.core.render.plan import plan_render  # noqa: E402
from opal_diffraction.core.render.prepare import prepare  # noqa: E402
from opal_diffraction.core.render.frame import render  # noqa: E402
from opal_diffraction.core.scene.settings import RenderSettings  # noqa: E402
from opal_diffraction.core.render.tiles import EyeWork  # noqa: E402


def _size(x) -> int:
    return len(pickle.dumps(x, protocol=5))


def _mb(b) -> str:
    return f"{b / 1e6:.2f} MB" if b >= 1e5 else f"{b / 1e3:.1f} kB" if b >= 1e3 else f"{b} B"


def timed_local(scene, settings):
    t = time.perf_counter()
    r = render(scene, settings)
    return time.perf_counter() - t, r


def _diff(r, reference) -> float:
    # RGB films (no spectral EXR): the RGB image and every pass
    return max(float(np.max(np.abs(r.rgb.astype(np.float64) - reference.rgb))),
               *(float(np.max(np.abs(r.passes[k] - reference.passes[k]))) for k in r.passes))


def timed_cluster(client, scene, settings, n_workers, reference):
    """One frame on ``client``: seconds, result, max |difference| from ``reference``, the tasks'
    compute durations on the workers (Dask's task stream) and how busy the workers were."""
    from dask.distributed import get_task_stream

    with get_task_stream(client) as ts:
        t = time.perf_counter()
        r = render(scene, settings, client=client)
        s = time.perf_counter() - t
    durations = {"light": [], "tile": []}
    for rec in ts.data:
        kind = "light" if str(rec["key"]).startswith("opal-light") else "tile"
        for part in rec["startstops"]:
            if part["action"] == "compute":
                durations[kind].append(part["stop"] - part["start"])
    busy = sum(map(sum, durations.values())) / (s * n_workers)
    return s, r, _diff(r, reference), durations, busy


def wire_sizes(scene, settings, spectral: bool = False):
    """Pickled sizes and client-side costs, measured by running the tasks in this process.
    ``spectral``: the tiles send their spectral sums too (a spectral EXR is asked); either way
    ``tile_bytes_rgb`` and ``tile_bytes_spectral`` hold both sizes of every tile (the RGB result
    is the spectral one without its spectral sums: tile_task's only difference, checked on the
    first tile against an RGB job's own result)."""
    prepared = prepare(scene, settings)
    t = time.perf_counter()
    prepare(scene, settings)
    prepare_s = time.perf_counter() - t
    region = (0, 0, scene.camera.width, scene.camera.height)
    job = dist.make_job(scene, settings, region, prepared.accel.name, spectral=True)
    job_rgb = dist.make_job(scene, settings, region, prepared.accel.name, spectral=False)
    work = LightWork.of(prepared)
    eye = EyeWork.of(prepared)
    key = "opal-light-0123456789ab-17"
    sizes = {"job": _size(job),
             "light task args": _size((dist.LIGHT_TASK, "job-" + "0" * 32, 17)),
             "tile task args": _size((dist.TILE_TASK, "job-" + "0" * 32, "light-" + "0" * 32, 1, 17)),
             "task key": len(key)}
    maps = [work.empty_maps(prepared.grid.n) for _ in range(LANES)]
    batch_bytes, batch_s, replay_s = [], [], []
    for j in range(len(work.batches)):
        t = time.perf_counter()
        out = dist.light_batch_task(job, j)
        batch_s.append(time.perf_counter() - t)
        batch_bytes.append(_size(out))
        t = time.perf_counter()
        illum, records = maps[j % LANES]
        dist.DepositLog.replay_calls(out["illum"], illum)
        if records is not None:
            dist.DepositLog.replay_calls(out["records"], records)
        replay_s.append(time.perf_counter() - t)
    light = run_light_pass(prepared, plan=plan_render(prepared))
    light_w = {"token": "0" * 12, "caustics": dist.pack_map(light.caustics),
               "grating_records": dist.pack_map(light.grating_records),
               "splat": light.splat is not None, "splat_spectral": light.splat is not None and light.splat.spectral}
    sizes["light maps"] = _size(light_w)
    sizes["light maps, dense"] = light.caustics.flux.nbytes + (0 if light.grating_records is None else
                                                              light.grating_records.flux.nbytes)
    # tiles: every tile of the first round (a tile's result size does not depend on the round)
    film = Film(scene.camera.width, scene.camera.height, prepared.conv, spectral=spectral)
    tile_rgb, tile_spec, tile_s, add_s = [], [], [], []
    for ti in range(len(eye.tiles)):
        t = time.perf_counter()
        out = dist.tile_task(job, light_w, 0, ti)
        tile_s.append(time.perf_counter() - t)
        tile_spec.append(_size(out))
        rgb_out = dict(out, spectral=None)
        tile_rgb.append(_size(rgb_out))
        if ti == 0:  # the RGB job's own result: the same bytes
            own = _size(dist.tile_task(job_rgb, light_w, 0, ti))
            assert own == tile_rgb[0], (own, tile_rgb[0])
        t = time.perf_counter()
        x0, y0, x1, y1, _ = eye.tiles[ti]
        o = out if spectral else rgb_out
        film.add_converted(x0, y0, x1, y1, o["rgb"], o["parts"], eye.rounds[0], spectral=o["spectral"])
        add_s.append(time.perf_counter() - t)
    return dict(sizes=sizes, prepare_s=prepare_s, n_batches=len(work.batches), batch_bytes=batch_bytes,
                batch_s=batch_s, replay_s=replay_s, rounds=len(eye.rounds), n_tiles=len(eye.tiles),
                tile_bytes=tile_spec if spectral else tile_rgb, tile_bytes_rgb=tile_rgb,
                tile_bytes_spectral=tile_spec, tile_s=tile_s, add_s=add_s)


def model(w, machines: int, cores: int, bandwidth_mb: float, local_1thread_s: float):
    """Seconds of one frame on ``machines`` x ``cores`` (each core as fast as one here), with a
    ``bandwidth_mb`` MB/s network per machine (the client's link too)."""
    bw = bandwidth_mb * 1e6
    slots = machines * cores
    s = w["sizes"]
    # scatter: client -> scheduler -> one worker, then Dask's tree copy (branching 2: the holders
    # triple every generation, each sending two copies)
    gens = int(np.ceil(np.log(machines) / np.log(3))) if machines > 1 else 0

    def broadcast(b):
        return (2 + 2 * gens) * b / bw

    light_trace = np.ceil(w["n_batches"] / slots) * max(w["batch_s"])
    light_recv = sum(w["batch_bytes"]) / bw
    light_fold = sum(w["replay_s"])
    units = w["rounds"] * w["n_tiles"]
    unit_max = max(w["tile_s"])
    eye_trace = np.ceil(units / slots) * unit_max
    eye_recv = units * float(np.mean(w["tile_bytes"])) / bw
    eye_add = units * float(np.mean(w["add_s"]))
    parts = {
        "scene broadcast": broadcast(s["job"]),
        "worker prepare (in parallel)": w["prepare_s"],
        "light pass: tracing (one wave of batches)": light_trace,
        "light pass: deposits to the client": light_recv,
        "light pass: replay into the lanes (client)": light_fold,
        "light maps broadcast": broadcast(s["light maps"]),
        "eye pass: tracing (waves of units)": eye_trace,
        "eye pass: tile results to the client": eye_recv,
        "eye pass: film adds (client)": eye_add,
    }
    # the light pass's three parts overlap (as results stream in), as do the eye pass's
    total = (parts["scene broadcast"] + parts["worker prepare (in parallel)"]
             + max(light_trace, light_recv, light_fold) + parts["light maps broadcast"]
             + max(eye_trace, eye_recv, eye_add))
    one_machine = local_1thread_s / cores
    return parts, total, one_machine


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=400)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--light-paths", type=int, default=1_000_000)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeat", type=int, default=3, help="frames per configuration (the best is reported)")
    ap.add_argument("--machines", type=int, default=64)
    ap.add_argument("--cores", type=int, default=8, help="cores per machine in the model")
    ap.add_argument("--bandwidth", type=float, default=117.0, help="MB/s per machine in the model (1 Gbit/s)")
    ap.add_argument("--spectral", action="store_true",
                    help="the frame writes a spectral EXR: tiles send their spectral sums too (the model uses those)")
    ap.add_argument("--sizes-only", action="store_true",
                    help="only the bytes and per-task times (no cluster, no frame timings); the model's "
                         "one-machine time is then the sum of the per-task times measured here")
    args = ap.parse_args(argv)

    scene = load_example("prism").build_scene(args.width, args.height)
    settings = RenderSettings(samples=args.spp, light_paths=args.light_paths, seed=0,
                              spectral_exr="spectral.exr" if args.spectral else "")  # a name only: render() writes no file
    print(f"prism example {args.width}x{args.height}, {args.spp} spp, {args.light_paths / 1e6:g} M light paths; "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at the start\n")

    render(load_example("prism").build_scene(32, 20), replace(settings, spectral_exr=""))  # warm caches
    if args.sizes_only:
        return report_sizes(args, scene, settings, None, {})
    from dask.distributed import Client, LocalCluster

    with ExitStack() as stack:
        clients = {}
        for n in args.workers:
            t = time.perf_counter()
            cluster = stack.enter_context(LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                                       dashboard_address=None))
            clients[n] = stack.enter_context(Client(cluster))
            clients[n].wait_for_workers(n)
            clients[n].start_s = time.perf_counter() - t
        # the configurations take turns, so a change in the machine's load hits them alike; the
        # best of --repeat is reported (a worker's first frame, which prepares, is reported apart)
        best: dict = {}
        first: dict = {}
        loads = []
        for rep in range(args.repeat):
            loads.append(os.getloadavg()[0])
            for threads in (1, os.cpu_count()):
                s, r = timed_local(scene, replace(settings, threads=threads))
                if ("local", threads) not in best or s < best[("local", threads)][0]:
                    best[("local", threads)] = (s, r)
            reference = best[("local", os.cpu_count())][1]
            for n, client in clients.items():
                if n not in first:  # the workers prepare the scene
                    first[n] = timed_cluster(client, scene, settings, n, reference)
                res = timed_cluster(client, scene, settings, n, reference)
                if n not in best or res[0] < best[n][0]:
                    best[n] = res
        t1, tn = best[("local", 1)][0], best[("local", os.cpu_count())][0]
        rows = [("single process, 1 thread", t1, None, None, ""),
                (f"single process, {os.cpu_count()} threads", tn, None, None, "")]
        stats = {}
        for n in args.workers:
            s1, r1, d1, _, busy1 = first[n]
            s2, r2, d2, dur, busy2 = best[n]
            stats[n] = r2.stats
            rows.append((f"{n} worker process(es), 1st frame", s1, r1.stats.get("light_pass_s"), d1,
                         f"cluster start {clients[n].start_s:.1f} s; workers busy {100 * busy1:.0f} %"))
            rows.append((f"{n} worker process(es), next frames", s2, r2.stats.get("light_pass_s"), d2,
                         f"workers busy {100 * busy2:.0f} %; on a worker: light batch "
                         f"{np.mean(dur['light']):.3f} s, tile {np.mean(dur['tile']):.3f} s"))
    print(f"best of {args.repeat}; load average before each repeat: {', '.join(f'{x:.1f}' for x in loads)}\n")

    print("| run | frame s | light pass s | speed-up vs 1 thread | vs all threads | max abs diff | note |")
    print("|---|---|---|---|---|---|---|")
    for name, s, lp, diff, note in rows:
        lp_s = "" if lp is None else f"{lp:.2f}"
        d = "" if diff is None else f"{diff:g}"
        print(f"| {name} | {s:.2f} | {lp_s} | {t1 / s:.2f} | {tn / s:.2f} | {d} | {note} |")
    return report_sizes(args, scene, settings, t1, stats)


def report_sizes(args, scene, settings, t1, stats) -> int:
    """The bytes table, the per-task times and the 64-machine model (``t1``: the measured 1-thread
    frame, or None: the sum of the per-task times measured here)."""
    w = wire_sizes(scene, settings, args.spectral)
    if t1 is None:
        t1 = w["prepare_s"] + sum(w["batch_s"]) + w["rounds"] * sum(w["tile_s"])
        print(f"(--sizes-only: 1-thread frame taken as the sum of the per-task times here, {t1:.2f} s)")
    sz = w["sizes"]
    n_units = w["rounds"] * w["n_tiles"]
    print(f"\nbytes on the wire (pickled), {w['n_batches']} light tasks, {n_units} eye tasks "
          f"({w['rounds']} rounds x {w['n_tiles']} tiles)\n")
    print("| what | when | bytes |")
    print("|---|---|---|")
    print(f"| job: scene + settings (+ digest, token) | once, broadcast to every worker | {_mb(sz['job'])} |")
    print(f"| light-pass maps (rows that hold flux) | once, broadcast to every worker | {_mb(sz['light maps'])} "
          f"(dense: {_mb(sz['light maps, dense'])}) |")
    print(f"| a light task's arguments | per light task | {_mb(sz['light task args'])} |")
    print(f"| a tile task's arguments | per eye task | {_mb(sz['tile task args'])} |")
    bb, tb = np.array(w["batch_bytes"]), np.array(w["tile_bytes"])
    print(f"| a light batch's deposits | per light task, to the client | mean {_mb(bb.mean())}, max {_mb(bb.max())}, "
          f"total {_mb(bb.sum())} |")
    for label, key in (("RGB only (no spectral EXR)", "tile_bytes_rgb"), ("with a spectral EXR", "tile_bytes_spectral")):
        tb = np.array(w[key])
        print(f"| a tile's result, {label} | per eye task, to the client | mean {_mb(tb.mean())}, max {_mb(tb.max())}, "
              f"total {_mb(tb.mean() * n_units)} |")
    tb = np.array(w["tile_bytes"])
    for n, st in stats.items():
        print(f"| (measured, {n} worker(s)) | stats of a next frame | job {_mb(st['sent_job_bytes'])}, light maps "
              f"{_mb(st.get('sent_light_bytes', 0))}, deposits {_mb(st.get('received_light_bytes', 0))}, tiles "
              f"{_mb(st['received_tile_bytes'])} (array bytes) |")

    print(f"\nper task, one thread here: light batch {np.mean(w['batch_s']):.3f} s (max {max(w['batch_s']):.3f}), "
          f"tile unit {np.mean(w['tile_s']):.3f} s (max {max(w['tile_s']):.3f}); client: replay "
          f"{np.mean(w['replay_s']) * 1e3:.1f} ms per batch, film add {np.mean(w['add_s']) * 1e3:.1f} ms per tile; "
          f"prepare {w['prepare_s']:.2f} s")

    # the client's link: a machine's cores return tile results at bytes / unit time each
    print(f"(the model below uses the tiles {'with' if args.spectral else 'without'} their spectral sums)")
    per_machine = args.cores * float(np.mean(w["tile_bytes"])) / float(np.mean(w["tile_s"])) / 1e6
    print(f"\none machine of {args.cores} cores returns {per_machine:.0f} MB/s of tile results (at "
          f"{settings.round_samples} samples per round): a {args.bandwidth:g} MB/s client link saturates at "
          f"{args.bandwidth / per_machine:.1f} machines; the bytes per tile do not depend on the samples per "
          f"round, the time does, so {args.machines} machines need about "
          f"{settings.round_samples * args.machines * per_machine / args.bandwidth:.0f} samples per round")

    parts, total, one = model(w, args.machines, args.cores, args.bandwidth, t1)
    print(f"\nmodel: {args.machines} machines x {args.cores} cores, {args.bandwidth:g} MB/s links\n")
    print("| part | s |")
    print("|---|---|")
    for k, v in parts.items():
        print(f"| {k} | {v:.3f} |")
    print(f"| **frame (overlapping parts as max)** | **{total:.2f}** |")
    print(f"| one machine of {args.cores} cores (1-thread time / {args.cores}) | {one:.2f} |")
    print(f"| speed-up over one machine | {one / total:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
