"""Depsgraph -> core Scene: geometry, materials, lights, camera and world, as flat NumPy arrays.

Everything is read from the evaluated depsgraph the engine is given (never from ``bpy.context``),
so modifiers, geometry nodes, instancing and the render-time visibility are what the render
sees. Geometry is read with ``foreach_get`` into NumPy (no Python loop per triangle or vertex);
a mesh that many instances share is read once and transformed for all of its instances in one
vectorised product. Blender's units are kept: metres, Cycles' light units (watts for point,
spot and area lights, W/m^2 for the sun), colours in the blend file's linear working space,
converted to the core's linear Rec.709.

What the core cannot render yet is approximated and named in the warnings rather than failing:
textures (averaged), rough reflection and refraction (made smooth), light radius and sun angle
(hard shadows). Grating settings are exported with a per-triangle grating direction
(``Scene.tri_tangent``) and, where the mesh has the opal tools' per-face period attribute
(``opal_grating_period``), a per-triangle period (``Scene.tri_period``); impossible values are
an error naming the material.
"""

from __future__ import annotations

import math
import time
from collections import defaultdict
from dataclasses import dataclass, field

import bpy
import numpy as np

from ..core.scene import Camera, Lights, Materials, Scene, SceneError

__all__ = [
    "ExportCancelled",
    "ExportResult",
    "export_scene",
    "render_size",
    "render_region",
    "working_space_to_rec709",
    "rec709_to_working_space",
]

GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META"}
UNSUPPORTED_GEOMETRY = {"CURVES", "POINTCLOUD", "VOLUME", "GREASEPENCIL", "GPENCIL"}
#: Blender's default surface (no material, or an empty slot): grey diffuse, as in Cycles.
DEFAULT_MATERIAL = {"name": "(default surface)", "kind": "DIFFUSE", "color": (0.8, 0.8, 0.8)}
#: Roughness above which a glossy surface is treated as diffuse rather than as a mirror.
ROUGH_AS_DIFFUSE = 0.5
#: Roughness above which smooth-surface approximations are worth a warning.
ROUGH_WARN = 0.1
#: How often (in object instances) export polls test_break.
POLL_EVERY = 64
GRATING_ATTRIBUTE = "opal_grating_direction"
#: Per-face grating period (FLOAT, nm) the opal tools write: overrides the material's period on
#: grating faces (0 or less: the material's).
PERIOD_ATTRIBUTE = "opal_grating_period"


class ExportCancelled(Exception):
    """The user pressed Esc while the scene was being exported."""


@dataclass
class ExportResult:
    scene: Scene
    warnings: list[str] = field(default_factory=list)
    stats: dict = field(default_factory=dict)


class _Warnings:
    """Collects warnings once each, in order."""

    def __init__(self):
        self.items: list[str] = []
        self._seen: set[str] = set()

    def __call__(self, message: str) -> None:
        if message not in self._seen:
            self._seen.add(message)
            self.items.append(message)


# ============================================================================ colour spaces
_COLOUR_SPACE_NAMES = {
    "Linear Rec.2020": "ITU-R BT.2020",
    "ACEScg": "ACEScg",
}


def _working_space() -> str:
    cs = getattr(bpy.data, "colorspace", None)  # Blender 5.0+: a per-file working space
    return getattr(cs, "working_space", "Linear Rec.709") if cs is not None else "Linear Rec.709"


def _matrix_to_rec709(space: str) -> np.ndarray | None:
    name = _COLOUR_SPACE_NAMES.get(space)
    if name is None:
        return None
    from ..core.spectrum import _colour

    colour = _colour()
    return np.asarray(colour.matrix_RGB_to_RGB(colour.RGB_COLOURSPACES[name], colour.RGB_COLOURSPACES["sRGB"],
                                               chromatic_adaptation_transform="Bradford"), np.float64)


def working_space_to_rec709() -> np.ndarray | None:
    """3x3 matrix from the blend file's linear working space to linear Rec.709 (None: identity)."""
    return _matrix_to_rec709(_working_space())


def rec709_to_working_space() -> np.ndarray | None:
    """3x3 matrix from linear Rec.709 to the blend file's working space (None: identity)."""
    m = _matrix_to_rec709(_working_space())
    return None if m is None else np.linalg.inv(m)


# ============================================================================ image size
def render_size(scene) -> tuple[int, int]:
    """Rendered image size in pixels: resolution times percentage, as Blender computes it."""
    r = scene.render
    pct = int(r.resolution_percentage)
    return max(1, int(r.resolution_x) * pct // 100), max(1, int(r.resolution_y) * pct // 100)


def render_region(scene, width: int, height: int) -> tuple[int, int, int, int] | None:
    """The border-render rectangle in pixels, (x0, y0, x1, y1) with rows counted from the BOTTOM
    (Blender's convention), or None for the full frame. Matches Blender's own truncation."""
    r = scene.render
    if not r.use_border:
        return None
    x0, x1 = int(r.border_min_x * width), int(r.border_max_x * width)
    y0, y1 = int(r.border_min_y * height), int(r.border_max_y * height)
    x0, y0 = max(0, min(x0, width)), max(0, min(y0, height))
    x1, y1 = max(0, min(x1, width)), max(0, min(y1, height))
    if x1 <= x0 or y1 <= y0 or (x0, y0, x1, y1) == (0, 0, width, height):
        return None
    return x0, y0, x1, y1


# ============================================================================ shader nodes
@dataclass
class _Surface:
    """What a shader evaluates to, in the core's terms."""

    kind: str | None  # 'DIFFUSE' | 'MIRROR' | 'DIELECTRIC'; None: no BSDF (emission only or black)
    color: np.ndarray
    ior: float = 1.5
    roughness: float = 0.0
    emission: np.ndarray = field(default_factory=lambda: np.zeros(3))


def _node_tree(id_data):
    """The shader node tree an ID renders with, or None (use_nodes is always on from Blender 5.0)."""
    nt = getattr(id_data, "node_tree", None)
    if nt is not None and bpy.app.version < (5, 0, 0) and not id_data.use_nodes:
        return None
    return nt


def _rgb(v) -> np.ndarray:
    return np.array(tuple(v)[:3], np.float64)


class _NodeReader:
    """Evaluates a shader node tree to a _Surface, approximating what it cannot represent."""

    def __init__(self, owner: str, warn: _Warnings, to709: np.ndarray | None):
        self.owner, self.warn, self.to709 = owner, warn, to709

    # ---------------------------------------------------------------- sockets
    @staticmethod
    def _source(socket):
        """(node, output socket) feeding ``socket``, following reroutes; None when unlinked."""
        seen = 0
        while socket is not None and socket.is_linked and seen < 64:
            link = socket.links[0]
            if not getattr(link, "is_valid", True) or getattr(link, "is_muted", False):
                return None
            node = link.from_node
            if node.bl_idname == "NodeReroute":
                socket = node.inputs[0] if node.inputs else None
                seen += 1
                continue
            return node, link.from_socket
        return None

    def color(self, node, name: str, default=(0.8, 0.8, 0.8)) -> np.ndarray:
        """Linear Rec.709 colour of input ``name``; textures are averaged, other links fall back."""
        sock = node.inputs.get(name)
        if sock is None:
            return np.array(default, np.float64)
        src = self._source(sock)
        if src is None:
            return self._to709(_rgb(sock.default_value))
        n, out = src
        if n.bl_idname == "ShaderNodeRGB":
            return self._to709(_rgb(out.default_value))
        if n.bl_idname == "ShaderNodeBlackbody":
            return _blackbody_rgb(self.value(n, "Temperature", 6500.0))
        if n.bl_idname in ("ShaderNodeTexImage", "ShaderNodeTexEnvironment") and getattr(n, "image", None):
            mean = _image_mean(n.image)
            if mean is not None:
                self.warn(f"{self.owner}: image texture '{n.image.name}' on '{name}' is rendered as its average colour")
                return self._to709(mean)
        self.warn(f"{self.owner}: '{name}' of '{node.name}' is driven by a '{n.name}' node, which is not "
                  f"supported: using the socket's own value")
        return self._to709(_rgb(sock.default_value))

    def value(self, node, name: str, default: float = 0.0) -> float:
        sock = node.inputs.get(name)
        if sock is None:
            return float(default)
        src = self._source(sock)
        if src is None:
            return float(sock.default_value)
        n, out = src
        if n.bl_idname == "ShaderNodeValue":
            return float(out.default_value)
        self.warn(f"{self.owner}: '{name}' of '{node.name}' is driven by a '{n.name}' node, which is not "
                  f"supported: using the socket's own value")
        return float(sock.default_value)

    def _to709(self, rgb: np.ndarray) -> np.ndarray:
        return rgb if self.to709 is None else self.to709 @ rgb

    # ---------------------------------------------------------------- shaders
    def surface(self, socket) -> _Surface:
        """Evaluate the shader plugged into ``socket`` (an output node's Surface input)."""
        return self._shader(self._source(socket), depth=0)

    def _shader(self, src, depth: int) -> _Surface:
        black = _Surface(None, np.zeros(3))
        if src is None:
            return black
        node, out = src
        if depth > 32:
            self.warn(f"{self.owner}: shader nesting too deep: truncated")
            return black
        idn = node.bl_idname
        if getattr(node, "mute", False):
            self.warn(f"{self.owner}: muted shader node '{node.name}' renders black")
            return black
        if idn == "ShaderNodeBsdfPrincipled":
            return self._principled(node)
        if idn == "ShaderNodeBsdfDiffuse":
            return _Surface("DIFFUSE", self.color(node, "Color"))
        if idn in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic", "ShaderNodeBsdfMetallic"):
            col = self.color(node, "Base Color" if idn == "ShaderNodeBsdfMetallic" else "Color")
            rough = self.value(node, "Roughness", 0.5)
            return self._glossy(node, col, rough)
        if idn in ("ShaderNodeBsdfGlass", "ShaderNodeBsdfRefraction"):
            rough = self.value(node, "Roughness", 0.0)
            if rough > ROUGH_WARN:
                self.warn(f"{self.owner}: rough glass (roughness {rough:.2f}) is rendered perfectly smooth")
            if idn == "ShaderNodeBsdfRefraction":
                self.warn(f"{self.owner}: Refraction BSDF is rendered as glass (with Fresnel reflection)")
            return _Surface("DIELECTRIC", self.color(node, "Color", (1, 1, 1)), self.value(node, "IOR", 1.5), rough)
        if idn == "ShaderNodeEmission":
            strength = self.value(node, "Strength", 1.0)
            return _Surface(None, np.zeros(3), emission=self.color(node, "Color", (1, 1, 1)) * max(strength, 0.0))
        if idn == "ShaderNodeMixShader":
            f = min(max(self.value(node, "Fac", 0.5) if node.inputs.get("Fac") else 0.5, 0.0), 1.0)
            a = self._shader(self._source(node.inputs[1]), depth + 1)
            b = self._shader(self._source(node.inputs[2]), depth + 1)
            return self._combine(a, b, 1.0 - f, f, node)
        if idn == "ShaderNodeAddShader":
            a = self._shader(self._source(node.inputs[0]), depth + 1)
            b = self._shader(self._source(node.inputs[1]), depth + 1)
            return self._combine(a, b, 1.0, 1.0, node)
        # Anything else (Translucent, Subsurface, Sheen, Toon, Hair, groups, ...): a diffuse
        # surface of the node's colour, if it has one.
        col = None
        for name in ("Color", "Base Color"):
            if node.inputs.get(name) is not None and getattr(node.inputs[name], "type", "") == "RGBA":
                col = self.color(node, name)
                break
        if idn == "ShaderNodeBsdfTransparent":
            self.warn(f"{self.owner}: Transparent BSDF is not supported: rendered black")
            return black
        self.warn(f"{self.owner}: shader node '{node.name}' ({idn}) is not supported: rendered as a diffuse "
                  f"surface{' of its colour' if col is not None else ''}")
        return _Surface("DIFFUSE", col if col is not None else np.full(3, 0.8))

    def _glossy(self, node, col, rough) -> _Surface:
        if rough >= ROUGH_AS_DIFFUSE:
            self.warn(f"{self.owner}: '{node.name}' roughness {rough:.2f} is rendered as a diffuse surface")
            return _Surface("DIFFUSE", col, roughness=rough)
        if rough > ROUGH_WARN:
            self.warn(f"{self.owner}: '{node.name}' roughness {rough:.2f} is rendered as a perfect mirror")
        return _Surface("MIRROR", col, roughness=rough)

    def _principled(self, node) -> _Surface:
        base = self.color(node, "Base Color")
        metallic = self.value(node, "Metallic", 0.0)
        rough = self.value(node, "Roughness", 0.5)
        trans_name = "Transmission Weight" if node.inputs.get("Transmission Weight") else "Transmission"
        trans = self.value(node, trans_name, 0.0)
        ior = self.value(node, "IOR", 1.5)
        strength = self.value(node, "Emission Strength", 0.0) if node.inputs.get("Emission Strength") else 1.0
        emission = self.color(node, "Emission Color" if node.inputs.get("Emission Color") else "Emission", (0, 0, 0))
        emission = emission * max(strength, 0.0)
        if node.inputs.get("Alpha") is not None and self.value(node, "Alpha", 1.0) < 1.0:
            self.warn(f"{self.owner}: alpha below 1 is not supported: rendered opaque")
        for layer in ("Subsurface Weight", "Coat Weight", "Sheen Weight"):
            if node.inputs.get(layer) is not None and self.value(node, layer, 0.0) > 0.0:
                self.warn(f"{self.owner}: the Principled BSDF's {layer.split()[0].lower()} layer is not rendered")
        if 0.0 < metallic < 1.0 or 0.0 < trans < 1.0:
            self.warn(f"{self.owner}: partial metallic/transmission ({metallic:.2f}/{trans:.2f}) is rounded to "
                      "the nearest of diffuse, mirror and glass")
        if trans >= 0.5 and metallic < 0.5:
            if rough > ROUGH_WARN:
                self.warn(f"{self.owner}: rough glass (roughness {rough:.2f}) is rendered perfectly smooth")
            return _Surface("DIELECTRIC", base, ior, rough, emission)
        if metallic >= 0.5:
            s = self._glossy(node, base, rough)
            s.emission = emission
            return s
        return _Surface("DIFFUSE", base, ior, rough, emission)

    def _combine(self, a: _Surface, b: _Surface, wa: float, wb: float, node) -> _Surface:
        emission = wa * a.emission + wb * b.emission
        if a.kind is None and b.kind is None:
            return _Surface(None, np.zeros(3), emission=emission)
        if a.kind is None or b.kind is None:
            s, w = (b, wb) if a.kind is None else (a, wa)
            return _Surface(s.kind, s.color * (w if s.kind == "DIFFUSE" else 1.0), s.ior, s.roughness, emission)
        if a.kind == b.kind:
            t = wb / max(wa + wb, 1e-12)
            col = wa * a.color + wb * b.color if node.bl_idname == "ShaderNodeAddShader" else (1 - t) * a.color + t * b.color
            return _Surface(a.kind, col, (1 - t) * a.ior + t * b.ior, (1 - t) * a.roughness + t * b.roughness, emission)
        keep = a if wa >= wb else b
        self.warn(f"{self.owner}: '{node.name}' mixes {a.kind.lower()} and {b.kind.lower()} surfaces: rendered as "
                  f"{keep.kind.lower()}")
        return _Surface(keep.kind, keep.color, keep.ior, keep.roughness, emission)


def _blackbody_rgb(temperature: float) -> np.ndarray:
    """Linear Rec.709 colour of a blackbody with luminance 1 (Blender's Blackbody node convention)."""
    from ..core.spectrum import SpectralConverter

    conv = _blackbody_rgb.conv = getattr(_blackbody_rgb, "conv", None) or SpectralConverter()
    t = float(temperature) if temperature > 0 else 6500.0
    return conv.to_rgb(conv.blackbody(t)).astype(np.float64)


def _image_mean(image) -> np.ndarray | None:
    """Average linear RGB of an image's pixels (sRGB-encoded images are decoded first)."""
    try:
        n = len(image.pixels)
        if n == 0:
            return None
        px = np.empty(n, np.float32)
        image.pixels.foreach_get(px)
        ch = max(int(image.channels), 1)
        rgb = px.reshape(-1, ch)[:, :3].astype(np.float64)
        if rgb.shape[1] < 3:
            rgb = np.repeat(rgb[:, :1], 3, axis=1)
        if not image.is_float and image.colorspace_settings.name in ("sRGB", "sRGB 2.1"):
            rgb = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
        return rgb.mean(axis=0)
    except Exception:  # unreadable or missing file: the caller falls back
        return None


# ============================================================================ materials
class _MaterialTable:
    """Material rows for the core, one per Blender material used, in first-use order."""

    def __init__(self, warn: _Warnings, to709):
        self.rows: list[dict] = []
        self.index: dict[str, int] = {}
        self.grating: list[dict | None] = []  # per row: grating settings or None
        self.warn, self.to709 = warn, to709

    def lookup(self, material) -> int:
        key = "\0default" if material is None else material.name_full  # unique across linked libraries
        if key in self.index:
            return self.index[key]
        row, grating = (dict(DEFAULT_MATERIAL), None) if material is None else self._convert(material)
        self.index[key] = len(self.rows)
        self.rows.append(row)
        self.grating.append(grating)
        return self.index[key]

    def _convert(self, mat) -> tuple[dict, dict | None]:
        owner = f"material '{mat.name}'"
        reader = _NodeReader(owner, self.warn, self.to709)
        nt = _node_tree(mat)
        surf = None
        if nt is not None:
            out = nt.get_output_node("CYCLES") or nt.get_output_node("ALL")
            if out is not None and out.inputs.get("Surface") is not None:
                surf = reader.surface(out.inputs["Surface"])
            else:
                self.warn(f"{owner}: no Material Output node: rendered black")
                surf = _Surface(None, np.zeros(3))
        if surf is None:  # no node tree: the viewport colour, like Workbench
            col = _rgb(mat.diffuse_color)
            col = col if self.to709 is None else self.to709 @ col
            surf = _Surface("MIRROR" if mat.metallic >= 0.5 and mat.roughness < ROUGH_AS_DIFFUSE else "DIFFUSE", col)
        kind = surf.kind or "DIFFUSE"
        color = surf.color if surf.kind is not None else np.zeros(3)
        row = {
            "name": mat.name[:63],
            "kind": kind,
            "color": tuple(float(c) for c in np.clip(color, 0.0, None)),
            "ior": float(surf.ior),
            "emission": tuple(float(c) for c in np.clip(surf.emission, 0.0, None)),
        }
        opal = getattr(mat, "opal", None)
        if kind == "DIELECTRIC":
            if not surf.ior >= 1.0:
                self.warn(f"{owner}: IOR {surf.ior:g} below 1 is raised to 1")
                row["ior"] = 1.0
            if opal is not None:
                row["dispersion"] = opal.dispersion
                row["abbe"] = float(opal.abbe_number)
        elif opal is not None and opal.dispersion != "NONE":
            self.warn(f"{owner}: dispersion is set but the surface is not glass-like: dispersion ignored")
        grating = None
        if opal is not None and opal.grating:
            problems = opal.grating_problems()
            if problems:
                raise SceneError(f"{owner}: " + "; ".join(problems))
            grating = {
                "grating": 1, "grating_type": opal.grating_type, "lattice": opal.lattice,
                "period": float(opal.period), "slit_width": float(opal.slit_width),
                "slit_count": int(opal.slit_count), "coherence_length": float(opal.coherence_length),
                "grating_direction": opal.grating_direction, "rotation": float(opal.rotation),
            }
            row.update(grating)
        return row, grating


# ============================================================================ geometry
@dataclass
class _MeshData:
    vertices: np.ndarray      # (V, 3) float64, object space
    triangles: np.ndarray     # (T, 3) int32
    slot: np.ndarray          # (T,) int32 material slot per triangle
    uv: np.ndarray | None     # (T, 3, 2) float32 per-corner UVs of triangles, or None
    face_dir: np.ndarray | None  # (T, 3) per-triangle grating attribute, or None
    name: str
    face_period: np.ndarray | None = None  # (T,) per-triangle period attribute (nm), or None


def _foreach(coll, attr: str, n: int, dtype, width: int = 1) -> np.ndarray:
    a = np.empty(n * width, dtype)
    if n:
        coll.foreach_get(attr, a)
    return a.reshape(n, width) if width > 1 else a


def _read_mesh(me, name: str, want_uv: bool) -> _MeshData:
    if hasattr(me, "calc_loop_triangles"):
        me.calc_loop_triangles()
    lt = me.loop_triangles
    nt, nv = len(lt), len(me.vertices)
    pos = me.attributes.get("position")
    if pos is not None and pos.data_type == "FLOAT_VECTOR":
        verts = _foreach(pos.data, "vector", nv, np.float32, 3)
    else:
        verts = _foreach(me.vertices, "co", nv, np.float32, 3)
    tris = _foreach(lt, "vertices", nt, np.int32, 3)
    # material slot per triangle: through the triangle -> face map when this Blender has it
    mi_attr = me.attributes.get("material_index")
    if hasattr(me, "loop_triangle_polygons") and nt:
        face = _foreach(me.loop_triangle_polygons, "value", nt, np.int32)
        if mi_attr is not None and mi_attr.domain == "FACE":
            slot = _foreach(mi_attr.data, "value", len(me.polygons), np.int32)[face]
        else:
            slot = np.zeros(nt, np.int32)
    else:
        face = None
        slot = _foreach(lt, "material_index", nt, np.int32)
    uv = face_dir = face_period = None
    if want_uv and nt:
        uvl = me.uv_layers.active
        if uvl is not None:
            loops = _foreach(lt, "loops", nt, np.int32, 3)
            uv_all = _foreach(uvl.uv if hasattr(uvl, "uv") else uvl.data, "vector" if hasattr(uvl, "uv") else "uv",
                              len(me.loops), np.float32, 2)
            uv = uv_all[loops]
        attr = me.attributes.get(GRATING_ATTRIBUTE)
        if attr is not None and attr.domain == "FACE" and attr.data_type == "FLOAT_VECTOR" and face is not None:
            face_dir = _foreach(attr.data, "vector", len(me.polygons), np.float32, 3)[face]
        attr = me.attributes.get(PERIOD_ATTRIBUTE)
        if attr is not None and attr.domain == "FACE" and attr.data_type == "FLOAT" and face is not None:
            face_period = _foreach(attr.data, "value", len(me.polygons), np.float32)[face]
    return _MeshData(verts.astype(np.float64), tris, slot, uv, face_dir, name, face_period)


def _tangents(md: _MeshData, gratings: list, tri_mat_local: np.ndarray, warn) -> np.ndarray:
    """Object-space grating vectors (T, 3) for one mesh: the UV map's U direction, the local X
    axis, or the per-face attribute, per the material's ``grating_direction`` (the core projects
    them onto each triangle and applies the material's rotation)."""
    v = md.vertices[md.triangles]
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    modes = np.array([g["grating_direction"] if g else "" for g in gratings], dtype=object)[tri_mat_local]
    t = np.zeros((len(md.triangles), 3))
    t[:] = (1.0, 0.0, 0.0)
    if (modes == "UV").any() and md.uv is None:
        warn(f"object '{md.name}': no UV map for the grating direction: using the object's local X axis")
    if md.uv is not None and (modes == "UV").any():
        duv1 = (md.uv[:, 1] - md.uv[:, 0]).astype(np.float64)
        duv2 = (md.uv[:, 2] - md.uv[:, 0]).astype(np.float64)
        det = duv1[:, 0] * duv2[:, 1] - duv2[:, 0] * duv1[:, 1]
        ok = (modes == "UV") & (np.abs(det) > 1e-20)
        tu = (e1 * duv2[:, 1:2] - e2 * duv1[:, 1:2]) / np.where(ok, det, 1.0)[:, None]
        t[ok] = tu[ok]
    if (modes == "ATTRIBUTE").any():
        if md.face_dir is not None:
            attr = modes == "ATTRIBUTE"
            t[attr] = md.face_dir[attr]
        else:
            warn(f"object '{md.name}': no '{GRATING_ATTRIBUTE}' face attribute: using the object's local X axis")
    return t


def _periods(md: _MeshData, has: np.ndarray, warn) -> np.ndarray:
    """Per-triangle period overrides (T,) nm for one mesh: the face attribute on grating
    triangles, 0 elsewhere (0: the material's period); NaN, infinite or negative values are 0."""
    out = np.zeros(len(md.triangles), np.float32)
    if md.face_period is None or not has.any():
        return out
    p = np.asarray(md.face_period, np.float32)
    bad = has & ~(np.isfinite(p) & (p >= 0))
    if bad.any():
        warn(f"object '{md.name}': {int(bad.sum())} face(s) have a NaN, infinite or negative "
             f"'{PERIOD_ATTRIBUTE}': using the material's period there")
    out[has] = np.where(np.isfinite(p[has]) & (p[has] > 0), p[has], 0.0)
    return out


def _transform(md: _MeshData, mats: np.ndarray):
    """World vertices (K*V, 3) and triangles for K instances (matrices (K, 4, 4)); mirrored
    instances get their winding flipped so normals keep pointing outwards."""
    k, nv = len(mats), len(md.vertices)
    verts = np.einsum("kij,vj->kvi", mats[:, :3, :3], md.vertices) + mats[:, None, :3, 3]
    det = np.linalg.det(mats[:, :3, :3])
    base = (np.arange(k, dtype=np.int64) * nv)[:, None, None]
    tris = np.broadcast_to(md.triangles[None].astype(np.int64), (k,) + md.triangles.shape) + base
    if (det < 0).any():
        tris = tris.copy()
        tris[det < 0] = tris[det < 0][:, :, [0, 2, 1]]
    return verts.reshape(-1, 3), tris.reshape(-1, 3), det


# ============================================================================ lights
def _light_color(light, warn, to709) -> tuple[np.ndarray, float, float]:
    """(Rec.709 colour, temperature K or 0, strength factor from the light's nodes)."""
    col = _rgb(light.color)
    col = col if to709 is None else to709 @ col
    temperature = 0.0
    if getattr(light, "use_temperature", False):
        if np.allclose(col, 1.0, atol=1e-4):
            temperature = float(light.temperature)
        else:  # tinted blackbody: an RGB product (the spectrum is approximated)
            tc = _rgb(light.temperature_color)
            col = col * (tc if to709 is None else to709 @ tc)
    strength = 1.0
    nt = light.node_tree if getattr(light, "use_nodes", False) else None
    if nt is not None:
        owner = f"light '{light.name}'"
        reader = _NodeReader(owner, warn, to709)
        out = nt.get_output_node("CYCLES") or nt.get_output_node("ALL")
        src = reader._source(out.inputs["Surface"]) if out is not None and out.inputs.get("Surface") else None
        if src is None:
            return col, temperature, 0.0
        node = src[0]
        if node.bl_idname != "ShaderNodeEmission":
            warn(f"{owner}: light node '{node.name}' is not supported: using the light's colour")
            return col, temperature, strength
        strength = max(reader.value(node, "Strength", 1.0), 0.0)
        csrc = reader._source(node.inputs["Color"])
        if csrc is not None and csrc[0].bl_idname == "ShaderNodeBlackbody":
            t_node = reader.value(csrc[0], "Temperature", 6500.0)
            if temperature == 0.0 and np.allclose(col, 1.0, atol=1e-4):
                temperature = t_node
            else:
                col = col * _blackbody_rgb(t_node)
        else:
            col = col * reader.color(node, "Color", (1, 1, 1))
    return col, temperature, strength


def _light_row(ob, m: np.ndarray, warn, to709, soft: list) -> dict | None:
    light = ob.data
    x, y, z = m[:3, 0], m[:3, 1], m[:3, 2]
    nz = np.linalg.norm(z)
    if not np.isfinite(m).all() or nz < 1e-12:
        raise SceneError(f"light '{ob.name}': its transform is NaN, infinite or has zero scale")
    col, temperature, strength = _light_color(light, warn, to709)
    power = float(light.energy) * 2.0 ** float(getattr(light, "exposure", 0.0)) * strength
    row = {
        "position": tuple(m[:3, 3]), "direction": tuple(-z / nz), "axis_u": tuple(x / max(np.linalg.norm(x), 1e-30)),
        "color": tuple(float(c) for c in np.clip(col, 0.0, None)), "power": max(power, 0.0),
        "temperature": temperature,
    }
    t = light.type
    if t in ("POINT", "SPOT"):
        if light.shadow_soft_size > 0:
            soft.append(ob.name)
        row["kind"] = t
        if t == "SPOT":
            row["spot_size"] = float(light.spot_size)
            row["spot_blend"] = float(light.spot_blend)
            if getattr(light, "use_square", False):
                warn(f"light '{ob.name}': square spot cones are rendered round")
            sx, sy = np.linalg.norm(x), np.linalg.norm(y)
            if abs(sx - sy) > 1e-3 * max(sx, sy):
                warn(f"light '{ob.name}': a non-uniformly scaled spot cone is rendered round")
    elif t == "SUN":
        row["kind"] = "SUN"
        if getattr(light, "angle", 0.0) > math.radians(1.0):
            soft.append(ob.name)
    elif t == "AREA":
        shape = light.shape
        su = float(light.size) * float(np.linalg.norm(x))
        sv = float(light.size_y if shape in ("RECTANGLE", "ELLIPSE") else light.size) * float(np.linalg.norm(y))
        row["kind"] = "AREA_RECT" if shape in ("SQUARE", "RECTANGLE") else "AREA_DISK"
        row["size_u"], row["size_v"] = su, sv
        if su <= 0 or sv <= 0:
            warn(f"light '{ob.name}': area light of zero size skipped")
            return None
        if not getattr(light, "normalize", True):  # Cycles: an unnormalised light emits power per m^2
            area = su * sv * (1.0 if row["kind"] == "AREA_RECT" else math.pi / 4)
            row["power"] *= area
        if getattr(light, "spread", math.pi) < math.pi - 1e-4:
            warn(f"light '{ob.name}': area light spread below 180 degrees is rendered as a full 180")
    else:
        warn(f"light '{ob.name}': light type {t} is not supported: skipped")
        return None
    return row


# ============================================================================ world, camera
def _world_color(world, warn, to709) -> np.ndarray:
    if world is None:
        return np.zeros(3)
    nt = _node_tree(world)
    if nt is None:
        col = _rgb(world.color)
        return col if to709 is None else to709 @ col
    owner = f"world '{world.name}'"
    reader = _NodeReader(owner, warn, to709)
    out = nt.get_output_node("CYCLES") or nt.get_output_node("ALL")
    if out is None or out.inputs.get("Surface") is None:
        return np.zeros(3)
    src = reader._source(out.inputs["Surface"])
    if src is None:
        return np.zeros(3)
    node = src[0]
    if node.bl_idname in ("ShaderNodeBackground", "ShaderNodeEmission"):
        return reader.color(node, "Color", (0.05, 0.05, 0.05)) * max(reader.value(node, "Strength", 1.0), 0.0)
    warn(f"{owner}: world shader '{node.name}' is not supported: using the world colour as a uniform background")
    col = _rgb(world.color)
    return col if to709 is None else to709 @ col


def _camera(cam_ob, width: int, height: int, scene, warn) -> Camera:
    cam = cam_ob.data
    if cam_ob.type != "CAMERA":
        raise SceneError(f"the active camera '{cam_ob.name}' is not a camera object")
    if cam.type not in ("PERSP", "ORTHO"):
        raise SceneError(f"camera '{cam_ob.name}': {cam.type.lower()} cameras are not supported; use a perspective "
                         "or orthographic camera")
    m = np.array(cam_ob.matrix_world, np.float64)
    if not np.isfinite(m).all():
        raise SceneError(f"camera '{cam_ob.name}': its transform is NaN or infinite")
    r = scene.render
    if abs(r.pixel_aspect_x - r.pixel_aspect_y) > 1e-6:
        warn("non-square pixel aspect is not supported: rendered with square pixels")
    if getattr(cam, "dof", None) is not None and cam.dof.use_dof:
        warn(f"camera '{cam_ob.name}': depth of field is not rendered (pinhole camera)")
    return Camera(
        matrix=m, kind=cam.type, lens=float(cam.lens), sensor_width=float(cam.sensor_width),
        sensor_height=float(cam.sensor_height), sensor_fit=cam.sensor_fit, ortho_scale=float(cam.ortho_scale),
        shift_x=float(cam.shift_x), shift_y=float(cam.shift_y), width=int(width), height=int(height),
    )


# ============================================================================ the export
def export_scene(depsgraph, *, width: int | None = None, height: int | None = None, camera=None,
                 test_break=None, progress=None) -> ExportResult:
    """Export the evaluated ``depsgraph`` to a core Scene.

    ``width``/``height`` default to the scene's resolution times its percentage; ``camera``
    (an object) overrides the scene camera. ``test_break()`` is polled every few dozen object
    instances (raise ExportCancelled when it returns True); ``progress(message)`` receives a
    status line now and then. Raises SceneError with a readable message for input that
    cannot be rendered (NaN coordinates, a panoramic camera, ...).
    """
    t0 = time.perf_counter()
    warn = _Warnings()
    to709 = working_space_to_rec709()
    scene = depsgraph.scene
    if width is None or height is None:
        width, height = render_size(scene)
    materials = _MaterialTable(warn, to709)
    mesh_cache: dict = {}
    groups: dict = defaultdict(list)  # (mesh key, material tuple) -> matrices
    lights: list[dict] = []
    soft: list[str] = []
    skipped: dict[str, int] = defaultdict(int)
    n_instances = 0

    for i, inst in enumerate(depsgraph.object_instances):
        if i % POLL_EVERY == 0:
            if test_break is not None and test_break():
                raise ExportCancelled()
            if progress is not None and i:
                progress(f"exporting: {i} objects")
        ob = inst.object
        otype = ob.type
        if otype == "LIGHT":
            row = _light_row(ob, np.array(inst.matrix_world, np.float64), warn, to709, soft)
            if row is not None:
                lights.append(row)
            continue
        if otype not in GEOMETRY_TYPES:
            if otype in UNSUPPORTED_GEOMETRY:
                skipped[otype.lower()] += 1
            continue
        if not inst.show_self:
            continue
        data = ob.data
        mkey = ("data", data.as_pointer()) if (otype == "MESH" and data is not None) else ("obj", ob.name)
        slots = tuple(materials.lookup(s.material) for s in ob.material_slots) or (materials.lookup(None),)
        if mkey not in mesh_cache:
            mesh_cache[mkey] = _mesh_for(ob, otype)
        md = mesh_cache[mkey]
        if md is None or len(md.triangles) == 0:
            continue
        groups[(mkey, slots)].append(np.array(inst.matrix_world, np.float64))
        n_instances += 1

    # ---------------------------------------------------------------- flatten
    if test_break is not None and test_break():
        raise ExportCancelled()
    any_grating = any(g is not None for g in materials.grating)
    vert_chunks, tri_chunks, mat_chunks, tan_chunks, per_chunks = [], [], [], [], []
    n_verts = 0
    for (mkey, slots), mlist in groups.items():
        md = mesh_cache[mkey]
        mats = np.stack(mlist)
        if not np.isfinite(mats).all():
            raise SceneError(f"object '{md.name}': its transform is NaN or infinite")
        slot_map = np.asarray(slots, np.int32)
        tri_mat_local = slot_map[np.clip(md.slot, 0, len(slot_map) - 1)]
        verts, tris, det = _transform(md, mats)
        vert_chunks.append(verts)
        tri_chunks.append(tris + n_verts)
        mat_chunks.append(np.tile(tri_mat_local, len(mats)))
        if any_grating:
            grat = [materials.grating[j] for j in range(len(materials.rows))]
            has = np.array([g is not None for g in grat])[tri_mat_local]
            if has.any():
                t_local = _tangents(md, grat, tri_mat_local, warn)
                t_world = np.einsum("kij,tj->kti", mats[:, :3, :3], t_local)
                t_world /= np.maximum(np.linalg.norm(t_world, axis=2, keepdims=True), 1e-30)
                t_world[:, ~has] = 0.0
                tan_chunks.append(t_world.reshape(-1, 3).astype(np.float32))
            else:
                tan_chunks.append(np.zeros((len(mats) * len(md.triangles), 3), np.float32))
            per_chunks.append(np.tile(_periods(md, has, warn), len(mats)))
        n_verts += len(verts)
    vertices = np.concatenate(vert_chunks).astype(np.float32) if vert_chunks else np.zeros((0, 3), np.float32)
    triangles = np.concatenate(tri_chunks).astype(np.int32) if tri_chunks else np.zeros((0, 3), np.int32)
    tri_material = np.concatenate(mat_chunks).astype(np.int32) if mat_chunks else np.zeros(0, np.int32)
    tri_period = np.zeros(0, np.float32)
    if any_grating and per_chunks and any(p.any() for p in per_chunks):
        tri_period = np.concatenate(per_chunks).astype(np.float32)
    if n_verts >= 2**31:
        raise SceneError(f"the scene has {n_verts} vertices, more than a 32-bit index can address")

    # ---------------------------------------------------------------- the rest
    if soft:
        names = ", ".join(f"'{n}'" for n in soft[:3]) + (" ..." if len(soft) > 3 else "")
        warn(f"light radius and sun angle are not rendered yet: {names} cast hard shadows")
    for kind, count in skipped.items():
        warn(f"{count} {kind} object(s) are not supported and were skipped")
    if not materials.rows:
        materials.lookup(None)
    cam_ob = camera if camera is not None else scene.camera
    cam = None
    if cam_ob is not None:
        cam_eval = cam_ob.evaluated_get(depsgraph) if not cam_ob.is_evaluated else cam_ob
        cam = _camera(cam_eval, width, height, scene, warn)
    world = _world_color(scene.world, warn, to709)
    core_scene = Scene(
        vertices=vertices, triangles=triangles, tri_material=tri_material,
        materials=Materials.from_list(materials.rows), lights=Lights.from_list(lights), camera=cam,
        world_color=np.clip(world, 0.0, None).astype(np.float32),
        tri_tangent=np.concatenate(tan_chunks) if (any_grating and tan_chunks) else np.zeros((0, 3), np.float32),
        tri_period=tri_period,
    )
    stats = {
        "export_s": time.perf_counter() - t0, "objects": n_instances, "meshes": len(mesh_cache),
        "triangles": len(triangles), "vertices": len(vertices), "lights": len(lights),
        "materials": len(materials.rows),
    }
    return ExportResult(core_scene, warn.items, stats)


def _mesh_for(ob, otype: str) -> _MeshData | None:
    """Triangles of an evaluated object (modifiers applied), object space; None if it has none."""
    want_uv = any(s.material is not None and getattr(s.material, "opal", None) is not None and s.material.opal.grating
                  for s in ob.material_slots)
    if otype == "MESH":
        md = _read_mesh(ob.data, ob.name, want_uv)
    else:
        try:
            me = ob.to_mesh()
        except RuntimeError:
            return None
        try:
            md = None if me is None else _read_mesh(me, ob.name, want_uv)
        finally:
            ob.to_mesh_clear()
    if md is not None and len(md.vertices) and not np.isfinite(md.vertices).all():
        bad = int((~np.isfinite(md.vertices).all(axis=1)).sum())
        raise SceneError(f"object '{ob.name}': {bad} vertex coordinate(s) are NaN or infinite; fix or delete them")
    return md
