"""The opal tools' mesh attributes: a mesh's faces <-> NumPy arrays and the per-face grating field.

Reads a mesh's faces into arrays (``foreach_get`` in Object Mode, bmesh in Edit Mode) and writes
a :class:`~opal_diffraction.core.opal.DomainField` back as per-face attributes:

    opal_grating_direction  FLOAT_VECTOR, FACE  unit grating vector in the face's plane (object space)
    opal_grating_period     FLOAT, FACE         period in nm (the material's where 0)
    opal_grating_domain     INT, FACE           domain id
    opal_preview            FLOAT_COLOR, CORNER hue = direction, brightness = period (Solid mode)

They are ordinary mesh attributes, so they survive save/load, modifiers and undo; the exporter
reads direction and period (:mod:`..mesh_io` names them for both). In Edit Mode only the given
faces are written.
"""

from __future__ import annotations

import bmesh
import numpy as np

from ...core import opal as core_opal
from ..mesh_io import GRATING_ATTRIBUTE, PERIOD_ATTRIBUTE, attribute_ok, foreach

__all__ = [
    "DIRECTION_ATTRIBUTE", "PERIOD_ATTRIBUTE", "DOMAIN_ATTRIBUTE", "PREVIEW_ATTRIBUTE",
    "FaceData", "read_faces", "write_field", "show_preview",
]

DIRECTION_ATTRIBUTE = GRATING_ATTRIBUTE
DOMAIN_ATTRIBUTE = "opal_grating_domain"
PREVIEW_ATTRIBUTE = "opal_preview"

_ATTRS = ((DIRECTION_ATTRIBUTE, "FLOAT_VECTOR"), (PERIOD_ATTRIBUTE, "FLOAT"), (DOMAIN_ATTRIBUTE, "INT"))


class FaceData:
    """A mesh's faces as arrays: vertices (V, 3), triangles (T, 3) with their face (T,), face
    geometry, selection (F,), the active face and edge, and the grating field (or None)."""

    def __init__(self, vertices, triangles, tri_face, n_faces, selected, field, active_face=None, active_edge=None):
        self.vertices = np.asarray(vertices, np.float64).reshape(-1, 3)
        self.triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
        self.tri_face = np.asarray(tri_face, np.int64).reshape(-1)
        self.n_faces = int(n_faces)
        self.selected = np.asarray(selected, bool).reshape(-1)
        self.field = field
        self.active_face = active_face
        self.active_edge = active_edge  # (3,) object-space vector of the active edge, or None
        self.geometry = core_opal.face_geometry(self.vertices, self.triangles, self.tri_face, self.n_faces)

    def field_or_default(self) -> core_opal.DomainField:
        """The stored field, or one domain with the object's X axis and no period (0)."""
        if self.field is not None:
            return self.field.copy()
        return core_opal.DomainField(np.zeros(self.n_faces, np.int32),
                                     core_opal.aligned_directions(self.geometry.normal),
                                     np.zeros(self.n_faces, np.float32))


def read_faces(ob) -> FaceData:
    """Snapshot of ``ob``'s mesh faces (Edit Mode: the edit mesh, through bmesh)."""
    me = ob.data
    if me.is_editmode:
        return _read_bmesh(bmesh.from_edit_mesh(me))
    me.calc_loop_triangles()
    nv, nt, nf = len(me.vertices), len(me.loop_triangles), len(me.polygons)
    verts = foreach(me.vertices, "co", nv, np.float32, 3)
    tris = foreach(me.loop_triangles, "vertices", nt, np.int32, 3)
    tri_face = foreach(me.loop_triangle_polygons, "value", nt, np.int32)
    sel = foreach(me.polygons, "select", nf, bool)
    field = None
    a_dir, a_per, a_dom = (me.attributes.get(n) for n, _ in _ATTRS)
    if attribute_ok(a_dir, "FLOAT_VECTOR"):
        direction = foreach(a_dir.data, "vector", nf, np.float32, 3)
        period = foreach(a_per.data, "value", nf, np.float32) if attribute_ok(a_per, "FLOAT") else np.zeros(nf, np.float32)
        domain = foreach(a_dom.data, "value", nf, np.int32) if attribute_ok(a_dom, "INT") else np.zeros(nf, np.int32)
        field = core_opal.DomainField(domain, direction, period)
    active = me.polygons.active if 0 <= me.polygons.active < nf else None
    return FaceData(verts, tris, tri_face, nf, sel, field, active)


def _read_bmesh(bm) -> FaceData:
    bm.verts.index_update()
    bm.faces.index_update()
    bm.faces.ensure_lookup_table()
    verts = np.array([v.co[:] for v in bm.verts], np.float64).reshape(-1, 3)
    lt = bm.calc_loop_triangles()
    tris = np.array([[l.vert.index for l in tri] for tri in lt], np.int64).reshape(-1, 3)
    tri_face = np.array([tri[0].face.index for tri in lt], np.int64)
    faces = bm.faces
    sel = np.array([f.select for f in faces], bool)
    field = None
    l_dir = faces.layers.float_vector.get(DIRECTION_ATTRIBUTE)
    if l_dir is not None:
        l_per = faces.layers.float.get(PERIOD_ATTRIBUTE)
        l_dom = faces.layers.int.get(DOMAIN_ATTRIBUTE)
        direction = np.array([f[l_dir][:] for f in faces], np.float32).reshape(-1, 3)
        period = np.array([f[l_per] for f in faces], np.float32) if l_per is not None else np.zeros(len(faces), np.float32)
        domain = np.array([f[l_dom] for f in faces], np.int32) if l_dom is not None else np.zeros(len(faces), np.int32)
        field = core_opal.DomainField(domain, direction, period)
    active = faces.active.index if faces.active is not None else None
    edge = None
    hist = bm.select_history.active
    if isinstance(hist, bmesh.types.BMEdge):
        a, b = hist.verts
        edge = np.array(b.co - a.co, np.float64)
    return FaceData(verts, tris, tri_face, len(faces), sel, field, active, edge)


def write_field(ob, field: core_opal.DomainField, faces: np.ndarray | None = None, preview: bool = True,
                normals: np.ndarray | None = None) -> None:
    """Store ``field`` in ``ob``'s face attributes (created when missing) and refresh the preview
    colours. ``faces`` (F,) bool: only those faces are written (Edit Mode; others untouched);
    ``normals``: the faces' normals when the caller has them (else they are read)."""
    me = ob.data
    geo_normals = None
    if preview:
        geo_normals = normals if normals is not None else read_faces(ob).geometry.normal
    if me.is_editmode:
        bm = bmesh.from_edit_mesh(me)
        _write_bmesh(bm, field, faces, geo_normals)
        bmesh.update_edit_mesh(me, loop_triangles=False, destructive=False)
    else:
        _write_mesh(me, field, geo_normals)
        me.update()
    if preview:
        _set_active_color(me)


def _preview_colors(field, normals):
    return core_opal.preview_colors(field.direction, normals, field.period)


def _write_mesh(me, field, normals) -> None:
    nf = len(me.polygons)
    for name, dtype in _ATTRS:
        a = me.attributes.get(name)
        if a is not None and not attribute_ok(a, dtype):
            me.attributes.remove(a)
            a = None
        if a is None:
            me.attributes.new(name, dtype, "FACE")
    me.attributes[DIRECTION_ATTRIBUTE].data.foreach_set("vector", np.ascontiguousarray(field.direction, np.float32).ravel())
    me.attributes[PERIOD_ATTRIBUTE].data.foreach_set("value", np.ascontiguousarray(field.period, np.float32))
    me.attributes[DOMAIN_ATTRIBUTE].data.foreach_set("value", np.ascontiguousarray(field.domain, np.int32))
    if normals is not None:
        col = me.color_attributes.get(PREVIEW_ATTRIBUTE)
        if col is not None and not attribute_ok(col, "FLOAT_COLOR", "CORNER"):
            me.color_attributes.remove(col)
            col = None
        if col is None:
            col = me.color_attributes.new(PREVIEW_ATTRIBUTE, "FLOAT_COLOR", "CORNER")
        rgba = _preview_colors(field, normals)
        starts = foreach(me.polygons, "loop_start", nf, np.int32)
        order = np.argsort(starts, kind="stable")
        loop_face = order[np.searchsorted(starts[order], np.arange(len(me.loops)), side="right") - 1]
        col.data.foreach_set("color", np.ascontiguousarray(rgba[loop_face], np.float32).ravel())


def _write_bmesh(bm, field, faces, normals) -> None:
    fl = bm.faces.layers
    l_dir = fl.float_vector.get(DIRECTION_ATTRIBUTE) or fl.float_vector.new(DIRECTION_ATTRIBUTE)
    l_per = fl.float.get(PERIOD_ATTRIBUTE) or fl.float.new(PERIOD_ATTRIBUTE)
    l_dom = fl.int.get(DOMAIN_ATTRIBUTE) or fl.int.new(DOMAIN_ATTRIBUTE)
    bm.faces.ensure_lookup_table()
    idx = np.arange(len(bm.faces)) if faces is None else np.flatnonzero(faces)
    d, p, dom = field.direction, field.period, field.domain
    for i in idx.tolist():
        f = bm.faces[i]
        f[l_dir] = d[i].tolist()
        f[l_per] = float(p[i])
        f[l_dom] = int(dom[i])
    if normals is not None:
        ll = bm.loops.layers.float_color
        l_col = ll.get(PREVIEW_ATTRIBUTE) or ll.new(PREVIEW_ATTRIBUTE)
        rgba = _preview_colors(field, normals)  # all faces: brightness is relative to the whole range
        for f in bm.faces:
            c = rgba[f.index].tolist()
            for loop in f.loops:
                loop[l_col] = c


def _set_active_color(me) -> None:
    try:
        col = me.color_attributes.get(PREVIEW_ATTRIBUTE)
        if col is not None:
            me.color_attributes.active_color = col
            names = [c.name for c in me.color_attributes]
            me.color_attributes.render_color_index = names.index(PREVIEW_ATTRIBUTE)
    except (AttributeError, TypeError, ValueError, RuntimeError):  # API differences between versions
        pass


def show_preview(context) -> None:
    """Solid-mode 3D views show the preview colour attribute (Viewport Shading > Color > Attribute)."""
    screen = getattr(context, "screen", None)
    if screen is None:
        return
    for area in screen.areas:
        if area.type != "VIEW_3D":
            continue
        for space in area.spaces:
            if space.type == "VIEW_3D" and space.shading.type == "SOLID":
                space.shading.color_type = "VERTEX"
        area.tag_redraw()
