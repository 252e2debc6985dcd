"""Render and material settings: ``scene.opal`` and ``material.opal``.

The names are the Blender-facing contract (every one is listed in docs/blender.md, "Settings",
and the README's "In Blender"): users' scripts and saved .blend files rely on them, so they
never change. Every EnumProperty item has
an explicit, stable index, so a file saved today still loads after items are added (the values
are stored as those numbers): the identifiers and indices are the members and codes of the
core's enumerations (``core/util/enums.py``); only the names and tooltips are written here.

Base colour, metallic, roughness, transmission and IOR are not duplicated here: they come from
the material's shader nodes (Principled, Diffuse, Glossy, Glass BSDF, Emission), so existing
scenes render without conversion. ``material.opal`` holds only what Blender has no slot for:
dispersion and the diffraction grating. "The source paper" in the item descriptions is
Kobayashi & Kawai (docs/physics.md); SPLIT and SAMPLE are described in docs/physics.md
section 2.4.
"""

from __future__ import annotations

import math
from enum import IntEnum

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty, PointerProperty,
                       StringProperty)
from bpy.types import PropertyGroup

from ..core.util.enums import (Backend, DispersionModel, DispersionSampling, DomainOrientation, GratingDirection, GratingType, Lattice)
from ..core.spectral.spectrum import WavelengthGrid

__all__ = [
    "OpalRenderSettings",
    "OpalMaterialSettings",
    "DISPERSION_ITEMS",
    "DISPERSION_PRESETS",
    "MIN_GOOD_WAVELENGTHS",
    "MIN_PERIOD_NM",
    "MIN_COHERENCE_UM",
    "DOMAIN_ORIENTATION_ITEMS",
    "principled_node",
    "register",
    "unregister",
]

# A wavelength-valued float shows "nm" where this Blender has the subtype (4.x does).
_SUBTYPES = bpy.types.FloatProperty.bl_rna.properties["subtype"].enum_items.keys()
_NM = "WAVELENGTH" if "WAVELENGTH" in _SUBTYPES else "NONE"
# Output paths accept '//' (relative to the .blend) where this Blender asks paths to say so.
_PATH_OPTIONS = ({"PATH_SUPPORTS_BLEND_RELATIVE"}
                 if "is_path_supports_blend_relative" in bpy.types.Property.bl_rna.properties else set())

#: Fewer wavelength samples than this make colours visibly approximate (and dispersion banded):
#: the panel and the render's warnings say so.
MIN_GOOD_WAVELENGTHS = 16
#: Smallest grating period and slit width (nm) the fields accept: 0 can only fail at render time.
MIN_PERIOD_NM = 1.0
#: Smallest coherence length (um) the field accepts (1 nm).
MIN_COHERENCE_UM = 0.001


# ---------------------------------------------------------------------------- enum items
def _items(enum: type[IntEnum], labels: dict) -> list[tuple[str, str, str, int]]:
    """EnumProperty items (identifier, name, description, stable index) of a core enumeration, in
    code order: the identifier is the member's name and the index its code (what a .blend stores),
    ``labels`` gives each member's (name, description)."""
    if set(labels) != set(enum):
        raise ValueError(f"{enum.__name__}: labels for {sorted(m.name for m in set(enum) ^ set(labels))} "
                         "missing or extra")
    return [(m.name, *labels[m], int(m)) for m in enum]


DISPERSION_ITEMS = _items(DispersionModel, {
    DispersionModel.NONE: ("None", "Constant index of refraction: the IOR of the material's BSDF node"),
    DispersionModel.ABBE: ("IOR + Abbe Number",
                           "Cauchy fit n = A + B/lambda^2 to the node's IOR (at 587.6 nm, the d line) and the Abbe "
                           "number below; a lower Abbe number spreads colours more"),
    DispersionModel.BK7: ("Crown Glass (N-BK7)",
                          "Sellmeier data of SCHOTT N-BK7 (n_d 1.5168, V_d 64.2); the node's IOR is ignored"),
    DispersionModel.FUSED_SILICA: ("Fused Silica",
                                   "Sellmeier data of Malitson 1965 (n_d 1.4585, V_d 67.8); the node's IOR is ignored"),
    DispersionModel.DIAMOND: ("Diamond",
                              "Sellmeier data of Peter 1923 (n_d 2.4175, V_d 55.3); the node's IOR is ignored"),
})

DISPERSION_SAMPLING_ITEMS = _items(DispersionSampling, {
    DispersionSampling.SAMPLE: ("Sample", "At a dispersive surface a ray continues with one wavelength picked at "
                                "random (hero-wavelength style): cheap per ray, converges with samples"),
    DispersionSampling.SPLIT: ("Split", "At a dispersive surface a ray splits into one ray per wavelength (the source "
                               "paper's method): no colour noise from dispersion, more rays"),
})

BACKEND_ITEMS = _items(Backend, {
    Backend.AUTO: ("Automatic", "Embree where its wheel is installed, otherwise the NumPy BVH"),
    Backend.EMBREE: ("Embree", "Intel Embree through embreex (fastest; x86-64 only)"),
    Backend.NUMPY: ("NumPy", "The vectorised NumPy BVH (works everywhere)"),
})

GRATING_TYPE_ITEMS = _items(GratingType, {
    GratingType.REFLECTION: ("Reflection", "Light diffracts back off the surface (CDs, opal, beetle shells)"),
    GratingType.TRANSMISSION: ("Transmission",
                               "Light diffracts through the surface (grating film, slide gratings)"),
})

LATTICE_ITEMS = _items(Lattice, {
    Lattice.LINES: ("Lines", "Parallel slits (a 1D ruled grating)"),
    Lattice.HEXAGONAL: ("Hexagonal", "A 2D hexagonal lattice of scatterers (opal's close-packed spheres)"),
    Lattice.BRAGG: ("Bragg (FCC Opal)", "Precious opal as it is: Bragg reflection from the (111) planes of 3D "
                    "domains of close-packed silica spheres; the colour moves towards blue as the stone tilts"),
})

DOMAIN_ORIENTATION_ITEMS = _items(DomainOrientation, {
    DomainOrientation.RANDOM: ("Random", "Each domain's (111) planes face a random direction"),
    DomainOrientation.LAYERED: ("Layered", "The domains' (111) planes lean towards the object's Z axis (opal grows "
                                "in layers): most flashes face up"),
})

GRATING_DIRECTION_ITEMS = _items(GratingDirection, {
    GratingDirection.UV: ("UV Map", "Across the slits along the active UV map's U direction; the object's local X "
                          "axis where the mesh has no UV map"),
    GratingDirection.OBJECT_X: ("Object X Axis", "Across the slits along the object's local X axis"),
    GratingDirection.ATTRIBUTE: ("Face Attribute", "The per-face direction attribute written by the opal tools"),
})

#: Named glasses: (identifier, name, dispersion model, n_d, V_d). Applying one sets
#: ``material.opal.dispersion`` / ``abbe_number`` and the IOR of the material's BSDF node to n_d,
#: so Cycles and EEVEE previews bend light the same way on average.
DISPERSION_PRESETS = [
    ("BK7", "Crown Glass N-BK7", "BK7", 1.5168, 64.17),
    ("FUSED_SILICA", "Fused Silica", "FUSED_SILICA", 1.4585, 67.82),
    ("DIAMOND", "Diamond", "DIAMOND", 2.4175, 55.3),
    ("WATER", "Water (20 C)", "ABBE", 1.333, 55.7),
    ("ACRYLIC", "Acrylic (PMMA)", "ABBE", 1.4914, 57.4),
    ("POLYCARBONATE", "Polycarbonate", "ABBE", 1.585, 30.0),
    ("FLINT_F2", "Flint Glass F2", "ABBE", 1.62004, 36.37),
    ("DENSE_FLINT", "Dense Flint (1.72, V 29)", "ABBE", 1.72, 29.0),
    ("SF11", "Dense Flint N-SF11", "ABBE", 1.78472, 25.68),
    ("SAPPHIRE", "Sapphire", "ABBE", 1.768, 72.2),
]


# ---------------------------------------------------------------------------- scene.opal
class OpalRenderSettings(PropertyGroup):
    """``scene.opal``: the settings of one render (names copied one to one into core RenderSettings)."""

    samples: IntProperty(
        name="Samples", description="Eye samples per pixel: more samples, less noise", default=16, min=1,
        max=1 << 24, soft_max=4096,
    )
    light_paths_auto: BoolProperty(
        name="Automatic Light Paths", description="Size the light pass to the image: 1 light path per camera sample (pixels x samples), "
        "between 65 536 and 1 000 000 (off: the number below)",
        default=True,
    )
    light_paths: IntProperty(
        name="Light Paths", description="Paths traced from the lights in the light pass (caustics and light "
        "reaching gratings through glass) when Automatic is off; the light pass is skipped when the scene needs none",
        default=1_000_000, min=0, soft_max=100_000_000,
        update=lambda self, _context: setattr(self, "light_paths_auto", False),  # a number typed in is meant
    )
    wavelength_min: FloatProperty(
        name="Wavelength Min", description="Shortest wavelength simulated (the CIE observer covers 360-830 nm)",
        default=400.0, min=360.0, max=830.0, subtype=_NM, precision=1,
    )
    wavelength_max: FloatProperty(
        name="Wavelength Max", description="Longest wavelength simulated (the CIE observer covers 360-830 nm)",
        default=700.0, min=360.0, max=830.0, subtype=_NM, precision=1,
    )
    wavelength_step: FloatProperty(
        name="Wavelength Step", description="Spacing of the wavelength samples: 5 nm is the reference, 10 or "
        "20 nm render faster with a small colour error", default=5.0, min=0.5, max=100.0, subtype=_NM, precision=1,
    )
    max_bounces: IntProperty(
        name="Total", description="Bounces of every kind along a path, as Cycles' Max Bounces "
        "(0: direct light only)", default=12, min=0, max=1024, soft_max=64,
    )
    diffuse_bounces: IntProperty(
        name="Diffuse", description="Diffuse bounces along an eye path, as Cycles'", default=4, min=0, max=1024,
        soft_max=64,
    )
    glossy_bounces: IntProperty(
        name="Glossy", description="Mirror and glossy reflections along an eye path, as Cycles'", default=4, min=0,
        max=1024, soft_max=64,
    )
    transmission_bounces: IntProperty(
        name="Transmission", description="Refractions through glass along an eye path, as Cycles'", default=12,
        min=0, max=1024, soft_max=64,
    )
    seed: IntProperty(
        name="Seed", description="Seed of the random numbers: the same seed gives the same image whatever "
        "the number of threads", default=0, min=0,
    )
    use_animated_seed: BoolProperty(
        name="Animated Seed", description="Add the frame number to the seed so the noise changes between frames",
        default=False,
    )
    dispersion_sampling: EnumProperty(
        name="Dispersion Sampling", description="How a ray continues at a dispersive surface",
        items=DISPERSION_SAMPLING_ITEMS, default="SAMPLE",
    )
    spectral_exr: StringProperty(
        name="Spectral EXR", description="Also write the spectral image here (OpenEXR, the JCGT 2021 spectral "
        "layout with one channel per wavelength, plus R, G, B); '#' is replaced by the frame number, '//' is "
        "relative to the .blend file. Empty: off", default="", subtype="FILE_PATH", options=_PATH_OPTIONS,
    )
    scene_npz: StringProperty(
        name="Scene File", description="Also save the exported scene here at render time (.npz, with the "
        "render's modifier levels), so the command line re-renders it without Blender; '#' is replaced by the "
        "frame number, '//' is relative to the .blend file. Empty: off", default="", subtype="FILE_PATH",
        options=_PATH_OPTIONS,
    )
    use_adaptive_sampling: BoolProperty(
        name="Noise Threshold", description="Adaptive sampling, as Cycles': pixels whose noise is below the "
        "threshold stop taking samples, and tiles whose pixels all have are not rendered again (Cycles has it "
        "on by default; here it is off, so existing renders stay as they were)", default=False,
    )
    adaptive_threshold: FloatProperty(
        name="Noise Threshold", description="Noise level at which a pixel stops sampling, as Cycles' (lower: "
        "less noise, longer renders); 0: automatic, max(0.001, 1 / samples), as Cycles", default=0.01, min=0.0,
        max=1.0, soft_max=0.1, precision=4, step=0.1,
    )
    adaptive_min_samples: IntProperty(
        name="Min Samples", description="Samples every pixel takes before adaptive sampling may stop it; "
        "0: automatic from the noise threshold, as Cycles (64 at 0.01)", default=0, min=0, max=1 << 24,
        soft_max=4096,
    )
    use_denoising: BoolProperty(
        name="Denoise", description="Denoise the final render with Intel Open Image Denoise, guided by the "
        "Denoising Albedo and Denoising Normal passes; the noisy image is kept in the Noisy Image pass. Needs "
        "the pyoidn package in Blender's Python (otherwise a warning says so: the passes are still written "
        "for the compositor's Denoise node). Off by default (Cycles has it on)", default=False,
    )
    blue_noise: BoolProperty(
        name="Blue-Noise Sampling", description="Pixels share one low-discrepancy sequence in a blue-noise "
        "order (as Cycles' Automatic pattern), so neighbouring pixels' noise cancels at a distance; off: "
        "each pixel samples its own sequence", default=True,
    )
    grating_footprint: BoolProperty(
        name="Grating Footprint", description="Integrate diffraction gratings' patterns over each pixel's "
        "footprint (ray differentials), so narrow orders and long tracks render without speckle; off: "
        "point samples, which converge only with many samples", default=True,
    )
    caustic_splat: BoolProperty(
        name="Camera Caustics", description="Caustics the camera sees directly (on diffuse surfaces, not "
        "through mirrors or glass): light paths joined to the camera and splatted into the image, sharp "
        "as a light tracer renders them; off: looked up in the caustic map, blurred by its elements",
        default=True,
    )
    time_limit: FloatProperty(
        name="Time Limit", description="Stop after this many seconds (at the end of a progressive round); "
        "0: no limit", default=0.0, min=0.0, step=100.0, unit="TIME_ABSOLUTE",
    )
    backend: EnumProperty(
        name="Ray Casting", description="Ray casting backend", items=BACKEND_ITEMS, default="AUTO",
    )
    scheduler: StringProperty(
        name="Scheduler", description="Render on a Dask cluster (F12 and headless renders): the scheduler's "
        "address, tcp://HOST:8786, or local:N for N worker processes on this machine; the image is the same "
        "as rendered here. Needs dask (requirements-dask.txt) here and on the workers. Empty: render here",
        default="",
    )
    tile_size: IntProperty(
        name="Tile Size", description="Side of the square tiles the image is split into (pixels); cancel "
        "requests are honoured between tiles", default=64, min=8, max=1024, subtype="PIXEL",
    )
    round_samples: IntProperty(
        name="Samples per Round", description="Samples per pixel added by each progressive round: the image "
        "updates after every round", default=16, min=1, max=4096,
    )
    filter_width: FloatProperty(
        name="Filter Width", description="Width of the Blackman-Harris pixel filter, as in Cycles",
        default=1.5, min=0.0, max=10.0, subtype="PIXEL",
    )
    preview_samples: IntProperty(
        name="Viewport Samples", description="Samples per pixel of the rendered viewport at full resolution "
        "(after the quick low-resolution images)", default=16, min=1, soft_max=1024,
    )
    preview_start_scale: IntProperty(
        name="Start Resolution Divider", description="The rendered viewport's first image is this many times "
        "smaller than the view (then halved step by step to full resolution)", default=8, min=1, max=64,
    )

    def wavelength_count(self) -> int | None:
        """Wavelength samples of the grid these settings give, or None when the grid is invalid
        (minimum not below maximum, NaN, out of range: the render stops with the core's message)."""
        try:
            return WavelengthGrid(float(self.wavelength_min), float(self.wavelength_max),
                                  float(self.wavelength_step)).n
        except ValueError:
            return None

    def wavelength_warning(self) -> str:
        """A warning when the grid has fewer than ``MIN_GOOD_WAVELENGTHS`` samples, else ""."""
        n = self.wavelength_count()
        if n is None or n >= MIN_GOOD_WAVELENGTHS:
            return ""
        span = float(self.wavelength_max) - float(self.wavelength_min)
        good = int(span / (MIN_GOOD_WAVELENGTHS - 1) * 10) / 10
        return (f"the wavelength step of {self.wavelength_step:g} nm leaves only {n} wavelength samples between "
                f"{self.wavelength_min:g} and {self.wavelength_max:g} nm (fewer than {MIN_GOOD_WAVELENGTHS}): colours "
                f"are approximate and dispersion is banded; use a step of {good:g} nm or less")

    @classmethod
    def register(cls):
        bpy.types.Scene.opal = PointerProperty(
            name="Opal Diffraction Settings", description="Opal Diffraction render settings", type=cls,
        )

    @classmethod
    def unregister(cls):
        del bpy.types.Scene.opal


# ---------------------------------------------------------------------------- material.opal
_TRANSMISSION = "Transmission Weight"  # Principled v2's name (Blender 4.0+)
_IOR_NODES = ("ShaderNodeBsdfPrincipled", "ShaderNodeBsdfGlass", "ShaderNodeBsdfRefraction")


def principled_node(mat, create: bool = False):
    """The Principled BSDF feeding ``mat``'s output (created, with the output, when ``create``)."""
    if create and bpy.app.version < (5, 0, 0) and not mat.use_nodes:
        mat.use_nodes = True  # always on (and deprecated) from Blender 5.0
    nt = mat.node_tree
    if nt is None:
        return None
    out = nt.get_output_node("ALL") or nt.get_output_node("CYCLES")
    if out is None:
        if not create:
            return None
        out = nt.nodes.new("ShaderNodeOutputMaterial")
        out.location = (300, 0)
    sock = out.inputs["Surface"]
    if sock.is_linked and sock.links[0].from_node.bl_idname == "ShaderNodeBsdfPrincipled":
        return sock.links[0].from_node
    if not create:
        return None
    node = nt.nodes.new("ShaderNodeBsdfPrincipled")
    node.location = (0, 0)
    nt.links.new(node.outputs[0], sock)
    return node


def _body_get(self, name, default):
    node = principled_node(self.id_data)
    sock = node.inputs.get(name) if node is not None else None
    if sock is None:
        return default
    v = sock.default_value
    return tuple(v[:3]) if name == "Base Color" else float(v)


def _body_set(self, name, value):
    mat = self.id_data
    node = principled_node(mat, create=True)
    sock = node.inputs.get(name) or (node.inputs.get("Transmission") if name == _TRANSMISSION else None)
    if sock is not None:
        sock.default_value = value
    if name == "Base Color":
        mat.diffuse_color = value  # Solid mode's material colour


# named functions: Blender evaluates the (string) annotations, and lambdas made there lose this module
def _body_color_get(self):
    return _body_get(self, "Base Color", (0.8, 0.8, 0.8))


def _body_color_set(self, value):
    _body_set(self, "Base Color", (*value, 1.0))


def _body_roughness_get(self):
    return _body_get(self, "Roughness", 0.5)


def _body_roughness_set(self, value):
    _body_set(self, "Roughness", value)


def _body_transmission_get(self):
    return _body_get(self, _TRANSMISSION, 0.0)


def _body_transmission_set(self, value):
    _body_set(self, _TRANSMISSION, value)


def _node_ior_get(self):
    nt = self.id_data.node_tree
    for node in (nt.nodes if nt is not None else ()):
        sock = node.inputs.get("IOR") if node.bl_idname in _IOR_NODES else None
        if sock is not None and not sock.is_linked:
            return float(sock.default_value)
    return 1.45


def _node_ior_set(self, value):
    mat = self.id_data
    if mat.node_tree is None:
        principled_node(mat, create=True)
    for node in mat.node_tree.nodes:
        sock = node.inputs.get("IOR") if node.bl_idname in _IOR_NODES else None
        if sock is not None and not sock.is_linked:
            sock.default_value = value


class OpalMaterialSettings(PropertyGroup):
    """``material.opal``: dispersion and the diffraction grating of a material."""

    dispersion: EnumProperty(
        name="Dispersion", description="How the index of refraction of glass-like materials (Glass BSDF, or "
        "Principled BSDF with transmission) varies with wavelength", items=DISPERSION_ITEMS, default="NONE",
    )
    abbe_number: FloatProperty(
        name="Abbe Number", description="V_d = (n_d - 1) / (n_F - n_C): low values (flint glass, ~30) spread "
        "colours strongly, high values (crown glass, ~60) weakly", default=40.0, min=1.0, max=200.0,
        soft_min=10.0, soft_max=100.0, precision=2,
    )

    grating: BoolProperty(
        name="Diffraction Grating", description="The surface diffracts light like a grating (opal, CD, "
        "holographic foil)", default=False,
    )
    grating_type: EnumProperty(
        name="Type", description="Whether diffracted light leaves on the incident side or passes through",
        items=GRATING_TYPE_ITEMS, default="REFLECTION",
    )
    lattice: EnumProperty(
        name="Lattice", description="Arrangement of the diffracting elements", items=LATTICE_ITEMS, default="LINES",
    )
    period: FloatProperty(
        name="Period", description="Distance between neighbouring slits (grating pitch): a CD is 1600 nm, a "
        "DVD 740 nm; orders appear at sin(theta) = m lambda / period", default=1600.0, min=MIN_PERIOD_NM,
        soft_min=100.0, soft_max=10000.0, subtype=_NM, precision=1,
    )
    slit_width: FloatProperty(
        name="Slit Width", description="Width of one slit or ridge in nm: at most the period; half the period "
        "suppresses the even orders", default=800.0, min=MIN_PERIOD_NM, soft_min=10.0, soft_max=10000.0,
        subtype=_NM, precision=1,
    )
    slit_count: IntProperty(
        name="Slit Count", description="Slits that diffract coherently together: more slits, sharper "
        "orders (peaks are lambda / (N period) wide)", default=1000, min=1, soft_max=100000,
    )
    coherence_length: FloatProperty(
        name="Coherence Length", description="Length along the slits that diffracts coherently, in µm: "
        "shorter lengths smear the orders across the slit direction", default=10.0, min=MIN_COHERENCE_UM,
        soft_min=0.1, soft_max=1000.0, precision=3,
    )
    grating_direction: EnumProperty(
        name="Direction", description="How the direction across the slits is found on the surface",
        items=GRATING_DIRECTION_ITEMS, default="UV",
    )
    rotation: FloatProperty(
        name="Rotation", description="Rotation of the slits about the surface normal, added to the direction "
        "above", default=0.0, subtype="ANGLE",
    )

    # the BRAGG lattice (FCC opal; docs/physics.md section 5.2)
    sphere_diameter: FloatProperty(
        name="Sphere Diameter", description="Diameter D_s of the silica spheres (nm); the (111) planes are "
        "sqrt(2/3) D_s apart and reflect lambda = 2 d111 n_eff at normal incidence (250 nm in air: 550 nm). "
        "Volume domains draw theirs around it (Diameter Spread)", default=250.0, min=MIN_PERIOD_NM,
        soft_min=150.0, soft_max=350.0, subtype=_NM, precision=1,
    )
    sphere_ior: FloatProperty(
        name="Sphere IOR", description="Refractive index of the spheres (silica: 1.45)", default=1.45, min=1.0,
        soft_max=2.0, precision=3,
    )
    void_ior: FloatProperty(
        name="Void IOR", description="Refractive index of the voids between the spheres: air 1.0 (synthetic, "
        "dried), water 1.33, silica cement 1.40-1.43 (natural opal: a smaller contrast gives narrower bands)",
        default=1.0, min=1.0, soft_max=2.0, precision=3,
    )
    layers: IntProperty(
        name="Layers", description="Ordered (111) layers that reflect coherently: more layers, a brighter and "
        "narrower band", default=40, min=1, soft_max=1000,
    )
    mosaic_spread: FloatProperty(
        name="Mosaic Spread", description="Spread of the (111) normals within a domain (degrees): the angular "
        "width of a flash", default=3.0, min=0.0, max=90.0, soft_max=20.0, precision=2,
    )
    # the layout Generate Domains and Add Opal use for volume domains (presets set them)
    domain_count: IntProperty(
        name="Domains", description="Number of volume domains Generate Domains makes in the stone (harlequin: "
        "few and large; pinfire: many and small)", default=300, min=1, soft_max=20000,
    )
    domain_size_spread: FloatProperty(
        name="Size Spread", description="Spread of the domain sizes (additive Voronoi weights, in units of the "
        "mean domain spacing): 0 similar sizes, 1 about a factor of two", default=0.5, min=0.0, soft_max=3.0,
    )
    domain_orientation: EnumProperty(
        name="Orientation", description="How the domains' (111) planes are oriented", items=DOMAIN_ORIENTATION_ITEMS,
        default="LAYERED",
    )
    domain_axis_spread: FloatProperty(
        name="Axis Spread", description="Layered: largest angle between a domain's (111) normal and the object's "
        "Z axis (degrees)", default=25.0, min=0.0, max=180.0, precision=1,
    )
    diameter_spread: FloatProperty(
        name="Diameter Spread", description="Volume domains draw their sphere diameter uniformly in Sphere "
        "Diameter +- this (nm): the range of colours", default=40.0, min=0.0, soft_max=150.0, subtype=_NM,
        precision=1,
    )
    # the body (the material's Principled BSDF), for presets: not stored here
    body_color: FloatVectorProperty(
        name="Body Colour", description="Base Color of the material's Principled BSDF (the opal's body tone)",
        size=3, subtype="COLOR", min=0.0, max=1.0, get=_body_color_get, set=_body_color_set, options=set(),
    )
    body_roughness: FloatProperty(
        name="Body Roughness", description="Roughness of the material's Principled BSDF", min=0.0, max=1.0,
        get=_body_roughness_get, set=_body_roughness_set, options=set(),
    )
    body_transmission: FloatProperty(
        name="Body Transmission", description="Transmission of the material's Principled BSDF (crystal opal: 1)",
        min=0.0, max=1.0, get=_body_transmission_get, set=_body_transmission_set, options=set(),
    )
    node_ior: FloatProperty(
        name="IOR", description="The IOR of the material's Principled, Glass and Refraction BSDF nodes (a glass "
        "preset sets it to n_d)", min=1.0, max=10.0, get=_node_ior_get, set=_node_ior_set, options=set(),
    )

    def grating_problems(self) -> list[str]:
        """Readable reasons why the grating settings cannot work (empty when they can). The fields'
        minimums exclude most of them; values from older files, scripts or drivers (0, NaN) are
        caught here, and a render stops with them as its error."""
        problems = []
        period, slit, coherence = float(self.period), float(self.slit_width), float(self.coherence_length)
        finite = float("inf")
        if not 0.0 < period < finite:
            problems.append(f"grating period must be > 0 nm (got {period:g} nm)")
        if not 0.0 < slit < finite:
            problems.append(f"grating slit width must be > 0 nm (got {slit:g} nm)")
        elif 0.0 < period < finite and slit > period:
            problems.append(f"grating slit width ({slit:g} nm) is larger than its period ({period:g} nm)")
        if not self.slit_count >= 1:
            problems.append(f"grating slit count must be at least 1 (got {self.slit_count})")
        if not 0.0 < coherence < finite:
            problems.append(f"grating coherence length must be > 0 µm (got {coherence:g} µm)")
        if not math.isfinite(self.rotation):
            problems.append(f"grating rotation must be a finite angle (got {self.rotation:g})")
        if self.lattice == "BRAGG":
            d, ns, nv = float(self.sphere_diameter), float(self.sphere_ior), float(self.void_ior)
            if not 0.0 < d < finite:
                problems.append(f"sphere diameter must be > 0 nm (got {d:g} nm)")
            if not (1.0 <= ns < finite and 1.0 <= nv < finite):
                problems.append(f"sphere and void IOR must be at least 1 (got {ns:g}, {nv:g})")
            if not 0.0 <= float(self.mosaic_spread) <= 90.0:
                problems.append(f"mosaic spread must be 0-90 degrees (got {self.mosaic_spread:g})")
        return problems

    @classmethod
    def register(cls):
        bpy.types.Material.opal = PointerProperty(
            name="Opal Diffraction Material", description="Opal Diffraction material settings", type=cls,
        )

    @classmethod
    def unregister(cls):
        del bpy.types.Material.opal


classes = (OpalRenderSettings, OpalMaterialSettings)


register, unregister = bpy.utils.register_classes_factory(classes)
