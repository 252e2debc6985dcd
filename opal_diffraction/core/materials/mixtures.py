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

Principled's sheen and coat (docs/physics.md section 14.10) are two more lobes over those layers,
as Cycles' principled closure stacks them (``closure_layering_weight``): the sheen (Zeltner et
al.'s microfiber LTC, core/materials/sheen.py) of weight s t R(mu_o), the coat (a GGX dielectric
reflection: bsdf's PLASTIC lobe of zero base) of weight A_s c, and the layers below scaled by
A_s A_c mix(1, T^(1/cos_t), c) (``coat_sheen_layers``). Their weights W_i are spectral and differ
from the probabilities P_i with which the bounce draws them (the layers' estimated albedos), so
the mixture carries both: f = sum_i W_i f_i, p = sum_i P_i p_i, and a delta event is weighed by
its layer's W_i / P_i.
"""

from __future__ import annotations

import numpy as np

from ..util.enums import LayerFac
from . import bsdf

__all__ = ["fresnel_dielectric_cos", "layer_fac", "layer_weights", "per_hit_layers", "LobeMixture",
           "coat_sheen_layers", "COAT", "SHEEN"]

_F32 = np.float32
#: Layer codes of the coat and the sheen in a LobeMixture (0 base, 1 metal, 2 glass as the table's).
COAT, SHEEN = 3, 4


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
    per layer present its weight (K,) or (K, k) and its bsdf.SurfaceParams (K rows, with_outgoing
    done), so that next events and the bounce's MIS see f = sum_i W_i f_i and p = sum_i P_i p_i
    (module docstring). ``probs`` (K,) per layer: the probability with which the bounce draws it
    (None: the weights, which are then scalars). With Principled's coat and sheen (``layered``)
    the layers are base, metal, glass under the coat under the sheen (docs/physics.md section
    14.10): ``draw`` picks the top layers, ``put_top`` puts their lobes in the bounce's
    parameters, and ``singular_scale`` (K, k) is W / P of the drawn layer for delta events. The
    batch's other rows keep their one lobe."""

    def __init__(self, n: int, rows: np.ndarray, weights: list, layers: list, probs: list | None = None,
                 codes: list | None = None, singular_scale: np.ndarray | None = None):
        self.n, self.rows, self.weights, self.layers = n, rows, weights, layers
        self.probs = weights if probs is None else probs
        self.codes = codes if codes is not None else [None] * len(layers)
        self.singular_scale = singular_scale
        self._base_share = None  # (K,) the probability of the base layers together (draw)

    @property
    def layered(self) -> bool:
        """Whether a coat or a sheen layer is among the lobes."""
        return any(c in (COAT, SHEEN) for c in self.codes)

    @classmethod
    def of(cls, materials, mat, front, mixed, metallic, transmission, wo, ns, lam=None, base=None,
           roughness=None):
        """The mixture of the hits ``mixed`` (B,) bool on materials rows ``mat`` with the layer
        weights metallic, transmission (B,) (the table's or ``per_hit_layers``'), for the
        outgoing directions wo and shading normals ns; None where no hit mixes layers.
        lam, base, roughness as bsdf.params_from_materials takes them (B rows). Rows with a
        coat or a sheen get those layers over the rest (``coat_sheen_layers``)."""
        rows = np.flatnonzero(mixed)
        if rows.size == 0:
            return None
        wm = np.clip(np.asarray(metallic, _F32)[rows], 0, 1)
        wg = (_F32(1) - wm) * np.clip(np.asarray(transmission, _F32)[rows], 0, 1)
        wb = np.maximum(_F32(1) - wm - wg, _F32(0))
        sub = (lambda a: None if a is None else np.asarray(a)[rows])
        weights, layers, codes = [], [], []
        mr, wo_r, ns_r = np.asarray(mat)[rows], np.asarray(wo)[rows], np.asarray(ns)[rows]
        for code, w in ((0, wb), (1, wm), (2, wg)):
            if not (w > 0).any():
                continue
            p = bsdf.params_from_materials(materials, mr, np.asarray(front)[rows],
                                           lam=sub(lam), base=sub(base), roughness=sub(roughness),
                                           layer=np.full(len(rows), code))
            weights.append(w.astype(_F32))
            layers.append(bsdf.with_outgoing(p, wo_r, ns_r))
            codes.append(code)
        lay = getattr(materials, "layered", None)
        if lay is None or not lay[mr].any():
            return cls(len(mixed), rows, weights, layers, codes=codes)
        k = layers[0].base.shape[1]
        top = coat_sheen_layers(materials, mr, np.einsum("ij,ij->i", wo_r, ns_r), sub(lam), k)
        probs = [w * top["base_share"] for w in weights]
        weights = [w[:, None] * top["under"] for w in weights]
        for code, key in ((COAT, "coat"), (SHEEN, "sheen")):
            if key in top:
                p, w, pr = top[key]
                weights.append(w)
                probs.append(pr)
                layers.append(bsdf.with_outgoing(p, wo_r, ns_r))
                codes.append(code)
        out = cls(len(mixed), rows, weights, layers, probs, codes)
        out._base_share = top["base_share"]
        out.singular_scale = top["under"] / np.maximum(top["base_share"], _F32(1e-12))[:, None]
        return out

    def draw(self, u_layer: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u for params_from_materials' choice among the base layers (B,), the top layer drawn
        (B,) int: -1 none, else its index in ``layers``) for the batch's uniforms ``u_layer``
        (B,): the sheen with its probability, then the coat, then the base layers (``u`` rescaled
        to what they leave). ``singular_scale`` becomes the drawn layer's W / P."""
        u = np.array(u_layer, np.float64)
        top = np.full(self.n, -1, np.int64)
        if not self.layered:
            return u, top
        ur = u[self.rows]
        acc = np.zeros(len(self.rows))
        chosen = np.full(len(self.rows), -1, np.int64)
        for i in (i for i, c in enumerate(self.codes) if c == SHEEN):
            pick = (chosen < 0) & (ur < acc + self.probs[i])
            chosen[pick] = i
            acc = acc + self.probs[i]
        for i in (i for i, c in enumerate(self.codes) if c == COAT):
            pick = (chosen < 0) & (ur < acc + self.probs[i])
            chosen[pick] = i
            acc = acc + self.probs[i]
        share = np.maximum(self._base_share.astype(np.float64), 1e-12)
        u[self.rows] = np.where(chosen < 0, np.clip((ur - acc) / share, 0.0, np.nextafter(1.0, 0.0)), ur)
        top[self.rows] = chosen
        scale = np.array(self.singular_scale, _F32)
        for i in np.unique(chosen[chosen >= 0]):
            m = chosen == i
            w = self.weights[i]
            w = w[m] if w.ndim == 2 else w[m][:, None]
            scale[m] = w / np.maximum(self.probs[i][m], _F32(1e-12))[:, None]
        self.singular_scale = scale
        return u, top

    def put_top(self, params, top: np.ndarray):
        """bsdf.SurfaceParams ``params`` (the batch's, before with_outgoing) with the rows whose
        drawn layer is a top one (``draw``) replaced by that layer's lobe."""
        rows = np.flatnonzero(top >= 0)
        if rows.size == 0:
            return params
        pos = np.full(self.n, -1, np.int64)
        pos[self.rows] = np.arange(len(self.rows))
        names = ("lobe", "base", "edge", "alpha", "eta", "spec_f0", "spec_tint")
        cols = {f: np.array(getattr(params, f)) for f in names}
        for i in np.unique(top[rows]):
            r = rows[top[rows] == i]
            lay = self.layers[int(i)]
            for f in names:
                cols[f][r] = getattr(lay, f)[pos[r]]
        film = {}
        if params.film_d is not None:
            film = dict(film_d=np.array(params.film_d), film_n=params.film_n, film_ni=params.film_ni,
                        film_wl=params.film_wl)
            film["film_d"][rows] = 0.0
        return bsdf.SurfaceParams(**cols, **film)

    def take(self, idx: np.ndarray) -> "LobeMixture | None":
        """The mixture of the batch's rows ``idx`` (sorted, unique), renumbered; None where none mixes."""
        pos = np.full(self.n, -1, np.int64)
        pos[idx] = np.arange(len(idx))
        keep = np.flatnonzero(pos[self.rows] >= 0)
        if keep.size == 0:
            return None
        if keep.size == len(self.rows) and len(idx) == self.n:
            return self
        out = LobeMixture(len(idx), pos[self.rows[keep]], [w[keep] for w in self.weights],
                          [p.take(keep) for p in self.layers], [p[keep] for p in self.probs], self.codes,
                          None if self.singular_scale is None else self.singular_scale[keep])
        out._base_share = None if self._base_share is None else self._base_share[keep]
        return out

    def scale_singular(self, weight: np.ndarray, flags: np.ndarray) -> np.ndarray:
        """The bounce's weights (B, k) with the delta events of mixture rows scaled by their drawn
        layer's W / P (the one-sample estimate of a layered mixture: coat and sheen)."""
        if self.singular_scale is None:
            return weight
        r = self.rows
        sing = (np.asarray(flags)[r] & bsdf.SINGULAR) != 0
        if not sing.any():
            return weight
        out = np.array(weight, _F32)
        rr = r[sing]
        out[rr] = out[rr] * self.singular_scale[sing]
        return out

    def evaluate(self, params, wo, wi, ns, ng, lambert_scale=None):
        """f |cos| (B, k) and pdf (B,) as bsdf.evaluate, the mixture rows summed over their lobes
        (weights W_i, probabilities P_i), the others their one lobe ``params``; ``lambert_scale``
        (B,) (the bump term) multiplies the Lambertian lobes."""
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
        for w, pr, p in zip(self.weights, self.probs, self.layers):
            fl, pl = bsdf.evaluate(p, *args)
            if ls is not None:
                fl = fl * np.where(p.lobe == bsdf.LAMBERT, ls, _F32(1))[:, None]
            wf = w[:, None] * fl if w.ndim == 1 else w * fl
            fm = wf if fm is None else fm + wf
            pm = pr * pl if pm is None else pm + pr * pl
        if whole:
            return fm.astype(_F32), pm.astype(_F32)
        if fm.shape[1] != f.shape[1]:
            f = np.broadcast_to(f, (len(f), fm.shape[1])).copy()
        f[r], pdf[r] = fm, pm
        return f, pdf


def coat_sheen_layers(materials, mat, cos_o, lam, k: int) -> dict:
    """Principled's coat and sheen over the rest for hits on materials rows ``mat`` (K,) seen at
    cos_o = wo.ns (K,), as Cycles layers them (``svm_node_closure_bsdf``'s principled branch and
    ``closure_layering_weight``; docs/physics.md section 14.10):

    - sheen (weight s, tint t, roughness r): the lobe of sheen.py of weight s t R(cos_o, r); the
      layers below keep A_s = clip(1 - s max_rgb(t) R).
    - coat (weight c, roughness, IOR eta, tint T): a GGX dielectric reflection (bsdf's PLASTIC of
      zero base, F0 = ((eta - 1) / (eta + 1))^2, its multiscatter factor) of weight A_s c; below it
      A_c = clip(1 - c E_c(cos_o)), E_c the coat's directional albedo (the PLASTIC layer's E_spec),
      and the tint's absorption mix(1, T^(1 / cos_t), c), cos_t = sqrt(1 - (1 - cos_o^2) / eta^2).

    Returns 'under' (K, k): A_s A_c mix(1, T^(1/cos_t), c), the factor of the base layers' weights;
    'coat' / 'sheen' (where a row has one): (raw SurfaceParams (K rows), weight (K,) or (K, k),
    draw probability (K,)); 'base_share' (K,): the base layers' probability together. The draw
    probabilities are the layers' estimated albedos (the base's as 1) normalised."""
    m = materials
    mat = np.asarray(mat, np.int64)
    K = len(mat)
    mu = np.clip(np.asarray(cos_o, _F32), _F32(0), _F32(1))

    def spectral(table):
        return table[mat] if lam is None else table[mat, np.asarray(lam, np.int64)][:, None]

    ones = np.ones((K, k), _F32)
    one = np.ones((K, 1), _F32)  # the colourless lobes' columns (broadcast against the others' k)
    out = {}
    sw = m.sheen_weight[mat].astype(_F32)
    a_s = np.ones(K, _F32)
    e_sheen = np.zeros(K, _F32)
    if (sw > 0).any():
        from .sheen import ltc_coefficients

        albedo = ltc_coefficients(mu, m.sheen_roughness[mat])[2]
        tint = np.broadcast_to(spectral(m.sheen_tint), (K, k)).astype(_F32)
        a_s = np.clip(_F32(1) - sw * m.sheen_tint_max[mat] * albedo, _F32(0), _F32(1))
        w = (sw * albedo)[:, None] * tint
        e_sheen = w.mean(axis=1)
        p = bsdf.SurfaceParams(np.full(K, bsdf.SHEEN, np.int32), one, one, m.sheen_roughness[mat].astype(_F32),
                               np.ones(K, _F32), np.zeros(K, _F32), one)
        out["sheen"] = [p, w.astype(_F32), e_sheen]
    cw = m.coat_weight[mat].astype(_F32)
    a_c = np.ones(K, _F32)
    absorb = ones
    e_coat = np.zeros(K, _F32)
    if (cw > 0).any():
        ior = np.maximum(m.coat_ior[mat].astype(_F32), _F32(1))
        f0 = ((ior - 1) / (ior + 1)) ** 2
        rough = np.clip(m.coat_roughness[mat], 0, 1).astype(_F32)
        p = bsdf.SurfaceParams(np.full(K, bsdf.PLASTIC, np.int32), np.zeros((K, 1), _F32), one,
                               rough * rough, np.ones(K, _F32), f0.astype(_F32), one)
        e_c = bsdf.coat_albedo(p, mu)
        a_c = np.clip(_F32(1) - cw * e_c, _F32(0), _F32(1))
        tint = spectral(m.coat_tint)
        tinted = np.flatnonzero((cw > 0) & (tint != 1).any(axis=1))
        if len(tinted):  # Beer's law through the coat along the refracted view direction
            mu_t, ior_t = mu[tinted].astype(np.float64), ior[tinted].astype(np.float64)
            cos_t = np.sqrt(np.maximum(1.0 - (1.0 - mu_t * mu_t) / (ior_t * ior_t), 1e-12))
            through = np.power(np.broadcast_to(tint[tinted], (len(tinted), k)).astype(np.float64),
                               (1.0 / cos_t)[:, None])
            absorb = ones.copy()
            absorb[tinted] = 1.0 + cw[tinted, None] * (through - 1.0)
        w = a_s * cw
        e_coat = w * e_c
        out["coat"] = [p, w.astype(_F32), e_coat]
    under = (a_s * a_c)[:, None] * absorb
    e_base = under.mean(axis=1)
    tot = e_sheen + e_coat + e_base
    ok = tot > 0
    safe = np.where(ok, tot, _F32(1))
    for key in ("sheen", "coat"):
        if key in out:
            out[key][2] = np.where(ok, out[key][2] / safe, _F32(0)).astype(_F32)
            out[key] = tuple(out[key])
    out["base_share"] = np.where(ok, e_base / safe, _F32(1)).astype(_F32)
    out["under"] = under.astype(_F32)
    return out
