"""Blender materials -> the core's material table: one row per material used, in first-use order.

A row's surface comes from the material's shader nodes (:mod:`.nodes`); without a node tree,
from its viewport colour, like Workbench. ``material.opal`` adds what Blender has no slot for:
dispersion (on glass-like surfaces only) and the diffraction grating, whose impossible settings
are an error naming the material. Blender's default surface (no material, or an empty slot) is
grey diffuse, as in Cycles.
"""

from __future__ import annotations

import numpy as np

from ...core.scene import Materials, SceneError
from .colour import in_rec709, rgb, working_space_to_rec709
from .messages import Warnings
from .meshes import is_surface_instance
from .nodes import ROUGH_AS_DIFFUSE, NodeReader, Surface, node_tree, surface_socket

__all__ = ["DEFAULT_MATERIAL", "MaterialTable", "export_materials"]

#: Blender's default surface (no material, or an empty slot): grey diffuse, as in Cycles.
DEFAULT_MATERIAL = {"name": "(default surface)", "kind": "DIFFUSE", "color": (0.8, 0.8, 0.8)}


class MaterialTable:
    """Material rows for the core, one per Blender material used, in first-use order."""

    def __init__(self, warn: Warnings, to709):
        self.rows: list[dict] = []
        self.index: dict[str, int] = {}
        self.grating: list[dict | None] = []  # per row: grating settings or None
        self.warn, self.to709 = warn, to709

    def lookup(self, material) -> int:
        key = "\0default" if material is None else material.name_full  # unique across linked libraries
        if key in self.index:
            return self.index[key]
        row, grating = (dict(DEFAULT_MATERIAL), None) if material is None else self._convert(material)
        self.index[key] = len(self.rows)
        self.rows.append(row)
        self.grating.append(grating)
        return self.index[key]

    def slots(self, ob) -> tuple[int, ...]:
        """Row of each of ``ob``'s material slots (the default surface for no slot or an empty one)."""
        return tuple(self.lookup(s.material) for s in ob.material_slots) or (self.lookup(None),)

    def finish(self) -> Materials:
        """The core's material table (the default surface alone when no material is used)."""
        if not self.rows:
            self.lookup(None)
        return Materials.from_list(self.rows)

    def _convert(self, mat) -> tuple[dict, dict | None]:
        owner = f"material '{mat.name}'"
        reader = NodeReader(owner, self.warn, self.to709)
        nt = node_tree(mat)
        surf = None
        if nt is not None:
            sock = surface_socket(nt)
            if sock is not None:
                surf = reader.surface(sock)
            else:
                self.warn(f"{owner}: no Material Output node: rendered black")
                surf = Surface(None, np.zeros(3))
        if surf is None:  # no node tree: the viewport colour, like Workbench
            col = in_rec709(rgb(mat.diffuse_color), self.to709)
            surf = Surface("MIRROR" if mat.metallic >= 0.5 and mat.roughness < ROUGH_AS_DIFFUSE else "DIFFUSE", col)
        kind = surf.kind or "DIFFUSE"
        color = surf.color if surf.kind is not None else np.zeros(3)
        row = {
            "name": mat.name[:63],
            "kind": kind,
            "color": tuple(float(c) for c in np.clip(color, 0.0, None)),
            "ior": float(surf.ior),
            "emission": tuple(float(c) for c in np.clip(surf.emission, 0.0, None)),
        }
        opal = getattr(mat, "opal", None)
        if kind == "DIELECTRIC":
            if not surf.ior >= 1.0:
                self.warn(f"{owner}: IOR {surf.ior:g} below 1 is raised to 1")
                row["ior"] = 1.0
            if opal is not None:
                row["dispersion"] = opal.dispersion
                row["abbe"] = float(opal.abbe_number)
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
                "grating_direction": opal.grating_direction, "rotation": float(opal.rotation),
            }
            row.update(grating)
        return row, grating



def export_materials(depsgraph, warn: Warnings | None = None) -> Materials:
    """The core's material table alone, row for row the one :func:`export_scene` makes (the same
    instance order, so a cached scene's ``tri_material`` still indexes it). ``warn``: collects the
    warnings (default: dropped)."""
    table = MaterialTable(warn if warn is not None else Warnings(), working_space_to_rec709())
    for inst in depsgraph.object_instances:
        if is_surface_instance(inst):
            table.slots(inst.object)
    return table.finish()
