"""Shader mixes of unlike BSDFs as lobe mixtures: the per-hit layer weights (docs/physics.md section 14.8).

A material is a weighted set of lobes - the metal (Glossy / Metallic / Principled metal), the
glass and the dielectric base (Diffuse, or Principled's diffuse under its specular layer) -
with weights w_metal = metallic, w_glass = (1 - metallic) transmission and w_base the rest
(core/materials/bsdf.py ``params_from_materials``). Its BSDF is the weighted sum
f = sum_i w_i f_i. The eye pass's next events evaluate the whole mixture (``LobeMixture``):
f = sum_i w_i f_i towards the light and, for MIS, the mixture's sampling density
p = sum_i w_i p_i, as Cycles sums its closures (kernel/closure/bsdf.h ``bsdf_eval`` over
``surface_shader_bsdf_eval``, the pdfs weighted by the closures' sample weights) and pbrt-v4's
MixMaterial would without its stochastic choice. The bounce draws one lobe per hit with
probability w_i (u_layer) and samples a direction from it - density sum_i w_i p_i over the
lobe choice - then weighs it by f / p of the whole mixture at that direction (a delta event
keeps its own lobe's f_i / p_i, the one-sample estimate of Veach 1997 section 9.2.2).

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
from . import bsdf

__all__ = ["fresnel_dielectric_cos", "layer_fac", "layer_weights", "per_hit_layers", "LobeMixture"]

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


class LobeMixture:
    """Every lobe of the hits (rows ``rows`` (K,) of a batch of ``n``) whose material mixes layers:
    per layer present its weight (K,) and its bsdf.SurfaceParams (K rows, with_outgoing done), so
    that next events and the bounce's MIS see f = sum_i w_i f_i and p = sum_i w_i p_i (module
    docstring). The batch's other rows keep their one lobe."""

    def __init__(self, n: int, rows: np.ndarray, weights: list, layers: list):
        self.n, self.rows, self.weights, self.layers = n, rows, weights, layers

    @classmethod
    def of(cls, materials, mat, front, mixed, metallic, transmission, wo, ns, lam=None, base=None,
           roughness=None):
        """The mixture of the hits ``mixed`` (B,) bool on materials rows ``mat`` with the layer
        weights metallic, transmission (B,) (the table's or ``per_hit_layers``'), for the
        outgoing directions wo and shading normals ns; None where no hit mixes layers.
        lam, base, roughness as bsdf.params_from_materials takes them (B rows)."""
        rows = np.flatnonzero(mixed)
        if rows.size == 0:
            return None
        wm = np.clip(np.asarray(metallic, _F32)[rows], 0, 1)
        wg = (_F32(1) - wm) * np.clip(np.asarray(transmission, _F32)[rows], 0, 1)
        wb = np.maximum(_F32(1) - wm - wg, _F32(0))
        sub = (lambda a: None if a is None else np.asarray(a)[rows])
        weights, layers = [], []
        for code, w in ((0, wb), (1, wm), (2, wg)):
            if not (w > 0).any():
                continue
            p = bsdf.params_from_materials(materials, np.asarray(mat)[rows], np.asarray(front)[rows],
                                           lam=sub(lam), base=sub(base), roughness=sub(roughness),
                                           layer=np.full(len(rows), code))
            weights.append(w.astype(_F32))
            layers.append(bsdf.with_outgoing(p, np.asarray(wo)[rows], np.asarray(ns)[rows]))
        return cls(len(mixed), rows, weights, layers)

    def take(self, idx: np.ndarray) -> "LobeMixture | None":
        """The mixture of the batch's rows ``idx`` (sorted, unique), renumbered; None where none mixes."""
        pos = np.full(self.n, -1, np.int64)
        pos[idx] = np.arange(len(idx))
        keep = np.flatnonzero(pos[self.rows] >= 0)
        if keep.size == 0:
            return None
        if keep.size == len(self.rows) and len(idx) == self.n:
            return self
        return LobeMixture(len(idx), pos[self.rows[keep]], [w[keep] for w in self.weights],
                           [p.take(keep) for p in self.layers])

    def evaluate(self, params, wo, wi, ns, ng, lambert_scale=None):
        """f |cos| (B, k) and pdf (B,) as bsdf.evaluate, the mixture rows summed over their lobes
        (weights w_i), the others their one lobe ``params``; ``lambert_scale`` (B,) (the bump
        term) multiplies the Lambertian lobes."""
        r = self.rows
        whole = len(r) == self.n
        if whole:
            f = pdf = None
        else:
            f, pdf = bsdf.evaluate(params, wo, wi, ns, ng)
            if lambert_scale is not None:
                f = f * np.where(params.lobe == bsdf.LAMBERT, lambert_scale, _F32(1))[:, None]
        args = (wo, wi, ns, ng) if whole else tuple(np.asarray(a)[r] for a in (wo, wi, ns, ng))
        ls = None if lambert_scale is None else (np.broadcast_to(np.asarray(lambert_scale, _F32), (self.n,))[r])
        fm = pm = None
        for w, p in zip(self.weights, self.layers):
            fl, pl = bsdf.evaluate(p, *args)
            if ls is not None:
                fl = fl * np.where(p.lobe == bsdf.LAMBERT, ls, _F32(1))[:, None]
            fm = w[:, None] * fl if fm is None else fm + w[:, None] * fl
            pm = w * pl if pm is None else pm + w * pl
        if whole:
            return fm.astype(_F32), pm.astype(_F32)
        if fm.shape[1] != f.shape[1]:
            f = np.broadcast_to(f, (len(f), fm.shape[1])).copy()
        f[r], pdf[r] = fm, pm
        return f, pdf
