"""Operators: export the evaluated scene to the core's ``.npz``, and apply a dispersion preset."""

from __future__ import annotations

import os
import sys
import traceback

import bpy
from bpy.props import EnumProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from ..core.scene.checks import SceneError
from ..core.scene.npz import save_scene
from ..core.scene.validation import validate
from .export import ExportCancelled, export_scene
from .properties import DISPERSION_PRESETS

__all__ = ["OPAL_OT_export_scene", "OPAL_OT_dispersion_preset", "register", "unregister"]


class OPAL_OT_export_scene(bpy.types.Operator, ExportHelper):
    """Export the evaluated scene to an .npz file the command line renders without Blender"""

    # the tooltip: one line, no final period (Blender's style; a docstring's line breaks would show)
    bl_description = ("Export the evaluated scene (geometry with modifiers, materials, lights, camera, world) to "
                      "an .npz scene file that the command line re-renders without Blender")

    bl_idname = "opal.export_scene"
    bl_label = "Export Opal Scene (.npz)"
    bl_options = {"REGISTER"}

    filename_ext = ".npz"
    filter_glob: StringProperty(default="*.npz", options={"HIDDEN"})

    @classmethod
    def poll(cls, context):
        return context.scene is not None

    def execute(self, context):
        depsgraph = context.evaluated_depsgraph_get()
        try:
            exported = export_scene(depsgraph)
            validate(exported.scene)  # the same checks a render makes, before writing anything
            path = bpy.path.abspath(self.filepath)
            if not path.lower().endswith(".npz"):
                path += ".npz"
            os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
            save_scene(exported.scene, path)
        except (SceneError, ExportCancelled, OSError) as e:
            self.report({"ERROR"}, f"Opal Diffraction export failed: {e or 'cancelled'}")
            return {"CANCELLED"}
        except Exception as e:  # a bug: say so plainly, keep the details for the console
            traceback.print_exc(file=sys.stderr)
            self.report({"ERROR"}, f"Opal Diffraction export failed: internal error ({type(e).__name__}: {e}); "
                                   "details are in the system console")
            return {"CANCELLED"}
        for w in exported.warnings:
            self.report({"WARNING"}, f"Opal Diffraction: {w}")
        s = exported.stats
        self.report({"INFO"}, f"Exported {s['triangles']} triangles, {s['lights']} lights, {s['materials']} "
                              f"materials to {path} in {s['export_s']:.2f} s (viewport modifier levels)")
        return {"FINISHED"}


def _preset_items():
    return [(ident, name, f"{model.replace('_', ' ').title()} dispersion, n_d {nd:g}, Abbe number {vd:g}", i)
            for i, (ident, name, model, nd, vd) in enumerate(DISPERSION_PRESETS)]


class OPAL_OT_dispersion_preset(bpy.types.Operator):
    """Set the material's dispersion to a named glass, and its BSDF nodes' IOR to the glass's n_d"""

    bl_idname = "opal.dispersion_preset"
    bl_label = "Dispersion Preset"
    bl_options = {"REGISTER", "UNDO"}

    preset: EnumProperty(name="Preset", items=_preset_items(), description="Named glass")

    @classmethod
    def poll(cls, context):
        return getattr(context, "material", None) is not None

    def execute(self, context):
        mat = context.material
        ident, name, model, n_d, abbe = next(p for p in DISPERSION_PRESETS if p[0] == self.preset)
        mat.opal.dispersion = model
        mat.opal.abbe_number = abbe
        changed = 0
        if mat.node_tree is not None:
            for node in mat.node_tree.nodes:
                if node.bl_idname in ("ShaderNodeBsdfGlass", "ShaderNodeBsdfRefraction", "ShaderNodeBsdfPrincipled"):
                    sock = node.inputs.get("IOR")
                    if sock is not None and not sock.is_linked:
                        sock.default_value = n_d
                        changed += 1
        self.report({"INFO"}, f"{mat.name}: {name} (n_d {n_d:g}, V_d {abbe:g}); IOR set on {changed} node(s)")
        return {"FINISHED"}


classes = (OPAL_OT_export_scene, OPAL_OT_dispersion_preset)


def _menu_export(self, context):
    self.layout.operator(OPAL_OT_export_scene.bl_idname, text="Opal Diffraction Scene (.npz)")


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.TOPBAR_MT_file_export.append(_menu_export)


def unregister():
    bpy.types.TOPBAR_MT_file_export.remove(_menu_export)
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
