"""The Blender layer: everything that touches bpy (the core never imports it).

    properties  scene.opal and material.opal (the Blender-facing contract)
    export      depsgraph -> core Scene
    engine      the OPAL_DIFFRACTION render engine
    operators   export to .npz, dispersion presets
    opal_presets  opal and glass presets through Blender's preset system (shipped in ../presets)
    opal_domains  an object's opal volume domains, stored in object space
    opal        Add Opal, volume and grating domains, Edit Mode tools (opal_ops: its former name)
    mesh_io     mesh data -> NumPy, the face attributes the opal tools and the exporter share
    viewport    the engine's rendered viewport (progressive, drawn with the gpu module)
    ui          panels, and Blender's own panels enabled for the engine
"""

from __future__ import annotations

from . import engine, opal, opal_presets, operators, properties, ui

__all__ = ["register", "unregister"]

_modules = (properties, engine, operators, opal_presets, opal, ui)


def register():
    for m in _modules:
        m.register()


def unregister():
    for m in reversed(_modules):
        m.unregister()
