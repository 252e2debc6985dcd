"""The opal operators: Add Opal, grating domains, and grating placement on selected faces in Edit Mode.

The logic lives in :mod:`opal_diffraction.core.opal` (pure NumPy on mesh arrays); each operator
reads the mesh's faces (:mod:`.attributes`), calls it, and writes the per-face attributes back.
Every operator is REGISTER/UNDO with a redo panel; Edit Mode operators change the selected faces
only (Merge Domains: the whole domains of the selected faces).
"""

from __future__ import annotations

import bmesh
import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty
from bpy_extras import object_utils

from ..properties import DOMAIN_ORIENTATION_ITEMS

from ...core import opal as core_opal
from ..opal_domains import bragg_material, read_domains
from ..opal_presets import PRESET_ITEMS, new_opal_material
from .attributes import FaceData, read_faces, show_preview, write_field
from .volume_ops import OPAL_OT_set_domain, face_cells, generate_object_domains, write_bragg_preview

__all__ = [
    "is_mesh",
    "MESH_OT_primitive_opal_add", "OPAL_OT_generate_domains", "OPAL_OT_assign_grating", "OPAL_OT_jitter_period",
    "OPAL_OT_split_domain", "OPAL_OT_merge_domains", "OPAL_OT_select_domain", "OPAL_OT_update_preview",
    "OPAL_OT_set_domain", "operators",
]


def is_mesh(context) -> bool:
    """Poll: the active object is a mesh."""
    ob = getattr(context, "active_object", None)
    return ob is not None and ob.type == "MESH"


# ============================================================================ shared properties
_PERIOD_MODE_ITEMS = [
    ("SPHERES", "Sphere Diameter", "Draw the silica sphere diameter and convert it with the Bragg law "
     "(period = 2 sqrt(2/3) D n_eff: 250 nm spheres give 550 nm)", 0),
    ("PERIOD", "Period", "Draw the grating period itself", 1),
]
_DIRECTION_MODE_ITEMS = [
    ("RANDOM", "Random per Domain", "Each domain its own random direction, tangent to the surface", 0),
    ("ALIGNED", "Aligned (Paper Model)", "Every face the object's X axis projected onto it: one consistent "
     "orientation, as in the source paper", 1),
]


def _domain_props():
    return dict(
        count=IntProperty(name="Domains", description="Number of Voronoi grating domains", default=300, min=1,
                          soft_max=5000),
        seed=IntProperty(name="Seed", description="Random seed: the same seed gives the same domains", default=0,
                         min=0),
        period_mode=EnumProperty(name="Period From", items=_PERIOD_MODE_ITEMS, default="SPHERES"),
        low=FloatProperty(name="Min", description="Smallest sphere diameter (or period), nm", default=200.0,
                          min=1.0, soft_min=100.0, soft_max=2000.0, precision=1),
        high=FloatProperty(name="Max", description="Largest sphere diameter (or period), nm", default=330.0,
                           min=1.0, soft_min=100.0, soft_max=2000.0, precision=1),
        direction_mode=EnumProperty(name="Directions", items=_DIRECTION_MODE_ITEMS, default="RANDOM"),
        # volume (BRAGG) domains; unset: the material's layout (its preset's)
        size_spread=FloatProperty(name="Size Spread", description="Volume domains: spread of the sizes (additive "
                                  "weights in units of the mean spacing; unset: the material's)", default=0.5,
                                  min=0.0, soft_max=3.0),
        orientation=EnumProperty(name="Orientation", items=DOMAIN_ORIENTATION_ITEMS, default="LAYERED",
                                 description="Volume domains: how the (111) planes are oriented (unset: the "
                                 "material's)"),
        axis_spread=FloatProperty(name="Axis Spread", description="Volume domains, layered: largest angle of a "
                                  "(111) normal from the object's Z axis, degrees (unset: the material's)",
                                  default=25.0, min=0.0, max=180.0),
    )


def _volume_given(op) -> dict:
    """The volume-layout properties the caller set (the rest come from the material)."""
    names = {"count": "count", "size_spread": "size_spread", "orientation": "orientation",
             "axis_spread": "axis_spread", "low": "low", "high": "high"}
    return {k: getattr(op, a) if op.properties.is_property_set(a) else None for k, a in names.items()}


def _draw_volume_props(layout, op):
    layout.label(text="Unset values: the material's (its preset's)", icon="INFO")
    col = layout.column(align=True)
    col.prop(op, "count")
    col.prop(op, "seed")
    col = layout.column(align=True)
    col.prop(op, "low", text="Sphere Diameter Min")
    col.prop(op, "high", text="Max")
    layout.prop(op, "size_spread")
    layout.prop(op, "orientation")
    row = layout.row()
    row.active = op.orientation == "LAYERED"
    row.prop(op, "axis_spread")


def _draw_domain_props(layout, op):
    col = layout.column(align=True)
    col.prop(op, "count")
    col.prop(op, "seed")
    layout.prop(op, "direction_mode")
    layout.prop(op, "period_mode")
    col = layout.column(align=True)
    label = "Sphere Diameter" if op.period_mode == "SPHERES" else "Period"
    col.prop(op, "low", text=f"{label} Min")
    col.prop(op, "high", text="Max")
    if op.period_mode == "SPHERES":
        lo, hi = (core_opal.period_from_sphere_diameter(v) for v in (op.low, op.high))
        layout.label(text=f"Periods {lo:.0f}-{hi:.0f} nm", icon="INFO")


def _generate(faces: FaceData, op, seed_mask=None, only=None) -> core_opal.DomainField:
    """Domains over all faces, or over the faces ``only`` (F,) bool with new ids."""
    kw = dict(period_mode=op.period_mode, low=op.low, high=op.high, direction_mode=op.direction_mode)
    if only is None:
        return core_opal.generate_domains(faces.vertices, faces.triangles, op.count, op.seed, faces.tri_face,
                                          faces.n_faces, seed_mask=seed_mask, **kw)
    field = faces.field_or_default()
    keep_tri = only[faces.tri_face]
    sub_faces = np.flatnonzero(only)
    remap = np.full(faces.n_faces, -1, np.int64)
    remap[sub_faces] = np.arange(len(sub_faces))
    sub = core_opal.generate_domains(faces.vertices, faces.triangles[keep_tri], op.count, op.seed,
                                     remap[faces.tri_face[keep_tri]], len(sub_faces), **kw)
    base = int(field.domain.max()) + 1 if len(field) else 0
    field.domain[sub_faces] = sub.domain + base
    field.direction[sub_faces] = sub.direction
    field.period[sub_faces] = sub.period
    return field


# ============================================================================ Add Opal
class MESH_OT_primitive_opal_add(bpy.types.Operator, object_utils.AddObjectHelper):
    """Add an opal cabochon (an oval dome) with an opal material and grating domains"""

    bl_idname = "mesh.primitive_opal_add"
    bl_label = "Add Opal"
    bl_options = {"REGISTER", "UNDO", "PRESET"}

    # a real cabochon: 18 x 13 x 6 mm
    size_x: FloatProperty(name="Length", description="Length of the oval base (X)", default=0.018, min=1e-5,
                          soft_max=1.0, unit="LENGTH", precision=4)
    size_y: FloatProperty(name="Width", description="Width of the oval base (Y)", default=0.013, min=1e-5,
                          soft_max=1.0, unit="LENGTH", precision=4)
    height: FloatProperty(name="Height", description="Height of the dome", default=0.006, min=1e-5, soft_max=1.0,
                          unit="LENGTH", precision=4)
    resolution: IntProperty(name="Resolution", description="Rings from the top to the rim (6 r^2 triangles)",
                            default=48, min=2, max=256)
    preset: EnumProperty(name="Preset", items=PRESET_ITEMS, default="BLACK",
                         description="Opal material preset (Paper model: one aligned domain)")
    show_preview: BoolProperty(name="Show Preview", description="Show the domains' preview colours in Solid mode",
                               default=True)

    @classmethod
    def poll(cls, context):
        return context.mode == "OBJECT"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        col = layout.column(align=True)
        col.prop(self, "size_x")
        col.prop(self, "size_y")
        col.prop(self, "height")
        layout.prop(self, "resolution")
        layout.prop(self, "preset")
        if self.preset == "PAPER":
            pass
        elif _preset_is_bragg(self.preset):
            _draw_volume_props(layout, self)
        else:
            _draw_domain_props(layout, self)
        layout.prop(self, "show_preview")
        layout.prop(self, "align")
        layout.prop(self, "location")
        layout.prop(self, "rotation")

    def execute(self, context):
        verts, tris = core_opal.cabochon(self.size_x, self.size_y, self.height, self.resolution)
        me = bpy.data.meshes.new("Opal")
        me.from_pydata(verts.tolist(), [], tris.tolist())
        me.update()
        ob = object_utils.object_data_add(context, me, operator=self)
        me.materials.append(new_opal_material(self.preset))
        faces = read_faces(ob)
        dome = faces.geometry.normal[:, 2] > -0.5  # seeds on the visible dome, not the base
        if bragg_material(ob) is not None:
            generate_object_domains(ob, faces, self.seed, **_volume_given(self))
        elif self.preset == "PAPER":
            period = float(me.materials[0].opal.period)
            field = core_opal.generate_domains(faces.vertices, faces.triangles, 1, self.seed, faces.tri_face,
                                               faces.n_faces, period_mode="PERIOD", low=period, high=period,
                                               direction_mode="ALIGNED")
            write_field(ob, field, normals=faces.geometry.normal)
        else:
            write_field(ob, _generate(faces, self, seed_mask=dome), normals=faces.geometry.normal)
        if self.show_preview:
            show_preview(context)
        return {"FINISHED"}


# ============================================================================ domains
class OPAL_OT_generate_domains(bpy.types.Operator):
    """Cover the mesh (Edit Mode: the selected faces) with Voronoi grating domains, each with its own
    direction tangent to the surface and period"""

    bl_idname = "opal.generate_domains"
    bl_label = "Generate Grating Domains"
    bl_options = {"REGISTER", "UNDO"}

    domain_type: EnumProperty(name="Domains", items=[
        ("AUTO", "Automatic", "Volume domains when a material of the object has the Bragg lattice, else surface "
         "grating domains", 0),
        ("VOLUME", "Volume (Bragg)", "3D domains in the object's volume (a closed mesh), each with a (111) "
         "orientation and a sphere diameter", 1),
        ("SURFACE", "Surface Gratings", "Voronoi grating domains over the faces (LINES / HEXAGONAL)", 2),
    ], default="AUTO")
    only_selected: BoolProperty(name="Selected Faces Only", description="In Edit Mode, cover only the selected "
                                "faces (new domain ids; other faces keep theirs)", default=True)
    show_preview: BoolProperty(name="Show Preview", description="Show the domains' preview colours in Solid mode",
                               default=True)

    @classmethod
    def poll(cls, context):
        return is_mesh(context) and context.mode in ("OBJECT", "EDIT_MESH")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(self, "domain_type")
        if _wants_volume(self, context.active_object):
            _draw_volume_props(layout, self)
            layout.prop(self, "show_preview")
            return
        _draw_domain_props(layout, self)
        if context.mode == "EDIT_MESH":
            layout.prop(self, "only_selected")
        layout.prop(self, "show_preview")

    def execute(self, context):
        ob = context.active_object
        faces = read_faces(ob)
        if faces.n_faces == 0:
            self.report({"ERROR"}, "the mesh has no faces")
            return {"CANCELLED"}
        if _wants_volume(self, ob):
            try:
                d = generate_object_domains(ob, faces, self.seed, **_volume_given(self))
            except ValueError as e:  # not a closed mesh
                self.report({"ERROR"}, f"object '{ob.name}': {e}")
                return {"CANCELLED"}
            if bragg_material(ob) is None:
                self.report({"WARNING"}, "no material of this object has the Bragg lattice: the render ignores "
                            "the volume domains (use an opal preset)")
            if self.show_preview:
                show_preview(context)
            self.report({"INFO"}, f"{len(d)} volume domains, sphere diameters {d.diameter.min():.0f}-"
                        f"{d.diameter.max():.0f} nm")
            return {"FINISHED"}
        only = None
        if ob.data.is_editmode and self.only_selected:
            if not faces.selected.any():
                self.report({"ERROR"}, "no faces selected")
                return {"CANCELLED"}
            only = faces.selected
        field = _generate(faces, self, only=only)
        write_field(ob, field, faces=only, normals=faces.geometry.normal)
        _warn_material(self, ob)
        if self.show_preview:
            show_preview(context)
        n = len(np.unique(field.domain if only is None else field.domain[only]))
        self.report({"INFO"}, f"{n} domains, periods {field.period.min():.0f}-{field.period.max():.0f} nm")
        return {"FINISHED"}


def _wants_volume(op, ob) -> bool:
    """Generate Domains makes volume domains: asked for, or automatic with a BRAGG material."""
    return op.domain_type == "VOLUME" or (op.domain_type == "AUTO" and bragg_material(ob) is not None)


def _preset_is_bragg(ident: str) -> bool:
    from ..opal_presets import preset_file, read_preset

    try:
        return read_preset(preset_file(ident)).get("lattice") == "BRAGG"
    except (KeyError, OSError, SyntaxError, ValueError):
        return False


def _warn_material(op, ob) -> None:
    mats = [s.material for s in ob.material_slots if s.material is not None]
    if not any(m.opal.grating and m.opal.grating_direction == "ATTRIBUTE" for m in mats):
        op.report({"WARNING"}, "no material of this object has a grating with Direction = Face Attribute: "
                  "the render ignores the domains (use an Opal preset)")


def _domains_of(field, selected) -> np.ndarray:
    """(F,) bool: every face of the domains that have a selected face."""
    return np.isin(field.domain, np.unique(field.domain[selected]))


class _EditOp:
    """Poll and helpers shared by the Edit Mode operators."""

    @classmethod
    def poll(cls, context):
        return is_mesh(context) and context.mode == "EDIT_MESH"

    def _begin(self, context):
        ob = context.active_object
        faces = read_faces(ob)
        if not faces.selected.any():
            self.report({"ERROR"}, "no faces selected")
            return ob, faces, None
        return ob, faces, faces.field_or_default()


_DIRECTION_SOURCE_ITEMS = [
    ("VIEW", "View", "Across the slits along the view's horizontal axis: the slits run up the screen", 0),
    ("ACTIVE_EDGE", "Active Edge", "Across the slits along the active (last selected) edge", 1),
    ("ANGLE", "Angle", "At an angle from the object's X axis, about each face's normal", 2),
    ("ROTATE", "Rotate", "Rotate the faces' current directions by the angle", 3),
    ("KEEP", "Keep", "Keep the faces' directions (set only the period or the domain)", 4),
]


class OPAL_OT_assign_grating(_EditOp, bpy.types.Operator):
    """Give the selected faces a grating direction (from the view, the active edge or an angle) and
    optionally a period, as a new domain"""

    bl_idname = "opal.assign_grating"
    bl_label = "Assign Grating"
    bl_options = {"REGISTER", "UNDO"}

    direction: EnumProperty(name="Direction", items=_DIRECTION_SOURCE_ITEMS, default="VIEW")
    angle: FloatProperty(name="Angle", description="ANGLE: from the object's X axis; ROTATE: the rotation; VIEW "
                         "and ACTIVE EDGE: added to their direction", default=0.0, subtype="ANGLE")
    set_period: BoolProperty(name="Set Period", description="Also set the selected faces' period", default=False)
    period: FloatProperty(name="Period", description="Grating period, nm", default=550.0, min=1.0, soft_min=100.0,
                          soft_max=3000.0, precision=1)
    new_domain: BoolProperty(name="New Domain", description="Make the selected faces one new domain",
                             default=True)
    view_vector: FloatVectorProperty(name="View Axis", description="The view's horizontal axis in object space "
                                     "(captured when the operator starts)", size=3, options={"HIDDEN", "SKIP_SAVE"})

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(self, "direction")
        row = layout.row()
        row.active = self.direction != "KEEP"
        row.prop(self, "angle")
        row = layout.row(heading="Period")
        row.prop(self, "set_period", text="")
        sub = row.row()
        sub.active = self.set_period
        sub.prop(self, "period", text="")
        layout.prop(self, "new_domain")

    def invoke(self, context, event):
        if self.direction == "VIEW":
            self._capture_view(context)
        return self.execute(context)

    def _capture_view(self, context) -> bool:
        rv3d = getattr(context, "region_data", None)
        if rv3d is None or not hasattr(rv3d, "view_rotation"):
            return False
        from mathutils import Vector

        right = rv3d.view_rotation @ Vector((1.0, 0.0, 0.0))
        local = context.active_object.matrix_world.to_3x3().inverted_safe() @ right
        self.view_vector = local
        return True

    def execute(self, context):
        ob, faces, field = self._begin(context)
        if field is None:
            return {"CANCELLED"}
        sel = faces.selected
        n = faces.geometry.normal
        direction = None
        if self.direction == "VIEW":
            if np.linalg.norm(self.view_vector) < 1e-9 and not self._capture_view(context):
                self.report({"ERROR"}, "no 3D view to take the direction from: use Angle or Active Edge")
                return {"CANCELLED"}
            direction = core_opal.direction_from_vector(n[sel], np.array(self.view_vector, np.float64))
        elif self.direction == "ACTIVE_EDGE":
            if faces.active_edge is None or np.linalg.norm(faces.active_edge) == 0:
                self.report({"ERROR"}, "no active edge: select an edge last (edge select mode), then the faces")
                return {"CANCELLED"}
            direction = core_opal.direction_from_vector(n[sel], faces.active_edge)
        elif self.direction == "ANGLE":
            direction = core_opal.direction_from_angle(n[sel], self.angle)
        elif self.direction == "ROTATE":
            direction = core_opal.rotate_directions(field.direction, n, sel, self.angle)[sel]
        if direction is not None and self.direction in ("VIEW", "ACTIVE_EDGE") and self.angle:
            full = field.direction.copy()
            full[sel] = direction
            direction = core_opal.rotate_directions(full, n, sel, self.angle)[sel]
        per_face = None
        if direction is not None:
            per_face = field.direction.astype(np.float64).copy()
            per_face[sel] = direction
        out = core_opal.assign_grating(field, n, sel, per_face, self.period if self.set_period else None,
                                       self.new_domain)
        write_field(ob, out, faces=sel, normals=n)
        return {"FINISHED"}


class OPAL_OT_jitter_period(_EditOp, bpy.types.Operator):
    """Move the selected faces' periods by a random amount (one offset per domain, or per face)"""

    bl_idname = "opal.jitter_period"
    bl_label = "Jitter Period"
    bl_options = {"REGISTER", "UNDO"}

    amount: FloatProperty(name="Amount", description="Largest change, nm (uniform in +-amount)", default=30.0,
                          min=0.0, soft_max=500.0, precision=1)
    seed: IntProperty(name="Seed", default=0, min=0)
    per_domain: BoolProperty(name="Per Domain", description="One offset per domain (domains stay uniform); off: "
                             "one per face", default=True)

    def execute(self, context):
        ob, faces, field = self._begin(context)
        if field is None:
            return {"CANCELLED"}
        base = np.where(field.period > 0, field.period, _material_period(ob))
        field.period = core_opal.jitter_period(base, field.domain, faces.selected, self.amount, self.seed,
                                               self.per_domain, low=1.0)
        write_field(ob, field, faces=faces.selected, normals=faces.geometry.normal)
        return {"FINISHED"}


def _material_period(ob) -> float:
    for s in ob.material_slots:
        if s.material is not None and s.material.opal.grating:
            return float(s.material.opal.period)
    return 550.0


class OPAL_OT_split_domain(_EditOp, bpy.types.Operator):
    """Split the selected faces into new domains (Voronoi cells over the selection), each with a new
    random direction"""

    bl_idname = "opal.split_domain"
    bl_label = "Split Domains"
    bl_options = {"REGISTER", "UNDO"}

    parts: IntProperty(name="Parts", description="Number of new domains", default=2, min=1, soft_max=100)
    seed: IntProperty(name="Seed", default=0, min=0)

    def execute(self, context):
        ob, faces, field = self._begin(context)
        if field is None:
            return {"CANCELLED"}
        out = core_opal.split_domains(field, faces.geometry, faces.selected, self.parts, self.seed)
        write_field(ob, out, faces=faces.selected, normals=faces.geometry.normal)
        return {"FINISHED"}


class OPAL_OT_merge_domains(_EditOp, bpy.types.Operator):
    """Merge the domains of the selected faces into one, with the active face's direction and period"""

    bl_idname = "opal.merge_domains"
    bl_label = "Merge Domains"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        ob, faces, field = self._begin(context)
        if field is None:
            return {"CANCELLED"}
        active = faces.active_face if faces.active_face is not None and faces.selected[faces.active_face] else None
        out = core_opal.merge_domains(field, faces.geometry.normal, faces.selected, active)
        changed = _domains_of(field, faces.selected)
        write_field(ob, out, faces=changed, normals=faces.geometry.normal)
        return {"FINISHED"}


class OPAL_OT_select_domain(_EditOp, bpy.types.Operator):
    """Select every face of the domains that have a selected face (volume domains: the faces whose
    centres lie in the same cells)"""

    bl_idname = "opal.select_domain"
    bl_label = "Select Domains"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        ob, faces, field = self._begin(context)
        if field is None:
            return {"CANCELLED"}
        vol = read_domains(ob)
        if vol is not None and (bragg_material(ob) is not None or faces.field is None):
            cells = face_cells(faces, vol)
            want = np.isin(cells, np.unique(cells[faces.selected]))
        else:
            want = _domains_of(field, faces.selected)
        bm = bmesh.from_edit_mesh(ob.data)
        bm.faces.ensure_lookup_table()
        for i in np.flatnonzero(want & ~faces.selected).tolist():
            bm.faces[i].select_set(True)
        bm.select_flush_mode()
        bmesh.update_edit_mesh(ob.data, loop_triangles=False, destructive=False)
        return {"FINISHED"}


class OPAL_OT_update_preview(bpy.types.Operator):
    """Recompute the preview colours (hue = direction, brightness = period) and show them in Solid mode"""

    bl_idname = "opal.update_preview"
    bl_label = "Update Grating Preview"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return is_mesh(context) and context.mode in ("OBJECT", "EDIT_MESH")

    def execute(self, context):
        ob = context.active_object
        faces = read_faces(ob)
        vol = read_domains(ob)
        if vol is not None:
            write_bragg_preview(ob, vol, faces)
            show_preview(context)
            return {"FINISHED"}
        if faces.field is None:
            self.report({"ERROR"}, "the mesh has no grating attributes: generate domains first")
            return {"CANCELLED"}
        write_field(ob, faces.field, normals=faces.geometry.normal)
        show_preview(context)
        return {"FINISHED"}


for _cls in (MESH_OT_primitive_opal_add, OPAL_OT_generate_domains):
    _cls.__annotations__.update(_domain_props())  # Blender reads properties from annotations


#: The operators, in registration order.
operators = (
    MESH_OT_primitive_opal_add,
    OPAL_OT_generate_domains,
    OPAL_OT_assign_grating,
    OPAL_OT_jitter_period,
    OPAL_OT_split_domain,
    OPAL_OT_merge_domains,
    OPAL_OT_select_domain,
    OPAL_OT_update_preview,
    OPAL_OT_set_domain,
)
