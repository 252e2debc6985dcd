"""Eye-pass CPU seconds against the batch size (issue 24): tile side and samples per round set how
many camera rays one tile round traces at once (tiles.MAX_TILE_RAYS raised here so rounds of 32
samples fit). One thread, the light pass run once per configuration and reused, two interleaved
runs. Results: docs/benchmarks.md ("Issue 24: what the wavelength count and the batch size cost
the eye pass").

    python benchmarks/bench_batch_size.py [SCENE] [SPP] [--configs 64x16 64x32 ...]
"""
import argparse, time
from opal_diffraction._scripts import load_example
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.frame import render_prepared, render
from opal_diffraction.core.scene.validation import validate
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.integrators.light.light_pass import run_light_pass
from opal_diffraction.core.render.plan import plan_render
import opal_diffraction.core.render.tiles as tl; tl.MAX_TILE_RAYS = 1 << 19


def light_of(prepared):
    """The prepared scene's light pass (None where its plan runs none), for eye-only timings."""
    plan = plan_render(prepared)
    return run_light_pass(prepared, plan=plan) if plan.light_pass else None


ap = argparse.ArgumentParser()
ap.add_argument("scene", nargs="?", default="prism")
ap.add_argument("spp", nargs="?", type=int, default=32)
ap.add_argument("--configs", nargs="+", default=["64x16", "64x32", "128x32", "96x32"])
a = ap.parse_args()
scene_name, spp = a.scene, a.spp
render(validate(load_example("prism").build_scene(32, 20)).scene, RenderSettings(samples=1, threads=1))
sc = validate(load_example(scene_name).build_scene(640, 400)).scene
configs = [tuple(int(x) for x in c.split("x")) for c in a.configs]
res = {c: [] for c in configs}
preps = {}
for c in configs:
    preps[c] = prepare(sc, RenderSettings(samples=spp, threads=1, tile_size=c[0], round_samples=c[1]))
lights = {c: light_of(preps[c]) for c in configs}
for rep in range(2):
    for c in configs:
        c0 = time.process_time(); render_prepared(preps[c], light=lights[c]); res[c].append(time.process_time() - c0)
for c in configs:
    print(c, " ".join(f"{x:.2f}" for x in res[c]), flush=True)
