"""The scene model: flat NumPy arrays, one ``.npz`` file, and validation with readable errors.

A scene holds geometry (vertices, triangles, per-triangle material index), a material table, a
light table and a camera, all in world space (Blender's convention: metres, Z up; the camera
looks down its local -Z axis with +Y up). Colours are linear Rec.709 RGB; they become spectra at
render time, because the wavelength grid is a render setting.

Enumerations are stored as integer codes with fixed values so saved files keep loading when
entries are added (the same rule Blender's EnumProperty items follow).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np

from .enums import GratingDirection, GratingType, Lattice, LightKind, MaterialKind, codes
from .optics import DISPERSION_MODELS

__all__ = [
    "SceneError",
    "GRATING_TYPES",
    "LATTICES",
    "GRATING_DIRECTIONS",
    "MATERIAL_KINDS",
    "LIGHT_KINDS",
    "Materials",
    "Lights",
    "Camera",
    "Scene",
    "FORMAT_VERSION",
]

FORMAT_VERSION = 1

#: Material kinds and light kinds: name -> stable code (enums.py).
MATERIAL_KINDS = codes(MaterialKind)
LIGHT_KINDS = codes(LightKind)


class SceneError(ValueError):
    """A scene that cannot be rendered; the message names the problem for the user."""


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
}


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

    Grating layer (docs/physics.md section 3), on top of the base kind: grating (0/1), grating_type
    (GRATING_TYPES), lattice (LATTICES), period D (nm), slit_width a (nm), slit_count N,
    coherence_length L (um, the slits' length), grating_direction (GRATING_DIRECTIONS: how the
    exporter found the per-triangle tangent in ``Scene.tri_tangent``), rotation (radians, about
    the normal).
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

    def __len__(self):
        return len(self.kind)

    @classmethod
    def from_list(cls, rows: list[dict]) -> "Materials":
        """Build from dicts like {'kind': 'DIELECTRIC', 'color': (1,1,1), 'ior': 1.5, 'dispersion': 'BK7'}.

        Missing keys take their defaults (a dielectric's colour defaults to clear, 1); enumerations
        are given by name ('BK7', 'REFLECTION', ...).
        """
        out = {}
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
                    if val not in enum:
                        raise SceneError(f"material {i}: unknown {name} {val!r}; expected one of {sorted(enum)}")
                    val = enum[val]
                col[i] = val
            out[name] = col
        # clear glass by default: a dielectric without a colour is untinted
        for i, r in enumerate(rows):
            if "color" not in r and out["kind"][i] == MATERIAL_KINDS["DIELECTRIC"]:
                out["color"][i] = 1.0
        return cls(**out)

    @classmethod
    def from_columns(cls, columns: dict, rows: int) -> "Materials":
        """Build from stored columns, filling columns an older file lacks with their defaults."""
        return cls(**{name: np.asarray(columns[name]) if name in columns else _material_column_default(name, rows)
                      for name in _MATERIAL_COLUMNS})


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

    def __len__(self):
        return len(self.kind)

    @classmethod
    def from_list(cls, rows: list[dict]) -> "Lights":
        """Build from dicts like {'kind': 'POINT', 'position': (0, 0, 2), 'power': 100}."""
        cols = {f.name: [] for f in fields(cls)}
        for i, r in enumerate(rows):
            k = r.get("kind", "POINT")
            if k not in LIGHT_KINDS:
                raise SceneError(f"light {i}: unknown kind {k!r}; expected one of {sorted(LIGHT_KINDS)}")
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
            }
            for name, v in vals.items():
                cols[name].append(v)
        out = cls()
        for f in fields(cls):
            proto = getattr(out, f.name)
            setattr(out, f.name, np.array(cols[f.name], proto.dtype).reshape((-1,) + proto.shape[1:]))
        return out


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

    # ------------------------------------------------------------------ building
    def add_mesh(self, vertices, triangles, material: int, tangent=None, period=None) -> None:
        """Append a mesh (its own vertex numbering) with one material for all its triangles.

        ``tangent``: a grating direction (3,) for all its triangles or (T, 3) per triangle;
        ``period``: a period override in nm, scalar or (T,).
        """
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

    # ------------------------------------------------------------------ validation
    def validated(self) -> tuple["Scene", list[str]]:
        """Return (a clean copy, warnings); raise SceneError naming what makes it unrenderable.

        Errors: non-finite coordinates, indices out of range, no camera, bad camera or light
        numbers. Dropped with a warning: zero-area triangles. Warned: nothing to render, no light.
        """
        warns: list[str] = []
        if self.camera is None:
            raise SceneError("the scene has no camera: add one and make it the active camera")
        _validate_camera(self.camera)
        v = np.asarray(self.vertices, np.float32)
        t = np.asarray(self.triangles)
        if v.ndim != 2 or v.shape[1] != 3:
            raise SceneError(f"vertices must have shape (V, 3), got {v.shape}")
        if t.ndim != 2 or t.shape[1] != 3:
            raise SceneError(f"triangles must have shape (T, 3), got {t.shape}")
        bad = ~np.isfinite(np.asarray(self.vertices, np.float64)).all(axis=1)
        if bad.any():
            raise SceneError(
                f"{int(bad.sum())} vertex coordinate(s) are NaN or infinite (first: vertex {int(np.argmax(bad))})"
            )
        if len(t):
            if t.min() < 0 or t.max() >= len(v):
                i = int(np.argmax((t < 0).any(1) | (t >= len(v)).any(1)))
                raise SceneError(
                    f"triangle {i} uses vertex index {t[i].tolist()} but the scene has {len(v)} vertices"
                )
        tm = np.asarray(self.tri_material)
        if tm.shape != (len(t),):
            raise SceneError(f"tri_material must have one entry per triangle ({len(t)}), got shape {tm.shape}")
        nm = len(self.materials)
        if len(tm) and (tm.min() < 0 or tm.max() >= nm):
            i = int(np.argmax((tm < 0) | (tm >= nm)))
            raise SceneError(f"triangle {i} uses material {int(tm[i])} but the scene has {nm} materials")
        _validate_materials(self.materials)
        _validate_lights(self.lights)
        if not np.isfinite(np.asarray(self.world_color, np.float64)).all():
            raise SceneError("world colour is NaN or infinite")

        tt = np.asarray(self.tri_tangent, np.float32).reshape(-1, 3)
        tp = np.asarray(self.tri_period, np.float32).reshape(-1)
        if len(tt) not in (0, len(t)) or len(tp) not in (0, len(t)):
            raise SceneError(f"tri_tangent / tri_period must have one entry per triangle ({len(t)}) or none")
        if not np.isfinite(tt).all() or not np.isfinite(tp).all() or (tp < 0).any():
            raise SceneError("a per-triangle grating direction or period is NaN, infinite or negative")
        t = t.astype(np.int32)
        if len(t):
            p = v.astype(np.float64)[t]
            area2 = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
            degenerate = area2 <= 0.0
            if degenerate.any():
                warns.append(f"dropped {int(degenerate.sum())} degenerate (zero-area) triangle(s)")
                keep = ~degenerate
                t, tm = t[keep], tm[keep]
                tt = tt[keep] if len(tt) else tt
                tp = tp[keep] if len(tp) else tp
        if len(t) == 0:
            warns.append("the scene has no geometry: the image shows only the background")
        if len(self.lights) == 0:
            warns.append("the scene has no lights: only the background is lit")
        clean = replace(self, vertices=v, triangles=t, tri_material=tm.astype(np.int32), tri_tangent=tt, tri_period=tp)
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
        }
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
        """Read a scene written by :meth:`save`; a clear SceneError if it is not one."""
        try:
            z = np.load(path, allow_pickle=False)
        except FileNotFoundError:
            raise SceneError(f"scene file not found: {path}") from None
        except Exception as e:  # not a zip, truncated, ...
            raise SceneError(f"cannot read scene file {path}: {e}") from None
        with z:
            if "format_version" not in z:
                raise SceneError(f"{path} is not an opal_diffraction scene (no format_version)")
            ver = int(z["format_version"])
            if ver > FORMAT_VERSION:
                raise SceneError(f"{path} was written by a newer version (format {ver} > {FORMAT_VERSION})")
            cols = {f.name: z["material_" + f.name] for f in fields(Materials) if "material_" + f.name in z}
            mats = Materials.from_columns(cols, len(cols.get("kind", ())))
            lights = Lights(**{f.name: z["light_" + f.name] for f in fields(Lights) if "light_" + f.name in z})
            cam = None
            if "camera_matrix" in z:
                kw = {}
                for f in fields(Camera):
                    if "camera_" + f.name in z:
                        val = z["camera_" + f.name]
                        kw[f.name] = val.item() if val.ndim == 0 else val
                cam = Camera(**kw)
            return cls(
                vertices=z["vertices"],
                triangles=z["triangles"],
                tri_material=z["tri_material"],
                materials=mats,
                lights=lights,
                camera=cam,
                world_color=z["world_color"],
                tri_tangent=z["tri_tangent"] if "tri_tangent" in z else np.zeros((0, 3), np.float32),
                tri_period=z["tri_period"] if "tri_period" in z else np.zeros(0, np.float32),
            )


def _validate_camera(c: Camera) -> None:
    m = np.asarray(c.matrix, np.float64)
    if m.shape != (4, 4) or not np.isfinite(m).all():
        raise SceneError("camera matrix must be a finite 4x4 matrix")
    if abs(np.linalg.det(m[:3, :3])) < 1e-12:
        raise SceneError("camera matrix is singular (zero scale?)")
    if c.kind not in ("PERSP", "ORTHO"):
        raise SceneError(f"camera type {c.kind!r} is not supported (PERSP or ORTHO)")
    if c.sensor_fit not in ("AUTO", "HORIZONTAL", "VERTICAL"):
        raise SceneError(f"camera sensor fit {c.sensor_fit!r} is not AUTO, HORIZONTAL or VERTICAL")
    if int(c.width) < 1 or int(c.height) < 1:
        raise SceneError(f"image resolution must be at least 1x1, got {c.width}x{c.height}")
    for name in ("lens", "sensor_width", "sensor_height", "ortho_scale"):
        val = float(getattr(c, name))
        if not np.isfinite(val) or val <= 0:
            raise SceneError(f"camera {name} must be > 0, got {val}")


def _validate_materials(m: Materials) -> None:
    n = len(m.kind)
    for f in fields(Materials):
        if len(getattr(m, f.name)) != n:
            raise SceneError(f"material table column {f.name!r} has {len(getattr(m, f.name))} rows, expected {n}")
    if n == 0:
        return
    if not np.isin(m.kind, list(MATERIAL_KINDS.values())).all():
        raise SceneError(f"material kind codes must be in {sorted(MATERIAL_KINDS.values())}")
    if not np.isin(m.dispersion, list(DISPERSION_MODELS.values())).all():
        raise SceneError(f"dispersion codes must be in {sorted(DISPERSION_MODELS.values())}")
    if not np.isfinite(m.color).all():
        raise SceneError("a material colour is NaN or infinite")
    if not np.isfinite(m.emission).all() or (m.emission < 0).any():
        raise SceneError("a material emission is negative, NaN or infinite")
    diel = m.kind == MATERIAL_KINDS["DIELECTRIC"]
    bad_ior = diel & ~(np.isfinite(m.ior) & (m.ior >= 1.0))
    if bad_ior.any():
        i = int(np.argmax(bad_ior))
        raise SceneError(f"material {m.name[i]!r}: IOR must be >= 1, got {float(m.ior[i])}")
    abbe = diel & (m.dispersion == DISPERSION_MODELS["ABBE"]) & ~(m.abbe > 0)
    if abbe.any():
        i = int(np.argmax(abbe))
        raise SceneError(f"material {m.name[i]!r}: Abbe dispersion needs an Abbe number > 0")
    g = np.asarray(m.grating) != 0
    for col, what in (("period", "period"), ("slit_width", "slit width"), ("coherence_length", "coherence length")):
        bad = g & ~(np.isfinite(getattr(m, col)) & (getattr(m, col) > 0))
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"material {m.name[i]!r}: grating {what} must be > 0, got {float(getattr(m, col)[i])}")
    bad = g & (m.slit_width > m.period)
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"material {m.name[i]!r}: grating slit width {float(m.slit_width[i])} nm is larger "
                         f"than the period {float(m.period[i])} nm")
    bad = g & (m.slit_count < 1)
    if bad.any():
        raise SceneError(f"material {m.name[int(np.argmax(bad))]!r}: grating slit count must be >= 1")


def _validate_lights(lt: Lights) -> None:
    n = len(lt.kind)
    for f in fields(Lights):
        if len(getattr(lt, f.name)) != n:
            raise SceneError(f"light table column {f.name!r} has {len(getattr(lt, f.name))} rows, expected {n}")
    if n == 0:
        return
    for name in ("position", "direction", "axis_u", "color", "power", "spot_size", "size_u", "size_v"):
        if not np.isfinite(np.asarray(getattr(lt, name), np.float64)).all():
            raise SceneError(f"a light's {name} is NaN or infinite")
    if (lt.power < 0).any():
        raise SceneError(f"light {int(np.argmax(lt.power < 0))}: power must be >= 0")
    if (np.linalg.norm(lt.direction, axis=1) < 1e-12).any():
        raise SceneError("a light has a zero direction vector")
    area = np.isin(lt.kind, [LIGHT_KINDS["AREA_RECT"], LIGHT_KINDS["AREA_DISK"]])
    if (area & ((lt.size_u <= 0) | (lt.size_v <= 0))).any():
        raise SceneError("an area light has a zero or negative size")
