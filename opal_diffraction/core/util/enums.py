"""Every enumeration stored in a scene file (.npz) or a .blend file, with its stable integer code.

These codes are a contract: saved scenes and saved .blend files hold the numbers, so a member's
value never changes and new members take new values (the rule Blender's EnumProperty items
follow). The core's tables (``scene.MATERIAL_KINDS`` ...) and the add-on's EnumProperty items are
built from these classes, so a code is written in one place only.
"""

from __future__ import annotations

from enum import IntEnum

__all__ = [
    "MaterialKind",
    "ConductorFresnel",
    "GlassTint",
    "LayerFac",
    "LightKind",
    "DispersionModel",
    "GratingType",
    "Lattice",
    "GratingDirection",
    "DomainOrientation",
    "DispersionSampling",
    "Backend",
    "TextureInterpolation",
    "TextureExtension",
    "TextureEncoding",
    "codes",
]


class MaterialKind(IntEnum):
    DIFFUSE = 0
    MIRROR = 1
    DIELECTRIC = 2


class ConductorFresnel(IntEnum):
    """A metal's Fresnel: CONSTANT (the colour at every angle: Glossy BSDF, and every mirror
    before the column existed) or F82_TINT (Principled / Metallic BSDF: Schlick with an edge tint)."""

    CONSTANT = 0
    F82_TINT = 1


class LayerFac(IntEnum):
    """Where the weights of a two-layer shader mix come from per hit (docs/physics.md section
    14.8): CONSTANT (the material's metallic / transmission), FRESNEL (Blender's Fresnel node of
    IOR layer_fac_value), LAYER_FRESNEL / LAYER_FACING (the Layer Weight node's outputs of Blend
    layer_fac_value), each a function of the view direction and the shading normal; PROGRAM (the
    material's shader program's 'mix' output per hit: a texture or converter chain on the Fac)."""

    CONSTANT = 0
    FRESNEL = 1
    LAYER_FRESNEL = 2
    LAYER_FACING = 3
    PROGRAM = 4


class GlassTint(IntEnum):
    """What a glass's colour is the colour of (docs/physics.md section 2.7): REFRACTION (one
    refraction's: the Glass / Refraction BSDF, and every glass before the column existed) or
    PASS (one pass through a closed object, two refractions: Principled's Base Color)."""

    REFRACTION = 0
    PASS = 1


class LightKind(IntEnum):
    POINT = 0
    SPOT = 1
    SUN = 2
    AREA_RECT = 3
    AREA_DISK = 4


class DispersionModel(IntEnum):
    NONE = 0
    ABBE = 1
    BK7 = 2
    FUSED_SILICA = 3
    DIAMOND = 4


class GratingType(IntEnum):
    REFLECTION = 0
    TRANSMISSION = 1


class Lattice(IntEnum):
    LINES = 0
    HEXAGONAL = 1
    BRAGG = 2  # FCC opal: Bragg reflection from 3-D (111) domains (docs/physics.md section 5.2)


class GratingDirection(IntEnum):
    UV = 0
    OBJECT_X = 1
    ATTRIBUTE = 2


class DomainOrientation(IntEnum):
    """How opal volume domains' (111) normals are drawn (core/opal/volume.py); stored in .blend
    files only (``material.opal.domain_orientation``), the core takes the name."""

    RANDOM = 0
    LAYERED = 1


class DispersionSampling(IntEnum):
    """Stored in .blend files only (``scene.opal.dispersion_sampling``); the core takes the name."""

    SAMPLE = 0
    SPLIT = 1


class Backend(IntEnum):
    """Stored in .blend files only (``scene.opal.backend``); the core takes the lower-case name."""

    AUTO = 0
    EMBREE = 1
    NUMPY = 2


class TextureInterpolation(IntEnum):
    """An image texture's lookup (Blender's Image Texture node; Cycles' kernel/device/cpu/image.h)."""

    CLOSEST = 0
    LINEAR = 1
    CUBIC = 2  # Cycles' uniform cubic B-spline
    SMART = 3  # Cycles renders Smart as Cubic (OSL's own choice aside)


class TextureExtension(IntEnum):
    """What an image texture shows outside [0, 1] (Blender's Image Texture node Extension)."""

    REPEAT = 0
    EXTEND = 1
    CLIP = 2
    MIRROR = 3


class TextureEncoding(IntEnum):
    """How a texture's stored colour channels are encoded: linear Rec.709, or sRGB-encoded Rec.709
    decoded after interpolation, as Cycles keeps 8-bit sRGB images (``compress_as_srgb``)."""

    LINEAR = 0
    SRGB = 1


def codes(enum: type[IntEnum]) -> dict[str, int]:
    """``{name: code}`` of an enumeration, in code order (the scene file's tables)."""
    return {m.name: int(m) for m in enum}
