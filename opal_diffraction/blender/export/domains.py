"""Opal volume domains -> the core Scene's domain columns (``Scene.add_domains``; docs/physics.md
section 5.4).

Each object instance with domains (``object["opal_domains"]``, object space: :mod:`..opal_domains`)
becomes one group: its seeds and weights taken to world space with the instance's matrix, its
(111) normals with the inverse transpose (core ``transform_domains``), and every triangle of that
instance in ``tri_domain_group``; triangles of objects without domains get -1. The walk is
:func:`.meshes.instance_groups`, the one :func:`.meshes.flatten` makes the triangles with, so the
rows line up.
"""

from __future__ import annotations

import numpy as np

from ...core.opal.volume import transform_domains
from ..opal_domains import read_domains
from .meshes import instance_groups

__all__ = ["instance_domains", "flatten_domains"]


def instance_domains(ob):
    """The domains of an evaluated object (its original's custom property), or None."""
    d = read_domains(ob)
    if d is None and getattr(ob, "original", None) is not None and ob.original is not ob:
        d = read_domains(ob.original)
    return d


def flatten_domains(groups: dict, sources: dict, meshes, hidden=None) -> dict:
    """Scene fields (``domain_seeds``, ``domain_weight``, ``domain_axis``, ``domain_diameter``,
    ``domain_group``, ``tri_domain_group``) of every instance: ``sources`` maps each key of
    ``groups`` to the instances' domains (ObjectDomains or None), in the order of their matrices.
    Empty when no instance has domains."""
    if not any(d is not None for lst in sources.values() for d in lst):
        return {}
    seeds, weight, axis, diameter, group, tri_group = [], [], [], [], [], []
    g = 0
    for key, md, mats, _tri_mat in instance_groups(groups, meshes, hidden, with_key=True):
        nt = len(md.triangles)
        for k, src in enumerate(sources[key]):
            if src is None:
                tri_group.append(np.full(nt, -1, np.int32))
                continue
            s, w, a = transform_domains(mats[k], src.seeds, src.weight, src.axis)
            seeds.append(s)
            weight.append(w)
            axis.append(a)
            diameter.append(np.asarray(src.diameter, np.float32))
            group.append(np.full(len(s), g, np.int32))
            tri_group.append(np.full(nt, g, np.int32))
            g += 1
    return {
        "domain_seeds": np.concatenate(seeds), "domain_weight": np.concatenate(weight),
        "domain_axis": np.concatenate(axis), "domain_diameter": np.concatenate(diameter),
        "domain_group": np.concatenate(group), "tri_domain_group": np.concatenate(tri_group),
    }
