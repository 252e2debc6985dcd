"""Russian roulette of mono (dispersed) rays (issue 24): before, mono rays went on to the bounce
limits whatever their throughput; now they are rouletted as white rays are, judged by their
white parent's throughput times what they lost since (core/integrators/eye/continuation.py,
core/transport/wavelengths.py ``child_split``). Eye-pass CPU seconds (one thread, the light pass
run once and reused), rays per sample, RMSE against a reference of many samples (rendered with
the new rule; both rules are unbiased) and efficiency 1 / (MSE x CPU s), interleaved over seeds.
The old rule is patched in here (an experiment, not a setting). Results: docs/benchmarks.md
("Issue 24: Russian roulette of mono rays").

    python benchmarks/bench_mono_roulette.py [SCENE W H SPP REFERENCE_SPP SEEDS]
        (default: prism 320 200 16 512 3)
"""
import sys
import time

import numpy as np

from opal_diffraction._scripts import load_example
from opal_diffraction.core.integrators.eye import eye_pass
from opal_diffraction.core.integrators.light.light_pass import run_light_pass
from opal_diffraction.core.render.frame import render, render_prepared
from opal_diffraction.core.render.plan import plan_render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.scene.validation import validate

NEW = eye_pass.russian_roulette


def old_rule(c, rays, rng):
    """The rule before: mono rays were not rouletted (bounce limits only)."""
    if rays.lam is not None:
        return (rays.depth < c.limits[0]) & ~rays.state.final
    return NEW(c, rays, rng)


def sqrt_rule(c, rays, rng):
    """Cycles' milder survival probability, sqrt of the throughput (kernel/integrator/path_state.h
    ``path_state_continuation_probability``), for mono rays only."""
    if rays.lam is None or rays.w is None:
        return NEW(c, rays, rng)
    split = rays.state.split
    x = np.maximum(rays.w / split, np.float32(1e-30))  # the throughput the rule judges by
    rays.state.split = split * np.sqrt(x)  # so that w / split = sqrt(throughput)
    try:
        return NEW(c, rays, rng)
    finally:
        rays.state.split = split


def go(scene, spp, seed, rule):
    eye_pass.russian_roulette = rule
    try:
        p = prepare(scene, RenderSettings(samples=spp, threads=1, seed=seed))
        plan = plan_render(p)
        light = run_light_pass(p, plan=plan) if plan.light_pass else None
        c0 = time.process_time()
        r = render_prepared(p, light=light)
        return r.rgb.astype(np.float64), time.process_time() - c0, r.stats["rays"] - (
            0 if light is None else light.stats.get("light_rays", 0))
    finally:
        eye_pass.russian_roulette = NEW


def main():
    args = sys.argv[1:] or ["prism", "320", "200", "16", "512", "3"]
    name, (w, h, spp, ref_spp, seeds) = args[0], map(int, args[1:6])
    render(validate(load_example("prism").build_scene(32, 20)).scene, RenderSettings(samples=1, threads=1))
    scene = validate(load_example(name).build_scene(w, h)).scene
    ref, t_ref, _ = go(scene, ref_spp, 99, NEW)
    print(f"{name} {w}x{h}: reference {ref_spp} spp (new rule) {t_ref:.1f} CPU s, mean {ref.mean():.4f}", flush=True)
    rules = [("before", old_rule), ("after", NEW), ("after, sqrt", sqrt_rule)]
    res = {label: [] for label, _ in rules}
    for seed in range(seeds):
        for label, rule in (rules if seed % 2 == 0 else rules[::-1]):
            img, t, rays = go(scene, spp, seed + 1, rule)
            res[label].append((float(np.mean((img - ref) ** 2)), t, rays, img.mean()))
    print(f"| rule | {spp} spp: eye CPU s | rays / sample | image mean | RMSE | efficiency 1/(MSE s) |")
    print("|---|---:|---:|---:|---:|---:|")
    for label, rows in res.items():
        mse, t, rays, mean = (np.mean([r[i] for r in rows]) for i in range(4))
        print(f"| {label} | {t:.2f} | {rays / (w * h * spp):.2f} | {mean:.4f} | {mse ** 0.5:.4f} | {1 / (mse * t):.1f} |")


if __name__ == "__main__":
    main()
