"""Opal volume domains stored on a Blender object, in object space (docs/physics.md section 5.4).

The domains of an opal object (core/opal/volume.py: seeds, additive weights, (111) normals,
sphere diameters) are an ID property group ``object["opal_domains"]`` of flat arrays:

    seeds     (3 S,) float64  object space, m
    weight    (S,)   float64  object space, m
    axis      (3 S,) float32  unit (111) normals, object space
    diameter  (S,)   float32  nm

On the object, not the mesh: they transform with it (the exporter takes them to world space
with each instance's matrix), survive save/load and are copied with the object (Shift D, Alt D).
Edit Mode's undo restores the mesh only: a change of the domains made in Edit Mode is undone in
Object Mode.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PROPERTY", "ObjectDomains", "read_domains", "write_domains", "clear_domains", "bragg_material"]

PROPERTY = "opal_domains"


@dataclass
class ObjectDomains:
    """One object's volume domains, object space."""

    seeds: np.ndarray     # (S, 3) float64
    weight: np.ndarray    # (S,) float64
    axis: np.ndarray      # (S, 3) float32
    diameter: np.ndarray  # (S,) float32

    def __len__(self) -> int:
        return len(self.seeds)

    def copy(self) -> "ObjectDomains":
        return ObjectDomains(self.seeds.copy(), self.weight.copy(), self.axis.copy(), self.diameter.copy())


def read_domains(ob) -> ObjectDomains | None:
    """``ob``'s domains, or None (none stored, or a malformed group: then None too)."""
    try:
        g = ob.get(PROPERTY)
    except (AttributeError, TypeError):
        return None
    if g is None:
        return None
    try:
        # copies: an ID property array's buffer is Blender's memory (freed with the file)
        seeds = np.array(g["seeds"], np.float64, copy=True).reshape(-1, 3)
        weight = np.array(g["weight"], np.float64, copy=True).reshape(-1)
        axis = np.array(g["axis"], np.float32, copy=True).reshape(-1, 3)
        diameter = np.array(g["diameter"], np.float32, copy=True).reshape(-1)
    except (KeyError, TypeError, ValueError):
        return None
    if not (len(seeds) == len(weight) == len(axis) == len(diameter)) or len(seeds) == 0:
        return None
    return ObjectDomains(seeds, weight, axis, diameter)


def write_domains(ob, d: ObjectDomains) -> None:
    """Store ``d`` on ``ob`` (replacing what was there)."""
    ob[PROPERTY] = {
        "seeds": np.ascontiguousarray(d.seeds, np.float64).reshape(-1),
        "weight": np.ascontiguousarray(d.weight, np.float64).reshape(-1),
        "axis": np.ascontiguousarray(d.axis, np.float32).reshape(-1),
        "diameter": np.ascontiguousarray(d.diameter, np.float32).reshape(-1),
    }
    ob.update_tag()  # a custom property is not a depsgraph change by itself: the rendered viewport re-exports


def clear_domains(ob) -> None:
    if PROPERTY in ob.keys():
        del ob[PROPERTY]


def bragg_material(ob):
    """The first material of ``ob`` with a BRAGG grating, or None."""
    for s in getattr(ob, "material_slots", ()):
        m = s.material
        if m is not None and getattr(m, "opal", None) is not None and m.opal.grating and m.opal.lattice == "BRAGG":
            return m
    return None
