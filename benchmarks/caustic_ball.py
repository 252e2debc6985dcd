"""Benchmark (not a test): a smooth-shaded glass ball's caustic against Mitsuba 3's ptracer (issue 30).

The scene of benchmarks/caustic_sphere.py (glass IOR 1.5 radius 1 resting on a grey diffuse
floor, one point light, black world, 256 x 256, Blackman-Harris 1.5 px) with the ball as an
artist would make it in Blender: a UV sphere of 32 segments x 16 rings (960 triangles) shaded
smooth, i.e. radial vertex normals interpolated over the facets, so the shading normal departs
from the geometric one by up to about 6 degrees (the icosphere of caustic_sphere.py: about 1.3).
Mitsuba loads the same PLY with the same vertex normals (``face_normals`` off), so both
renderers see one surface.

Plane RMSE against a high-sample Mitsuba ``ptracer`` reference, ball RMSE against its ``path``
reference (also without our Caustics pass, which the path reference cannot have), for ours at
several light-path budgets and Mitsuba's ptracer at several sample counts, wall and CPU time.
Every row also gives the floor's error by region (caustic focus, shadow, lit floor) and, for
ours, each pass's mean and its speckles (pixels above 0.05) inside the shadow: the path-type
breakdown of docs/caustics.md (Direct / Indirect are the eye pass's, Caustics the light paths').

    python benchmarks/caustic_ball.py [--quick] [--without-adjoint] [--configs 250000x12,...]

Mitsuba (benchmarks/requirements.txt) may live in a venv of its own: put a folder holding only
links to its ``mitsuba`` and ``drjit`` packages on PYTHONPATH, so the project's NumPy stays the
one imported (docs/caustics.md, "issue 30"). ``MITSUBA_NO_LLVM=1`` where the installed libLLVM
aborts Dr.Jit's LLVM variants (libLLVM 15): Mitsuba then runs ``scalar_rgb``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from opal_diffraction import _scripts
from opal_diffraction.core.integrators.light.walker import LightWalker

cs = _scripts.load_script("benchmarks/caustic_sphere.py")

ROOT = cs.ROOT


def spec(smooth=True) -> cs.Spec:
    return cs.Spec(smooth=smooth, sphere_mesh="uv32")


def regions(sp: cs.Spec, ref_pt, lab):
    """Floor pixels split by what the reference shows there: 'focus' (the caustic, above 2x the
    lit floor's median), 'shadow' (below 0.5x the lit floor's median: under the ball), 'lit'."""
    floor = lab == cs.FLOOR
    lum = ref_pt @ np.array([0.2126, 0.7152, 0.0722])
    med = np.median(lum[floor])
    return {"focus": floor & (lum > 2 * med), "shadow": floor & (lum < 0.5 * med),
            "lit": floor & (lum >= 0.5 * med) & (lum <= 2 * med)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--ref-spp", type=int, default=256, help="the ptracer reference's spp per half at 4x")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--cache", default=os.path.join(ROOT, "out", "caustic_ball"))
    ap.add_argument("--flat", action="store_true", help="the same UV sphere with flat facets")
    ap.add_argument("--configs", default="", help="light paths x spp, e.g. 250000x4,1000000x8")
    ap.add_argument("--mitsuba-spp", default="4,16")
    ap.add_argument("--extra", default="{}", help="JSON of extra RenderSettings for ours")
    ap.add_argument("--without-adjoint", action="store_true",
                    help="also ours without the light paths' adjoint shading-normal factor (as before issue 30)")
    args = ap.parse_args(argv)
    os.makedirs(args.cache, exist_ok=True)
    from opal_diffraction.core.render.output import write_png

    sp = spec(smooth=not args.flat)
    t_all = time.perf_counter()

    def log(msg):
        print(f"[{time.perf_counter() - t_all:7.1f} s] {msg}", flush=True)

    lab = cs.masks(sp)
    floor, ball = lab == cs.FLOOR, lab == cs.SPHERE
    ref = cs.references(sp, args.cache, lab, False, False, log, glass=False, spp=(args.ref_spp, args.ref_spp // 2))
    noise_floor = float(np.sqrt(np.mean(ref["pt_halfdiff"][floor] ** 2)) / 2)
    noise_ball = float(np.sqrt(np.nanmean(ref["path_halfdiff"][ball] ** 2)) / 2)
    reg = regions(sp, ref["pt"], lab)
    log(f"{int(floor.sum())} floor px ({', '.join(f'{k} {int(m.sum())}' for k, m in reg.items())}), {int(ball.sum())} "
        f"ball px; reference noise floor {noise_floor:.4f}, ball {noise_ball:.4f} ({ref['variant']})")
    write_png(os.path.join(args.cache, "ref_pt.png"), ref["pt"].astype(np.float32))
    from scipy.ndimage import binary_erosion

    inner_shadow = binary_erosion(reg["shadow"], iterations=4)  # away from the shadow's edge
    rows = []

    def record(who, config, img, wall, cpu, caus=None, extra=None):
        r = {"renderer": who, "config": config, "wall_s": round(wall, 2), "cpu_s": round(cpu, 2),
             "floor_rmse": round(cs.rmse(img, ref["pt"], floor), 4), "ball_rmse": round(cs.rmse(img, ref["path"], ball), 4),
             "floor_mean_diff": round(float((img[floor] - ref["pt"][floor]).mean()), 4),
             **{f"{k}_rmse": round(cs.rmse(img, ref["pt"], m), 4) for k, m in reg.items()}}
        if caus is not None:
            r["ball_rmse_without_caustics"] = round(cs.rmse(img - caus, ref["path"], ball), 4)
            r["ball_mean_diff_without_caustics"] = round(float((img - caus - ref["path"])[ball].mean()), 4)
            r["caustics_in_shadow_mean"] = round(float(caus[reg["shadow"]].mean()), 4)
        r.update(extra or {})
        rows.append(r)
        log(json.dumps(r))
        return r

    cfgs = [tuple(int(x) for x in c.split("x")) for c in args.configs.split(",") if c] or \
        ([(250_000, 4), (1_000_000, 8)] if args.quick else [(250_000, 4), (1_000_000, 8), (4_000_000, 16)])
    extra = json.loads(args.extra)
    cs.run_ours(sp, 1000, 1, args.threads, **extra)  # compiles the kernels: not part of any timing
    for adjoint in (True, False) if args.without_adjoint else (True,):
        LightWalker.adjoint_shading = adjoint
        tag = "" if adjoint else "_noadjoint"
        for lp, spp in cfgs:
            best = None
            for _ in range(args.repeats):
                c0 = time.process_time()
                img, dt, res = cs.run_ours(sp, lp, spp, args.threads, **extra)
                cpu = time.process_time() - c0
                if best is None or dt < best[1]:
                    best = (img, dt, res, cpu)
            img, dt, res, cpu = best
            caus = res.passes["Caustics"].astype(np.float64)
            br = {}
            for name in ("Direct", "Indirect", "Caustics"):
                v = np.asarray(res.passes[name], np.float64)[inner_shadow]
                br[f"shadow_{name.lower()}_mean"] = round(float(v.mean()), 5)
                br[f"shadow_{name.lower()}_speckles"] = int((v.max(axis=1) > 0.05).sum())
            record("ours" if adjoint else "ours, no adjoint factor", f"{lp / 1e6:g} M paths, {spp} spp", img, dt, cpu,
                   caus, {"cpu_light_s": round(res.stats["cpu_light_s"], 2),
                          "cpu_eye_s": round(res.stats["cpu_eye_s"], 2), **br})
            write_png(os.path.join(args.cache, f"ours{tag}_{lp}_{spp}.png"), img.astype(np.float32))
            np.savez_compressed(os.path.join(args.cache, f"ours{tag}_{lp}_{spp}.npz"), img=img, caus=caus)
    LightWalker.adjoint_shading = True
    for spp in [int(s) for s in args.mitsuba_spp.split(",") if s]:
        best = None
        for _ in range(args.repeats):
            c0 = time.process_time()
            img, dt = cs.run_mitsuba(sp, "scalar_rgb" if not cs.mitsuba_llvm_ok() else "llvm_ad_rgb", "ptracer", spp,
                                     args.cache, seed=spp)
            cpu = time.process_time() - c0
            if best is None or dt < best[1]:
                best = (img, dt, cpu)
        img, dt, cpu = best
        record("mitsuba ptracer", f"{spp} spp at {cs.SS}x", img, dt, cpu)
        write_png(os.path.join(args.cache, f"mitsuba_pt_{spp}.png"), img.astype(np.float32))
    with open(os.path.join(args.cache, "results.json"), "w") as f:
        json.dump({"noise_floor": noise_floor, "noise_ball": noise_ball, "rows": rows}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
