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
  N'' = normalize(N + s (S - N)) (s clamped at 0), S the sum c_x T + c_y B + c_z N before its
  normalisation, as Cycles 5.0 blends it (measured); finally N'' is kept on the geometric
  normal's side.
- A Normal Map node whose colour a shader program computes (``normalmap_tangent`` / ``_object`` /
  ``_world`` and ``normalmap_strength``): the same in tangent space; in world space
  N' = normalize(c), in object space N' = normalize(M^-T c) with M the object's linear map (from
  the triangle's world and object-space corners; Blender's object / world spaces negate c_y and
  c_z at export); flipped on a back face, then the strength blend (Cycles' ``svm_node_normal_map``).
- A Bump node's Height (a shader program's ``bump_height``, with ``bump_strength`` and
  ``bump_distance``) bends the normal as Cycles' ``svm_node_set_bump`` (:func:`_bump`;
  docs/physics.md section 13.7), after any normal map.
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
    if tx.normal_mapped():
        n = _normal_map(tx, hit, n)
    for space in ("tangent", "object", "world"):
        if tx.uses("normalmap_" + space):
            n = _program_normal_map(prepared, hit, n, space)
    if tx.uses("bump_height"):
        n = _bump(prepared, hit, n)
    return n


def _normal_map(tx, hit, n: np.ndarray) -> np.ndarray:
    """The tangent-space normal map of the hits' materials applied to ``n`` (module docstring)."""
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
    raw = c[:, 0:1] * t + c[:, 1:2] * b + c[:, 2:3] * n_out
    mapped, ok = _normalize(raw)
    mapped = mapped * side
    s = np.maximum(tx.normal_strength[hit.mat[rows]], np.float32(0))[:, None]
    blend = s[:, 0] != 1
    if blend.any():  # the strength blends the sum before it is normalised, as Cycles 5.0 (measured)
        mixed, ok_mix = _normalize(ns + (raw * side - ns) * s)
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


#: The Bump node's finite-difference step, as a fraction of the pixel footprint at the hit (Cycles'
#: default Filter Width: the heights are sampled at P + 0.1 dPdx and P + 0.1 dPdy).
BUMP_FILTER_WIDTH = 0.1
#: The smallest step, relative to 1 + |P| (float32 coordinates keep about 7 digits).
BUMP_MIN_STEP = 1e-5


def _footprint(prepared, p: np.ndarray) -> np.ndarray:
    """(b,) metres: the width of a camera pixel at the points ``p`` (b, 3), Cycles' ray
    differential of a camera ray at that distance (perspective: distance x the pixel's angle;
    orthographic: the pixel's width); other cameras: 1e-3 (1 + |p|)."""
    cam = getattr(prepared.scene, "camera", None)
    far = np.float64(1e-3) * (1.0 + np.abs(p).max(axis=1))
    if cam is None:
        return far
    size = max(int(cam.width), int(cam.height), 1)
    if cam.kind == "ORTHO":
        return np.full(len(p), float(cam.ortho_scale) / size)
    if cam.kind != "PERSP":
        return far
    sensor = cam.sensor_width if cam.sensor_fit != "VERTICAL" else cam.sensor_height
    if cam.sensor_fit == "AUTO":
        sensor = cam.sensor_width
    origin = np.asarray(cam.matrix, np.float64)[:3, 3]
    dist = np.sqrt(((p - origin) ** 2).sum(axis=1))
    return dist * (float(sensor) / float(cam.lens)) / size


def _bump(prepared, hit, n: np.ndarray) -> np.ndarray:
    """The Bump node (docs/physics.md section 13.7), as Cycles' ``svm_node_set_bump``
    (kernel/svm/displace.h, Apache-2.0, ported): the height h of the material's program at the hit
    and at P + dPdx, P + dPdy, where dPdx, dPdy are orthogonal steps in the triangle's plane (Cycles:
    ``differential_from_compact(Ng, dP)``; here the camera pixel's footprint at the hit times the
    filter width 0.1, as an eye ray's differential); Rx = dPdy x N, Ry = N x dPdx, det = dPdx . Rx,
    N' = normalize(|det| N - distance sign(det) ((h_x - h_c) Rx + (h_y - h_c) Ry)) (N itself when
    that is zero), then normalize(s N' + (1 - s) N) with s = max(strength, 0). To first order N' is
    N - distance grad h, whatever the step. The points P + dP are reached by their barycentric
    offsets on the hit's triangle, so every per-corner input (Generated, Object, UV, attributes)
    is read there exactly as at the hit. The result is kept on the geometric normal's side."""
    tx = prepared.textures
    pid = tx.program_slots["bump_height"][hit.mat]
    rows = np.flatnonzero(pid >= 0)
    if rows.size == 0:
        return n
    every = rows.size == len(n)
    pick = (lambda a: np.asarray(a)) if every else (lambda a: np.asarray(a)[rows])  # noqa: E731
    prim, bu, bv, k = pick(hit.prim), pick(hit.bu), pick(hit.bv), pid[rows]
    nin = pick(n).astype(np.float64)
    ng = pick(hit.ng).astype(np.float64)
    v = np.asarray(prepared.scene.vertices, np.float64)
    tri = np.asarray(prepared.scene.triangles)[prim]
    v0 = v[tri[:, 0]]
    e1, e2 = v[tri[:, 1]] - v0, v[tri[:, 2]] - v0
    p = v0 + bu[:, None].astype(np.float64) * e1 + bv[:, None].astype(np.float64) * e2
    # an orthonormal pair in the triangle's plane, right-handed about ng (make_orthonormals(Ng))
    t = e1 - np.einsum("ij,ij->i", e1, ng)[:, None] * ng
    t /= np.maximum(np.sqrt(np.einsum("ij,ij->i", t, t)), 1e-300)[:, None]
    b = np.cross(ng, t)
    step = np.maximum(BUMP_FILTER_WIDTH * _footprint(prepared, p), BUMP_MIN_STEP * (1.0 + np.abs(p).max(axis=1)))
    dpdx, dpdy = t * step[:, None], b * step[:, None]
    g11, g12, g22 = (np.einsum("ij,ij->i", e1, e1), np.einsum("ij,ij->i", e1, e2), np.einsum("ij,ij->i", e2, e2))
    gdet = g11 * g22 - g12 * g12
    gdet = np.where(gdet > 0, gdet, 1.0)

    def bary(d):  # (du, dv) with du e1 + dv e2 = d (d in the triangle's plane)
        r1, r2 = np.einsum("ij,ij->i", e1, d), np.einsum("ij,ij->i", e2, d)
        return (g22 * r1 - g12 * r2) / gdet, (g11 * r2 - g12 * r1) / gdet

    def height(du, dv):
        return tx._program_lookup("bump_height", k, prim, bu + du, bv + dv)[:, 3].astype(np.float64)

    h_c = height(0.0, 0.0)
    h_x = height(*bary(dpdx))
    h_y = height(*bary(dpdy))
    strength = np.maximum(tx._program_lookup("bump_strength", k, prim, bu, bv)[:, 3].astype(np.float64), 0.0)
    distance = tx._program_lookup("bump_distance", k, prim, bu, bv)[:, 3].astype(np.float64)
    rx, ry = np.cross(dpdy, nin), np.cross(nin, dpdx)
    det = np.einsum("ij,ij->i", dpdx, rx)
    surfgrad = (h_x - h_c)[:, None] * rx + (h_y - h_c)[:, None] * ry
    out = np.abs(det)[:, None] * nin - (distance * np.sign(det))[:, None] * surfgrad
    length = np.sqrt(np.einsum("ij,ij->i", out, out))
    ok = length > 0
    out = np.where(ok[:, None], out / np.where(ok, length, 1.0)[:, None], nin)
    mixed = strength[:, None] * out + (1.0 - strength)[:, None] * nin
    mixed /= np.maximum(np.sqrt(np.einsum("ij,ij->i", mixed, mixed)), 1e-300)[:, None]
    out = np.where(ok[:, None], mixed, nin)
    # below the surface: lifted to NORMAL_MIN_COS above the tangent plane (Cycles: ensure_valid_reflection)
    d = np.einsum("ij,ij->i", out, ng)
    low = d < NORMAL_MIN_COS
    if low.any():
        lifted = out[low] + (NORMAL_MIN_COS - d[low])[:, None] * ng[low]
        out[low] = lifted / np.sqrt(np.einsum("ij,ij->i", lifted, lifted))[:, None]
    out = np.nan_to_num(out).astype(np.float32)
    if every:
        return out
    res = n.copy()
    res[rows] = out
    return res


def _object_normals(prepared, prim, c: np.ndarray) -> np.ndarray:
    """M^-T c (b, 3) float64, M the object-to-world linear map of each hit's triangle: M takes the
    object-space edges to the world edges and the object normal n_o to k |n_o| / |n_w| n_w with
    k^2 the area ratio (exact for rotation and uniform scale; under non-uniform scale the
    in-plane part is exact). M^-T c = W^-T A^T c with A = [e1_o e2_o n_o], W = [e1_w e2_w M n_o]."""
    v = np.asarray(prepared.scene.vertices, np.float64)
    tri = np.asarray(prepared.scene.triangles)[prim]
    o = np.asarray(prepared.textures.corner_object, np.float64)[prim]
    e1w, e2w = v[tri[:, 1]] - v[tri[:, 0]], v[tri[:, 2]] - v[tri[:, 0]]
    e1o, e2o = o[:, 1] - o[:, 0], o[:, 2] - o[:, 0]
    nw, no = np.cross(e1w, e2w), np.cross(e1o, e2o)
    lw, lo = np.linalg.norm(nw, axis=1), np.linalg.norm(no, axis=1)
    ok = (lw > 0) & (lo > 0)
    k = np.sqrt(np.where(ok, lw / np.where(ok, lo, 1.0), 1.0))
    mn = nw * (k * lo / np.where(ok, lw, 1.0))[:, None]
    a = np.stack([e1o, e2o, no], axis=2)
    w = np.stack([e1w, e2w, mn], axis=2)
    good = ok & (np.abs(np.linalg.det(w)) > 0)
    out = c.astype(np.float64).copy()
    if good.any():
        atc = np.einsum("bji,bj->bi", a[good], c[good].astype(np.float64))
        out[good] = np.linalg.solve(np.transpose(w[good], (0, 2, 1)), atc[..., None])[..., 0]
    return out


def _program_normal_map(prepared, hit, n: np.ndarray, space: str) -> np.ndarray:
    """The Normal Map nodes read through shader programs in ``space`` (module docstring;
    docs/physics.md section 13.5), applied to ``n`` at the hits whose material has one."""
    tx = prepared.textures
    pid = tx.program_slots["normalmap_" + space][hit.mat]
    rows = np.flatnonzero(pid >= 0)
    if rows.size == 0 or (space == "tangent" and not len(tx.corner_tangents)) \
            or (space == "object" and not len(tx.corner_object)):
        return n
    prim, bu, bv, k = hit.prim[rows], hit.bu[rows], hit.bv[rows], pid[rows]
    c = np.float64(2) * (tx._program_lookup("normalmap_" + space, k, prim, bu, bv)[:, :3].astype(np.float64) - 0.5)
    ns = n[rows].astype(np.float64)
    ng = np.asarray(hit.ng, np.float64)[rows]
    side = np.where(np.asarray(hit.front)[rows], 1.0, -1.0)[:, None]
    if space == "tangent":
        frame = interpolate_corners(tx.corner_tangents, prim, bu, bv).astype(np.float64)
        t, sign = frame[:, :3], frame[:, 3:4]
        n_out = ns * side
        mapped = c[:, 0:1] * t + c[:, 1:2] * (sign * np.cross(n_out, t)) + c[:, 2:3] * n_out
    elif space == "object":
        mapped = _object_normals(prepared, prim, c)
    else:
        mapped = c
    length = np.sqrt(np.einsum("ij,ij->i", mapped, mapped))
    ok = length > 0
    # the strength blends the tangent-space sum before it is normalised (measured: Cycles 5.0 with
    # |c| != 1 and strength 0.6 agrees within 8e-4 so, 1.8e-2 otherwise); world / object: unit
    raw = mapped * side if space == "tangent" else None
    mapped = mapped / np.where(ok, length, 1.0)[:, None] * side  # turned to face the ray on a back face
    raw = mapped if raw is None else raw
    s = np.maximum(tx._program_lookup("normalmap_strength", k, prim, bu, bv)[:, 3].astype(np.float64), 0.0)
    blend = s != 1
    if blend.any():
        mixed = ns + (raw - ns) * s[:, None]
        ml = np.sqrt(np.einsum("ij,ij->i", mixed, mixed))
        mapped = np.where(blend[:, None], mixed / np.where(ml > 0, ml, 1.0)[:, None], mapped)
        ok = np.where(blend, ml > 0, ok)
    mapped = np.where(ok[:, None], mapped, ns)  # a zero result keeps the normal, as Cycles
    d = np.einsum("ij,ij->i", mapped, ng)
    low = d < NORMAL_MIN_COS
    if low.any():
        lifted = mapped[low] + (NORMAL_MIN_COS - d[low])[:, None] * ng[low]
        mapped[low] = lifted / np.sqrt(np.einsum("ij,ij->i", lifted, lifted))[:, None]
    out = n.copy()
    out[rows] = np.nan_to_num(mapped).astype(np.float32)
    return out
