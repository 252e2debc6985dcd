"""Thin-film interference: a soap bubble, a coated black sphere and a tempered-steel sphere, beside Cycles.

    .venv/bin/python examples/thin_film.py [--spp 64] [--cycles-spp 128] [--resolution 360 200]
                                           [--out docs/thin_film.png]

Builds, with bpy, three spheres on a dark floor in the studio environment of
``examples/environments.py`` (four soft boxes in a dark room), each a Principled BSDF with a
*Thin Film* (docs/physics.md section 2.8):

- left, a **soap bubble**: glass of IOR 1.0 (air inside) under a 380 nm water film (IOR 1.33):
  both walls are films between air and air, so it shows only the film's interference colours,
  changing from its centre to its rim as the angle in the film grows;
- middle, a **coated black sphere** (a beetle's shell, a coated lens): a black dielectric base
  (IOR 1.5) under a 520 nm film of IOR 1.6;
- right, **tempered steel**: a grey metal (F0 0.6) under a 300 nm oxide film of IOR 2.0.

It renders the scene with OPAL_DIFFRACTION (exact Airy interference at every wavelength sample)
and with Cycles (its RGB thin film, Belcour & Barla's spectral integration) in the same bpy
session, and writes one PNG with ours on the left and Cycles on the right, at the same exposure
(view transform Standard). Prints both renders' mean colour per sphere.
"""

from __future__ import annotations

import argparse
import math
import os
import sys

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")

#: (name, location x, Principled inputs, base colour)
SPHERES = (
    ("soap bubble", -1.25, {"Transmission Weight": 1.0, "IOR": 1.0, "Roughness": 0.0,
                            "Thin Film Thickness": 380.0, "Thin Film IOR": 1.33}, (1.0, 1.0, 1.0)),
    ("coated black", 0.0, {"IOR": 1.5, "Roughness": 0.0, "Thin Film Thickness": 520.0, "Thin Film IOR": 1.6},
     (0.0, 0.0, 0.0)),
    ("tempered steel", 1.25, {"Metallic": 1.0, "Roughness": 0.0, "Thin Film Thickness": 300.0,
                              "Thin Film IOR": 2.0}, (0.6, 0.6, 0.6)),
)
RADIUS = 0.5


def _principled(bpy, name, color, inputs):
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    node = mat.node_tree.nodes["Principled BSDF"]
    node.inputs["Base Color"].default_value = (*color, 1.0)
    for k, v in inputs.items():
        node.inputs[k].default_value = v
    return mat


def build_scene(width: int, height: int, spp: int):
    """The three spheres, the floor, the studio world and the camera in an emptied file."""
    import bpy
    from mathutils import Vector

    from opal_diffraction._scripts import load_example

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.name = "Thin film"
    for name, x, inputs, color in SPHERES:
        bpy.ops.mesh.primitive_uv_sphere_add(segments=96, ring_count=48, radius=RADIUS, location=(x, 0.0, RADIUS))
        ob = bpy.context.active_object
        ob.name = name
        bpy.ops.object.shade_smooth()
        ob.data.materials.append(_principled(bpy, name, color, inputs))
    bpy.ops.mesh.primitive_plane_add(size=30.0, location=(0.0, 0.0, 0.0))
    floor = bpy.data.materials.new("floor")
    if bpy.app.version < (5, 0, 0):
        floor.use_nodes = True
    floor.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.008, 0.008, 0.01, 1.0)
    floor.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 0.8
    bpy.context.active_object.data.materials.append(floor)

    environments = load_example("environments")
    scene.world = environments.blender_world(bpy, environments.studio(512, 256), 1.0)

    cam = bpy.data.cameras.new("Camera")
    cam.lens = 50.0
    cob = bpy.data.objects.new("Camera", cam)
    cob.location = (0.0, -5.2, 1.1)
    cob.rotation_euler = (Vector((0.0, 0.0, 0.45)) - cob.location).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(cob)
    scene.camera = cob

    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.opal.samples = spp
    scene.opal.light_paths = 0  # the eye pass alone, as Cycles
    # Cycles without its biasing defaults (as tests/blender/parity_scenes.py): no clamping (the
    # floor's caustics through the bubble are fireflies Cycles would clip), no Filter Glossy, the
    # same pixel filter and bounce limits
    scene.opal.filter_width = 1.5
    cy = scene.cycles
    cy.pixel_filter_type, cy.filter_width = "BLACKMAN_HARRIS", 1.5
    cy.sample_clamp_direct = cy.sample_clamp_indirect = 0.0
    cy.blur_glossy = 0.0
    for k, v in dict(max_bounces=12, diffuse_bounces=4, glossy_bounces=4, transmission_bounces=12).items():
        setattr(cy, k, v)
        setattr(scene.opal, k, v)
    return scene


def _render(bpy, engine: str, samples: int, path: str) -> np.ndarray:
    from opal_diffraction.core.render.output import read_exr

    sc = bpy.context.scene
    sc.render.engine = engine
    if engine == "CYCLES":
        sc.cycles.device = "CPU"
        sc.cycles.samples = samples
        sc.cycles.use_denoising = False
        sc.cycles.use_adaptive_sampling = False
    else:
        sc.opal.samples = samples
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    sc.render.filepath = path
    bpy.ops.render.render(write_still=True)
    ch = read_exr(path)
    return np.stack([ch["R"], ch["G"], ch["B"]], axis=-1).astype(np.float64)


def _sphere_means(img: np.ndarray, width: int) -> list[np.ndarray]:
    """Mean colour in a box at each sphere's image centre (a fifth of the height wide)."""
    h = img.shape[0]
    out = []
    for _, x, _, _ in SPHERES:
        cx = int(width / 2 + x / 1.25 * width * 0.265)
        cy = int(h * 0.5)
        r = max(2, h // 10)
        out.append(img[cy - r:cy + r, cx - r:cx + r].reshape(-1, 3).mean(axis=0))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, default=64, help="our samples per pixel (default 64)")
    ap.add_argument("--cycles-spp", type=int, default=128, help="Cycles' samples per pixel (default 128)")
    ap.add_argument("--resolution", type=int, nargs=2, default=(360, 200), metavar=("W", "H"))
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "thin_film.png"), help="the side-by-side PNG")
    args = ap.parse_args(argv)

    import tempfile

    import bpy

    import opal_diffraction
    from opal_diffraction.core.render.output import write_png

    opal_diffraction.register()
    try:
        build_scene(*args.resolution, spp=args.spp)
        with tempfile.TemporaryDirectory() as tmp:
            ours = _render(bpy, "OPAL_DIFFRACTION", args.spp, os.path.join(tmp, "ours.exr"))
            cycles = _render(bpy, "CYCLES", args.cycles_spp, os.path.join(tmp, "cycles.exr"))
        gap = np.ones((ours.shape[0], 4, 3))
        out = os.path.abspath(args.out)
        os.makedirs(os.path.dirname(out), exist_ok=True)
        write_png(out, np.concatenate([ours, gap, cycles], axis=1).astype(np.float32))
        print(f"wrote {out}: OPAL_DIFFRACTION ({args.spp} spp) | Cycles ({args.cycles_spp} spp)")
        for (name, *_), o, c in zip(SPHERES, _sphere_means(ours, args.resolution[0]),
                                    _sphere_means(cycles, args.resolution[0])):
            print(f"  {name:15s} ours {np.round(o, 3).tolist()}  Cycles {np.round(c, 3).tolist()}")
        return 0
    finally:
        opal_diffraction.unregister()


if __name__ == "__main__":
    sys.exit(main())
