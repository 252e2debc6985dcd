"""The scene model: flat NumPy arrays in dataclasses (Scene, Materials, Lights, Camera) and their builders.

A scene holds geometry (vertices, triangles, per-triangle material index), a material table, a
light table and a camera, all in world space (Blender's convention: metres, Z up; the camera
looks down its local -Z axis with +Y up). Colours are linear Rec.709 RGB; they become spectra at
render time, because the wavelength grid is a render setting.

Enumerations are stored as integer codes with fixed values so saved files keep loading when
entries are added (the same rule Blender's EnumProperty items follow).

The builders (``Materials.from_list``, ``Lights.from_list``, ``Camera.look_at``,
``Scene.add_mesh`` / ``add_texture`` / ``add_domains``) check what they are given and raise a
one-line SceneError (checks.py); the full checks of a scene are validation.py's
``validate``, and npz.py saves and loads it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from ..util.geometry import triangle_normals, uv_tangents as uv_tangent_frames
from ..util.enums import (ConductorFresnel, GlassTint, LayerFac, GratingDirection, GratingType, Lattice, LightKind, MaterialKind, TextureEncoding, TextureExtension, TextureInterpolation, codes)
from ..spectral.optics import DISPERSION_MODELS
from ..opal.volume import VolumeDomains
from .checks import SceneError

__all__ = [
    "GRATING_TYPES",
    "LATTICES",
    "GRATING_DIRECTIONS",
    "MATERIAL_KINDS",
    "CONDUCTOR_FRESNELS",
    "GLASS_TINTS",
    "LAYER_FACS",
    "LIGHT_KINDS",
    "TEXTURE_INTERPOLATIONS",
    "TEXTURE_EXTENSIONS",
    "TEXTURE_ENCODINGS",
    "MATERIAL_COLUMNS",
    "TEXTURE_COLUMNS",
    "LIGHT_COLUMNS",
    "Materials",
    "Lights",
    "Camera",
    "Scene",
]

#: Material kinds and light kinds: name -> stable code (enums.py).
MATERIAL_KINDS = codes(MaterialKind)
CONDUCTOR_FRESNELS = codes(ConductorFresnel)
GLASS_TINTS = codes(GlassTint)
LAYER_FACS = codes(LayerFac)
LIGHT_KINDS = codes(LightKind)

#: Image texture settings: name -> stable code (enums.py).
TEXTURE_INTERPOLATIONS = codes(TextureInterpolation)
TEXTURE_EXTENSIONS = codes(TextureExtension)
TEXTURE_ENCODINGS = codes(TextureEncoding)

#: Grating enumerations: name -> stable code (enums.py).
GRATING_TYPES = codes(GratingType)
LATTICES = codes(Lattice)
GRATING_DIRECTIONS = codes(GratingDirection)

#: The material table's columns: name -> (dtype, per-row shape, default, enumeration or None).
MATERIAL_COLUMNS = {
    "kind": (np.int32, (), "DIFFUSE", MATERIAL_KINDS),
    "color": (np.float32, (3,), (0.8, 0.8, 0.8), None),
    "ior": (np.float32, (), 1.5, None),
    "dispersion": (np.int32, (), "NONE", DISPERSION_MODELS),
    "abbe": (np.float32, (), 0.0, None),
    "name": ("<U64", (), None, None),
    "emission": (np.float32, (3,), (0.0, 0.0, 0.0), None),
    "grating": (np.int32, (), 0, None),
    "grating_type": (np.int32, (), "REFLECTION", GRATING_TYPES),
    "lattice": (np.int32, (), "LINES", LATTICES),
    "period": (np.float32, (), 1600.0, None),
    "slit_width": (np.float32, (), 800.0, None),
    "slit_count": (np.int32, (), 1000, None),
    "coherence_length": (np.float32, (), 10.0, None),
    "grating_direction": (np.int32, (), "UV", GRATING_DIRECTIONS),
    "rotation": (np.float32, (), 0.0, None),
    # image textures (an index into Scene.textures, -1: none; docs/physics.md section 13)
    "color_texture": (np.int32, (), -1, None),
    "roughness_texture": (np.int32, (), -1, None),
    "metallic_texture": (np.int32, (), -1, None),
    "emission_texture": (np.int32, (), -1, None),
    "normal_texture": (np.int32, (), -1, None),
    "normal_strength": (np.float32, (), 1.0, None),
    "emission_strength": (np.float32, (), 1.0, None),
    "roughness_channel": (np.int32, (), -1, None),
    "metallic_channel": (np.int32, (), -1, None),
    # a compiled node tree (an index into Scene.shader_programs, -1: none; docs/physics.md section 13.6)
    "shader_program": (np.int32, (), -1, None),
    # rough surfaces and Principled's layers (docs/physics.md section 14)
    "roughness": (np.float32, (), 0.0, None),
    "metallic": (np.float32, (), 0.0, None),
    "transmission": (np.float32, (), 0.0, None),
    "specular_ior_level": (np.float32, (), 0.0, None),
    "specular_tint": (np.float32, (3,), (1.0, 1.0, 1.0), None),
    "conductor_fresnel": (np.int32, (), "CONSTANT", CONDUCTOR_FRESNELS),
    # what a glass's colour is the colour of (docs/physics.md section 2.7)
    "glass_tint": (np.int32, (), "REFRACTION", GLASS_TINTS),
    # a shader mix of unlike BSDFs as a lobe mixture (docs/physics.md section 14.8): the metal and
    # glass layers' own colours (negative: ``color``) and the per-hit source of a two-layer mix's
    # weights (layer codes 0 base, 1 metal, 2 glass; the weight of layer_fac_to is the Fac)
    "metal_color": (np.float32, (3,), (-1.0, -1.0, -1.0), None),
    "glass_color": (np.float32, (3,), (-1.0, -1.0, -1.0), None),
    "layer_fac": (np.int32, (), "CONSTANT", LAYER_FACS),
    "layer_fac_value": (np.float32, (), 0.5, None),
    "layer_fac_from": (np.int32, (), 0, None),
    "layer_fac_to": (np.int32, (), 1, None),
    # the Diffuse BSDF's Roughness: Oren-Nayar's sigma (docs/physics.md section 14.9; 0: Lambert)
    "diffuse_roughness": (np.float32, (), 0.0, None),
    # a Holdout's weight in [0, 1] (docs/physics.md section 14.8): with Film > Transparent a camera
    # ray meeting the surface takes it off the pixel's alpha (Cycles' holdout); 0: none
    "holdout": (np.float32, (), 0.0, None),
    # Principled's coat and sheen layers over the rest (docs/physics.md section 14.10): weights and
    # roughness in [0, 1], the coat's index and tint (linear RGB, the colour at normal incidence
    # through the coat's unit thickness), the sheen's tint (linear RGB)
    "coat_weight": (np.float32, (), 0.0, None),
    "coat_roughness": (np.float32, (), 0.03, None),
    "coat_ior": (np.float32, (), 1.5, None),
    "coat_tint": (np.float32, (3,), (1.0, 1.0, 1.0), None),
    "sheen_weight": (np.float32, (), 0.0, None),
    "sheen_roughness": (np.float32, (), 0.5, None),
    "sheen_tint": (np.float32, (3,), (1.0, 1.0, 1.0), None),
    # the BRAGG (FCC opal) lattice (docs/physics.md section 5.7; core/materials/bragg_bsdf.py)
    "sphere_diameter": (np.float32, (), 250.0, None),
    "sphere_ior": (np.float32, (), 1.45, None),
    "void_ior": (np.float32, (), 1.0, None),
    "layers": (np.int32, (), 40, None),
    "mosaic_spread": (np.float32, (), 3.0, None),
    # a thin film over the surface's Fresnel (Principled's Thin Film; docs/physics.md section 2.8)
    "thin_film_thickness": (np.float32, (), 0.0, None),
    "thin_film_ior": (np.float32, (), 1.33, None),
    # the homogeneous medium inside the surface (a Volume output; docs/physics.md section 15):
    # sigma_s = volume_scatter_density * colour, sigma_a = volume_absorption_density * colour
    # (1/m; each colour uplifted per wavelength), the Henyey-Greenstein anisotropy and the emission
    # coefficient (linear RGB radiance per metre, Cycles' volume emission); zero: no medium
    "volume_scatter_density": (np.float32, (), 0.0, None),
    "volume_scatter_color": (np.float32, (3,), (1.0, 1.0, 1.0), None),
    "volume_absorption_density": (np.float32, (), 0.0, None),
    "volume_absorption_color": (np.float32, (3,), (1.0, 1.0, 1.0), None),
    "volume_anisotropy": (np.float32, (), 0.0, None),
    "volume_emission": (np.float32, (3,), (0.0, 0.0, 0.0), None),
}

#: The material columns that name a texture.
TEXTURE_COLUMNS = ("color_texture", "roughness_texture", "metallic_texture", "emission_texture", "normal_texture")


def _layer_defaults(kind: np.ndarray, given: dict) -> dict:
    """metallic / transmission a row did not give: 1 for a MIRROR / DIELECTRIC row (what those
    kinds meant before the columns existed), else 0."""
    out = {}
    if "metallic" not in given:
        out["metallic"] = (kind == MATERIAL_KINDS["MIRROR"]).astype(np.float32)
    if "transmission" not in given:
        out["transmission"] = (kind == MATERIAL_KINDS["DIELECTRIC"]).astype(np.float32)
    return out


def _material_column_default(name, rows):
    dtype, tail, default, enum = MATERIAL_COLUMNS[name]
    if name == "name":
        return np.array([f"material_{i}" for i in range(rows)], dtype)
    if enum is not None:
        default = enum[default]
    return np.array([default] * rows, dtype).reshape((rows,) + tail)


@dataclass
class Materials:
    """Material table, one row per material.

    kind: MATERIAL_KINDS code. color: base colour (diffuse albedo, mirror tint, or dielectric
    tint applied to transmission and reflection alike). ior: index of refraction at the d line
    (used by 'NONE' and 'ABBE' dispersion). dispersion: DISPERSION_MODELS code. abbe: Abbe number V_d.
    emission: emitted radiance as linear RGB (Cycles' units: Emission colour x strength; a white
    emitter of strength 1 has the radiance of the world colour (1, 1, 1)), both sides, any kind.

    Rough surfaces and Principled BSDF v2 layers (docs/physics.md section 14; core/materials/bsdf.py):
    roughness: Blender's roughness in [0, 1] (GGX alpha = roughness^2; below bsdf.MIN_ROUGHNESS
    the surface is smooth). metallic and transmission in [0, 1]: Principled's layer weights - a
    conductor of F0 = color with weight metallic, then glass (tint color) with weight
    (1 - metallic) transmission, then the dielectric base (diffuse albedo color under a specular
    layer) with the rest; a Glossy / Metallic BSDF is metallic 1, a Glass BSDF transmission 1,
    a Diffuse BSDF both 0. Missing, they follow kind (1 for MIRROR / DIELECTRIC rows). kind stays
    the heaviest layer (the smooth transport and the light pass read it). specular_ior_level:
    Principled's IOR Level - the base's specular layer has F0 = ((ior - 1) / (ior + 1))^2 x 2 x
    level (0.5: the physical F0 of ior; 0, the default: no layer, pure Lambert). specular_tint:
    linear RGB, Principled's Specular Tint - the specular layer's F0 tint and, on metals, the
    F82 edge tint (a Metallic BSDF's Edge Tint). conductor_fresnel (CONDUCTOR_FRESNELS): CONSTANT
    (the metal reflects color at every angle: Glossy BSDF and older files) or F82_TINT (Schlick
    from F0 = color with the edge tint: Principled and Metallic BSDF). glass_tint (GLASS_TINTS,
    docs/physics.md section 2.7): what a glass's color is the colour of - REFRACTION (one
    refraction's, the default: Glass BSDF and older files) or PASS (one pass through a closed
    object, two refractions: Principled's Base Color).

    Shader mixes of unlike BSDFs (docs/physics.md section 14.8) are these layers as a lobe
    mixture: metal_color and glass_color (linear RGB; negative, the default: ``color``) are the
    metal's F0 / Glossy colour and the glass's colour where they differ from the base's (a Mix
    of a Diffuse and a Glossy BSDF). layer_fac (LAYER_FACS) CONSTANT keeps metallic /
    transmission; FRESNEL, LAYER_FRESNEL, LAYER_FACING give a two-layer mix its weights per hit
    from the view direction (Blender's Fresnel node of IOR layer_fac_value, the Layer Weight
    node's outputs of Blend layer_fac_value): layer layer_fac_to (0 base, 1 metal, 2 glass)
    gets the Fac, layer_fac_from the rest. diffuse_roughness in [0, 1]: a Diffuse BSDF's Roughness,
    its base rendered Oren-Nayar (docs/physics.md section 14.9) where it is above 0 and the base has
    no specular layer. holdout in [0, 1]: the weight of a Holdout shader in the surface (Film >
    Transparent: a camera ray meeting it takes that much off the pixel's alpha). coat_weight,
    coat_roughness, coat_ior (>= 1), coat_tint, sheen_weight, sheen_roughness, sheen_tint:
    Principled's coat and sheen layered over the rest as Cycles layers them (docs/physics.md
    section 14.10; weights and roughness in [0, 1], tints linear RGB >= 0).

    Grating layer (docs/physics.md section 3), on top of the base kind: grating (0/1), grating_type
    (GRATING_TYPES), lattice (LATTICES), period D (nm), slit_width a (nm), slit_count N,
    coherence_length L (um, the slits' length), grating_direction (GRATING_DIRECTIONS: how the
    exporter found the per-triangle tangent in ``Scene.tri_tangent``), rotation (radians, about
    the normal). With lattice BRAGG the layer is not a surface grating but FCC opal's volume
    Bragg reflection (docs/physics.md section 5.7): sphere_diameter D_s (nm, 100-500), sphere_ior
    and void_ior (1-3), layers (ordered (111) periods, 1-10000) and mosaic_spread (degrees, 0-45:
    the spread of the plane normals about the domain's axis); the base kind is the body tone.

    Interior medium (docs/physics.md section 15; core/volumes/): a homogeneous medium inside the
    closed surface, from the material's Volume output: volume_scatter_density and
    volume_absorption_density (1/m, >= 0) times volume_scatter_color / volume_absorption_color
    (linear RGB in [0, 1], uplifted per wavelength) are sigma_s and sigma_a, volume_anisotropy
    (-1..1) the Henyey-Greenstein g, volume_emission (linear RGB, >= 0) the emitted radiance per
    metre. A volume-only material is a DIELECTRIC of index 1 (a null boundary).

    Thin film (docs/physics.md section 2.8; core/spectral/thin_film.py): thin_film_thickness d
    (nm, >= 0; 0: none) and thin_film_ior (>= 1) of a film over the surface, whose Airy
    interference replaces the Fresnel reflectance of smooth glass, mirrors and metals (and of the
    rough lobes) at every wavelength; Principled BSDF's Thin Film Thickness and Thin Film IOR.

    Image textures (docs/physics.md section 13), each an index into ``Scene.textures`` or -1:
    color_texture replaces ``color`` per hit (which keeps the texture's average for what reads
    one colour per material), roughness_texture / metallic_texture replace those values (the
    texture's luminance, or with roughness_channel / metallic_channel 0-3 its R, G, B or alpha,
    as a Separate Color node reads it), emission_texture's colour times emission_strength is the emitted
    radiance (``emission`` keeps its average), normal_texture is a tangent-space normal map
    (Blender's Normal Map node) applied with normal_strength.
    """

    kind: np.ndarray = field(default_factory=lambda: _material_column_default("kind", 0))
    color: np.ndarray = field(default_factory=lambda: _material_column_default("color", 0))
    ior: np.ndarray = field(default_factory=lambda: _material_column_default("ior", 0))
    dispersion: np.ndarray = field(default_factory=lambda: _material_column_default("dispersion", 0))
    abbe: np.ndarray = field(default_factory=lambda: _material_column_default("abbe", 0))
    name: np.ndarray = field(default_factory=lambda: _material_column_default("name", 0))
    emission: np.ndarray = field(default_factory=lambda: _material_column_default("emission", 0))
    grating: np.ndarray = field(default_factory=lambda: _material_column_default("grating", 0))
    grating_type: np.ndarray = field(default_factory=lambda: _material_column_default("grating_type", 0))
    lattice: np.ndarray = field(default_factory=lambda: _material_column_default("lattice", 0))
    period: np.ndarray = field(default_factory=lambda: _material_column_default("period", 0))
    slit_width: np.ndarray = field(default_factory=lambda: _material_column_default("slit_width", 0))
    slit_count: np.ndarray = field(default_factory=lambda: _material_column_default("slit_count", 0))
    coherence_length: np.ndarray = field(default_factory=lambda: _material_column_default("coherence_length", 0))
    grating_direction: np.ndarray = field(default_factory=lambda: _material_column_default("grating_direction", 0))
    rotation: np.ndarray = field(default_factory=lambda: _material_column_default("rotation", 0))
    color_texture: np.ndarray = field(default_factory=lambda: _material_column_default("color_texture", 0))
    roughness_texture: np.ndarray = field(default_factory=lambda: _material_column_default("roughness_texture", 0))
    metallic_texture: np.ndarray = field(default_factory=lambda: _material_column_default("metallic_texture", 0))
    emission_texture: np.ndarray = field(default_factory=lambda: _material_column_default("emission_texture", 0))
    normal_texture: np.ndarray = field(default_factory=lambda: _material_column_default("normal_texture", 0))
    normal_strength: np.ndarray = field(default_factory=lambda: _material_column_default("normal_strength", 0))
    emission_strength: np.ndarray = field(default_factory=lambda: _material_column_default("emission_strength", 0))
    roughness_channel: np.ndarray = field(default_factory=lambda: _material_column_default("roughness_channel", 0))
    metallic_channel: np.ndarray = field(default_factory=lambda: _material_column_default("metallic_channel", 0))
    shader_program: np.ndarray = field(default_factory=lambda: _material_column_default("shader_program", 0))
    roughness: np.ndarray = field(default_factory=lambda: _material_column_default("roughness", 0))
    metallic: np.ndarray = field(default_factory=lambda: _material_column_default("metallic", 0))
    transmission: np.ndarray = field(default_factory=lambda: _material_column_default("transmission", 0))
    specular_ior_level: np.ndarray = field(default_factory=lambda: _material_column_default("specular_ior_level", 0))
    specular_tint: np.ndarray = field(default_factory=lambda: _material_column_default("specular_tint", 0))
    conductor_fresnel: np.ndarray = field(default_factory=lambda: _material_column_default("conductor_fresnel", 0))
    glass_tint: np.ndarray = field(default_factory=lambda: _material_column_default("glass_tint", 0))
    metal_color: np.ndarray = field(default_factory=lambda: _material_column_default("metal_color", 0))
    glass_color: np.ndarray = field(default_factory=lambda: _material_column_default("glass_color", 0))
    layer_fac: np.ndarray = field(default_factory=lambda: _material_column_default("layer_fac", 0))
    layer_fac_value: np.ndarray = field(default_factory=lambda: _material_column_default("layer_fac_value", 0))
    layer_fac_from: np.ndarray = field(default_factory=lambda: _material_column_default("layer_fac_from", 0))
    layer_fac_to: np.ndarray = field(default_factory=lambda: _material_column_default("layer_fac_to", 0))
    diffuse_roughness: np.ndarray = field(default_factory=lambda: _material_column_default("diffuse_roughness", 0))
    holdout: np.ndarray = field(default_factory=lambda: _material_column_default("holdout", 0))
    coat_weight: np.ndarray = field(default_factory=lambda: _material_column_default("coat_weight", 0))
    coat_roughness: np.ndarray = field(default_factory=lambda: _material_column_default("coat_roughness", 0))
    coat_ior: np.ndarray = field(default_factory=lambda: _material_column_default("coat_ior", 0))
    coat_tint: np.ndarray = field(default_factory=lambda: _material_column_default("coat_tint", 0))
    sheen_weight: np.ndarray = field(default_factory=lambda: _material_column_default("sheen_weight", 0))
    sheen_roughness: np.ndarray = field(default_factory=lambda: _material_column_default("sheen_roughness", 0))
    sheen_tint: np.ndarray = field(default_factory=lambda: _material_column_default("sheen_tint", 0))
    sphere_diameter: np.ndarray = field(default_factory=lambda: _material_column_default("sphere_diameter", 0))
    sphere_ior: np.ndarray = field(default_factory=lambda: _material_column_default("sphere_ior", 0))
    void_ior: np.ndarray = field(default_factory=lambda: _material_column_default("void_ior", 0))
    layers: np.ndarray = field(default_factory=lambda: _material_column_default("layers", 0))
    mosaic_spread: np.ndarray = field(default_factory=lambda: _material_column_default("mosaic_spread", 0))
    thin_film_thickness: np.ndarray = field(default_factory=lambda: _material_column_default("thin_film_thickness", 0))
    thin_film_ior: np.ndarray = field(default_factory=lambda: _material_column_default("thin_film_ior", 0))
    volume_scatter_density: np.ndarray = field(default_factory=lambda: _material_column_default("volume_scatter_density", 0))
    volume_scatter_color: np.ndarray = field(default_factory=lambda: _material_column_default("volume_scatter_color", 0))
    volume_absorption_density: np.ndarray = field(default_factory=lambda: _material_column_default("volume_absorption_density", 0))
    volume_absorption_color: np.ndarray = field(default_factory=lambda: _material_column_default("volume_absorption_color", 0))
    volume_anisotropy: np.ndarray = field(default_factory=lambda: _material_column_default("volume_anisotropy", 0))
    volume_emission: np.ndarray = field(default_factory=lambda: _material_column_default("volume_emission", 0))

    def __len__(self):
        return _rows(self.kind)

    @classmethod
    def from_list(cls, rows: list[dict]) -> "Materials":
        """Build from dicts like {'kind': 'DIELECTRIC', 'color': (1,1,1), 'ior': 1.5, 'dispersion': 'BK7'}.

        Missing keys take their defaults (a dielectric's colour defaults to clear, 1); enumerations
        are given by name ('BK7', 'REFLECTION', ...).
        """
        out = {}
        for i, r in enumerate(rows):
            if not isinstance(r, dict):
                raise SceneError(f"material {i}: expected a dict of settings, got {type(r).__name__}")
        for name, (dtype, tail, default, enum) in MATERIAL_COLUMNS.items():
            col = _material_column_default(name, len(rows))
            for i, r in enumerate(rows):
                unknown = set(r) - set(MATERIAL_COLUMNS)
                if unknown:
                    raise SceneError(f"material {i}: unknown setting(s) {sorted(unknown)}")
                if name not in r:
                    continue
                val = r[name]
                if enum is not None:
                    if not isinstance(val, str) or val not in enum:
                        raise SceneError(f"material {i}: unknown {name} {val!r}; expected one of {sorted(enum)}")
                    val = enum[val]
                _check_cell(val, f"material {i}: {name}", tail, name == "name")
                try:
                    col[i] = val
                except Exception:
                    raise SceneError(f"material {i}: {name} {val!r} is not a valid value "
                                     f"(expected {'a name' if name == 'name' else _shape_words(tail)})") from None
            out[name] = col
        # clear glass by default: a dielectric without a colour is untinted
        for i, r in enumerate(rows):
            if "color" not in r and out["kind"][i] == MATERIAL_KINDS["DIELECTRIC"]:
                out["color"][i] = 1.0
            for name, col in _layer_defaults(out["kind"][i:i + 1], r).items():
                out[name][i] = col[0]
        return cls(**out)

    @classmethod
    def from_columns(cls, columns: dict, rows: int) -> "Materials":
        """Build from stored columns, filling columns an older file lacks with their defaults
        (metallic / transmission from the kind, as ``from_list`` does)."""
        out = {name: np.asarray(columns[name]) if name in columns else _material_column_default(name, rows)
               for name in MATERIAL_COLUMNS}
        kind = np.asarray(out["kind"])
        if kind.shape == (rows,) and kind.dtype.kind in "iu":  # else validation names the problem
            out.update(_layer_defaults(kind, columns))
        return cls(**out)


@dataclass
class Lights:
    """Light table, one row per light, with Cycles' units.

    POINT / SPOT: ``power`` in watts; a white light has radiant intensity power / (4 pi) W/sr in
    every direction (a spot masks that by its cone: ``spot_size`` full angle in radians,
    ``spot_blend`` in [0, 1]).
    SUN: ``power`` is the strength, the irradiance in W/m^2 on a surface facing the sun;
    ``direction`` is the direction the light travels.
    AREA_RECT / AREA_DISK: ``power`` in watts, emitted one-sided along ``direction`` as a Lambertian
    emitter of radiance power / (pi * area); ``axis_u`` is the local X axis, ``size_u`` / ``size_v``
    the side lengths (disk: diameters).
    ``radius`` (m, POINT / SPOT; Blender's ``shadow_soft_size``): 0 is a delta point light; > 0 a
    light of that radius with the same intensity in total, radiance power / (4 pi * pi radius^2)
    (docs/physics.md section 7.5): a sphere, or with ``soft_falloff`` 1 (Blender's "Soft
    Falloff", Cycles' default) a disk of that radius facing the shading point.
    ``angle`` (radians, SUN; Blender's ``angle``): the sun's full angular diameter, 0 a delta
    direction; the strength stays the irradiance facing it.
    ``color`` is linear RGB; ``temperature`` > 0 (kelvin) uses a blackbody spectrum instead
    (scaled to the same luminance as a white light of the same power).
    """

    kind: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    position: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float64))
    direction: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float64))
    axis_u: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float64))
    color: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float32))
    power: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float64))
    temperature: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float64))
    spot_size: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float64))
    spot_blend: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float64))
    size_u: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float64))
    size_v: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float64))
    radius: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float64))
    angle: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float64))
    soft_falloff: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    # SUN: 1 where camera rays see its disc (Blender's object Visibility > Camera, off for lamps by
    # default as in Cycles; on for the sun a Sky Texture's disc becomes: docs/physics.md 7.12)
    camera_visible: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))

    def __len__(self):
        return _rows(self.kind)

    @classmethod
    def from_list(cls, rows: list[dict]) -> "Lights":
        """Build from dicts like {'kind': 'POINT', 'position': (0, 0, 2), 'power': 100}."""
        cols = {f.name: [] for f in fields(cls)}
        known = {f.name for f in fields(cls)}
        proto = cls()
        for i, r in enumerate(rows):
            if not isinstance(r, dict):
                raise SceneError(f"light {i}: expected a dict of settings, got {type(r).__name__}")
            unknown = set(r) - known
            if unknown:
                raise SceneError(f"light {i}: unknown setting(s) {sorted(unknown)}")
            k = r.get("kind", "POINT")
            if not isinstance(k, str) or k not in LIGHT_KINDS:
                raise SceneError(f"light {i}: unknown kind {k!r}; expected one of {sorted(LIGHT_KINDS)}")
            for name, val in r.items():
                if name != "kind":
                    _check_cell(val, f"light {i}: {name}", getattr(proto, name).shape[1:], False)
            d = np.asarray(r.get("direction", (0.0, 0.0, -1.0)), np.float64)
            au = np.asarray(r.get("axis_u", _any_perpendicular(d)), np.float64)
            vals = {
                "kind": LIGHT_KINDS[k],
                "position": r.get("position", (0.0, 0.0, 0.0)),
                "direction": d,
                "axis_u": au,
                "color": r.get("color", (1.0, 1.0, 1.0)),
                "power": r.get("power", 1000.0 if k != "SUN" else 1.0),
                "temperature": r.get("temperature", 0.0),
                "spot_size": r.get("spot_size", np.radians(45.0)),
                "spot_blend": r.get("spot_blend", 0.15),
                "size_u": r.get("size_u", 1.0),
                "size_v": r.get("size_v", r.get("size_u", 1.0)),
                "radius": r.get("radius", 0.0),
                "angle": r.get("angle", 0.0),
                "soft_falloff": r.get("soft_falloff", 0),
                "camera_visible": r.get("camera_visible", 0),
            }
            for name, v in vals.items():
                cols[name].append(v)
        out = cls()
        for f in fields(cls):
            proto = getattr(out, f.name)
            setattr(out, f.name, np.array(cols[f.name], proto.dtype).reshape((-1,) + proto.shape[1:]))
        return out


#: The light table's columns: name -> (per-row shape, canonical dtype).
LIGHT_COLUMNS = {
    "kind": ((), np.int32), "position": ((3,), np.float64), "direction": ((3,), np.float64),
    "axis_u": ((3,), np.float64), "color": ((3,), np.float32), "power": ((), np.float64),
    "temperature": ((), np.float64), "spot_size": ((), np.float64), "spot_blend": ((), np.float64),
    "size_u": ((), np.float64), "size_v": ((), np.float64), "radius": ((), np.float64),
    "angle": ((), np.float64), "soft_falloff": ((), np.int32), "camera_visible": ((), np.int32),
}


def _rows(column) -> int:
    """Rows of a table column; 0 for what is not an array of rows (validation names the problem)."""
    try:
        shape = np.shape(column)
    except Exception:
        return 0
    return int(shape[0]) if shape else 0


def _shape_words(tail) -> str:
    return "a number" if not tail else f"{tail[0]} numbers"


def _check_cell(val, what: str, tail, is_name: bool) -> None:
    """One value given to ``from_list``: a string for a name, else a number or ``tail[0]`` numbers."""
    if is_name:
        if not isinstance(val, str):
            raise SceneError(f"{what} must be a string, got {val!r}")
        return
    try:
        a = np.asarray(val)
    except Exception:
        a = None
    if a is None or a.dtype.kind not in "iufb" or a.shape != tuple(tail) or (a.dtype.kind == "b" and "grating" not in what):
        raise SceneError(f"{what} must be {_shape_words(tail)}, got {val!r}")


def _any_perpendicular(d) -> np.ndarray:
    d = np.asarray(d, np.float64)
    a = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(d, a)
    return u / max(np.linalg.norm(u), 1e-30)


@dataclass
class Camera:
    """A perspective, orthographic or panoramic camera with Blender's (Cycles') conventions.

    ``matrix``: 4x4 camera-to-world (local -Z is the view direction, +Y up). ``lens`` focal length
    and ``sensor_width`` / ``sensor_height`` in mm; ``sensor_fit`` 'AUTO' (the sensor width spans
    the larger image dimension), 'HORIZONTAL' (sensor_width spans the width) or 'VERTICAL'
    (sensor_height spans the height). ``ortho_scale`` spans the fitted dimension in metres.
    ``shift_x`` / ``shift_y`` are fractions of the fitted dimension, as in Blender.
    """

    matrix: np.ndarray = field(default_factory=lambda: np.eye(4))
    kind: str = "PERSP"
    lens: float = 50.0
    sensor_width: float = 36.0
    sensor_height: float = 24.0
    sensor_fit: str = "AUTO"
    ortho_scale: float = 6.0
    shift_x: float = 0.0
    shift_y: float = 0.0
    width: int = 640
    height: int = 480
    # depth of field (thin lens, Cycles' conventions: docs/physics.md sections 6.7-6.9): the aperture's
    # radius in metres (0: a pinhole), the distance in metres to the plane in focus (along the
    # view axis), the blade count (below 3: a round aperture), the blades' rotation (radians) and
    # the anamorphic ratio (the aperture's x is divided by it)
    aperture_radius: float = 0.0
    focus_distance: float = 10.0
    aperture_blades: int = 0
    aperture_rotation: float = 0.0
    aperture_ratio: float = 1.0
    # clipping (Cycles: planes at these depths along the view axis; panoramic cameras: distances
    # along the ray): nothing nearer than clip_start or farther than clip_end is seen
    clip_start: float = 0.0
    clip_end: float = float("inf")
    # panoramic cameras (kind 'PANO'): 'EQUIRECTANGULAR' (latitude / longitude ranges, radians),
    # 'FISHEYE_EQUIDISTANT' (fisheye_fov radians across the image's circle) or
    # 'FISHEYE_EQUISOLID' (fisheye_lens in mm on the fitted sensor, fisheye_fov the circle's limit)
    panorama_type: str = "EQUIRECTANGULAR"
    fisheye_fov: float = float(np.pi)
    fisheye_lens: float = 10.5
    latitude_min: float = float(-np.pi / 2)
    latitude_max: float = float(np.pi / 2)
    longitude_min: float = float(-np.pi)
    longitude_max: float = float(np.pi)
    # motion blur (docs/physics.md section 6.13): the camera-to-world matrices (N, 4, 4) at N >= 2
    # evenly spaced times across the shutter, first to last (empty: no camera motion, ``matrix``
    # throughout), and the shutter curve as an inverse CDF over [0, 1] (a ray's uniform number ->
    # its time in the shutter, 0 first, 1 last; empty: a flat curve, time = the number)
    motion: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 4)))
    shutter_table: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @staticmethod
    def look_at(eye, target, up=(0.0, 0.0, 1.0), **kw) -> "Camera":
        """A camera at ``eye`` looking at ``target`` with ``up`` roughly up."""
        eye, target, up = (np.asarray(v, np.float64) for v in (eye, target, up))
        back = eye - target
        back /= np.linalg.norm(back)
        right = np.cross(up, back)
        if np.linalg.norm(right) < 1e-9:
            right = _any_perpendicular(back)
        right /= np.linalg.norm(right)
        upv = np.cross(back, right)
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, upv, back, eye
        return Camera(matrix=m, **kw)


@dataclass
class Scene:
    """Flat arrays describing everything a render needs.

    Optional per-triangle grating data (empty arrays mean "not given"): ``tri_tangent`` (T, 3),
    the grating vector t-hat in world space (projected onto each triangle's plane at render
    time; zero rows fall back to the world X axis), and ``tri_period`` (T,), a period in nm that
    overrides the material's (0: use the material's), as the opal domain tools write them.

    ``corner_normals`` (T, 3, 3): the shading normal at each corner of each triangle (Blender's
    corner normals: smooth, split or custom), world space, interpolated across the triangle at
    render time (docs/physics.md section 4.6); empty (0, 3, 3) means flat shading everywhere.
    The world: ``world_color`` (3,) linear RGB radiance, or, when ``world_image`` (H, W, 3)
    float32 holds an equirectangular map (Cycles' convention, row 0 at the bottom;
    core/lights/environment.py), the multiplier of that map (the Background's strength times its
    tint): the radiance from direction d is world_color * image(world_rotation @ d).
    ``world_rotation`` (3, 3) is orthogonal, world direction -> map direction. An empty
    (0, 0, 3) image: a uniform world.
    Image textures (docs/physics.md section 13; empty arrays mean "none"): ``corner_uvs``
    (T, 3, 2) texture coordinates per triangle corner, ``corner_tangents`` (T, 3, 4) per-corner
    tangent (x, y, z, world space) and bitangent sign for tangent-space normal maps,
    ``textures`` a list of (H, W, 4) float32 RGBA images (row 0 at the bottom, Blender's order;
    linear Rec.709, or sRGB-encoded where ``texture_encoding`` says so), and per texture the
    TEXTURE_INTERPOLATIONS / TEXTURE_EXTENSIONS / TEXTURE_ENCODINGS codes
    ``texture_interpolation``, ``texture_extension``, ``texture_encoding`` (K,) (empty: LINEAR,
    REPEAT, LINEAR for every texture). Materials bind them by index (``Materials.color_texture``...).
    Shader programs (docs/physics.md section 13.6): ``shader_programs`` a list of
    core/scene/shader_programs.ShaderProgram, bound by ``Materials.shader_program``; the texture
    coordinates they read per triangle corner, ``corner_generated`` (T, 3, 3) (Generated: object
    space over the mesh's texture space) and ``corner_object`` (T, 3, 3) (object space); empty
    (0, 3, 3): none (a program reading them gets (0, 0, 0), with a validation warning);
    ``corner_attributes`` name -> (T, 3, 4) the mesh attributes they read (RGBA per corner).
    Opal volume domains (docs/physics.md section 5.4; empty: none), world space:
    ``domain_seeds`` (S, 3) m, ``domain_weight`` (S,) m (additive Voronoi weights),
    ``domain_axis`` (S, 3) unit (111) normals, ``domain_diameter`` (S,) nm, ``domain_group``
    (S,) (one group per opal object instance) and ``tri_domain_group`` (T,) (-1: a triangle
    without domains); built with :meth:`add_domains`, read with :meth:`volume_domains`.
    """

    vertices: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float32))
    triangles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int32))
    tri_material: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    materials: Materials = field(default_factory=Materials)
    lights: Lights = field(default_factory=Lights)
    camera: Camera | None = None
    world_color: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    tri_tangent: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float32))
    tri_period: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    corner_normals: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3), np.float32))
    world_image: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 3), np.float32))
    world_rotation: np.ndarray = field(default_factory=lambda: np.eye(3))

    corner_uvs: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 2), np.float32))
    corner_tangents: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 4), np.float32))
    textures: list = field(default_factory=list)
    texture_interpolation: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    texture_extension: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    texture_encoding: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    shader_programs: list = field(default_factory=list)
    corner_generated: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3), np.float32))
    corner_object: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3), np.float32))
    # mesh attributes shader programs read (Attribute / Color Attribute nodes; docs/physics.md
    # section 13.6): name -> (T, 3, 4) float32 RGBA per triangle corner (zeros where a mesh lacks it)
    corner_attributes: dict = field(default_factory=dict)
    # object motion blur (docs/physics.md section 6.13): the vertices (K, V, 3) at the centres of K
    # equal time bins of the shutter (bin k: shutter times [k / K, (k + 1) / K)); a camera ray of
    # time t sees bin floor(t K)'s geometry; empty (0, 0, 3): the geometry does not move
    motion_vertices: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 3), np.float32))
    # opal volume domains (core/opal/volume.py; docs/physics.md section 5.4), world space; empty: none
    domain_seeds: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float64))
    domain_weight: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float64))
    domain_axis: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float32))
    domain_diameter: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    domain_group: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    tri_domain_group: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    # the world's volume (docs/physics.md section 15): the material row whose volume columns fill
    # the space outside every closed mesh with a medium of its own; -1: none (a vacuum)
    world_volume: int = -1

    # ------------------------------------------------------------------ building
    def add_domains(self, seeds, weight, axis, diameter, triangles=None) -> int:
        """Append one group of opal volume domains (an opal object: seeds (S, 3) m, additive
        weights (S,) m, (111) normals (S, 3), sphere diameters (S,) nm, world space) whose cells
        the ``triangles`` lie in (a slice, index array or (T,) mask of the triangles added so
        far; None: all). Returns the group's index. Call it after the object's ``add_mesh``."""
        s = np.asarray(seeds, np.float64).reshape(-1, 3)
        g = int(np.max(self.domain_group)) + 1 if len(self.domain_group) else 0
        self.domain_seeds = np.concatenate([np.asarray(self.domain_seeds, np.float64).reshape(-1, 3), s])
        self.domain_weight = np.concatenate([np.asarray(self.domain_weight, np.float64).reshape(-1),
                                             np.broadcast_to(np.asarray(weight, np.float64), (len(s),))])
        self.domain_axis = np.concatenate([np.asarray(self.domain_axis, np.float32).reshape(-1, 3),
                                           np.asarray(axis, np.float32).reshape(-1, 3)])
        self.domain_diameter = np.concatenate([np.asarray(self.domain_diameter, np.float32).reshape(-1),
                                               np.broadcast_to(np.asarray(diameter, np.float32), (len(s),))])
        self.domain_group = np.concatenate([np.asarray(self.domain_group, np.int32).reshape(-1),
                                            np.full(len(s), g, np.int32)])
        n = len(self.triangles)
        tg = np.asarray(self.tri_domain_group, np.int32).reshape(-1)
        tg = np.concatenate([tg, np.full(n - len(tg), -1, np.int32)]) if len(tg) < n else tg.copy()
        tg[slice(None) if triangles is None else triangles] = g
        self.tri_domain_group = tg
        return g

    def volume_domains(self):
        """The scene's opal volume domains as a core.opal.volume.VolumeDomains, or None."""
        if not len(self.domain_seeds):
            return None
        return VolumeDomains(np.asarray(self.domain_seeds, np.float64), np.asarray(self.domain_weight, np.float64),
                             np.asarray(self.domain_axis, np.float32), np.asarray(self.domain_diameter, np.float32),
                             np.asarray(self.domain_group, np.int32), np.asarray(self.tri_domain_group, np.int32))

    def add_mesh(self, vertices, triangles, material: int, tangent=None, period=None, normals=None, uvs=None,
                 uv_tangents: bool = False) -> None:
        """Append a mesh (its own vertex numbering) with one material for all its triangles.

        ``tangent``: a grating direction (3,) for all its triangles or (T, 3) per triangle;
        ``period``: a period override in nm, scalar or (T,); ``normals``: shading normals, (V, 3)
        per vertex or (T, 3, 3) per corner (None: flat; see ``corner_normals``).
        ``uvs``: texture coordinates, (V, 2) per vertex or (T, 3, 2) per triangle corner (meshes
        without get (0, 0) once any mesh has UVs); ``uv_tangents``: also store per-corner tangent
        frames from those UVs (``util.geometry.uv_tangents``) for normal maps.
        """
        with np.errstate(over="ignore"):  # beyond float32: inf, which validation names (no warning here)
            v = np.asarray(vertices, np.float32).reshape(-1, 3)
        t = np.asarray(triangles, np.int64).reshape(-1, 3) + len(self.vertices)
        n_old = len(self.triangles)
        self.vertices = np.concatenate([self.vertices, v])
        self.triangles = np.concatenate([self.triangles, t.astype(np.int32)])
        self.tri_material = np.concatenate(
            [self.tri_material, np.full(len(t), material, np.int32)]
        )
        if tangent is not None or len(self.tri_tangent):
            old = self.tri_tangent if len(self.tri_tangent) else np.zeros((n_old, 3), np.float32)
            new = np.zeros((len(t), 3), np.float32) if tangent is None else np.broadcast_to(
                np.asarray(tangent, np.float32), (len(t), 3))
            self.tri_tangent = np.concatenate([old, new])
        if period is not None or len(self.tri_period):
            old = self.tri_period if len(self.tri_period) else np.zeros(n_old, np.float32)
            new = np.zeros(len(t), np.float32) if period is None else np.broadcast_to(
                np.asarray(period, np.float32), (len(t),))
            self.tri_period = np.concatenate([old, new])
        self._add_corner_normals(v, t - (len(self.vertices) - len(v)), n_old, normals)
        self._add_corner_data(v, t - (len(self.vertices) - len(v)), n_old, uvs, uv_tangents)

    def _add_corner_normals(self, v, t_local, n_old: int, normals) -> None:
        """Append the new mesh's corner normals; once any mesh has them, the flat ones (before or
        after) get their face normal at all three corners."""
        if normals is None and not len(self.corner_normals):
            return
        if normals is None:
            new = np.repeat(triangle_normals(v, t_local)[:, None, :], 3, axis=1)
        else:
            nrm = np.asarray(normals, np.float32)
            if nrm.shape == (len(v), 3):
                new = nrm[t_local]
            elif nrm.shape == (len(t_local), 3, 3):
                new = nrm
            else:
                raise SceneError(f"mesh normals must have shape ({len(v)}, 3) per vertex or ({len(t_local)}, 3, 3) "
                                 f"per corner, got {nrm.shape}")
        old = self.corner_normals
        if not len(old) and n_old:
            prev = np.asarray(self.triangles[:n_old], np.int64)
            old = np.repeat(triangle_normals(self.vertices, prev)[:, None, :], 3, axis=1)
        self.corner_normals = np.concatenate([np.asarray(old, np.float32).reshape(-1, 3, 3),
                                              np.asarray(new, np.float32)])

    def _add_corner_data(self, v, t_local, n_old: int, uvs, uv_tangents: bool) -> None:
        """add_mesh's UVs and tangents, kept one row per triangle across meshes."""
        n_new = len(t_local)
        corner = None
        if uvs is not None:
            a = np.asarray(uvs, np.float32)
            corner = a[t_local] if a.ndim == 2 and a.shape == (len(v), 2) else a.reshape(n_new, 3, 2)
        if corner is not None or len(self.corner_uvs):
            old = self.corner_uvs if len(self.corner_uvs) else np.zeros((n_old, 3, 2), np.float32)
            new = np.zeros((n_new, 3, 2), np.float32) if corner is None else corner
            self.corner_uvs = np.concatenate([np.asarray(old, np.float32).reshape(-1, 3, 2), new])
        if (uv_tangents and corner is not None) or len(self.corner_tangents):
            old = self.corner_tangents if len(self.corner_tangents) else np.zeros((n_old, 3, 4), np.float32)
            new = uv_tangent_frames(v, t_local, corner) if (uv_tangents and corner is not None) else np.zeros((n_new, 3, 4),
                                                                                                   np.float32)
            self.corner_tangents = np.concatenate([np.asarray(old, np.float32).reshape(-1, 3, 4), new])

    def add_texture(self, pixels, interpolation: str = "LINEAR", extension: str = "REPEAT",
                    encoding: str = "LINEAR") -> int:
        """Append an image texture (H, W, 4) (or (H, W, 3): alpha 1), row 0 at the bottom, with its
        settings by name; returns its index for the material columns (``color_texture``, ...)."""
        px = np.asarray(pixels, np.float32)
        if px.ndim == 3 and px.shape[2] == 3:
            px = np.concatenate([px, np.ones(px.shape[:2] + (1,), np.float32)], axis=2)
        k = len(self.textures)
        cols = {}
        for name, value, table in (("interpolation", interpolation, TEXTURE_INTERPOLATIONS),
                                   ("extension", extension, TEXTURE_EXTENSIONS),
                                   ("encoding", encoding, TEXTURE_ENCODINGS)):
            if not isinstance(value, str) or value not in table:
                raise SceneError(f"texture {k}: unknown {name} {value!r}; expected one of {sorted(table)}")
            old = np.asarray(getattr(self, "texture_" + name), np.int32).reshape(-1)
            if len(old) != k:  # empty: the defaults so far
                old = np.full(k, {"interpolation": TEXTURE_INTERPOLATIONS["LINEAR"],
                                  "extension": TEXTURE_EXTENSIONS["REPEAT"],
                                  "encoding": TEXTURE_ENCODINGS["LINEAR"]}[name], np.int32)
            cols[name] = np.concatenate([old, [table[value]]]).astype(np.int32)
        self.textures = list(self.textures) + [px]
        for name, col in cols.items():
            setattr(self, "texture_" + name, col)
        return k
