"""Export speed: depsgraph -> core Scene for scenes of about a million triangles.

    .venv/bin/python benchmarks/bench_export.py [--repeat 3]

Three scenes: one 1M-triangle grid, 1000 collection instances of a 1280-triangle icosphere, and
a 1M-triangle mesh made by a Subdivision Surface modifier. For each, the time of
``export_scene`` on the evaluated depsgraph (best of --repeat; the depsgraph evaluation itself,
modifiers included, is timed apart), and the time the engine reports for its export inside a
real render (the render depsgraph, a 16x16 image at 1 sample). A benchmark, not a test: it
prints numbers and never fails on a timing.
"""

from __future__ import annotations

import argparse
import sys
import time


def _reset():
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "OPAL_DIFFRACTION"
    sc.render.resolution_x = sc.render.resolution_y = 16
    sc.opal.samples = 1
    sc.opal.wavelength_step = 20.0
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    cam.location = (0, -30, 20)
    cam.rotation_euler = (1.0, 0, 0)
    sc.collection.objects.link(cam)
    sc.camera = cam
    light = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    sc.collection.objects.link(light)
    return sc


def grid_scene():
    import bpy

    _reset()
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=708, y_subdivisions=708, size=20)


def instances_scene():
    import bpy

    sc = _reset()
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=4, radius=0.4)  # 1280 triangles
    ico = bpy.context.active_object
    src = bpy.data.collections.new("source")
    sc.collection.objects.unlink(ico)
    src.objects.link(ico)
    for i in range(1000):
        e = bpy.data.objects.new(f"inst{i}", None)
        e.instance_type = "COLLECTION"
        e.instance_collection = src
        e.location = (i % 32 - 16, (i // 32) % 32 - 16, i // 1024)
        sc.collection.objects.link(e)


def modifier_scene():
    import bpy

    _reset()
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=177, y_subdivisions=177, size=20)  # 31k quads
    sub = bpy.context.active_object.modifiers.new("subsurf", "SUBSURF")
    sub.levels = sub.render_levels = 2  # x16 quads: 1M triangles
    sub.subdivision_type = "SIMPLE"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)

    import bpy

    import opal_diffraction
    from opal_diffraction.blender import engine
    from opal_diffraction.blender.export import export_scene

    opal_diffraction.register()
    print(f"{'scene':<28}{'triangles':>11}{'depsgraph s':>13}{'export s':>10}{'Mtri/s':>8}{'in render s':>13}")
    for name, build in (("1M-triangle grid", grid_scene), ("1000 instances x 1280 tris", instances_scene),
                        ("subdivision modifier", modifier_scene)):
        build()
        t0 = time.perf_counter()
        dg = bpy.context.evaluated_depsgraph_get()
        dg.update()
        t_dg = time.perf_counter() - t0
        best, n = float("inf"), 0
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            ex = export_scene(dg)
            best = min(best, time.perf_counter() - t0)
            n = len(ex.scene.triangles)
        bpy.ops.render.render()
        in_render = engine.last_render.get("export", {}).get("export_s", float("nan"))
        print(f"{name:<28}{n:>11,}{t_dg:>13.2f}{best:>10.2f}{n / best / 1e6:>8.2f}{in_render:>13.2f}")
    opal_diffraction.unregister()
    return 0


if __name__ == "__main__":
    sys.exit(main())
