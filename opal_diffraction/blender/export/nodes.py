"""Shader node trees -> the core's surface kinds: what a material, light or world shader evaluates to.

Follows a node tree from its output node through reroutes, mix and add shaders, and evaluates
the BSDF it finds to one of the core's surfaces (diffuse, mirror, dielectric) with a colour, an
IOR, an emission and the rough-surface columns (core/materials/bsdf.py: roughness, Principled's metallic /
transmission weights, IOR level, specular tint, the metal's Fresnel). Mix and Add Shaders of
unlike BSDFs become lobe mixtures (docs/physics.md section 14.8): the layers' weights summed,
each layer with its own colour, a Mix's Fac from a Fresnel or Layer Weight node read per hit. Image Texture nodes on a
BSDF's colour, roughness, metallic or emission colour and, through a tangent-space Normal Map
node, on its normal are bound as textures sampled per hit (:class:`TextureRef`,
``Surface.textures``; docs/physics.md section 13) with their coordinates (the UV map, or
Generated) and any Mapping node folded in. Procedural textures and converters on those inputs
(Noise, Voronoi, Checker, ColorRamp, Math, Mix, node groups, ...) are compiled into the
material's shader program (export/shader_compiler.py, ``Surface.programs``; docs/physics.md
section 13.6), evaluated per hit; so are a Bump node's Height on a BSDF's Normal (section 13.7)
and a Normal Map node's Color in object or world space or from anything but a plain image
(section 13.5). Node groups are inlined on the shader path too (a BSDF or Mix Shader inside a
group): :meth:`NodeReader.source` follows a Group Input out to the group node's input. What the core cannot represent is approximated and
named in the warnings: other textures and procedural nodes are averaged
(:func:`images.image_mean`) or use the socket's own value, anisotropy is dropped, a
physical-conductor Metallic BSDF is fitted with the F82-tint model.

Nothing a node tree holds can hang the export or reach the tracer as NaN or Inf: a node cycle
(Blender marks one link of it invalid) is detected and named (:attr:`NodeReader.cycle`; the
material then renders as the default surface), other invalid links are ignored as Cycles
ignores them, a NaN input is an error naming the owner, node and socket, and an emission
strength or colour beyond ``MAX_INTENSITY`` (Blender's fields go up to FLT_MAX) is clamped with a
warning, as is a negative strength.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import bpy
import numpy as np
from mathutils import Euler

from ...core.scene.checks import IOR_MAX as MAX_IOR, SceneError
from .colour import blackbody_rgb, in_rec709, rgb
from .images import image_mean
from .messages import Warnings

__all__ = ["MAX_INTENSITY", "Surface", "TextureRef", "node_tree", "output_node", "missing_output",
           "surface_socket", "NodeReader", "TEXTURE_SOCKETS"]

#: The largest emission (colour x strength, W/(m^2 sr) per colour unit) and light power (W, or
#: W/m^2 for a sun) exported; larger values are clamped with a warning. Blender's fields accept up
#: to FLT_MAX (3.4e38), which overflows the tracer's float32 arithmetic into Inf pixels; 1e20
#: leaves 18 orders of magnitude for the 1/r^2 falloff, spectral weights and sample sums.
MAX_INTENSITY = 1e20
#: Cycles' colour -> float conversion (linear_rgb_to_gray): Rec.709 luminance.
_LUMINANCE = np.array([0.2126729, 0.7151522, 0.0721750])
#: Cycles' colour for a missing image (TEX_IMAGE_MISSING_R/G/B).
_MISSING_RGB = (1.0, 0.0, 1.0)
#: Output node types, and what Blender calls them.
OUTPUT_NODES = {"ShaderNodeOutputMaterial": "Material Output", "ShaderNodeOutputWorld": "World Output",
                "ShaderNodeOutputLight": "Light Output"}


@dataclass
class TextureRef:
    """An Image Texture bound to a surface input: the export's texture number
    (:class:`images.TextureTable`), its coordinates and the Mapping folded into them."""

    index: int
    coords: str          # 'UV' or 'GENERATED'
    uv_map: str          # the UV map ('': the mesh's active render map) of its coordinates
    matrix: np.ndarray   # 4x4: (u, v, 0, 1) or generated (x, y, z, 1) -> the texture's (u, v) in its first two rows
    node: str            # the Image Texture node's name, for warnings
    strength: float = 1.0  # a Normal Map node's strength, an emission's strength
    tangent_map: str | None = None  # a normal map's: the UV map of its tangents ('': the active render map)
    channel: int = -1    # a float input's: -1 the colour's luminance, 0/1/2 R/G/B (a Separate Color node), 3 alpha

    def same_coordinates(self, other: "TextureRef") -> bool:
        return (self.coords, self.uv_map) == (other.coords, other.uv_map) and np.allclose(self.matrix, other.matrix)


@dataclass
class Surface:
    """What a shader evaluates to, in the core's terms."""

    kind: str | None  # 'DIFFUSE' | 'MIRROR' | 'DIELECTRIC' (the heaviest layer); None: no BSDF (emission only or black)
    color: np.ndarray
    ior: float = 1.5
    roughness: float = 0.0
    emission: np.ndarray = field(default_factory=lambda: np.zeros(3))
    # image textures per slot ('color', 'roughness', 'metallic', 'emission', 'normal')
    textures: dict = field(default_factory=dict)
    metallic: float | None = None       # layer weights (core Materials); None: from the kind
    transmission: float | None = None
    specular_ior_level: float = 0.0     # the base's specular layer (Principled); 0: none
    specular_tint: np.ndarray = field(default_factory=lambda: np.ones(3))
    conductor_fresnel: str = "CONSTANT"  # 'CONSTANT' (Glossy BSDF) | 'F82_TINT' (Principled, Metallic BSDF)
    # what the glass's colour is the colour of (docs/physics.md section 2.7): 'REFRACTION' (Glass /
    # Refraction BSDF: Cycles tints each refraction by Color) | 'PASS' (Principled: sqrt(Base Color)
    # per refraction, so one pass through a closed object gives Base Color)
    glass_tint: str = "REFRACTION"
    # shader-program registers per slot ('color', 'roughness', 'metallic', 'emission'), compiled by
    # the reader's ShaderCompiler (docs/physics.md section 13.6); empty: none
    programs: dict = field(default_factory=dict)
    # Principled's Thin Film (docs/physics.md section 2.8): thickness (nm; 0: none) and the film's IOR
    thin_film_thickness: float = 0.0
    thin_film_ior: float = 1.33
    # a shader mix of unlike BSDFs as a lobe mixture (docs/physics.md section 14.8): the metal and
    # glass layers' own colours (None: ``color``), and a Fresnel / Layer Weight Fac per hit
    # (LayerFac name; the layer ``layer_fac_to`` (0 base, 1 metal, 2 glass) weighs the Fac)
    metal_color: np.ndarray | None = None
    glass_color: np.ndarray | None = None
    layer_fac: str = "CONSTANT"
    layer_fac_value: float = 0.5
    layer_fac_from: int = 0
    layer_fac_to: int = 1
    diffuse_roughness: float = 0.0  # a Diffuse BSDF's Roughness: Oren-Nayar's sigma (0: Lambert)
    holdout: float = 0.0  # a Holdout shader's weight (Film > Transparent: alpha 1 - holdout; docs/physics.md 14.8)
    # Principled's coat and sheen over the rest (docs/physics.md section 14.10); weight 0: none
    coat_weight: float = 0.0
    coat_roughness: float = 0.03
    coat_ior: float = 1.5
    coat_tint: np.ndarray = field(default_factory=lambda: np.ones(3))
    sheen_weight: float = 0.0
    sheen_roughness: float = 0.5
    sheen_tint: np.ndarray = field(default_factory=lambda: np.ones(3))

    def layers(self) -> tuple[float, float]:
        """(metallic, transmission), from the kind where not given."""
        m = self.metallic if self.metallic is not None else float(self.kind == "MIRROR")
        t = self.transmission if self.transmission is not None else float(self.kind == "DIELECTRIC")
        return m, t

    def layer_weights(self) -> np.ndarray:
        """(3,) the weights of the base, metal and glass layers (summing to 1; zeros: no BSDF)."""
        if self.kind is None:
            return np.zeros(3)
        m, t = self.layers()
        return np.array([(1.0 - m) * (1.0 - t), m, (1.0 - m) * t])

    def layer_color(self, i: int) -> np.ndarray:
        """The colour of layer ``i`` (0 base, 1 metal, 2 glass)."""
        own = (None, self.metal_color, self.glass_color)[i]
        return np.asarray(self.color if own is None else own, np.float64)



#: Shader inputs that may take an image texture, per node type: socket name -> texture slot.
TEXTURE_SOCKETS = {
    "ShaderNodeBsdfPrincipled": {"Base Color": "color", "Roughness": "roughness", "Metallic": "metallic",
                                 "Emission Color": "emission", "Emission": "emission"},
    "ShaderNodeBsdfDiffuse": {"Color": "color"},
    "ShaderNodeBsdfGlossy": {"Color": "color", "Roughness": "roughness"},
    "ShaderNodeBsdfAnisotropic": {"Color": "color", "Roughness": "roughness"},
    "ShaderNodeBsdfMetallic": {"Base Color": "color", "Roughness": "roughness"},
    "ShaderNodeBsdfGlass": {"Color": "color", "Roughness": "roughness"},
    "ShaderNodeBsdfRefraction": {"Color": "color", "Roughness": "roughness"},
    "ShaderNodeEmission": {"Color": "emission"},
}


def node_tree(id_data):
    """The shader node tree an ID renders with, or None (use_nodes is always on from Blender 5.0)."""
    nt = getattr(id_data, "node_tree", None)
    if nt is not None and bpy.app.version < (5, 0, 0) and not id_data.use_nodes:
        return None
    return nt


def output_node(nt):
    """The output node Cycles renders, or None: of the output nodes whose target is Cycles or All,
    an exact Cycles target first, then the active one (``get_output_node``, Cycles' own choice when
    a tree has several outputs)."""
    return nt.get_output_node("CYCLES") or nt.get_output_node("ALL")


def missing_output(nt, what: str = "Material Output") -> str:
    """Why :func:`output_node` found nothing, in words for a warning: no output node at all, or
    output nodes that all target EEVEE (named, with the fix)."""
    outs = [n for n in nt.nodes if n.bl_idname in OUTPUT_NODES]
    if not outs:
        return f"no {what} node"
    names = ", ".join(f"'{n.name}'" for n in outs[:3]) + (" ..." if len(outs) > 3 else "")
    targets = sorted({getattr(n, "target", "ALL") for n in outs})
    if targets == ["EEVEE"]:
        many = len(outs) > 1
        return (f"its {OUTPUT_NODES.get(outs[0].bl_idname, what)} node{'s' if many else ''} ({names}) "
                f"target{'' if many else 's'} EEVEE only: set the Target to All or Cycles")
    return f"no {what} node for Cycles or All ({names} target {', '.join(targets)})"


def surface_socket(nt):
    """The Surface input of a node tree's output node (:func:`output_node`), or None when there is
    no output node or it has no Surface input."""
    out = output_node(nt)
    return out.inputs.get("Surface") if out is not None else None


class TextureBindings:
    """The image-texture part of :class:`NodeReader`: Image Texture nodes on the inputs in
    TEXTURE_SOCKETS (and tangent-space Normal Map nodes) become :class:`TextureRef` bindings in
    ``Surface.textures``, sampled per hit by the core (docs/physics.md section 13)."""

    def _bindable(self, node, name: str) -> bool:
        """Whether input ``name`` of ``node`` takes an image texture sampled per hit."""
        return self.textures is not None and name in TEXTURE_SOCKETS.get(node.bl_idname, {})

    def _bind_scalar(self, node, name: str, src_node, out):
        """Bind what feeds the float input ``name`` of ``node``: an Image Texture's Color (its
        luminance) or Alpha, or one channel of it through a Separate Color (RGB) / Separate RGB
        node. Returns the average value, or None when it cannot be bound (the caller warns)."""
        channel, tex = -1, (src_node, out)
        if src_node.bl_idname in ("ShaderNodeSeparateColor", "ShaderNodeSeparateRGB"):
            if getattr(src_node, "mode", "RGB") != "RGB":
                return None
            channel = {"Red": 0, "R": 0, "Green": 1, "G": 1, "Blue": 2, "B": 2}.get(out.name, -1)
            tex = self.source(src_node.inputs[0])
            if channel < 0 or tex is None or tex[0].bl_idname != "ShaderNodeTexImage" or tex[1].name != "Color":
                return None
        elif src_node.bl_idname != "ShaderNodeTexImage":
            return None
        elif out.name == "Alpha":
            channel = 3
        mean = self._bind_image(node, name, tex[0], tex[1], channel)
        if mean is None:
            return None
        value = float(np.asarray(mean[:3]) @ _LUMINANCE) if channel < 0 else float(mean[channel])
        return min(max(value, 0.0), 1.0)

    def _bind_image(self, node, name: str, tex_node, out, channel: int = -1):
        """Bind the Image Texture ``tex_node`` feeding input ``name`` of ``node`` (through
        ``channel``, for a float input); return the texture's average linear Rec.709 colour and
        alpha (4,) (what one value per material reads), Cycles' missing-image magenta for an
        image without pixels, or None when it cannot be bound (then the caller averages it as
        before, with its warning)."""
        if out.name != "Color" and channel != 3:
            self.warn(f"{self.owner}: the Alpha output of image texture '{tex_node.name}' on '{name}' is not supported: "
                      "the texture is averaged")
            return None
        image = getattr(tex_node, "image", None)
        if image is None:
            self.warn(f"{self.owner}: image texture '{tex_node.name}' on '{name}' has no image: rendered magenta, as "
                      "Cycles renders a missing image")
            return np.array(_MISSING_RGB + (1.0,), np.float64)
        if getattr(image, "source", "FILE") not in ("FILE", "GENERATED"):
            self.warn(f"{self.owner}: image '{image.name}' ({image.source.lower()} source) on '{name}' is read as a "
                      "single image")
        if getattr(tex_node, "projection", "FLAT") != "FLAT":
            self.warn(f"{self.owner}: image texture '{tex_node.name}' uses {tex_node.projection.lower()} projection: "
                      "rendered with flat projection")
        coords = _texture_coordinates(self, tex_node)
        if coords is None:
            return None
        idx = self.textures.index(image, getattr(tex_node, "interpolation", "Linear"),
                                  getattr(tex_node, "extension", "REPEAT"), self.owner)
        if idx is None:  # no pixels (warned, naming the image and the material)
            return np.array(_MISSING_RGB + (1.0,), np.float64)
        kind, uv_map, matrix = coords
        self._bound[self._key(node, name)] = TextureRef(idx, kind, uv_map, matrix, tex_node.name, channel=channel)
        return self.textures.mean_rgba(idx)

    def _normal_map(self, node) -> TextureRef | None:
        """The tangent-space normal map on ``node``'s Normal input (a Normal Map node whose Color is
        an Image Texture), or None; what else drives Normal is named in a warning and ignored."""
        sock = node.inputs.get("Normal")
        src = self.source(sock) if sock is not None else None
        if src is None or self.textures is None:
            return None
        n, _ = src
        if n.bl_idname != "ShaderNodeNormalMap":
            self.warn(f"{self.owner}: '{n.name}' on the Normal of '{node.name}' is not supported (a Normal Map node with "
                      "an image texture is): the normal is not perturbed")
            return None
        if n.space != "TANGENT":  # its colour was not read by the shader program (_program_normal_map)
            self.warn(f"{self.owner}: the Color of Normal Map node '{n.name}' ({n.space.lower()} space) is not read: "
                      "the normal is not perturbed")
            return None
        col = self.source(n.inputs.get("Color"))
        if col is None or col[0].bl_idname != "ShaderNodeTexImage":
            if col is not None:
                self.warn(f"{self.owner}: the Color of Normal Map node '{n.name}' comes from '{col[0].name}', which is "
                          "not supported (an image texture is): the normal is not perturbed")
            return None
        tex_node, out = col
        image = getattr(tex_node, "image", None)
        if out.name != "Color" or image is None:
            self.warn(f"{self.owner}: Normal Map node '{n.name}' has no image texture colour: the normal is not perturbed")
            return None
        coords = _texture_coordinates(self, tex_node)
        if coords is None:
            return None
        idx = self.textures.index(image, getattr(tex_node, "interpolation", "Linear"),
                                  getattr(tex_node, "extension", "REPEAT"), self.owner)
        if idx is None:
            return None
        strength = self.value(n, "Strength", 1.0)
        if not np.isfinite(strength):
            raise SceneError(f"{self.owner}: 'Strength' of '{n.name}' is not finite")
        kind, uv_map, matrix = coords
        # the tangents come from the Normal Map node's own UV map (Cycles reads its tangent attribute)
        return TextureRef(idx, kind, uv_map, matrix, tex_node.name, float(strength), tangent_map=n.uv_map)

    def _attach_textures(self, node, surf: Surface) -> None:
        """The bindings recorded while ``node`` (a BSDF or Emission node) was read, into ``surf``."""
        if self.textures is None:
            return
        for sock_name, slot in TEXTURE_SOCKETS[node.bl_idname].items():
            reg = self._programmed.get(self._key(node, sock_name))
            if reg is not None and slot not in surf.programs and slot not in surf.textures:
                surf.programs[slot] = reg
                if slot == "emission":
                    s = node.inputs.get("Emission Strength")
                    s = node.inputs.get("Strength") if s is None else s
                    surf.programs["emission_strength"] = self.strength(node, s.name, 1.0) if s is not None else 1.0
                continue
            ref = self._bound.get(self._key(node, sock_name))
            if ref is not None and slot not in surf.textures:
                if slot == "emission":
                    s = node.inputs.get("Emission Strength")
                    s = node.inputs.get("Strength") if s is None else s
                    ref.strength = self.strength(node, s.name, 1.0) if s is not None else 1.0
                surf.textures[slot] = ref
        if surf.kind is not None and node.inputs.get("Normal") is not None:
            src = self.source(node.inputs["Normal"])
            if src is not None and src[0].bl_idname == "ShaderNodeBump" and not getattr(src[0], "mute", False):
                self._bump(src[0], surf)
                return self._alpha_warning(node)
            if src is not None and src[0].bl_idname == "ShaderNodeNormalMap" and not getattr(src[0], "mute", False) \
                    and self._program_normal_map(src[0], surf):
                return self._alpha_warning(node)
            ref = self._normal_map(node)
            if ref is not None:
                surf.textures["normal"] = ref
        self._alpha_warning(node)

    def _alpha_warning(self, node) -> None:
        if node.bl_idname == "ShaderNodeBsdfPrincipled" and node.inputs.get("Alpha") is not None:
            alpha = self.source(node.inputs["Alpha"])
            if alpha is not None and alpha[0].bl_idname == "ShaderNodeTexImage":
                self.warn(f"{self.owner}: image texture '{alpha[0].name}' on Alpha is not supported: rendered opaque")

    def _program_normal_map(self, n, surf: Surface) -> bool:
        """A Normal Map node read through the shader program (docs/physics.md section 13.5): in
        object or world space (any colour the compiler reads), or in tangent space when its Color
        is not a plain Image Texture (an image behind a Mix, a procedural colour). True when it
        was compiled (its slots set in ``surf.programs``); False: the image binding (or its
        warning) takes it."""
        from .shader_compiler import ShaderCompiler

        col = self.source(n.inputs.get("Color"))
        if col is None or self.textures is None:
            return False
        if n.space == "TANGENT" and col[0].bl_idname == "ShaderNodeTexImage":
            return False  # the image binding (TextureRef) reads it
        if self.compiler is None:
            self.compiler = ShaderCompiler(self)
        c = self.compiler
        reg = c.compile_input(n, "Color", "v")
        if reg is None:
            return False  # _normal_map warns
        b = c.builder
        if n.space in ("BLENDER_OBJECT", "BLENDER_WORLD"):  # Blender's convention: y and z negated
            reg = b.op("vector_math", [reg, b.const([1.0, -1.0, -1.0]), b.const([0.0, 1.0, 1.0]), b.const(1.0)],
                       operation="MULTIPLY_ADD")[0]
        space = {"TANGENT": "tangent", "OBJECT": "object", "BLENDER_OBJECT": "object"}.get(n.space, "world")
        if space == "object":
            b.op("coord", kind="object")  # the object-space corners give the object's normal transform per hit
        sock = n.inputs.get("Strength")
        strength = c.compile_input(n, "Strength", "f") if sock is not None and self.source(sock) is not None else None
        if strength is None:
            v = self.value(n, "Strength", 1.0)
            if not np.isfinite(v):
                raise SceneError(f"{self.owner}: 'Strength' of '{n.name}' is not finite")
            strength = b.const(float(v))
        surf.programs.setdefault("normalmap_" + space, reg)
        surf.programs.setdefault("normalmap_strength", strength)
        if space == "tangent":
            surf.programs.setdefault("_tangent_map", n.uv_map)
        return True

    def _bump(self, bump, surf: Surface) -> None:
        """A Bump node on a BSDF's Normal: its Height (and Strength, Distance; Invert negates the
        distance) compiled into the material's shader program (slots BUMP_SLOTS), from which the
        core perturbs the shading normal per hit as Cycles' ``svm_node_set_bump`` does
        (core/materials/surface.py; docs/physics.md section 13.7)."""
        from .shader_compiler import ShaderCompiler

        if self.textures is None:
            return
        hs = bump.inputs.get("Height")
        if hs is None or self.source(hs) is None:
            return  # a constant height: no slope, the normal is unchanged (as in Cycles)
        if self.compiler is None:
            self.compiler = ShaderCompiler(self)
        c = self.compiler
        height = c.compile_input(bump, "Height", "f")
        if height is None:
            self.warn(f"{self.owner}: the Height of Bump node '{bump.name}' comes from '{self.source(hs)[0].name}', "
                      "which is not read: the normal is not perturbed")
            return
        regs = {}
        for name, default in (("Strength", 1.0), ("Distance", 1.0)):
            sock = bump.inputs.get(name)
            reg = None
            if sock is not None and self.source(sock) is not None:
                reg = c.compile_input(bump, name, "f")
            if reg is None:
                v = self.value(bump, name, default) if sock is not None else default
                if not np.isfinite(v):
                    raise SceneError(f"{self.owner}: '{name}' of '{bump.name}' is not finite")
                reg = c.builder.const(float(v))
            regs[name] = reg
        if getattr(bump, "invert", False):
            regs["Distance"] = c.builder.op("math", [regs["Distance"], c.builder.const(-1.0), c.builder.const(0.0)],
                                            operation="MULTIPLY", clamp=False)[0]
        ns = bump.inputs.get("Normal")
        if ns is not None and self.source(ns) is not None:
            self.warn(f"{self.owner}: the Normal input of Bump node '{bump.name}' is not read: the bump perturbs the "
                      "shading normal")
        for slot, reg in (("bump_height", height), ("bump_strength", regs["Strength"]),
                          ("bump_distance", regs["Distance"])):
            surf.programs.setdefault(slot, reg)

    def _combined_textures(self, a: Surface, b: Surface, wa: float, wb: float, node, out: Surface) -> dict:
        """The textures of a Mix/Add of ``a`` and ``b``: each slot from the surface ``out`` kept
        (same kind: the heavier that has one), with a warning where a texture is mixed with a
        plain value or another texture (the texture alone is rendered)."""
        if not a.textures and not b.textures:
            return {}
        first, second = (a, b) if wa >= wb else (b, a)
        res = {}
        for slot in sorted(set(a.textures) | set(b.textures)):
            pick = first if slot in first.textures else second
            if _is_mixture(out) and slot != "emission":
                if not _mixture_slot(pick, slot):
                    self.warn(f"{self.owner}: '{node.name}' mixes unlike BSDFs: image texture "
                              f"'{pick.textures[slot].node}' on the {slot} of its {pick.kind.lower()} BSDF is "
                              "rendered as its average")
                    continue
            elif slot != "emission" and pick.kind != out.kind:
                continue  # the surface not kept
            ref = pick.textures[slot]
            other = second if pick is first else first
            if slot == "emission":
                ref = replace(ref, strength=ref.strength * (wa if pick is a else wb))
            elif other.kind is None and pick.kind == "DIFFUSE" and (wa if pick is a else wb) != 1.0:
                self.warn(f"{self.owner}: '{node.name}' weighs image texture '{ref.node}' by "
                          f"{wa if pick is a else wb:g}: the texture is rendered at full weight")
            elif other.kind == pick.kind:
                self.warn(f"{self.owner}: '{node.name}' mixes image texture '{ref.node}' with "
                          f"{'another texture' if slot in other.textures else 'a plain ' + slot}: rendered with the "
                          "texture alone")
            res[slot] = ref
        return res


class NodeReader(TextureBindings):
    """Evaluates a shader node tree to a Surface, approximating what it cannot represent."""

    def __init__(self, owner: str, warn: Warnings, to709: np.ndarray | None, textures=None):
        self.owner, self.warn, self.to709 = owner, warn, to709
        #: The first node cycle met ("'A' -> 'B'", the link Blender marked invalid), or None.
        self.cycle: str | None = None
        #: The export's images.TextureTable: Image Texture nodes on TEXTURE_SOCKETS are bound
        #: (None: every texture is averaged, as before).
        self.textures = textures
        self._bound: dict[tuple, TextureRef] = {}  # (group path, node name, socket) -> binding
        #: The material's shader-program compiler (export/shader_compiler.py), made when a
        #: procedural node drives a BSDF input; None: nothing compiled.
        self.compiler = None
        self._programmed: dict[tuple, int] = {}  # (group path, node name, socket) -> register
        self._paths: dict[int, tuple] = {}  # node pointer -> the group nodes it was reached through

    # ---------------------------------------------------------------- sockets
    def source(self, socket, groups: bool = True):
        """(node, output socket) feeding ``socket``, following reroutes and, with ``groups``, a
        node group's Group Input out to the group node's own input (the group path each node was
        reached through is kept: :meth:`group_path`); None when unlinked, muted or linked through
        an invalid link (a cycle is recorded in :attr:`cycle`)."""
        return self._walk(socket, groups)[0]

    def effective_socket(self, socket):
        """The socket whose own value an unlinked ``socket`` takes: itself, or, inside a node
        group, the group node's input its Group Input link leads to (a group input's default)."""
        return self._walk(socket, True)[1]

    def group_path(self, node) -> tuple:
        """The group nodes (outermost first) through which ``node`` was reached: () at the top."""
        return self._paths.get(node.as_pointer(), ()) if node is not None else ()

    def _walk(self, socket, groups: bool):
        path = self.group_path(socket.node) if groups and socket is not None else ()
        visited = set()
        while socket is not None and socket.is_linked:
            link = socket.links[0]
            if getattr(link, "is_muted", False):
                return None, socket
            if not getattr(link, "is_valid", True):
                self._invalid_link(link)
                return None, socket
            node = link.from_node
            if node.bl_idname == "NodeReroute":
                if (path, node.name) in visited:  # a loop of reroutes that Blender did not flag
                    self.cycle = self.cycle or f"'{node.name}' -> '{link.to_node.name}'"
                    return None, socket
                visited.add((path, node.name))
                socket = node.inputs[0] if node.inputs else None
                continue
            if groups and node.bl_idname == "NodeGroupInput" and path:  # one level out of the group
                outer = next((s for s in path[-1].inputs if s.identifier == link.from_socket.identifier), None)
                if outer is None:
                    return None, socket
                socket, path = outer, path[:-1]
                continue
            if groups:
                self._paths[node.as_pointer()] = path
            return (node, link.from_socket), socket
        return None, socket

    def _key(self, node, name: str) -> tuple:
        """The key of input ``name`` of ``node`` in the bindings: its group path, node and socket."""
        return tuple(g.name for g in self.group_path(node)), node.name, name

    def _invalid_link(self, link) -> None:
        """A link Blender drew red: part of a cycle (recorded) or between incompatible sockets
        (ignored, as Cycles ignores it, with a warning)."""
        a, b = link.from_node, link.to_node
        if _feeds(b, a):
            self.cycle = self.cycle or f"'{a.name}' -> '{b.name}'"
        else:
            self.warn(f"{self.owner}: the link from '{a.name}' to '{b.name}' is invalid (red in the node "
                      "editor): ignored, as in Cycles")

    def color(self, node, name: str, default=(0.8, 0.8, 0.8)) -> np.ndarray:
        """Linear Rec.709 colour of input ``name``; textures are averaged, other links fall back.
        NaN is an error naming the socket; infinite or huge components are clamped to
        ``MAX_INTENSITY``."""
        return self._finite_color(self._color(node, name, default), node, name)

    def _color(self, node, name: str, default) -> np.ndarray:
        sock = node.inputs.get(name)
        if sock is None:
            return np.array(default, np.float64)
        src = self.source(sock)
        if src is None:
            return self._to709(rgb(self.effective_socket(sock).default_value))
        n, out = src
        if n.bl_idname == "ShaderNodeRGB":
            return self._to709(rgb(out.default_value))
        if n.bl_idname == "ShaderNodeBlackbody" and (n.inputs.get("Temperature") is None
                                                     or self.source(n.inputs["Temperature"]) is None):
            return blackbody_rgb(self.temperature(n))  # a fixed temperature (a linked one compiles)
        if n.bl_idname == "ShaderNodeTexImage" and self._bindable(node, name):
            col = self._bind_image(node, name, n, out)
            if col is not None:
                return np.asarray(col[:3], np.float64)
        if self._bindable(node, name):
            mean = self._compile(node, name, "v")
            if mean is not None:
                return mean
        if n.bl_idname in ("ShaderNodeTexImage", "ShaderNodeTexEnvironment") and getattr(n, "image", None):
            mean = image_mean(n.image)
            if mean is not None:
                self.warn(f"{self.owner}: image texture '{n.image.name}' on '{name}' is rendered as its average colour")
                return self._to709(mean)
        self.warn(f"{self.owner}: '{name}' of '{node.name}' is driven by a '{n.name}' node, which is not "
                  f"supported: using the socket's own value")
        return self._to709(rgb(sock.default_value))

    def _compile(self, node, name: str, kind: str):
        """Compile what drives input ``name`` of ``node`` into the material's shader program
        (export/shader_compiler.py); returns its average (what reads one value per material) or
        None when it is not read (the caller warns as before)."""
        from .shader_compiler import ShaderCompiler

        if self.compiler is None:
            self.compiler = ShaderCompiler(self)
        reg = self.compiler.compile_input(node, name, kind)
        if reg is None:
            return None
        self._programmed[self._key(node, name)] = reg
        mean = self.compiler.average(reg, "color" if kind == "v" else "roughness")
        return np.asarray(mean, np.float64) if kind == "v" else float(mean)

    def _finite_color(self, col: np.ndarray, node, name: str) -> np.ndarray:
        col = np.asarray(col, np.float64)
        if np.isnan(col).any():
            raise SceneError(f"{self.owner}: '{name}' of '{node.name}' is NaN")
        if (col > MAX_INTENSITY).any():
            self.warn(f"{self.owner}: '{name}' of '{node.name}' is above {MAX_INTENSITY:.0e}: clamped")
            col = np.minimum(col, MAX_INTENSITY)
        return col

    def value(self, node, name: str, default: float = 0.0) -> float:
        """Input ``name`` as a float (a Value node's, or the socket's own); NaN is an error naming
        the socket."""
        v = self._value(node, name, default)
        if v != v:
            raise SceneError(f"{self.owner}: '{name}' of '{node.name}' is NaN")
        return v

    def _value(self, node, name: str, default: float) -> float:
        sock = node.inputs.get(name)
        if sock is None:
            return float(default)
        src = self.source(sock)
        if src is None:
            return float(self.effective_socket(sock).default_value)
        n, out = src
        if n.bl_idname == "ShaderNodeValue":
            return float(out.default_value)
        if self._bindable(node, name):
            value = self._bind_scalar(node, name, n, out)
            if value is not None:  # the average, for what reads one value per material
                return value
            mean = self._compile(node, name, "f")
            if mean is not None:
                return float(np.clip(mean, 0.0, 1.0)) if name in ("Roughness", "Metallic") else float(mean)
        self.warn(f"{self.owner}: '{name}' of '{node.name}' is driven by a '{n.name}' node, which is not "
                  f"supported: using the socket's own value")
        return float(sock.default_value)

    def strength(self, node, name: str = "Strength", default: float = 1.0) -> float:
        """An emission strength in [0, MAX_INTENSITY]: a negative one is 0 and a larger one
        ``MAX_INTENSITY``, each with a warning (Cycles subtracts light for a negative strength,
        which the tracer cannot)."""
        s = self.value(node, name, default)
        if s < 0.0:
            self.warn(f"{self.owner}: negative '{name}' ({s:g}) of '{node.name}' is rendered as 0")
            return 0.0
        if s > MAX_INTENSITY:
            self.warn(f"{self.owner}: '{name}' of '{node.name}' ({s:.3g}) is above {MAX_INTENSITY:.0e}: clamped")
            return MAX_INTENSITY
        return s

    def emission(self, color: np.ndarray, strength: float, node) -> np.ndarray:
        """Emission colour x strength, each component at most ``MAX_INTENSITY`` (with a warning)."""
        e = np.asarray(color, np.float64) * strength
        if (e > MAX_INTENSITY).any():
            self.warn(f"{self.owner}: the emission of '{node.name}' (colour x strength {e.max():.3g}) is above "
                      f"{MAX_INTENSITY:.0e}: clamped")
            e = np.minimum(e, MAX_INTENSITY)
        return e

    def temperature(self, node) -> float:
        """A Blackbody node's temperature (K); infinite or not positive: 6500 K, with a warning."""
        t = self.value(node, "Temperature", 6500.0)
        if not (0.0 < t < float("inf")):
            self.warn(f"{self.owner}: Blackbody temperature {t:g} K of '{node.name}' is not a positive number: "
                      "using 6500 K")
            return 6500.0
        return t

    def _to709(self, col: np.ndarray) -> np.ndarray:
        return in_rec709(col, self.to709)

    # ---------------------------------------------------------------- shaders
    def surface(self, socket) -> Surface:
        """Evaluate the shader plugged into ``socket`` (an output node's Surface input)."""
        return self._shader(self.source(socket), depth=0)

    def _shader(self, src, depth: int) -> Surface:
        surf = self._shader_node(src, depth)
        if src is not None and src[0].bl_idname in TEXTURE_SOCKETS and not getattr(src[0], "mute", False):
            self._attach_textures(src[0], surf)
        return surf

    def _shader_node(self, src, depth: int) -> Surface:
        black = Surface(None, np.zeros(3))
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
        if idn == "ShaderNodeGroup":  # inlined: the shader behind the group's output socket
            return self._group_shader(node, out, depth)
        if idn == "ShaderNodeBsdfPrincipled":
            return self._principled(node)
        if idn == "ShaderNodeBsdfDiffuse":  # Roughness > 0: Oren-Nayar (docs/physics.md section 14.9)
            return Surface("DIFFUSE", self.color(node, "Color"), metallic=0.0, transmission=0.0,
                           diffuse_roughness=self._roughness(node, 0.0))
        if idn in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"):
            self._microfacet_options(node, "Anisotropy")
            return Surface("MIRROR", self.color(node, "Color"), roughness=self._roughness(node, 0.5),
                           metallic=1.0, transmission=0.0)
        if idn == "ShaderNodeBsdfMetallic":
            return self._metallic(node)
        if idn in ("ShaderNodeBsdfGlass", "ShaderNodeBsdfRefraction"):
            self._microfacet_options(node, None)
            if idn == "ShaderNodeBsdfRefraction":
                self.warn(f"{self.owner}: Refraction BSDF is rendered as glass (with Fresnel reflection)")
            return Surface("DIELECTRIC", self.color(node, "Color", (1, 1, 1)), self.value(node, "IOR", 1.5),
                           self._roughness(node, 0.0), metallic=0.0, transmission=1.0)
        if idn == "ShaderNodeEmission":
            strength = self.strength(node, "Strength", 1.0)
            color = self.color(node, "Color", (1, 1, 1))
            return Surface(None, np.zeros(3), emission=self.emission(color, strength, node))
        if idn == "ShaderNodeMixShader":
            view = self._view_fac(node)
            program = None if view is not None else self._program_fac(node)
            if view is not None:  # Fresnel / Layer Weight: per hit; the table keeps its hemispherical mean
                f = _mean_fac(*view)
            elif program is not None:  # a texture / converter chain: per hit; the table keeps its average
                f = program[1]
            else:
                f = min(max(self.value(node, "Fac", 0.5) if node.inputs.get("Fac") else 0.5, 0.0), 1.0)
            a = self._shader(self.source(node.inputs[1]), depth + 1)
            b = self._shader(self.source(node.inputs[2]), depth + 1)
            out = self._combine(a, b, 1.0 - f, f, node)
            if view is not None:
                self._per_hit_fac(out, a, b, view, node)
            elif program is not None:
                self._per_hit_fac(out, a, b, ("PROGRAM", f), node, program[0])
            return out
        if idn == "ShaderNodeAddShader":
            a = self._shader(self.source(node.inputs[0]), depth + 1)
            b = self._shader(self.source(node.inputs[1]), depth + 1)
            return self._combine(a, b, 1.0, 1.0, node)
        # Anything else (Translucent, Subsurface, Sheen, Toon, Hair, groups, ...): a diffuse
        # surface of the node's colour, if it has one.
        col = None
        for name in ("Color", "Base Color"):
            if node.inputs.get(name) is not None and getattr(node.inputs[name], "type", "") == "RGBA":
                col = self.color(node, name)
                break
        if idn == "ShaderNodeHoldout":  # black, and with Film > Transparent a hole: alpha 0 (Cycles)
            return Surface(None, np.zeros(3), holdout=1.0)
        if idn == "ShaderNodeBsdfTransparent":  # straight through, tinted per crossing: glass of IOR 1
            return Surface("DIELECTRIC", self.color(node, "Color", (1, 1, 1)), 1.0, 0.0, metallic=0.0,
                           transmission=1.0, glass_tint="REFRACTION")
        self.warn(f"{self.owner}: shader node '{node.name}' ({idn}) is not supported: rendered as a diffuse "
                  f"surface{' of its colour' if col is not None else ''}")
        return Surface("DIFFUSE", col if col is not None else np.full(3, 0.8))

    def _group_shader(self, node, out, depth: int) -> Surface:
        """A node group's shader output: the shader its Group Output receives, read inside the
        group (its Group Input links lead back to this group node's inputs: :meth:`source`)."""
        tree = node.node_tree
        path = self.group_path(node)
        gout = None if tree is None else next(
            (n for n in tree.nodes if n.bl_idname == "NodeGroupOutput" and getattr(n, "is_active_output", True)), None)
        inner = None if gout is None else next((s for s in gout.inputs if s.identifier == out.identifier), None)
        if inner is None or any(g.node_tree == tree for g in path):
            self.warn(f"{self.owner}: node group '{node.name}' has no {'output' if inner is None else 'finite nesting'}"
                      ": renders black")
            return Surface(None, np.zeros(3))
        self._paths[gout.as_pointer()] = path + (node,)
        return self._shader(self.source(inner), depth + 1)

    def _view_fac(self, node) -> tuple[str, float] | None:
        """(LayerFac name, its IOR or Blend) where a Mix Shader's Fac is a Fresnel or Layer Weight
        node's output (docs/physics.md section 14.8), else None."""
        sock = node.inputs.get("Fac")
        src = self.source(sock) if sock is not None else None
        if src is None:
            return None
        n, out = src
        if n.bl_idname not in ("ShaderNodeFresnel", "ShaderNodeLayerWeight"):
            return None
        if n.inputs.get("Normal") is not None and self.source(n.inputs["Normal"]) is not None:
            self.warn(f"{self.owner}: the Normal input of '{n.name}' is not read: the shading normal is used")
        if n.bl_idname == "ShaderNodeFresnel":
            return "FRESNEL", self.value(n, "IOR", 1.5)
        return ("LAYER_FACING" if out.name == "Facing" else "LAYER_FRESNEL"), self.value(n, "Blend", 0.5)

    def _program_fac(self, node) -> tuple[int, float] | None:
        """(register, average) where a Mix Shader's Fac is driven by nodes the shader compiler reads
        (a texture, a ColorRamp, Math ...: docs/physics.md sections 13.6 and 14.8), else None."""
        sock = node.inputs.get("Fac")
        src = self.source(sock) if sock is not None else None
        if src is None or self.textures is None or src[0].bl_idname == "ShaderNodeValue":
            return None
        mean = self._compile(node, "Fac", "f")
        if mean is None:
            return None
        return self._programmed[self._key(node, "Fac")], float(np.clip(mean, 0.0, 1.0))

    def _per_hit_fac(self, out: Surface, a: Surface, b: Surface, view, node, register: int | None = None) -> None:
        """Give ``out`` (a Mix of ``a`` and ``b``) its Fac per hit where a and b are one layer each
        and different layers; otherwise warn that the Fac's hemispherical mean is rendered."""
        la, lb = a.layer_weights(), b.layer_weights()
        one_a, one_b = la.max() == 1.0, lb.max() == 1.0
        ia, ib = int(np.argmax(la)), int(np.argmax(lb))
        if a.kind is None or b.kind is None or not (one_a and one_b) or ia == ib:
            what = "a texture or converter chain" if register is not None else \
                f"a {view[0].replace('_', ' ').lower()} node"
            mean = view[1] if register is not None else _mean_fac(*view)
            self.warn(f"{self.owner}: '{node.name}' takes its Fac from {what}, read per hit only between two "
                      f"single BSDFs of different kinds (diffuse, glossy, glass): rendered with its mean {mean:.3g}")
            return
        out.layer_fac, out.layer_fac_value, out.layer_fac_from, out.layer_fac_to = view[0], float(view[1]), ia, ib
        if register is not None:
            out.programs["mix"] = register

    def _roughness(self, node, default: float, name: str = "Roughness") -> float:
        """A roughness input clamped to [0, 1], as Cycles clamps it."""
        return min(max(self.value(node, name, default), 0.0), 1.0)

    def _microfacet_options(self, node, aniso: str | None) -> None:
        """Warnings for what a microfacet node sets that is rendered otherwise: anisotropy
        (isotropic here), a distribution other than Multiscatter GGX (rendered as it)."""
        if aniso is not None and node.inputs.get(aniso) is not None and abs(self.value(node, aniso, 0.0)) > 0.0:
            self.warn(f"{self.owner}: the anisotropy of '{node.name}' is not rendered (isotropic roughness)")
        dist = getattr(node, "distribution", "MULTI_GGX")
        if dist not in ("MULTI_GGX", "MULTI_GGX_GLASS"):
            self.warn(f"{self.owner}: '{node.name}' uses the {dist} distribution: rendered as Multiscatter GGX")

    def _vector(self, node, name: str, default) -> np.ndarray:
        """A vector input's own value (a link is not followed: warned, the socket's value used)."""
        sock = node.inputs.get(name)
        if sock is None:
            return np.asarray(default, np.float64)
        if self.source(sock) is not None:
            self.warn(f"{self.owner}: '{name}' of '{node.name}' is driven by a node, which is not supported: "
                      "using the socket's own value")
        v = np.asarray(tuple(sock.default_value)[:3], np.float64)
        if np.isnan(v).any():
            raise SceneError(f"{self.owner}: '{name}' of '{node.name}' is NaN")
        return v

    def _metallic(self, node) -> Surface:
        """Metallic BSDF: F82 (Base Color = F0, Edge Tint) as Cycles; a physical conductor (n, k)
        as the F82-tint fit through its reflectance at 0 and ~82 degrees (the fit Cycles itself
        uses for its energy compensation)."""
        self._microfacet_options(node, "Anisotropy")
        rough = self._roughness(node, 0.5)
        if getattr(node, "fresnel_type", "F82") == "PHYSICAL_CONDUCTOR":
            n = np.maximum(self._vector(node, "IOR", (2.757, 2.513, 2.231)), 0.0)
            k = np.maximum(self._vector(node, "Extinction", (3.867, 3.404, 3.009)), 0.0)
            f0, f82 = _conductor_fresnel(1.0, n, k), _conductor_fresnel(1.0 / 7.0, n, k)
            schlick = f0 + (1.0 - f0) * (6.0 / 7.0) ** 5
            tint = np.clip(f82 / np.maximum(schlick, 1e-6), 0.0, 1.0)
            self.warn(f"{self.owner}: the physical conductor of '{node.name}' is rendered with the F82-tint fit "
                      f"(F0 {np.round(f0, 3).tolist()}, edge tint {np.round(tint, 3).tolist()})")
            base = f0
        else:
            base = self.color(node, "Base Color", (0.617, 0.577, 0.540))
            tint = self.color(node, "Edge Tint", (0.695, 0.726, 0.770))
        return Surface("MIRROR", base, roughness=rough, metallic=1.0, transmission=0.0,
                       specular_tint=np.clip(tint, 0.0, 1.0), conductor_fresnel="F82_TINT")

    def _principled(self, node) -> Surface:
        """Principled BSDF v2: the metal (F0 = Base Color, F82 edge tint = Specular Tint), glass
        and the dielectric base (diffuse under a specular layer of IOR, IOR Level and Specular
        Tint), with the layer weights Metallic and Transmission Weight carried to the core (which
        samples between the layers). The table's kind is the heaviest layer. The glass's colour
        is the colour of one pass (glass_tint 'PASS': Cycles tints each refraction by
        sqrt(Base Color), docs/physics.md section 2.7)."""
        base = self.color(node, "Base Color")
        metallic = min(max(self.value(node, "Metallic", 0.0), 0.0), 1.0)
        rough = self._roughness(node, 0.5)
        trans_name = "Transmission Weight" if node.inputs.get("Transmission Weight") else "Transmission"
        trans = min(max(self.value(node, trans_name, 0.0), 0.0), 1.0)
        ior = self.value(node, "IOR", 1.5)
        level_name = next((n for n in ("Specular IOR Level", "IOR Level") if node.inputs.get(n)), None)
        level = max(self.value(node, level_name, 0.5), 0.0) if level_name else 0.5
        tint = self.color(node, "Specular Tint", (1, 1, 1)) if node.inputs.get("Specular Tint") is not None \
            and getattr(node.inputs["Specular Tint"], "type", "") == "RGBA" else np.ones(3)
        strength = self.strength(node, "Emission Strength", 0.0) if node.inputs.get("Emission Strength") else 1.0
        emission = self.color(node, "Emission Color" if node.inputs.get("Emission Color") else "Emission", (0, 0, 0))
        emission = self.emission(emission, strength, node)
        if node.inputs.get("Alpha") is not None and self.value(node, "Alpha", 1.0) < 1.0:
            self.warn(f"{self.owner}: alpha below 1 is not supported: rendered opaque")
        if node.inputs.get("Subsurface Weight") is not None and self.value(node, "Subsurface Weight", 0.0) > 0.0:
            self.warn(f"{self.owner}: the Principled BSDF's subsurface layer is not rendered")
        coat = self._coat_sheen(node)
        if coat and np.asarray(emission).max() > 0:
            self.warn(f"{self.owner}: the emission of '{node.name}' is rendered without the coat's and sheen's "
                      "attenuation (Cycles dims it by what they reflect)")
        if node.inputs.get("Diffuse Roughness") is not None and self.value(node, "Diffuse Roughness", 0.0) > 0.0:
            self.warn(f"{self.owner}: the Principled BSDF's diffuse roughness (Oren-Nayar) is rendered Lambertian")
        self._microfacet_options(node, "Anisotropic")
        film_d, film_n = self._thin_film(node)
        weights = {"MIRROR": metallic, "DIELECTRIC": (1.0 - metallic) * trans, "DIFFUSE": (1.0 - metallic) * (1.0 - trans)}
        kind = max(weights, key=weights.get)  # ties: metal, then glass
        return Surface(kind, base, ior, rough, emission, metallic=metallic, transmission=trans,
                       specular_ior_level=level, specular_tint=np.clip(tint, 0.0, None), conductor_fresnel="F82_TINT",
                       glass_tint="PASS", thin_film_thickness=film_d, thin_film_ior=film_n, **coat)

    def _coat_sheen(self, node) -> dict:
        """Principled's coat (Weight, Roughness, IOR, Tint) and sheen (Weight, Roughness, Tint) as
        Surface fields (docs/physics.md section 14.10): weights clamped to [0, 1] (above 1: warned),
        roughness to [0, 1] and the coat IOR to at least 1, as Cycles clamps them; a linked Coat
        Normal is not read (warned: the shading normal is used)."""
        out = {}
        for layer, names in (("coat", ("Coat Weight", "Coat Roughness", "Coat IOR", "Coat Tint")),
                             ("sheen", ("Sheen Weight", "Sheen Roughness", None, "Sheen Tint"))):
            if node.inputs.get(names[0]) is None:
                continue
            w = self.value(node, names[0], 0.0)
            if not w > 0.0:
                continue
            if w > 1.0:
                self.warn(f"{self.owner}: the Principled BSDF's {layer} weight {w:g} is rendered as 1")
            out[f"{layer}_weight"] = min(w, 1.0)
            out[f"{layer}_roughness"] = self._roughness(node, 0.03 if layer == "coat" else 0.5, names[1])
            if names[2] is not None:
                ior = self.value(node, names[2], 1.5)
                if not 1.0 <= ior <= MAX_IOR:
                    self.warn(f"{self.owner}: the coat IOR {ior:g} of '{node.name}' is outside 1-{MAX_IOR:g}: "
                              f"rendered as {min(max(ior, 1.0), MAX_IOR):g}")
                out["coat_ior"] = min(max(ior, 1.0), MAX_IOR)
            out[f"{layer}_tint"] = np.clip(self.color(node, names[3], (1, 1, 1)), 0.0, None)
        if out.get("coat_weight") and node.inputs.get("Coat Normal") is not None \
                and self.source(node.inputs["Coat Normal"]) is not None:
            self.warn(f"{self.owner}: the Coat Normal of '{node.name}' is not read: the shading normal is used")
        return out

    def _thin_film(self, node) -> tuple[float, float]:
        """Principled's Thin Film Thickness (nm) and Thin Film IOR (Blender 4.2+; 0 and 1.33 where
        absent). A linked socket is read as its own value, with value()'s warning; a negative
        thickness is 0 and an IOR below 1 is 1, as the core's table requires, with a warning."""
        if node.inputs.get("Thin Film Thickness") is None:
            return 0.0, 1.33
        d = self.value(node, "Thin Film Thickness", 0.0)
        if d <= 0.0:
            return 0.0, 1.33
        if d == float("inf"):
            raise SceneError(f"{self.owner}: 'Thin Film Thickness' of '{node.name}' is infinite")
        n = self.value(node, "Thin Film IOR", 1.33) if node.inputs.get("Thin Film IOR") is not None else 1.33
        if not 1.0 <= n <= MAX_IOR:
            clamped = min(max(n, 1.0), MAX_IOR)
            self.warn(f"{self.owner}: thin film IOR {n:g} of '{node.name}' is outside 1-{MAX_IOR:g}: "
                      f"rendered as {clamped:g}")
            n = clamped
        return float(d), float(n)

    def _combine(self, a: Surface, b: Surface, wa: float, wb: float, node) -> Surface:
        out = self._combine_surfaces(a, b, wa, wb, node)
        out.holdout = min(wa * a.holdout + wb * b.holdout, 1.0)  # Cycles sums the holdout closures' weights
        out.textures = self._combined_textures(a, b, wa, wb, node, out)
        first, second = (a, b) if wa >= wb else (b, a)
        for s in (first, second):  # the shader programs of the surface kept (the heavier first)
            if s.programs and _is_mixture(out):  # a lobe mixture: the base's colour, the others' roughness
                for slot, reg in s.programs.items():
                    if slot != "mix" and (slot == "emission" or _mixture_slot(s, slot)):
                        out.programs.setdefault(slot, reg)
                continue
            if s.programs and (s.kind == out.kind or out.kind is None or s.kind is None):
                for slot, reg in s.programs.items():
                    out.programs.setdefault(slot, reg)
        return out

    def _combine_surfaces(self, a: Surface, b: Surface, wa: float, wb: float, node) -> Surface:
        emission = wa * a.emission + wb * b.emission
        if a.kind is None and b.kind is None:
            return Surface(None, np.zeros(3), emission=emission)
        if a.kind is None or b.kind is None:
            s, w = (b, wb) if a.kind is None else (a, wa)
            out = _copy(s, emission)
            out.color = s.color * (w if s.kind == "DIFFUSE" else 1.0)
            return out
        if a.kind == b.kind:
            t = wb / max(wa + wb, 1e-12)
            col = wa * a.color + wb * b.color if node.bl_idname == "ShaderNodeAddShader" else (1 - t) * a.color + t * b.color
            (ma, ta), (mb, tb) = a.layers(), b.layers()
            return Surface(a.kind, col, (1 - t) * a.ior + t * b.ior, (1 - t) * a.roughness + t * b.roughness, emission,
                           metallic=(1 - t) * ma + t * mb, transmission=(1 - t) * ta + t * tb,
                           specular_ior_level=(1 - t) * a.specular_ior_level + t * b.specular_ior_level,
                           specular_tint=(1 - t) * a.specular_tint + t * b.specular_tint,
                           conductor_fresnel=(a if t < 0.5 else b).conductor_fresnel,
                           glass_tint=(a if t < 0.5 else b).glass_tint,
                           thin_film_thickness=(a if t < 0.5 else b).thin_film_thickness,
                           thin_film_ior=(a if t < 0.5 else b).thin_film_ior,
                           diffuse_roughness=(1 - t) * a.diffuse_roughness + t * b.diffuse_roughness,
                           **_top_layers(a, b, t))
        return self._mixture(a, b, wa, wb, node, emission)

    def _mixture(self, a: Surface, b: Surface, wa: float, wb: float, node, emission) -> Surface:
        """A Mix / Add of unlike BSDFs as a lobe mixture (docs/physics.md section 14.8): the layer
        weights (base, metal, glass) are wa a's + wb b's, each layer with its own colour (the
        weighted mean of the surfaces that have it). An Add whose weights sum above 1 scales the
        colours by the sum (exact for Diffuse, Glossy and glass colours; warned)."""
        la, lb = wa * a.layer_weights(), wb * b.layer_weights()
        w = la + lb
        total = float(w.sum())
        if total <= 0.0:
            return Surface(None, np.zeros(3), emission=emission)
        scale = max(total, 1.0)
        wn = w / total
        cols = []
        for i in range(3):
            cols.append(scale * (la[i] * a.layer_color(i) + lb[i] * b.layer_color(i)) / w[i] if w[i] > 0 else None)
        if total > 1.0 + 1e-6:
            self.warn(f"{self.owner}: '{node.name}' adds BSDFs of total weight {total:.3g}: rendered as their "
                      f"mixture with colours times {total:.3g}")
        kinds = ("DIFFUSE", "MIRROR", "DIELECTRIC")
        kind = kinds[int(np.argmax(wn))]  # the heaviest layer (ties: base, metal, glass)
        metallic = float(wn[1])
        transmission = float(wn[2] / (1.0 - wn[1])) if wn[1] < 1.0 else 0.0

        def of(i):  # the surface that gives layer i most weight
            return a if la[i] >= lb[i] else b

        glossy = [s for s, ws in ((a, la), (b, lb)) if ws[1] > 0 or ws[2] > 0 or (ws[0] > 0 and s.specular_ior_level > 0)]
        rough = [s.roughness for s in glossy]
        if len(rough) == 2 and abs(rough[0] - rough[1]) > 1e-6:
            self.warn(f"{self.owner}: '{node.name}' mixes roughness {rough[0]:g} and {rough[1]:g}: rendered with "
                      f"their mean {0.5 * (rough[0] + rough[1]):g}")
        roughness = float(np.mean(rough)) if rough else max(a.roughness, b.roughness)
        base_s = of(0) if w[0] > 0 else None
        glass_s = of(2) if w[2] > 0 else None
        metal_s = of(1) if w[1] > 0 else None
        if glass_s is not None and base_s is not None and base_s.specular_ior_level > 0 and glass_s.ior != base_s.ior:
            self.warn(f"{self.owner}: '{node.name}' mixes glass of IOR {glass_s.ior:g} with a specular layer of IOR "
                      f"{base_s.ior:g}: both rendered with {glass_s.ior:g}")
        first = a if wa >= wb else b
        top = _top_layers(a, b, wb / max(wa + wb, 1e-12))
        for layer in ("coat", "sheen"):
            if (getattr(a, f"{layer}_weight") > 0) != (getattr(b, f"{layer}_weight") > 0):
                self.warn(f"{self.owner}: '{node.name}' mixes a surface with a Principled {layer} and one without: "
                          f"the {layer} is rendered over the whole mix with weight {top[layer + '_weight']:.3g}")
        color = cols[0] if cols[0] is not None else cols[int(np.argmax(wn))]
        return Surface(kind, color, (glass_s or base_s or first).ior, roughness, emission,
                       metallic=metallic, transmission=transmission,
                       specular_ior_level=base_s.specular_ior_level if base_s is not None else 0.0,
                       specular_tint=(metal_s or base_s or first).specular_tint,
                       conductor_fresnel=metal_s.conductor_fresnel if metal_s is not None else "CONSTANT",
                       glass_tint=glass_s.glass_tint if glass_s is not None else "REFRACTION",
                       thin_film_thickness=first.thin_film_thickness, thin_film_ior=first.thin_film_ior,
                       metal_color=cols[1], glass_color=cols[2],
                       diffuse_roughness=base_s.diffuse_roughness if base_s is not None else 0.0, **top)


def _copy(s: Surface, emission) -> Surface:
    return Surface(s.kind, s.color, s.ior, s.roughness, emission, metallic=s.metallic, transmission=s.transmission,
                   specular_ior_level=s.specular_ior_level, specular_tint=s.specular_tint,
                   conductor_fresnel=s.conductor_fresnel, glass_tint=s.glass_tint,
                   thin_film_thickness=s.thin_film_thickness, thin_film_ior=s.thin_film_ior,
                   metal_color=s.metal_color, glass_color=s.glass_color, layer_fac=s.layer_fac,
                   layer_fac_value=s.layer_fac_value, layer_fac_from=s.layer_fac_from, layer_fac_to=s.layer_fac_to,
                   diffuse_roughness=s.diffuse_roughness, holdout=s.holdout, **_top_layers(s, s, 0.0))


_TOP_FIELDS = ("coat_roughness", "coat_ior", "coat_tint", "sheen_roughness", "sheen_tint")


def _top_layers(a: Surface, b: Surface, t: float) -> dict:
    """The coat and sheen of a mix of ``a`` (weight 1 - t) and ``b`` (t): their weights mixed, the
    other inputs of the surface whose layer weighs more (docs/physics.md section 14.10: a coat over
    part of a mix is rendered over all of it, with the mixed weight)."""
    out = {"coat_weight": (1 - t) * a.coat_weight + t * b.coat_weight,
           "sheen_weight": (1 - t) * a.sheen_weight + t * b.sheen_weight}
    for layer in ("coat", "sheen"):
        src = a if (1 - t) * getattr(a, f"{layer}_weight") >= t * getattr(b, f"{layer}_weight") else b
        for f in _TOP_FIELDS:
            if f.startswith(layer):
                out[f] = getattr(src, f)
    return out


def _is_mixture(s: Surface) -> bool:
    """Whether ``s`` is a lobe mixture of unlike BSDFs (its layers have their own colours)."""
    return s.kind is not None and (s.metal_color is not None or s.glass_color is not None)


def _mixture_slot(s: Surface, slot: str) -> bool:
    """Whether a texture / program on ``slot`` of the mixed surface ``s`` is read per hit in the
    mixture: the colour is the base layer's (the metal's and glass's are their own constants),
    roughness and metallic are shared by all its layers."""
    return slot != "color" or s.layer_weights()[0] > 0


def _mean_fac(code: str, value: float) -> float:
    """The cosine-weighted hemispherical mean 2 int Fac(mu) mu dmu of a Fresnel / Layer Weight Fac
    on a front face (the table's one weight for what reads one value per material)."""
    from ...core.materials.mixtures import layer_fac
    from ...core.util.enums import LayerFac

    mu = (np.arange(512) + 0.5) / 512
    f = layer_fac(np.full(512, int(LayerFac[code])), np.full(512, value, np.float32), mu.astype(np.float32),
                  np.ones(512, bool))
    return float(np.clip(2.0 * np.mean(f * mu), 0.0, 1.0))


def _conductor_fresnel(cos: float, n: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Unpolarised reflectance of a conductor n + ik in vacuum (Born & Wolf section 14.4.1)."""
    c2 = cos * cos
    s2 = 1.0 - c2
    t0 = n * n - k * k - s2
    a2b2 = np.sqrt(t0 * t0 + 4.0 * n * n * k * k)
    a = np.sqrt(np.maximum(0.5 * (a2b2 + t0), 0.0))
    rs = (a2b2 + c2 - 2.0 * a * cos) / (a2b2 + c2 + 2.0 * a * cos)
    t1, t2 = a2b2 * c2 + s2 * s2, 2.0 * a * cos * s2
    rp = rs * (t1 - t2) / np.maximum(t1 + t2, 1e-30)
    return 0.5 * (rs + rp)


def _feeds(target, start) -> bool:
    """Whether ``target`` is upstream of ``start`` through any links, valid or not (so a link
    ``start -> target`` closes a cycle). Visits each node once."""
    stack, seen = [start], set()
    while stack:
        n = stack.pop()
        if n.name in seen:
            continue
        seen.add(n.name)
        for sock in n.inputs:
            for link in sock.links:
                if link.from_node.name == target.name:
                    return True
                stack.append(link.from_node)
    return False


# ============================================================================ image texture coordinates


def _mapping_matrix(node, reader: NodeReader) -> np.ndarray | None:
    """The 4x4 affine a Mapping node applies to a point (Cycles' svm/mapping_util.h): POINT
    T(L) R S, TEXTURE its inverse S^-1 R^T T(-L), VECTOR R S; None (with a warning) for NORMAL
    or driven inputs."""
    kind = getattr(node, "vector_type", "POINT")
    vals = {}
    for name in ("Location", "Rotation", "Scale"):
        sock = node.inputs.get(name)
        if sock is None or not sock.enabled:
            vals[name] = np.zeros(3) if name != "Scale" else np.ones(3)
            continue
        if reader.source(sock) is not None:
            reader.warn(f"{reader.owner}: the {name} of Mapping node '{node.name}' is driven by a node: not supported, "
                        "the texture is averaged")
            return None
        vals[name] = np.array(tuple(sock.default_value), np.float64)
    if kind == "NORMAL":
        reader.warn(f"{reader.owner}: Mapping node '{node.name}' of type Normal on a texture's coordinates is not "
                    "supported: the texture is averaged")
        return None
    rot = np.array(Euler(tuple(vals["Rotation"]), "XYZ").to_matrix(), np.float64)
    m = np.eye(4)
    if kind == "TEXTURE":
        scale = vals["Scale"]
        inv_s = np.where(scale != 0, 1.0 / np.where(scale != 0, scale, 1.0), 0.0)  # Cycles' safe_divide
        m[:3, :3] = inv_s[:, None] * rot.T
        m[:3, 3] = -(m[:3, :3] @ vals["Location"])
    else:
        m[:3, :3] = rot * vals["Scale"][None, :]
        if kind == "POINT":
            m[:3, 3] = vals["Location"]
    return m


def _texture_coordinates(reader: NodeReader, tex_node):
    """(coords, uv map, 4x4 matrix) of an Image Texture node's Vector input: the UV map
    (unlinked, a UV Map node, Texture Coordinate UV) or Generated (Texture Coordinate
    Generated), through any Mapping nodes; None (with a warning naming the node) otherwise."""
    m = np.eye(4)
    sock = tex_node.inputs.get("Vector")
    for _ in range(16):  # a chain of Mapping nodes, at most this long
        src = reader.source(sock) if sock is not None else None
        if src is None:
            return "UV", "", m
        n, out = src
        idn = n.bl_idname
        if idn == "ShaderNodeUVMap":
            return "UV", n.uv_map, m
        if idn == "ShaderNodeTexCoord" and out.name in ("UV", "Generated"):
            return ("UV" if out.name == "UV" else "GENERATED"), "", m
        if idn == "ShaderNodeMapping":
            mm = _mapping_matrix(n, reader)
            if mm is None:
                return None
            m = m @ mm
            sock = n.inputs.get("Vector")
            continue
        what = f"output '{out.name}' of '{n.name}'" if idn == "ShaderNodeTexCoord" else f"'{n.name}'"
        reader.warn(f"{reader.owner}: the coordinates of image texture '{tex_node.name}' come from {what}, which "
                    "is not supported (UV maps and Generated are): the texture is averaged")
        return None
    return None
