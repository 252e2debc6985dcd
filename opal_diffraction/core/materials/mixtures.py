"""Shader mixes of unlike BSDFs as lobe mixtures: the per-hit layer weights (docs/physics.md section 14.8).

A material is a weighted set of lobes - the metal (Glossy / Metallic / Principled metal), the
glass and the dielectric base (Diffuse, or Principled's diffuse under its specular layer) -
with weights w_metal = metallic, w_glass = (1 - metallic) transmission and w_base the rest
(core/materials/bsdf.py ``params_from_materials``). Its BSDF is the weighted sum
f = sum_i w_i f_i. The eye pass draws one lobe per hit with probability w_i (u_layer), which
makes f_i / (w_i-pdf) an unbiased one-sample estimate of the sum for next-event estimation
and BSDF sampling alike (the drawn lobe's own pdf then serves MIS: the lobe choice is a
discrete random variable independent of the direction, so f_i / p_i with p_i the lobe's pdf is
an unbiased estimate of f for that hit; Veach 1997 section 9.2.2's one-sample model).

Where a Mix Shader's Fac comes from Blender's Fresnel or Layer Weight node, the weights depend
on the view direction; this module evaluates them per hit as Cycles' SVM does
(intern/cycles/kernel/svm/fresnel.h ``svm_node_fresnel`` / ``svm_node_layer_weight``, with
``fresnel_dielectric_cos`` of kernel/closure/bsdf_util.h), in float32:

- Fresnel (IOR n): eta = max(n, 1e-5), 1 / eta on a back face; Fac = F(|cos|, eta).
- Layer Weight, Fresnel output (Blend b): eta = max(1 - b, 1e-5), 1 / eta on a front face;
  Fac = F(|cos|, eta).
- Layer Weight, Facing output: Fac = 1 - |cos|^e with e = 2 b (b < 0.5) or 0.5 / (1 - b)
  (b clamped to [0, 1 - 1e-5]; b = 0.5 exactly: e = 1).

with F(c, eta) = ½ A² (1 + B²), g = sqrt(eta² - 1 + c²), A = (g - c) / (g + c),
B = (c (g + c) - 1) / (c (g - c) + 1) (1 where eta² - 1 + c² <= 0: total reflection), and cos
the cosine between the view direction and the shading normal. A Fac from a texture or a
converter chain is the material's shader program's 'mix' output at the hit (LayerFac.PROGRAM,
core/materials/surface.py ``surface_mix_fac``), clamped to [0, 1] as the Mix Shader clamps it.
"""

from __future__ import annotations

import numpy as np

from ..util.enums import LayerFac

__all__ = ["fresnel_dielectric_cos", "layer_fac", "layer_weights", "per_hit_layers"]

_F32 = np.float32


def fresnel_dielectric_cos(cos, eta) -> np.ndarray:
    """Cycles' ``fresnel_dielectric_cos``: the unpolarised Fresnel reflectance at |cos| for the
    relative index eta, float32 (module docstring)."""
    c = np.abs(np.asarray(cos, _F32))
    eta = np.asarray(eta, _F32)
    g = eta * eta - _F32(1) + c * c
    ok = g > 0
    gs = np.sqrt(np.where(ok, g, _F32(0)))
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (gs - c) / (gs + c)
        b = (c * (gs + c) - _F32(1)) / (c * (gs - c) + _F32(1))
        f = _F32(0.5) * a * a * (_F32(1) + b * b)
    return np.where(ok, np.where(np.isfinite(f), f, _F32(1)), _F32(1)).astype(_F32)


def layer_fac(code, value, cos, front) -> np.ndarray:
    """(B,) float32 the Fac of the node ``code`` (LayerFac, per hit) with its input ``value``
    (IOR or Blend) at the cosine ``cos`` between the view direction and the shading normal,
    ``front`` the hit's side (module docstring). CONSTANT rows give 0 (the caller keeps their
    table weights)."""
    code = np.asarray(code)
    value = np.asarray(value, _F32)
    cos = np.asarray(cos, _F32)
    front = np.asarray(front, bool)
    out = np.zeros(np.broadcast(code, value, cos, front).shape, _F32)
    fres = code == LayerFac.FRESNEL
    if fres.any():
        eta = np.maximum(value, _F32(1e-5))
        eta = np.where(front, eta, _F32(1) / eta)
        out = np.where(fres, fresnel_dielectric_cos(cos, eta), out)
    lf = code == LayerFac.LAYER_FRESNEL
    if lf.any():
        eta = np.maximum(_F32(1) - value, _F32(1e-5))
        eta = np.where(front, _F32(1) / eta, eta)
        out = np.where(lf, fresnel_dielectric_cos(cos, eta), out)
    face = code == LayerFac.LAYER_FACING
    if face.any():
        b = np.clip(value, _F32(0), _F32(1 - 1e-5))
        e = np.where(b < 0.5, _F32(2) * b, _F32(0.5) / (_F32(1) - b))
        e = np.where(value == _F32(0.5), _F32(1), e)
        out = np.where(face, _F32(1) - np.power(np.abs(cos), e), out)
    return out.astype(_F32)


def layer_weights(fac, src, dst) -> tuple[np.ndarray, np.ndarray]:
    """(metallic, transmission) (B,) float32 of two-layer mixes whose layer ``dst`` (0 base,
    1 metal, 2 glass) has weight ``fac`` and layer ``src`` the rest, in the table's terms
    (w_metal = metallic, w_glass = (1 - metallic) transmission)."""
    fac = np.clip(np.asarray(fac, np.float64), 0.0, 1.0)
    src, dst = np.asarray(src), np.asarray(dst)
    w_metal = np.where(dst == 1, fac, 0.0) + np.where(src == 1, 1.0 - fac, 0.0)
    w_glass = np.where(dst == 2, fac, 0.0) + np.where(src == 2, 1.0 - fac, 0.0)
    rest = 1.0 - w_metal
    trans = np.where(rest > 0, w_glass / np.where(rest > 0, rest, 1.0), 0.0)
    return w_metal.astype(_F32), np.clip(trans, 0.0, 1.0).astype(_F32)


def per_hit_layers(materials, mat, cos, front, program_fac=None):
    """(metallic, transmission) (B,) per hit for the hits of materials (PreparedMaterials) rows
    ``mat`` whose weights come from a Fresnel / Layer Weight node or from the shader program's
    'mix' output (``program_fac`` (B,), read at those rows; None: the table's mean there), the
    table's elsewhere; None when no hit has such a material (the table's columns serve)."""
    code = getattr(materials, "layer_fac", None)
    if code is None:
        return None
    mat = np.asarray(mat, np.int64)
    c = code[mat]
    live = c != LayerFac.CONSTANT
    if not live.any():
        return None
    metallic = np.asarray(materials.metallic, _F32)[mat].copy()
    transmission = np.asarray(materials.transmission, _F32)[mat].copy()
    rows = np.flatnonzero(live & (c != LayerFac.PROGRAM))
    fac = layer_fac(c[rows], materials.layer_fac_value[mat[rows]], np.asarray(cos)[rows], np.asarray(front)[rows])
    prog = np.flatnonzero(c == LayerFac.PROGRAM)
    if len(prog) and program_fac is not None:
        pf = np.asarray(program_fac, _F32)[prog]
        ok = np.isfinite(pf)  # a hit the program did not reach keeps the table's mean
        rows = np.concatenate([rows, prog[ok]])
        fac = np.concatenate([fac, np.clip(pf[ok], _F32(0), _F32(1))])
    metallic[rows], transmission[rows] = layer_weights(fac, materials.layer_fac_from[mat[rows]],
                                                       materials.layer_fac_to[mat[rows]])
    return metallic, transmission
