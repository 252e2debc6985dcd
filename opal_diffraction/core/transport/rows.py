"""Row subsets of the walk's structure-of-arrays records, gathered when a field is first read.

The wavefront walk cuts its populations into subsets again and again: the rays that hit
something, the live ones, the diffuse ones, those at their first diffuse vertex, the lit ones...
(core/transport/walker.py, core/integrators/eye/eye_pass.py). Gathering every field of every
subset at once copies rows a stage never reads, and copies the same rows once per level of a
chain of subsets. ``RowView`` makes such a record (``Rays``, ``Hit``, ``PathState``) take its
subsets lazily: ``subset(obj, idx, names)`` is a new object of the same class whose fields
``names`` are *pending* - a source array and the row indices into it - until first read, when
``__getattr__`` gathers them with one ``ndarray.take`` and keeps the result as an ordinary
attribute (later reads cost nothing extra). A subset of a subset composes the indices, so each
field is gathered once, from the array where it last lived, however long the chain; ``join``
(a step's continuing populations, one after another) keeps a field pending where every part
has it pending on one array (the indices joined), so a field no stage changes or reads (a
path's pixel, sampler ids, wavelength number) is not copied at all from step to step.

The values are exactly those of an eager gather (a row gather is a copy, no arithmetic). The
one rule it needs - already the walk's rule for its records - is that a stage that changes a
field assigns a new array instead of writing into the old one (a pending subset reads its
source when first read, not when taken). Russian roulette, which reweights survivors, assigns
its weights as a new array for that reason, so ``Rays.w`` too is gathered only when read.

A pending entry is a two-element list [source, indices], or the name of another field whose
object it is (``Hit.ns`` of a flat hit is ``Hit.ng`` itself: callers test ``ns is ng``). A
materialised entry is a one-element list [array] shared by shallow copies (``PathState.copy``),
so a copy and its original gather a field once between them.
"""

from __future__ import annotations

import operator

import numpy as np

__all__ = ["RowView", "subset", "pending_copy", "join", "holds_none"]


class RowView:
    """Mixin for a dataclass of per-row arrays: fields left out of the instance's ``__dict__``
    are read from its ``_pending`` entries on first access (see the module docstring). A field
    with a class-level default must not be pending (the class attribute would answer first)."""

    def __getattr__(self, name):  # only called for attributes the instance does not hold
        d = self.__dict__
        pending = d.get("_pending")
        cell = None if pending is None else pending.get(name)
        if cell is None:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        if type(cell) is str:  # the same object as another field
            value = getattr(self, cell)
        elif len(cell) == 1:  # gathered already, by a shallow copy sharing the entry
            value = cell[0]
        else:
            value = cell[0].take(cell[1], axis=0)
            cell[:] = (value,)
        d[name] = value
        del pending[name]
        return value


def subset(obj, idx, names, out=None):
    """A new object of ``obj``'s class (or ``out``'s instance dict filled in) whose fields
    ``names`` hold the rows ``idx`` (an int index array) of ``obj``'s, pending until read; a
    field that is None stays None. Other attributes are the caller's to set."""
    new = object.__new__(type(obj)) if out is None else out
    nd = new.__dict__
    d = obj.__dict__
    src_pending = d.get("_pending")
    if not src_pending:  # every field held (the usual parent: a population): its rows idx
        pending = {}
        for k in names:
            v = d[k]
            if v is None:
                nd[k] = None
            else:
                pending[k] = [v, idx]
        nd["_pending"] = pending
        return new
    pending = {}
    composed = {}  # id of a pending index array of obj -> its rows idx (fields taken together share one)
    for k in names:
        if k in d:  # a materialised (or reassigned) field: its rows idx
            v = d[k]
            if v is None:
                nd[k] = None
            else:
                pending[k] = [v, idx]
            continue
        cell = src_pending[k]
        if type(cell) is str:
            pending[k] = cell
        elif len(cell) == 1:
            pending[k] = [cell[0], idx]
        else:  # still pending in obj: the source's rows (obj's indices)[idx], composed once
            c = composed.get(id(cell[1]))
            if c is None:
                c = composed[id(cell[1])] = cell[1].take(idx)
            pending[k] = [cell[0], c]
    nd["_pending"] = pending
    return new


def pending_copy(obj):
    """A shallow copy of ``obj`` that shares its pending entries (a field gathered by either
    is gathered for both) and its arrays; fields reassigned on it leave ``obj`` alone."""
    new = object.__new__(type(obj))
    nd = new.__dict__
    nd.update(obj.__dict__)
    pending = nd.get("_pending")
    if pending is not None:
        nd["_pending"] = dict(pending)
    return new


def join(parts, names, out):
    """Fill ``out``'s instance dict with the fields ``names`` of ``parts`` (objects of one
    class, alike: a field None in one is None in all) stacked one after another: a field every
    part holds pending on the same source array stays pending (the parts' indices joined, one
    gather when first read), any other is concatenated. Other attributes are the caller's."""
    nd = out.__dict__
    dicts = [p.__dict__ for p in parts]
    pends = [d.get("_pending") or _NONE_PENDING for d in dicts]
    pending = {}
    last = joined = None
    for k in names:
        cells = [pe.get(k) for pe in pends]  # None where gathered or assigned
        c0 = cells[0]
        if c0 is not None and type(c0) is list and len(c0) == 2 and all(
                c is not None and type(c) is list and len(c) == 2 and c[0] is c0[0] and k not in d
                for c, d in zip(cells, dicts)):
            idxs = [c[1] for c in cells]
            if last is None or not all(map(_same, idxs, last)) or len(idxs) != len(last):
                last, joined = idxs, np.concatenate(idxs)  # fields taken together share their indices
            pending[k] = [c0[0], joined]
            continue
        vals = [getattr(p, k) for p in parts]
        if vals[0] is None:
            if any(v is not None for v in vals):
                raise ValueError(f"cannot join records where {k!r} is None in some parts only")
            nd[k] = None
        else:
            nd[k] = np.concatenate(vals)
    nd["_pending"] = pending
    return out


_NONE_PENDING: dict = {}
_same = operator.is_


def holds_none(obj, name) -> bool:
    """Whether field ``name`` of ``obj`` is None, without gathering it (None fields are never pending)."""
    return obj.__dict__.get(name, 0) is None
