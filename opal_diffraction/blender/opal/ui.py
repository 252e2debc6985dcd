"""The opal tools' menus and panel: Add > Mesh > Opal, the Edit Mode Face menu's Opal Gratings, the
Object menu's entries, and the 3D View sidebar's "Opal" tab."""

from __future__ import annotations

import math

import bpy

from .operators import (
    MESH_OT_primitive_opal_add,
    OPAL_OT_assign_grating,
    OPAL_OT_generate_domains,
    OPAL_OT_jitter_period,
    OPAL_OT_merge_domains,
    OPAL_OT_select_domain,
    OPAL_OT_split_domain,
    OPAL_OT_set_domain,
    OPAL_OT_update_preview,
    is_mesh,
)

__all__ = ["VIEW3D_MT_opal_edit", "VIEW3D_PT_opal_tools", "menus", "append_menus", "remove_menus"]


def _menu_add(self, context):
    self.layout.operator(MESH_OT_primitive_opal_add.bl_idname, text="Opal", icon="MESH_UVSPHERE")


class VIEW3D_MT_opal_edit(bpy.types.Menu):
    """Opal grating tools (Edit Mode: Face menu)"""

    bl_idname = "VIEW3D_MT_opal_edit"
    bl_label = "Opal Gratings"

    def draw(self, context):
        layout = self.layout
        layout.operator(OPAL_OT_set_domain.bl_idname, text="Domain Faces the Surface").orientation = "NORMAL"
        layout.operator(OPAL_OT_set_domain.bl_idname, text="Domain Faces the View").orientation = "VIEW"
        op = layout.operator(OPAL_OT_set_domain.bl_idname, text="Set Domain Sphere Diameter")
        op.orientation, op.set_diameter = "KEEP", True
        layout.separator()
        layout.operator(OPAL_OT_assign_grating.bl_idname, text="Assign from View").direction = "VIEW"
        layout.operator(OPAL_OT_assign_grating.bl_idname, text="Assign from Active Edge").direction = "ACTIVE_EDGE"
        op = layout.operator(OPAL_OT_assign_grating.bl_idname, text="Assign at Angle")
        op.direction = "ANGLE"
        op = layout.operator(OPAL_OT_assign_grating.bl_idname, text="Rotate 90\u00b0")
        op.direction, op.angle, op.new_domain = "ROTATE", math.pi / 2, False
        op = layout.operator(OPAL_OT_assign_grating.bl_idname, text="Set Period")
        op.direction, op.set_period, op.new_domain = "KEEP", True, False
        layout.operator(OPAL_OT_jitter_period.bl_idname)
        layout.separator()
        layout.operator(OPAL_OT_split_domain.bl_idname)
        layout.operator(OPAL_OT_merge_domains.bl_idname)
        layout.operator(OPAL_OT_select_domain.bl_idname)
        layout.separator()
        layout.operator(OPAL_OT_generate_domains.bl_idname)
        layout.operator(OPAL_OT_update_preview.bl_idname)


class VIEW3D_PT_opal_tools(bpy.types.Panel):
    """The opal tools in the 3D View's sidebar (N), tab "Opal"."""

    bl_idname = "VIEW3D_PT_opal_tools"
    bl_label = "Opal"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Opal"

    @classmethod
    def poll(cls, context):
        return context.mode in ("OBJECT", "EDIT_MESH")

    def draw(self, context):
        layout = self.layout
        ob = context.active_object
        if context.mode == "OBJECT":
            layout.operator(MESH_OT_primitive_opal_add.bl_idname, icon="MESH_UVSPHERE")
        if ob is None or ob.type != "MESH":
            return
        mat = ob.active_material
        if mat is not None:
            row = layout.row(align=True)
            row.label(text=mat.name, icon="MATERIAL")
            row.context_pointer_set("material", mat)  # the presets run on bpy.context.material
            row.menu("OPAL_MT_opal_presets", text="", icon="PRESET")
        layout.operator(OPAL_OT_generate_domains.bl_idname, icon="MOD_TRIANGULATE")
        layout.operator(OPAL_OT_update_preview.bl_idname, icon="COLOR")
        if context.mode != "EDIT_MESH":
            layout.label(text="Edit Mode: set the domains of faces", icon="INFO")
            return
        col = layout.column(align=True)
        col.label(text="Volume Domains of the Selected Faces")
        col.operator(OPAL_OT_set_domain.bl_idname, text="Face the Surface").orientation = "NORMAL"
        col.operator(OPAL_OT_set_domain.bl_idname, text="Face the View").orientation = "VIEW"
        op = col.operator(OPAL_OT_set_domain.bl_idname, text="Set Sphere Diameter")
        op.orientation, op.set_diameter = "KEEP", True
        col = layout.column(align=True)
        col.label(text="Selected Faces")
        col.operator(OPAL_OT_assign_grating.bl_idname, text="Direction from View").direction = "VIEW"
        col.operator(OPAL_OT_assign_grating.bl_idname, text="Direction from Active Edge").direction = "ACTIVE_EDGE"
        col.operator(OPAL_OT_assign_grating.bl_idname, text="Direction at Angle").direction = "ANGLE"
        op = col.operator(OPAL_OT_assign_grating.bl_idname, text="Rotate 90\u00b0")
        op.direction, op.angle, op.new_domain = "ROTATE", math.pi / 2, False
        col = layout.column(align=True)
        op = col.operator(OPAL_OT_assign_grating.bl_idname, text="Set Period")
        op.direction, op.set_period, op.new_domain = "KEEP", True, False
        col.operator(OPAL_OT_jitter_period.bl_idname)
        col = layout.column(align=True)
        col.operator(OPAL_OT_split_domain.bl_idname)
        col.operator(OPAL_OT_merge_domains.bl_idname)
        col.operator(OPAL_OT_select_domain.bl_idname)


def _menu_edit_faces(self, context):
    self.layout.separator()
    self.layout.menu(VIEW3D_MT_opal_edit.bl_idname)


def _menu_object(self, context):
    if is_mesh(context):
        self.layout.separator()
        self.layout.operator(OPAL_OT_generate_domains.bl_idname)
        self.layout.operator(OPAL_OT_update_preview.bl_idname)


#: The menu and panel classes, in registration order.
menus = (VIEW3D_MT_opal_edit, VIEW3D_PT_opal_tools)


def append_menus() -> None:
    """Add the opal entries to Blender's Add Mesh, Edit Mode Face and Object menus."""
    bpy.types.VIEW3D_MT_mesh_add.append(_menu_add)
    bpy.types.VIEW3D_MT_edit_mesh_faces.append(_menu_edit_faces)
    bpy.types.VIEW3D_MT_object.append(_menu_object)


def remove_menus() -> None:
    bpy.types.VIEW3D_MT_object.remove(_menu_object)
    bpy.types.VIEW3D_MT_edit_mesh_faces.remove(_menu_edit_faces)
    bpy.types.VIEW3D_MT_mesh_add.remove(_menu_add)
