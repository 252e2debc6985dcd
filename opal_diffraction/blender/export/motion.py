"""Object motion blur: the scene's vertices in K time bins of the shutter (docs/physics.md section 6.13).

With Render > Motion Blur on in a final render, the depsgraph is re-evaluated at the centre of
each of ``MOTION_BINS`` equal time bins of the shutter (RenderEngine.frame_set, as Cycles' own
motion sync does, then back to the frame), every exported instance's world matrix is read
again and the frame's meshes are placed with it (export/meshes.py ``flatten``): the core traces
a camera ray of shutter time t in bin floor(t K)'s geometry. Transforms move and turn the
objects (parents, constraints, drivers included); a mesh's deformation over the shutter is not
read (the frame's shape moves rigidly). Nothing is returned when nothing moves.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from .camera import motion_times
from .messages import Warnings
from .meshes import flatten

__all__ = ["MOTION_BINS", "MOTION_TRIANGLE_BUDGET", "motion_bin_count", "instance_id", "object_motion"]

#: time bins of the shutter for object motion: the geometry of a bin is its centre's, so an
#: object moving d during the shutter is at most d / (2 K) from where it should be
MOTION_BINS = 16
#: triangles all the bins may hold together (each bin has its own ray caster): a scene of more
#: than a million triangles gets fewer bins (at least 2), so memory stays within ~16 such casters
MOTION_TRIANGLE_BUDGET = 16_000_000


def motion_bin_count(n_triangles: int) -> int:
    """The time bins for a scene of ``n_triangles``: MOTION_BINS, fewer past the triangle budget."""
    return int(min(MOTION_BINS, max(2, MOTION_TRIANGLE_BUDGET // max(int(n_triangles), 1))))


def instance_id(inst) -> tuple:
    """What identifies a depsgraph instance across re-evaluations: its object's name, its
    instancer's and its persistent id (the same object instanced twice has two)."""
    parent = inst.parent.name if getattr(inst, "is_instance", False) and inst.parent is not None else ""
    return inst.object.name, parent, tuple(inst.persistent_id) if getattr(inst, "is_instance", False) else ()


def object_motion(depsgraph, frame_set, kept: list, groups: dict, meshes, grating, hidden, warn,
                  n_triangles: int = 0) -> np.ndarray | None:
    """(K, V, 3) float32 vertices (K = :func:`motion_bin_count` of ``n_triangles``), bin k's at the
    shutter's time (k + 1/2) / K, in the
    order ``flatten(groups, ...)`` gave the frame's; None when motion blur is off, the shutter is
    zero, there is no ``frame_set`` (not a final render) or nothing moves. ``kept``: (group key,
    :func:`instance_id`) of each exported instance in the frame's order."""
    scene = depsgraph.scene
    r = scene.render
    if frame_set is None or not getattr(r, "use_motion_blur", False) or float(r.motion_blur_shutter) <= 0 or not kept:
        return None
    key_of = dict((ident, key) for key, ident in kept)
    if len(key_of) != len(kept):
        warn("object motion blur is not rendered: two instances could not be told apart")
        return None
    s0, s1 = motion_times(scene, 2)
    frame, sub = int(scene.frame_current), float(getattr(scene, "frame_subframe", 0.0))
    quiet = Warnings()
    out = []
    n_bins = motion_bin_count(n_triangles)
    try:
        for k in range(n_bins):
            t = s0 + (k + 0.5) / n_bins * (s1 - s0)
            f = int(np.floor(t))
            frame_set(f, t - f)
            mats = defaultdict(list)
            for inst in depsgraph.object_instances:
                if not inst.show_self:
                    continue
                key = key_of.get(instance_id(inst))
                if key is not None:
                    mats[key].append(np.array(inst.matrix_world, np.float64))
            if any(len(mats[key]) != len(groups[key]) for key in groups):
                warn("object motion blur is not rendered: the objects seen change during the shutter")
                return None
            out.append(flatten({key: mats[key] for key in groups}, meshes, grating, quiet, hidden)[0])
    finally:
        frame_set(frame, sub)
    mv = np.stack(out).astype(np.float32)
    if np.allclose(mv, mv[:1], atol=1e-7, rtol=0.0):
        return None  # nothing moves
    return mv
