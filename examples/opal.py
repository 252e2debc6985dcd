"""A black opal on dark velvet, built with bpy and rendered headless through the OPAL_DIFFRACTION engine.

    .venv/bin/python examples/opal.py [--resolution 512 512] [--spp 16] [--out docs] [--no-moved]

Adds an opal with ``bpy.ops.mesh.primitive_opal_add`` (an oval cabochon with the "Black opal"
preset: a near-black body under Voronoi domains of a hexagonal lattice, periods from silica
sphere diameters of 200-330 nm), lays it on a dark cloth under a small light and a dim daylight
sky (an Environment Texture; examples/environments.py), and renders it
with ``bpy.ops.render.render(write_still=True)`` as F12 would, to ``docs/opal.png``; then moves
the light and renders ``docs/opal_light_moved.png``: other domains light up in other colours
(the play of colour). Prints the render times and the time the rendered viewport's first (1/8
resolution) image takes; ``--blend out/opal.blend`` also saves the scene, which renders the same
with Blender once the extension is installed.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

#: The sky's strength (a multiplier of examples/environments.py's sky): a dim fill beside the lamp.
SKY_STRENGTH = 0.01

#: Where the light sits for the two images (metres; the opal is 2 m long, centred at the origin).
LIGHT_FIRST = (-3.0, -9.0, 12.0)
LIGHT_MOVED = (7.0, 1.0, 12.0)
CAMERA = (0.0, -4.6, 4.9)
TARGET = (0.0, 0.05, 0.12)


def _material(bpy, name, color):
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True  # always on (and deprecated) from Blender 5.0
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    bsdf = nt.nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (*color, 1.0)
    nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat


def build_scene(width: int = 512, height: int = 512, spp: int = 16, seed: int = 7):
    """Build the opal scene in the current (emptied) Blender file; return (scene, opal, light)."""
    import bpy
    from mathutils import Vector

    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "OPAL_DIFFRACTION"
    sc.render.resolution_x, sc.render.resolution_y = width, height
    sc.render.resolution_percentage = 100
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.exposure = -1.0
    sc.opal.samples = spp
    sc.opal.round_samples = spp
    sc.opal.wavelength_step = 10.0
    sc.opal.seed = 1
    # a dark room with a window: a dim daylight sky (examples/environments.py) beside the lamp
    from opal_diffraction._scripts import load_example

    environments = load_example("environments")
    sc.world = environments.blender_world(bpy, environments.sky(256, 128), SKY_STRENGTH)

    # the cloth: a dark blue-black velvet
    bpy.ops.mesh.primitive_plane_add(size=40.0)
    bpy.context.active_object.data.materials.append(_material(bpy, "velvet", (0.004, 0.004, 0.006)))

    # the opal
    bpy.ops.mesh.primitive_opal_add(size_x=2.0, size_y=1.5, height=0.38, resolution=96, preset="BLACK",
                                    count=400, seed=seed, low=200.0, high=330.0, show_preview=False)
    opal = bpy.context.active_object
    opal.rotation_euler = (0.0, 0.0, math.radians(8.0))

    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens = 100.0
    cam = bpy.data.objects.new("camera", cam_data)
    sc.collection.objects.link(cam)
    cam.location = CAMERA
    cam.rotation_euler = (Vector(TARGET) - Vector(CAMERA)).to_track_quat("-Z", "Y").to_euler()
    sc.camera = cam

    light_data = bpy.data.lights.new("lamp", "POINT")
    light_data.energy = 60000.0
    light_data.shadow_soft_size = 0.0
    light = bpy.data.objects.new("lamp", light_data)
    sc.collection.objects.link(light)
    light.location = LIGHT_FIRST
    return sc, opal, light


def render(path: str) -> float:
    import bpy

    sc = bpy.context.scene
    sc.render.image_settings.file_format = "PNG"
    sc.render.filepath = os.path.abspath(path)
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    return time.perf_counter() - t0


def viewport_first_image(width: int, height: int) -> float:
    """Seconds until the rendered viewport's first image (1/8 resolution, 1 sample) is ready,
    from the exported scene (the view matrices of the scene camera stand in for a 3D view)."""
    import bpy
    import numpy as np

    from opal_diffraction.blender.settings import render_settings
    from opal_diffraction.blender.export import export_scene
    from opal_diffraction.blender.viewport import ProgressiveRenderer, preview_levels, viewport_camera
    from opal_diffraction.core.prepare import prepare

    sc = bpy.context.scene
    dg = bpy.context.evaluated_depsgraph_get()
    t0 = time.perf_counter()
    exported = export_scene(dg, width=width, height=height)
    view = np.array(sc.camera.matrix_world.inverted())
    window = np.array(sc.camera.calc_matrix_camera(dg, x=width, y=height))
    scene = exported.scene
    scene.camera = viewport_camera(view, window, True, width, height)
    r = ProgressiveRenderer()
    r.start(prepare(scene, render_settings(sc.opal, sc)), preview_levels(16, 8)[:1])
    r.wait(120.0)
    return time.perf_counter() - t0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, nargs=2, default=(512, 512))
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--seed", type=int, default=7, help="domain layout seed")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs"))
    ap.add_argument("--blend", default="", help="also save the scene as this .blend file")
    ap.add_argument("--no-moved", action="store_true", help="skip the second image (light moved)")
    args = ap.parse_args(argv)

    import bpy

    import opal_diffraction
    from opal_diffraction.blender.engine import last_render

    opal_diffraction.register()
    try:
        os.makedirs(args.out, exist_ok=True)
        sc, opal, light = build_scene(*args.resolution, spp=args.spp, seed=args.seed)
        if args.blend:
            bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(args.blend))
        first = os.path.join(args.out, "opal.png")
        t = render(first)
        if last_render.get("status") != "FINISHED":
            print(f"render failed: {last_render.get('message')}", file=sys.stderr)
            return 1
        s = last_render["stats"]
        print(f"{first}: {args.resolution[0]}x{args.resolution[1]}, {args.spp} spp, {t:.1f} s "
              f"(export {s.get('export_export_s', 0):.2f} s, prepare {s.get('prepare_s', 0):.2f} s, "
              f"{s.get('triangles', 0)} triangles, {s.get('rays', 0) / 1e6:.1f} M rays)")
        if not args.no_moved:
            light.location = LIGHT_MOVED
            moved = os.path.join(args.out, "opal_light_moved.png")
            t = render(moved)
            print(f"{moved}: {t:.1f} s")
        fv = viewport_first_image(*args.resolution)
        print(f"viewport first image ({args.resolution[0] // 8}x{args.resolution[1] // 8}, 1 spp): {fv:.2f} s")
    finally:
        opal_diffraction.unregister()
    return 0


if __name__ == "__main__":
    sys.exit(main())
