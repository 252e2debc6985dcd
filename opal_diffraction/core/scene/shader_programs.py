"""Shader programs as data: a material's node tree compiled to a flat list of operations over
registers (docs/physics.md section 13.6), their JSON form for the scene file and their checks.

A :class:`ShaderProgram` is what the exporter makes of the nodes that feed a BSDF's colour or
scalar inputs (blender/export/shader_compiler.py): every node becomes one or a few :class:`Op` s
in topological order, each reading registers and writing new ones (a register holds a float (B,)
or a vector / colour (B, 3) per hit, its kind fixed at compile time); ``outputs`` names the
register each material slot ('color', 'roughness', 'metallic', 'emission') reads. It is plain data
(names, register numbers, JSON-able parameters), so the scene's ``.npz`` carries it as JSON
(:meth:`ShaderProgram.to_json`), and :func:`program_problems` checks one at validation
(unknown operations or parameters, registers read before they are written or of the wrong kind:
one SceneError line naming the material and the op). ``Materials.shader_program`` indexes
``Scene.shader_programs``. The operations' meaning (Cycles' SVM, ported) and their evaluation per
hit are core/materials/shader_eval.py's.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Op", "ShaderProgram", "ProgramBuilder", "program_problems", "OPS", "SLOTS", "BUMP_SLOTS", "NORMAL_MAP_SLOTS", "COORDINATES",
           "MATH_OPERATIONS", "VECTOR_MATH_OPERATIONS", "MIX_BLEND_TYPES", "NOISE_TYPES", "VORONOI_FEATURES",
           "VORONOI_METRICS", "GRADIENT_TYPES", "MAP_RANGE_TYPES", "MAPPING_TYPES", "RAMP_TABLE_SIZE", "SKY_PARAMS"]

#: The material slots a program may feed, and the kind of register each reads ('mix': a Mix Shader's
#: Fac, the weight of a lobe mixture's second layer; docs/physics.md section 14.8).
SLOTS = {"color": "v", "roughness": "f", "metallic": "f", "emission": "v", "mix": "f",
         # a Bump node on a BSDF's Normal (docs/physics.md section 13.7): its Height, Strength and
         # Distance (negated for Invert), evaluated at the hit and at two nearby points
         "bump_height": "f", "bump_strength": "f", "bump_distance": "f",
         # a Normal Map node on a BSDF's Normal whose Color a program computes (docs/physics.md
         # section 13.5): the colour in the node's space (one of the three) and its Strength
         "normalmap_tangent": "v", "normalmap_object": "v", "normalmap_world": "v", "normalmap_strength": "f"}
#: The slots of a Normal Map node read through a program.
NORMAL_MAP_SLOTS = ("normalmap_tangent", "normalmap_object", "normalmap_world", "normalmap_strength")
#: The slots of a Bump node.
BUMP_SLOTS = ("bump_height", "bump_strength", "bump_distance")
#: Texture Coordinate outputs a program may read (per hit, interpolated from the triangle's corners).
COORDINATES = ("generated", "object", "uv")
#: Entries of a ColorRamp's table (Cycles' RAMP_TABLE_SIZE: 257 in Blender 5.0, measured against its renders).
RAMP_TABLE_SIZE = 257
#: The Math node's operations (Blender's enum names; svm/math_util.h ``svm_math``).
MATH_OPERATIONS = ("ADD", "SUBTRACT", "MULTIPLY", "DIVIDE", "MULTIPLY_ADD", "POWER", "LOGARITHM", "SQRT",
                   "INVERSE_SQRT", "ABSOLUTE", "EXPONENT", "MINIMUM", "MAXIMUM", "LESS_THAN", "GREATER_THAN",
                   "SIGN", "COMPARE", "SMOOTH_MIN", "SMOOTH_MAX", "ROUND", "FLOOR", "CEIL", "TRUNC", "FRACT",
                   "MODULO", "FLOORED_MODULO", "WRAP", "SNAP", "PINGPONG", "SINE", "COSINE", "TANGENT", "ARCSINE",
                   "ARCCOSINE", "ARCTANGENT", "ARCTAN2", "SINH", "COSH", "TANH", "RADIANS", "DEGREES")
#: The Vector Math node's operations and the kind of their result ('v' vector, 'f' float).
VECTOR_MATH_OPERATIONS = {
    "ADD": "v", "SUBTRACT": "v", "MULTIPLY": "v", "DIVIDE": "v", "MULTIPLY_ADD": "v", "CROSS_PRODUCT": "v",
    "PROJECT": "v", "REFLECT": "v", "REFRACT": "v", "FACEFORWARD": "v", "DOT_PRODUCT": "f", "DISTANCE": "f",
    "LENGTH": "f", "SCALE": "v", "NORMALIZE": "v", "SNAP": "v", "FLOOR": "v", "CEIL": "v", "MODULO": "v",
    "WRAP": "v", "FRACTION": "v", "ABSOLUTE": "v", "MINIMUM": "v", "MAXIMUM": "v", "SINE": "v", "COSINE": "v",
    "TANGENT": "v"}
#: The Mix node's colour blend modes read (svm/color_util.h); Hue, Saturation, Value and Color are not.
MIX_BLEND_TYPES = ("MIX", "ADD", "MULTIPLY", "SUBTRACT", "SCREEN", "DIVIDE", "DIFFERENCE", "EXCLUSION", "DARKEN",
                   "LIGHTEN", "OVERLAY", "DODGE", "BURN", "SOFT_LIGHT", "LINEAR_LIGHT")
NOISE_TYPES = ("MULTIFRACTAL", "FBM", "HYBRID_MULTIFRACTAL", "RIDGED_MULTIFRACTAL", "HETERO_TERRAIN")
VORONOI_FEATURES = ("F1", "F2", "SMOOTH_F1", "DISTANCE_TO_EDGE")
VORONOI_METRICS = ("EUCLIDEAN", "MANHATTAN", "CHEBYCHEV", "MINKOWSKI")
GRADIENT_TYPES = ("LINEAR", "QUADRATIC", "EASING", "DIAGONAL", "SPHERICAL", "QUADRATIC_SPHERE", "RADIAL")
MAP_RANGE_TYPES = ("LINEAR", "STEPPED", "SMOOTHSTEP", "SMOOTHERSTEP")
MAPPING_TYPES = ("POINT", "TEXTURE", "VECTOR", "NORMAL")


@dataclass(frozen=True)
class Op:
    """One operation: ``name`` (a key of OPS), the registers it reads (``args``) and writes
    (``out``), and its parameters (JSON-able)."""

    name: str
    args: tuple = ()
    out: tuple = ()
    params: dict = field(default_factory=dict)

    def __hash__(self):
        return hash((self.name, self.args, self.out, json.dumps(self.params, sort_keys=True)))


@dataclass(frozen=True)
class ShaderProgram:
    """A compiled node tree: ``ops`` in evaluation order, ``kinds`` the kind of each register
    ('f' float, 'v' vector / colour), ``outputs`` slot -> register, ``name`` for messages."""

    ops: tuple
    kinds: tuple
    outputs: dict
    name: str = ""

    def __hash__(self):
        return hash(self.to_json())

    def images(self) -> frozenset:
        """The scene textures (indices into Scene.textures) the program samples."""
        return frozenset(int(op.params["texture"]) for op in self.ops if op.name == "image")

    def reads(self) -> frozenset:
        """The texture coordinates the program reads ('generated', 'object', 'uv')."""
        return frozenset(op.params.get("kind") for op in self.ops if op.name == "coord")

    def attributes(self) -> frozenset:
        """The mesh attributes the program reads (Attribute / Color Attribute nodes; '' the mesh's
        default colour attribute)."""
        return frozenset(str(op.params.get("attribute", "")) for op in self.ops if op.name == "attribute")

    def needed(self, slot: str) -> list:
        """Indices of the ops the slot's register depends on, in order."""
        if slot not in self.outputs:
            return []
        want = {self.outputs[slot]}
        keep = []
        for i in range(len(self.ops) - 1, -1, -1):
            op = self.ops[i]
            if want.intersection(op.out):
                keep.append(i)
                want.update(op.args)
        return keep[::-1]

    def to_json(self) -> str:
        return json.dumps({"name": self.name, "kinds": "".join(self.kinds), "outputs": self.outputs,
                           "ops": [[op.name, list(op.args), list(op.out), op.params] for op in self.ops]},
                          sort_keys=True)

    @staticmethod
    def from_json(text: str) -> "ShaderProgram":
        d = json.loads(text)
        if not isinstance(d, dict):
            raise ValueError("a shader program must be a JSON object")
        ops = tuple(Op(str(o[0]), tuple(int(a) for a in o[1]), tuple(int(a) for a in o[2]), dict(o[3]))
                    for o in d.get("ops", []))
        return ShaderProgram(ops, tuple(str(d.get("kinds", ""))), {str(k): int(v) for k, v in d.get("outputs", {}).items()},
                             str(d.get("name", "")))


# ---------------------------------------------------------------------------- the op table
#: name -> (argument kinds, output kinds); a '*' output kind is decided by parameters (vector_math).
OPS = {
    "const": ((), ("?",)),
    "coord": ((), ("v",)),
    "attribute": ((), ("v", "f")),
    "math": (("f", "f", "f"), ("f",)),
    "vector_math": (("v", "v", "v", "f"), ("?",)),
    "mix_float": (("f", "f", "f"), ("f",)),
    "mix_vector": (("f", "v", "v"), ("v",)),
    "mix_vector_nonuniform": (("v", "v", "v"), ("v",)),
    "mix_color": (("f", "v", "v"), ("v",)),
    "map_range": (("f", "f", "f", "f", "f", "f"), ("f",)),
    "clamp": (("f", "f", "f"), ("f",)),
    "invert": (("f", "v"), ("v",)),
    "separate": (("v",), ("f", "f", "f")),
    "combine": (("f", "f", "f"), ("v",)),
    "mapping": (("v", "v", "v", "v"), ("v",)),
    "ramp": (("f",), ("v", "f")),
    "to_float": (("v",), ("f",)),
    "to_vector": (("f",), ("v",)),
    "noise": (("v", "f", "f", "f", "f", "f", "f", "f", "f"), ("f", "v")),
    "voronoi": (("v", "f", "f", "f", "f", "f", "f", "f", "f"), ("f", "v", "v", "f")),
    "checker": (("v", "v", "v", "f"), ("f", "v")),
    "gradient": (("v",), ("f", "v")),
    "white_noise": (("v", "f"), ("f", "v")),
    "image": (("v",), ("v", "f")),
    "wave": (("v", "f", "f", "f", "f", "f", "f"), ("f", "v")),
    "magic": (("v", "f", "f"), ("v", "f")),
    "brick": (("v", "v", "v", "v", "f", "f", "f", "f", "f", "f"), ("f", "v")),
    "gamma": (("v", "f"), ("v",)),
    "bright_contrast": (("v", "f", "f"), ("v",)),
    "hue_saturation": (("f", "f", "f", "f", "v"), ("v",)),
    "sky": (("v",), ("v",)),
    "sky_preetham": (("v",), ("v",)),
    "equirect": (("v",), ("v",)),
    "curves": (("f", "v"), ("v",)),
    "float_curve": (("f", "f"), ("f",)),
    "wavelength": (("f",), ("v",)),
    "blackbody": (("f",), ("v",)),
}
#: The Sky Texture op's parameters (core/materials/sky_texture.py ``SkyParams``, plus ``with_sun``).
SKY_PARAMS = ("multiple", "sun_disc", "sun_size", "sun_intensity", "elevation", "rotation", "altitude", "air",
              "aerosol", "ozone", "with_sun")

_ENUMS = {
    ("coord", "kind"): COORDINATES,
    ("math", "operation"): MATH_OPERATIONS,
    ("vector_math", "operation"): tuple(VECTOR_MATH_OPERATIONS),
    ("mix_color", "blend"): MIX_BLEND_TYPES,
    ("map_range", "interpolation"): MAP_RANGE_TYPES,
    ("clamp", "type"): ("MINMAX", "RANGE"),
    ("mapping", "type"): MAPPING_TYPES,
    ("noise", "type"): NOISE_TYPES,
    ("voronoi", "feature"): VORONOI_FEATURES,
    ("voronoi", "metric"): VORONOI_METRICS,
    ("gradient", "type"): GRADIENT_TYPES,
    ("to_float", "from"): ("color", "vector"),
    ("wave", "type"): ("BANDS", "RINGS"),
    ("wave", "bands_direction"): ("X", "Y", "Z", "DIAGONAL"),
    ("wave", "rings_direction"): ("X", "Y", "Z", "SPHERICAL"),
    ("wave", "profile"): ("SIN", "SAW", "TRI"),
}
_DIMENSIONS = {"noise": (1, 2, 3, 4), "voronoi": (1, 2, 3, 4), "white_noise": (1, 2, 3, 4)}


def _out_kinds(op: Op) -> tuple:
    if op.name == "const":
        return ("v",) if isinstance(op.params.get("value"), (list, tuple)) else ("f",)
    if op.name == "vector_math":
        return (VECTOR_MATH_OPERATIONS[op.params["operation"]],)
    return OPS[op.name][1]


def program_problems(program: ShaderProgram) -> str | None:
    """Why ``program`` cannot run, in one line, or None: unknown ops or parameters, registers
    read before they are written or of the wrong kind, outputs missing, non-finite constants."""
    if not isinstance(program, ShaderProgram):
        return f"a shader program must be a ShaderProgram, got {type(program).__name__}"
    kinds = program.kinds
    written: set = set()
    for i, op in enumerate(program.ops):
        where = f"op {i} ({op.name})"
        if op.name not in OPS:
            return f"{where}: unknown operation"
        arg_kinds, _ = OPS[op.name]
        if len(op.args) != len(arg_kinds):
            return f"{where}: takes {len(arg_kinds)} argument(s), got {len(op.args)}"
        for (op_name, key), allowed in _ENUMS.items():
            if op_name == op.name and op.params.get(key) not in allowed:
                return f"{where}: {key} {op.params.get(key)!r} is not one of {', '.join(allowed)}"
        if op.name in _DIMENSIONS and op.params.get("dimensions", 3) not in _DIMENSIONS[op.name]:
            return f"{where}: dimensions must be 1 to 4"
        if op.name == "const":
            v = np.asarray(op.params.get("value", np.nan), np.float64)
            if v.shape not in ((), (3,)) or not np.isfinite(v).all():
                return f"{where}: the value must be a finite number or three"
        if op.name in ("separate", "combine") and op.params.get("mode", "RGB") not in ("RGB", "HSV", "HSL"):
            return f"{where}: mode {op.params.get('mode')!r} is not one of RGB, HSV, HSL"
        if op.name == "attribute" and not isinstance(op.params.get("attribute"), str):
            return f"{where}: attribute must be an attribute name"
        if op.name == "magic" and op.params.get("depth") not in range(11):
            return f"{where}: depth must be 0 to 10"
        if op.name == "image" and (not isinstance(op.params.get("texture"), int) or op.params["texture"] < 0):
            return f"{where}: texture must be a texture index"
        if op.name == "sky":
            vals = [op.params.get(k) for k in SKY_PARAMS]
            if any(not isinstance(v, (bool, int, float)) or not np.isfinite(float(v)) for v in vals) \
                    or float(op.params["sun_size"]) <= 0 or float(op.params["altitude"]) < 0:
                return f"{where}: the sky needs finite {', '.join(SKY_PARAMS)} (sun size > 0, altitude >= 0)"
        if op.name == "sky_preetham":
            sd = np.asarray(op.params.get("sun_direction", np.nan), np.float64)
            t = np.asarray(op.params.get("turbidity", np.nan), np.float64)
            if sd.shape != (3,) or t.shape != () or not np.isfinite(sd).all() or not np.isfinite(t):
                return f"{where}: the Preetham sky needs a finite sun_direction (3) and turbidity"
        if op.name == "ramp":
            table = np.asarray(op.params.get("table", []), np.float64)
            if table.ndim != 2 or table.shape[1] != 4 or len(table) < 2 or not np.isfinite(table).all():
                return f"{where}: the table must be (n >= 2, 4) finite numbers"
        if op.name in ("curves", "float_curve"):
            table = np.asarray(op.params.get("table", []), np.float64)
            shape_ok = table.ndim == 2 and table.shape[1] == 3 if op.name == "curves" else table.ndim == 1
            lo, hi = (np.asarray(op.params.get(k, np.nan), np.float64) for k in ("min_x", "max_x"))
            if not shape_ok or len(table) < 2 or not np.isfinite(table).all() or lo.shape != () or hi.shape != () \
                    or not np.isfinite(lo) or not np.isfinite(hi) or not hi > lo \
                    or not isinstance(op.params.get("extrapolate"), bool):
                return f"{where}: the curve needs a table of n >= 2 finite {'(r, g, b) ' if op.name == 'curves' else ''}" \
                       "values, finite min_x < max_x and a boolean extrapolate"
        for a, want in zip(op.args, arg_kinds):
            if a not in written:
                return f"{where}: register {a} is read before it is written"
            if kinds[a] != want:
                return f"{where}: register {a} is a {'float' if kinds[a] == 'f' else 'vector'}, a " \
                       f"{'float' if want == 'f' else 'vector'} is expected"
        try:
            outs = _out_kinds(op)
        except KeyError:
            return f"{where}: bad parameters"
        if len(op.out) != len(outs):
            return f"{where}: writes {len(outs)} register(s), got {len(op.out)}"
        for r, want in zip(op.out, outs):
            if not 0 <= r < len(kinds) or kinds[r] != want:
                return f"{where}: register {r} must be a {'float' if want == 'f' else 'vector'}"
            written.add(r)
    for slot, r in program.outputs.items():
        if slot not in SLOTS:
            return f"unknown output slot {slot!r} (one of {', '.join(SLOTS)})"
        if r not in written or kinds[r] != SLOTS[slot]:
            return f"output {slot!r}: register {r} is not a written {'float' if SLOTS[slot] == 'f' else 'vector'}"
    return None



class ProgramBuilder:
    """Builds a :class:`ShaderProgram` op by op: :meth:`op` appends an operation and returns its
    output registers; constants are shared (one register per value)."""

    def __init__(self, name: str = ""):
        self.name = name
        self.ops: list = []
        self.kinds: list = []
        self.outputs: dict = {}
        self._consts: dict = {}

    def op(self, name: str, args=(), **params) -> tuple:
        proto = Op(name, tuple(args), (), params)
        outs = []
        for kind in _out_kinds(proto):
            self.kinds.append(kind)
            outs.append(len(self.kinds) - 1)
        self.ops.append(Op(name, tuple(int(a) for a in args), tuple(outs), params))
        return tuple(outs)

    def const(self, value) -> int:
        v = [float(x) for x in value][:3] if isinstance(value, (list, tuple, np.ndarray)) else float(value)
        key = json.dumps(v)
        if key not in self._consts:
            self._consts[key] = self.op("const", value=v)[0]
        return self._consts[key]

    def kind(self, reg: int) -> str:
        return self.kinds[reg]

    def finish(self) -> ShaderProgram:
        return ShaderProgram(tuple(self.ops), tuple(self.kinds), dict(self.outputs), self.name)

