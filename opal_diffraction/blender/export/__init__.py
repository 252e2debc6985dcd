"""Depsgraph -> core Scene: geometry, materials, lights, camera and world, as flat NumPy arrays.

Everything is read from the evaluated depsgraph the engine is given (never from ``bpy.context``),
so modifiers, geometry nodes, instancing and the render-time visibility are what the render
sees. Geometry is read with ``foreach_get`` into NumPy (no Python loop per triangle or vertex);
a mesh that many instances share is read once and transformed for all of its instances in one
vectorised product. Blender's units are kept: metres, Cycles' light units (watts for point,
spot and area lights, W/m^2 for the sun), colours in the blend file's linear working space,
converted to the core's linear Rec.709.

Image Texture nodes on a BSDF's colour, roughness, metallic, emission colour and (through a
tangent-space Normal Map node) normal are exported as images (``Scene.textures``, each image read
once), per-material bindings and per-corner UVs and tangents, sampled per hit by the core
(docs/physics.md section 13); rough reflection and refraction are exported as roughness (and
Principled's metallic / transmission layers) for the core's GGX microfacets (core/materials/bsdf.py),
a world's equirectangular Environment Texture as a map. What the core cannot render is
approximated and named in the warnings rather than failing: other textures and procedural nodes
(averaged); volume shaders become homogeneous media (a material's interior, the world's volume:
export/volumes.py; a volume-only material's surface is a null boundary); hair (curves objects and hair particle systems), point clouds and volume
objects are skipped with counts. Values that would overflow the tracer's float32 (an emission or
light power up to Blender's FLT_MAX) are clamped with a warning, NaN is an error naming the
material or light, and a node cycle renders as the default surface with a warning. Grating
settings are exported with a per-triangle grating direction (``Scene.tri_tangent``) and, where
the mesh has the opal tools' per-face period attribute (``opal_grating_period``), a per-triangle
period (``Scene.tri_period``); impossible values are an error naming the material. Smooth
shading is exported as per-corner shading normals (``Scene.corner_normals``, world space).

One module per concept, as in BlendLuxCore's ``export`` package:

    colour     working space <-> Rec.709, blackbody colours, image averages
    images     Blender images as Cycles reads them; the export's texture table
    nodes      shader node trees -> the core's surfaces (and their image textures)
    materials  the material table (export_materials)
    meshes     meshes, tangents, periods, instances -> arrays; the MeshCache
    lights     the light table (export_lights)
    world      the world: a colour, or an environment map with its rotation (export_world_light)
    camera     render size, border region, the camera (export_camera), its motion over the shutter
    motion     objects' motion: the vertices in the shutter's time bins (object_motion)
    messages   the warnings, once each

:func:`export_scene` here puts them together. A rendered viewport passes a persistent
:class:`MeshCache` (invalidated from ``depsgraph.updates``) so a re-export reads only the meshes
whose geometry changed, or calls the per-concept functions alone.
"""

from __future__ import annotations

import time
from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

from ...core.scene.model import Lights, Scene
from ..mesh_io import GRATING_ATTRIBUTE, PERIOD_ATTRIBUTE
from .camera import export_camera, render_region, render_size
from .motion import instance_id, object_motion
from .colour import rec709_to_working_space, working_space_to_rec709
from .domains import flatten_domains, instance_domains
from .lights import LightRows, export_lights
from .materials import MaterialTable, export_materials
from .meshes import (GEOMETRY_TYPES, UNSUPPORTED_GEOMETRY, MeshCache, SceneMeshes, element_count, flatten,
                     flatten_attribute_corners, flatten_corners, flatten_program_corners, hair_systems, strand_count)
from .messages import Skipped, Warnings
from .world import export_world, export_world_light, export_world_volume

__all__ = [
    "ExportCancelled",
    "ExportResult",
    "export_scene",
    "render_size",
    "render_region",
    "working_space_to_rec709",
    "rec709_to_working_space",
    "GRATING_ATTRIBUTE",
    "PERIOD_ATTRIBUTE",
    "MeshCache",
    "Warnings",
    "export_lights",
    "export_materials",
    "export_world",
    "export_world_light",
    "export_camera",
]

#: How often (in object instances) export polls test_break.
POLL_EVERY = 64


class ExportCancelled(Exception):
    """The user pressed Esc while the scene was being exported."""


@dataclass
class ExportResult:
    scene: Scene
    warnings: list[str] = field(default_factory=list)
    stats: dict = field(default_factory=dict)


def export_scene(depsgraph, *, width: int | None = None, height: int | None = None, camera=None,
                 test_break=None, progress=None, mesh_cache: MeshCache | None = None,
                 frame_set=None) -> ExportResult:
    """Export the evaluated ``depsgraph`` to a core Scene.

    ``width``/``height`` default to the scene's resolution times its percentage; ``camera``
    (an object) overrides the scene camera. ``test_break()`` is polled every few dozen object
    instances (raise ExportCancelled when it returns True); ``progress(message)`` receives a
    status line now and then. ``mesh_cache``: a :class:`MeshCache` kept between exports of this
    depsgraph, so that only meshes it does not hold (or that :meth:`MeshCache.invalidate`
    dropped) are read; None reads every mesh. ``frame_set(frame, subframe)``: re-evaluates the
    depsgraph at a sub-frame (a final render's RenderEngine.frame_set), for motion blur
    (export/camera.py camera_motion); None: no motion blur. Raises SceneError with a readable message for
    input that cannot be rendered (NaN coordinates, a panoramic camera, ...).
    """
    t0 = time.perf_counter()
    warn = Warnings()
    to709 = working_space_to_rec709()
    scene = depsgraph.scene
    if width is None or height is None:
        width, height = render_size(scene)
    materials = MaterialTable(warn, to709)
    meshes = SceneMeshes(mesh_cache)
    groups: dict = defaultdict(list)  # (mesh key, material tuple) -> matrices
    domains: dict = defaultdict(list)  # the same keys -> each instance's opal volume domains or None
    lights = LightRows(warn, to709)
    skipped = Skipped()
    n_instances = 0
    kept: list = []  # (group key, instance id) in export order: object motion reads them again

    for i, inst in enumerate(depsgraph.object_instances):
        if i % POLL_EVERY == 0:
            if test_break is not None and test_break():
                raise ExportCancelled()
            if progress is not None and i:
                progress(f"exporting: {i} objects")
        ob = inst.object
        otype = ob.type
        if otype == "LIGHT":
            lights.add(ob, inst.matrix_world)
            continue
        if otype not in GEOMETRY_TYPES:
            if otype in UNSUPPORTED_GEOMETRY and inst.show_self:
                skipped.add(otype, ob.name, element_count(ob))
            continue
        if inst.show_particles:
            for psys in hair_systems(ob):
                skipped.add("HAIR", ob.name, strand_count(psys))
        if not inst.show_self:
            continue
        slots = materials.slots(ob)
        mkey, md = meshes.get(ob, otype, materials.corner_needs(slots), warn)
        if md is None or len(md.triangles) == 0:
            continue
        groups[(mkey, slots)].append(np.array(inst.matrix_world, np.float64))
        kept.append(((mkey, slots), instance_id(inst)))
        domains[(mkey, slots)].append(instance_domains(ob))
        n_instances += 1

    if test_break is not None and test_break():
        raise ExportCancelled()
    vertices, triangles, tri_material, tri_tangent, tri_period, corner_normals = flatten(
        groups, meshes, materials.grating, warn, materials.hidden_rows())
    corner_uvs, corner_tangents = flatten_corners(groups, meshes, materials.corners, materials.hidden_rows())
    corner_generated, corner_object = flatten_program_corners(groups, meshes, materials.program_reads,
                                                              materials.hidden_rows())
    corner_attributes = flatten_attribute_corners(groups, meshes, materials.program_reads, materials.hidden_rows())
    domain_fields = flatten_domains(groups, domains, meshes, materials.hidden_rows())

    skipped.report(warn)
    # object motion blur: the vertices in the shutter's time bins (export/motion.py)
    motion_vertices = object_motion(depsgraph, frame_set, kept, groups, meshes, materials.grating,
                                    materials.hidden_rows(), warn, n_triangles=len(triangles))
    world_medium = export_world_volume(depsgraph, warn)  # the world's Volume (docs/physics.md section 15)
    world_row = -1 if world_medium is None else materials.world_medium(world_medium)
    core_materials = materials.finish()
    cam = export_camera(depsgraph, width=width, height=height, camera=camera, warn=warn, frame_set=frame_set,
                        objects_checked=frame_set is not None)
    world = export_world_light(depsgraph, warn)
    core_scene = Scene(
        vertices=vertices, triangles=triangles, tri_material=tri_material,
        materials=core_materials, lights=Lights.from_list(lights.rows + world.lights), camera=cam,
        world_color=world.color, tri_tangent=tri_tangent, tri_period=tri_period, corner_normals=corner_normals,
        world_image=world.image, world_rotation=world.rotation,
        corner_uvs=corner_uvs, corner_tangents=corner_tangents, **materials.textures.scene_fields(), **domain_fields,
        shader_programs=list(materials.programs), corner_generated=corner_generated, corner_object=corner_object,
        corner_attributes=corner_attributes,
        **({} if motion_vertices is None else {"motion_vertices": motion_vertices}),
        world_volume=world_row,
    )
    meshes.done()
    stats = {
        "export_s": time.perf_counter() - t0, "objects": n_instances, "meshes": len(meshes),
        "triangles": len(triangles), "vertices": len(vertices), "lights": len(lights.rows) + len(world.lights),
        "materials": len(materials.rows), "textures": len(materials.textures),
    }
    return ExportResult(core_scene, warn.items, stats)
