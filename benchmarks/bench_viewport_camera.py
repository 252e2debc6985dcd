"""Rendered viewport: seconds from a camera move to the first new image, on the prism example.

    .venv/bin/python benchmarks/bench_viewport_camera.py [--region 640 400] [--moves 5]

Builds examples/render_example.py's scene in the bpy module, starts the engine's viewport
session (view_update) with the scene camera's matrices standing in for a 3D view, waits until
the preview is done, then moves the view ``--moves`` times (view_draw with new matrices) and
times each first new image (the 1/8-resolution, one-sample level). The same moves are timed
once more with the session's light-pass result dropped before each move, which is what every
camera move cost before the session kept it (the light pass reran with the eye pass).
Also times a world-colour edit (view_update: re-export, prepare reusing the acceleration
structure, light pass kept since the light pass never reads the world) and an update that
changes nothing the preview shows (no restart). Prints a table; the numbers go in
docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
import types

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _example(name):
    spec = importlib.util.spec_from_file_location(name, os.path.join(ROOT, "examples", f"{name}.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _context(cam, dg, w, h, dx=0.0):
    from mathutils import Matrix

    m = Matrix.Translation((dx, 0.0, 0.0)) @ cam.matrix_world
    rv3d = types.SimpleNamespace(view_matrix=m.inverted(), window_matrix=cam.calc_matrix_camera(dg, x=w, y=h),
                                 is_perspective=True)
    return types.SimpleNamespace(region=types.SimpleNamespace(width=w, height=h), region_data=rv3d)


def _first_image(session, gen_before: int, timeout: float = 120.0) -> float:
    t0 = time.perf_counter()
    r = session.renderer
    while time.perf_counter() - t0 < timeout:
        f = r.frame()
        if r.generation > gen_before and f is not None and f.generation == r.generation:
            return time.perf_counter() - t0
        time.sleep(0.001)
    raise TimeoutError("no image")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--region", type=int, nargs=2, default=(640, 400))
    ap.add_argument("--moves", type=int, default=5)
    args = ap.parse_args(argv)
    w, h = args.region

    import bpy

    import opal_diffraction
    from opal_diffraction.blender import viewport
    from opal_diffraction.blender.engine import OpalRenderEngine

    example = _example("render_example")
    opal_diffraction.register()
    try:
        sc = example.build_scene(w, h, spp=4)
        sc.opal.preview_samples = 4
        cam = sc.camera
        viewport.ViewportSession._draw_frame = lambda *a, **k: None  # no GPU in the bpy module

        class Engine:
            _viewport = None
            _viewport_session = OpalRenderEngine._viewport_session

            def update_stats(self, *a):
                pass

        eng = Engine()
        dg = bpy.context.evaluated_depsgraph_get()
        t0 = time.perf_counter()
        OpalRenderEngine.view_update(eng, _context(cam, dg, w, h), dg)
        session = eng._viewport
        first = _first_image(session, 0)
        session.renderer.wait(600.0)
        print(f"start: first image {first:.2f} s, preview done {time.perf_counter() - t0:.2f} s "
              f"(light pass kept: {session.light is not None})")

        rows = []
        for label, drop_light in (("camera move, light pass kept", False),
                                  ("camera move, light pass rerun (before)", True)):
            times = []
            for i in range(args.moves):
                session.renderer.wait(600.0)
                if drop_light:
                    session.light = None
                gen = session.renderer.generation
                OpalRenderEngine.view_draw(eng, _context(cam, dg, w, h, dx=0.05 * (i + 1) * (1 if drop_light else -1)), dg)
                times.append(_first_image(session, gen))
            session.renderer.wait(600.0)
            rows.append((label, times))

        # an update that changes nothing the preview shows: no restart at all
        restarts = session.restarts
        t1 = time.perf_counter()
        OpalRenderEngine.view_update(eng, _context(cam, dg, w, h, dx=-0.05 * args.moves), bpy.context.evaluated_depsgraph_get())
        idle = time.perf_counter() - t1
        print(f"view_update with nothing changed: {idle:.3f} s, restarted: {session.restarts != restarts}")

        # a world colour edit: re-export, prepare with reuse (same geometry: no BVH build), light pass kept
        sc.world.color = (0.1, 0.1, 0.12)
        sc.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.1, 0.1, 0.12, 1.0)
        sc.world.update_tag()
        gen = session.renderer.generation
        t1 = time.perf_counter()
        OpalRenderEngine.view_update(eng, _context(cam, dg, w, h, dx=-0.05 * args.moves), bpy.context.evaluated_depsgraph_get())
        _first_image(session, gen)
        world_first = time.perf_counter() - t1
        print(f"world colour edit: first new image {world_first:.2f} s (light pass kept: {session.light is not None})")
        session.free()

        print(f"\nregion {w}x{h}, prism example (render_example.py), first image = 1/8 resolution, 1 sample")
        print("| change | first new image (s), median | min | max |")
        print("|---|---|---|---|")
        for label, times in rows:
            times = sorted(times)
            print(f"| {label} | {times[len(times) // 2]:.3f} | {times[0]:.3f} | {times[-1]:.3f} |")
        print(f"| world colour edit (re-export, prepare reusing the BVH, light pass kept) | {world_first:.3f} | | |")
        print(f"| view_update with nothing changed (no restart) | {idle:.3f} | | |")
    finally:
        opal_diffraction.unregister()
    return 0


if __name__ == "__main__":
    sys.exit(main())
