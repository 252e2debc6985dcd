"""Surface parameters at hit points: base colour, roughness, metallic, emission and the shading
normal, from the material table or, where a material binds an image texture or a shader program
(docs/physics.md section 13.6), from the texture at the hit's UV or the program at the hit's
coordinates (docs/physics.md section 13).

The path tracer calls these on a batch of hits (a :class:`transport.Hit`: ``mat``, ``prim``,
``bu``, ``bv``, ``ng``, ``front``, and ``ns`` where the shading-normal code adds it). Most hits
of a batch have untextured materials: they take the material's value by one gather, and only
the textured rows are looked up (:meth:`textures.PreparedTextures.lookup`).

- Colours become spectra with the converter's Mallett-Yuksel basis, which is linear in RGB:
  a reflectance is ``clip(rgb, 0, 1) @ basis`` (``SpectralConverter.reflectance_from_rgb``) and
  an emission ``max(rgb, 0) @ (basis x white illuminant)`` (``illuminant_from_rgb``).
- A colour read into a float (roughness, metallic) is its Rec.709 luminance, as Cycles converts
  a colour output plugged into a float socket (``linear_rgb_to_gray``, svm/convert.h), or the
  one channel a Separate Color node (or the Alpha output) hands on, clamped to [0, 1] as the
  Principled BSDF clamps them.
- Normal maps follow Cycles' Normal Map node in tangent space (``svm_node_normal_map``,
  kernel/svm/tex_coord.h): c = 2 rgb - 1, B = sign (N x T), N' = normalize(c_x T + c_y B + c_z N)
  on the triangle's outward side (flipped for back faces), then the strength s blends
  N'' = normalize(N + s (N' - N)) (s clamped at 0); finally N'' is kept on the geometric
  normal's side.
"""

from __future__ import annotations

import numpy as np

from ..util.geometry import interpolate_corners
from .textures import LUMINANCE_709

__all__ = ["surface_reflectance", "surface_roughness", "surface_metallic", "surface_emission", "surface_mix_fac",
           "shading_normal",
           "NORMAL_MIN_COS"]

#: A mapped normal is kept at least this far (cosine) on the geometric normal's side.
NORMAL_MIN_COS = 1e-3


def _per_hit(table: np.ndarray, mat: np.ndarray, lam) -> np.ndarray:
    """table[mat] (B, n) for white rays, table[mat, lam] (B,) for mono rays (a fresh array)."""
    return table[mat] if lam is None else table[mat, lam]


def _spectrum(rgb: np.ndarray, basis: np.ndarray, lam, rows: np.ndarray) -> np.ndarray:
    """(b, 3) RGB -> (b, n) spectra, or (b,) at the rows' wavelength indices."""
    if lam is None:
        return rgb @ basis
    return np.einsum("ij,ji->i", rgb, basis[:, np.asarray(lam)[rows]])


def surface_reflectance(prepared, hit, lam=None) -> np.ndarray:
    """The base colour as a spectrum: (B, n) float32 for white rays (``lam`` None), (B,) at the
    wavelength index ``lam`` (B,) for mono rays. Untextured materials:
    ``prepared.materials.reflectance[hit.mat]``; a colour texture: its RGB through
    ``reflectance_from_rgb``'s linear basis."""
    tx = prepared.textures
    if tx.uses("color"):
        rows, rgba = tx.lookup("color", hit.mat, hit.prim, hit.bu, hit.bv)
        if rows.size:
            rgb = np.clip(rgba[:, :3], np.float32(0), np.float32(1))
            spectra = _spectrum(rgb, tx.reflectance_basis, lam, rows)
            if rows.size == len(hit.mat):  # every hit textured: nothing of the table to keep
                return spectra
            out = _per_hit(prepared.materials.reflectance, hit.mat, lam)
            out[rows] = spectra
            return out
    return _per_hit(prepared.materials.reflectance, hit.mat, lam)


def _scalar(prepared, hit, column: str, slot: str) -> np.ndarray:
    base = getattr(prepared.materials, column, None)
    out = (np.zeros(len(hit.mat), np.float32) if base is None
           else np.asarray(base, np.float32)[hit.mat].astype(np.float32, copy=True))
    tx = prepared.textures
    if tx.uses(slot):
        rows, rgba = tx.lookup(slot, hit.mat, hit.prim, hit.bu, hit.bv)
        if rows.size:
            value = rgba[:, :3] @ LUMINANCE_709
            ch = getattr(tx, f"{slot}_channel")[hit.mat[rows]]
            if tx.program_slots:  # a shader program's float output is its alpha
                ch = np.where(tx.program_slots[slot][hit.mat[rows]] >= 0, 3, ch)
            one = ch >= 0  # a Separate Color node's channel, or the alpha
            if one.any():
                value[one] = rgba[np.flatnonzero(one), ch[one]]
            out[rows] = np.clip(value, np.float32(0), np.float32(1))
    return out


def surface_roughness(prepared, hit) -> np.ndarray:
    """(B,) float32 in [0, 1]: the material's roughness (0 where the material table has none) or
    the roughness texture's luminance (or its ``roughness_channel``) at the hit."""
    return _scalar(prepared, hit, "roughness", "roughness")


def surface_metallic(prepared, hit) -> np.ndarray:
    """(B,) float32 in [0, 1]: the material's metallic value (0 where the table has none) or the
    metallic texture's luminance at the hit."""
    return _scalar(prepared, hit, "metallic", "metallic")


def surface_mix_fac(prepared, hit) -> np.ndarray | None:
    """(B,) float32: the shader program's 'mix' output (a Mix Shader's Fac from a texture or a
    converter chain; docs/physics.md section 14.8) at the hits whose material has one, NaN at the
    others; None when no hit has one."""
    tx = prepared.textures
    if not tx.uses("mix"):
        return None
    rows, rgba = tx.lookup("mix", hit.mat, hit.prim, hit.bu, hit.bv)
    if not rows.size:
        return None
    out = np.full(len(hit.mat), np.nan, np.float32)
    out[rows] = np.clip(rgba[:, 3], np.float32(0), np.float32(1))
    return out


def surface_emission(prepared, hit, lam=None) -> np.ndarray:
    """Emitted spectral radiance: (B, n) float32 for white rays, (B,) at ``lam`` for mono rays.
    Untextured: ``prepared.materials.emission[hit.mat]``; an emission texture: its colour times
    the material's ``emission_strength``, through ``illuminant_from_rgb``'s linear basis."""
    out = _per_hit(prepared.materials.emission, hit.mat, lam)
    tx = prepared.textures
    if tx.uses("emission"):
        rows, rgba = tx.lookup("emission", hit.mat, hit.prim, hit.bu, hit.bv)
        if rows.size:
            rgb = np.maximum(rgba[:, :3], np.float32(0)) * tx.emission_strength[hit.mat[rows]][:, None]
            out[rows] = _spectrum(rgb, tx.emission_basis, lam, rows)
    return out


def _normalize(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(v / |v|, |v| > 0) rowwise (zero rows stay zero)."""
    n = np.sqrt(np.einsum("ij,ij->i", v, v))
    ok = n > 0
    return v / np.where(ok, n, np.float32(1))[:, None], ok


def shading_normal(prepared, hit) -> np.ndarray:
    """(B, 3) float32 unit shading normals: ``hit.ns`` where the hit has one (else ``hit.ng``),
    with the material's tangent-space normal map applied (module docstring), kept on ``hit.ng``'s
    side. ``ns`` is taken to face the ray like ``ng``."""
    n = np.asarray(getattr(hit, "ns", None) if getattr(hit, "ns", None) is not None else hit.ng, np.float32)
    tx = prepared.textures
    if not tx.uses("normal") or not len(tx.corner_tangents):
        return n
    rows, rgba = tx.lookup("normal", hit.mat, hit.prim, hit.bu, hit.bv)
    if rows.size == 0:
        return n
    every = rows.size == len(n)  # every hit mapped: no gathers of the batch
    pick = (lambda a: np.asarray(a)) if every else (lambda a: np.asarray(a)[rows])  # noqa: E731
    ns = pick(n)
    ng = pick(np.asarray(hit.ng, np.float32))
    # the map is applied on the triangle's own (outward) side, then turned to face the ray
    side = np.where(pick(hit.front), np.float32(1), np.float32(-1))[:, None]
    frame = interpolate_corners(tx.corner_tangents, pick(hit.prim), pick(hit.bu), pick(hit.bv))
    t, sign = frame[:, :3], frame[:, 3:4]
    n_out = ns * side
    b = sign * _cross(n_out, t)
    c = np.float32(2) * (rgba[:, :3] - np.float32(0.5))
    mapped, ok = _normalize(c[:, 0:1] * t + c[:, 1:2] * b + c[:, 2:3] * n_out)
    mapped = mapped * side
    s = np.maximum(tx.normal_strength[hit.mat[rows]], np.float32(0))[:, None]
    blend = s[:, 0] != 1
    if blend.any():
        mixed, ok_mix = _normalize(ns + (mapped - ns) * s)
        mapped = np.where(blend[:, None], mixed, mapped)
        ok = np.where(blend, ok_mix, ok)
    mapped = np.where(ok[:, None], mapped, ns)  # a zero result keeps the unmapped normal, as Cycles
    # below the surface: lifted to NORMAL_MIN_COS above the tangent plane
    d = np.einsum("ij,ij->i", mapped, ng)
    low = d < NORMAL_MIN_COS
    if low.any():
        lifted, _ = _normalize(mapped[low] + (np.float32(NORMAL_MIN_COS) - d[low])[:, None] * ng[low])
        mapped[low] = lifted
    if every:
        return mapped
    out = n.copy()
    out[rows] = mapped
    return out


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a x b of (B, 3) arrays (np.cross's arithmetic without its generic set-up)."""
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    b0, b1, b2 = b[:, 0], b[:, 1], b[:, 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=1)
