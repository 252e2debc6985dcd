"""The opal tools in Blender: Add Opal, grating domains, and interactive grating placement in Edit Mode.

    attributes  a mesh's faces <-> arrays, the per-face grating attributes and preview colours
    operators   Add Opal, Generate Domains, the Edit Mode grating operators, Update Preview
    volume_ops  volume (BRAGG) domains: generation, the Bragg-colour preview, Set Domain
    ui          the Add Mesh, Face and Object menu entries and the sidebar's "Opal" tab

The logic lives in :mod:`opal_diffraction.core.opal` (pure NumPy on mesh arrays); these modules
only read meshes into arrays, call it, and write the results back as mesh attributes. The
'Aligned' direction mode is the source paper's model (Kobayashi & Kawai, docs/physics.md
section 5.1).
"""

from __future__ import annotations

import bpy

from .attributes import (
    DIRECTION_ATTRIBUTE,
    DOMAIN_ATTRIBUTE,
    PERIOD_ATTRIBUTE,
    PREVIEW_ATTRIBUTE,
    FaceData,
    read_faces,
    show_preview,
    write_field,
)
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
    operators,
)
from .ui import VIEW3D_MT_opal_edit, VIEW3D_PT_opal_tools, append_menus, menus, remove_menus

__all__ = [
    "DIRECTION_ATTRIBUTE", "PERIOD_ATTRIBUTE", "DOMAIN_ATTRIBUTE", "PREVIEW_ATTRIBUTE",
    "FaceData", "read_faces", "write_field", "show_preview",
    "MESH_OT_primitive_opal_add", "OPAL_OT_generate_domains", "OPAL_OT_assign_grating", "OPAL_OT_jitter_period",
    "OPAL_OT_split_domain", "OPAL_OT_merge_domains", "OPAL_OT_select_domain", "OPAL_OT_update_preview",
    "OPAL_OT_set_domain", "VIEW3D_MT_opal_edit", "VIEW3D_PT_opal_tools", "classes",
    "register", "unregister",
]

#: Every class to register, operators first.
classes = operators + menus


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    append_menus()


def unregister():
    remove_menus()
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
