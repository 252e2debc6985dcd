"""Benchmark (not a test): time to a fixed error for the prism, the gem and the opal examples.

The [caustics] issue's (issue 14) "table of time to a fixed error for the prism, the gem and the
opal examples, before and after". Each example's scene is built as the example builds it
(examples/prism.py and examples/gem.py with the core Scene; examples/opal.py with bpy, exported
from the depsgraph as F12 would, rendered by the core with the Blender scene's settings) at a
reduced size with the same camera (160 px wide: prism 160 x 100, gem 160 x 120, opal 160 x 160),
rendered at increasing samples per pixel (light paths automatic, 2 threads), and compared with
a converged reference of the same scene.

**Error** (tools/cycles_parity.py ``filtered_rel_rmse``): both images box-filtered over 8 x 8
pixel blocks, the RMS over blocks and channels of the difference over the reference's mean
(rows past the last whole block are dropped: the prism's 100 rows give 96). Two columns: the
linear image as rendered, and the display-referred one (clipped to [0, 1], what the PNG shows;
benchmarks/bench_opal_example.py explains why the opal's dome highlight makes the linear error
measure only how many samples hit the highlight).

**Reference**: the mean of two renders at ``--ref-spp``/2 with seeds 101 and 102, cached in
out/bench_examples/ref_<example>_<W>x<H>_<spp>.npz together with the commit that rendered it.
Once made it is reused whatever the code version (a converged image is the same image for any
correct code: use one reference, made by the "before" code, for both columns; ``--ref-dir``
points at another checkout's cache, ``--new-reference`` remakes it). Its own noise s_ref (the
RMS of the box-filtered half difference over the mean) is printed; the error of an image is
reported raw and with the reference's noise removed in quadrature, sqrt(E^2 - s_ref^2).

**Time to error**: for each target (0.05, 0.02 by default) the wall and CPU seconds at which the
noise-corrected error reaches it, interpolated in log-log between the two renders that bracket
it (Monte Carlo error goes as t^-1/2), or extrapolated from the last render along t^-1/2 (marked
``~``). CPU seconds (``time.process_time``, all threads) are less disturbed by other work on a
shared machine than wall seconds.

    .venv/bin/python benchmarks/bench_examples_error.py [--examples prism gem opal] [--spp 1 2 4 8 16 32]
        [--ref-spp 512] [--json out/bench_examples/before.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time

import numpy as np

from opal_diffraction._scripts import REPO_ROOT, load_example, load_script

OUT = os.path.join(REPO_ROOT, "out", "bench_examples")
REF_SEEDS = (101, 102)
SEED = 3
#: Example -> (width, height) at 160 px wide (the examples' aspect ratios: 640x400, 480x360, 512x512).
SIZES = {"prism": (160, 100), "gem": (160, 120), "opal": (160, 160)}


def commit_of_tree() -> str:
    try:
        out = subprocess.run(["git", "-C", REPO_ROOT, "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", REPO_ROOT, "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True).stdout.strip()
        return out + ("+dirty" if dirty else "")
    except Exception:  # noqa: BLE001 - not a git checkout
        return "unknown"


def build(name: str):
    """(scene, settings) of the example ``name`` at its SIZES entry; settings are the example's."""
    from opal_diffraction.core.scene.settings import RenderSettings

    w, h = SIZES[name]
    if name == "prism":
        return load_example("prism").build_scene(w, h), RenderSettings()
    if name == "gem":
        return load_example("gem").build_scene(w, h), RenderSettings()
    if name == "opal":
        import bpy

        import opal_diffraction
        from opal_diffraction.blender.export import export_scene
        from opal_diffraction.blender.settings import render_settings

        opal_diffraction.register()
        try:
            sc, _opal, _light = load_example("opal").build_scene(w, h, spp=4)
            dg = bpy.context.evaluated_depsgraph_get()
            scene = export_scene(dg, width=w, height=h).scene
            return scene, render_settings(sc.opal, sc)
        finally:
            opal_diffraction.unregister()
    raise ValueError(f"unknown example {name!r}")


def render_rgb(scene, base, spp: int, seed: int, **overrides):
    """(rgb (H, W, 3), wall s, cpu s, stats) of one render with ``base``'s settings at ``spp``."""
    from dataclasses import replace

    from opal_diffraction.core.render.frame import render

    settings = replace(base, samples=int(spp), seed=int(seed), threads=2, light_paths=None, adaptive_threshold=0.0,
                       time_limit=0.0, spectral_exr="", **overrides)
    c0, t0 = time.process_time(), time.perf_counter()
    r = render(scene, settings)
    return np.asarray(r.rgb, np.float64), time.perf_counter() - t0, time.process_time() - c0, r.stats


def crop(img: np.ndarray, block: int = 8) -> np.ndarray:
    h, w = img.shape[:2]
    return img[: h - h % block, : w - w % block]


def reference(name: str, scene, base, ref_spp: int, ref_dir: str, new: bool) -> dict:
    w, h = SIZES[name]
    path = os.path.join(ref_dir, f"ref_{name}_{w}x{h}_{ref_spp}.npz")
    if os.path.exists(path) and not new:
        z = np.load(path)
        return {"a": z["a"], "b": z["b"], "commit": str(z["commit"]), "seconds": float(z["seconds"]), "path": path}
    half = max(1, ref_spp // 2)
    a, ta, _, _ = render_rgb(scene, base, half, REF_SEEDS[0])
    b, tb, _, _ = render_rgb(scene, base, half, REF_SEEDS[1])
    os.makedirs(ref_dir, exist_ok=True)
    commit = commit_of_tree()
    np.savez_compressed(path, a=a.astype(np.float32), b=b.astype(np.float32), commit=commit, seconds=ta + tb)
    try:  # the reference as a picture to look at (clipped linear -> sRGB-ish gamma)
        from PIL import Image

        Image.fromarray((np.clip((a + b) / 2, 0, 1) ** (1 / 2.2) * 255 + 0.5).astype(np.uint8)).save(path[:-4] + ".png")
    except ImportError:
        pass
    return {"a": a, "b": b, "commit": commit, "seconds": ta + tb, "path": path}


def errors(img, a, b, cp) -> dict:
    """Raw and reference-noise-corrected filtered rel. RMSE, linear and clipped to [0, 1]."""
    out = {}
    for key, f in (("linear", lambda x: x), ("display", lambda x: np.clip(x, 0.0, 1.0))):
        fa, fb, fi = crop(f(a)), crop(f(b)), crop(f(img))
        ref = (fa + fb) / 2
        e = cp.filtered_rel_rmse(fi, ref)
        d = cp.box_filter((fa - fb) / 2)
        s_ref = float(np.sqrt(np.mean(d * d)) / cp.box_filter(ref).mean())
        out[key] = {"raw": e, "ref_noise": s_ref, "corrected": math.sqrt(max(e * e - s_ref * s_ref, 0.0))}
    return out


def time_to(rows: list[dict], target: float, key: str, clock: str):
    """(seconds, extrapolated?) at which rows' corrected ``key`` error reaches ``target``."""
    pts = [(r[clock], r["error"][key]["corrected"]) for r in rows]
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if e0 > target >= e1 and e1 > 0:
            s = math.log(e1 / e0) / math.log(t1 / t0) if t1 != t0 else -0.5
            return t0 * (target / e0) ** (1.0 / s), False
    if pts and pts[0][1] <= target:
        return pts[0][0], False
    t, e = pts[-1]
    return t * (e / target) ** 2, True


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", nargs="+", default=["prism", "gem", "opal"], choices=sorted(SIZES))
    ap.add_argument("--spp", type=int, nargs="+", default=[1, 2, 4, 8, 16, 32])
    ap.add_argument("--ref-spp", type=int, default=512)
    ap.add_argument("--targets", type=float, nargs="+", default=[0.05, 0.02])
    ap.add_argument("--ref-dir", default=OUT, help="where the references are cached (default out/bench_examples)")
    ap.add_argument("--new-reference", action="store_true", help="render the references again")
    ap.add_argument("--json", default="", help="also write the results to this JSON file")
    ap.add_argument("--reference-only", action="store_true", help="only make (or check) the references")
    args = ap.parse_args(argv)

    cp = load_script("tools/cycles_parity.py")
    commit = commit_of_tree()
    results = {"commit": commit, "spp": args.spp, "ref_spp": args.ref_spp, "examples": {}}
    print(f"code: {commit} ({REPO_ROOT})")
    for name in args.examples:
        scene, base = build(name)
        ref = reference(name, scene, base, args.ref_spp, args.ref_dir, args.new_reference)
        w, h = SIZES[name]
        print(f"\n{name} {w}x{h}: reference {args.ref_spp} spp by {ref['commit']} ({ref['seconds']:.0f} s, "
              f"{ref['path']})", flush=True)
        if args.reference_only:
            continue
        rows = []
        print("| spp | wall s | cpu s | err linear (raw) | err display (raw) |\n|---|---|---|---|---|")
        for spp in args.spp:
            img, wall, cpu, stats = render_rgb(scene, base, spp, SEED)
            err = errors(img, ref["a"], ref["b"], cp)
            rows.append({"spp": spp, "wall": wall, "cpu": cpu, "error": err, "rays": int(stats.get("rays", 0))})
            print(f"| {spp} | {wall:.2f} | {cpu:.2f} | {err['linear']['corrected']:.4f} ({err['linear']['raw']:.4f}) "
                  f"| {err['display']['corrected']:.4f} ({err['display']['raw']:.4f}) |", flush=True)
        noise = rows[0]["error"]
        print(f"reference noise: linear {noise['linear']['ref_noise']:.4f}, display {noise['display']['ref_noise']:.4f}")
        tt = {}
        for key in ("linear", "display"):
            for target in args.targets:
                for clock in ("wall", "cpu"):
                    t, extra = time_to(rows, target, key, clock)
                    tt[f"{key}@{target:g}:{clock}"] = {"seconds": t, "extrapolated": extra}
                print(f"time to {key} error {target:g}: {'~' if tt[f'{key}@{target:g}:wall']['extrapolated'] else ''}"
                      f"{tt[f'{key}@{target:g}:wall']['seconds']:.1f} s wall, "
                      f"{tt[f'{key}@{target:g}:cpu']['seconds']:.1f} s cpu")
        results["examples"][name] = {"size": [w, h], "reference": {"commit": ref["commit"], "path": ref["path"]},
                                     "rows": rows, "time_to": tt}
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
