"""The Blender world -> the core's world light: a uniform colour, an equirectangular map with its
multiplier and rotation, or any node tree baked into a map, a Sky Texture's sun disc as a sun
lamp (linear Rec.709, Cycles' units).

A Background or Emission shader whose Color is an Environment Texture node (equirectangular
projection) exports that node's image (``images.read_image``: linear Rec.709, row 0 at the
bottom) as ``Scene.world_image``, the shader's Strength as ``Scene.world_color`` (the map's
multiplier), and the Mapping node on the texture's Vector (fed by Texture Coordinate Generated
or Object, or nothing: the ray direction) as ``Scene.world_rotation``, the world -> map
rotation Cycles applies (``kernel/svm/mapping_util.h``: POINT and VECTOR map a direction v to
R S v, TEXTURE to R^T v / S, NORMAL to R v / S, with R = Rz Ry Rx from the Euler angles; the
texture then normalises, so only the signs of a uniform scale matter). Approximated, with a
warning naming the world and the node: a mirror-ball projection and other colour sources
(averaged, or the socket's value, as for materials), a Mapping location or non-uniform scale
(ignored), interpolation other than Linear (rendered Linear). A missing image renders magenta
times the strength, as in Cycles (checked: Cycles 5.0 shows (1, 0, 1) for an Environment
Texture with no image or a missing file). Without a node tree: the world's viewport colour. A
NaN colour or strength is an error naming the world, a huge one is clamped with a warning.

Any other node graph on the shader's Color or Strength (docs/physics.md section 7.12) is compiled
by export/shader_compiler.py into a shader program (Color x Strength) and evaluated at the texel
centres of a BAKE_WIDTH x BAKE_HEIGHT map with the ray direction as Generated and Object (Cycles'
background coordinates); a graph that reads no coordinate is a uniform colour. A Sky Texture
(core/materials/sky_texture.py) straight on the Color, with a plain Strength, is baked without
its sun disc, and the disc becomes a SUN row of ``WorldLight.lights`` (its direction, angular
diameter and integrated irradiance): what the scene's light table adds from the world.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...core.lights.environment import uv_to_direction
from ...core.materials.shader_eval import evaluate
from ...core.materials.sky_texture import SKY_TYPES, sky_params, sun_direction, sun_irradiance
from ...core.materials.textures import sample_texture
from ...core.scene.checks import SceneError
from ...core.scene.model import TEXTURE_EXTENSIONS, TEXTURE_INTERPOLATIONS
from .colour import in_rec709, rgb, working_space_to_rec709
from .images import TextureTable, read_image
from .messages import Warnings
from .nodes import MAX_INTENSITY, NodeReader, missing_output, node_tree, output_node, surface_socket
from .volumes import read_volume
from .shader_compiler import ShaderCompiler

__all__ = ["WorldLight", "world_light", "world_volume", "export_world_volume", "world_color", "export_world", "export_world_light", "mapping_rotation",
           "MISSING_IMAGE_RGB", "bake_program", "BAKE_HEIGHT", "BAKE_WIDTH"]

#: What Cycles shows for an image texture without pixels (kernel/svm/image.h: IMAGE_TEXTURE_MISSING_RGBA).
MISSING_IMAGE_RGB = (1.0, 0.0, 1.0)


@dataclass
class WorldLight:
    """The world as the core takes it: ``color`` (3,), the uniform radiance or, with an image,
    its multiplier; ``image`` (H, W, 3) float32 or (0, 0, 3); ``rotation`` (3, 3) world -> map."""

    color: np.ndarray
    image: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 3), np.float32))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    #: Light-table rows (Lights.from_list dicts) the world adds: a Sky Texture's sun disc as a sun.
    lights: list = field(default_factory=list)


def world_volume(world, warn, to709) -> dict | None:
    """The medium columns of the World Output's Volume (docs/physics.md section 15; export/volumes.py):
    the whole scene outside closed meshes in that medium; None: none."""
    if world is None:
        return None
    nt = node_tree(world)
    out = output_node(nt) if nt is not None else None
    sock = out.inputs.get("Volume") if out is not None else None
    if sock is None:
        return None
    reader = NodeReader(f"world '{world.name}'", warn, to709)
    if reader.source(sock) is None:
        return None
    return read_volume(reader, sock)


def world_color(world, warn, to709) -> np.ndarray:
    """The world's colour (3,) (None: black), unclipped: with an environment map, its multiplier."""
    return world_light(world, warn, to709).color


def world_light(world, warn, to709) -> WorldLight:
    """``world`` (None: black) as a :class:`WorldLight`, colour unclipped."""
    if world is None:
        return WorldLight(np.zeros(3))
    owner = f"world '{world.name}'"
    nt = node_tree(world)
    if nt is None:
        return WorldLight(_viewport_color(world, owner, to709))
    reader = NodeReader(owner, warn, to709)
    sock = surface_socket(nt)
    if sock is None:
        warn(f"{owner}: {missing_output(nt, 'World Output')}: the background is black, as in Cycles")
        return WorldLight(np.zeros(3))
    src = reader.source(sock)
    if reader.cycle is not None:
        warn(f"{owner}: its node tree has a cycle (through the link {reader.cycle}): using the world colour")
        return WorldLight(_viewport_color(world, owner, to709))
    if src is None:
        return WorldLight(np.zeros(3))
    node = src[0]
    if node.bl_idname in ("ShaderNodeBackground", "ShaderNodeEmission"):
        col_src = reader.source(node.inputs["Color"]) if node.inputs.get("Color") is not None else None
        if (col_src is not None and col_src[0].bl_idname == "ShaderNodeTexEnvironment"
                and not getattr(col_src[0], "mute", False)):
            env = col_src[0]
            if env.projection == "EQUIRECTANGULAR" or env.image is None:
                return _environment(reader, node, env, owner, warn)
            warn(f"{owner}: Environment Texture '{env.name}' uses the mirror-ball projection, which is not "
                 "supported: rendered as the image's average colour")
        elif _driven(reader, node):
            baked = _baked(reader, node, owner, warn)
            if baked is not None:
                return baked
        return WorldLight(reader.emission(reader.color(node, "Color", (0.05, 0.05, 0.05)), reader.strength(node), node))
    warn(f"{owner}: world shader '{node.name}' is not supported: using the world colour as a uniform background")
    return WorldLight(_viewport_color(world, owner, to709))


#: The baked map of a world node tree: rows (elevation) x columns (azimuth), 0.35 degree texels.
BAKE_HEIGHT, BAKE_WIDTH = 512, 1024
#: Rows evaluated at once while baking.
_BAKE_CHUNK = 65536


def _driven(reader: NodeReader, shader) -> bool:
    """Whether a node drives the Color or the Strength of the world's ``shader``."""
    return any(shader.inputs.get(n) is not None and reader.source(shader.inputs[n]) is not None
               for n in ("Color", "Strength"))


def _lamp_sky(reader: NodeReader, shader):
    """The Sky Texture node whose sun disc becomes a sun lamp, or None: the sky straight on the
    shader's Color (its Vector the ray direction), the Strength a plain number, the disc on."""
    src = reader.source(shader.inputs["Color"])
    if src is None or src[0].bl_idname != "ShaderNodeTexSky" or getattr(src[0], "mute", False):
        return None
    sky = src[0]
    if sky.sky_type not in SKY_TYPES or not sky.sun_disc or reader.source(shader.inputs["Strength"]) is not None:
        return None
    sock = sky.inputs.get("Vector")
    vec = reader.source(sock) if sock is not None else None
    if vec is not None and not (vec[0].bl_idname == "ShaderNodeTexCoord" and vec[1].name in ("Generated", "Object")
                                and getattr(vec[0], "object", None) is None):
        return None
    return sky


def _baked(reader: NodeReader, shader, owner: str, warn) -> WorldLight | None:
    """The world's node graph (what drives the Background's Color and Strength) compiled to a
    shader program and evaluated at the texel centres of an equirectangular map (the direction as
    Generated and Object), Cycles' background of a node tree; a Sky Texture's sun disc becomes a
    sun lamp where the sky lights the world alone. None when nothing in the graph is read."""
    reader.textures = TextureTable(warn)  # images inside the graph, read for the bake
    compiler = ShaderCompiler(reader)
    compiler.world = True
    reader.compiler = compiler
    sky = _lamp_sky(reader, shader)
    if sky is not None:
        compiler.sky_sun_lamps = frozenset([sky.name])
    b = compiler.builder
    col = compiler.compile_input(shader, "Color", "v")
    strength = compiler.compile_input(shader, "Strength", "f")
    if col is None and strength is None:
        return None  # the caller warns and uses the sockets' values
    if col is None:
        col = b.const([float(c) for c in reader.color(shader, "Color", (0.05, 0.05, 0.05))])
    if strength is None:
        strength = b.const(reader.strength(shader))
    zero = b.const([0.0, 0.0, 0.0])
    out = b.op("vector_math", [col, zero, zero, strength], operation="SCALE")[0]
    program = compiler.finish({"emission": out})
    if not any(program.ops[i].name == "coord" for i in program.needed("emission")):  # the same everywhere
        one = np.zeros((1, 3), np.float32)
        value = evaluate(program, "emission", {"generated": one, "object": one, "uv": one}, 1)[0]
        return WorldLight(np.minimum(np.asarray(value, np.float64), MAX_INTENSITY))
    image = bake_program(program, reader.textures)
    if (image < 0).any():
        warn(f"{owner}: its node tree gives negative radiance in some directions: rendered as 0")
    image = np.maximum(image, 0.0)
    if not np.isfinite(image).all() or image.max() > MAX_INTENSITY:
        warn(f"{owner}: its node tree gives radiance above {MAX_INTENSITY:.0e}: clamped")
        image = np.minimum(np.nan_to_num(image, nan=0.0, posinf=MAX_INTENSITY), MAX_INTENSITY)
    lights = []
    if sky is not None:
        row = _sun_lamp(sky, reader.strength(shader))
        if row is not None:
            lights.append(row)
    return WorldLight(np.ones(3), image.astype(np.float32), np.eye(3), lights)


def bake_program(program, textures: TextureTable | None = None) -> np.ndarray:
    """(BAKE_HEIGHT, BAKE_WIDTH, 3) float32 linear Rec.709 radiance: the program's 'emission'
    at each texel centre's direction (core/lights/environment.py convention, row 0 at the bottom);
    ``textures``: the images its image ops read (core/materials/textures.py ``sample_texture``)."""
    images = None
    if textures is not None and len(textures):
        interp = [TEXTURE_INTERPOLATIONS[x] for x in textures.interpolation]
        ext = [TEXTURE_EXTENSIONS[x] for x in textures.extension]

        def images(k, uv):
            return sample_texture(textures.pixels[k], uv, interp[k], ext[k], textures.encoding[k])
    h, w = BAKE_HEIGHT, BAKE_WIDTH
    u = (np.arange(w) + 0.5) / w
    v = (np.arange(h) + 0.5) / h
    uu, vv = np.broadcast_arrays(u[None, :], v[:, None])
    d = uv_to_direction(uu, vv).reshape(-1, 3).astype(np.float32)
    out = np.empty((len(d), 3), np.float32)
    for s in range(0, len(d), _BAKE_CHUNK):
        chunk = d[s:s + _BAKE_CHUNK]
        inputs = {"generated": chunk, "object": chunk, "uv": np.zeros_like(chunk)}
        out[s:s + _BAKE_CHUNK] = evaluate(program, "emission", inputs, len(chunk), images)
    return out.reshape(h, w, 3)


def _sun_lamp(sky, strength: float) -> dict | None:
    """A SUN light-table row for ``sky``'s disc: its direction and angular diameter, its
    irradiance the disc's radiance integrated over it (sky_texture.sun_irradiance) times the
    world's strength; None when the disc is dark (below the horizon or behind the earth)."""
    p = sky_params(sky.sky_type, sky.sun_disc, sky.sun_size, sky.sun_intensity, sky.sun_elevation,
                   sky.sun_rotation, sky.altitude, sky.air_density, sky.aerosol_density, sky.ozone_density)
    irradiance = sun_irradiance(p) * strength
    peak = float(irradiance.max())
    if not peak > 0 or not np.isfinite(peak):
        return None
    return {"kind": "SUN", "direction": tuple(-sun_direction(p)), "power": min(peak, MAX_INTENSITY),
            "color": tuple(irradiance / peak), "angle": p.sun_size,
            "camera_visible": 1}  # the disc is part of the sky Cycles' camera rays see


def _environment(reader: NodeReader, shader, env, owner: str, warn) -> WorldLight:
    """A Background/Emission ``shader`` lit by Environment Texture ``env`` (equirectangular)."""
    strength = reader.strength(shader)
    image = env.image
    has_pixels = image is not None and image.size[0] * image.size[1] > 0 and image.channels > 0
    px = read_image(image, warn, owner) if has_pixels else None
    if px is None:
        what = f"image '{image.name}' has no pixels (missing file '{image.filepath}'?)" if image is not None \
            else "has no image"
        warn(f"{owner}: Environment Texture '{env.name}' {what}: the world is magenta, as in Cycles")
        return WorldLight(reader.emission(np.array(MISSING_IMAGE_RGB), strength, shader))
    rgb_img = np.ascontiguousarray(px[..., :3], np.float32)
    if not np.isfinite(rgb_img).all():
        raise SceneError(f"{owner}: image '{image.name}' of '{env.name}' holds NaN or infinite pixels")
    if (rgb_img < 0).any():  # float images may hold negative values (out-of-gamut colours)
        warn(f"{owner}: image '{image.name}' has negative values: clamped to 0")
        rgb_img = np.maximum(rgb_img, 0.0)
    peak = float(rgb_img.max()) * strength
    if peak > MAX_INTENSITY:
        warn(f"{owner}: image '{image.name}' times the strength of '{shader.name}' ({peak:.3g}) is above "
             f"{MAX_INTENSITY:.0e}: clamped")
        rgb_img = np.minimum(rgb_img, np.float32(MAX_INTENSITY / max(strength, 1e-30)))
    if env.interpolation != "Linear":
        warn(f"{owner}: Environment Texture '{env.name}' interpolation '{env.interpolation}' is rendered as Linear")
    rotation = _vector_rotation(reader, env, owner, warn)
    return WorldLight(np.full(3, strength), rgb_img, rotation)


def _vector_rotation(reader: NodeReader, env, owner: str, warn) -> np.ndarray:
    """The world -> map rotation of what feeds ``env``'s Vector: nothing, Texture Coordinate
    Generated / Object (the ray direction), or a Mapping node on one of those."""
    src = reader.source(env.inputs["Vector"])
    if src is None:
        return np.eye(3)
    node, out = src
    if node.bl_idname == "ShaderNodeMapping":
        rot = mapping_rotation(node, owner, warn)
        inner = reader.source(node.inputs["Vector"])
        if inner is None:
            warn(f"{owner}: the Vector of Mapping '{node.name}' is not linked: using the ray direction")
        elif not _is_direction(*inner, owner, warn):
            return np.eye(3)
        return rot
    _is_direction(node, out, owner, warn)  # warns when it is not the ray direction
    return np.eye(3)


def _is_direction(node, out, owner: str, warn) -> bool:
    """Whether (node, output) is the world's ray direction (Texture Coordinate Generated, or
    Object without an object); else a warning, and the ray direction is used."""
    if node.bl_idname == "ShaderNodeTexCoord" and out.name in ("Generated", "Object"):
        if out.name == "Object" and getattr(node, "object", None) is not None:
            warn(f"{owner}: Texture Coordinate '{node.name}' Object output of object '{node.object.name}' is not "
                 "supported for the world: using the ray direction")
            return False
        return True
    warn(f"{owner}: '{node.name}' ({out.name}) driving the environment's Vector is not supported: "
         "using the ray direction")
    return False


def _euler_xyz(angles) -> np.ndarray:
    """Blender's XYZ Euler rotation: Rz Ry Rx."""
    x, y, z = (float(a) for a in angles)
    cx, sx, cy, sy, cz, sz = np.cos(x), np.sin(x), np.cos(y), np.sin(y), np.cos(z), np.sin(z)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def mapping_rotation(node, owner: str, warn) -> np.ndarray:
    """The world -> map rotation (3, 3) a Mapping node applies to a direction, as Cycles: POINT and
    VECTOR R S v, TEXTURE R^T v / S, NORMAL R v / S; of the scale only its signs matter after
    the texture normalises (a non-uniform one is warned about), the location is ignored (warned)."""
    def socket(name, default):
        s = node.inputs.get(name)
        if s is None:
            return np.array(default, np.float64)
        if s.is_linked:
            warn(f"{owner}: Mapping '{node.name}' {name} is driven by a node: using its own value")
        return np.array(s.default_value[:], np.float64)

    vtype = node.vector_type
    rot = _euler_xyz(socket("Rotation", (0, 0, 0)))
    scale = socket("Scale", (1, 1, 1))
    if vtype in ("POINT", "TEXTURE") and np.any(socket("Location", (0, 0, 0)) != 0):
        warn(f"{owner}: Mapping '{node.name}' location is ignored for the environment (a direction has no position)")
    if not np.isfinite(rot).all() or not np.isfinite(scale).all():
        raise SceneError(f"{owner}: Mapping '{node.name}' rotation or scale is NaN or infinite")
    mag = np.abs(scale)
    if np.any(mag == 0) or mag.max() > mag.min() * (1 + 1e-6):
        warn(f"{owner}: Mapping '{node.name}' non-uniform or zero scale {tuple(np.round(scale, 4))} is ignored "
             "for the environment (only its signs are kept)")
    sign = np.diag(np.where(scale < 0, -1.0, 1.0))
    if vtype == "TEXTURE":
        return sign @ rot.T
    return rot @ sign


def _viewport_color(world, owner: str, to709) -> np.ndarray:
    col = in_rec709(rgb(world.color), to709)
    if np.isnan(col).any():
        raise SceneError(f"{owner}: its colour is NaN")
    return np.minimum(col, MAX_INTENSITY)


def export_world_light(depsgraph, warn: Warnings | None = None) -> WorldLight:
    """The core's world (``Scene.world_color``, ``world_image``, ``world_rotation``) as
    :func:`export_scene` makes it: the colour clipped to >= 0 and float32. ``warn``: collects
    the warnings (default: dropped)."""
    light = world_light(depsgraph.scene.world, warn if warn is not None else Warnings(), working_space_to_rec709())
    light.color = np.clip(light.color, 0.0, None).astype(np.float32)
    return light


def export_world_volume(depsgraph, warn: Warnings | None = None) -> dict | None:
    """The world's medium columns (``world_volume``) as :func:`export_scene` reads them."""
    return world_volume(depsgraph.scene.world, warn if warn is not None else Warnings(), working_space_to_rec709())


def export_world(depsgraph, warn: Warnings | None = None) -> np.ndarray:
    """The core's ``Scene.world_color`` alone, (3,) float32, as :func:`export_scene` makes it."""
    return export_world_light(depsgraph, warn).color
