"""Blender materials -> the core's material table: one row per material used, in first-use order.

A row's surface comes from the material's shader nodes (:mod:`.nodes`); without a node tree,
from its viewport colour, like Workbench. ``material.opal`` adds what Blender has no slot for:
dispersion (on glass-like surfaces only) and the diffraction grating, whose impossible settings
are an error naming the material. Blender's default surface (no material, or an empty slot) is
grey diffuse, as in Cycles.

What Cycles would not render either is black, as in Cycles, with a warning saying why (no output
node for Cycles, e.g. one that targets EEVEE only; nothing on Surface). A material's Volume
output becomes the homogeneous medium inside its surface (:mod:`.volumes`; docs/physics.md
section 15); a volume-only material's surface is a null boundary (a smooth dielectric of index 1:
Cycles draws no surface for it). A node cycle renders as the default surface, and NaN values are
an error naming the material.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...core.scene.model import Materials
from ...core.scene.shader_programs import BUMP_SLOTS, NORMAL_MAP_SLOTS
from ...core.scene.checks import SceneError
from .colour import in_rec709, rgb, working_space_to_rec709
from .images import TextureTable
from .messages import Warnings
from .meshes import is_surface_instance
from .nodes import MAX_INTENSITY, NodeReader, Surface, missing_output, node_tree, output_node
from .volumes import read_volume

__all__ = ["DEFAULT_MATERIAL", "MaterialTable", "CornerSpec", "export_materials"]

#: The largest IOR exported (larger ones are lowered, with a warning): Blender accepts up to
#: FLT_MAX, whose square overflows the tracer's float32 Fresnel terms.
MAX_IOR = 1000.0

#: Blender's default surface (no material, or an empty slot): grey diffuse, as in Cycles.
DEFAULT_MATERIAL = {"name": "(default surface)", "kind": "DIFFUSE", "color": (0.8, 0.8, 0.8)}


@dataclass(frozen=True)
class CornerSpec:
    """The per-corner data a textured material reads from its meshes: texture coordinates from
    a UV map (``uv_map``, '' for the active render map) or Generated (object space over the
    mesh's texture space), with a Mapping's 4x4 affine folded in (``matrix``, 16 floats, row
    major), and for a normal map the UV map of its tangents (``tangent_map``; None: none)."""

    coords: str
    uv_map: str
    matrix: tuple
    tangent_map: str | None

    def affine(self) -> np.ndarray:
        return np.array(self.matrix, np.float64).reshape(4, 4)


_TEXTURE_COLUMN = {"color": "color_texture", "roughness": "roughness_texture", "metallic": "metallic_texture",
                   "emission": "emission_texture", "normal": "normal_texture"}


class MaterialTable:
    """Material rows for the core, one per Blender material used, in first-use order."""

    def __init__(self, warn: Warnings, to709):
        self.rows: list[dict] = []
        self.index: dict[str, int] = {}
        self.grating: list[dict | None] = []  # per row: grating settings or None
        self.hidden: set[int] = set()  # rows whose faces are left out (volume-only materials)
        self.warn, self.to709 = warn, to709
        self.textures = TextureTable(warn)  # the images the rows' texture columns number
        self.corners: list[CornerSpec | None] = []  # per row: what its textures read from meshes
        self.programs: list = []  # the shader programs the rows' shader_program column numbers
        self.program_reads: list[frozenset] = []  # per row: the coordinates its program reads
        self._compiler = None
        self._volume = None  # the medium columns _surface read for the row _convert makes (export/volumes.py)

    def lookup(self, material) -> int:
        key = "\0default" if material is None else material.name_full  # unique across linked libraries
        if key in self.index:
            return self.index[key]
        row, grating = (dict(DEFAULT_MATERIAL), None) if material is None else self._convert(material)
        self.index[key] = len(self.rows)
        self.corners.append(row.pop("_corners", None))
        self.program_reads.append(row.pop("_program_reads", frozenset()))
        self.rows.append(row)
        self.grating.append(grating)
        return self.index[key]

    def corner_needs(self, slots) -> frozenset:
        """What meshes with these material rows must provide: ('UV', map) / ('GENERATED', '') /
        ('TANGENT', map) items (map '': the active render UV map)."""
        needs = set()
        for r in slots:
            for kind in self.program_reads[r]:  # a shader program's coordinates and attributes
                if kind.startswith("attribute:"):
                    needs.add(("ATTRIBUTE", kind.split(":", 1)[1]))
                    continue
                needs.add(("GENERATED" if kind == "generated" else "OBJECT", "") if kind != "uv" else ("UV", ""))
            spec = self.corners[r]
            if spec is None:
                continue
            needs.add((spec.coords, spec.uv_map if spec.coords == "UV" else ""))
            if spec.tangent_map is not None:
                needs.add(("TANGENT", spec.tangent_map))
        return frozenset(needs)

    def _texture_columns(self, surf: Surface, owner: str) -> dict:
        """The row's texture columns from ``surf.textures`` and its CornerSpec (key '_corners',
        taken off by :meth:`lookup`): one set of coordinates per material, the colour's first (a
        material whose textures read different coordinates is warned and uses those; UV before
        Generated)."""
        refs = {slot: ref for slot, ref in surf.textures.items()
                if (slot == "emission" and ref.strength > 0) or (slot != "emission" and surf.kind is not None)}
        if not refs:
            return {}
        cols = {_TEXTURE_COLUMN[slot]: ref.index for slot, ref in refs.items()}
        if "emission" in refs:
            cols["emission_strength"] = float(refs["emission"].strength)
        if "normal" in refs:
            cols["normal_strength"] = float(refs["normal"].strength)
        for slot in ("roughness", "metallic"):
            if slot in refs and refs[slot].channel >= 0:
                cols[f"{slot}_channel"] = int(refs[slot].channel)
        order = [refs[s] for s in ("color", "emission", "roughness", "metallic", "normal") if s in refs]
        uv = [r for r in order if r.coords == "UV"]
        first = uv[0] if uv else order[0]
        others = [r for r in order if not r.same_coordinates(first)]
        if others:
            self.warn(f"{owner}: its image textures use different coordinates ('{others[0].node}' and "
                      f"'{first.node}'): all read those of '{first.node}'")
        tangent = refs["normal"].tangent_map if "normal" in refs else None
        cols["_corners"] = CornerSpec(first.coords, first.uv_map, tuple(first.matrix.reshape(-1).tolist()), tangent)
        return cols

    def _program_columns(self, surf: Surface, owner: str, row: dict) -> dict:
        """The row's shader_program column (and an emission program's strength) from
        ``surf.programs``; keys '_program_reads' (taken off by :meth:`lookup`) and '_corners'
        (a program reading UVs on a material without image textures: the UV map, unmapped)."""
        compiler, self._compiler = self._compiler, None
        progs = {k: v for k, v in surf.programs.items() if k in ("color", "roughness", "metallic", "emission", "mix")
                 + BUMP_SLOTS + NORMAL_MAP_SLOTS}
        if surf.kind is None:
            progs = {k: v for k, v in progs.items() if k == "emission"}
        if not progs or compiler is None:
            return {}
        program = compiler.finish(progs)
        out = {"shader_program": len(self.programs),
               "_program_reads": program.reads() | {"attribute:" + a for a in program.attributes()}}
        self.programs.append(program)
        if "emission" in progs:
            strength = float(surf.programs.get("emission_strength", 1.0))
            out["emission_strength"] = strength
            if not any(row["emission"]):  # emissive however dark its average: the program decides per hit
                out["emission"] = (1e-6 * strength,) * 3
        tangent_map = surf.programs.get("_tangent_map") if "normalmap_tangent" in progs else None
        if tangent_map is not None:  # a tangent-space normal map's colour from the program: its UV map's tangents
            spec = row.get("_corners")
            if spec is None:
                out["_corners"] = CornerSpec("UV", tangent_map, tuple(np.eye(4).reshape(-1).tolist()), tangent_map)
            elif spec.tangent_map is None:
                out["_corners"] = CornerSpec(spec.coords, spec.uv_map, spec.matrix, tangent_map)
        if "uv" in program.reads():
            maps = compiler.uv_maps - {""}
            if len(maps) > 1:
                self.warn(f"{owner}: its shader program reads several UV maps: all read '{sorted(maps)[0]}'")
            uv_map = sorted(maps)[0] if maps else ""
            have = out.get("_corners", row.get("_corners"))
            if have is None:
                out["_corners"] = CornerSpec("UV", uv_map, tuple(np.eye(4).reshape(-1).tolist()), None)
            elif have.coords != "UV" or not np.allclose(have.affine(), np.eye(4)):
                self.warn(f"{owner}: its shader program reads UVs and its image textures other coordinates: the "
                          "program reads those of the image textures")
        return out

    def slots(self, ob) -> tuple[int, ...]:
        """Row of each of ``ob``'s material slots (the default surface for no slot or an empty one)."""
        return tuple(self.lookup(s.material) for s in ob.material_slots) or (self.lookup(None),)

    def world_medium(self, columns: dict) -> int:
        """A row holding the world's medium (``Scene.world_volume``; no face uses it)."""
        self.rows.append({"name": "(world volume)", "kind": "DIFFUSE", **columns})
        self.corners.append(None)
        self.program_reads.append(frozenset())
        self.grating.append(None)
        return len(self.rows) - 1

    def finish(self) -> Materials:
        """The core's material table (the default surface alone when no material is used)."""
        if not self.rows:
            self.lookup(None)
        return Materials.from_list(self.rows)

    def _convert(self, mat) -> tuple[dict, dict | None]:
        owner = f"material '{mat.name}'"
        surf = self._surface(mat, owner)
        if surf is None:  # no node tree: the viewport colour, like Workbench
            col = in_rec709(rgb(mat.diffuse_color), self.to709)
            if np.isnan(col).any():
                raise SceneError(f"{owner}: its viewport colour is NaN")
            metallic = min(max(float(mat.metallic), 0.0), 1.0)
            surf = Surface("MIRROR" if metallic >= 0.5 else "DIFFUSE", np.minimum(col, MAX_INTENSITY),
                           roughness=min(max(float(mat.roughness), 0.0), 1.0), metallic=metallic, transmission=0.0,
                           conductor_fresnel="F82_TINT")
        volume, self._volume = self._volume, None
        kind = surf.kind or "DIFFUSE"
        color = surf.color if surf.kind is not None else np.zeros(3)
        metallic, transmission = surf.layers() if surf.kind is not None else (0.0, 0.0)
        row = {
            "name": mat.name[:63],
            "kind": kind,
            "color": tuple(float(c) for c in np.clip(color, 0.0, None)),
            "ior": float(surf.ior),
            "emission": tuple(float(c) for c in np.clip(surf.emission, 0.0, None)),
            "roughness": float(np.clip(surf.roughness, 0.0, 1.0)),
            "metallic": float(np.clip(metallic, 0.0, 1.0)),
            "transmission": float(np.clip(transmission, 0.0, 1.0)),
            "specular_ior_level": float(max(surf.specular_ior_level, 0.0)) if surf.kind is not None else 0.0,
            "specular_tint": tuple(float(c) for c in np.clip(surf.specular_tint, 0.0, MAX_INTENSITY)),
            "conductor_fresnel": surf.conductor_fresnel,
            "glass_tint": surf.glass_tint,
            "thin_film_thickness": float(surf.thin_film_thickness) if surf.kind is not None else 0.0,
            "thin_film_ior": float(surf.thin_film_ior),
            "diffuse_roughness": float(np.clip(surf.diffuse_roughness, 0.0, 1.0)) if surf.kind is not None else 0.0,
            "holdout": float(np.clip(surf.holdout, 0.0, 1.0)),
        }
        if surf.kind is not None and (surf.coat_weight > 0 or surf.sheen_weight > 0):  # section 14.10
            row.update(coat_weight=float(np.clip(surf.coat_weight, 0.0, 1.0)),
                       coat_roughness=float(np.clip(surf.coat_roughness, 0.0, 1.0)), coat_ior=float(surf.coat_ior),
                       coat_tint=tuple(float(c) for c in np.clip(surf.coat_tint, 0.0, MAX_INTENSITY)),
                       sheen_weight=float(np.clip(surf.sheen_weight, 0.0, 1.0)),
                       sheen_roughness=float(np.clip(surf.sheen_roughness, 0.0, 1.0)),
                       sheen_tint=tuple(float(c) for c in np.clip(surf.sheen_tint, 0.0, MAX_INTENSITY)))
        if surf.kind is not None:  # a shader mix of unlike BSDFs (docs/physics.md section 14.8)
            for name in ("metal_color", "glass_color"):
                col = getattr(surf, name)
                if col is not None:
                    row[name] = tuple(float(c) for c in np.clip(col, 0.0, MAX_INTENSITY))
            if surf.layer_fac != "CONSTANT":
                row.update(layer_fac=surf.layer_fac, layer_fac_value=float(surf.layer_fac_value),
                           layer_fac_from=int(surf.layer_fac_from), layer_fac_to=int(surf.layer_fac_to))
        if volume is not None:  # the medium inside (docs/physics.md section 15)
            row.update(volume)
        row.update(self._texture_columns(surf, owner))
        row.update(self._program_columns(surf, owner, row))
        opal = getattr(mat, "opal", None)
        uses_ior = kind == "DIELECTRIC" or row["transmission"] > 0 or row["specular_ior_level"] > 0
        if uses_ior:
            if surf.ior != surf.ior:
                raise SceneError(f"{owner}: its IOR is NaN")
            if not surf.ior >= 1.0:
                self.warn(f"{owner}: IOR {surf.ior:g} below 1 is raised to 1")
                row["ior"] = 1.0
            elif surf.ior > MAX_IOR:
                self.warn(f"{owner}: IOR {surf.ior:.3g} above {MAX_IOR:g} is lowered to {MAX_IOR:g}")
                row["ior"] = MAX_IOR
        if kind == "DIELECTRIC":  # dispersion: where glass is the heaviest layer (the transport's split)
            if opal is not None:
                row["dispersion"] = opal.dispersion
                row["abbe"] = float(opal.abbe_number)
                if opal.dispersion == "ABBE" and not 0.0 < opal.abbe_number < float("inf"):
                    raise SceneError(f"{owner}: the Abbe number must be a positive number (got {opal.abbe_number:g})")
        elif opal is not None and opal.dispersion != "NONE":
            self.warn(f"{owner}: dispersion is set but the surface is not glass-like: dispersion ignored")
        grating = None
        if opal is not None and opal.grating:
            problems = opal.grating_problems()
            if problems:
                raise SceneError(f"{owner}: " + "; ".join(problems))
            grating = {
                "grating": 1, "grating_type": opal.grating_type, "lattice": opal.lattice,
                "period": float(opal.period), "slit_width": float(opal.slit_width),
                "slit_count": int(opal.slit_count), "coherence_length": float(opal.coherence_length),
                "grating_direction": opal.grating_direction,
                # one turn at most (Blender accepts up to FLT_MAX radians, whose float32 sine is noise)
                "rotation": math.remainder(float(opal.rotation), math.tau),
                # the BRAGG lattice's columns (docs/physics.md section 5.2)
                "sphere_diameter": float(opal.sphere_diameter), "sphere_ior": float(opal.sphere_ior),
                "void_ior": float(opal.void_ior), "layers": int(opal.layers),
                "mosaic_spread": float(opal.mosaic_spread),
            }
            row.update(grating)
        return row, grating

    def _surface(self, mat, owner: str) -> Surface | None:
        """The Surface of ``mat``'s node tree (None: it has none, use the viewport colour). A tree
        Cycles cannot render either (no output node for Cycles, nothing on Surface) is black, as
        in Cycles, with a warning saying why; a volume-only material is a null boundary (its medium is
        kept for _convert); a node cycle gives
        the default surface."""
        nt = node_tree(mat)
        if nt is None:
            return None
        out = output_node(nt)
        if out is None:
            self.warn(f"{owner}: {missing_output(nt)}: rendered black, as in Cycles")
            return Surface(None, np.zeros(3))
        sock = out.inputs.get("Surface")
        reader = NodeReader(owner, self.warn, self.to709, self.textures)
        surf = reader.surface(sock) if sock is not None else Surface(None, np.zeros(3))
        self._compiler = reader.compiler  # the shader program's, read by _program_columns
        if reader.cycle is not None:
            self.warn(f"{owner}: its node tree has a cycle (through the link {reader.cycle}, drawn red in the node "
                      "editor): rendered as the default surface (grey diffuse)")
            return Surface("DIFFUSE", np.array(DEFAULT_MATERIAL["color"], np.float64))
        vol = out.inputs.get("Volume")
        has_surface = sock is not None and reader.source(sock) is not None
        # the medium inside the surface (docs/physics.md section 15; export/volumes.py)
        vreader = NodeReader(owner, self.warn, self.to709)
        self._volume = read_volume(vreader, vol) if vol is not None and vreader.source(vol) is not None else None
        if vreader.cycle is not None:
            self.warn(f"{owner}: its volume's nodes have a cycle (through the link {vreader.cycle}): no volume")
            self._volume = None
        if self._volume is not None and not has_surface:
            # Cycles draws no surface for a material with only a Volume shader: rays cross the
            # boundary unchanged and only the medium inside scatters, absorbs or emits. The
            # tracer's null boundary is a smooth dielectric of index 1 (no reflection, no bending)
            return Surface("DIELECTRIC", np.ones(3), ior=1.0)
        if not has_surface:            self.warn(f"{owner}: nothing is connected to the Surface of '{out.name}': rendered black, as in Cycles")
        return surf

    def hidden_rows(self) -> np.ndarray:
        """Per material row: whether its faces are left out of the scene (volume-only materials)."""
        hidden = np.zeros(len(self.rows), bool)
        hidden[list(self.hidden)] = True
        return hidden


def export_materials(depsgraph, warn: Warnings | None = None) -> Materials:
    """The core's material table alone, row for row the one :func:`export_scene` makes (the same
    instance order, so a cached scene's ``tri_material`` still indexes it). ``warn``: collects the
    warnings (default: dropped)."""
    table = MaterialTable(warn if warn is not None else Warnings(), working_space_to_rec709())
    for inst in depsgraph.object_instances:
        if is_surface_instance(inst):
            table.slots(inst.object)
    return table.finish()
