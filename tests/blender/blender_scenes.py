"""Small test scenes built with bpy, and helpers to render them with either engine.

Each builder starts from an empty file (``bpy.ops.wm.read_factory_settings(use_empty=True)``),
so tests do not depend on each other's leftovers.
"""

from __future__ import annotations

import math
import os

import bpy
import numpy as np

ENGINE = "OPAL_DIFFRACTION"


def empty_scene(width: int = 32, height: int = 32, engine: str = ENGINE):
    """A fresh empty file with a small resolution, the engine set and a black world."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = engine
    sc.render.resolution_x, sc.render.resolution_y = width, height
    sc.render.resolution_percentage = 100
    sc.render.threads_mode = "FIXED"
    sc.render.threads = 2
    sc.view_settings.view_transform = "Standard"
    sc.world = None
    sc.opal.samples = 8
    sc.opal.wavelength_step = 10.0
    return sc


def link(obj):
    bpy.context.scene.collection.objects.link(obj)
    return obj


def material(name: str, kind: str = "DIFFUSE", color=(0.5, 0.5, 0.5), **inputs):
    """A node material: kind 'DIFFUSE' (Diffuse BSDF), 'PRINCIPLED', 'GLASS', 'GLOSSY', 'EMISSION'."""
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True  # always on (and deprecated) from Blender 5.0
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    idname = {"DIFFUSE": "ShaderNodeBsdfDiffuse", "PRINCIPLED": "ShaderNodeBsdfPrincipled",
              "GLASS": "ShaderNodeBsdfGlass", "GLOSSY": "ShaderNodeBsdfGlossy",
              "EMISSION": "ShaderNodeEmission"}.get(kind, kind)
    node = nt.nodes.new(idname)
    col_name = "Base Color" if "Base Color" in node.inputs else "Color"
    node.inputs[col_name].default_value = (*color, 1.0)
    for k, v in inputs.items():
        node.inputs[k].default_value = v
    nt.links.new(node.outputs[0], out.inputs["Surface"])
    return mat


def mesh_object(name: str, verts, faces, mat=None, location=(0, 0, 0)):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(v) for v in verts], [], [tuple(f) for f in faces])
    me.update()
    ob = link(bpy.data.objects.new(name, me))
    ob.location = location
    if mat is not None:
        me.materials.append(mat)
    return ob


def plane(name="plane", half=2.0, z=0.0, mat=None):
    return mesh_object(name, [(-half, -half, z), (half, -half, z), (half, half, z), (-half, half, z)],
                       [(0, 1, 2, 3)], mat)


def camera(location=(0, 0, 5), rotation=(0, 0, 0), ortho_scale=None, lens=50.0):
    cam = bpy.data.cameras.new("camera")
    if ortho_scale is not None:
        cam.type = "ORTHO"
        cam.ortho_scale = ortho_scale
    cam.lens = lens
    ob = link(bpy.data.objects.new("camera", cam))
    ob.location = location
    ob.rotation_euler = rotation
    bpy.context.scene.camera = ob
    return ob


def light(kind: str, location, power: float, rotation=(0, 0, 0), **props):
    data = bpy.data.lights.new(f"{kind.lower()}_light", kind)
    data.energy = power
    if kind in ("POINT", "SPOT"):
        data.shadow_soft_size = 0.0
    if kind == "SUN":
        data.angle = 0.0
    for k, v in props.items():
        setattr(data, k, v)
    ob = link(bpy.data.objects.new(data.name, data))
    ob.location = location
    ob.rotation_euler = rotation
    return ob


def lit_plane_scene(light_kind: str, pixels: int = 32, engine: str = ENGINE, **light_props):
    """A grey (albedo 0.5) diffuse 6 m square seen from above by an orthographic camera that frames
    its central 4 m (so pixel-filter samples past the frame still land on the plane), lit by one
    light of the given kind (docs/physics.md section 1.5)."""
    sc = empty_scene(pixels, pixels, engine)
    plane(half=3.0, mat=material("grey", "DIFFUSE", (0.5, 0.5, 0.5)))
    camera(location=(0, 0, 5), ortho_scale=4.0)
    defaults = {
        "POINT": dict(location=(0, 0, 2), power=100.0),
        "SPOT": dict(location=(0, 0, 2), power=100.0, spot_size=math.radians(60), spot_blend=0.3),
        "SUN": dict(location=(0, 0, 3), power=2.0, rotation=(math.radians(20), 0, 0)),
        "AREA": dict(location=(0, 0, 1.5), power=100.0, shape="SQUARE", size=1.0),
    }[light_kind]
    defaults.update(light_props)
    light(light_kind, **defaults)
    return sc


def render_to_array(path: str, engine: str | None = None, samples: int | None = None) -> np.ndarray:
    """Render the current scene with ``engine`` to a float EXR at ``path`` and read it back as
    (H, W, 3) linear RGB, row 0 at the top."""
    from opal_diffraction.core.render.output import read_exr

    sc = bpy.context.scene
    if engine is not None:
        sc.render.engine = engine
    if sc.render.engine == "CYCLES":
        sc.cycles.device = "CPU"
        sc.cycles.samples = samples or 64
        sc.cycles.use_denoising = False
        sc.cycles.use_adaptive_sampling = False
        sc.cycles.seed = 1
    elif samples is not None:
        sc.opal.samples = samples
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    sc.render.filepath = path
    if os.path.exists(path):
        os.remove(path)
    bpy.ops.render.render(write_still=True)
    ch = read_exr(path)
    return np.stack([ch["R"], ch["G"], ch["B"]], axis=-1).astype(np.float64)
