"""What keeping the camera splat's light-path vertices costs the light pass, what they weigh, and
what splatting them into a moved camera costs against running the light pass again, on the prism
example (core/integrators/light/splat_vertices.py; the engine's Persistent Data).

    .venv/bin/python benchmarks/bench_splat_vertices.py [--size 320 200] [--light-paths 1000000] [--threads 2] [--repeat 3]

examples/prism.py's scene without Blender, its settings as examples/render_example.py's (one
sampled wavelength per path at the dispersive prism). Interleaved, ``--repeat`` times: the light
pass without keeping, with keeping, and the re-splat of the kept vertices into the camera moved
0.3 m sideways; wall and CPU seconds (the process's, all threads) of each. Checks that the
re-splat is the film a light pass run for the moved camera makes, bit for bit. Timings only.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np

from opal_diffraction._scripts import load_example


def _timed(fn):
    w0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w0, time.process_time() - c0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, nargs=2, default=(320, 200))
    ap.add_argument("--light-paths", type=int, default=1_000_000)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)

    from opal_diffraction.core.integrators.light.light_pass import run_light_pass
    from opal_diffraction.core.integrators.light.splat_vertices import resplat
    from opal_diffraction.core.render.frame import compile_stage
    from opal_diffraction.core.render.plan import plan_render
    from opal_diffraction.core.render.prepare import prepare
    from opal_diffraction.core.scene.settings import RenderSettings

    compile_stage("auto")
    scene = load_example("prism").build_scene(*args.size)
    settings = RenderSettings(light_paths=args.light_paths, threads=args.threads, dispersion_sampling="SAMPLE")
    p = prepare(scene, settings)
    plan = plan_render(p)
    cam = scene.camera
    m = np.array(cam.matrix, np.float64)
    m[:3, 3] += m[:3, 0] * 0.3  # 0.3 m along the camera's x axis
    p2 = p.with_view(replace(cam, matrix=m))
    print(f"prism {args.size[0]}x{args.size[1]}, {args.light_paths} light paths, {args.threads} threads, "
          f"{p.grid.n} wavelengths, splat {plan.camera_splat}, splat bounce {plan.splat_bounce}")
    print("| run | light pass wall s | CPU s | keeping: wall s | CPU s | vertices | MB | bytes / vertex "
          "| re-splat wall s | CPU s | light pass for the moved camera: wall s | CPU s | re-splat = fresh |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for k in range(args.repeat):
        _, w0, c0 = _timed(lambda: run_light_pass(p, plan=plan))
        kept, w1, c1 = _timed(lambda: run_light_pass(p, plan=plan, keep_vertices=1 << 40))
        again, w2, c2 = _timed(lambda: resplat(p2, kept))
        fresh, w3, c3 = _timed(lambda: run_light_pass(p2, plan=plan_render(p2)))
        v = kept.vertices
        same = bool(np.array_equal(again.splat.image, fresh.splat.image))
        print(f"| {k + 1} | {w0:.2f} | {c0:.2f} | {w1:.2f} | {c1:.2f} | {v.vertices / 1e6:.3f} M | "
              f"{v.nbytes / 2**20:.1f} | {v.nbytes / max(v.vertices, 1):.0f} | {w2:.2f} | {c2:.2f} | {w3:.2f} | {c3:.2f} "
              f"| {same} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
