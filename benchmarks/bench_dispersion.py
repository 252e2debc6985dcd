"""Benchmark (not a test): dispersion noise and SPLIT's memory on the gem example (issue 14).

**Wavelength sampling** (core/transport/wavelengths.py): the gem of examples/gem.py at 160 x 120 (the
camera of the example), SAMPLE dispersion, rendered with each combination of the settings
``dispersion_importance``, ``dispersion_white_reflection`` and ``dispersion_branches`` in turn (alternating, in one process, ``--repeats`` times; the best time is kept):

- ``uniform``: one wavelength per ray, uniform over the grid, the reflect / refract choice per
  mono ray: the code before core/transport/wavelengths.py;
- ``importance``: the wavelength drawn by the image's sensitivity;
- ``white-refl``: smooth glass reflects the white ray (the choice made once, on the white ray);
- ``both``: importance + white reflection (with K = 1);
- ``hero4``, ``hero8``, ``hero16``: both, with K = 4 (pbrt-v4's count), 8 or 16 rotated hero
  wavelengths per refracted ray, each its own mono ray of weight 1/K (``hero4``: the default settings).

Each is compared with the converged reference of benchmarks/bench_examples_error.py (the cached
``ref_gem_160x120_<spp>.npz``; its commit is printed) by the 8 x 8-box-filtered relative RMSE,
linear and display-referred (clipped to [0, 1]), with the reference's own noise removed in
quadrature; time to an error target is t (E / target)^2 (Monte Carlo error ~ t^-1/2) from the
render at the largest spp. PNGs of every variant at equal spp and of ``uniform`` against the
winner at equal time go to out/bench_dispersion/.

**SPLIT memory**: the same gem with SPLIT at ``--split-spp``, in a fresh process per setting so
the peak RSS (``ru_maxrss``) is the render's: chunks of ``wavelengths.SPLIT_CHUNK_RAYS`` mono rays
against one chunk of everything (the code before), and SAMPLE for scale.

    .venv/bin/python benchmarks/bench_dispersion.py [--spp 4 16] [--repeats 2] [--split-spp 8]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

from opal_diffraction._scripts import REPO_ROOT, load_script

OUT = os.path.join(REPO_ROOT, "out", "bench_dispersion")
VARIANTS = {  # name: RenderSettings (dispersion_importance, dispersion_white_reflection, dispersion_branches)
    "uniform": (False, False, 1),
    "importance": (True, False, 1),
    "white-refl": (False, True, 1),
    "both": (True, True, 1),
    "hero4": (True, True, 4),
    "hero8": (True, True, 8),
    "hero16": (True, True, 16),
}


def variant(settings, name: str):
    """``settings`` with the wavelength-sampling choices of VARIANTS[name]."""
    from dataclasses import replace

    importance, white, branches = VARIANTS[name]
    return replace(settings, dispersion_importance=importance, dispersion_white_reflection=white,
                   dispersion_branches=branches)


def save_png(path: str, img: np.ndarray, scale: int = 3) -> None:
    from PIL import Image

    a = (np.clip(img, 0, 1) ** (1 / 2.2) * 255 + 0.5).astype(np.uint8)
    a = a.repeat(scale, axis=0).repeat(scale, axis=1)
    Image.fromarray(a).save(path)


def split_probe(mode: str, chunk: int, spp: int) -> None:
    """One render in this (fresh) process; prints a JSON line with its time and peak RSS."""
    from dataclasses import replace

    from opal_diffraction.core.transport import wavelengths
    from opal_diffraction.core.render.frame import render

    bex = load_script("benchmarks/bench_examples_error.py")
    scene, base = bex.build("gem")
    wavelengths.SPLIT_CHUNK_RAYS = chunk
    settings = replace(base, samples=spp, seed=3, threads=2, dispersion_sampling=mode)
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0, c0 = time.perf_counter(), time.process_time()
    r = render(scene, settings)
    t, c = time.perf_counter() - t0, time.process_time() - c0
    print(json.dumps({"mode": mode, "chunk": chunk, "spp": spp, "seconds": t, "cpu_seconds": c,
                      "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                      "rss_before_mb": rss0 / 1024, "rays": int(r.stats.get("rays", 0))}))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, nargs="+", default=[4, 16])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument("--targets", type=float, nargs="+", default=[0.05, 0.02])
    ap.add_argument("--ref-spp", type=int, default=256)
    ap.add_argument("--ref-dir", default=os.path.join(REPO_ROOT, "out", "bench_examples"))
    ap.add_argument("--split-spp", type=int, default=8)
    ap.add_argument("--no-split", action="store_true", help="skip the SPLIT memory runs")
    ap.add_argument("--no-sampling", action="store_true", help="skip the wavelength-sampling runs")
    ap.add_argument("--probe", nargs=3, metavar=("MODE", "CHUNK", "SPP"), help=argparse.SUPPRESS)
    ap.add_argument("--json", default=os.path.join(OUT, "dispersion.json"))
    args = ap.parse_args(argv)
    if args.probe:
        split_probe(args.probe[0], int(args.probe[1]), int(args.probe[2]))
        return 0

    os.makedirs(OUT, exist_ok=True)
    results = {}
    bex = load_script("benchmarks/bench_examples_error.py")
    cp = load_script("tools/cycles_parity.py")
    print(f"code: {bex.commit_of_tree()}")
    if not args.no_sampling:
        scene, base = bex.build("gem")
        ref = bex.reference("gem", scene, base, args.ref_spp, args.ref_dir, False)
        print(f"gem 160x120, reference {args.ref_spp} spp by {ref['commit']} ({ref['path']})")
        rows = {v: {} for v in args.variants}
        for spp in args.spp:
            for rep in range(args.repeats):
                for v in args.variants:  # alternating: the machine's load hits every variant alike
                    img, wall, cpu, _ = bex.render_rgb(scene, variant(base, v), spp, 3)
                    row = rows[v].setdefault(spp, {"wall": np.inf, "cpu": np.inf})
                    row["wall"], row["cpu"] = min(row["wall"], wall), min(row["cpu"], cpu)
                    row["error"] = bex.errors(img, ref["a"], ref["b"], cp)
                    if rep == 0:
                        save_png(os.path.join(OUT, f"gem_{v}_{spp}spp.png"), img)
                        row["image"] = img
        print("| variant | spp | wall s | cpu s | err display | err linear | cpu s to display 0.05 | to 0.02 |")
        print("|---|---|---|---|---|---|---|---|")
        for v in args.variants:
            for spp, row in sorted(rows[v].items()):
                ed, el = row["error"]["display"]["corrected"], row["error"]["linear"]["corrected"]
                tt = [row["cpu"] * (ed / t) ** 2 for t in args.targets]
                row["cpu_to"] = dict(zip(map(str, args.targets), tt))
                print(f"| {v} | {spp} | {row['wall']:.2f} | {row['cpu']:.2f} | {ed:.4f} | {el:.4f} | "
                      + " | ".join(f"{t:.1f}" for t in tt) + " |", flush=True)
        top = max(args.spp)
        best = min(args.variants, key=lambda v: rows[v][top]["cpu_to"][str(args.targets[0])])
        print(f"fastest to display error {args.targets[0]}: {best}")
        # equal time: the winner at the spp that takes uniform's time at the top spp
        if "uniform" in rows and best != "uniform":
            t_u = rows["uniform"][top]["cpu"]
            spp_b = max(1, int(round(top * t_u / rows[best][top]["cpu"])))
            img, wall, cpu, _ = bex.render_rgb(scene, variant(base, best), spp_b, 3)
            e = bex.errors(img, ref["a"], ref["b"], cp)["display"]["corrected"]
            side = np.concatenate([rows["uniform"][top]["image"], img], axis=1)
            save_png(os.path.join(OUT, f"gem_equal_time_uniform{top}_vs_{best}{spp_b}.png"), side)
            print(f"equal time: uniform {top} spp {t_u:.1f} cpu s, display error "
                  f"{rows['uniform'][top]['error']['display']['corrected']:.4f}; {best} {spp_b} spp {cpu:.1f} cpu s, "
                  f"display error {e:.4f}")
            results["equal_time"] = {"uniform": [top, t_u], best: [spp_b, cpu, e]}
        for v in rows:
            for row in rows[v].values():
                row.pop("image", None)
        results["sampling"] = {v: {str(k): r for k, r in rows[v].items()} for v in rows}

    if not args.no_split:
        print(f"\nSPLIT memory and time (gem 160x120, {args.split_spp} spp, fresh process each):")
        print("| mode | chunk (mono rays) | wall s | cpu s | peak RSS MB |\n|---|---|---|---|---|")
        from opal_diffraction.core.transport import wavelengths

        probes = [("SPLIT", 1 << 40), ("SPLIT", wavelengths.SPLIT_CHUNK_RAYS), ("SAMPLE", wavelengths.SPLIT_CHUNK_RAYS)]
        results["split"] = []
        env = dict(os.environ, PYTHONPATH=REPO_ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
        for mode, chunk in probes:
            out = subprocess.run([sys.executable, os.path.abspath(__file__), "--probe", mode, str(chunk),
                                  str(args.split_spp)], capture_output=True, text=True, env=env)
            line = [ln for ln in out.stdout.splitlines() if ln.startswith("{")]
            if not line:
                print(f"probe {mode} {chunk} failed: {out.stderr[-500:]}")
                continue
            p = json.loads(line[-1])
            results["split"].append(p)
            print(f"| {mode} | {'all' if chunk >= 1 << 40 else chunk} | {p['seconds']:.1f} | {p['cpu_seconds']:.1f} | "
                  f"{p['peak_rss_mb']:.0f} |",
                  flush=True)
    with open(args.json, "w") as f:
        json.dump(results, f, indent=1, default=float)
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
