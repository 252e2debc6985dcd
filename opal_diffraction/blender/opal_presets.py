"""Opal material presets: "Paper model", "Precious opal", "Black opal", "Crystal opal".

A preset sets a material's body (a Principled BSDF: base colour, roughness, transmission, IOR,
which the exporter reads as a diffuse or glass base) and its grating layer (``material.opal``),
with the direction and period read from the per-face attributes the opal tools write
(``grating_direction = 'ATTRIBUTE'``; the material's period is the fall-back for faces without
one). Each preset also names the domain layout that suits it, which Add Opal uses:

- Paper model: the source paper's opal (Kobayashi & Kawai, docs/physics.md section 5.1), every
  triangle one grating, all oriented consistently (the object's X axis projected onto each
  face), one period; parallel slits.
- Precious opal: a milky body under domains of a hexagonal lattice (the close-packed silica
  spheres seen from the (111) face), periods from sphere diameters of 200-330 nm through the
  Bragg law (docs/physics.md section 5.2; air voids, and see section 5.5 for the hexagonal
  lattice's first orders); few coherent rows (24), so each lit domain flashes one
  colour over a broad range of angles.
- Black opal: the same lattice over a near-black body (dark potch), the most saturated colours.
- Crystal opal: the same lattice on a transparent body (glass, IOR 1.45).
"""

from __future__ import annotations

from dataclasses import dataclass

import bpy
from bpy.props import EnumProperty

__all__ = ["OpalPreset", "PRESETS", "PRESET_ITEMS", "apply_preset", "new_opal_material", "OPAL_OT_opal_preset",
           "OPAL_MT_opal_presets", "register", "unregister"]


@dataclass(frozen=True)
class OpalPreset:
    ident: str
    name: str
    description: str
    # body (Principled BSDF)
    base_color: tuple
    roughness: float
    transmission: float
    ior: float
    # grating layer (material.opal)
    lattice: str
    period: float          # nm, the fall-back for faces without a period attribute
    slit_ratio: float      # slit width / period
    slit_count: int
    coherence_length: float  # um
    # domain layout for Add Opal / Generate Domains
    direction_mode: str    # 'RANDOM' | 'ALIGNED'
    domain_count: int
    period_mode: str       # 'SPHERES' | 'PERIOD'
    low: float             # sphere diameter (or period) range, nm
    high: float


PRESETS = {
    "PAPER": OpalPreset(
        "PAPER", "Paper model", "The source paper's opal: every triangle one grating, all oriented consistently "
        "(parallel slits, one period)", (0.12, 0.12, 0.13), 0.3, 0.0, 1.45, "LINES", 550.0, 0.5, 100, 2.0,
        "ALIGNED", 1, "PERIOD", 550.0, 550.0),
    "PRECIOUS": OpalPreset(
        "PRECIOUS", "Precious opal", "Milky body, domains of a hexagonal lattice with periods from silica sphere "
        "diameters (200-330 nm, Bragg law): Bragg-like patches of colour", (0.22, 0.23, 0.25), 0.3, 0.0, 1.45,
        "HEXAGONAL", 550.0, 0.5, 24, 0.5, "RANDOM", 400, "SPHERES", 200.0, 330.0),
    "BLACK": OpalPreset(
        "BLACK", "Black opal", "Near-black body under domains of a hexagonal lattice (sphere diameters 200-330 nm): "
        "the most saturated play of colour", (0.005, 0.005, 0.006), 0.3, 0.0, 1.45, "HEXAGONAL", 550.0, 0.5, 24,
        0.5, "RANDOM", 400, "SPHERES", 200.0, 330.0),
    "CRYSTAL": OpalPreset(
        "CRYSTAL", "Crystal opal", "Transparent body (glass, IOR 1.45) under domains of a hexagonal lattice "
        "(sphere diameters 200-330 nm)", (0.97, 0.97, 0.98), 0.02, 1.0, 1.45, "HEXAGONAL", 550.0, 0.5, 24, 0.5,
        "RANDOM", 400, "SPHERES", 200.0, 330.0),
}

#: EnumProperty items (identifier, name, description, stable index).
PRESET_ITEMS = [(p.ident, p.name, p.description, i) for i, p in enumerate(PRESETS.values())]


def _principled(mat):
    """The material's Principled BSDF feeding its output (created, with the output, if missing)."""
    if bpy.app.version < (5, 0, 0) and not mat.use_nodes:
        mat.use_nodes = True  # always on (and deprecated) from Blender 5.0
    nt = mat.node_tree
    out = nt.get_output_node("ALL") or nt.get_output_node("CYCLES")
    if out is None:
        out = nt.nodes.new("ShaderNodeOutputMaterial")
        out.location = (300, 0)
    sock = out.inputs["Surface"]
    if sock.is_linked and sock.links[0].from_node.bl_idname == "ShaderNodeBsdfPrincipled":
        return sock.links[0].from_node
    node = nt.nodes.new("ShaderNodeBsdfPrincipled")
    node.location = (0, 0)
    nt.links.new(node.outputs[0], sock)
    return node


def apply_preset(mat, ident: str) -> OpalPreset:
    """Set ``mat``'s body and grating layer to the preset ``ident`` (see PRESETS)."""
    p = PRESETS[ident]
    node = _principled(mat)
    node.inputs["Base Color"].default_value = (*p.base_color, 1.0)
    node.inputs["Roughness"].default_value = p.roughness
    node.inputs["Metallic"].default_value = 0.0
    trans = "Transmission Weight" if node.inputs.get("Transmission Weight") else "Transmission"
    node.inputs[trans].default_value = p.transmission
    node.inputs["IOR"].default_value = p.ior
    mat.diffuse_color = (*p.base_color, 1.0)  # Solid mode's material colour
    o = mat.opal
    o.grating = True
    o.grating_type = "REFLECTION"
    o.lattice = p.lattice
    o.period = p.period
    o.slit_width = p.period * p.slit_ratio
    o.slit_count = p.slit_count
    o.coherence_length = p.coherence_length
    o.grating_direction = "ATTRIBUTE"
    o.rotation = 0.0
    o.dispersion = "NONE"  # opal's silica disperses little; glass-like bodies refract at the node's IOR
    return p


def new_opal_material(ident: str = "BLACK"):
    """A new material named after the preset, with the preset applied."""
    mat = bpy.data.materials.new(f"Opal ({PRESETS[ident].name})")
    apply_preset(mat, ident)
    return mat


class OPAL_OT_opal_preset(bpy.types.Operator):
    """Set the material's body and diffraction grating to an opal preset (the grating direction and
    period come from the face attributes that Add Opal and Generate Domains write)"""

    bl_idname = "opal.opal_preset"
    bl_label = "Opal Preset"
    bl_options = {"REGISTER", "UNDO"}

    preset: EnumProperty(name="Preset", items=PRESET_ITEMS, default="BLACK")

    @classmethod
    def poll(cls, context):
        return _target_material(context) is not None

    def execute(self, context):
        mat = _target_material(context)
        p = apply_preset(mat, self.preset)
        self.report({"INFO"}, f"{mat.name}: {p.name}")
        return {"FINISHED"}


def _target_material(context):
    mat = getattr(context, "material", None)
    if mat is None:
        ob = getattr(context, "object", None)
        mat = getattr(ob, "active_material", None) if ob is not None else None
    return mat


class OPAL_MT_opal_presets(bpy.types.Menu):
    bl_label = "Opal Presets"
    bl_idname = "OPAL_MT_opal_presets"

    def draw(self, context):
        for ident, name, _desc, _i in PRESET_ITEMS:
            self.layout.operator(OPAL_OT_opal_preset.bl_idname, text=name).preset = ident


classes = (OPAL_OT_opal_preset, OPAL_MT_opal_presets)


register, unregister = bpy.utils.register_classes_factory(classes)
