"""The prism example, built with bpy and rendered headless through the OPAL_DIFFRACTION engine.

    .venv/bin/python examples/render_example.py [--spp 32] [--resolution 640 400] [--light-paths N]
                                                [--out out/render_example]

Builds the scene of ``examples/prism.py`` as a Blender scene - a 60-degree dense-flint prism
(Glass BSDF, IOR 1.72, dispersion 'IOR + Abbe Number' with V_d 29) lying along X with its apex
down, a floor, a wall of horizontal stripes (N_STRIPES, 8 m in all) alternating white and black 3 m behind it,
a point light, a daylight sky (an Environment Texture with a sun), and a camera at (0, -5.5, 3.6) looking at (0, 0.5, 1.1) - then renders it with
``bpy.ops.render.render(write_still=True)`` as F12 would. Writes ``out/render_example.png`` and
``out/render_example.blend``; the .blend renders the same with Blender itself once the extension
is installed:

    blender -b out/render_example.blend -E OPAL_DIFFRACTION -o //render_####.png -f 1

Looking through the prism, the stripes' edges fan out into spectra.
"""

from __future__ import annotations

import argparse
import os
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")

#: The striped wall: stripes of WALL_HEIGHT / N_STRIPES metres, alternating white and black.
N_STRIPES, WALL_HEIGHT = 16, 8.0  # as examples/prism.py


def _mesh(bpy, name, verts, tris, mat):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, v)) for v in verts], [], [tuple(map(int, t)) for t in tris])
    me.update()
    me.materials.append(mat)
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _material(bpy, name, node, color, **inputs):
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True  # always on (and deprecated) from Blender 5.0
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    bsdf = nt.nodes.new(node)
    bsdf.location = (-250, 0)
    bsdf.inputs["Color"].default_value = (*color, 1.0)
    for k, v in inputs.items():
        bsdf.inputs[k].default_value = v
    nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat


def build_scene(width: int = 640, height: int = 400, spp: int = 32, light_paths: int | None = None):
    """Build the prism scene in the current (emptied) Blender file; return the scene."""
    import bpy
    from mathutils import Vector

    from opal_diffraction.core.scene import primitives

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.name = "Prism"

    floor = _material(bpy, "floor", "ShaderNodeBsdfDiffuse", (0.5, 0.5, 0.5))
    white = _material(bpy, "white stripe", "ShaderNodeBsdfDiffuse", (0.9, 0.9, 0.9))
    black = _material(bpy, "black stripe", "ShaderNodeBsdfDiffuse", (0.02, 0.02, 0.02))
    flint = _material(bpy, "flint glass", "ShaderNodeBsdfGlass", (1.0, 1.0, 1.0), IOR=1.72, Roughness=0.0)
    flint.opal.dispersion = "ABBE"
    flint.opal.abbe_number = 29.0

    _mesh(bpy, "Floor", *primitives.quad((0, 0, 0), (12, 0, 0), (0, 12, 0)), floor)
    for i in range(N_STRIPES):
        z = (i + 0.5) * WALL_HEIGHT / N_STRIPES
        quad = primitives.quad((0.0, 3.0, z), (10.0, 0, 0), (0, 0, WALL_HEIGHT / N_STRIPES))
        _mesh(bpy, f"Stripe {i}", *quad, white if i % 2 == 0 else black)
    # a 60-degree prism lying along X, apex down: it bends the view up onto the striped wall
    _mesh(bpy, "Prism", *primitives.prism((0, 0, 0.75), side=1.2, length=2.4, axis="X", rotation_deg=180.0), flint)

    light = bpy.data.lights.new("Light", "POINT")
    light.energy = 1500.0
    light.shadow_soft_size = 0.0
    lob = bpy.data.objects.new("Light", light)
    lob.location = (2.0, -3.0, 5.0)
    scene.collection.objects.link(lob)

    cam = bpy.data.cameras.new("Camera")
    cam.lens = 50.0
    cob = bpy.data.objects.new("Camera", cam)
    cob.location = (0.0, -5.5, 3.6)
    cob.rotation_euler = (Vector((0.0, 0.5, 1.1)) - cob.location).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(cob)
    scene.camera = cob

    # the daylight sky of examples/prism.py: an Environment Texture of a packed float image
    from opal_diffraction._scripts import load_example

    environments = load_example("environments")
    world = environments.blender_world(bpy, environments.sky(256, 128), load_example("prism").SKY_STRENGTH)
    scene.world = world

    scene.render.engine = "OPAL_DIFFRACTION"
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.opal.samples = spp
    if light_paths is not None:
        scene.opal.light_paths = light_paths
    scene.opal.dispersion_sampling = "SAMPLE"
    return scene


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, default=32, help="samples per pixel (default 32)")
    ap.add_argument("--resolution", type=int, nargs=2, default=(640, 400), metavar=("W", "H"))
    ap.add_argument("--light-paths", type=int, default=None, help="light-pass paths (default: the setting's default)")
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "render_example"),
                    help="output path without extension (.png and .blend are written)")
    args = ap.parse_args(argv)

    import bpy

    import opal_diffraction
    from opal_diffraction.blender import engine

    opal_diffraction.register()
    try:
        scene = build_scene(*args.resolution, spp=args.spp, light_paths=args.light_paths)
        out = os.path.abspath(args.out)
        os.makedirs(os.path.dirname(out), exist_ok=True)
        scene.render.image_settings.file_format = "PNG"
        scene.render.filepath = out + ".png"
        bpy.ops.wm.save_as_mainfile(filepath=out + ".blend")
        try:
            bpy.ops.render.render(write_still=True)
        except RuntimeError as e:  # the engine reported an error: its message, no traceback
            print(f"error: {e}", file=sys.stderr)
            return 2
        info = engine.last_render
        s = info.get("stats", {})
        print(f"wrote {out}.png and {out}.blend: {info.get('samples')} samples/pixel, "
              f"{s.get('rays', 0) / 1e6:.1f} M rays in {s.get('total_s', 0.0):.1f} s ({info.get('plan', '')})")
        for w in info.get("warnings", []):
            print(f"warning: {w}", file=sys.stderr)
        return 0
    finally:
        opal_diffraction.unregister()


if __name__ == "__main__":
    sys.exit(main())
