"""The scene model: flat NumPy arrays, one ``.npz`` file, and validation with readable errors.

A scene holds geometry (vertices, triangles, per-triangle material index), a material table, a
light table and a camera, all in world space (Blender's convention: metres, Z up; the camera
looks down its local -Z axis with +Y up). Colours are linear Rec.709 RGB; they become spectra at
render time, because the wavelength grid is a render setting.

Enumerations are stored as integer codes with fixed values so saved files keep loading when
entries are added (the same rule Blender's EnumProperty items follow).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, fields, replace

import numpy as np

from ..util.geometry import triangle_cross, triangle_normals, uv_tangents as uv_tangent_frames
from ..util.enums import (ConductorFresnel, GlassTint, GratingDirection, GratingType, Lattice, LightKind, MaterialKind, TextureEncoding, TextureExtension, TextureInterpolation, codes)
from ..spectral.optics import DISPERSION_MODELS, ior_spectrum

__all__ = [
    "SceneError",
    "GRATING_TYPES",
    "LATTICES",
    "GRATING_DIRECTIONS",
    "MATERIAL_KINDS",
    "CONDUCTOR_FRESNELS",
    "GLASS_TINTS",
    "LIGHT_KINDS",
    "TEXTURE_INTERPOLATIONS",
    "TEXTURE_EXTENSIONS",
    "TEXTURE_ENCODINGS",
    "Materials",
    "Lights",
    "Camera",
    "Scene",
    "FORMAT_VERSION",
]

FORMAT_VERSION = 1

#: Material kinds and light kinds: name -> stable code (enums.py).
MATERIAL_KINDS = codes(MaterialKind)
CONDUCTOR_FRESNELS = codes(ConductorFresnel)
GLASS_TINTS = codes(GlassTint)
LIGHT_KINDS = codes(LightKind)


#: The clean scene of ``Scene.validated`` carries its (T, 3) float64 triangle cross products
#: (geometry.triangle_cross of its vertices and triangles) under this attribute, so that
#: prepare does not compute them a second time; not a field (never saved, dropped by replace).
TRIANGLE_CROSS_ATTR = "_validated_triangle_cross"
#: ... and their norms (twice the areas), (T,) float64
TRIANGLE_CROSS_NORM_ATTR = "_validated_triangle_cross_norm"


class SceneError(ValueError):
    """A scene that cannot be rendered; the message (always one line) names the problem for the user."""

    def __init__(self, message="", *args):
        super().__init__(" ".join(str(message).split()), *args)


#: Image texture settings: name -> stable code (enums.py).
TEXTURE_INTERPOLATIONS = codes(TextureInterpolation)
TEXTURE_EXTENSIONS = codes(TextureExtension)
TEXTURE_ENCODINGS = codes(TextureEncoding)

#: Grating enumerations: name -> stable code (enums.py).
GRATING_TYPES = codes(GratingType)
LATTICES = codes(Lattice)
GRATING_DIRECTIONS = codes(GratingDirection)

# column name -> (dtype, per-row shape, default, enumeration or None)
_MATERIAL_COLUMNS = {
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
    # rough surfaces and Principled's layers (docs/physics.md section 14)
    "roughness": (np.float32, (), 0.0, None),
    "metallic": (np.float32, (), 0.0, None),
    "transmission": (np.float32, (), 0.0, None),
    "specular_ior_level": (np.float32, (), 0.0, None),
    "specular_tint": (np.float32, (3,), (1.0, 1.0, 1.0), None),
    "conductor_fresnel": (np.int32, (), "CONSTANT", CONDUCTOR_FRESNELS),
    # what a glass's colour is the colour of (docs/physics.md section 2.7)
    "glass_tint": (np.int32, (), "REFRACTION", GLASS_TINTS),
    # the BRAGG (FCC opal) lattice (docs/physics.md section 5.7; core/materials/bragg_bsdf.py)
    "sphere_diameter": (np.float32, (), 250.0, None),
    "sphere_ior": (np.float32, (), 1.45, None),
    "void_ior": (np.float32, (), 1.0, None),
    "layers": (np.int32, (), 40, None),
    "mosaic_spread": (np.float32, (), 3.0, None),
}

#: Valid ranges of the BRAGG lattice's columns (checked on grating rows with lattice BRAGG).
BRAGG_RANGES = {"sphere_diameter": (100.0, 500.0, " nm"), "sphere_ior": (1.0, 3.0, ""), "void_ior": (1.0, 3.0, ""),
                "layers": (1, 10000, ""), "mosaic_spread": (0.0, 45.0, " degrees")}

#: The material columns that name a texture.
TEXTURE_COLUMNS = ("color_texture", "roughness_texture", "metallic_texture", "emission_texture", "normal_texture")

#: Unit-interval material columns (validated to [0, 1]).
_UNIT_COLUMNS = ("roughness", "metallic", "transmission")


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
    dtype, tail, default, enum = _MATERIAL_COLUMNS[name]
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

    Grating layer (docs/physics.md section 3), on top of the base kind: grating (0/1), grating_type
    (GRATING_TYPES), lattice (LATTICES), period D (nm), slit_width a (nm), slit_count N,
    coherence_length L (um, the slits' length), grating_direction (GRATING_DIRECTIONS: how the
    exporter found the per-triangle tangent in ``Scene.tri_tangent``), rotation (radians, about
    the normal). With lattice BRAGG the layer is not a surface grating but FCC opal's volume
    Bragg reflection (docs/physics.md section 5.7): sphere_diameter D_s (nm, 100-500), sphere_ior
    and void_ior (1-3), layers (ordered (111) periods, 1-10000) and mosaic_spread (degrees, 0-45:
    the spread of the plane normals about the domain's axis); the base kind is the body tone.

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
    roughness: np.ndarray = field(default_factory=lambda: _material_column_default("roughness", 0))
    metallic: np.ndarray = field(default_factory=lambda: _material_column_default("metallic", 0))
    transmission: np.ndarray = field(default_factory=lambda: _material_column_default("transmission", 0))
    specular_ior_level: np.ndarray = field(default_factory=lambda: _material_column_default("specular_ior_level", 0))
    specular_tint: np.ndarray = field(default_factory=lambda: _material_column_default("specular_tint", 0))
    conductor_fresnel: np.ndarray = field(default_factory=lambda: _material_column_default("conductor_fresnel", 0))
    glass_tint: np.ndarray = field(default_factory=lambda: _material_column_default("glass_tint", 0))
    sphere_diameter: np.ndarray = field(default_factory=lambda: _material_column_default("sphere_diameter", 0))
    sphere_ior: np.ndarray = field(default_factory=lambda: _material_column_default("sphere_ior", 0))
    void_ior: np.ndarray = field(default_factory=lambda: _material_column_default("void_ior", 0))
    layers: np.ndarray = field(default_factory=lambda: _material_column_default("layers", 0))
    mosaic_spread: np.ndarray = field(default_factory=lambda: _material_column_default("mosaic_spread", 0))

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
        for name, (dtype, tail, default, enum) in _MATERIAL_COLUMNS.items():
            col = _material_column_default(name, len(rows))
            for i, r in enumerate(rows):
                unknown = set(r) - set(_MATERIAL_COLUMNS)
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
               for name in _MATERIAL_COLUMNS}
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
            }
            for name, v in vals.items():
                cols[name].append(v)
        out = cls()
        for f in fields(cls):
            proto = getattr(out, f.name)
            setattr(out, f.name, np.array(cols[f.name], proto.dtype).reshape((-1,) + proto.shape[1:]))
        return out


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
    """A pinhole perspective or orthographic camera with Blender's conventions.

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
    # opal volume domains (core/opal/volume.py; docs/physics.md section 5.4), world space; empty: none
    domain_seeds: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float64))
    domain_weight: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float64))
    domain_axis: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float32))
    domain_diameter: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    domain_group: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    tri_domain_group: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))

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
        from ..opal.volume import VolumeDomains

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
        with np.errstate(over="ignore"):  # beyond float32: inf, which validated() names (no warning here)
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

    # ------------------------------------------------------------------ validation
    def validated(self) -> tuple["Scene", list[str]]:
        """Return (a clean copy, warnings); raise SceneError naming what makes it unrenderable.

        Every table column is checked for its dtype (numbers, or integers for indices and
        codes: strings, complex numbers, booleans and objects are errors), its shape (row count
        and per-row shape), finite values, float32 range (the tracer computes in float32) and
        the rules of its quantity; the message names the column, the row and the rule. Dropped
        with a warning: zero-area triangles and triangles too small for float32 ray casting.
        Warned: nothing to render, no light.
        """
        try:
            return self._validated()
        except SceneError:
            raise
        except MemoryError:
            raise SceneError("the scene is too large to validate in this machine's memory") from None
        except Exception as e:  # a gap in the checks: still one readable line, never a traceback
            raise SceneError(f"the scene cannot be validated ({type(e).__name__}: {_one_line(e)})") from None

    def _validated(self) -> tuple["Scene", list[str]]:
        warns: list[str] = []
        if self.camera is None:
            raise SceneError("the scene has no camera: add one and make it the active camera")
        if not isinstance(self.camera, Camera):
            raise SceneError(f"the scene's camera must be a Camera, got {type(self.camera).__name__}")
        camera = _validate_camera(self.camera)
        v = _column(self.vertices, "vertices", (3,), allow_empty=True)
        t = _column(self.triangles, "triangles", (3,), kind="int", allow_empty=True)
        if not _within(v, COORD_LIMIT):  # the full checks only when something is wrong
            v64 = v.astype(np.float64, copy=False)
            bad = ~np.isfinite(v64).all(axis=1)
            if bad.any():
                raise SceneError(
                    f"{int(bad.sum())} vertex coordinate(s) are NaN or infinite (first: vertex {int(np.argmax(bad))})"
                )
            _check_range(v64, lambda i: f"vertex {i}", "coordinate", " m", limit=COORD_LIMIT)
        v = v if v.dtype == np.float32 else v.astype(np.float32)
        if len(t):
            if t.min() < 0 or t.max() >= len(v):
                i = int(np.argmax((t < 0).any(1) | (t >= len(v)).any(1)))
                raise SceneError(
                    f"triangle {i} uses vertex index {t[i].tolist()} but the scene has {len(v)} vertices"
                )
        tm = _column(self.tri_material, "tri_material", (), kind="int", allow_empty=len(t) == 0)
        if tm.shape != (len(t),):
            raise SceneError(f"tri_material must have one entry per triangle ({len(t)}), got shape {tm.shape}")
        if not isinstance(self.materials, Materials):
            raise SceneError(f"the scene's materials must be a Materials table, got {type(self.materials).__name__}")
        if not isinstance(self.lights, Lights):
            raise SceneError(f"the scene's lights must be a Lights table, got {type(self.lights).__name__}")
        materials = _validate_materials(self.materials)
        nm = len(materials)
        if len(tm) and (tm.min() < 0 or tm.max() >= nm):
            i = int(np.argmax((tm < 0) | (tm >= nm)))
            raise SceneError(f"triangle {i} uses material {int(tm[i])} but the scene has {nm} materials")
        lights = _validate_lights(self.lights)
        wc = _column(self.world_color, "world colour", (), rows=3)
        _check_range(wc[None, :], lambda i: "world colour", "value", "", limit=EMISSION_LIMIT, finite_text="world colour is NaN or infinite")
        world_image, world_rotation = _validate_world_image(self.world_image, self.world_rotation, wc)

        tt = _column(self.tri_tangent, "tri_tangent", (3,), allow_empty=True)
        tp = _column(self.tri_period, "tri_period", (), allow_empty=True)
        if len(tt) not in (0, len(t)) or len(tp) not in (0, len(t)):
            raise SceneError(f"tri_tangent / tri_period must have one entry per triangle ({len(t)}) or none")
        if not np.isfinite(tt).all() or not np.isfinite(tp).all() or (tp < 0).any():
            raise SceneError("a per-triangle grating direction or period is NaN, infinite or negative")
        _check_range(tt, lambda i: f"triangle {i}", "grating direction", "")
        _check_range(tp, lambda i: f"triangle {i}", "grating period", " nm", limit=PERIOD_MAX)
        tt = tt if tt.dtype == np.float32 else tt.astype(np.float32)
        tp = tp if tp.dtype == np.float32 else tp.astype(np.float32)
        tex = _validate_textures(self, len(t), materials, tm, warns)
        dom = _validate_domains(self, len(t))
        t = t.astype(np.int32)
        cn = _validate_corner_normals(self.corner_normals, v, t, warns)
        cross = None
        if len(t):
            cross, area2 = triangle_cross(v, t, with_norm=True)  # area2: np.linalg.norm(cross, axis=1)
            degenerate = area2 <= 0.0
            tiny = ~degenerate & (area2 < 2 * MIN_TRIANGLE_AREA)
            if degenerate.any():
                warns.append(f"dropped {int(degenerate.sum())} degenerate (zero-area) triangle(s)")
            if tiny.any():
                warns.append(f"dropped {int(tiny.sum())} triangle(s) too small for float32 ray casting "
                             f"(area below {MIN_TRIANGLE_AREA:g} m^2)")
            if degenerate.any() or tiny.any():
                keep = ~(degenerate | tiny)
                t, tm, cross, area2 = t[keep], tm[keep], cross[keep], area2[keep]
                tt = tt[keep] if len(tt) else tt
                tp = tp[keep] if len(tp) else tp
                cn = cn[keep] if len(cn) else cn
                dom["tri_domain_group"] = dom["tri_domain_group"][keep] if len(dom["tri_domain_group"]) else \
                    dom["tri_domain_group"]
                for name in ("corner_uvs", "corner_tangents"):  # per-corner data stays one row per triangle
                    tex[name] = tex[name][keep] if len(tex[name]) else tex[name]
        if len(t) == 0:
            warns.append("the scene has no geometry: the image shows only the background")
        # a coloured or mapped world lights the scene, and so does a mesh whose material emits
        emitting = len(t) > 0 and bool(np.any(np.asarray(materials.emission)[np.bincount(tm, minlength=nm) > 0] > 0))
        world_lit = bool(np.any(np.asarray(wc) > 0)) and (world_image.size == 0 or bool(np.any(world_image > 0)))
        if len(lights) == 0 and not world_lit and not emitting:
            warns.append("the scene has no lights: only the background is lit")
        clean = replace(self, vertices=v, triangles=t, tri_material=tm.astype(np.int32), tri_tangent=tt, tri_period=tp,
                        materials=materials, lights=lights, camera=camera, world_color=wc, corner_normals=cn,
                        world_image=world_image, world_rotation=world_rotation, **tex, **dom)
        if cross is not None:  # prepare's normals are these products normalised (it pops them)
            clean.__dict__[TRIANGLE_CROSS_ATTR] = cross
            clean.__dict__[TRIANGLE_CROSS_NORM_ATTR] = area2
        return clean, warns

    # ------------------------------------------------------------------ .npz
    def save(self, path) -> None:
        """Write the scene to one ``.npz`` file (no pickles)."""
        d: dict[str, np.ndarray] = {
            "format_version": np.array(FORMAT_VERSION),
            "vertices": np.asarray(self.vertices, np.float32),
            "triangles": np.asarray(self.triangles, np.int32),
            "tri_material": np.asarray(self.tri_material, np.int32),
            "world_color": np.asarray(self.world_color, np.float32),
            "tri_tangent": np.asarray(self.tri_tangent, np.float32).reshape(-1, 3),
            "tri_period": np.asarray(self.tri_period, np.float32).reshape(-1),
            "corner_normals": np.asarray(self.corner_normals, np.float32).reshape(-1, 3, 3),
            "world_image": np.asarray(self.world_image, np.float32),
            "world_rotation": np.asarray(self.world_rotation, np.float64),
        }
        if len(self.domain_seeds):
            for name in _DOMAIN_FIELDS:
                d[name] = np.asarray(getattr(self, name))
        if len(self.corner_uvs):
            d["corner_uvs"] = np.asarray(self.corner_uvs, np.float32)
        if len(self.corner_tangents):
            d["corner_tangents"] = np.asarray(self.corner_tangents, np.float32)
        if len(self.textures):
            d["texture_count"] = np.array(len(self.textures))
            for i, px in enumerate(self.textures):
                d[f"texture_{i}"] = np.asarray(px, np.float32)
            for name in ("interpolation", "extension", "encoding"):
                d["texture_" + name] = np.asarray(getattr(self, "texture_" + name), np.int32)
        for f in fields(Materials):
            d["material_" + f.name] = getattr(self.materials, f.name)
        for f in fields(Lights):
            d["light_" + f.name] = getattr(self.lights, f.name)
        if self.camera is not None:
            for f in fields(Camera):
                d["camera_" + f.name] = np.asarray(getattr(self.camera, f.name))
        np.savez_compressed(path, **d)

    @classmethod
    def load(cls, path) -> "Scene":
        """Read a scene written by :meth:`save`; a clear one-line SceneError if it is not one
        (missing, a directory, empty, not a .npz archive, a corrupted or missing member).
        The arrays are checked by :meth:`validated` (every render does that)."""
        shown = os.fspath(path) if isinstance(path, (str, bytes, os.PathLike)) else path
        if isinstance(shown, (str, bytes)):
            if not os.path.exists(shown):
                raise SceneError(f"scene file not found: {shown}")
            if os.path.isdir(shown):
                raise SceneError(f"{shown} is a directory, not a scene file")
            if os.path.getsize(shown) == 0:
                raise SceneError(f"{shown} is empty, not a scene file")
        try:
            z = np.load(path, allow_pickle=False)
        except FileNotFoundError:
            raise SceneError(f"scene file not found: {shown}") from None
        except Exception as e:  # not a zip, truncated, a pickle, unreadable, ...
            raise SceneError(f"cannot read scene file {shown}: {_one_line(e)}") from None
        if not isinstance(z, np.lib.npyio.NpzFile):
            raise SceneError(f"{shown} is a single array (.npy), not a scene archive (.npz)")
        with z:
            def read(name):
                try:
                    return z[name]
                except KeyError:
                    raise SceneError(f"{shown} has no {name!r} array: not a complete scene file") from None
                except Exception as e:  # zipfile.BadZipFile, zlib.error, EOFError, ValueError, MemoryError, ...
                    raise SceneError(f"{shown}: array {name!r} is corrupted or unreadable ({_one_line(e)})") from None

            try:
                names = set(z.files)
            except Exception as e:
                raise SceneError(f"cannot read scene file {shown}: {_one_line(e)}") from None
            if "format_version" not in names:
                raise SceneError(f"{shown} is not an opal_diffraction scene (no format_version)")
            fv = read("format_version")
            if fv.shape != () or fv.dtype.kind not in "iu":
                raise SceneError(f"{shown}: format_version must be one integer, got {fv.dtype} of shape {fv.shape}")
            ver = int(fv)
            if ver > FORMAT_VERSION:
                raise SceneError(f"{shown} was written by a newer version (format {ver} > {FORMAT_VERSION})")
            cols = {f.name: read("material_" + f.name) for f in fields(Materials) if "material_" + f.name in names}
            kind = cols.get("kind")
            rows = kind.shape[0] if kind is not None and kind.ndim >= 1 else 0
            mats = Materials.from_columns(cols, rows)
            lights = Lights(**{f.name: read("light_" + f.name) for f in fields(Lights) if "light_" + f.name in names})
            for name in _LIGHT_OPTIONAL:  # columns an older file lacks: 0 (delta lights, as they rendered)
                if "light_" + name not in names:
                    setattr(lights, name, np.zeros(_rows(lights.kind), _LIGHT_COLUMNS[name][1]))
            cam = None
            if "camera_matrix" in names:
                kw = {}
                for f in fields(Camera):
                    if "camera_" + f.name in names:
                        val = read("camera_" + f.name)
                        kw[f.name] = val.item() if val.ndim == 0 else val
                cam = Camera(**kw)
            return cls(
                vertices=read("vertices"),
                triangles=read("triangles"),
                tri_material=read("tri_material"),
                materials=mats,
                lights=lights,
                camera=cam,
                world_color=read("world_color"),
                tri_tangent=read("tri_tangent") if "tri_tangent" in names else np.zeros((0, 3), np.float32),
                tri_period=read("tri_period") if "tri_period" in names else np.zeros(0, np.float32),
                # older files have no shading normals: flat shading
                corner_normals=read("corner_normals") if "corner_normals" in names else np.zeros((0, 3, 3), np.float32),
                # older files have no world map: a uniform world
                world_image=read("world_image") if "world_image" in names else np.zeros((0, 0, 3), np.float32),
                world_rotation=read("world_rotation") if "world_rotation" in names else np.eye(3),
                **_read_textures(read, names, shown),
                **{name: read(name) for name in _DOMAIN_FIELDS if name in names},
            )


def _check_bragg(f64: dict, layers, label) -> None:
    """The BRAGG lattice's columns (docs/physics.md section 5.2): D_s > 0 nm, indices >= 1,
    at least one layer, a mosaic spread of 0-90 degrees."""
    for name, ok, rule in (("sphere_diameter", lambda x: (x > 0) & (x <= PERIOD_MAX), "must be > 0 nm"),
                           ("sphere_ior", lambda x: x >= 1.0, "must be at least 1"),
                           ("void_ior", lambda x: x >= 1.0, "must be at least 1"),
                           ("mosaic_spread", lambda x: (x >= 0.0) & (x <= 90.0), "must be 0-90 degrees")):
        bad = ~ok(f64[name])
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"{label(i)}: {name.replace('_', ' ')} {_g(f64[name][i])} {rule}")
    lay = np.asarray(layers, np.int64)
    if (lay < 1).any():
        i = int(np.argmax(lay < 1))
        raise SceneError(f"{label(i)}: layers must be at least 1, got {int(lay[i])}")


#: The opal volume domain columns (Scene.add_domains), saved only when there are domains.
_DOMAIN_FIELDS = ("domain_seeds", "domain_weight", "domain_axis", "domain_diameter", "domain_group",
                  "tri_domain_group")


def _validate_domains(sc, n_tri: int) -> dict:
    """The domain columns checked (shapes, finite, unit axes, positive diameters, groups in range)."""
    s = _column(sc.domain_seeds, "domain_seeds", (3,), allow_empty=True).astype(np.float64)
    k = len(s)
    w = _column(sc.domain_weight, "domain_weight", (), rows=k, allow_empty=k == 0).astype(np.float64)
    a = _column(sc.domain_axis, "domain_axis", (3,), rows=k, allow_empty=k == 0).astype(np.float64)
    d = _column(sc.domain_diameter, "domain_diameter", (), rows=k, allow_empty=k == 0).astype(np.float64)
    g = _column(sc.domain_group, "domain_group", (), rows=k, kind="int", allow_empty=k == 0).astype(np.int32)
    tg = _column(sc.tri_domain_group, "tri_domain_group", (), kind="int", allow_empty=True).astype(np.int32)
    if not np.isfinite(s).all() or not np.isfinite(w).all():
        raise SceneError("an opal domain seed or weight is NaN or infinite")
    _check_range(s, lambda i: f"opal domain {i}", "seed", " m", limit=COORD_LIMIT)
    length = np.linalg.norm(a, axis=1)
    bad = ~(np.isfinite(length) & (length > 1e-12))
    if bad.any():
        raise SceneError(f"opal domain {int(np.argmax(bad))}: its (111) axis is zero, NaN or infinite")
    bad = ~(np.isfinite(d) & (d > 0) & (d < PERIOD_MAX))
    if bad.any():
        raise SceneError(f"opal domain {int(np.argmax(bad))}: sphere diameter {d[bad][0]:g} nm must be > 0")
    n_groups = int(g.max()) + 1 if k else 0
    if k and g.min() < 0:
        raise SceneError("opal domain groups must be >= 0")
    if k and len(tg) < n_tri:  # triangles added after the last add_domains have none
        tg = np.concatenate([tg, np.full(n_tri - len(tg), -1, np.int32)])
    if len(tg) not in (0, n_tri) or (len(tg) and (tg.min() < -1 or tg.max() >= n_groups)):
        raise SceneError(f"tri_domain_group must have one entry per triangle ({n_tri}), each -1 or one of the "
                         f"{n_groups} domain groups")
    return {"domain_seeds": s, "domain_weight": w, "domain_axis": (a / np.where(bad, 1.0, length)[:, None]).astype(
        np.float32), "domain_diameter": d.astype(np.float32), "domain_group": g, "tri_domain_group": tg}


# ---------------------------------------------------------------------------------- validation
# The limits of what the tracer can compute (it traces and accumulates in float32).

#: Largest finite float32 (3.4e38): any value above it becomes inf when the tracer reads it.
FLOAT32_MAX = float(np.finfo(np.float32).max)
#: Positions (vertices, lights, the camera) and lengths stay within this many metres: float32
#: ray-triangle tests multiply three coordinates (differences to the ray origin), which
#: overflows beyond ~1e12 m.
COORD_LIMIT = 1e12
#: Emitted quantities (a light's intensity W/sr, irradiance W/m^2 or radiance W/m^2/sr, an
#: emission or world colour) stay below this, leaving float32 room for spectra, distances and sums.
EMISSION_LIMIT = 1e25
#: Triangles below this area (m^2) cannot be intersected in float32 (their edge products
#: underflow); they are dropped with a warning.
MIN_TRIANGLE_AREA = 1e-30
#: Image size: each side, and the pixel count (checked before anything is allocated).
MAX_SIDE = 65536
MAX_PIXELS = 1 << 28
#: Blackbody temperatures (K); 0 means "no temperature: use the colour". Below 100 K Planck's
#: law underflows on parts of the 360-830 nm observer range.
TEMPERATURE_MIN, TEMPERATURE_MAX = 100.0, 1e9
#: Refractive indices, grating lengths and counts the tracer handles without overflow.
IOR_MAX = 1000.0
PERIOD_MAX = 1e7            # nm (1 cm)
COHERENCE_MAX = 1e6         # um (1 m)
SLIT_COUNT_MAX = 10_000_000
#: Camera: the tangent of the half field of view (persp) at most this, shifts at most this.
FOV_TAN_MAX = 1e6
SHIFT_MAX = 1000.0

_OBSERVER_NM = (360.0, 830.0)  # the wavelengths any grid may hold (spectrum.py)


def _g(x) -> str:
    """A number for a message: 3 significant digits."""
    try:
        return f"{float(x):.3g}"
    except (TypeError, ValueError, OverflowError):
        return repr(x)


def _one_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return text[0][:200] if text else type(e).__name__


_DTYPE_WORDS = {"U": "strings", "S": "bytes", "c": "complex numbers", "b": "booleans", "O": "Python objects",
                "M": "dates", "m": "time spans", "V": "raw records"}


def _column(value, what: str, tail: tuple = (), rows: int | None = None, kind: str = "float",
            allow_empty: bool = False) -> np.ndarray:
    """``value`` as an array of numbers of shape (rows,) + tail (rows None: any count), or a
    SceneError naming ``what``, the dtype or the shape. kind: 'float' (integers and floats),
    'int' (integers only), 'flag' (integers or booleans). ``allow_empty``: any empty array
    stands for zero rows."""
    try:
        a = np.asarray(value)
    except Exception:  # ragged nested lists, objects numpy cannot hold
        raise SceneError(f"{what} is not a regular array of numbers") from None
    k = a.dtype.kind
    if k not in "iuf" and not (kind == "flag" and k == "b"):
        words = _DTYPE_WORDS.get(k, str(a.dtype))
        want = "numbers" if kind == "float" else "integers"
        raise SceneError(f"{what} must hold {want}, got {words} ({a.dtype})")
    if kind != "float" and k == "f":
        raise SceneError(f"{what} must hold integers, got {a.dtype}")
    ok = a.ndim == 1 + len(tail) and a.shape[1:] == tuple(tail) and (rows is None or a.shape[0] == rows)
    if not ok:
        if allow_empty and a.size == 0 and rows in (None, 0):
            return a.reshape((0,) + tuple(tail))
        want = "(" + ", ".join([str(rows) if rows is not None else "N"] + [str(x) for x in tail]) + \
               ("," if not tail else "") + ")"
        raise SceneError(f"{what} must have shape {want}, got {a.shape}")
    if kind != "float" and a.size and k in "iu":
        lo, hi = int(a.min()), int(a.max())
        if lo < -(2**31) or hi >= 2**31:
            raise SceneError(f"{what} holds {hi if hi >= 2**31 else lo}, outside the 32-bit integer range")
    return a


def _first_row(mask: np.ndarray) -> int:
    m = mask.reshape(len(mask), -1).any(axis=1) if mask.ndim > 1 else mask
    return int(np.argmax(m))


def _within(a, limit: float | None = None, nonneg: bool = False) -> bool:
    """True when every value of ``a`` (any real dtype) is finite, within float32 and ``limit``
    (and >= 0 with ``nonneg``): two reductions and no float64 copy (a NaN propagates through
    min and max). False: the caller's full check finds and names the first bad row."""
    a = np.asarray(a)
    if a.size == 0:
        return True
    lo, hi = float(np.min(a)), float(np.max(a))
    mag = max(-lo, hi)
    return bool(np.isfinite(lo) and np.isfinite(hi) and mag <= FLOAT32_MAX and (limit is None or mag <= limit)
                and (not nonneg or lo >= 0))


def _check_range(a64: np.ndarray, label, name: str, unit: str, limit: float | None = None,
                 finite_text: str | None = None, nonneg: bool = False) -> None:
    """Finite, within float32, |x| <= limit (and >= 0 with ``nonneg``), per row; ``label(i)``
    names row i ("light 2"). Empty arrays pass."""
    if a64.size == 0 or _within(a64, limit, nonneg):
        return
    a64 = np.asarray(a64, np.float64)
    bad = ~np.isfinite(a64)
    if bad.any():
        i = _first_row(bad)
        if finite_text:
            raise SceneError(finite_text)
        raise SceneError(f"{label(i)}: {name} is NaN or infinite")
    mag = np.abs(a64)
    over = mag > FLOAT32_MAX
    if over.any():
        i = _first_row(over)
        raise SceneError(f"{label(i)}: {name} {_g(np.max(mag.reshape(len(mag), -1)[i]))}{unit} overflows float32 "
                         f"(max 3.4e38)")
    if limit is not None:
        big = mag > limit
        if big.any():
            i = _first_row(big)
            raise SceneError(f"{label(i)}: {name} {_g(np.max(mag.reshape(len(mag), -1)[i]))}{unit} is beyond "
                             f"the renderable limit {limit:g}{unit}")
    if nonneg and (a64 < 0).any():
        i = _first_row(a64 < 0)
        raise SceneError(f"{label(i)}: {name} must be >= 0, got {_g(np.min(a64.reshape(len(a64), -1)[i]))}{unit}")


def _number(value, what: str, integer: bool = False):
    """A scalar setting as a Python int/float, or a SceneError (strings, complex, bool, arrays)."""
    if isinstance(value, (bool, np.bool_)) or isinstance(value, (str, bytes, complex, np.complexfloating)):
        raise SceneError(f"{what} must be a number, got {value!r}")
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()
        if isinstance(value, (bool, str, bytes, complex)):
            raise SceneError(f"{what} must be a number, got {value!r}")
    if not isinstance(value, (int, float, np.integer, np.floating)):
        raise SceneError(f"{what} must be a number, got {type(value).__name__}")
    if integer:
        if isinstance(value, (int, np.integer)):
            return int(value)
        f = float(value)
        if not np.isfinite(f) or f != int(f):
            raise SceneError(f"{what} must be a whole number, got {_g(f)}")
        return int(f)
    f = float(value)
    if not np.isfinite(f):
        raise SceneError(f"{what} must be a finite number, got {f}")
    return f


def _validate_world_image(image, rotation, world_color) -> tuple[np.ndarray, np.ndarray]:
    """The world map (H, W, 3) float32 (empty: (0, 0, 3)) and its rotation (3, 3) float64, or a
    SceneError: finite, non-negative, within the image size limits, its product with the world
    colour within EMISSION_LIMIT, the rotation orthogonal."""
    try:
        img = np.asarray(image)
    except Exception:
        raise SceneError("world image is not a regular array of numbers") from None
    if img.dtype.kind not in "iuf":
        raise SceneError(f"world image must hold numbers, got {_DTYPE_WORDS.get(img.dtype.kind, img.dtype)}")
    if img.size == 0:
        img = np.zeros((0, 0, 3), np.float32)
    else:
        if img.ndim != 3 or img.shape[2] != 3:
            raise SceneError(f"world image must have shape (H, W, 3), got {img.shape}")
        h, w = img.shape[:2]
        if h > MAX_SIDE or w > MAX_SIDE:
            raise SceneError(f"world image {w}x{h}: each side must be at most {MAX_SIDE} pixels")
        if h * w > MAX_PIXELS:
            raise SceneError(f"world image {w}x{h} is {w * h / 1e6:.0f} M pixels, more than the "
                             f"{MAX_PIXELS / 1e6:.0f} M allowed")
        if img.dtype != np.float32:
            with np.errstate(over="ignore", invalid="ignore"):
                if not np.isfinite(img.astype(np.float64)).all() or np.abs(img.astype(np.float64)).max() > FLOAT32_MAX:
                    raise SceneError("world image holds NaN, infinite or float32-overflowing values")
            img = img.astype(np.float32)
        if not np.isfinite(img).all():
            raise SceneError("world image holds NaN or infinite values")
        if (img < 0).any():
            raise SceneError(f"world image holds negative radiance (min {_g(img.min())})")
        peak = float(img.max()) * float(np.max(world_color))
        if peak > EMISSION_LIMIT:
            raise SceneError(f"world image times the world colour reaches {_g(peak)}, beyond the renderable "
                             f"limit {EMISSION_LIMIT:g}")
        img = np.ascontiguousarray(img)
    try:
        rot = np.asarray(rotation)
    except Exception:
        raise SceneError("world rotation must be a 3x3 rotation matrix") from None
    if rot.dtype.kind not in "iuf" or rot.shape != (3, 3):
        raise SceneError(f"world rotation must be a 3x3 matrix of numbers, got {rot.dtype} of shape {rot.shape}")
    rot = rot.astype(np.float64)
    if not np.isfinite(rot).all():
        raise SceneError("world rotation is NaN or infinite")
    err = float(np.abs(rot @ rot.T - np.eye(3)).max())
    if err > 1e-4:
        raise SceneError(f"world rotation is not orthonormal (|R R^T - I| = {_g(err)}): a rotation, "
                         "optionally with a mirror, is expected")
    return img, rot


def _validate_camera(c: Camera) -> Camera:
    try:
        m = np.asarray(c.matrix)
    except Exception:
        raise SceneError("camera matrix must be a finite 4x4 matrix") from None
    if m.dtype.kind not in "iuf":
        raise SceneError(f"camera matrix must hold numbers, got {_DTYPE_WORDS.get(m.dtype.kind, m.dtype)}")
    m = m.astype(np.float64)
    if m.shape != (4, 4) or not np.isfinite(m).all():
        raise SceneError("camera matrix must be a finite 4x4 matrix")
    if np.abs(m[3] - (0.0, 0.0, 0.0, 1.0)).max() > 1e-6:
        raise SceneError(f"camera matrix: the bottom row must be (0, 0, 0, 1) (an affine transform), got "
                         f"{[float(x) for x in m[3]]}")
    if np.abs(m[:3, 3]).max() > COORD_LIMIT:
        raise SceneError(f"camera position {_g(np.abs(m[:3, 3]).max())} m is beyond the renderable limit "
                         f"{COORD_LIMIT:g} m")
    if np.abs(m[:3, :3]).max() > COORD_LIMIT:
        raise SceneError("camera matrix: its scale is beyond the renderable limit")
    if abs(np.linalg.det(m[:3, :3])) < 1e-12:
        raise SceneError("camera matrix is singular (zero scale?)")
    for name, allowed in (("kind", ("PERSP", "ORTHO")), ("sensor_fit", ("AUTO", "HORIZONTAL", "VERTICAL"))):
        val = getattr(c, name)
        if not isinstance(val, str) or val not in allowed:
            what = "camera type" if name == "kind" else "camera sensor fit"
            raise SceneError(f"{what} {val!r} is not supported ({' or '.join(allowed)})")
    w = _number(c.width, "image width", integer=True)
    h = _number(c.height, "image height", integer=True)
    if w < 1 or h < 1:
        raise SceneError(f"image resolution must be at least 1x1, got {c.width}x{c.height}")
    if w > MAX_SIDE or h > MAX_SIDE:
        raise SceneError(f"image resolution {w}x{h}: each side must be at most {MAX_SIDE} pixels")
    if w * h > MAX_PIXELS:
        raise SceneError(f"image resolution {w}x{h} is {w * h / 1e6:.0f} M pixels, more than the "
                         f"{MAX_PIXELS / 1e6:.0f} M a render allows")
    vals = {}
    for name in ("lens", "sensor_width", "sensor_height", "ortho_scale"):
        val = _number(getattr(c, name), f"camera {name}")
        if not val > 0:
            raise SceneError(f"camera {name} must be > 0, got {val}")
        if val > FLOAT32_MAX:
            raise SceneError(f"camera {name} {_g(val)} overflows float32 (max 3.4e38)")
        vals[name] = val
    for name in ("shift_x", "shift_y"):
        val = _number(getattr(c, name), f"camera {name}")
        if abs(val) > SHIFT_MAX:
            raise SceneError(f"camera {name} {_g(val)} is beyond +-{SHIFT_MAX:g} (a fraction of the image)")
        vals[name] = val
    if c.kind == "PERSP":
        for sensor in ("sensor_width", "sensor_height"):
            tan_half = vals[sensor] / vals["lens"] / 2
            if tan_half > FOV_TAN_MAX:
                raise SceneError(f"camera field of view too wide: {sensor} / lens = {_g(2 * tan_half)} "
                                 f"(at most {2 * FOV_TAN_MAX:g})")
    elif vals["ortho_scale"] > COORD_LIMIT:
        raise SceneError(f"camera ortho_scale {_g(vals['ortho_scale'])} m is beyond the renderable limit "
                         f"{COORD_LIMIT:g} m")
    same = (w == c.width and type(c.width) is int and h == c.height and type(c.height) is int
            and type(c.kind) is str and type(c.sensor_fit) is str)
    return c if same else replace(c, width=w, height=h, kind=str(c.kind), sensor_fit=str(c.sensor_fit))


def _clean_float(a: np.ndarray, canonical) -> np.ndarray:
    """Float columns keep their float32/float64 dtype (the values the caller gave); others
    (integers, float16, longdouble) become the canonical dtype."""
    return a if a.dtype in (np.float32, np.float64) else a.astype(canonical)


def _enum_check(col: np.ndarray, enum: dict, label, what: str) -> None:
    bad = ~np.isin(col, list(enum.values()))
    if bad.any():
        i = int(np.argmax(bad))
        names = ", ".join(f"{v}={k}" for k, v in enum.items())
        raise SceneError(f"{label(i)}: {what} code {int(col[i])} is not one of {names}")


def _material_label(names):
    def label(i):
        try:
            return f"material {i} {str(names[i])!r}"
        except Exception:
            return f"material {i}"
    return label


def _check_row_counts(table, what: str, n: int) -> None:
    """Every column of a material or light table has ``n`` rows (SceneError naming the column)."""
    for f in fields(table):
        try:
            rows = len(getattr(table, f.name))
        except TypeError:
            rows = None
        if rows != n:
            raise SceneError(f"{what} table column {f.name!r} has {rows if rows is not None else 'no'} rows, "
                             f"expected {n}")


_ROWS_PER_CHUNK = 1 << 14  # rows of per-corner data normalised at a time (a few MB: in cache)


def _validate_corner_normals(value, v: np.ndarray, t: np.ndarray, warns: list) -> np.ndarray:
    """Scene.corner_normals: (T, 3, 3) finite, or empty (flat). Returned unit length in float32;
    a zero normal falls back to its triangle's face normal (one warning for all of them)."""
    cn = _column(value, "corner_normals", (3, 3), allow_empty=True)
    if len(cn) == 0:
        return np.zeros((0, 3, 3), np.float32)
    if len(cn) != len(t):
        raise SceneError(f"corner_normals must have one (3, 3) entry per triangle ({len(t)}) or none, got {len(cn)}")
    _check_range(cn.reshape(len(cn), 9), lambda i: f"triangle {i}", "shading normal", "")
    # normalised in float64 in chunks of rows (the same values as over the whole array at once,
    # without (T, 3, 3) float64 temporaries), chunks small enough to stay in cache; the length is sqrt((x^2 + y^2) + z^2), the order
    # np.linalg.norm's reduction adds in (the same values, tests/test_prepare_scale.py)
    out = np.empty(cn.shape, np.float32)
    n_zero = 0
    for s in range(0, len(cn), _ROWS_PER_CHUNK):
        c64 = cn[s:s + _ROWS_PER_CHUNK].astype(np.float64)
        sq = c64 * c64
        length = sq[..., 0] + sq[..., 1]
        length += sq[..., 2]
        del sq
        length = np.sqrt(length, out=length)[..., None]
        zero = ~(length > 1e-30)
        if zero.any():
            tc = t[s:s + _ROWS_PER_CHUNK]  # the chunk's corners only (not all V vertices in float64)
            face = triangle_normals(v[tc.reshape(-1)], np.arange(tc.size).reshape(-1, 3))
            # degenerate triangles (zero face normal) are dropped later: no warning for them
            n_zero += int((zero[:, :, 0] & (np.abs(face).max(axis=1) > 0)[:, None]).sum())
            c64 = np.where(zero, face[:, None, :], c64)
            length = np.where(zero, 1.0, length)
        np.divide(c64, length, out=c64)
        out[s:s + _ROWS_PER_CHUNK] = c64
    if n_zero:
        warns.append(f"{n_zero} zero shading normal(s): their triangles' face normals are used there")
    return out


def _validate_materials(m: Materials) -> Materials:
    # the row count comes from the kind column; every column must have that many rows and its per-row shape
    kind = _column(m.kind, "material table column 'kind'", (), kind="int", allow_empty=True)
    n = len(kind)
    _check_row_counts(m, "material", n)
    try:
        names = np.asarray(m.name)
    except Exception:
        names = None
    if names is None or names.shape != (n,) or not (names.dtype.kind in "US" or
                                                     (names.dtype.kind == "O" and all(isinstance(x, str) for x in names))):
        raise SceneError(f"material table column 'name' must hold {n} strings, got "
                         f"{'shape ' + str(names.shape) + ' of ' + str(names.dtype) if names is not None else 'no array'}")
    label = _material_label(names)
    out = {"name": m.name, "kind": kind}
    for name, (dtype, tail, _default, enum) in _MATERIAL_COLUMNS.items():
        if name in ("name", "kind"):
            continue
        is_int = np.dtype(dtype).kind == "i"
        col = _column(getattr(m, name), f"material table column {name!r}", tail, rows=n,
                      kind=("flag" if name == "grating" else "int") if is_int else "float", allow_empty=n == 0)
        out[name] = col
    if n == 0:
        return m if all(out[k] is getattr(m, k) for k in out) else Materials(**out)
    _enum_check(kind, MATERIAL_KINDS, label, "kind")
    _enum_check(out["dispersion"], DISPERSION_MODELS, label, "dispersion")
    for name, enum in (("grating_type", GRATING_TYPES), ("lattice", LATTICES), ("grating_direction", GRATING_DIRECTIONS),
                       ("conductor_fresnel", CONDUCTOR_FRESNELS), ("glass_tint", GLASS_TINTS)):
        _enum_check(out[name], enum, label, name.replace("_", " "))
    g = out["grating"].astype(np.int64)
    bad = (g != 0) & (g != 1)
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"{label(i)}: grating flag must be 0 or 1, got {int(g[i])}")
    f64 = {name: out[name].astype(np.float64) for name in out
           if name != "name" and np.dtype(_MATERIAL_COLUMNS[name][0]).kind == "f"}
    # every float column: finite and within float32
    for name in ("color", "emission", "ior", "abbe", "period", "slit_width", "coherence_length", "rotation",
                 "normal_strength", "emission_strength", "roughness", "metallic", "transmission",
                 "specular_ior_level", "specular_tint", "sphere_diameter", "sphere_ior", "void_ior", "mosaic_spread"):
        _check_range(f64[name], label, name.replace("_", " "), "")
    for name in TEXTURE_COLUMNS:
        bad = out[name].astype(np.int64) < -1
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"{label(i)}: {name.replace('_', ' ')} {int(out[name][i])} is not a texture index "
                             f"(-1: none)")
    for name in ("roughness_channel", "metallic_channel"):
        ch = out[name].astype(np.int64)
        bad = (ch < -1) | (ch > 3)
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"{label(i)}: {name.replace('_', ' ')} {int(ch[i])} is not -1 (luminance) or 0-3 "
                             f"(R, G, B, alpha)")
    es = f64["emission_strength"]
    if (es < 0).any():
        i = int(np.argmax(es < 0))
        raise SceneError(f"{label(i)}: emission strength {_g(es[i])} is negative")
    _check_range(es, label, "emission strength", "", limit=EMISSION_LIMIT)
    for name in _UNIT_COLUMNS:
        bad = ~((f64[name] >= 0.0) & (f64[name] <= 1.0))
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"{label(i)}: {name} must be between 0 and 1, got {_g(f64[name][i])}")
    for name in ("specular_ior_level", "specular_tint"):
        _check_range(f64[name], label, name.replace("_", " "), "", nonneg=True)
    em = f64["emission"]
    if (em < 0).any():
        i = _first_row(em < 0)
        raise SceneError(f"{label(i)}: emission {em[i].tolist()} is negative")
    _check_range(em, label, "emission", "", limit=EMISSION_LIMIT)
    k = kind
    # the IOR is read by glass and by a specular layer
    diel = k == MATERIAL_KINDS["DIELECTRIC"]
    uses_ior = diel | (f64["transmission"] > 0) | (f64["specular_ior_level"] > 0)
    ior = f64["ior"]
    bad_ior = uses_ior & ~((ior >= 1.0) & (ior <= IOR_MAX))
    if bad_ior.any():
        i = int(np.argmax(bad_ior))
        if ior[i] < 1.0:
            raise SceneError(f"{label(i)}: IOR must be >= 1, got {float(ior[i])}")
        raise SceneError(f"{label(i)}: IOR {_g(ior[i])} is above {IOR_MAX:g}")
    abbe_rows = diel & (out["dispersion"] == DISPERSION_MODELS["ABBE"])
    abbe = f64["abbe"]
    bad = abbe_rows & ~(abbe > 0)
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"{label(i)}: Abbe dispersion needs an Abbe number > 0")
    for i in np.flatnonzero(abbe_rows):  # loop over Abbe glasses (a few): the index must stay in [1, IOR_MAX]
        n_ends = ior_spectrum(np.array(_OBSERVER_NM), "ABBE", float(ior[i]), float(abbe[i]))
        if not (np.isfinite(n_ends).all() and n_ends.min() >= 1.0 and n_ends.max() <= IOR_MAX):
            raise SceneError(f"{label(i)}: Abbe number {_g(abbe[i])} with IOR {_g(ior[i])} gives an index of "
                             f"{_g(n_ends[1])} at {_OBSERVER_NM[1]:g} nm and {_g(n_ends[0])} at "
                             f"{_OBSERVER_NM[0]:g} nm, outside 1-{IOR_MAX:g} (use a larger Abbe number)")
    bragg = (g != 0) & (out["lattice"] == LATTICES["BRAGG"])
    for col, (lo, hi, unit) in BRAGG_RANGES.items():
        val = out[col].astype(np.float64)
        bad = bragg & ~((val >= lo) & (val <= hi))
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"{label(i)}: opal {col.replace('_', ' ')} must be between {lo:g} and {hi:g}{unit}, "
                             f"got {_g(val[i])}")
    _check_bragg(f64, out["layers"], label)  # every row (a BRAGG row has been held to its ranges above)
    on = (g != 0) & ~bragg  # the surface-grating columns (a BRAGG layer does not read them)
    for col, what, unit, limit in (("period", "period", " nm", PERIOD_MAX), ("slit_width", "slit width", " nm", PERIOD_MAX),
                                   ("coherence_length", "coherence length", " um", COHERENCE_MAX)):
        val = f64[col]
        bad = on & ~(val > 0)
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"{label(i)}: grating {what} must be > 0, got {float(val[i])}")
        bad = on & (val > limit)
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"{label(i)}: grating {what} {_g(val[i])}{unit} is above {limit:g}{unit}")
    bad = on & (f64["slit_width"] > f64["period"])
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"{label(i)}: grating slit width {float(out['slit_width'][i])} nm is larger "
                         f"than the period {float(out['period'][i])} nm")
    sc = out["slit_count"].astype(np.int64)
    bad = on & ((sc < 1) | (sc > SLIT_COUNT_MAX))
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"{label(i)}: grating slit count must be >= 1 and <= {SLIT_COUNT_MAX}, got {int(sc[i])}")
    clean = {}
    for name, col in out.items():
        dtype = _MATERIAL_COLUMNS[name][0]
        if name == "name":
            clean[name] = col
        elif np.dtype(dtype).kind == "f":
            clean[name] = _clean_float(col, dtype)
        else:
            clean[name] = col if col.dtype == dtype else col.astype(dtype)
    if all(clean[f.name] is getattr(m, f.name) for f in fields(Materials)):
        return m
    return Materials(**clean)


def _validate_textures(scene: "Scene", n_tri: int, materials: Materials, tri_material: np.ndarray,
                       warns: list) -> dict:
    """The texture fields of ``scene`` checked (docs/physics.md section 13): every image (H, W, 4)
    of finite numbers within float32 and MAX_SIDE / MAX_PIXELS, the codes, per-corner UVs and
    tangents (T, 3, 2) / (T, 3, 4) or none, and the materials' texture indices within the list.
    Returns the clean fields (the given arrays where nothing needed converting); warns where a
    used texture has no UVs or a normal map no tangents."""
    raw = scene.textures
    if raw is None:
        raw = []
    if isinstance(raw, np.ndarray) and raw.ndim == 4:  # one stacked array: a list of its images
        raw = list(raw)
    if not isinstance(raw, (list, tuple)):
        raise SceneError(f"the scene's textures must be a list of (H, W, 4) images, got {type(raw).__name__}")
    images, same = [], isinstance(raw, list)
    for i, px in enumerate(raw):
        try:
            a = np.asarray(px)
        except Exception:
            raise SceneError(f"texture {i} is not a regular array of numbers") from None
        if a.dtype.kind not in "iuf":
            raise SceneError(f"texture {i} must hold numbers, got {_DTYPE_WORDS.get(a.dtype.kind, str(a.dtype))} "
                             f"({a.dtype})")
        if a.ndim != 3 or a.shape[2] != 4:
            raise SceneError(f"texture {i} must have shape (height, width, 4) (RGBA), got {a.shape}")
        h, w = a.shape[:2]
        if h < 1 or w < 1:
            raise SceneError(f"texture {i} is empty ({w}x{h} pixels)")
        if h > MAX_SIDE or w > MAX_SIDE or h * w > MAX_PIXELS:
            raise SceneError(f"texture {i} is {w}x{h} pixels: each side must be at most {MAX_SIDE} and the "
                             f"image at most {MAX_PIXELS / 1e6:.0f} M pixels")
        a32 = a if a.dtype == np.float32 else a.astype(np.float32)
        finite = np.isfinite(a32)
        if not finite.all():
            j = int(np.argmax(~finite.reshape(-1))) // 4
            what = "overflows float32 (max 3.4e38)" if np.isfinite(a).all() else "is NaN or infinite"
            raise SceneError(f"texture {i}: pixel ({j % w}, {j // w}) {what}")
        same = same and a32 is px
        images.append(a32)
    k = len(images)
    out = {"textures": raw if same else images}
    for name, table, default in (("interpolation", TEXTURE_INTERPOLATIONS, "LINEAR"),
                                 ("extension", TEXTURE_EXTENSIONS, "REPEAT"), ("encoding", TEXTURE_ENCODINGS, "LINEAR")):
        what = f"texture_{name}"
        col = _column(getattr(scene, what), what, (), kind="int", allow_empty=True)
        if len(col) == 0 and k:
            col = np.full(k, table[default], np.int32)
        if len(col) != k:
            raise SceneError(f"{what} must have one code per texture ({k}), got {len(col)}")
        _enum_check(col, table, lambda i: f"texture {i}", name)
        out[what] = col if col.dtype == np.int32 else col.astype(np.int32)
    for name, width in (("corner_uvs", 2), ("corner_tangents", 4)):
        a = _column(getattr(scene, name), name, (3, width), allow_empty=True)
        if len(a) not in (0, n_tri):
            raise SceneError(f"{name} must have one row of 3 corners per triangle ({n_tri}) or none, got {len(a)}")
        if a.size and not _within(a):
            bad = ~np.isfinite(a.astype(np.float64))
            if bad.any():
                raise SceneError(f"{name}: triangle {_first_row(bad)} has a NaN or infinite value")
            _check_range(a.astype(np.float64), lambda i: f"triangle {i}", name.replace("_", " ")[:-1], "")
        out[name] = a if a.dtype == np.float32 else a.astype(np.float32)
    label = _material_label(materials.name)
    used = np.zeros(len(materials), bool)
    if len(tri_material):  # validated: 0 <= tri_material < len(materials)
        used |= np.bincount(tri_material, minlength=len(materials))[:len(materials)] > 0
    for col in TEXTURE_COLUMNS:
        idx = np.asarray(getattr(materials, col)).astype(np.int64)
        bad = idx >= k
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"{label(i)}: {col.replace('_', ' ')} {int(idx[i])} but the scene has {k} texture(s)")
        rows = np.flatnonzero(used & (idx >= 0))
        if rows.size and not len(out["corner_uvs"]):
            warns.append(f"{label(int(rows[0]))} has image textures but the scene has no UVs: they are read at "
                         "UV (0, 0), as Cycles reads them without a UV map")
        if col == "normal_texture" and rows.size and not len(out["corner_tangents"]):
            warns.append(f"{label(int(rows[0]))} has a normal map but the scene has no tangents: the normal map is "
                         "ignored, as Cycles does without tangents")
    return out


def _read_textures(read, names: set, shown) -> dict:
    """The texture fields of a scene file (none in files written before textures existed)."""
    out = {}
    for name in ("corner_uvs", "corner_tangents"):
        if name in names:
            out[name] = read(name)
    if "texture_count" in names:
        count = read("texture_count")
        if count.shape != () or count.dtype.kind not in "iu" or not 0 <= int(count) <= 1_000_000:
            raise SceneError(f"{shown}: texture_count must be one integer, got {count.dtype} of shape {count.shape}")
        out["textures"] = [read(f"texture_{i}") for i in range(int(count))]
        for name in ("interpolation", "extension", "encoding"):
            if "texture_" + name in names:
                out["texture_" + name] = read("texture_" + name)
    return out


_LIGHT_COLUMNS = {  # name -> (per-row shape, canonical dtype)
    "kind": ((), np.int32), "position": ((3,), np.float64), "direction": ((3,), np.float64),
    "axis_u": ((3,), np.float64), "color": ((3,), np.float32), "power": ((), np.float64),
    "temperature": ((), np.float64), "spot_size": ((), np.float64), "spot_blend": ((), np.float64),
    "size_u": ((), np.float64), "size_v": ((), np.float64), "radius": ((), np.float64),
    "angle": ((), np.float64), "soft_falloff": ((), np.int32),
}
#: Light columns added after format 1: a file without them loads with 0 (what it rendered then).
_LIGHT_OPTIONAL = ("radius", "angle", "soft_falloff")


def _validate_lights(lt: Lights) -> Lights:
    kind = _column(lt.kind, "light table column 'kind'", (), kind="int", allow_empty=True)
    n = len(kind)
    _check_row_counts(lt, "light", n)
    out = {"kind": kind}
    for name, (tail, _dtype) in _LIGHT_COLUMNS.items():
        if name != "kind":
            out[name] = _column(getattr(lt, name), f"light table column {name!r}", tail, rows=n, allow_empty=n == 0,
                                **({"kind": "int"} if name == "soft_falloff" else {}))
    if n == 0:
        return lt if all(out[k] is getattr(lt, k) for k in out) else Lights(**{
            k: v if v.dtype == _LIGHT_COLUMNS[k][1] else v.astype(_LIGHT_COLUMNS[k][1]) for k, v in out.items()})

    def label(i):
        return f"light {i}"

    _enum_check(kind, LIGHT_KINDS, label, "kind")
    f64 = {name: out[name].astype(np.float64) for name in out if name not in ("kind", "soft_falloff")}
    units = {"position": " m", "power": " W", "size_u": " m", "size_v": " m", "temperature": " K", "radius": " m",
             "angle": " rad"}
    for name in ("position", "direction", "axis_u", "color", "power", "temperature", "spot_size", "spot_blend",
                 "size_u", "size_v", "radius", "angle"):
        a = f64[name]
        if not np.isfinite(a).all():
            i = _first_row(~np.isfinite(a))
            raise SceneError(f"light {i}: {name.replace('_', ' ')} is NaN or infinite")
        limit = COORD_LIMIT if name in ("position", "size_u", "size_v", "radius") else None
        _check_range(a, label, name.replace("_", " "), units.get(name, ""), limit=limit)
    power = f64["power"]
    if (power < 0).any():
        raise SceneError(f"light {int(np.argmax(power < 0))}: power must be >= 0, got {_g(power[power < 0][0])}")
    dn = np.linalg.norm(f64["direction"], axis=1)
    if (dn < 1e-12).any():
        i = int(np.argmax(dn < 1e-12))
        raise SceneError(f"light {i}: direction {f64['direction'][i].tolist()} is a zero vector")
    temp = f64["temperature"]
    bad = (temp != 0) & ~((temp >= TEMPERATURE_MIN) & (temp <= TEMPERATURE_MAX))
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"light {i}: temperature {_g(temp[i])} K is outside {TEMPERATURE_MIN:g}-{TEMPERATURE_MAX:g} K "
                         f"(0: use the light's colour)")
    spot = kind == LIGHT_KINDS["SPOT"]
    bad = spot & ~((f64["spot_size"] >= 0) & (f64["spot_size"] <= np.pi + 1e-6))
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"light {i}: spot size {_g(f64['spot_size'][i])} rad is outside 0-pi")
    bad = spot & ~((f64["spot_blend"] >= 0) & (f64["spot_blend"] <= 1 + 1e-6))
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"light {i}: spot blend {_g(f64['spot_blend'][i])} is outside 0-1")
    point = np.isin(kind, [LIGHT_KINDS["POINT"], LIGHT_KINDS["SPOT"]])
    bad = point & (f64["radius"] < 0)
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"light {i}: radius {_g(f64['radius'][i])} m is negative")
    sun = kind == LIGHT_KINDS["SUN"]
    bad = sun & ~((f64["angle"] >= 0) & (f64["angle"] <= np.pi + 1e-6))
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"light {i}: sun angle {_g(f64['angle'][i])} rad is outside 0-pi")
    sf = out["soft_falloff"].astype(np.int64)
    bad = (sf != 0) & (sf != 1)
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"light {i}: soft falloff must be 0 or 1, got {int(sf[i])}")
    su, sv = f64["size_u"], f64["size_v"]
    rect, disk = kind == LIGHT_KINDS["AREA_RECT"], kind == LIGHT_KINDS["AREA_DISK"]
    area_rows = rect | disk
    bad = area_rows & ((su <= 0) | (sv <= 0))
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"light {i}: an area light has a zero or negative size ({_g(su[i])} x {_g(sv[i])} m)")
    area = np.where(rect, su * sv, np.where(disk, np.pi * su * sv / 4, 0.0))
    tiny = area_rows & (area < float(np.finfo(np.float32).tiny))
    if tiny.any():
        i = int(np.argmax(tiny))
        raise SceneError(f"light {i}: area {_g(area[i])} m^2 underflows float32 (min 1.2e-38)")
    # what the light emits, before its spectrum's shape: W/sr, W/m^2 or W/m^2/sr
    scale = np.where(temp > 0, 1.0, np.maximum(f64["color"], 0.0).max(axis=1))
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        point = np.isin(kind, [LIGHT_KINDS["POINT"], LIGHT_KINDS["SPOT"]])
        emitted = np.where(point, power / (4 * np.pi), np.where(area_rows, power / (np.pi * np.where(area_rows, area, 1.0)),
                                                                  power)) * scale
    over = ~(emitted <= EMISSION_LIMIT)
    if over.any():
        i = int(np.argmax(over))
        if point[i]:
            what, unit, how = "intensity", "W/sr", "power / (4 pi)"
        elif area_rows[i]:
            what, unit, how = "radiance", "W/m^2/sr", "power / (pi * area)"
        else:
            what, unit, how = "irradiance", "W/m^2", "strength"
        why = "overflows float32" if emitted[i] > FLOAT32_MAX else "is beyond the renderable limit"
        raise SceneError(f"light {i}: {what} {_g(emitted[i])} {unit} ({how}, times the colour) {why} "
                         f"(max {EMISSION_LIMIT:g} {unit})")
    clean = {}
    for name, (tail, dtype) in _LIGHT_COLUMNS.items():
        col = out[name]
        if np.dtype(dtype).kind == "f":
            clean[name] = _clean_float(col, dtype)
        else:
            clean[name] = col if col.dtype == dtype else col.astype(dtype)
    if all(clean[f.name] is getattr(lt, f.name) for f in fields(Lights)):
        return lt
    return Lights(**clean)
