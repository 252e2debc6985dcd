"""Image textures: Cycles' texel lookup, vectorised over a batch of UVs, and their prepared form.

The lookup follows Cycles' CPU kernel (``intern/cycles/kernel/device/cpu/image.h``, Blender 5.0)
so a texture renders as it does in Cycles (docs/physics.md section 13.1):

- texel (i, j) covers [i, i + 1) / W x [j, j + 1) / H of UV space, row 0 at the bottom (Blender's
  image order), and its value sits at the centre ((i + 0.5) / W, (j + 0.5) / H);
- CLOSEST returns the texel containing ``uv``; LINEAR blends the four texels around it
  bilinearly (x = u W - 0.5, so a texel centre returns that texel exactly); CUBIC (and SMART,
  which Cycles' CPU kernel renders as cubic) is the uniform cubic B-spline over 4 x 4 texels;
- REPEAT wraps, EXTEND clamps to the border texel, MIRROR reflects, CLIP reads transparent
  black outside the image (also in the border taps of LINEAR and CUBIC);
- an sRGB-encoded texture (``TextureEncoding.SRGB``: an 8-bit sRGB image, which Cycles keeps
  encoded, ``compress_as_srgb``) is interpolated in its encoded values and decoded after, with
  Cycles' ``color_srgb_to_linear`` (alpha is never decoded).

Everything is float32 like the kernel; the integer part is taken as Cycles' ``frac`` does
(truncation, minus one below zero). :class:`PreparedTextures` holds the images (read-only) and
each material's bindings, and :meth:`PreparedTextures.lookup` samples only the hits whose
material has a texture in a given slot (most hits of a batch have none).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..util.enums import TextureEncoding, TextureExtension, TextureInterpolation
from ..util.geometry import interpolate_corners
from ..scene.shader_programs import BUMP_SLOTS, NORMAL_MAP_SLOTS
from .shader_eval import evaluate

__all__ = [
    "LUMINANCE_709",
    "srgb_to_linear",
    "sample_texture",
    "PreparedTextures",
    "prepare_textures",
    "TEXTURE_SLOTS",
]

#: Rec.709 luminance weights: Cycles reads a colour plugged into a float socket (roughness,
#: metallic) as ``linear_rgb_to_gray`` (svm/convert.h NODE_CONVERT_CF), the film's RGB -> Y.
LUMINANCE_709 = np.array([0.2126729, 0.7151522, 0.0721750], np.float32)

#: The material columns that bind a texture, and the slot name each has in PreparedTextures.
TEXTURE_SLOTS = {"color": "color_texture", "roughness": "roughness_texture", "metallic": "metallic_texture",
                 "emission": "emission_texture", "normal": "normal_texture"}

_CLOSEST, _LINEAR = int(TextureInterpolation.CLOSEST), int(TextureInterpolation.LINEAR)
_REPEAT, _EXTEND, _CLIP, _MIRROR = (int(e) for e in (TextureExtension.REPEAT, TextureExtension.EXTEND,
                                                      TextureExtension.CLIP, TextureExtension.MIRROR))
_SRGB = int(TextureEncoding.SRGB)


def srgb_to_linear(x) -> np.ndarray:
    """sRGB-encoded values -> linear, as Cycles' ``color_srgb_to_linear`` (util/color.h): below
    0.04045 x / 12.92 (negative: 0), else ((x + 0.055) / 1.055)^2.4. float32, elementwise."""
    x = np.asarray(x, np.float32)
    lo = np.maximum(x, np.float32(0)) * np.float32(1 / 12.92)
    hi = ((np.maximum(x, np.float32(0.04045)) + np.float32(0.055)) * np.float32(1 / 1.055)) ** np.float32(2.4)
    return np.where(x < np.float32(0.04045), lo, hi).astype(np.float32, copy=False)


def _frac(x: np.ndarray):
    """(integer part, fraction) as Cycles' ``frac``: int(x) - (x < 0)."""
    i = x.astype(np.int32) - (x < 0)
    return i, x - i.astype(np.float32)


def _wrap(i: np.ndarray, n: int, extension: int) -> np.ndarray:
    if extension == _REPEAT:
        return np.mod(i, n)  # non-negative for n > 0, as Cycles' wrap_periodic
    if extension == _MIRROR:
        m = np.abs(i + (i < 0)) % (2 * n)
        return np.where(m >= n, 2 * n - m - 1, m)
    return np.clip(i, 0, n - 1)  # EXTEND; CLIP indices are masked by the caller


def _cubic_weights(t: np.ndarray) -> list:
    """Uniform cubic B-spline weights of the taps at -1, 0, +1, +2 (Cycles' SET_CUBIC_SPLINE_WEIGHTS)."""
    return [(((-1 / 6) * t + 0.5) * t - 0.5) * t + 1 / 6,
            ((0.5 * t - 1.0) * t) * t + 2 / 3,
            ((-0.5 * t + 0.5) * t + 0.5) * t + 1 / 6,
            (1 / 6) * t * t * t]


def sample_texture(tex, uv, interpolation: int = _LINEAR, extension: int = _REPEAT,
                   encoding: int = int(TextureEncoding.LINEAR)) -> np.ndarray:
    """The texture ``tex`` (H, W, 4) float32 (row 0 at the bottom) at ``uv`` (B, 2): (B, 4)
    float32 RGBA, with Cycles' conventions (module docstring; docs/physics.md section 13.1).
    ``interpolation`` / ``extension`` / ``encoding``: TextureInterpolation / TextureExtension /
    TextureEncoding codes (or members)."""
    tex = np.asarray(tex)
    h, w = tex.shape[:2]
    flat = tex.reshape(h * w, tex.shape[2])
    uv = np.asarray(uv, np.float32).reshape(-1, 2)
    x = uv[:, 0] * np.float32(w)
    y = uv[:, 1] * np.float32(h)
    interpolation, extension = int(interpolation), int(extension)
    clip = extension == _CLIP

    def taps(i, n, offsets):
        """Per tap offset: (wrapped index, inside mask or None)."""
        out = []
        for o in offsets:
            j = i + o if o else i
            if clip:
                inside = (j >= 0) & (j < n)
                out.append((np.where(inside, j, 0), inside))
            else:
                out.append((_wrap(j, n, extension), None))
        return out

    if interpolation == _CLOSEST:
        (cx, in_x), = taps(_frac(x)[0], w, (0,))
        (cy, in_y), = taps(_frac(y)[0], h, (0,))
        out = np.take(flat, cy * w + cx, axis=0)  # np.take: several times faster than flat[idx]
        if clip:
            out[~(in_x & in_y)] = 0.0
    else:
        # A -0.5 offset centres the taps on the sample point (a texel centre is that texel).
        ix, tx = _frac(x - np.float32(0.5))
        iy, ty = _frac(y - np.float32(0.5))
        if interpolation == _LINEAR:
            offsets = (0, 1)
            wx, wy = [1 - tx, tx], [1 - ty, ty]
        else:  # CUBIC, SMART: the cubic B-spline
            offsets = (-1, 0, 1, 2)
            wx, wy = _cubic_weights(tx), _cubic_weights(ty)
        cols, rows = taps(ix, w, offsets), taps(iy, h, offsets)
        out = np.zeros((len(uv), flat.shape[1]), np.float32)
        for (ry, in_y), wyk in zip(rows, wy):  # 4 or 16 taps, each a vectorised gather
            row = ry * w
            for (cx, in_x), wxk in zip(cols, wx):
                weight = (wxk * wyk).astype(np.float32, copy=False)
                if clip:  # taps outside the image read transparent black
                    weight = np.where(in_x & in_y, weight, np.float32(0))
                out += weight[:, None] * np.take(flat, row + cx, axis=0)
    out = out.astype(np.float32, copy=False)
    if int(encoding) == _SRGB:
        out = out.copy() if not out.flags.writeable else out
        out[:, :3] = srgb_to_linear(out[:, :3])
    return out


@dataclass(frozen=True)
class PreparedTextures:
    """The scene's textures and each material's bindings, ready to sample (arrays read-only)."""

    images: tuple                 # K arrays (H, W, 4) float32, row 0 at the bottom
    interpolation: np.ndarray     # (K,) int32 TextureInterpolation codes
    extension: np.ndarray         # (K,) int32 TextureExtension codes
    encoding: np.ndarray          # (K,) int32 TextureEncoding codes
    color: np.ndarray             # (M,) int32 texture on the base colour, -1: none
    roughness: np.ndarray         # (M,) int32
    metallic: np.ndarray          # (M,) int32
    emission: np.ndarray          # (M,) int32
    normal: np.ndarray            # (M,) int32 tangent-space normal map
    normal_strength: np.ndarray   # (M,) float32 the Normal Map node's strength
    roughness_channel: np.ndarray  # (M,) int32 -1: the luminance, 0-3: R, G, B, alpha
    metallic_channel: np.ndarray  # (M,) int32
    emission_strength: np.ndarray  # (M,) float32 multiplies an emission texture's colour
    corner_uvs: np.ndarray        # (T, 3, 2) float32, or (0, 3, 2): every UV is (0, 0)
    corner_tangents: np.ndarray   # (T, 3, 4) float32 tangent + bitangent sign, or (0, 3, 4)
    reflectance_basis: np.ndarray  # (3, n) float32: rgb @ basis = reflectance_from_rgb(rgb), rgb in [0, 1]
    emission_basis: np.ndarray    # (3, n) float32: rgb @ basis = illuminant_from_rgb(rgb), rgb >= 0
    # shader programs (docs/physics.md section 13.6): per slot, each material's program that feeds
    # the slot (an index into ``programs``, -1: none); the coordinates they read per triangle corner
    programs: tuple = ()
    program_slots: dict = None    # slot -> (M,) int32
    corner_generated: np.ndarray = None  # (T, 3, 3) float32 or (0, 3, 3)
    corner_object: np.ndarray = None     # (T, 3, 3) float32 or (0, 3, 3)
    mix: np.ndarray = None               # (M,) int32 -1: no image texture on a mix's Fac (programs only)
    corner_attributes: dict = None       # name -> (T, 3, 4) float32: mesh attributes programs read

    def _program_column(self, slot: str):
        return None if not self.program_slots else self.program_slots.get(slot)

    def bound(self, slot: str) -> np.ndarray:
        """(M,) bool: the materials whose ``slot`` varies per hit (a texture or a shader program;
        'normal': a normal map or a Bump node's program)."""
        col = getattr(self, slot, None)
        out = np.asarray(col) >= 0 if col is not None else np.zeros(len(self.color), bool)
        prog = self._program_column(slot)
        out = out | (prog >= 0) if prog is not None else out
        if slot == "normal":
            for other in ("bump_height",) + NORMAL_MAP_SLOTS[:3]:
                out = out | self.bound(other)
        return out

    def uses(self, slot: str) -> bool:
        """Whether any material binds a texture or a shader program in ``slot`` ('color', 'roughness', ...;
        'normal': a normal map or a Bump node's program)."""
        col = getattr(self, slot, None)
        if col is not None and bool(len(col)) and bool(col.max() >= 0):
            return True
        prog = self._program_column(slot)
        if prog is not None and bool(len(prog)) and bool(prog.max() >= 0):
            return True
        return slot == "normal" and any(self.uses(other) for other in ("bump_height",) + NORMAL_MAP_SLOTS[:3])

    def normal_mapped(self) -> bool:
        """Whether any material binds a tangent-space normal-map image."""
        return bool(len(self.normal)) and bool(self.normal.max() >= 0) and bool(len(self.corner_tangents))

    def lookup(self, slot: str, mat, prim, bu, bv):
        """(rows, rgba): the hits (indices into the batch) whose material has a texture or a
        shader program in ``slot``, and its (len(rows), 4) float32 value there (a program's float
        output is (v, v, v, v), its colour (r, g, b, 1)). Only those rows are touched (a gather
        of ``mat``, then work on the bound rows alone)."""
        if not self.uses(slot):
            return np.zeros(0, np.int64), np.zeros((0, 4), np.float32)
        prog = self._program_column(slot)
        if prog is None or prog.max() < 0:
            return self._texture_lookup(slot, mat, prim, bu, bv)
        pid = prog[mat]
        prows = np.flatnonzero(pid >= 0)
        trows, trgba = self._texture_lookup(slot, mat, prim, bu, bv)
        if prows.size == 0:
            return trows, trgba
        keep = pid[trows] < 0  # a program wins over a texture in the same slot
        trows, trgba = trows[keep], trgba[keep]
        prgba = self._program_lookup(slot, pid[prows], prim[prows], bu[prows], bv[prows])
        if trows.size == 0:
            return prows, prgba
        rows = np.concatenate([trows, prows])
        order = np.argsort(rows, kind="stable")
        return rows[order], np.concatenate([trgba, prgba])[order]

    def _program_lookup(self, slot: str, pid, prim, bu, bv) -> np.ndarray:
        """(b, 4) float32: each hit's program's ``slot`` output at its interpolated coordinates."""
        out = np.empty((len(pid), 4), np.float32)
        for k in np.unique(pid):  # a handful of programs in a batch
            sel = np.flatnonzero(pid == k)
            program = self.programs[k]
            inputs = {}
            for name in program.reads():
                corners = {"generated": self.corner_generated, "object": self.corner_object}.get(name)
                if name == "uv":
                    if len(self.corner_uvs):
                        uv = interpolate_corners(self.corner_uvs, prim[sel], bu[sel], bv[sel])
                        inputs[name] = np.concatenate([uv, np.zeros((len(sel), 1), np.float32)], axis=1)
                elif corners is not None and len(corners):
                    inputs[name] = interpolate_corners(corners, prim[sel], bu[sel], bv[sel]).astype(np.float32)
            for name in program.attributes():
                corners = (self.corner_attributes or {}).get(name)
                if corners is not None and len(corners):
                    inputs["attribute:" + name] = interpolate_corners(corners, prim[sel], bu[sel],
                                                                      bv[sel]).astype(np.float32)
            value = evaluate(program, slot, inputs, len(sel), self._image)
            if value.ndim == 1:
                out[sel] = value[:, None]
            else:
                out[sel, :3] = value
                out[sel, 3] = 1.0
        return out

    def _image(self, k: int, uv: np.ndarray) -> np.ndarray:
        """Scene texture ``k`` at ``uv`` (b, 2): a shader program's image op."""
        if not 0 <= k < len(self.images):
            return np.zeros((len(uv), 4), np.float32)
        return sample_texture(self.images[k], uv, self.interpolation[k], self.extension[k], self.encoding[k])

    def _texture_lookup(self, slot: str, mat, prim, bu, bv):
        col = getattr(self, slot)
        if not (bool(len(col)) and bool(col.max() >= 0)):
            return np.zeros(0, np.int64), np.zeros((0, 4), np.float32)
        tid = col[mat]
        rows = np.flatnonzero(tid >= 0)
        if rows.size == 0:
            return rows, np.zeros((0, 4), np.float32)
        every = rows.size == len(tid)  # every hit textured: no gathers of the batch
        tid = tid if every else tid[rows]
        if len(self.corner_uvs):
            uv = (interpolate_corners(self.corner_uvs, prim, bu, bv) if every
                  else interpolate_corners(self.corner_uvs, prim[rows], bu[rows], bv[rows]))
        else:  # no UV map: (0, 0), as Cycles reads a missing UV attribute
            uv = np.zeros((rows.size, 2), np.float32)
        if tid.min() == tid.max():  # one texture (the usual case)
            k = int(tid[0])
            return rows, sample_texture(self.images[k], uv, self.interpolation[k], self.extension[k], self.encoding[k])
        out = np.empty((rows.size, 4), np.float32)
        for k in np.unique(tid):  # loop over the textures present (a handful)
            sel = tid == k
            out[sel] = sample_texture(self.images[k], uv[sel], self.interpolation[k], self.extension[k],
                                      self.encoding[k])
        return rows, out


def _frozen(a) -> np.ndarray:
    a = np.asarray(a)
    if a.flags.writeable:
        a = a.view()
        a.flags.writeable = False
    return a


def prepare_textures(scene, conv) -> PreparedTextures:
    """The PreparedTextures of a validated ``scene`` on the converter's grid (no copies of the
    images: read-only views of the scene's arrays)."""
    m = scene.materials
    basis = np.asarray(conv._mallett_basis, np.float64)  # (n, 3), rows sum to 1
    refl = basis.T.astype(np.float32)
    emis = (basis * conv.white_illuminant[:, None]).T.astype(np.float32)
    k = len(scene.textures)

    def codes(arr, default):
        a = np.asarray(arr, np.int32).reshape(-1)
        return a if len(a) == k else np.full(k, int(default), np.int32)

    def column(name, dtype, default):
        a = getattr(m, name, None)
        return np.full(len(m), default, dtype) if a is None else np.asarray(a, dtype)

    return PreparedTextures(
        images=tuple(_frozen(np.asarray(t, np.float32)) for t in scene.textures),
        interpolation=_frozen(codes(scene.texture_interpolation, TextureInterpolation.LINEAR)),
        extension=_frozen(codes(scene.texture_extension, TextureExtension.REPEAT)),
        encoding=_frozen(codes(scene.texture_encoding, TextureEncoding.LINEAR)),
        color=_frozen(column("color_texture", np.int32, -1)),
        roughness=_frozen(column("roughness_texture", np.int32, -1)),
        metallic=_frozen(column("metallic_texture", np.int32, -1)),
        emission=_frozen(column("emission_texture", np.int32, -1)),
        normal=_frozen(column("normal_texture", np.int32, -1)),
        normal_strength=_frozen(column("normal_strength", np.float32, 1.0)),
        roughness_channel=_frozen(column("roughness_channel", np.int32, -1)),
        metallic_channel=_frozen(column("metallic_channel", np.int32, -1)),
        emission_strength=_frozen(column("emission_strength", np.float32, 1.0)),
        mix=_frozen(np.full(len(m), -1, np.int32)),
        corner_uvs=_frozen(np.asarray(scene.corner_uvs, np.float32).reshape(-1, 3, 2)),
        corner_tangents=_frozen(np.asarray(scene.corner_tangents, np.float32).reshape(-1, 3, 4)),
        reflectance_basis=_frozen(refl),
        emission_basis=_frozen(emis),
        **_programs(scene, m),
    )


def _programs(scene, m) -> dict:
    """The shader-program fields of PreparedTextures: per slot the program of each material that
    has that output (-1: none); a float slot reads the program's value as the alpha channel."""
    programs = tuple(getattr(scene, "shader_programs", None) or ())
    idx = np.asarray(getattr(m, "shader_program", np.full(len(m), -1)), np.int32).reshape(-1)
    slots = {}
    for slot in ("color", "roughness", "metallic", "emission", "mix") + BUMP_SLOTS + NORMAL_MAP_SLOTS:
        has = np.array([i >= 0 and slot in programs[i].outputs for i in idx], bool) if len(idx) else np.zeros(0, bool)
        slots[slot] = _frozen(np.where(has, idx, -1).astype(np.int32))

    def corners(name):
        return _frozen(np.asarray(getattr(scene, name, np.zeros((0, 3, 3))), np.float32).reshape(-1, 3, 3))

    attrs = {str(k): _frozen(np.asarray(a, np.float32).reshape(-1, 3, 4))
             for k, a in (getattr(scene, "corner_attributes", None) or {}).items()}
    return {"programs": programs, "program_slots": slots, "corner_generated": corners("corner_generated"),
            "corner_object": corners("corner_object"), "corner_attributes": attrs}
