"""Shader node trees -> the core's surface kinds: what a material, light or world shader evaluates to.

Follows a node tree from its output node through reroutes, mix and add shaders, and evaluates
the BSDF it finds to one of the core's surfaces (diffuse, mirror, dielectric) with a colour, an
IOR, an emission and the rough-surface columns (core/bsdf.py: roughness, Principled's metallic /
transmission weights, IOR level, specular tint, the metal's Fresnel). What the core cannot
represent is approximated and named in the warnings: textures are averaged
(:func:`colour.image_mean`), mixes of unlike surfaces keep the heavier, anisotropy is dropped,
a Diffuse BSDF's (Oren-Nayar) roughness is Lambertian, a physical-conductor Metallic BSDF is
fitted with the F82-tint model.

Nothing a node tree holds can hang the export or reach the tracer as NaN or Inf: a node cycle
(Blender marks one link of it invalid) is detected and named (:attr:`NodeReader.cycle`; the
material then renders as the default surface), other invalid links are ignored as Cycles
ignores them, a NaN input is an error naming the owner, node and socket, and an emission
strength or colour beyond ``MAX_INTENSITY`` (Blender's fields go up to FLT_MAX) is clamped with a
warning, as is a negative strength.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import bpy
import numpy as np

from ...core.scene import SceneError
from .colour import blackbody_rgb, image_mean, in_rec709, rgb
from .messages import Warnings

__all__ = ["MAX_INTENSITY", "Surface", "node_tree", "output_node", "missing_output", "surface_socket",
           "NodeReader"]

#: The largest emission (colour x strength, W/(m^2 sr) per colour unit) and light power (W, or
#: W/m^2 for a sun) exported; larger values are clamped with a warning. Blender's fields accept up
#: to FLT_MAX (3.4e38), which overflows the tracer's float32 arithmetic into Inf pixels; 1e20
#: leaves 18 orders of magnitude for the 1/r^2 falloff, spectral weights and sample sums.
MAX_INTENSITY = 1e20
#: Output node types, and what Blender calls them.
OUTPUT_NODES = {"ShaderNodeOutputMaterial": "Material Output", "ShaderNodeOutputWorld": "World Output",
                "ShaderNodeOutputLight": "Light Output"}


@dataclass
class Surface:
    """What a shader evaluates to, in the core's terms."""

    kind: str | None  # 'DIFFUSE' | 'MIRROR' | 'DIELECTRIC' (the heaviest layer); None: no BSDF (emission only or black)
    color: np.ndarray
    ior: float = 1.5
    roughness: float = 0.0
    emission: np.ndarray = field(default_factory=lambda: np.zeros(3))
    metallic: float | None = None       # layer weights (core Materials); None: from the kind
    transmission: float | None = None
    specular_ior_level: float = 0.0     # the base's specular layer (Principled); 0: none
    specular_tint: np.ndarray = field(default_factory=lambda: np.ones(3))
    conductor_fresnel: str = "CONSTANT"  # 'CONSTANT' (Glossy BSDF) | 'F82_TINT' (Principled, Metallic BSDF)

    def layers(self) -> tuple[float, float]:
        """(metallic, transmission), from the kind where not given."""
        m = self.metallic if self.metallic is not None else float(self.kind == "MIRROR")
        t = self.transmission if self.transmission is not None else float(self.kind == "DIELECTRIC")
        return m, t


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


class NodeReader:
    """Evaluates a shader node tree to a Surface, approximating what it cannot represent."""

    def __init__(self, owner: str, warn: Warnings, to709: np.ndarray | None):
        self.owner, self.warn, self.to709 = owner, warn, to709
        #: The first node cycle met ("'A' -> 'B'", the link Blender marked invalid), or None.
        self.cycle: str | None = None

    # ---------------------------------------------------------------- sockets
    def source(self, socket):
        """(node, output socket) feeding ``socket``, following reroutes; None when unlinked, muted
        or linked through an invalid link (a cycle is recorded in :attr:`cycle`)."""
        visited = set()
        while socket is not None and socket.is_linked:
            link = socket.links[0]
            if getattr(link, "is_muted", False):
                return None
            if not getattr(link, "is_valid", True):
                self._invalid_link(link)
                return None
            node = link.from_node
            if node.bl_idname == "NodeReroute":
                if node.name in visited:  # a loop of reroutes that Blender did not flag
                    self.cycle = self.cycle or f"'{node.name}' -> '{link.to_node.name}'"
                    return None
                visited.add(node.name)
                socket = node.inputs[0] if node.inputs else None
                continue
            return node, link.from_socket
        return None

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
            return self._to709(rgb(sock.default_value))
        n, out = src
        if n.bl_idname == "ShaderNodeRGB":
            return self._to709(rgb(out.default_value))
        if n.bl_idname == "ShaderNodeBlackbody":
            return blackbody_rgb(self.temperature(n))
        if n.bl_idname in ("ShaderNodeTexImage", "ShaderNodeTexEnvironment") and getattr(n, "image", None):
            mean = image_mean(n.image)
            if mean is not None:
                self.warn(f"{self.owner}: image texture '{n.image.name}' on '{name}' is rendered as its average colour")
                return self._to709(mean)
        self.warn(f"{self.owner}: '{name}' of '{node.name}' is driven by a '{n.name}' node, which is not "
                  f"supported: using the socket's own value")
        return self._to709(rgb(sock.default_value))

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
            return float(sock.default_value)
        n, out = src
        if n.bl_idname == "ShaderNodeValue":
            return float(out.default_value)
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
        if idn == "ShaderNodeBsdfPrincipled":
            return self._principled(node)
        if idn == "ShaderNodeBsdfDiffuse":
            if self.value(node, "Roughness", 0.0) > 0.0:
                self.warn(f"{self.owner}: the roughness of '{node.name}' (Oren-Nayar) is rendered Lambertian")
            return Surface("DIFFUSE", self.color(node, "Color"), metallic=0.0, transmission=0.0)
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
            f = min(max(self.value(node, "Fac", 0.5) if node.inputs.get("Fac") else 0.5, 0.0), 1.0)
            a = self._shader(self.source(node.inputs[1]), depth + 1)
            b = self._shader(self.source(node.inputs[2]), depth + 1)
            return self._combine(a, b, 1.0 - f, f, node)
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
        if idn == "ShaderNodeBsdfTransparent":
            self.warn(f"{self.owner}: Transparent BSDF is not supported: rendered black")
            return black
        self.warn(f"{self.owner}: shader node '{node.name}' ({idn}) is not supported: rendered as a diffuse "
                  f"surface{' of its colour' if col is not None else ''}")
        return Surface("DIFFUSE", col if col is not None else np.full(3, 0.8))

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
        samples between the layers). The table's kind is the heaviest layer."""
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
        for layer in ("Subsurface Weight", "Coat Weight", "Sheen Weight"):
            if node.inputs.get(layer) is not None and self.value(node, layer, 0.0) > 0.0:
                self.warn(f"{self.owner}: the Principled BSDF's {layer.split()[0].lower()} layer is not rendered")
        if node.inputs.get("Diffuse Roughness") is not None and self.value(node, "Diffuse Roughness", 0.0) > 0.0:
            self.warn(f"{self.owner}: the Principled BSDF's diffuse roughness (Oren-Nayar) is rendered Lambertian")
        self._microfacet_options(node, "Anisotropic")
        weights = {"MIRROR": metallic, "DIELECTRIC": (1.0 - metallic) * trans, "DIFFUSE": (1.0 - metallic) * (1.0 - trans)}
        kind = max(weights, key=weights.get)  # ties: metal, then glass
        return Surface(kind, base, ior, rough, emission, metallic=metallic, transmission=trans,
                       specular_ior_level=level, specular_tint=np.clip(tint, 0.0, None), conductor_fresnel="F82_TINT")

    def _combine(self, a: Surface, b: Surface, wa: float, wb: float, node) -> Surface:
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
                           conductor_fresnel=(a if t < 0.5 else b).conductor_fresnel)
        keep = a if wa >= wb else b
        self.warn(f"{self.owner}: '{node.name}' mixes {a.kind.lower()} and {b.kind.lower()} surfaces: rendered as "
                  f"{keep.kind.lower()}")
        return _copy(keep, emission)


def _copy(s: Surface, emission) -> Surface:
    return Surface(s.kind, s.color, s.ior, s.roughness, emission, metallic=s.metallic, transmission=s.transmission,
                   specular_ior_level=s.specular_ior_level, specular_tint=s.specular_tint,
                   conductor_fresnel=s.conductor_fresnel)


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
