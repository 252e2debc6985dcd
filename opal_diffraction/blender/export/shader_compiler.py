"""Shader node trees -> shader programs: the nodes feeding a BSDF's colour or scalar inputs,
compiled to the core's flat program (core/scene/shader_programs.py; docs/physics.md section 13.6).

:class:`ShaderCompiler` walks from a BSDF input upstream, depth first, and appends each node's
operations once (memoised per node output and group path) to one :class:`ProgramBuilder` per
material, so the program lists the nodes in an order where every register is written before it
is read. It reads:

- textures: Noise, Voronoi (F1, F2, Smooth F1, Distance to Edge), Checker, Gradient, White Noise,
  Wave, Magic, Brick, Sky (single and multiple scattering; core/materials/sky_texture.py);
- converters: ColorRamp (a 257-entry table of Blender's own ``ColorRamp.evaluate``, as Cycles
  bakes it), Math, Vector Math, Mix (float, vector, colour; and the legacy MixRGB), Map Range
  (float), Clamp, Invert, Gamma, Bright/Contrast, Hue/Saturation/Value, RGB to BW,
  Separate / Combine XYZ and Color (RGB) (and the legacy RGB nodes),
  Mapping, Value, RGB; RGB Curves and Float Curves (a RAMP_TABLE_SIZE table of Blender's own
  curve evaluation over the curves' x range, as Cycles bakes it, read with Cycles' extrapolation);
  Wavelength and Blackbody (Cycles' RGB of them, core/materials/shader_eval.py);
- inputs: Texture Coordinate (Generated, Object, UV), UV Map; a texture's unlinked Vector is
  Generated, as in Cycles; Color Attribute and Attribute (geometry: a mesh attribute per corner,
  export/meshes.py ``corner_attribute``; Fac the components' average, as ``svm_node_attr``);
- structure: node groups are inlined (Group Input / Group Output followed through the group
  node's sockets, nested groups too), reroutes and muted nodes followed (a muted node passes
  its first matching input through, as Blender's internal links do), a cycle refused with a
  warning naming the node.

Image Texture nodes inside the program (behind a ColorRamp, a Mix, ...) sample the scene's
image per hit at their Vector (unlinked: the UV map), flat projection; in a world's graph
(``world``) an Environment Texture samples its image at the equirectangular (u, v) of its Vector
(unlinked: the ray direction). Anything else on the way
(Vector Curves, an object / instancer / view-layer Attribute, a Texture
Coordinate output other than the three above, a colour mode other than RGB) is named in one
warning and replaced by the socket's own value, as before. Colours typed into sockets are the
blend file's working space converted to linear Rec.709 (export/colour.py).
"""

from __future__ import annotations

import numpy as np

from ...core.materials.shader_eval import evaluate
from ...core.materials.sky_texture import SKY_TYPES, sky_params
from ...core.scene.checks import SceneError
from ...core.scene.shader_programs import (MATH_OPERATIONS, MIX_BLEND_TYPES, RAMP_TABLE_SIZE, VECTOR_MATH_OPERATIONS,
                                           ProgramBuilder, ShaderProgram)
from .colour import rgb

__all__ = ["ShaderCompiler", "COMPILED_NODES", "program_average"]

#: Node types the compiler reads.
COMPILED_NODES = frozenset({
    "ShaderNodeTexNoise", "ShaderNodeTexVoronoi", "ShaderNodeTexChecker", "ShaderNodeTexGradient",
    "ShaderNodeTexWhiteNoise", "ShaderNodeValToRGB", "ShaderNodeMath", "ShaderNodeVectorMath", "ShaderNodeMix",
    "ShaderNodeMixRGB", "ShaderNodeMapRange", "ShaderNodeClamp", "ShaderNodeInvert", "ShaderNodeSeparateXYZ",
    "ShaderNodeCombineXYZ", "ShaderNodeSeparateColor", "ShaderNodeCombineColor", "ShaderNodeSeparateRGB",
    "ShaderNodeCombineRGB", "ShaderNodeMapping", "ShaderNodeValue", "ShaderNodeRGB", "ShaderNodeTexCoord",
    "ShaderNodeUVMap", "ShaderNodeGroup", "NodeGroupInput", "ShaderNodeTexImage", "ShaderNodeTexWave",
    "ShaderNodeTexMagic", "ShaderNodeTexBrick", "ShaderNodeGamma", "ShaderNodeBrightContrast",
    "ShaderNodeHueSaturation", "ShaderNodeRGBToBW", "ShaderNodeTexSky", "ShaderNodeTexEnvironment",
    "ShaderNodeVertexColor", "ShaderNodeAttribute", "ShaderNodeRGBCurve", "ShaderNodeFloatCurve",
    "ShaderNodeWavelength", "ShaderNodeBlackbody"})

#: Attribute names Cycles resolves to its volume grids' standard attributes: zeros on a mesh.
CYCLES_VOLUME_ATTRIBUTES = frozenset({"density", "color", "flame", "heat", "temperature", "velocity"})

_KIND = {"VALUE": "f", "INT": "f", "BOOLEAN": "f", "RGBA": "v", "VECTOR": "v"}
_DIMS = {"1D": 1, "2D": 2, "3D": 3, "4D": 4}


class _Unread(Exception):
    """A node the compiler does not read (the caller warns and uses the socket's value)."""


class ShaderCompiler:
    """Compiles the node inputs of one material into one program (``builder``)."""

    def __init__(self, reader):
        self.reader = reader            # nodes.NodeReader: source(), warn, owner, colour conversion
        self.builder = ProgramBuilder(reader.owner)
        self._memo: dict = {}           # (group path, node name, output identifier) -> register
        self._visiting: set = set()
        self.uv_maps: set = set()       # UV maps the program reads ('' the active render map)
        #: Sky Texture nodes (by name) whose sun disc is left out: the world exports it as a sun lamp.
        self.sky_sun_lamps: frozenset = frozenset()
        #: Compiling a world's graph: Environment Textures are read (their Vector is the direction).
        self.world = False

    # ------------------------------------------------------------------ entry
    def compile_input(self, node, name: str, kind: str):
        """The register holding input ``name`` of ``node`` as ``kind`` ('f' / 'v'), or None when
        what drives it is not read (the caller then warns and keeps the socket's value)."""
        sock = node.inputs.get(name)
        if sock is None:
            return None
        src = self.reader.source(sock, groups=False)
        if src is None or not self._compilable(src[0]):
            return None
        try:
            return self._socket(sock, self.reader.group_path(node), kind)
        except _Unread:
            return None

    def finish(self, outputs: dict) -> ShaderProgram:
        self.builder.outputs = dict(outputs)
        return self.builder.finish()

    def average(self, reg: int, slot: str) -> np.ndarray:
        """The mean of register ``reg`` (program_average) as ``slot`` reads it."""
        b = self.builder
        return program_average(ShaderProgram(tuple(b.ops), tuple(b.kinds), {slot: reg}), slot)

    # ------------------------------------------------------------------ sockets
    @staticmethod
    def _compilable(node) -> bool:
        return node.bl_idname in COMPILED_NODES

    def _const_of(self, sock, kind: str) -> int:
        b = self.builder
        v = getattr(sock, "default_value", 0.0)
        stype = getattr(sock, "type", "VALUE")
        if stype == "RGBA":
            col = self.reader._to709(rgb(v))
            if np.isnan(col).any():
                raise SceneError(f"{self.reader.owner}: '{sock.name}' of '{sock.node.name}' is NaN")
            reg = b.const([float(c) for c in col])
        elif stype == "VECTOR":
            vec = [float(c) for c in tuple(v)[:3]]
            if any(c != c for c in vec):
                raise SceneError(f"{self.reader.owner}: '{sock.name}' of '{sock.node.name}' is NaN")
            reg = b.const(vec)
        else:
            f = float(v) if not hasattr(v, "__len__") else float(tuple(v)[0])
            if f != f:
                raise SceneError(f"{self.reader.owner}: '{sock.name}' of '{sock.node.name}' is NaN")
            reg = b.const(f)
        return self._convert(reg, kind, stype)

    def _convert(self, reg: int, kind: str, stype: str) -> int:
        have = self.builder.kind(reg)
        if have == kind:
            return reg
        if kind == "v":
            return self.builder.op("to_vector", [reg])[0]
        return self.builder.op("to_float", [reg], **{"from": "color" if stype == "RGBA" else "vector"})[0]

    def _socket(self, sock, path: tuple, kind: str, default_generated: bool = False) -> int:
        """Register of input socket ``sock`` (in the group ``path``) as ``kind``."""
        src = self.reader.source(sock, groups=False)
        if src is None:
            if default_generated and sock.name == "Vector" and getattr(sock, "type", "") == "VECTOR":
                return self.builder.op("coord", kind="generated")[0]  # a texture's default coordinates
            return self._const_of(sock, kind)
        node, out = src
        if node.bl_idname == "NodeGroupInput":  # the group node's own input, one level out
            if not path:
                return self._const_of(sock, kind)
            group = path[-1]
            outer = next((s for s in group.inputs if s.identifier == out.identifier), None)
            if outer is None:
                return self._const_of(sock, kind)
            return self._socket(outer, path[:-1], kind, default_generated)
        try:
            reg = self._output(node, out, path)
        except _Unread:  # named in a warning: this input keeps its own value, the rest compiles
            return self._const_of(sock, kind)
        return self._convert(reg, kind, out.type)

    def _output(self, node, out, path: tuple) -> int:
        key = (tuple(n.name for n in path), node.id_data.name if node.id_data else "", node.name, out.identifier)
        if key in self._memo:
            return self._memo[key]
        if key in self._visiting:
            raise self._fail(node, f"a node cycle through '{node.name}'")
        self._visiting.add(key)
        try:
            reg = self._node(node, out, path)
        finally:
            self._visiting.discard(key)
        self._memo[key] = reg
        return reg

    def _fail(self, node, why: str) -> _Unread:
        self.reader.warn(f"{self.reader.owner}: {why} is not read: its input uses the socket's own value")
        return _Unread()

    def _in(self, node, ident, path, kind, default_generated=False) -> int:
        sock = next((s for s in node.inputs if s.identifier == ident), None)
        if sock is None:
            sock = node.inputs.get(ident)
        if sock is None:
            raise self._fail(node, f"input '{ident}' of '{node.name}'")
        return self._socket(sock, path, kind, default_generated)

    # ------------------------------------------------------------------ nodes
    def _node(self, node, out, path: tuple) -> int:  # noqa: C901 - one branch per node type
        b = self.builder
        idn = node.bl_idname
        oname = out.identifier  # names change between versions ('Fac' is shown as 'Factor' in 5.0)
        if getattr(node, "mute", False):
            for link in getattr(node, "internal_links", ()):
                if link.to_socket.identifier == out.identifier:
                    return self._socket(link.from_socket, path, _KIND.get(out.type, "f"))
            return self._const_of(out, _KIND.get(out.type, "f"))
        if idn == "ShaderNodeGroup":
            tree = node.node_tree
            gout = None if tree is None else next(
                (n for n in tree.nodes if n.bl_idname == "NodeGroupOutput" and getattr(n, "is_active_output", True)),
                None)
            inner = None if gout is None else next((s for s in gout.inputs if s.identifier == out.identifier), None)
            if inner is None:
                return self._const_of(out, _KIND.get(out.type, "f"))
            return self._socket(inner, path + (node,), _KIND.get(out.type, "f"))
        if idn not in COMPILED_NODES:
            raise self._fail(node, f"node '{node.name}' ({idn})")
        if idn == "ShaderNodeValue":
            return b.const(float(out.default_value))
        if idn == "ShaderNodeRGB":
            return b.const([float(c) for c in self.reader._to709(rgb(out.default_value))])
        if idn == "ShaderNodeTexCoord":
            if oname in ("Generated", "UV") or (oname == "Object" and getattr(node, "object", None) is None):
                if oname == "UV":
                    self.uv_maps.add("")
                return b.op("coord", kind=oname.lower())[0]
            what = "Object output of another object" if oname == "Object" else f"{oname} output"
            raise self._fail(node, f"the Texture Coordinate {what} ('{node.name}')")
        if idn == "ShaderNodeVertexColor":  # Color Attribute: '' the mesh's default colour attribute
            col, alpha = self._attribute(node, str(getattr(node, "layer_name", "") or ""))
            return alpha if oname == "Alpha" else col
        if idn == "ShaderNodeAttribute":
            if getattr(node, "attribute_type", "GEOMETRY") != "GEOMETRY":
                raise self._fail(node, f"the {node.attribute_type.lower()} attribute of '{node.name}'")
            col, alpha = self._attribute(node, str(node.attribute_name))
            if oname == "Alpha":
                return alpha
            if oname in ("Fac", "Factor"):  # svm_node_attr: the average of the components
                return b.op("to_float", [col], **{"from": "vector"})[0]
            return col
        if idn == "ShaderNodeUVMap":
            self.uv_maps.add(getattr(node, "uv_map", ""))
            return b.op("coord", kind="uv")[0]
        if idn == "ShaderNodeMapping":
            kind = getattr(node, "vector_type", "POINT")
            vec = self._in(node, "Vector", path, "v")
            loc = self._in(node, "Location", path, "v") if kind in ("POINT", "TEXTURE") else b.const([0.0, 0.0, 0.0])
            return b.op("mapping", [vec, loc, self._in(node, "Rotation", path, "v"), self._in(node, "Scale", path, "v")],
                        type=kind)[0]
        if idn == "ShaderNodeMath":
            a = [self._socket(node.inputs[i], path, "f") for i in range(3)]
            if node.operation not in MATH_OPERATIONS:
                raise self._fail(node, f"Math operation {node.operation} of '{node.name}'")
            return b.op("math", a, operation=node.operation, clamp=bool(node.use_clamp))[0]
        if idn == "ShaderNodeVectorMath":
            op = node.operation
            if op not in VECTOR_MATH_OPERATIONS:
                raise self._fail(node, f"Vector Math operation {op} of '{node.name}'")
            a = [self._socket(node.inputs[i], path, "v") for i in range(3)] + [self._socket(node.inputs[3], path, "f")]
            reg = b.op("vector_math", a, operation=op)[0]
            want = "f" if oname == "Value" else "v"
            if b.kind(reg) != want:  # the other output of the node: Cycles leaves it zero
                return b.const(0.0) if want == "f" else b.const([0.0, 0.0, 0.0])
            return reg
        if idn == "ShaderNodeMix":
            dt = node.data_type
            if dt == "FLOAT":
                return b.op("mix_float", [self._in(node, "Factor_Float", path, "f"), self._in(node, "A_Float", path, "f"),
                                          self._in(node, "B_Float", path, "f")],
                            clamp_factor=bool(node.clamp_factor))[0]
            if dt == "VECTOR":
                if node.factor_mode == "NON_UNIFORM":
                    return b.op("mix_vector_nonuniform", [self._in(node, "Factor_Vector", path, "v"),
                                                          self._in(node, "A_Vector", path, "v"),
                                                          self._in(node, "B_Vector", path, "v")],
                                clamp_factor=bool(node.clamp_factor))[0]
                return b.op("mix_vector", [self._in(node, "Factor_Float", path, "f"), self._in(node, "A_Vector", path, "v"),
                                           self._in(node, "B_Vector", path, "v")],
                            clamp_factor=bool(node.clamp_factor))[0]
            if dt == "RGBA":
                if node.blend_type not in MIX_BLEND_TYPES:
                    raise self._fail(node, f"the {node.blend_type.title()} blend mode of '{node.name}'")
                return b.op("mix_color", [self._in(node, "Factor_Float", path, "f"), self._in(node, "A_Color", path, "v"),
                                          self._in(node, "B_Color", path, "v")],
                            blend=node.blend_type, clamp_factor=bool(node.clamp_factor),
                            clamp_result=bool(node.clamp_result))[0]
            raise self._fail(node, f"the {dt.lower()} Mix node '{node.name}'")
        if idn == "ShaderNodeMixRGB":
            if node.blend_type not in MIX_BLEND_TYPES:
                raise self._fail(node, f"the {node.blend_type.title()} blend mode of '{node.name}'")
            return b.op("mix_color", [self._in(node, "Fac", path, "f"), self._in(node, "Color1", path, "v"),
                                      self._in(node, "Color2", path, "v")],
                        blend=node.blend_type, clamp_factor=True, clamp_result=bool(node.use_clamp))[0]
        if idn == "ShaderNodeMapRange":
            if node.data_type != "FLOAT":
                raise self._fail(node, f"the vector Map Range node '{node.name}'")
            args = [self._in(node, n, path, "f") for n in ("Value", "From Min", "From Max", "To Min", "To Max", "Steps")]
            return b.op("map_range", args, interpolation=node.interpolation_type, clamp=bool(node.clamp))[0]
        if idn == "ShaderNodeClamp":
            return b.op("clamp", [self._in(node, n, path, "f") for n in ("Value", "Min", "Max")],
                        type=node.clamp_type)[0]
        if idn == "ShaderNodeGamma":
            return b.op("gamma", [self._in(node, "Color", path, "v"), self._in(node, "Gamma", path, "f")])[0]
        if idn == "ShaderNodeBrightContrast":
            return b.op("bright_contrast", [self._in(node, "Color", path, "v"), self._in(node, "Bright", path, "f"),
                                            self._in(node, "Contrast", path, "f")])[0]
        if idn == "ShaderNodeHueSaturation":
            return b.op("hue_saturation", [self._in(node, n, path, "f") for n in ("Hue", "Saturation", "Value", "Fac")]
                        + [self._in(node, "Color", path, "v")])[0]
        if idn == "ShaderNodeRGBToBW":
            return b.op("to_float", [self._in(node, "Color", path, "v")], **{"from": "color"})[0]
        if idn == "ShaderNodeInvert":
            return b.op("invert", [self._in(node, "Fac", path, "f"), self._in(node, "Color", path, "v")])[0]
        if idn in ("ShaderNodeSeparateXYZ", "ShaderNodeSeparateColor", "ShaderNodeSeparateRGB"):
            mode = getattr(node, "mode", "RGB")  # Separate Color: RGB, HSV or HSL
            regs = b.op("separate", [self._socket(node.inputs[0], path, "v")], **({} if mode == "RGB" else {"mode": mode}))
            index = {"X": 0, "Y": 1, "Z": 2, "Red": 0, "Green": 1, "Blue": 2, "R": 0, "G": 1, "B": 2}[oname]
            return regs[index]
        if idn in ("ShaderNodeCombineXYZ", "ShaderNodeCombineColor", "ShaderNodeCombineRGB"):
            mode = getattr(node, "mode", "RGB")
            return b.op("combine", [self._socket(node.inputs[i], path, "f") for i in range(3)],
                        **({} if mode == "RGB" else {"mode": mode}))[0]
        if idn == "ShaderNodeValToRGB":
            ramp = node.color_ramp
            table = [list(ramp.evaluate(i / (RAMP_TABLE_SIZE - 1))) for i in range(RAMP_TABLE_SIZE)]
            table = [self._ramp_colour(e) for e in table]
            col, alpha = b.op("ramp", [self._in(node, "Fac", path, "f")], table=table,
                              constant=ramp.interpolation == "CONSTANT")
            return col if oname == "Color" else alpha
        if idn in ("ShaderNodeRGBCurve", "ShaderNodeFloatCurve"):
            rgb_curves = idn == "ShaderNodeRGBCurve"
            table, lo, hi = self._curve_table(node, rgb_curves)
            params = dict(table=table, min_x=lo, max_x=hi, extrapolate=node.mapping.extend == "EXTRAPOLATED")
            if rgb_curves:
                return b.op("curves", [self._in(node, "Fac", path, "f"), self._in(node, "Color", path, "v")],
                            **params)[0]
            return b.op("float_curve", [self._in(node, "Factor", path, "f"), self._in(node, "Value", path, "f")],
                        **params)[0]
        if idn == "ShaderNodeWavelength":
            return b.op("wavelength", [self._in(node, "Wavelength", path, "f")])[0]
        if idn == "ShaderNodeBlackbody":
            return b.op("blackbody", [self._in(node, "Temperature", path, "f")])[0]
        if idn == "ShaderNodeTexImage":
            return self._image(node, oname, path)
        if idn == "ShaderNodeTexEnvironment":
            return self._environment(node, oname, path)
        # textures: the unlinked Vector is Generated
        vec = self._in(node, "Vector", path, "v", default_generated=True) if node.inputs.get("Vector") else None
        if idn == "ShaderNodeTexNoise":
            args = [vec] + [self._in(node, n, path, "f") for n in
                            ("W", "Scale", "Detail", "Roughness", "Lacunarity", "Offset", "Gain", "Distortion")]
            fac, col = b.op("noise", args, type=node.noise_type, dimensions=_DIMS[node.noise_dimensions],
                            normalize=bool(getattr(node, "normalize", True)))
            return fac if oname == "Fac" else col
        if idn == "ShaderNodeTexVoronoi":
            if node.feature == "N_SPHERE_RADIUS" or oname == "Radius":
                raise self._fail(node, f"the n-sphere radius of '{node.name}'")
            args = [vec] + [self._in(node, n, path, "f") for n in
                            ("W", "Scale", "Detail", "Roughness", "Lacunarity", "Smoothness", "Exponent", "Randomness")]
            regs = b.op("voronoi", args, feature=node.feature, metric=node.distance,
                        dimensions=_DIMS[node.voronoi_dimensions], normalize=bool(getattr(node, "normalize", False)))
            return regs[{"Distance": 0, "Color": 1, "Position": 2, "W": 3}[oname]]
        if idn == "ShaderNodeTexChecker":
            fac, col = b.op("checker", [vec, self._in(node, "Color1", path, "v"), self._in(node, "Color2", path, "v"),
                                        self._in(node, "Scale", path, "f")])
            return fac if oname == "Fac" else col
        if idn == "ShaderNodeTexGradient":
            fac, col = b.op("gradient", [vec], type=node.gradient_type)
            return fac if oname == "Fac" else col
        if idn == "ShaderNodeTexWhiteNoise":
            val, col = b.op("white_noise", [vec, self._in(node, "W", path, "f")],
                            dimensions=_DIMS[node.noise_dimensions])
            return val if oname == "Value" else col
        if idn == "ShaderNodeTexWave":
            args = [vec] + [self._in(node, n, path, "f") for n in
                            ("Scale", "Distortion", "Detail", "Detail Scale", "Detail Roughness", "Phase Offset")]
            fac, col = b.op("wave", args, type=node.wave_type, bands_direction=node.bands_direction,
                            rings_direction=node.rings_direction, profile=node.wave_profile)
            return fac if oname == "Fac" else col
        if idn == "ShaderNodeTexBrick":
            args = [vec] + [self._in(node, n, path, "v") for n in ("Color1", "Color2", "Mortar")] + [
                self._in(node, n, path, "f") for n in ("Scale", "Mortar Size", "Mortar Smooth", "Bias", "Brick Width",
                                                       "Row Height")]
            fac, col = b.op("brick", args, offset=float(node.offset), offset_frequency=int(node.offset_frequency),
                            squash=float(node.squash), squash_frequency=int(node.squash_frequency))
            return fac if oname == "Fac" else col
        if idn == "ShaderNodeTexSky":
            if vec is None:  # no Vector socket on the evaluated node: the direction, as unlinked
                vec = b.op("coord", kind="generated")[0]
            if node.sky_type == "PREETHAM":
                sd = [float(c) for c in node.sun_direction]
                if not all(np.isfinite(sd)) or not np.isfinite(float(node.turbidity)):
                    raise SceneError(f"{self.reader.owner}: Sky Texture '{node.name}' has a NaN or infinite setting")
                return b.op("sky_preetham", [vec], sun_direction=sd, turbidity=float(node.turbidity))[0]
            if node.sky_type not in SKY_TYPES:
                raise self._fail(node, f"the {node.sky_type.replace('_', ' ').title()} sky model of '{node.name}'")
            sp = sky_params(node.sky_type, node.sun_disc, node.sun_size, node.sun_intensity, node.sun_elevation,
                            node.sun_rotation, node.altitude, node.air_density, node.aerosol_density,
                            node.ozone_density)
            if not all(np.isfinite(float(v)) for v in sp):
                raise SceneError(f"{self.reader.owner}: Sky Texture '{node.name}' has a NaN or infinite setting")
            return b.op("sky", [vec], with_sun=node.name not in self.sky_sun_lamps,
                        **{k: (bool(v) if isinstance(v, bool) else float(v)) for k, v in sp._asdict().items()})[0]
        if idn == "ShaderNodeTexMagic":
            col, fac = b.op("magic", [vec, self._in(node, "Scale", path, "f"), self._in(node, "Distortion", path, "f")],
                            depth=int(node.turbulence_depth))
            return fac if oname == "Fac" else col
        raise self._fail(node, f"node '{node.name}' ({idn})")

    def _attribute(self, node, name: str) -> tuple:
        """(colour, alpha) registers of the mesh attribute ``name``. Names Cycles takes for its own
        standard attributes are read as Cycles reads them (measured in Blender 5.0): 'generated'
        and 'uv' are those coordinates (alpha 1), and the volume grids' names ('density', 'color',
        'flame', 'heat', 'temperature', 'velocity') read zeros on a mesh, whatever attribute of
        that name the mesh has (with a warning)."""
        b = self.builder
        if name in ("generated", "uv"):
            if name == "uv":
                self.uv_maps.add("")
            return b.op("coord", kind=name)[0], b.const(1.0)
        if name in CYCLES_VOLUME_ATTRIBUTES:
            self.reader.warn(f"{self.reader.owner}: '{node.name}' reads the attribute '{name}', which Cycles takes "
                             "for a volume grid: black on a mesh, as in Cycles (rename the attribute)")
            return b.const([0.0, 0.0, 0.0]), b.const(0.0)
        return b.op("attribute", attribute=name)

    def _image(self, node, oname: str, path: tuple) -> int:
        """An Image Texture inside the program (e.g. behind a ColorRamp): the scene texture at its
        Vector's (x, y) (unlinked: the UV map); flat projection only."""
        b = self.builder
        table = self.reader.textures
        image = getattr(node, "image", None)
        if table is None or image is None:
            raise self._fail(node, f"image texture '{node.name}' without an image")
        if getattr(node, "projection", "FLAT") != "FLAT":
            raise self._fail(node, f"the {node.projection.lower()} projection of image texture '{node.name}'")
        idx = table.index(image, getattr(node, "interpolation", "Linear"), getattr(node, "extension", "REPEAT"),
                          self.reader.owner)
        if idx is None:  # no pixels (warned by the table): Cycles' magenta
            return b.const([1.0, 0.0, 1.0]) if oname == "Color" else b.const(1.0)
        sock = node.inputs.get("Vector")
        if sock is not None and self.reader.source(sock, groups=False) is not None:
            vec = self._socket(sock, path, "v")
        else:
            self.uv_maps.add("")
            vec = b.op("coord", kind="uv")[0]
        col, alpha = b.op("image", [vec], texture=int(idx))
        return col if oname == "Color" else alpha

    def _environment(self, node, oname: str, path: tuple) -> int:
        """An Environment Texture inside a world's graph: the scene texture at the equirectangular
        (u, v) of its Vector (unlinked: the ray direction), Cycles' REPEAT lookup."""
        b = self.builder
        table = self.reader.textures
        if not self.world or table is None:
            raise self._fail(node, f"environment texture '{node.name}' outside a world")
        if getattr(node, "projection", "EQUIRECTANGULAR") != "EQUIRECTANGULAR":
            raise self._fail(node, f"the mirror-ball projection of environment texture '{node.name}'")
        image = getattr(node, "image", None)
        idx = None if image is None else table.index(image, getattr(node, "interpolation", "Linear"), "REPEAT",
                                                     self.reader.owner)
        if idx is None:  # no image or no pixels: Cycles' magenta
            if image is None:
                self.reader.warn(f"{self.reader.owner}: Environment Texture '{node.name}' has no image: magenta, "
                                 "as in Cycles")
            return b.const([1.0, 0.0, 1.0]) if oname == "Color" else b.const(1.0)
        sock = node.inputs.get("Vector")
        vec = self._socket(sock, path, "v", default_generated=True) if sock is not None else \
            b.op("coord", kind="generated")[0]
        col, alpha = b.op("image", [b.op("equirect", [vec])[0]], texture=int(idx))
        return col if oname == "Color" else alpha

    def _curve_table(self, node, rgb_curves: bool) -> tuple:
        """(table, min_x, max_x) of an RGB / Float Curves node as Cycles bakes it
        (intern/cycles/blender/util.h ``curvemapping_color_to_array`` / ``curvemapping_float_to_array``):
        RAMP_TABLE_SIZE samples over the curves' own x range (the first to the last point, over
        the R, G, B and combined curves, or the one float curve), each the channel's curve of the
        combined curve's value (R(C(x)), ...) as Blender itself evaluates them."""
        mapping = node.mapping
        mapping.initialize()
        mapping.update()
        curves = list(mapping.curves)[:4 if rgb_curves else 1]
        lo = min(float(c.points[0].location[0]) for c in curves)
        hi = max(float(c.points[len(c.points) - 1].location[0]) for c in curves)
        if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
            raise self._fail(node, f"the curve of '{node.name}' (its points share one x)")
        xs = [np.float32(lo + np.float32(i) / np.float32(RAMP_TABLE_SIZE - 1) * np.float32(hi - lo))
              for i in range(RAMP_TABLE_SIZE)]
        if not rgb_curves:
            return [float(mapping.evaluate(curves[0], float(x))) for x in xs], lo, hi
        combined = curves[3]
        table = []
        for x in xs:
            c = float(mapping.evaluate(combined, float(x)))
            table.append([float(mapping.evaluate(curves[k], c)) for k in range(3)])
        return table, lo, hi

    def _ramp_colour(self, rgba) -> list:
        col = self.reader._to709(np.asarray(rgba[:3], np.float64))
        return [float(c) for c in col] + [float(rgba[3])]


def program_average(program: ShaderProgram, slot: str, n: int = 8) -> np.ndarray:
    """The mean of ``slot`` over an n^3 grid of Generated coordinates in [0, 1]^3 (Object: the
    same points mapped to [-1, 1]^3, UV: their (x, y, 0)): the one value per material that what
    does not read per hit (the light pass, emitters' power) uses, as an image's mean colour."""
    c = (np.arange(n) + 0.5) / n
    g = np.stack(np.meshgrid(c, c, c, indexing="ij"), axis=-1).reshape(-1, 3).astype(np.float32)
    inputs = {"generated": g, "object": g * np.float32(2) - np.float32(1),
              "uv": np.concatenate([g[:, :2], np.zeros((len(g), 1), np.float32)], axis=1)}
    return np.asarray(evaluate(program, slot, inputs, len(g)), np.float64).mean(axis=0)
