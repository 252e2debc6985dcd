"""The Blender-facing contract: property names, units, ranges, stable enum indices; panels that
show only for the engine and draw only existing properties; built-in panels enabled and cleaned
up; operators."""

from __future__ import annotations

import types

import bpy
import pytest

import blender_scenes as bs
from opal_diffraction.blender import properties, ui
from opal_diffraction.blender.engine import ENGINE_ID
from opal_diffraction.core.util import enums
from opal_diffraction.core.spectral.optics import DISPERSION_MODELS, SELLMEIER_PRESETS
from opal_diffraction.core.spectral.spectrum import WavelengthGrid

SCENE_CONTRACT = ["samples", "light_paths", "wavelength_min", "wavelength_max", "wavelength_step", "max_bounces",
                  "diffuse_bounces", "glossy_bounces", "transmission_bounces",
                  "seed", "dispersion_sampling", "spectral_exr", "time_limit"]
MATERIAL_CONTRACT = ["grating", "grating_type", "lattice", "period", "slit_width", "slit_count", "coherence_length",
                     "grating_direction", "rotation", "dispersion", "abbe_number"]
#: The BRAGG lattice's names (scripts and tests rely on them; drawn only for that lattice).
BRAGG_CONTRACT = ["sphere_diameter", "sphere_ior", "void_ior", "layers", "mosaic_spread"]


def test_engine_id_and_contract_names():
    sc = bs.empty_scene()
    assert sc.render.engine == ENGINE_ID == "OPAL_DIFFRACTION"
    rna = sc.opal.bl_rna.properties
    for name in SCENE_CONTRACT:
        assert name in rna, name
        assert rna[name].description, f"{name} has no tooltip"
    mat = bpy.data.materials.new("m")
    rna = mat.opal.bl_rna.properties
    for name in MATERIAL_CONTRACT + BRAGG_CONTRACT:
        assert name in rna, name
        assert rna[name].description, f"{name} has no tooltip"
    assert set(sc.opal.bl_rna.properties["dispersion_sampling"].enum_items.keys()) == {"SPLIT", "SAMPLE"}
    assert set(rna["grating_type"].enum_items.keys()) == {"REFLECTION", "TRANSMISSION"}
    assert set(rna["lattice"].enum_items.keys()) == {"LINES", "HEXAGONAL", "BRAGG"}
    assert set(rna["grating_direction"].enum_items.keys()) == {"UV", "OBJECT_X", "ATTRIBUTE"}


def test_defaults_units_and_ranges():
    sc = bs.empty_scene()
    o = bpy.types.Scene.bl_rna.properties["opal"].fixed_type.properties
    assert (o["wavelength_min"].default, o["wavelength_max"].default, o["wavelength_step"].default) == (400, 700, 5)
    assert o["wavelength_min"].hard_min == 360 and o["wavelength_max"].hard_max == 830
    assert o["wavelength_step"].subtype == "WAVELENGTH"
    assert o["time_limit"].unit == "TIME_ABSOLUTE" and o["time_limit"].hard_min == 0
    assert o["samples"].hard_min == 1 and o["spectral_exr"].subtype == "FILE_PATH"
    m = bpy.types.Material.bl_rna.properties["opal"].fixed_type.properties
    assert m["period"].subtype == "WAVELENGTH" and m["rotation"].subtype == "ANGLE"
    assert m["abbe_number"].hard_min > 0
    sc.opal.samples = 0  # below the hard minimum: Blender clamps
    assert sc.opal.samples == 1


def test_enum_items_have_stable_explicit_indices():
    """Saved files store the index: the dispersion indices are the core's codes, the rest fixed."""
    m = bpy.types.Material.bl_rna.properties["opal"].fixed_type.properties
    assert {i.identifier: i.value for i in m["dispersion"].enum_items} == DISPERSION_MODELS
    assert {i.identifier: i.value for i in m["grating_type"].enum_items} == {"REFLECTION": 0, "TRANSMISSION": 1}
    assert {i.identifier: i.value for i in m["lattice"].enum_items} == {"LINES": 0, "HEXAGONAL": 1, "BRAGG": 2}
    assert {i.identifier: i.value for i in m["grating_direction"].enum_items} == {"UV": 0, "OBJECT_X": 1, "ATTRIBUTE": 2}
    s = bpy.types.Scene.bl_rna.properties["opal"].fixed_type.properties
    assert {i.identifier: i.value for i in s["dispersion_sampling"].enum_items} == {"SAMPLE": 0, "SPLIT": 1}
    for items in (properties.DISPERSION_ITEMS, properties.GRATING_TYPE_ITEMS, properties.LATTICE_ITEMS,
                  properties.GRATING_DIRECTION_ITEMS, properties.DISPERSION_SAMPLING_ITEMS, properties.BACKEND_ITEMS):
        assert all(len(it) == 4 and isinstance(it[3], int) for it in items)


#: Every EnumProperty of scene.opal and material.opal, and the core enumeration whose codes it stores.
ENUM_PROPERTIES = {
    ("Scene", "dispersion_sampling"): enums.DispersionSampling,
    ("Scene", "backend"): enums.Backend,
    ("Material", "dispersion"): enums.DispersionModel,
    ("Material", "grating_type"): enums.GratingType,
    ("Material", "lattice"): enums.Lattice,
    ("Material", "grating_direction"): enums.GratingDirection,
    ("Material", "domain_orientation"): enums.DomainOrientation,
}


def test_every_enum_property_stores_a_core_enumeration():
    """(identifier, index) of every item, in order, are the core enumeration's (name, code)."""
    found = {}
    for owner in ("Scene", "Material"):
        for prop in getattr(bpy.types, owner).bl_rna.properties["opal"].fixed_type.properties:
            if prop.type == "ENUM":
                found[(owner, prop.identifier)] = [(i.identifier, i.value) for i in prop.enum_items]
    assert found.keys() == ENUM_PROPERTIES.keys()
    for key, enum in ENUM_PROPERTIES.items():
        assert found[key] == [(m.name, int(m)) for m in enum], key


def test_settings_survive_save_and_reload(tmp_path):
    sc = bs.empty_scene()
    sc.opal.samples, sc.opal.dispersion_sampling, sc.opal.wavelength_step = 77, "SPLIT", 10.0
    mat = bpy.data.materials.new("keep")
    mat.use_fake_user = True
    mat.opal.dispersion, mat.opal.abbe_number, mat.opal.lattice = "FUSED_SILICA", 33.0, "HEXAGONAL"
    path = str(tmp_path / "saved.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=path)
    sc = bpy.context.scene
    assert (sc.opal.samples, sc.opal.dispersion_sampling, sc.opal.wavelength_step) == (77, "SPLIT", 10.0)
    m = bpy.data.materials["keep"].opal
    assert (m.dispersion, m.abbe_number, m.lattice) == ("FUSED_SILICA", 33.0, "HEXAGONAL")


def test_grating_problems():
    mat = bpy.data.materials.new("g")
    assert mat.opal.grating_problems() == []
    mat.opal.period = 0.0  # below the field's minimum: Blender clamps
    assert mat.opal.period == properties.MIN_PERIOD_NM
    mat.opal["period"] = 0.0  # as an older file may hold it (the stored value is not clamped)
    assert any("period must be > 0" in p for p in mat.opal.grating_problems())
    mat.opal.period, mat.opal.slit_width = 500.0, 900.0
    assert any("larger than its period" in p for p in mat.opal.grating_problems())


# ---------------------------------------------------------------------------- panels
class _Layout:
    """Records what a panel draws and checks every property it names exists."""

    def __init__(self, log):
        self.log = log

    def __getattr__(self, name):
        if name in ("row", "column", "box", "split", "column_flow", "grid_flow"):
            return lambda *a, **k: _Layout(self.log)
        if name in ("label", "separator", "template_node_view", "template_ID", "template_list", "menu",
                    "prop_decorator"):
            return lambda *a, **k: self.log.append((name, a, k))
        if name == "template_curve_mapping":  # a curve property: checked as prop is
            return lambda data, prop, *a, **k: self.prop(data, prop)
        raise AttributeError(name)

    def __setattr__(self, name, value):
        object.__setattr__(self, name, value)

    def prop(self, data, name, **kw):
        assert name in data.bl_rna.properties, f"{type(data).__name__} has no property {name!r}"
        self.log.append(("prop", name))

    def operator(self, idname, **kw):
        mod, _, op = idname.partition(".")
        assert hasattr(getattr(bpy.ops, mod), op), idname
        self.log.append(("operator", idname))
        return types.SimpleNamespace()


def _context(engine, **kw):
    sc = bpy.context.scene
    base = dict(engine=engine, scene=sc, material=None, world=None, object=None, light=None)
    base.update(kw)
    return types.SimpleNamespace(**base)


def test_panels_show_only_for_the_engine_and_draw_existing_properties():
    bs.empty_scene()
    mat = bs.material("glass", "GLASS")
    mat.opal.grating = True
    mat.opal["period"] = 0.0  # drawn as an alert (an older file's value: the field's minimum is above 0)
    world = bpy.data.worlds.new("w")
    cam = bpy.data.cameras.new("pano")
    cam.type, cam.panorama_type = "PANO", "FISHEYE_EQUISOLID"
    drawn = []
    for cls in ui.classes:
        if not issubclass(cls, bpy.types.Panel):
            continue
        ctx = _context(ENGINE_ID, material=mat, world=world, camera=cam)
        assert cls.poll(ctx), cls.__name__
        assert not cls.poll(_context("CYCLES", material=mat, world=world, camera=cam)), cls.__name__
        log = []
        panel = types.SimpleNamespace(layout=_Layout(log))
        if hasattr(cls, "draw_header"):
            cls.draw_header(panel, ctx)
        cls.draw(panel, ctx)
        drawn += log
    props = {e[1] for e in drawn if e[0] == "prop"}
    assert set(SCENE_CONTRACT) <= props and set(MATERIAL_CONTRACT) <= props
    labels = " ".join(str(e[2].get("text", "")) for e in drawn if e[0] == "label")
    assert "period must be > 0" in labels
    assert ("operator", "opal.export_scene") in drawn
    assert not set(BRAGG_CONTRACT) & props  # a LINES grating: the Bragg settings are not drawn
    mat.opal.lattice = "BRAGG"
    log = []
    ui.OPAL_MATERIAL_PT_grating.draw(types.SimpleNamespace(layout=_Layout(log)),
                                     _context(ENGINE_ID, material=mat, world=world))
    props = {e[1] for e in log if e[0] == "prop"}
    assert set(BRAGG_CONTRACT) <= props and "period" not in props


def _labels(cls, ctx) -> str:
    log = []
    cls.draw(types.SimpleNamespace(layout=_Layout(log)), ctx)
    return " ".join(str(e[2].get("text", "")) for e in log if e[0] == "label")


def test_panels_take_the_wavelength_count_and_the_sellmeier_glasses_from_the_core():
    sc = bs.empty_scene()
    sc.opal.wavelength_min, sc.opal.wavelength_max, sc.opal.wavelength_step = 400.0, 700.0, 7.0
    n = WavelengthGrid(400.0, 700.0, 7.0).n
    assert f"{n} wavelengths" in _labels(ui.OPAL_RENDER_PT_spectrum, _context(ENGINE_ID))
    mat = bs.material("glass", "GLASS")
    for ident in DISPERSION_MODELS:
        mat.opal.dispersion = ident
        own_index = "The glass's own index" in _labels(ui.OPAL_MATERIAL_PT_dispersion, _context(ENGINE_ID, material=mat))
        assert own_index == (ident in SELLMEIER_PRESETS), ident


def test_panorama_panel_draws_the_type_and_its_settings():
    """Blender's Lens panel draws a panorama's type for Cycles only: ours draws it, and each
    type's settings (those core/sampling/camera.py reads)."""
    bs.empty_scene()
    cam = bpy.data.cameras.new("pano")
    assert not ui.OPAL_DATA_PT_panorama.poll(_context(ENGINE_ID, camera=cam))  # a perspective camera
    cam.type = "PANO"
    for kind, expected in (("EQUIRECTANGULAR", {"latitude_min", "latitude_max", "longitude_min", "longitude_max"}),
                           ("FISHEYE_EQUIDISTANT", {"fisheye_fov"}), ("FISHEYE_EQUISOLID", {"fisheye_lens", "fisheye_fov"})):
        cam.panorama_type = kind
        log = []
        ui.OPAL_DATA_PT_panorama.draw(types.SimpleNamespace(layout=_Layout(log)), _context(ENGINE_ID, camera=cam))
        assert {e[1] for e in log if e[0] == "prop"} == {"panorama_type"} | expected, kind
    cam.panorama_type = "MIRRORBALL"
    assert "Not rendered" in _labels(ui.OPAL_DATA_PT_panorama, _context(ENGINE_ID, camera=cam))


def test_builtin_panels_enabled_and_cleaned_up():
    names = ["RENDER_PT_format", "RENDER_PT_output", "RENDER_PT_frame_range", "RENDER_PT_color_management",
             "DATA_PT_camera", "DATA_PT_lens", "DATA_PT_camera_dof", "DATA_PT_camera_dof_aperture",
             "DATA_PT_EEVEE_light", "DATA_PT_spot",
             "EEVEE_MATERIAL_PT_context_material", "WORLD_PT_context_world"]
    for n in names:
        assert ENGINE_ID in getattr(bpy.types, n).COMPAT_ENGINES, n
    assert ENGINE_ID not in bpy.types.DATA_PT_EEVEE_light_shadow.COMPAT_ENGINES  # EEVEE-only settings
    import opal_diffraction

    opal_diffraction.unregister()
    try:
        for n in names:
            assert ENGINE_ID not in getattr(bpy.types, n).COMPAT_ENGINES, n
        assert "BLENDER_EEVEE" in bpy.types.DATA_PT_EEVEE_light.COMPAT_ENGINES  # others untouched
        assert not hasattr(bpy.types.Scene, "opal") and not hasattr(bpy.types, "OPAL_RENDER_PT_sampling")
    finally:
        opal_diffraction.register()
    assert ENGINE_ID in bpy.types.RENDER_PT_format.COMPAT_ENGINES


def test_dispersion_preset_operator():
    bs.empty_scene()
    mat = bs.material("gem", "GLASS", IOR=1.5)
    with bpy.context.temp_override(material=mat):
        assert bpy.ops.opal.dispersion_preset.poll()
        assert bpy.ops.opal.dispersion_preset(preset="DENSE_FLINT") == {"FINISHED"}
    assert (mat.opal.dispersion, mat.opal.abbe_number) == ("ABBE", 29.0)
    assert mat.node_tree.nodes["Glass BSDF"].inputs["IOR"].default_value == pytest.approx(1.72)
    with bpy.context.temp_override(material=mat):
        bpy.ops.opal.dispersion_preset(preset="DIAMOND")
    assert mat.opal.dispersion == "DIAMOND"
    assert not bpy.ops.opal.dispersion_preset.poll()  # no material in this context


def test_light_paths_are_automatic_until_a_number_is_set():
    """Automatic light paths (sized to the image) by default: the core gets None; setting a count
    (as a user typing it, or a script) turns Automatic off and the count is used exactly."""
    from opal_diffraction.blender.settings import render_settings

    sc = bs.empty_scene()
    assert sc.opal.light_paths_auto
    assert render_settings(sc.opal, sc).light_paths is None
    sc.opal.light_paths = 0
    assert not sc.opal.light_paths_auto
    assert render_settings(sc.opal, sc).light_paths == 0
