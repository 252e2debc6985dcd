"""The opal tools through bpy: Add Opal (a real-size BRAGG cabochon), volume domains (generation,
save/load, the transform, the Set Domain tool, export to the Scene), presets through Blender's
preset system (shipped, added, removed; opal and glass), the BRAGG properties exported to the
material columns, surface grating domains, Edit Mode placement with undo, save/load of the
attributes, the export and render reading them, and the rendered viewport's logic (schedule,
camera, pixels, progressive thread, view_update/view_draw with mocks)."""

from __future__ import annotations

import math
import os
import types
import uuid

import bmesh
import bpy
import numpy as np
import pytest

import blender_scenes as bs
from opal_diffraction.blender import opal_ops, viewport
from opal_diffraction.blender.engine import OpalRenderEngine
from opal_diffraction.blender.export import export_scene
from opal_diffraction.blender import opal_presets
from opal_diffraction.blender.opal_domains import read_domains
from opal_diffraction.blender.opal_presets import PRESET_ITEMS, preset_file, preset_files, read_preset
from opal_diffraction.core.util import enums as core_enums
from opal_diffraction.core import opal as core_opal
from opal_diffraction.core.sampling.camera import generate_rays
from opal_diffraction.core.render import progressive
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.validation import validate
from opal_diffraction.core.scene.settings import RenderSettings

ATTRS = {"opal_grating_direction": ("FLOAT_VECTOR", "FACE"), "opal_grating_period": ("FLOAT", "FACE"),
         "opal_grating_domain": ("INT", "FACE"), "opal_preview": ("FLOAT_COLOR", "CORNER")}


def _add_opal(**kw):
    """A surface-grating opal (the paper's preset) covered with 25 grating domains."""
    bs.empty_scene()
    args = dict(resolution=10, preset="PAPER")
    args.update(kw)
    count, seed = args.pop("count", 25), args.pop("seed", 3)
    assert bpy.ops.mesh.primitive_opal_add(**args) == {"FINISHED"}
    assert bpy.ops.opal.generate_domains(domain_type="SURFACE", count=count, seed=seed) == {"FINISHED"}
    return bpy.context.active_object


def _add_bragg_opal(**kw):
    bs.empty_scene()
    args = dict(resolution=12)
    args.update(kw)
    assert bpy.ops.mesh.primitive_opal_add(**args) == {"FINISHED"}
    return bpy.context.active_object


def _field(ob):
    """(domain, direction, period) of the mesh (Object Mode)."""
    f = opal_ops.read_faces(ob).field
    return f.domain.copy(), f.direction.copy(), f.period.copy()


def _normals(me):
    n = np.empty(len(me.polygons) * 3, np.float32)
    me.polygons.foreach_get("normal", n)
    return n.reshape(-1, 3)


def _select_faces(ob, mask):
    """Enter Edit Mode with exactly the faces ``mask`` selected."""
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_mode(type="FACE")
    bm = bmesh.from_edit_mesh(ob.data)
    bm.faces.ensure_lookup_table()
    for f in bm.faces:
        f.select_set(bool(mask[f.index]))
    bm.select_flush_mode()
    bmesh.update_edit_mesh(ob.data)


# ---------------------------------------------------------------------------- Add Opal
def test_add_opal_creates_mesh_material_and_attributes():
    ob = _add_opal(size_x=2.0, size_y=1.2, height=0.4)
    me = ob.data
    assert ob.type == "MESH" and len(me.polygons) == 6 * 10 * 10 + 6 * 10
    assert ob.dimensions.x == pytest.approx(2.0, rel=1e-5) and ob.dimensions.z == pytest.approx(0.4, rel=1e-5)
    for name, (dtype, domain) in ATTRS.items():
        a = me.attributes.get(name)
        assert a is not None and (a.data_type, a.domain) == (dtype, domain), name
    assert me.color_attributes.active_color.name == "opal_preview"
    mat = me.materials[0]
    assert mat.opal.grating and mat.opal.grating_direction == "ATTRIBUTE" and mat.opal.lattice == "LINES"
    assert opal_ops._menu_add in bpy.types.VIEW3D_MT_mesh_add._dyn_ui_initialize()  # Add > Mesh > Opal


def test_default_add_opal_is_a_real_size_black_bragg_cabochon():
    bs.empty_scene()
    assert bpy.ops.mesh.primitive_opal_add() == {"FINISHED"}
    ob = bpy.context.active_object
    for got, want in zip(ob.dimensions, (0.018, 0.013, 0.006)):
        assert abs(got - want) <= 0.1 * want, (tuple(ob.dimensions), want)
    mat = ob.data.materials[0]
    black = read_preset(preset_file("BLACK"))
    o = mat.opal
    assert o.grating and o.lattice == "BRAGG" == black["lattice"]
    for name in ("sphere_diameter", "sphere_ior", "void_ior", "layers", "mosaic_spread", "domain_count"):
        assert getattr(o, name) == pytest.approx(black[name]), name
    node = mat.node_tree.nodes["Principled BSDF"]
    assert tuple(node.inputs["Base Color"].default_value)[:3] == pytest.approx(black["body_color"])
    assert o.grating_problems() == []
    d = read_domains(ob)
    assert len(d) == black["domain_count"]
    lo, hi = black["sphere_diameter"] - black["diameter_spread"], black["sphere_diameter"] + black["diameter_spread"]
    assert d.diameter.min() >= lo - 1e-3 and d.diameter.max() <= hi + 1e-3
    # every seed inside the half ellipsoid of the cabochon (which contains the mesh)
    a, b, h = 0.009, 0.0065, 0.006
    assert ((d.seeds[:, 0] / a) ** 2 + (d.seeds[:, 1] / b) ** 2 + (d.seeds[:, 2] / h) ** 2 <= 1 + 1e-9).all()
    assert ob.data.color_attributes.active_color.name == "opal_preview"


def _face_colors(me):
    """Per-face preview colour (the first corner's)."""
    col = me.color_attributes["opal_preview"]
    rgba = np.empty(len(me.loops) * 4, np.float32)
    col.data.foreach_get("color", rgba)
    starts = np.empty(len(me.polygons), np.int32)
    me.polygons.foreach_get("loop_start", starts)
    return rgba.reshape(-1, 4)[starts]


def _face_centres(me):
    c = np.empty(len(me.polygons) * 3, np.float32)
    me.polygons.foreach_get("center", c)
    return c.reshape(-1, 3).astype(np.float64)


def _cells_brute(points, d):
    """The cell of each point by the definition: argmin |p - seed| - weight over every seed."""
    dist = np.linalg.norm(points[:, None, :] - d.seeds[None], axis=2) - d.weight[None]
    return np.argmin(dist, axis=1)


def test_bragg_preview_shows_each_cells_colour_at_normal_incidence():
    """Faces of one cell share one colour; cells of small spheres preview blue, of large ones red:
    lambda = 2 sqrt(2/3) D n_eff with water voids (n_eff 1.4198) is below 470 nm for D < 203 nm
    and above 610 nm for D > 263 nm."""
    ob = _add_bragg_opal(resolution=16, count=60, seed=2)
    me = ob.data
    d = read_domains(ob)
    # the polygons' centres are area-weighted in Blender too; the cells the faces lie in
    cells = _cells_brute(_face_centres(me), d)
    rgb = _face_colors(me)[:, :3]
    for c in np.unique(cells):
        assert np.ptp(rgb[cells == c], axis=0).max() < 1e-6
    dia = d.diameter[cells]
    small, large = dia < 203, dia > 263
    assert small.any() and large.any()
    assert (rgb[small, 2] > rgb[small, 0]).all() and (rgb[large, 0] > rgb[large, 2]).all()


def test_bragg_properties_export_to_the_material_columns():
    ob = _add_bragg_opal()
    o = ob.data.materials[0].opal
    o.sphere_diameter, o.sphere_ior, o.void_ior, o.layers, o.mosaic_spread = 271.5, 1.44, 1.38, 77, 4.5
    ob.data.materials[0].update_tag()  # a script's change: the depsgraph copies the material again
    bs.camera(location=(0, 0, 0.1))
    m = export_scene(bpy.context.evaluated_depsgraph_get(), width=8, height=8).scene.materials
    row = [i for i, n in enumerate(m.name) if n.startswith("Opal")][0]
    assert int(m.lattice[row]) == int(core_enums.Lattice.BRAGG) and int(m.grating[row]) == 1
    assert m.sphere_diameter[row] == pytest.approx(271.5) and m.sphere_ior[row] == pytest.approx(1.44)
    assert m.void_ior[row] == pytest.approx(1.38) and int(m.layers[row]) == 77
    assert m.mosaic_spread[row] == pytest.approx(4.5)
    o.void_ior = 0.5  # below the field's minimum: clamped to 1 (air)
    assert o.void_ior == 1.0 and o.grating_problems() == []


@pytest.mark.parametrize("ident", [i[0] for i in PRESET_ITEMS])
def test_shipped_presets_set_body_and_lattice_and_state_their_physics(ident):
    bs.empty_scene()
    mat = bs.material("m", "PRINCIPLED")
    with bpy.context.temp_override(material=mat):
        assert bpy.ops.opal.opal_preset(preset=ident) == {"FINISHED"}
    path = preset_file(ident)
    p = read_preset(path)
    assert mat.opal.grating and mat.opal.lattice == p["lattice"]
    node = mat.node_tree.nodes["Principled BSDF"]
    assert tuple(node.inputs["Base Color"].default_value)[:3] == pytest.approx(p["body_color"])
    assert mat.opal.grating_problems() == []
    if p["lattice"] == "BRAGG":
        # the header's stated colour range is the Bragg law's (docs/physics.md section 5.2)
        with open(path, encoding="utf-8") as fh:
            head = fh.read(800)
        n_eff = math.sqrt(0.74 * p["sphere_ior"] ** 2 + 0.26 * p["void_ior"] ** 2)
        lo, hi = (2 * math.sqrt(2 / 3) * (p["sphere_diameter"] + k * p["diameter_spread"]) * n_eff for k in (-1, 1))
        assert f"{lo:.0f}-{hi:.0f} nm" in head and f"n_eff {n_eff:.4f}" in head
        assert f"n_void {p['void_ior']:g}" in head and f"D_s = {p['sphere_diameter']:g}" in head


def test_harlequin_has_large_domains_and_pinfire_small():
    count = {i: read_preset(preset_file(i))["domain_count"] for i in ("HARLEQUIN", "BLACK", "PINFIRE")}
    assert count["HARLEQUIN"] * 5 <= count["BLACK"] and count["BLACK"] * 5 <= count["PINFIRE"]


def _existing_folders(root: str, subdir: str) -> set[str]:
    """The folders from ``root`` down to ``root/subdir`` that exist now."""
    parts = subdir.split("/")
    paths = [os.path.join(root, *parts[:i]) for i in range(len(parts) + 1)]
    return {p for p in paths if os.path.isdir(p)}


def _remove_empty_folders(root: str, subdir: str, keep: set[str]) -> None:
    """Remove the empty folders from ``root/subdir`` upwards that were not in ``keep``."""
    parts = subdir.split("/")
    for i in range(len(parts), -1, -1):
        p = os.path.join(root, *parts[:i])
        if p in keep or not os.path.isdir(p) or os.listdir(p):
            return
        os.rmdir(p)


def _execute_preset(mat, path, menu):
    with bpy.context.temp_override(material=mat):
        assert bpy.ops.script.execute_preset(filepath=path, menu_idname=menu) == {"FINISHED"}


@pytest.mark.parametrize("kind", ["opal", "glass"])
def test_presets_add_and_remove_through_the_preset_operator(kind):
    """A user preset: + writes the material's values to the user's presets folder (listed in the
    menu beside the shipped ones), the menu's entry applies it to another material, - removes it."""
    bs.empty_scene()
    subdir = opal_presets.OPAL_SUBDIR if kind == "opal" else opal_presets.GLASS_SUBDIR
    menu = "OPAL_MT_opal_presets" if kind == "opal" else "OPAL_MT_glass_presets"
    add = bpy.ops.opal.opal_preset_add if kind == "opal" else bpy.ops.opal.glass_preset_add
    src = bs.material("src", "PRINCIPLED")
    o = src.opal
    if kind == "opal":
        opal_presets.apply_preset(src, "BLACK")
        o.sphere_diameter, o.void_ior, o.layers, o.mosaic_spread, o.domain_count = 262.0, 1.41, 55, 2.5, 123
        o.body_color = (0.2, 0.1, 0.05)
    else:
        o.dispersion, o.abbe_number, o.node_ior = "ABBE", 33.3, 1.654
    name = f"Test Stone {uuid.uuid4().hex[:8]}"
    user_presets = bpy.utils.user_resource("SCRIPTS", path="presets")
    existed = _existing_folders(user_presets, subdir)
    with bpy.context.temp_override(material=src):
        assert add(name=name) == {"FINISHED"}
    files = preset_files(subdir)
    assert name in files and os.path.isfile(files[name])
    try:
        assert files[name].startswith(bpy.utils.user_resource("SCRIPTS", path="presets"))
        dst = bs.material("dst", "PRINCIPLED")
        _execute_preset(dst, files[name], menu)
        if kind == "opal":
            d = dst.opal
            assert (d.lattice, d.layers, d.domain_count) == ("BRAGG", 55, 123)
            assert d.sphere_diameter == pytest.approx(262.0) and d.void_ior == pytest.approx(1.41)
            node = dst.node_tree.nodes["Principled BSDF"]
            assert tuple(node.inputs["Base Color"].default_value)[:3] == pytest.approx((0.2, 0.1, 0.05))
        else:
            assert dst.opal.dispersion == "ABBE" and dst.opal.abbe_number == pytest.approx(33.3)
            assert dst.node_tree.nodes["Principled BSDF"].inputs["IOR"].default_value == pytest.approx(1.654)
        with bpy.context.temp_override(material=src):
            assert add(name=os.path.basename(files[name])[:-3], remove_name=True) == {"FINISHED"}
        assert name not in preset_files(subdir) and not os.path.exists(files[name])
    finally:
        if os.path.exists(files[name]):
            os.remove(files[name])
        _remove_empty_folders(user_presets, subdir, existed)  # leave the user's config as it was
    # the shipped presets cannot be removed (they live in the extension's folder)
    shipped = next(iter(preset_files(subdir)))
    with bpy.context.temp_override(material=src):
        assert add(name=shipped, remove_name=True) == {"CANCELLED"}
    assert shipped in preset_files(subdir)


def test_glass_preset_sets_dispersion_and_node_ior():
    bs.empty_scene()
    mat = bs.material("g", "PRINCIPLED")
    _execute_preset(mat, preset_file("Diamond", opal_presets.GLASS_SUBDIR), "OPAL_MT_glass_presets")
    assert mat.opal.dispersion == "DIAMOND" and mat.opal.abbe_number == pytest.approx(55.3)
    assert mat.node_tree.nodes["Principled BSDF"].inputs["IOR"].default_value == pytest.approx(2.4175)


def test_shipped_glass_presets_are_the_named_glasses():
    """One shipped glass preset per DISPERSION_PRESETS entry (what opal.dispersion_preset applies), same values."""
    from opal_diffraction.blender.properties import DISPERSION_PRESETS

    files = {read_preset(p)["node_ior"]: read_preset(p) for p in preset_files(opal_presets.GLASS_SUBDIR).values()}
    for _ident, _name, model, n_d, abbe in DISPERSION_PRESETS:
        p = files[n_d]
        assert (p["dispersion"], p["abbe_number"]) == (model, abbe)


def test_preset_menus_draw_shipped_and_user_entries():
    for cls, add in ((opal_presets.OPAL_MT_opal_presets, "opal.opal_preset_add"),
                     (opal_presets.OPAL_MT_glass_presets, "opal.glass_preset_add")):
        calls = []
        fake = types.SimpleNamespace(preset_subdir=cls.preset_subdir, preset_operator=cls.preset_operator,
                                     preset_add_operator=cls.preset_add_operator,
                                     path_menu=lambda dirs, op, **kw: calls.append((dirs, op, kw)))
        cls.draw(fake, bpy.context)
        (dirs, op, kw), = calls
        assert op == "script.execute_preset" and kw["add_operator"] == add
        assert os.path.isdir(dirs[0]) and dirs[0].startswith(opal_presets.SHIPPED)
        assert dirs[1:] == list(bpy.utils.preset_paths(cls.preset_subdir))
    names = {n for n in preset_files()}
    assert {"Black", "White", "Crystal", "Boulder", "Harlequin", "Pinfire", "Paper Model"} <= names
    assert len(preset_files(opal_presets.GLASS_SUBDIR)) >= 10


# ---------------------------------------------------------------------------- volume domains
def test_volume_domains_survive_save_and_reload_and_transform_with_the_object(tmp_path):
    ob = _add_bragg_opal(count=40, seed=4)
    ob.location = (0.3, -0.1, 0.05)
    ob.rotation_euler = (0.4, -0.2, 1.1)
    ob.scale = (2.0, 2.0, 2.0)
    bs.camera(location=(0.3, -0.1, 1.0))
    before = read_domains(ob)
    name = ob.name
    path = str(tmp_path / "opal.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=path)
    ob = bpy.data.objects[name]
    after = read_domains(ob)
    for f in ("seeds", "weight", "axis", "diameter"):
        np.testing.assert_array_equal(getattr(before, f), getattr(after, f), err_msg=f)
    s = export_scene(bpy.context.evaluated_depsgraph_get(), width=8, height=8).scene
    m = np.array(ob.matrix_world)
    np.testing.assert_allclose(s.domain_seeds, after.seeds @ m[:3, :3].T + m[:3, 3], atol=1e-9)
    np.testing.assert_allclose(s.domain_weight, 2.0 * after.weight, rtol=1e-6)  # a float32 matrix
    rot = m[:3, :3] / 2.0
    np.testing.assert_allclose(s.domain_axis, after.axis @ rot.T, atol=1e-5)
    assert (s.tri_domain_group == 0).all() and len(s.tri_domain_group) == len(s.triangles)
    # a world point lies in the cell of its object-space point
    clean = validate(s).scene
    vd = clean.volume_domains()
    rng = np.random.default_rng(1)
    local = rng.uniform((-0.008, -0.006, 0.0), (0.008, 0.006, 0.005), (500, 3))
    world = local @ m[:3, :3].T + m[:3, 3]
    _, dia, found = vd.lookup(world, np.zeros(len(world), np.int64))
    assert found.all()
    np.testing.assert_array_equal(dia, after.diameter[_cells_brute(local, after)])


def test_export_gives_each_instance_its_group_and_plain_objects_none():
    ob = _add_bragg_opal(count=10, seed=1)
    dup = ob.copy()  # a linked duplicate (the same mesh), its own domains, moved
    bpy.context.scene.collection.objects.link(dup)
    dup.location = (0.05, 0.0, 0.0)
    bpy.ops.mesh.primitive_plane_add(size=0.1, location=(0, 0, -0.01))
    bs.camera(location=(0, 0, 1.0))
    s = export_scene(bpy.context.evaluated_depsgraph_get(), width=8, height=8).scene
    assert len(s.domain_seeds) == 20 and set(np.unique(s.domain_group)) == {0, 1}
    groups, counts = np.unique(s.tri_domain_group, return_counts=True)
    nt = len(ob.data.loop_triangles)
    assert dict(zip(groups.tolist(), counts.tolist())) == {-1: 2, 0: nt, 1: nt}
    moved = s.domain_seeds[s.domain_group == 1] - s.domain_seeds[s.domain_group == 0]
    np.testing.assert_allclose(moved, np.broadcast_to([0.05, 0, 0], moved.shape), atol=1e-9)


def test_generate_volume_domains_operator_is_seeded_and_needs_a_closed_mesh():
    ob = _add_bragg_opal()
    assert bpy.ops.opal.generate_domains(count=50, seed=7) == {"FINISHED"}
    a = read_domains(ob)
    assert len(a) == 50
    bpy.ops.opal.generate_domains(count=50, seed=8)
    assert not np.allclose(read_domains(ob).seeds, a.seeds)
    bpy.ops.opal.generate_domains(count=50, seed=7)
    np.testing.assert_array_equal(read_domains(ob).seeds, a.seeds)
    # unset values come from the material: its domain count and diameter range
    mat = ob.data.materials[0]
    mat.opal.domain_count, mat.opal.sphere_diameter, mat.opal.diameter_spread = 33, 300.0, 5.0
    bpy.ops.opal.generate_domains(seed=1)
    d = read_domains(ob)
    assert len(d) == 33 and d.diameter.min() >= 295.0 - 1e-3 and d.diameter.max() <= 305.0 + 1e-3
    bpy.ops.mesh.primitive_plane_add(size=0.01)  # open: no volume
    with pytest.raises(RuntimeError, match="closed"):
        bpy.ops.opal.generate_domains(domain_type="VOLUME", count=5)


@pytest.mark.parametrize("kw", [
    dict(orientation="AXIS", axis=(1.0, 0.0, 0.0), set_diameter=True, diameter=301.0),
    dict(orientation="NORMAL"),
    dict(orientation="KEEP", set_diameter=True, diameter=199.0),
    dict(orientation="RANDOM", seed=3),
])
def test_set_domain_changes_only_the_cells_of_the_selected_faces(kw):
    ob = _add_bragg_opal(resolution=12, count=80, seed=5)
    me = ob.data
    before = read_domains(ob)
    colors_before = _face_colors(me)
    cells = _cells_brute(_face_centres(me), before)
    sel = np.zeros(len(me.polygons), bool)
    sel[[3, 40, 41, 200, 500]] = True
    target = np.unique(cells[sel])
    _select_faces(ob, sel)
    assert bpy.ops.opal.set_domain(**kw) == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    after = read_domains(ob)
    changed = (np.abs(after.axis - before.axis).max(axis=1) > 1e-7) | (after.diameter != before.diameter)
    np.testing.assert_array_equal(np.flatnonzero(changed), target)
    np.testing.assert_array_equal(after.seeds, before.seeds)
    np.testing.assert_allclose(np.linalg.norm(after.axis, axis=1), 1.0, atol=1e-6)
    if kw["orientation"] == "AXIS":
        np.testing.assert_allclose(after.axis[target], np.broadcast_to([1, 0, 0], (len(target), 3)), atol=1e-6)
    if kw["orientation"] == "NORMAL":
        n = np.empty(len(me.polygons) * 3, np.float32)
        me.polygons.foreach_get("normal", n)
        area = np.empty(len(me.polygons), np.float32)
        me.polygons.foreach_get("area", area)
        mean = (n.reshape(-1, 3)[sel] * area[sel, None]).sum(axis=0)
        np.testing.assert_allclose(after.axis[target], np.broadcast_to(mean / np.linalg.norm(mean),
                                                                        (len(target), 3)), atol=1e-5)
    if kw.get("set_diameter"):
        assert (after.diameter[target] == np.float32(kw["diameter"])).all()
        # the preview changed exactly on the faces of those cells
        moved = np.abs(_face_colors(me) - colors_before).max(axis=1) > 1e-6
        assert not moved[~np.isin(cells, target)].any() and moved[sel].all()


def test_select_domain_grows_the_selection_to_whole_volume_cells():
    ob = _add_bragg_opal(resolution=12, count=40, seed=6)
    cells = _cells_brute(_face_centres(ob.data), read_domains(ob))
    sel = np.zeros(len(ob.data.polygons), bool)
    sel[[10, 300]] = True
    _select_faces(ob, sel)
    assert bpy.ops.opal.select_domain() == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    now = np.empty(len(ob.data.polygons), bool)
    ob.data.polygons.foreach_get("select", now)
    np.testing.assert_array_equal(now, np.isin(cells, cells[sel]))


def test_set_domain_needs_volume_domains_edit_mode_and_faces():
    ob = _add_bragg_opal(count=10)
    assert not bpy.ops.opal.set_domain.poll()  # Object Mode
    _select_faces(ob, np.zeros(len(ob.data.polygons), bool))
    assert bpy.ops.opal.set_domain.poll()
    with pytest.raises(RuntimeError, match="no faces selected"):
        bpy.ops.opal.set_domain(orientation="AXIS")
    with pytest.raises(RuntimeError, match="no 3D view"):
        _select_faces(ob, np.ones(len(ob.data.polygons), bool))
        bpy.ops.opal.set_domain(orientation="VIEW")
    bpy.ops.object.mode_set(mode="OBJECT")


def test_domains_cover_every_face_with_unit_directions_in_the_face_plane_and_ranged_periods():
    ob = _add_opal()
    assert bpy.ops.opal.generate_domains(count=30, seed=5, period_mode="SPHERES", low=180.0, high=300.0) == {"FINISHED"}
    domain, direction, period = _field(ob)
    n = _normals(ob.data)
    assert len(domain) == len(ob.data.polygons) and domain.min() >= 0
    np.testing.assert_array_equal(np.unique(domain), np.arange(domain.max() + 1))
    np.testing.assert_allclose(np.linalg.norm(direction, axis=1), 1.0, atol=1e-5)
    assert np.abs(np.einsum("ij,ij->i", direction, n)).max() < 1e-4
    lo, hi = core_opal.period_from_sphere_diameter(np.array([180.0, 300.0]))
    assert period.min() >= lo - 1e-3 and period.max() <= hi + 1e-3 and np.ptp(period) > 10
    bpy.ops.opal.generate_domains(count=30, seed=5, period_mode="PERIOD", low=400.0, high=420.0)
    assert _field(ob)[2].min() >= 400.0 and _field(ob)[2].max() <= 420.0


def test_the_seed_reproduces_the_domains():
    ob = _add_opal()
    bpy.ops.opal.generate_domains(count=20, seed=9)
    a = _field(ob)
    bpy.ops.opal.generate_domains(count=20, seed=10)
    b = _field(ob)
    bpy.ops.opal.generate_domains(count=20, seed=9)
    c = _field(ob)
    for x, z in zip(a, c):
        np.testing.assert_array_equal(x, z)
    assert (a[0] != b[0]).any()


def test_paper_model_preset_is_one_aligned_domain():
    bs.empty_scene()
    assert bpy.ops.mesh.primitive_opal_add(resolution=10, preset="PAPER") == {"FINISHED"}
    ob = bpy.context.active_object
    domain, direction, period = _field(ob)
    assert (domain == 0).all() and np.allclose(period, read_preset(preset_file("PAPER"))["period"])
    n = _normals(ob.data)
    np.testing.assert_allclose(direction, core_opal.aligned_directions(n), atol=1e-5)
    assert ob.data.materials[0].opal.lattice == "LINES" and read_domains(ob) is None


# ---------------------------------------------------------------------------- Edit Mode
@pytest.mark.parametrize("kw", [
    dict(direction="ANGLE", angle=0.6, set_period=True, period=612.0),
    dict(direction="ROTATE", angle=math.pi / 2, new_domain=False),
    dict(direction="ACTIVE_EDGE"),
    dict(direction="KEEP", set_period=True, period=480.0, new_domain=False),
])
def test_edit_mode_assignment_changes_exactly_the_selected_faces(kw):
    ob = _add_opal()
    before = _field(ob)
    sel = np.zeros(len(ob.data.polygons), bool)
    sel[5:40:3] = True
    _select_faces(ob, sel)
    if kw["direction"] == "ACTIVE_EDGE":
        bm = bmesh.from_edit_mesh(ob.data)
        bm.faces.ensure_lookup_table()
        edge = bm.faces[5].edges[0]
        bm.select_history.add(edge)  # the active edge, selection unchanged (its face is selected)
        bmesh.update_edit_mesh(ob.data)
    assert bpy.ops.opal.assign_grating(**kw) == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    after = _field(ob)
    changed = (after[0] != before[0]) | (np.abs(after[1] - before[1]).max(axis=1) > 1e-6) | (after[2] != before[2])
    np.testing.assert_array_equal(changed, sel)
    n = _normals(ob.data)
    assert np.abs(np.einsum("ij,ij->i", after[1], n)).max() < 1e-4
    if kw.get("set_period"):
        assert np.allclose(after[2][sel], kw["period"])
    if kw["direction"] == "ROTATE":
        np.testing.assert_allclose(np.einsum("ij,ij->i", after[1][sel], before[1][sel]), 0.0, atol=1e-4)
    if kw.get("new_domain", True):
        assert len(np.unique(after[0][sel])) == 1 and after[0][sel][0] == before[0].max() + 1


def test_edit_mode_jitter_split_merge_and_select():
    ob = _add_opal()
    before = _field(ob)
    sel = before[0] == before[0][0]
    _select_faces(ob, sel)
    assert bpy.ops.opal.jitter_period(amount=25.0, seed=2) == {"FINISHED"}
    assert bpy.ops.opal.split_domain(parts=3, seed=1) == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    after = _field(ob)
    np.testing.assert_array_equal(after[0][~sel], before[0][~sel])
    np.testing.assert_array_equal(after[2][~sel], before[2][~sel])
    assert after[0][sel].min() > before[0].max() and np.abs(after[2][sel] - before[2][sel]).max() <= 25.0 + 1e-3
    # merge two domains through one selected face each; select_domain grows a selection to whole domains
    d1, d2 = np.unique(before[0][~sel])[:2]
    one = np.zeros_like(sel)
    one[[np.flatnonzero(before[0] == d1)[0], np.flatnonzero(before[0] == d2)[0]]] = True
    _select_faces(ob, one)
    assert bpy.ops.opal.merge_domains() == {"FINISHED"}
    assert bpy.ops.opal.select_domain() == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    merged = _field(ob)
    both = (before[0] == d1) | (before[0] == d2)
    assert len(np.unique(merged[0][both])) == 1
    sel_now = np.empty(len(ob.data.polygons), bool)
    ob.data.polygons.foreach_get("select", sel_now)
    np.testing.assert_array_equal(sel_now, both)


def _edit_field(ob):
    """(domain, direction, period) read from the edit mesh (staying in Edit Mode)."""
    f = opal_ops.read_faces(ob).field
    return f.domain.copy(), f.direction.copy(), f.period.copy()


def test_undo_restores_the_assignment():
    """Undo in the bpy module (no window): called with ``undo=True`` (what the UI does for an
    operator with the UNDO flag; scripts skip it by default) the operator pushes its own undo
    step, and ``bpy.ops.ed.undo()`` brings the faces back as they were before it."""
    ob = _add_opal()
    sel = np.zeros(len(ob.data.polygons), bool)
    sel[:30] = True
    _select_faces(ob, sel)
    bpy.ops.ed.undo_push(message="selection")
    before = _edit_field(ob)
    assert bpy.ops.opal.assign_grating("EXEC_DEFAULT", True, direction="ANGLE", angle=1.0, set_period=True,
                                       period=700.0) == {"FINISHED"}
    assigned = _edit_field(bpy.context.active_object)
    assert (assigned[2][sel] == 700.0).all()
    assert bpy.ops.ed.undo() == {"FINISHED"}
    restored = _edit_field(bpy.context.active_object)
    for x, y in zip(before, restored):
        np.testing.assert_array_equal(x, y)
    assert bpy.ops.ed.redo() == {"FINISHED"}
    redone = _edit_field(bpy.context.active_object)
    np.testing.assert_array_equal(redone[2], assigned[2])
    bpy.ops.object.mode_set(mode="OBJECT")


def test_operators_have_undo_and_redo_panels():
    ops = [c for c in opal_ops.classes if issubclass(c, bpy.types.Operator)]
    assert {c.bl_idname for c in ops} >= {"mesh.primitive_opal_add", "opal.generate_domains", "opal.assign_grating"}
    for c in ops:
        assert {"REGISTER", "UNDO"} <= set(c.bl_options), c.bl_idname


def test_edit_operators_need_edit_mode_and_faces():
    ob = _add_opal()
    assert not bpy.ops.opal.assign_grating.poll()  # Object Mode
    _select_faces(ob, np.zeros(len(ob.data.polygons), bool))
    assert bpy.ops.opal.assign_grating.poll()
    with pytest.raises(RuntimeError, match="no faces selected"):
        bpy.ops.opal.assign_grating(direction="ANGLE")
    with pytest.raises(RuntimeError, match="no 3D view"):
        _select_faces(ob, np.ones(len(ob.data.polygons), bool))
        bpy.ops.opal.assign_grating(direction="VIEW")
    bpy.ops.object.mode_set(mode="OBJECT")


# ---------------------------------------------------------------------------- save / export / render
def test_attributes_survive_save_and_reload(tmp_path):
    ob = _add_opal()
    name = ob.name
    before = _field(ob)
    path = str(tmp_path / "opal.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=path)
    ob = bpy.data.objects[name]
    after = _field(ob)
    for x, y in zip(before, after):
        np.testing.assert_array_equal(x, y)
    assert ob.data.materials[0].opal.grating_direction == "ATTRIBUTE"


def test_export_reads_direction_and_period_attributes():
    ob = _add_opal()
    ob.rotation_euler = (0.0, 0.0, math.radians(30))
    bs.camera(location=(0, 0, 5))
    domain, direction, period = _field(ob)
    ex = export_scene(bpy.context.evaluated_depsgraph_get(), width=8, height=8)
    s = ex.scene
    face = np.empty(len(ob.data.loop_triangles), np.int32)
    ob.data.loop_triangle_polygons.foreach_get("value", face)
    np.testing.assert_allclose(s.tri_period, period[face], rtol=1e-6)
    rot = np.array(ob.matrix_world.to_3x3())
    want = direction[face] @ rot.T
    np.testing.assert_allclose(s.tri_tangent, want / np.linalg.norm(want, axis=1)[:, None], atol=1e-5)
    # no attribute: no per-triangle periods (the material's)
    ob.data.attributes.remove(ob.data.attributes["opal_grating_period"])
    ex = export_scene(bpy.context.evaluated_depsgraph_get(), width=8, height=8)
    assert len(ex.scene.tri_period) == 0


def _two_domain_plane():
    """A flat 2 x 1 m plate of two faces (left domain 0, right domain 1), both with the grating
    vector along X and a 900 nm period, under a sun 40 degrees from the zenith in the XZ plane,
    seen from straight above: the first order lands at u = sin 40 = 0.64, 580 nm (yellow)."""
    sc = bs.empty_scene(24, 12)
    sc.opal.samples = 2
    sc.opal.filter_width = 0.5
    mat = bs.material("grating", "DIFFUSE", (0.0, 0.0, 0.0))
    o = mat.opal
    o.grating, o.grating_direction, o.lattice = True, "ATTRIBUTE", "LINES"
    o.period, o.slit_width, o.slit_count, o.coherence_length = 1600.0, 450.0, 200, 20.0
    ob = bs.mesh_object("plate", [(-1, -0.5, 0), (0, -0.5, 0), (1, -0.5, 0), (1, 0.5, 0), (0, 0.5, 0), (-1, 0.5, 0)],
                        [(0, 1, 4, 5), (1, 2, 3, 4)], mat)
    me = ob.data
    field = core_opal.DomainField(np.array([0, 1], np.int32), np.array([[1, 0, 0], [1, 0, 0]], np.float32),
                                  np.array([900.0, 900.0], np.float32))
    opal_ops.write_field(ob, field)
    bs.camera(location=(0, 0, 3), ortho_scale=2.0)
    bs.light("SUN", (0, 0, 3), 3.0, rotation=(0.0, math.radians(-40), 0.0))
    return sc, ob, me


def test_render_reads_the_attributes_a_rotated_domain_changes_only_its_pixels(tmp_path, last_render):
    sc, ob, me = _two_domain_plane()
    first = bs.render_to_array(str(tmp_path / "a.exr"))
    assert last_render["status"] == "FINISHED" and last_render["plan_gratings"]
    left, right = first[2:-2, 2:10], first[2:-2, 14:22]
    assert right.mean() > 0.05 and left.mean() > 0.05  # both lit by the first order
    assert right[..., 0].mean() > right[..., 2].mean()  # yellow: the 900 nm period, not the material's 1600
    # rotate the right domain's grating by 90 degrees in Edit Mode
    bpy.context.view_layer.objects.active = ob
    _select_faces(ob, np.array([False, True]))
    assert bpy.ops.opal.assign_grating(direction="ROTATE", angle=math.pi / 2, new_domain=False) == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    second = bs.render_to_array(str(tmp_path / "b.exr"))
    np.testing.assert_allclose(second[2:-2, 2:10], left, rtol=1e-4, atol=1e-6)  # the other domain: unchanged
    assert second[2:-2, 14:22].mean() < 0.2 * right.mean()  # slits along the light: no first order here


# ---------------------------------------------------------------------------- viewport logic
def test_preview_levels_start_small_and_end_at_full_resolution():
    assert progressive.preview_levels(16, 8) == [(8, 1), (4, 1), (2, 1), (1, 16)]
    assert progressive.preview_levels(4, 1) == [(1, 4)]
    assert progressive.preview_levels(4, 6) == [(4, 1), (2, 1), (1, 4)]
    assert progressive.level_size(100, 61, 8) == (13, 8)


@pytest.mark.parametrize("kind,shift", [("PERSP", (0.0, 0.0)), ("PERSP", (0.1, -0.05)), ("ORTHO", (0.05, 0.1))])
def test_viewport_camera_sees_what_the_view_matrices_show(kind, shift):
    """Rays of the camera built from (view, window) matrices land where the projection puts them."""
    bs.empty_scene(40, 30)
    cam = bs.camera(location=(1.0, -4.0, 2.0), rotation=(math.radians(70), 0, math.radians(15)),
                    ortho_scale=3.0 if kind == "ORTHO" else None, lens=35.0)
    cam.data.shift_x, cam.data.shift_y = shift
    dg = bpy.context.evaluated_depsgraph_get()
    w, h = 40, 30
    view = np.array(cam.matrix_world.inverted())
    window = np.array(cam.calc_matrix_camera(dg, x=w, y=h))
    c = viewport.viewport_camera(view, window, kind == "PERSP", w, h)
    xs = np.array([0.0, 40.0, 20.0, 7.5, 33.0])
    ys = np.array([0.0, 30.0, 15.0, 22.0, 4.0])
    o, d = generate_rays(c, xs, ys)
    p = np.asarray(o, np.float64) + 2.5 * np.asarray(d, np.float64)
    clip = (window @ view @ np.c_[p, np.ones(len(p))].T).T
    ndc = clip[:, :2] / clip[:, 3:4]
    np.testing.assert_allclose(ndc[:, 0], 2 * xs / w - 1, atol=1e-4)
    np.testing.assert_allclose(ndc[:, 1], 1 - 2 * ys / h, atol=1e-4)


def test_prepare_pixels_flips_rows_adds_alpha_and_clears_nan():
    rgb = np.zeros((2, 3, 3), np.float32)
    rgb[0, 0] = (1.0, 2.0, 3.0)  # top-left
    rgb[1, 2] = (np.nan, -1.0, np.inf)
    px = viewport.prepare_pixels(rgb).reshape(2, 3, 4)
    assert px.dtype == np.float32 and px.flags.c_contiguous
    np.testing.assert_array_equal(px[1, 0], (1.0, 2.0, 3.0, 1.0))  # bottom row first
    np.testing.assert_array_equal(px[0, 2], (0.0, 0.0, 0.0, 1.0))
    m = np.diag([2.0, 1.0, 0.5])
    np.testing.assert_allclose(viewport.prepare_pixels(rgb, m).reshape(2, 3, 4)[1, 0, :3], (2.0, 2.0, 1.5))
    # Film > Transparent: the coverage as alpha, rows flipped like the colours, NaN cleared
    alpha = np.array([[1.0, 0.25, 0.0], [0.5, np.nan, 2.0]], np.float32)
    px = viewport.prepare_pixels(rgb, None, alpha).reshape(2, 3, 4)
    np.testing.assert_array_equal(px[..., 3], [[0.5, 0.0, 1.0], [1.0, 0.25, 0.0]])


def _tiny_core_scene(size=32):
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)}])
    s = Scene(materials=mats)
    s.add_mesh([(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], [(0, 1, 2), (0, 2, 3)], material=0)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (0, 0, 2), "power": 100.0}])
    s.camera = Camera.look_at((0, 0, 5), (0, 0, 0), up=(0, 1, 0), width=size, height=size)
    return s


def test_progressive_renderer_runs_levels_restarts_and_cancels():
    images = []
    r = viewport.ProgressiveRenderer(on_image=lambda: images.append(r.frame()))
    settings = RenderSettings(wavelength_step=20.0, threads=1, tile_size=16)
    scene = _tiny_core_scene(32)
    levels = progressive.preview_levels(4, 8)
    r.start(prepare(scene, settings), levels)
    assert r.wait(60.0) and r.done and not r.error
    frames = [f for f in images if f is not None]
    sizes = [(f.width, f.height) for f in frames]
    assert sizes[0] == (4, 4) and sizes[-1] == (32, 32)  # low resolution first, full resolution last
    assert frames[-1].samples == 4 and r.first_image_s is not None
    assert frames[-1].pixels.shape == (32 * 32 * 4,) and frames[-1].pixels.max() > 0
    # a restart bumps the generation; the old render's images never show up afterwards
    g1 = r.start(prepare(scene, settings), [(1, 64)])
    g2 = r.start(prepare(scene, settings), [(2, 1)])
    assert g2 == g1 + 1
    assert r.wait(60.0)
    assert r.frame().generation == g2 and (r.frame().width, r.frame().height) == (16, 16)
    # cancel stops a long render at its next tile
    r.start(prepare(_tiny_core_scene(64), settings), [(1, 4096)])
    r.cancel(wait=30.0)
    assert not r.running


class _FakeEngine:
    """What view_update/view_draw use of a RenderEngine, for a test without a window."""

    _viewport = None
    _viewport_session = OpalRenderEngine._viewport_session

    def __init__(self):
        self.stats, self.bound = [], 0

    def update_stats(self, a, b):
        self.stats.append(b)

    def bind_display_space_shader(self, scene):
        self.bound += 1

    def unbind_display_space_shader(self):
        self.bound -= 1


def _view_context(cam, w=64, h=48):
    dg = bpy.context.evaluated_depsgraph_get()
    rv3d = types.SimpleNamespace(view_matrix=cam.matrix_world.inverted(),
                                 window_matrix=cam.calc_matrix_camera(dg, x=w, y=h), is_perspective=True)
    return types.SimpleNamespace(region=types.SimpleNamespace(width=w, height=h), region_data=rv3d), dg


def test_view_update_and_view_draw_with_mocks(monkeypatch):
    ob = _add_opal(resolution=6, count=10)
    sc = bpy.context.scene
    sc.opal.preview_samples, sc.opal.preview_start_scale = 2, 4
    sc.opal.wavelength_step = 20.0
    cam = bs.camera(location=(0, -3, 3), rotation=(math.radians(45), 0, 0))
    bs.light("POINT", (0, -2, 4), 500.0)
    drawn = []
    monkeypatch.setattr(viewport.ViewportSession, "_draw_frame",
                        lambda self, engine, scene, frame, w, h: drawn.append((frame.width, frame.height, w, h)))
    eng = _FakeEngine()
    ctx, dg = _view_context(cam)
    OpalRenderEngine.view_update(eng, ctx, dg)
    session = eng._viewport
    assert session is not None and session.scene is not None and not session.error
    assert session.levels == [(4, 1), (2, 1), (1, 2)]
    assert session.renderer.wait(120.0) and session.renderer.done
    OpalRenderEngine.view_draw(eng, ctx, dg)
    assert drawn[-1] == (64, 48, 64, 48)
    restarts = session.restarts
    OpalRenderEngine.view_draw(eng, ctx, dg)  # same view: no restart
    assert session.restarts == restarts
    cam.location.x += 0.5  # the view moved: the preview restarts
    ctx2, dg = _view_context(cam)
    OpalRenderEngine.view_draw(eng, ctx2, dg)
    assert session.restarts == restarts + 1
    ob.data.materials[0].opal.slit_count = 8  # an edit: view_update re-exports and restarts
    ob.data.materials[0].update_tag()  # what the UI does on an edit (a script must tag the ID itself)
    OpalRenderEngine.view_update(eng, ctx2, bpy.context.evaluated_depsgraph_get())
    assert session.restarts == restarts + 2
    assert session.scene.materials.slit_count[list(session.scene.materials.name).index(ob.data.materials[0].name)] == 8
    session.free()
    assert session.renderer.wait(30.0)
    assert any(s.startswith(("Rendering", "Done")) for s in eng.stats)
    # without a GPU (background mode) the real draw is skipped quietly, and errors never escape
    monkeypatch.undo()
    OpalRenderEngine.view_draw(eng, ctx, dg)


def test_redraw_timer_runs_while_a_preview_renders():
    r = viewport.ProgressiveRenderer()
    r.start(prepare(_tiny_core_scene(64), RenderSettings(wavelength_step=20.0, threads=1, tile_size=16)), [(1, 4096)])
    viewport._RedrawTimer.renderers.add(r)
    viewport._RedrawTimer.pending.set()
    assert viewport._redraw_tick() == viewport.REDRAW_INTERVAL  # a new image: redraw the views
    assert viewport._redraw_tick() == viewport.REDRAW_INTERVAL  # still rendering: keep polling
    r.cancel(wait=30.0)
    assert viewport._redraw_tick() is None  # nothing renders any more: the timer ends


# ---------------------------------------------------------------------------- UI drawing
class _Recorder:
    """A stand-in UILayout: records what is drawn and checks that named properties exist."""

    def __init__(self, log):
        object.__setattr__(self, "log", log)

    def __getattr__(self, name):
        if name in ("row", "column", "box", "split"):
            return lambda *a, **k: _Recorder(self.log)
        if name in ("label", "separator", "menu", "context_pointer_set"):
            return lambda *a, **k: self.log.append((name, a, k))
        raise AttributeError(name)

    def __setattr__(self, name, value):
        object.__setattr__(self, name, value)

    def prop(self, data, name, **kw):
        assert hasattr(data, name), f"no property {name!r}"
        self.log.append(("prop", name))

    def operator(self, idname, **kw):
        mod, _, op = idname.partition(".")
        assert hasattr(getattr(bpy.ops, mod), op), idname
        self.log.append(("operator", idname))
        return types.SimpleNamespace()


def _fake_operator(cls, log):
    mod, _, op = cls.bl_idname.partition(".")
    rna = getattr(getattr(bpy.ops, mod), op).get_rna_type().properties
    names = set(rna.keys()) - {"rna_type"}
    props = {n: tuple(rna[n].default_array) if getattr(rna[n], "is_array", False) else rna[n].default
             for n in names}
    return types.SimpleNamespace(layout=_Recorder(log), **props)


def test_redo_panels_menus_and_sidebar_draw():
    ob = _add_opal()
    log = []
    for cls in opal_ops.classes:
        if issubclass(cls, bpy.types.Operator) and "draw" in cls.__dict__:
            cls.draw(_fake_operator(cls, log), bpy.context)
    names = {e[1] for e in log if e[0] == "prop"}
    assert {"count", "seed", "low", "high", "direction", "angle", "period", "preset", "resolution", "size_spread",
            "orientation", "axis_spread", "domain_type", "diameter", "tilt"} <= names
    for mode in ("OBJECT", "EDIT_MESH"):
        ctx = types.SimpleNamespace(mode=mode, active_object=ob)
        panel = types.SimpleNamespace(layout=_Recorder(log))
        assert opal_ops.VIEW3D_PT_opal_tools.poll(ctx)
        opal_ops.VIEW3D_PT_opal_tools.draw(panel, ctx)
        opal_ops.VIEW3D_MT_opal_edit.draw(panel, ctx)
    ops = {e[1] for e in log if e[0] == "operator"}
    assert {"opal.assign_grating", "opal.jitter_period", "opal.split_domain", "opal.merge_domains",
            "opal.generate_domains", "mesh.primitive_opal_add", "opal.set_domain"} <= ops
    # the sidebar's preset menu runs on the object's material (presets read bpy.context.material)
    assert ("context_pointer_set", ("material", ob.active_material), {}) in log
