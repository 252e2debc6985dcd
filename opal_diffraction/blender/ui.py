"""Panels: Render, Material and World tabs for OPAL_DIFFRACTION, and Blender's own panels.

Our panels show only when the engine is selected (``context.engine`` in ``COMPAT_ENGINES``).
Blender's built-in panels that apply unchanged (output, format, frame range, colour management,
camera, light, material slots, ...) are enabled by adding the engine id to their
``COMPAT_ENGINES`` on register, as Cycles does; unregister removes it from exactly the panels it
was added to.
"""

from __future__ import annotations

import bpy
from bpy.types import Panel

from ..core.spectral.optics import SELLMEIER_PRESETS
from .engine import ENGINE_ID
from .export.nodes import missing_output, output_node
from .opal_presets import OPAL_MT_glass_presets, OPAL_MT_opal_presets
from .operators import OPAL_OT_export_scene
from .properties import MIN_GOOD_WAVELENGTHS

__all__ = ["register", "unregister", "builtin_panels", "classes"]


def _split(layout):
    """``layout`` with labels beside the values and no animation decorators (Cycles' panel style)."""
    layout.use_property_split = True
    layout.use_property_decorate = False
    return layout


class OpalButtonsPanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    COMPAT_ENGINES = {ENGINE_ID}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES


# ============================================================================ render tab
class OPAL_RENDER_PT_sampling(OpalButtonsPanel, Panel):
    bl_label = "Sampling"
    bl_context = "render"

    def draw(self, context):
        layout = _split(self.layout)
        opal = context.scene.opal
        col = layout.column(align=True)
        # Cycles' layout: Noise Threshold as a checkbox beside its value
        heading = layout.column(align=True, heading="Noise Threshold")
        row = heading.row(align=True)
        row.prop(opal, "use_adaptive_sampling", text="")
        sub = row.row()
        sub.active = opal.use_adaptive_sampling
        sub.prop(opal, "adaptive_threshold", text="")
        col = layout.column(align=True)
        col.prop(opal, "samples", text="Max Samples" if opal.use_adaptive_sampling else "Samples")
        sub = col.column(align=True)
        sub.active = opal.use_adaptive_sampling
        sub.prop(opal, "adaptive_min_samples", text="Min Samples")
        col.prop(opal, "round_samples")
        col.prop(opal, "blue_noise")
        col = layout.column(align=True)
        col.prop(opal, "time_limit")
        col = layout.column(align=True, heading="Denoise")
        col.prop(opal, "use_denoising", text="")
        row = layout.row(align=True)
        row.prop(opal, "seed")
        row.prop(opal, "use_animated_seed", text="", icon="TIME")
        col = layout.column(align=True, heading="Viewport")
        col.prop(opal, "preview_samples", text="Viewport Samples")
        col.prop(opal, "preview_start_scale", text="Start Divider")


class OPAL_RENDER_PT_spectrum(OpalButtonsPanel, Panel):
    bl_label = "Spectrum"
    bl_context = "render"

    def draw(self, context):
        layout = _split(self.layout)
        opal = context.scene.opal
        col = layout.column(align=True)
        col.prop(opal, "wavelength_min", text="Wavelength Min")
        col.prop(opal, "wavelength_max", text="Max")
        col.prop(opal, "wavelength_step", text="Step")
        layout.prop(opal, "grating_footprint")
        n = opal.wavelength_count()
        if n is None:
            layout.label(text="Min must be below Max" if opal.wavelength_min >= opal.wavelength_max
                         else "Invalid wavelength range or step", icon="ERROR")
        elif n < MIN_GOOD_WAVELENGTHS:
            col = layout.column(align=True)
            col.label(text=f"Only {n} wavelengths: colours are approximate", icon="ERROR")
            col.label(text=f"Use at least {MIN_GOOD_WAVELENGTHS} (a smaller step)", icon="BLANK1")
        else:
            layout.label(text=f"{n} wavelengths", icon="INFO")
        layout.prop(opal, "dispersion_sampling")


class OPAL_RENDER_PT_light_paths(OpalButtonsPanel, Panel):
    bl_label = "Light Paths"
    bl_context = "render"

    def draw(self, context):
        layout = _split(self.layout)
        opal = context.scene.opal
        col = layout.column(align=True, heading="Max Bounces")
        for name in ("max_bounces", "diffuse_bounces", "glossy_bounces", "transmission_bounces"):
            col.prop(opal, name)
        col = layout.column(align=True, heading="Light Paths")
        col.prop(opal, "light_paths_auto", text="Automatic")
        sub = col.column()
        sub.active = not opal.light_paths_auto
        sub.prop(opal, "light_paths")
        layout.prop(opal, "caustic_splat")


class OPAL_RENDER_PT_film(OpalButtonsPanel, Panel):
    bl_label = "Film"
    bl_context = "render"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = _split(self.layout)
        layout.prop(context.scene.opal, "filter_width")
        # Film > Transparent (Blender's own setting, as Cycles' Film panel shows it): docs/physics.md section 6.11
        layout.prop(context.scene.render, "film_transparent", text="Transparent")
        cycles = getattr(context.scene, "cycles", None)
        if cycles is not None and hasattr(cycles, "film_transparent_glass"):  # Cycles' setting, read as Cycles reads it
            sub = layout.column()
            sub.active = context.scene.render.film_transparent
            sub.prop(cycles, "film_transparent_glass", text="Transparent Glass")


class OPAL_RENDER_PT_motion_blur(OpalButtonsPanel, Panel):
    """Render > Motion Blur (Blender's own settings, as Cycles' panel shows them): the camera's
    motion over the shutter is rendered (docs/physics.md section 6.13)."""

    bl_label = "Motion Blur"
    bl_context = "render"
    bl_options = {"DEFAULT_CLOSED"}

    def draw_header(self, context):
        self.layout.prop(context.scene.render, "use_motion_blur", text="")

    def draw(self, context):
        rd = context.scene.render
        layout = _split(self.layout)
        layout.active = rd.use_motion_blur
        layout.prop(rd, "motion_blur_position", text="Position")
        layout.prop(rd, "motion_blur_shutter")


class OPAL_RENDER_PT_motion_blur_curve(OpalButtonsPanel, Panel):
    bl_label = "Shutter Curve"
    bl_context = "render"
    bl_parent_id = "OPAL_RENDER_PT_motion_blur"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        rd = context.scene.render
        self.layout.active = rd.use_motion_blur
        self.layout.template_curve_mapping(rd, "motion_blur_shutter_curve")


class OPAL_DATA_PT_panorama(OpalButtonsPanel, Panel):
    """A panoramic camera's type and its settings (Blender's Lens panel draws them for Cycles only)."""
    bl_label = "Panorama"
    bl_context = "data"

    @classmethod
    def poll(cls, context):
        cam = getattr(context, "camera", None)
        return cam is not None and cam.type == "PANO" and context.engine in cls.COMPAT_ENGINES

    def draw(self, context):
        layout = _split(self.layout)
        cam = context.camera
        col = layout.column()
        col.prop(cam, "panorama_type")
        if cam.panorama_type == "FISHEYE_EQUIDISTANT":
            col.prop(cam, "fisheye_fov")
        elif cam.panorama_type == "FISHEYE_EQUISOLID":
            col.prop(cam, "fisheye_lens", text="Lens")
            col.prop(cam, "fisheye_fov")
        elif cam.panorama_type == "EQUIRECTANGULAR":
            sub = col.column(align=True)
            sub.prop(cam, "latitude_min", text="Latitude Min")
            sub.prop(cam, "latitude_max", text="Max")
            sub = col.column(align=True)
            sub.prop(cam, "longitude_min", text="Longitude Min")
            sub.prop(cam, "longitude_max", text="Max")
        else:
            col.label(text="Not rendered: use Equirectangular or a Fisheye (Equidistant, Equisolid)", icon="ERROR")


class OPAL_RENDER_PT_output(OpalButtonsPanel, Panel):
    bl_label = "Spectral Output"
    bl_context = "render"

    def draw(self, context):
        layout = _split(self.layout)
        opal = context.scene.opal
        layout.prop(opal, "spectral_exr")
        layout.prop(opal, "scene_npz")
        layout.operator(OPAL_OT_export_scene.bl_idname, icon="EXPORT")


class OPAL_RENDER_PT_performance(OpalButtonsPanel, Panel):
    bl_label = "Performance"
    bl_context = "render"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = _split(self.layout)
        rd, opal = context.scene.render, context.scene.opal
        col = layout.column(align=True)
        col.prop(rd, "threads_mode")
        sub = col.column(align=True)
        sub.enabled = rd.threads_mode == "FIXED"
        sub.prop(rd, "threads")
        layout.prop(opal, "backend")
        layout.prop(opal, "tile_size")
        layout.prop(opal, "scheduler")
        # Final Render > Persistent Data, as Cycles': keep the scene between frames (persistent.py)
        layout.prop(rd, "use_persistent_data", text="Persistent Data")


# ============================================================================ material tab
def _material_poll(cls, context):
    mat = getattr(context, "material", None)
    return mat is not None and not getattr(mat, "grease_pencil", None) and context.engine in cls.COMPAT_ENGINES


def _draw_node_input(layout, id_data, input_name: str, output: str = "Material Output") -> bool:
    """Draw the node tree feeding the output node's ``input_name`` (as Cycles' panels do); without
    an output node for Cycles, say why (``output``: what the node is called)."""
    ntree = getattr(id_data, "node_tree", None)
    if ntree is None:
        return False
    node = output_node(ntree)
    if node is None:
        why = missing_output(ntree, output)  # e.g. the only output targets EEVEE
        layout.label(text=why[0].upper() + why[1:], icon="ERROR")
        return True
    sock = node.inputs.get(input_name)
    if sock is None:
        layout.label(text="Incompatible output node")
        return True
    layout.template_node_view(ntree, node, sock)
    return True


class OPAL_MATERIAL_PT_surface(OpalButtonsPanel, Panel):
    bl_label = "Surface"
    bl_context = "material"

    @classmethod
    def poll(cls, context):
        return _material_poll(cls, context)

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        mat = context.material
        if not _draw_node_input(layout, mat, "Surface"):
            layout.prop(mat, "diffuse_color")


class OPAL_MATERIAL_PT_dispersion(OpalButtonsPanel, Panel):
    bl_label = "Dispersion"
    bl_context = "material"

    @classmethod
    def poll(cls, context):
        return _material_poll(cls, context)

    def draw_header_preset(self, context):
        self.layout.menu(OPAL_MT_glass_presets.bl_idname, text="", icon="PRESET")

    def draw(self, context):
        layout = _split(self.layout)
        opal = context.material.opal
        layout.prop(opal, "dispersion")
        row = layout.row()
        row.active = opal.dispersion == "ABBE"
        row.prop(opal, "abbe_number")
        if opal.dispersion in SELLMEIER_PRESETS:
            layout.label(text="The glass's own index replaces the node's IOR", icon="INFO")
        elif opal.dispersion != "NONE":
            layout.label(text="Applies to Glass BSDF or transmissive Principled BSDF", icon="INFO")


def _draw_bragg(layout, opal) -> None:
    """The BRAGG lattice's settings, its normal-incidence colour, and the volume-domain layout."""
    from ..core.opal.bragg import bragg_wavelength, effective_index

    col = layout.column(align=True)
    col.prop(opal, "sphere_diameter")
    col.prop(opal, "sphere_ior")
    col.prop(opal, "void_ior")
    col = layout.column(align=True)
    col.prop(opal, "layers")
    col.prop(opal, "mosaic_spread")
    ns, nv = float(opal.sphere_ior), float(opal.void_ior)
    lo, hi = (float(bragg_wavelength(max(opal.sphere_diameter + k * opal.diameter_spread, 1.0), 0.0, ns, nv))
              for k in (-1, 1))
    layout.label(text=f"n_eff {effective_index(ns, nv):.3f}; normal incidence {lo:.0f}-{hi:.0f} nm", icon="INFO")
    col = layout.column(align=True, heading="Volume Domains")
    col.prop(opal, "domain_count")
    col.prop(opal, "domain_size_spread")
    col.prop(opal, "diameter_spread")
    col.prop(opal, "domain_orientation")
    sub = col.row()
    sub.active = opal.domain_orientation == "LAYERED"
    sub.prop(opal, "domain_axis_spread")


class OPAL_MATERIAL_PT_grating(OpalButtonsPanel, Panel):
    bl_label = "Diffraction Grating"
    bl_context = "material"

    @classmethod
    def poll(cls, context):
        return _material_poll(cls, context)

    def draw_header(self, context):
        self.layout.prop(context.material.opal, "grating", text="")

    def draw_header_preset(self, context):
        self.layout.menu(OPAL_MT_opal_presets.bl_idname, text="", icon="PRESET")

    def draw(self, context):
        layout = _split(self.layout)
        opal = context.material.opal
        layout.active = opal.grating
        layout.prop(opal, "grating_type")
        layout.prop(opal, "lattice")
        if opal.lattice == "BRAGG":
            _draw_bragg(layout, opal)
        else:
            col = layout.column(align=True)
            col.prop(opal, "period")
            col.prop(opal, "slit_width")
            col.prop(opal, "slit_count")
            layout.prop(opal, "coherence_length", text="Coherence Length (µm)")
            col = layout.column(align=True)
            col.prop(opal, "grating_direction")
            col.prop(opal, "rotation")
        if opal.grating:
            for problem in opal.grating_problems():
                box = layout.box()
                box.alert = True
                box.label(text=problem[0].upper() + problem[1:], icon="ERROR")
            if opal.grating_direction == "ATTRIBUTE" and opal.lattice != "BRAGG":
                layout.label(text="Direction and period: the faces' opal attributes", icon="INFO")


# ============================================================================ world tab
class OPAL_WORLD_PT_surface(OpalButtonsPanel, Panel):
    bl_label = "Surface"
    bl_context = "world"

    @classmethod
    def poll(cls, context):
        return getattr(context, "world", None) is not None and context.engine in cls.COMPAT_ENGINES

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        world = context.world
        if not _draw_node_input(layout, world, "Surface", "World Output"):
            layout.prop(world, "color")
        # blender/export/world.py: a colour, or an equirectangular Environment Texture as a map
        layout.label(text="Lights the scene: a colour, or an equirectangular environment map", icon="INFO")


classes = (
    OPAL_RENDER_PT_sampling,
    OPAL_RENDER_PT_spectrum,
    OPAL_RENDER_PT_light_paths,
    OPAL_RENDER_PT_film,
    OPAL_RENDER_PT_motion_blur,
    OPAL_RENDER_PT_motion_blur_curve,
    OPAL_DATA_PT_panorama,
    OPAL_RENDER_PT_output,
    OPAL_RENDER_PT_performance,
    OPAL_MATERIAL_PT_surface,
    OPAL_MATERIAL_PT_dispersion,
    OPAL_MATERIAL_PT_grating,
    OPAL_WORLD_PT_surface,
)

# ============================================================================ built-in panels
#: Built-in panels made for Blender's own engines that do not apply to ours.
_EXCLUDE = {
    "DATA_PT_light",  # draws only the light type; DATA_PT_EEVEE_light below draws all we use
    "DATA_PT_preview",
    "MATERIAL_PT_preview",
    "VIEWLAYER_PT_filter",
    "VIEWLAYER_PT_layer_passes",
    "EEVEE_MATERIAL_PT_viewport_settings",
}
#: Built-in panels outside the 'BLENDER_RENDER' group that show settings we read.
_EXTRA = {
    "DATA_PT_EEVEE_light",  # type, colour, temperature, power, exposure, normalize, radius, shape, size
    "DATA_PT_spot",  # spot size and blend (a child of DATA_PT_EEVEE_light)
    "EEVEE_MATERIAL_PT_context_material",  # material slots
    "DATA_PT_camera_dof",  # depth of field: focus object / bone / distance (docs/physics.md section 6.7)
    "DATA_PT_camera_dof_aperture",  # f-stop, blades, rotation, ratio
}

_added: list = []


def builtin_panels() -> list:
    """Blender's panels we enable for the engine (those made for any engine, plus a few)."""
    out = []
    for panel in bpy.types.Panel.__subclasses__():
        engines = getattr(panel, "COMPAT_ENGINES", None)
        if not isinstance(engines, set) or panel.__name__ in _EXCLUDE:
            continue
        if "BLENDER_RENDER" in engines or panel.__name__ in _EXTRA:
            out.append(panel)
    return out


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    for panel in builtin_panels():
        if ENGINE_ID not in panel.COMPAT_ENGINES:
            panel.COMPAT_ENGINES.add(ENGINE_ID)
            _added.append(panel)


def unregister():
    while _added:
        panel = _added.pop()
        panel.COMPAT_ENGINES.discard(ENGINE_ID)
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
