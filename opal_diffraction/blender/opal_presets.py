"""Opal and glass presets through Blender's preset system (as Cycles' sampling presets).

A preset is a Python file of ``opal.<property> = value`` lines (``opal`` being
``bpy.context.material.opal``), run by ``script.execute_preset``; *Add Preset* (the + in the
menu) writes the material's current values to the user's ``scripts/presets/<subdir>`` with
``bl_operators.presets.AddPresetBase`` and - removes them. The shipped presets are read from
the extension's own folder (``opal_diffraction/presets/{opal,glass}``, read-only: a user preset
of the same name is listed beside it, and shipped ones cannot be removed).

The body tone lives in the material's Principled BSDF; the presets set it through
``material.opal.body_color`` / ``body_roughness`` / ``body_transmission`` / ``node_ior``,
properties without storage that read and write the node (blender/properties.py).

Opal presets (each file states its physics in its header; docs/opal.md has the table; the files
are written from one table by tools/opal_presets.py, and tests/opal/test_opal_presets.py checks them):

- Black, White, Crystal, Boulder, Harlequin (few large domains), Pinfire (many small): the BRAGG
  lattice (FCC opal, docs/physics.md section 5.2) - sphere diameter D_s and its spread, the void
  index (water 1.33, silica cement 1.40, air 1.0), ordered layers, mosaic spread, and the
  volume-domain layout Add Opal / Generate Domains use (count, size spread, orientation).
- Paper Model: the source paper's surface grating (Kobayashi & Kawai, docs/physics.md section
  5.1), LINES, one aligned domain, 550 nm.

Glass presets: the named glasses of the Dispersion panel (dispersion model, Abbe number, n_d
set on the material's BSDF nodes).
"""

from __future__ import annotations

import ast
import os

import bpy
from bl_operators.presets import AddPresetBase
from bpy.props import EnumProperty
from bpy.types import Menu, Operator

__all__ = [
    "OPAL_SUBDIR", "GLASS_SUBDIR", "SHIPPED", "OPAL_PRESET_VALUES", "GLASS_PRESET_VALUES",
    "preset_files", "read_preset", "preset_file", "apply_preset", "new_opal_material", "PRESET_ITEMS",
    "OPAL_OT_opal_preset", "OPAL_OT_opal_preset_add", "OPAL_OT_glass_preset_add", "OPAL_MT_opal_presets",
    "OPAL_MT_glass_presets", "register", "unregister",
]

#: Preset subfolders (of the user's scripts/presets and of SHIPPED).
OPAL_SUBDIR = "opal_diffraction/opal"
GLASS_SUBDIR = "opal_diffraction/glass"
#: The shipped presets: <package>/presets/opal, <package>/presets/glass.
SHIPPED = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "presets")

#: What an opal preset saves (material.opal's names: the grating, the BRAGG lattice, the
#: volume-domain layout, the body through the Principled BSDF).
OPAL_PRESET_VALUES = [
    "opal.grating", "opal.grating_type", "opal.lattice", "opal.grating_direction", "opal.rotation", "opal.period",
    "opal.slit_width", "opal.slit_count", "opal.coherence_length",
    "opal.sphere_diameter", "opal.sphere_ior", "opal.void_ior", "opal.layers", "opal.mosaic_spread",
    "opal.domain_count", "opal.domain_size_spread", "opal.domain_orientation", "opal.domain_axis_spread",
    "opal.diameter_spread",
    "opal.body_color", "opal.body_roughness", "opal.body_transmission", "opal.node_ior", "opal.dispersion",
]
GLASS_PRESET_VALUES = ["opal.dispersion", "opal.abbe_number", "opal.node_ior"]


def _shipped_dir(subdir: str) -> str:
    return os.path.join(SHIPPED, subdir.rsplit("/", 1)[-1])


def preset_files(subdir: str = OPAL_SUBDIR) -> dict[str, str]:
    """{display name: path} of the presets in ``subdir``: shipped first, then the user's."""
    out = {}
    for d in [_shipped_dir(subdir)] + list(bpy.utils.preset_paths(subdir)):
        if not os.path.isdir(d):
            continue
        for f in sorted(os.listdir(d)):
            if f.endswith(".py") and not f.startswith("_"):
                out.setdefault(bpy.path.display_name(f[:-3], title_case=False), os.path.join(d, f))
    return out


def read_preset(path: str) -> dict:
    """The ``opal.<name> = literal`` assignments of a preset file, without running it."""
    out = {}
    with open(path, encoding="utf-8") as fh:
        tree = ast.parse(fh.read(), path)
    for node in tree.body:
        if (isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Attribute)
                and isinstance(node.targets[0].value, ast.Name) and node.targets[0].value.id == "opal"):
            out[node.targets[0].attr] = ast.literal_eval(node.value)
    return out


def _ident(name: str) -> str:
    return name.split(" ")[0].upper()  # "Black" -> BLACK, "Paper Model" -> PAPER


def preset_file(ident_or_name: str, subdir: str = OPAL_SUBDIR) -> str:
    """The file of a preset given by its identifier (BLACK) or display name (Black)."""
    files = preset_files(subdir)
    for name, path in files.items():
        if ident_or_name in (name, _ident(name)):
            return path
    raise KeyError(f"no preset {ident_or_name!r} (have {sorted(files)})")


def apply_preset(mat, ident_or_name: str, subdir: str = OPAL_SUBDIR) -> str:
    """Run a preset on ``mat`` (as the preset menu does on the active material); its path."""
    path = preset_file(ident_or_name, subdir)
    with bpy.context.temp_override(material=mat):
        bpy.utils.execfile(path)
    return path


def new_opal_material(ident: str = "BLACK"):
    """A new material named after the opal preset, with the preset applied."""
    name = next(n for n in preset_files() if ident in (n, _ident(n)))
    mat = bpy.data.materials.new(f"Opal ({name})")
    apply_preset(mat, ident)
    return mat


#: The shipped opal presets' order in menus: the physical opals, then the paper's grating.
_ORDER = ("Black", "White", "Crystal", "Boulder", "Harlequin", "Pinfire", "Paper Model")


def _shipped_items():
    d = _shipped_dir(OPAL_SUBDIR)
    names = [bpy.path.display_name(f[:-3], title_case=False) for f in os.listdir(d) if f.endswith(".py")]
    names.sort(key=lambda n: (_ORDER.index(n) if n in _ORDER else len(_ORDER), n))
    out = []
    for i, n in enumerate(names):
        with open(os.path.join(d, n.replace(" ", "_") + ".py"), encoding="utf-8") as fh:
            first = fh.readline().lstrip("# ").strip()
        out.append((_ident(n), n, first[:200], i))
    return out


#: EnumProperty items of the shipped opal presets (identifier, name, description, index).
PRESET_ITEMS = _shipped_items()


def _target_material(context):
    mat = getattr(context, "material", None)
    if mat is None:
        ob = getattr(context, "object", None)
        mat = getattr(ob, "active_material", None) if ob is not None else None
    return mat


class OPAL_OT_opal_preset(Operator):
    """Apply a shipped opal preset to the material (body, lattice, volume-domain layout)"""

    bl_idname = "opal.opal_preset"
    bl_label = "Opal Preset"
    bl_options = {"REGISTER", "UNDO"}

    preset: EnumProperty(name="Preset", items=PRESET_ITEMS, default="BLACK")

    @classmethod
    def poll(cls, context):
        return _target_material(context) is not None

    def execute(self, context):
        mat = _target_material(context)
        apply_preset(mat, self.preset)
        self.report({"INFO"}, f"{mat.name}: {self.preset.title()}")
        return {"FINISHED"}


class _PresetMenu(Menu):
    """A preset menu over the shipped folder and the user's presets, with + / - (Menu.draw_preset
    searches only the script paths)."""

    preset_operator = "script.execute_preset"

    def draw(self, context):
        dirs = [_shipped_dir(self.preset_subdir)] + list(bpy.utils.preset_paths(self.preset_subdir))
        self.path_menu(dirs, self.preset_operator, filter_ext=lambda ext: ext.lower() == ".py",
                       add_operator=self.preset_add_operator,
                       display_name=lambda name: bpy.path.display_name(name, title_case=False))


class OPAL_MT_opal_presets(_PresetMenu):
    bl_label = "Opal Presets"
    bl_idname = "OPAL_MT_opal_presets"
    preset_subdir = OPAL_SUBDIR
    preset_add_operator = "opal.opal_preset_add"


class OPAL_MT_glass_presets(_PresetMenu):
    bl_label = "Glass Presets"
    bl_idname = "OPAL_MT_glass_presets"
    preset_subdir = GLASS_SUBDIR
    preset_add_operator = "opal.glass_preset_add"


class _MaterialPresetAdd(AddPresetBase):
    preset_defines = ["opal = bpy.context.material.opal"]

    @classmethod
    def poll(cls, context):
        return getattr(context, "material", None) is not None


class OPAL_OT_opal_preset_add(_MaterialPresetAdd, Operator):
    """Add (or remove) an opal preset: the material's grating, Bragg lattice, domain layout and body"""

    bl_idname = "opal.opal_preset_add"
    bl_label = "Add Opal Preset"
    preset_menu = "OPAL_MT_opal_presets"
    preset_subdir = OPAL_SUBDIR
    preset_values = OPAL_PRESET_VALUES


class OPAL_OT_glass_preset_add(_MaterialPresetAdd, Operator):
    """Add (or remove) a glass preset: the material's dispersion, Abbe number and IOR"""

    bl_idname = "opal.glass_preset_add"
    bl_label = "Add Glass Preset"
    preset_menu = "OPAL_MT_glass_presets"
    preset_subdir = GLASS_SUBDIR
    preset_values = GLASS_PRESET_VALUES


classes = (OPAL_OT_opal_preset, OPAL_OT_opal_preset_add, OPAL_OT_glass_preset_add, OPAL_MT_opal_presets,
           OPAL_MT_glass_presets)


register, unregister = bpy.utils.register_classes_factory(classes)
