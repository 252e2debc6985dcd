"""The eye pass's per-path state: named arrays that travel with the rays through the walk.

A path tracer needs more per path than a ray's origin, direction and weight (docs/physics.md
sections 4.5 and 4.12): how many diffuse vertices it has met (which film part its light goes
to), its bounces of each kind (Cycles' bounce limits), the last BSDF sample's pdf (the power
heuristic's partner), whether the light pass's caustic map already holds where it goes, its
sampler numbers, and its ray differentials (core/sampling/footprint.py). ``PathState`` holds
them as structure-of-arrays, one row per ray, carried in ``Rays.state``: gathered by
``Rays.take``, joined by ``Rays.concat`` and inherited by ``Rays.moved`` (a shallow copy: a
stage that changes a field assigns a new array to it, so the parent's rows stay as they were).
A subset's fields are gathered when first read (core/transport/rows.py: most stages read a few).
The light pass's rays carry none (``Rays.state`` None). A subclass with more array fields
(benchmarks/sphere_noise.py tags paths by their first event) is carried the same way.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from .rows import RowView, holds_none, join, pending_copy, subset

__all__ = ["Caustic", "MAX_DIFFUSE_VERTICES", "PathState"]


class Caustic:
    """Where a path stands towards the light pass's caustic map (``PathState.caustic``, int8):
    the codes as int8 scalars (comparing an array with an IntEnum member costs NumPy several
    times the comparison itself: its int subclass takes a slow conversion every time)."""
    #: no caustic receiver since the last emission-relevant vertex: the eye pass counts its light
    NONE = np.int8(0)
    #: the last diffuse vertex receives the light pass's caustics
    RECEIVER = np.int8(1)
    #: ... and specular bounces followed it: a caustic path the light pass counted (left out here)
    PATH = np.int8(2)


#: ``PathState.nd`` (int8) saturates here: the film parts only tell 0, 1 and 2+ apart.
MAX_DIFFUSE_VERTICES = 100


@dataclass
class PathState(RowView):
    """Per-path arrays (B,) of the eye pass (rows match the rays that carry them)."""
    nd: np.ndarray            # int8 diffuse (non-specular) vertices so far, at most MAX_DIFFUSE_VERTICES
    diffuse: np.ndarray       # int16 diffuse bounces (Cycles' counts; their total is Rays.depth)
    glossy: np.ndarray        # int16 glossy bounces (mirror reflections count here)
    transmission: np.ndarray  # int16 transmission bounces (refractions)
    pdf: np.ndarray           # float32 solid-angle pdf of the last BSDF-sampled direction; 0: a camera
    #                           ray or a specular bounce (no MIS partner)
    caustic: np.ndarray       # int8 a Caustic code
    final: np.ndarray         # bool: a bounce limit was reached; this segment only gathers emission (MIS)
    seen: np.ndarray          # bool: the last diffuse vertex was seen straight from the camera on a
    #                           core/integrators/light/splat_bounce.py receiver
    split: np.ndarray         # float32 the Fresnel weight a split gave the path (core/integrators/eye/
    #                           fresnel_split.py; 1: none), which Russian roulette divides out
    pid: np.ndarray           # uint32 pixel number of core/sampling/sampler.py's points
    sid: np.ndarray           # uint32 sample number of those points
    # (B, 5, 3) float32 ray differentials (core/sampling/footprint.py); None: not carried
    rd: np.ndarray | None = None

    @classmethod
    def new(cls, b: int, differentials: bool = False) -> "PathState":
        """The state of ``b`` camera paths (nothing met yet; differentials zero if carried)."""
        return cls(np.zeros(b, np.int8), np.zeros(b, np.int16), np.zeros(b, np.int16), np.zeros(b, np.int16),
                   np.zeros(b, np.float32), np.zeros(b, np.int8), np.zeros(b, bool), np.zeros(b, bool),
                   np.ones(b, np.float32), np.zeros(b, np.uint32), np.zeros(b, np.uint32),
                   np.zeros((b, 5, 3), np.float32) if differentials else None)

    def take(self, idx: np.ndarray) -> "PathState":
        """The rows at indices ``idx`` (each field gathered when first read)."""
        lazy, eager, _ = _names(type(self))
        new = subset(self, idx, lazy)
        for k in eager:  # fields with a class-level default (a subclass's): gathered now
            v = getattr(self, k)
            setattr(new, k, None if v is None else v.take(idx, axis=0))
        return new

    def copy(self) -> "PathState":
        """A new state holding the same arrays (fields reassigned on it leave this one alone)."""
        return pending_copy(self)

    @staticmethod
    def concat(a: "PathState", b: "PathState") -> "PathState":
        return PathState.join([a, b])

    @staticmethod
    def join(parts: list) -> "PathState":
        """The rows of ``parts`` (states of one class) one after another; a field every part
        holds pending on one array stays pending (core/transport/rows.py)."""
        cls = type(parts[0])
        rd = holds_none(parts[0], "rd")
        if any(type(p) is not cls or holds_none(p, "rd") != rd for p in parts):
            raise ValueError("cannot join ray populations that carry different state")
        lazy, eager, _ = _names(cls)
        new = join(parts, lazy, object.__new__(cls))
        for k in eager:
            vals = [getattr(p, k) for p in parts]
            setattr(new, k, None if vals[0] is None else np.concatenate(vals))
        return new

    def _arrays(self) -> tuple:
        return tuple(getattr(self, k) for k in _names(type(self))[2])


# no class-level default: a subset's pending rd must reach RowView.__getattr__ (the dataclass's
# __init__ keeps its default None)
del PathState.rd

_NAMES: dict = {}


def _names(cls) -> tuple:
    """(fields a subset gathers when first read, fields it gathers at once (those with a
    class-level default), all fields in order) of a PathState class (a subclass adds its own),
    looked up once per class: dataclasses.fields costs more than a take of a small array."""
    names = _NAMES.get(cls)
    if names is None:
        every = tuple(f.name for f in fields(cls))
        names = _NAMES[cls] = (tuple(k for k in every if not hasattr(cls, k)),
                               tuple(k for k in every if hasattr(cls, k)), every)
    return names
