"""Time to the rendered viewport's first image on the opal example scene (not a test).

    .venv/bin/python benchmarks/bench_opal_viewport.py [--region 1280 720] [--repeat 3]

Builds examples/opal.py's scene, then drives the engine's ``view_update`` / ``view_draw`` as
Blender would for a 3D view looking through the scene camera (a stand-in context: the bpy
module has no window), and prints the seconds from ``view_update`` to the first image (1/8
resolution, 1 sample) and to the full-resolution image with the viewport samples: first "cold"
(the first render of the process: colour-science is imported then) and then "warm".
"""

from __future__ import annotations

import argparse
import sys
import time
import types

from opal_diffraction._scripts import load_example


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--region", type=int, nargs=2, default=(1280, 720))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--samples", type=int, default=4, help="viewport samples at full resolution")
    args = ap.parse_args(argv)

    import bpy

    import opal_diffraction
    from opal_diffraction.blender import viewport
    from opal_diffraction.blender.engine import OpalRenderEngine

    example = load_example("opal")  # examples/opal.py

    opal_diffraction.register()
    try:
        sc, _opal, _light = example.build_scene(*args.region, spp=4)
        sc.opal.preview_samples = args.samples
        w, h = args.region
        cam = sc.camera
        viewport.ViewportSession._draw_frame = lambda *a, **k: None  # no GPU in the bpy module

        class Engine:
            _viewport = None
            _viewport_session = OpalRenderEngine._viewport_session

            def update_stats(self, *a):
                pass

        print("colour-science already imported:", "colour" in sys.modules)
        for i in range(args.repeat):
            dg = bpy.context.evaluated_depsgraph_get()
            ctx = types.SimpleNamespace(
                region=types.SimpleNamespace(width=w, height=h),
                region_data=types.SimpleNamespace(view_matrix=cam.matrix_world.inverted(), is_perspective=True,
                                                  window_matrix=cam.calc_matrix_camera(dg, x=w, y=h)))
            eng = Engine()
            t0 = time.perf_counter()
            OpalRenderEngine.view_update(eng, ctx, dg)
            r = eng._viewport.renderer
            while r.frame() is None and r.running:
                time.sleep(0.002)
            first = time.perf_counter() - t0
            f = r.frame()
            r.wait(600.0)
            full = time.perf_counter() - t0
            label = "cold" if i == 0 else "warm"
            print(f"{label}: region {w}x{h}: first image {f.width}x{f.height} in {first:.2f} s; "
                  f"{w}x{h} at {args.samples} spp in {full:.2f} s")
            eng._viewport.free()
    finally:
        opal_diffraction.unregister()
    return 0


if __name__ == "__main__":
    sys.exit(main())
