"""Volume (BRAGG) domains in Blender: generating them in an object's volume, the Bragg-colour preview,
and the Edit Mode tool that sets the orientation and size of the domains under the selected faces.

The logic is core/opal/volume.py (docs/physics.md section 5.4); the domains are stored on the
object in object space (:mod:`..opal_domains`). A face lies in the cell that holds its centre,
so "the domains under the selected faces" are the cells of the selected faces' centres; a tool
changes those cells (their (111) normal, their sphere diameter), and with them every other face
in the same cells - nothing else.
"""

from __future__ import annotations

import bmesh
import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty

from ...core import opal as core_opal
from ...core.opal.volume import cells_of, generate_volume_domains
from ..mesh_io import attribute_ok, foreach
from ..opal_domains import ObjectDomains, bragg_material, read_domains, write_domains
from .attributes import PREVIEW_ATTRIBUTE, FaceData, _set_active_color, read_faces

__all__ = ["layout_of", "generate_object_domains", "face_cells", "write_bragg_preview", "OPAL_OT_set_domain"]


def layout_of(mat, **given) -> dict:
    """The volume-domain layout: the material's (its preset's) values, overridden by ``given``
    (keys: count, size_spread, orientation, axis_spread, low, high; None = the material's)."""
    o = mat.opal if mat is not None else None
    d = float(o.sphere_diameter) if o is not None else 250.0
    s = float(o.diameter_spread) if o is not None else 40.0
    base = dict(count=int(o.domain_count) if o is not None else 300,
                size_spread=float(o.domain_size_spread) if o is not None else 0.5,
                orientation=o.domain_orientation if o is not None else "LAYERED",
                axis_spread=float(o.domain_axis_spread) if o is not None else 25.0,
                low=max(d - s, 1.0), high=d + s)
    base.update({k: v for k, v in given.items() if v is not None})
    return base


def generate_object_domains(ob, faces: FaceData, seed: int = 0, **given) -> ObjectDomains:
    """Volume domains in ``ob``'s mesh (object space; the mesh must be closed), laid out as
    :func:`layout_of` says, stored on the object and shown in the preview."""
    mat = bragg_material(ob)
    lay = layout_of(mat, **given)
    seeds, weight, axis, diameter = generate_volume_domains(
        faces.vertices, faces.triangles, lay["count"], seed, lay["size_spread"], lay["orientation"],
        (0.0, 0.0, 1.0), lay["axis_spread"], (lay["low"], lay["high"]))
    d = ObjectDomains(seeds, weight, axis, diameter)
    write_domains(ob, d)
    write_bragg_preview(ob, d, faces, mat)
    return d


def face_cells(faces: FaceData, d: ObjectDomains) -> np.ndarray:
    """The cell (F,) each face's centre lies in."""
    return cells_of(faces.geometry.center, d.seeds, d.weight)


def write_bragg_preview(ob, d: ObjectDomains, faces: FaceData | None = None, mat=None) -> None:
    """Per-face preview colours (corner colour attribute ``opal_preview``): the Bragg colour at
    normal incidence of the cell each face lies in (core.opal.bragg_colors, the material's
    sphere and void indices)."""
    faces = faces if faces is not None else read_faces(ob)
    mat = mat if mat is not None else bragg_material(ob)
    ns = float(mat.opal.sphere_ior) if mat is not None else core_opal.N_SILICA
    nv = float(mat.opal.void_ior) if mat is not None else core_opal.N_VOID
    palette = core_opal.bragg_colors(d.diameter, ns, nv)
    rgba = palette[face_cells(faces, d)]
    me = ob.data
    if me.is_editmode:
        bm = bmesh.from_edit_mesh(me)
        ll = bm.loops.layers.float_color
        layer = ll.get(PREVIEW_ATTRIBUTE) or ll.new(PREVIEW_ATTRIBUTE)
        bm.faces.ensure_lookup_table()
        for f in bm.faces:
            c = rgba[f.index].tolist()
            for loop in f.loops:
                loop[layer] = c
        bmesh.update_edit_mesh(me, loop_triangles=False, destructive=False)
    else:
        col = me.color_attributes.get(PREVIEW_ATTRIBUTE)
        if col is not None and not attribute_ok(col, "FLOAT_COLOR", "CORNER"):
            me.color_attributes.remove(col)
            col = None
        if col is None:
            col = me.color_attributes.new(PREVIEW_ATTRIBUTE, "FLOAT_COLOR", "CORNER")
        nf = len(me.polygons)
        starts = foreach(me.polygons, "loop_start", nf, np.int32)
        order = np.argsort(starts, kind="stable")
        loop_face = order[np.searchsorted(starts[order], np.arange(len(me.loops)), side="right") - 1]
        col.data.foreach_set("color", np.ascontiguousarray(rgba[loop_face], np.float32).ravel())
        me.update()
    _set_active_color(me)


_ORIENTATION_ITEMS = [
    ("KEEP", "Keep", "Keep the cells' (111) orientation (set only the sphere diameter)", 0),
    ("NORMAL", "Surface Normal", "(111) planes parallel to the surface: the selected faces' mean normal (the "
     "flash faces the viewer who looks straight down onto those faces)", 1),
    ("VIEW", "Towards the View", "(111) normal along the view direction: the cells flash towards the viewer "
     "(under a light behind the viewer)", 2),
    ("AXIS", "Axis", "(111) normal along the given object-space axis", 3),
    ("RANDOM", "Random", "A new random (111) orientation per cell", 4),
]


class OPAL_OT_set_domain(bpy.types.Operator):
    """Set the (111) orientation and the sphere diameter of the volume domains under the selected faces
    (the cells their centres lie in)"""

    bl_idname = "opal.set_domain"
    bl_label = "Set Domain"
    bl_options = {"REGISTER", "UNDO"}

    orientation: EnumProperty(name="Orientation", items=_ORIENTATION_ITEMS, default="NORMAL")
    axis: FloatVectorProperty(name="Axis", description="AXIS: the (111) normal, object space", size=3,
                              default=(0.0, 0.0, 1.0))
    tilt: FloatProperty(name="Tilt", description="Tilt the new orientation by this angle (towards the object's "
                        "X axis): a flash that many degrees off", default=0.0, subtype="ANGLE")
    set_diameter: BoolProperty(name="Set Diameter", description="Also set the cells' sphere diameter",
                               default=False)
    diameter: FloatProperty(name="Sphere Diameter", description="Sphere diameter of the cells, nm (the Bragg "
                            "colour at normal incidence is 2 sqrt(2/3) D n_eff)", default=250.0, min=1.0,
                            soft_min=150.0, soft_max=350.0, precision=1)
    seed: IntProperty(name="Seed", description="RANDOM: the seed", default=0, min=0)
    view_vector: FloatVectorProperty(name="View Direction", description="The view direction in object space "
                                     "(captured when the operator starts)", size=3,
                                     options={"HIDDEN", "SKIP_SAVE"})

    @classmethod
    def poll(cls, context):
        ob = getattr(context, "active_object", None)
        return (ob is not None and ob.type == "MESH" and context.mode == "EDIT_MESH"
                and read_domains(ob) is not None)

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(self, "orientation")
        if self.orientation == "AXIS":
            layout.prop(self, "axis")
        if self.orientation == "RANDOM":
            layout.prop(self, "seed")
        if self.orientation != "KEEP":
            layout.prop(self, "tilt")
        row = layout.row(heading="Diameter")
        row.prop(self, "set_diameter", text="")
        sub = row.row()
        sub.active = self.set_diameter
        sub.prop(self, "diameter", text="")

    def invoke(self, context, event):
        rv3d = getattr(context, "region_data", None)
        if rv3d is not None and hasattr(rv3d, "view_rotation"):
            from mathutils import Vector

            towards_viewer = rv3d.view_rotation @ Vector((0.0, 0.0, 1.0))
            self.view_vector = context.active_object.matrix_world.to_3x3().inverted_safe() @ towards_viewer
        return self.execute(context)

    def execute(self, context):
        ob = context.active_object
        d = read_domains(ob)
        faces = read_faces(ob)
        if d is None:
            self.report({"ERROR"}, "the object has no volume domains: Generate Domains first")
            return {"CANCELLED"}
        if not faces.selected.any():
            self.report({"ERROR"}, "no faces selected")
            return {"CANCELLED"}
        cells = np.unique(face_cells(faces, d)[faces.selected])
        out = d.copy()
        new_axis = None
        if self.orientation == "NORMAL":
            w = faces.geometry.area[faces.selected]
            new_axis = (faces.geometry.normal[faces.selected] * w[:, None]).sum(axis=0)
        elif self.orientation == "VIEW":
            new_axis = np.array(self.view_vector, np.float64)
            if not np.linalg.norm(new_axis) > 0:
                self.report({"ERROR"}, "no 3D view to take the direction from: use Axis")
                return {"CANCELLED"}
        elif self.orientation == "AXIS":
            new_axis = np.array(self.axis, np.float64)
        elif self.orientation == "RANDOM":
            v = np.random.default_rng(int(self.seed)).normal(size=(len(cells), 3))
            new_axis = v / np.linalg.norm(v, axis=1, keepdims=True)
        if new_axis is not None:
            a = np.broadcast_to(np.asarray(new_axis, np.float64), (len(cells), 3))
            n = np.linalg.norm(a, axis=1, keepdims=True)
            if not (n > 0).all():
                self.report({"ERROR"}, "the orientation is a zero vector")
                return {"CANCELLED"}
            a = a / n
            if self.tilt:
                # rotate towards the object's X axis (about a x X; about Y where a is along X)
                ref = np.where(np.abs(a[:, :1]) > 0.99, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
                perp = ref - np.sum(ref * a, axis=1, keepdims=True) * a
                perp /= np.linalg.norm(perp, axis=1, keepdims=True)
                a = np.cos(self.tilt) * a + np.sin(self.tilt) * perp
            out.axis[cells] = a.astype(np.float32)
        if self.set_diameter:
            out.diameter[cells] = np.float32(self.diameter)
        write_domains(ob, out)
        write_bragg_preview(ob, out, faces)
        self.report({"INFO"}, f"{len(cells)} domain(s) changed")
        return {"FINISHED"}
