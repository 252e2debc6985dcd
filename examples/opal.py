"""A real-size opal cabochon on dark velvet, built with bpy and rendered headless through the OPAL_DIFFRACTION engine.

    .venv/bin/python examples/opal.py [--preset black] [--resolution 512 512] [--spp 16] [--out docs]
    .venv/bin/python examples/opal.py --all-presets            # docs/opal_<preset>.png for every preset
    .venv/bin/python examples/opal.py --preset harlequin --no-orbit

Adds an opal with ``bpy.ops.mesh.primitive_opal_add`` (*Add > Mesh > Opal*: an 18 x 13 x 6 mm
cabochon, volume domains of the preset's FCC opal: docs/opal.md), lays it on a dark cloth under
a small lamp and a dim daylight sky (an Environment Texture; examples/environments.py), and
renders it with ``bpy.ops.render.render(write_still=True)`` as F12 would.

- The default (``--preset black``) writes ``docs/opal.png`` and, orbiting the camera 5 degrees
  down and up about the stone (the view tilts against the domains' (111) planes: the flashes
  move towards blue as the angle to the planes grows), ``docs/opal_orbit_minus5.png`` and
  ``docs/opal_orbit_plus5.png``.
- ``--preset NAME`` writes ``docs/opal_<name>.png`` (and its two orbit frames
  ``opal_<name>_orbit_minus5.png`` / ``_plus5.png`` unless ``--no-orbit``); ``--all-presets``
  writes ``docs/opal_<name>.png`` for every shipped preset (no orbit frames).

Prints the render times and the time the rendered viewport's first (1/8 resolution) image takes;
``--blend out/opal.blend`` also saves the scene, which renders the same with Blender once the
extension is installed.
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

#: The stone: 18 x 13 x 6 mm, centred at the origin on the cloth (z = 0).
SIZE = (0.018, 0.013, 0.006)
#: The camera looks at the dome's centre from 70 mm, 40 degrees above the cloth (a 100 mm lens
#: frames about 25 mm); the lamp hangs 35 cm away on the other side, 50 degrees up, so the
#: domains whose (111) planes lie near the surface send their first-order flash towards the
#: camera (and the polished dome a small highlight).
TARGET = (0.0, 0.0, 0.0025)
CAMERA_DISTANCE = 0.07
CAMERA_ELEVATION = 40.0   # degrees above the cloth, seen from -Y
LAMP_DISTANCE = 0.35
LAMP_ELEVATION = 50.0     # degrees above the cloth, from +Y
LAMP_POWER = 20.0         # W (Blender's point-light power)
#: The studio's soft boxes: name -> (azimuth from +X deg, elevation deg, distance m, width m,
#: height m, power W). A large key above and behind the stone (the mirror side of planes lying
#: near the dome, so layered domains flash towards the camera), two strip boxes to the sides.
SOFT_BOXES = {
    "key": (90.0, 65.0, 0.45, 0.40, 0.40, 4.0),
    "strip_left": (225.0, 40.0, 0.40, 0.12, 0.40, 1.5),
    "strip_right": (20.0, 35.0, 0.40, 0.12, 0.40, 1.5),
}
#: Light sets: a small lamp (the old example), three soft boxes, the daylight sky alone.
LIGHTINGS = ("studio", "sky", "lamp")
#: View exposure per light set (Standard view transform).
EXPOSURE = {"lamp": -1.0, "studio": 0.0, "sky": -2.0}
#: Under the sky a light body (White) is exposed this many stops darker (a photographer exposes
#: for the subject; the sun's irradiance, about 43 W/m^2, would clip a 0.55 white body).
SKY_LIGHT_BODY_STOPS = 1.5
#: The orbit: the camera's elevation moved by these many degrees (two extra frames).
ORBIT = (-5.0, 5.0)


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


def camera_location(elevation_deg: float = CAMERA_ELEVATION):
    """The camera on a circle of CAMERA_DISTANCE about TARGET in the YZ plane, ``elevation_deg`` up."""
    e = math.radians(elevation_deg)
    return (TARGET[0], TARGET[1] - CAMERA_DISTANCE * math.cos(e), TARGET[2] + CAMERA_DISTANCE * math.sin(e))


def place_camera(cam, elevation_deg: float = CAMERA_ELEVATION) -> None:
    from mathutils import Vector

    cam.location = camera_location(elevation_deg)
    cam.rotation_euler = (Vector(TARGET) - Vector(cam.location)).to_track_quat("-Z", "Y").to_euler()


def build_scene(width: int = 512, height: int = 512, spp: int = 16, seed: int = 7, preset: str = "BLACK",
                lighting: str = "studio"):
    """Build the opal scene in the current (emptied) Blender file under ``lighting`` (LIGHTINGS);
    return (scene, opal, lights)."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "OPAL_DIFFRACTION"
    sc.render.resolution_x, sc.render.resolution_y = width, height
    sc.render.resolution_percentage = 100
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.exposure = -1.0
    sc.unit_settings.length_unit = "MILLIMETERS"
    sc.opal.samples = spp
    sc.opal.round_samples = spp
    sc.opal.wavelength_step = 10.0
    sc.opal.seed = 1
    # the world: a dark room with a window (a dim daylight sky, examples/environments.py) around
    # the lamp or the soft boxes; or the open daylight sky alone
    from opal_diffraction._scripts import load_example

    environments = load_example("environments")
    strength = SKY_STRENGTH if lighting != "sky" else 1.0
    sc.world = environments.blender_world(bpy, environments.sky(256, 128), strength)
    sc.view_settings.exposure = EXPOSURE[lighting]

    # the cloth: a dark blue-black velvet
    bpy.ops.mesh.primitive_plane_add(size=0.4)
    bpy.context.active_object.data.materials.append(_material(bpy, "velvet", (0.004, 0.004, 0.006)))

    # the opal: Add > Mesh > Opal at its real size, the preset's material and volume domains
    bpy.ops.mesh.primitive_opal_add(size_x=SIZE[0], size_y=SIZE[1], height=SIZE[2], resolution=96,
                                    preset=preset.upper(), seed=seed, show_preview=False)
    opal = bpy.context.active_object
    opal.rotation_euler = (0.0, 0.0, math.radians(8.0))
    if lighting == "sky" and max(opal.data.materials[0].opal.body_color) > 0.3:
        sc.view_settings.exposure -= SKY_LIGHT_BODY_STOPS  # a light body in the sun: exposed for the body

    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens = 100.0
    cam_data.clip_start = 0.001
    cam = bpy.data.objects.new("camera", cam_data)
    sc.collection.objects.link(cam)
    place_camera(cam)
    sc.camera = cam

    lights = []
    if lighting == "lamp":
        light_data = bpy.data.lights.new("lamp", "POINT")
        light_data.energy = LAMP_POWER
        light_data.shadow_soft_size = 0.0
        light = bpy.data.objects.new("lamp", light_data)
        sc.collection.objects.link(light)
        e = math.radians(LAMP_ELEVATION)
        light.location = (TARGET[0], TARGET[1] + LAMP_DISTANCE * math.cos(e), TARGET[2] + LAMP_DISTANCE * math.sin(e))
        lights.append(light)
    elif lighting == "studio":
        for name, (azimuth, elevation, distance, sx, sy, power) in SOFT_BOXES.items():
            lights.append(_soft_box(bpy, sc, name, azimuth, elevation, distance, sx, sy, power))
    return sc, opal, lights


def _soft_box(bpy, sc, name, azimuth_deg, elevation_deg, distance, size_x, size_y, power):
    """A rectangular area light ``size_x`` x ``size_y`` m of ``power`` W, ``distance`` m from TARGET
    at ``azimuth_deg`` (from +X, counter-clockwise) and ``elevation_deg``, facing TARGET."""
    from mathutils import Vector

    data = bpy.data.lights.new(name, "AREA")
    data.shape = "RECTANGLE"
    data.size, data.size_y = size_x, size_y
    data.energy = power
    ob = bpy.data.objects.new(name, data)
    sc.collection.objects.link(ob)
    a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
    ob.location = (TARGET[0] + distance * math.cos(e) * math.cos(a), TARGET[1] + distance * math.cos(e) * math.sin(a),
                   TARGET[2] + distance * math.sin(e))
    ob.rotation_euler = (Vector(TARGET) - Vector(ob.location)).to_track_quat("-Z", "Y").to_euler()
    return ob


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
    from opal_diffraction.core.render.prepare import prepare

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


def _report(path: str, t: float, args) -> bool:
    from opal_diffraction.blender.engine import last_render

    if last_render.get("status") != "FINISHED":
        print(f"render failed: {last_render.get('message')}", file=sys.stderr)
        return False
    s = last_render["stats"]
    print(f"{path}: {args.resolution[0]}x{args.resolution[1]}, {args.spp} spp, {t:.1f} s "
          f"(export {s.get('export_export_s', 0):.2f} s, prepare {s.get('prepare_s', 0):.2f} s, "
          f"{s.get('triangles', 0)} triangles, {s.get('rays', 0) / 1e6:.1f} M rays)")
    return True


def render_cycles(path: str, spp: int) -> float:
    """Render the current scene with Cycles (CPU, ``spp`` samples) to ``path``: the same stone,
    cloth, lights and world, the body only (Cycles has no Bragg lattice). Returns the wall time."""
    import bpy

    sc = bpy.context.scene
    engine = sc.render.engine
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = int(spp)
    sc.cycles.use_denoising = False
    try:
        return render(path)
    finally:
        sc.render.engine = engine


def side_by_side(ours: str, cycles: str, out: str, caption: str) -> None:
    """``ours`` beside ``cycles`` with a caption strip below (PIL)."""
    from PIL import Image, ImageDraw

    a, b = Image.open(ours).convert("RGB"), Image.open(cycles).convert("RGB")
    strip = 22
    img = Image.new("RGB", (a.width + b.width, max(a.height, b.height) + strip), (255, 255, 255))
    img.paste(a, (0, 0))
    img.paste(b, (a.width, 0))
    ImageDraw.Draw(img).text((6, max(a.height, b.height) + 5), caption, fill=(0, 0, 0))
    img.save(out)


def _render_preset(preset: str, stem: str, args, orbit: bool) -> bool:
    import bpy

    sc, _opal, _lights = build_scene(*args.resolution, spp=args.spp, seed=args.seed, preset=preset,
                                     lighting=args.lighting)
    if args.lighting != "studio":
        stem = f"{stem}_{args.lighting}"
    if args.blend:
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(args.blend))
    path = os.path.join(args.out, f"{stem}.png")
    t_ours = render(path)
    if not _report(path, t_ours, args):
        return False
    if args.cycles > 0:
        cpath = os.path.join(args.out, f"{stem}_cycles.png")
        t_cycles = render_cycles(cpath, args.cycles)
        print(f"{cpath}: Cycles {args.cycles} spp, {t_cycles:.1f} s")
        side_by_side(path, cpath, os.path.join(args.out, f"{stem}_vs_cycles.png"),
                     f"{preset.title()}, {args.lighting}: ours {args.spp} spp {t_ours:.0f} s | "
                     f"Cycles {args.cycles} spp {t_cycles:.0f} s (body only, no Bragg)")
    if orbit:
        for step in ORBIT:
            place_camera(sc.camera, CAMERA_ELEVATION + step)
            path = os.path.join(args.out, f"{stem}_orbit_{'minus' if step < 0 else 'plus'}{abs(step):g}.png")
            if not _report(path, render(path), args):
                return False
        place_camera(sc.camera)
    return True


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="black", help="an opal preset (black, white, crystal, boulder, harlequin, "
                    "pinfire, paper)")
    ap.add_argument("--all-presets", action="store_true", help="render docs/opal_<preset>.png for every preset")
    ap.add_argument("--no-orbit", action="store_true", help="skip the two orbit frames (+-5 degrees)")
    ap.add_argument("--resolution", type=int, nargs=2, default=(512, 512))
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--seed", type=int, default=7, help="domain layout seed")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs"))
    ap.add_argument("--blend", default="", help="also save the scene as this .blend file")
    ap.add_argument("--lighting", default="studio", choices=LIGHTINGS, help="three soft boxes (studio), the "
                    "daylight sky alone (sky: files end in _sky), or the old small lamp (lamp: _lamp)")
    ap.add_argument("--cycles", type=int, default=0, metavar="SPP", help="also render the scene with Cycles at "
                    "SPP samples (the body only) and write <stem>_cycles.png and <stem>_vs_cycles.png")
    ap.add_argument("--no-viewport", action="store_true", help="skip timing the viewport's first image")
    args = ap.parse_args(argv)

    import opal_diffraction

    opal_diffraction.register()
    try:
        from opal_diffraction.blender.opal_presets import PRESET_ITEMS

        idents = [i[0] for i in PRESET_ITEMS]
        os.makedirs(args.out, exist_ok=True)
        if args.all_presets:
            for ident in idents:
                if not _render_preset(ident, f"opal_{ident.lower()}", args, orbit=False):
                    return 1
        else:
            ident = args.preset.upper()
            if ident not in idents:
                print(f"unknown preset {args.preset!r}; expected one of {[i.lower() for i in idents]}",
                      file=sys.stderr)
                return 2
            stem = "opal" if ident == "BLACK" else f"opal_{ident.lower()}"
            if not _render_preset(ident, stem, args, orbit=not args.no_orbit):
                return 1
        if not args.no_viewport:
            fv = viewport_first_image(*args.resolution)
            print(f"viewport first image ({args.resolution[0] // 8}x{args.resolution[1] // 8}, 1 spp): {fv:.2f} s")
    finally:
        opal_diffraction.unregister()
    return 0


if __name__ == "__main__":
    sys.exit(main())
