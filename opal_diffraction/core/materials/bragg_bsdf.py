"""The opal lobe: refraction into the stone, Bragg reflection off mosaic (111) planes, refraction out.

docs/physics.md section 5.8. Directions: wo towards the viewer, wi towards the light, both unit
and above the surface normal n (the shading normal on wo's side). Inside the stone (index
n_eff) a direction w has the refracted partner v (Snell, v . n > 0); the light travels in along
-v_i, reflects off planes of normal m (v_o = 2 (v_i . m) m - v_i, so m = +-h, h = normalize(v_i +
v_o)) and leaves along v_o. The plane normals scatter about the domain's axis a as a von
Mises-Fisher distribution (an axis: m and -m are the same planes),

    P(m) = kappa / (2 pi (1 - exp(-2 kappa))) exp(kappa (m . a - 1)),   P_ax(h) = P(h) + P(-h),
    kappa = 1 / sigma^2,  sigma = the mosaic spread (radians; the tilt's spread per axis),

sampled exactly (Wenzel Jakob, "Numerically stable sampling of the von Mises Fisher
distribution on S^2", 2012). With R(lambda, v_i . h) the band (core/materials/bragg_multilayer.py) and
T(w) = 1 - F(w . n, n_eff) the surface's Fresnel transmittance,

    f(wo, wi) = T(wo) T(wi) R P_ax(h) / (4 n_eff^2 (v_i . h) max(v_i . n, v_o . n))
    pdf(wi | wo) = P_ax(h) (wi . n) / (4 (v_o . h) n_eff^2 (v_i . n))     (mirror Jacobian 1 / (4 v.h),
                                                                       refraction n^2 cos' / cos)
    f cos / pdf = T(wo) T(wi) R (v_i . n) / max(v_i . n, v_o . n) <= 1

The max() makes the lobe reciprocal and its albedo at most 1 from either side (for planes
parallel to the face, v_i . n = v_o . n and it is exact); a reflection that heads down into the
stone, or stays inside by total internal reflection, leaves the lobe (the body takes it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..spectral.optics import fresnel_dielectric
from ..util.geometry import orthonormal_basis

__all__ = ["BraggLobe", "MIN_SPREAD_DEG", "kappa_from_spread", "inside", "outside", "vmf_sample", "vmf_pdf"]

#: Smaller mosaic spreads are taken as this (0.05 degrees): a delta lobe would need its own
#: transport; 0.05 degrees is under a pixel of usual cameras.
MIN_SPREAD_DEG = 0.05


def kappa_from_spread(spread_deg):
    s = np.radians(np.maximum(np.asarray(spread_deg, np.float64), MIN_SPREAD_DEG))
    return 1.0 / (s * s)


def _f64(a):
    return np.asarray(a, np.float64)


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def inside(w, n, n_eff):
    """The refracted partner v of external directions w (w . n > 0) in index n_eff, v . n > 0."""
    c = _dot(w, n)
    t = w - c[:, None] * n
    t_in = t / n_eff[:, None]
    cv = np.sqrt(np.maximum(0.0, 1.0 - _dot(t_in, t_in)))
    return t_in + cv[:, None] * n, cv


def outside(v, n, n_eff):
    """External partner of internal v (v . n > 0): (w, cos w.n, ok); not ok under total internal reflection."""
    c = _dot(v, n)
    t = (v - c[:, None] * n) * n_eff[:, None]
    s2 = _dot(t, t)
    ok = (s2 < 1.0) & (c > 0)
    cw = np.sqrt(np.maximum(0.0, 1.0 - s2))
    return t + cw[:, None] * n, cw, ok


def vmf_pdf(m, axis, kappa):
    """Axial vMF density of plane normals m (B, 3) about ``axis``: P(m) + P(-m) (per steradian)."""
    c = np.clip(_dot(m, axis), -1.0, 1.0)
    norm = kappa / (2.0 * np.pi * -np.expm1(-2.0 * kappa))
    return norm * (np.exp(kappa * (c - 1.0)) + np.exp(kappa * (-c - 1.0)))


def vmf_sample(axis, kappa, u1, u2):
    """vMF directions about ``axis`` (B, 3) (Jakob 2012): w = 1 + log(u + (1 - u) e^{-2 kappa}) / kappa."""
    w = 1.0 + np.log(u1 + (1.0 - u1) * np.exp(-2.0 * kappa)) / kappa
    w = np.clip(w, -1.0, 1.0)
    r = np.sqrt(np.maximum(0.0, 1.0 - w * w))
    phi = 2.0 * np.pi * u2
    tu, tv = orthonormal_basis(axis)
    return (r * np.cos(phi))[:, None] * tu + (r * np.sin(phi))[:, None] * tv + w[:, None] * axis


@dataclass
class BraggLobe:
    """The lobe's parameters at B hits: ``axis`` (B, 3) unit (111) normal (world), ``diameter``
    (B,) nm, ``n_eff`` (B,), ``kappa`` (B,), ``tables`` a list of multilayer.BandTable and
    ``table`` (B,) int: which one each hit uses."""

    axis: np.ndarray
    diameter: np.ndarray
    n_eff: np.ndarray
    kappa: np.ndarray
    tables: list
    table: np.ndarray

    def __len__(self):
        return len(self.diameter)

    def take(self, idx) -> "BraggLobe":
        return BraggLobe(self.axis[idx], self.diameter[idx], self.n_eff[idx], self.kappa[idx], self.tables,
                         self.table[idx])

    # --------------------------------------------------------------------- the band
    def band(self, cos_int, edges, lam=None):
        """R averaged over wavelength bins: (B, n) for white (``lam`` None), (B,) at bins ``lam``."""
        b = len(self)
        out = np.zeros((b, len(edges) - 1) if lam is None else b, np.float32)
        for k in np.unique(self.table):  # the domain types present (a handful)
            sel = self.table == k
            tab = self.tables[int(k)]
            out[sel] = tab.band_average(edges, cos_int[sel], self.diameter[sel], None if lam is None else lam[sel])
        return out

    # --------------------------------------------------------------------- geometry
    def _pair(self, wo, wi, n):
        """Everything f and pdf need for (wo, wi): valid mask, cosines, v_i . h, P_ax(h)."""
        ne = self.n_eff
        wo, wi, n = _f64(wo), _f64(wi), _f64(n)
        co, ci = _dot(wo, n), _dot(wi, n)
        ok = (co > 0) & (ci > 0)
        vo, cvo = inside(wo, n, ne)
        vi, cvi = inside(wi, n, ne)
        h = vo + vi
        hl = np.linalg.norm(h, axis=1)
        ok &= hl > 1e-12
        h = h / np.maximum(hl, 1e-30)[:, None]
        vh = np.abs(_dot(vi, h))
        pax = vmf_pdf(h, self.axis, self.kappa)
        return ok, co, ci, cvo, cvi, vh, pax

    def _transmittance(self, cos_ext):
        f, _ = fresnel_dielectric(cos_ext, self.n_eff)
        return 1.0 - f

    def evaluate(self, wo, wi, n, edges, lam=None):
        """(f cos(wi) (B, n) or (B,), pdf (B,)) of the lobe for light from wi seen from wo."""
        ok, co, ci, cvo, cvi, vh, pax = self._pair(wo, wi, n)
        ne2 = self.n_eff ** 2
        with np.errstate(divide="ignore", invalid="ignore"):
            pdf = np.where(ok, pax * ci / (4.0 * np.maximum(vh, 1e-12) * ne2 * np.maximum(cvi, 1e-12)), 0.0)
            scalar = np.where(ok, self._transmittance(co) * self._transmittance(ci) * pax * ci
                              / (4.0 * ne2 * np.maximum(vh, 1e-12) * np.maximum(np.maximum(cvi, cvo), 1e-12)), 0.0)
        r = self.band(vh, edges, lam)
        f_cos = (r * scalar[:, None]) if lam is None else r * scalar
        return f_cos.astype(np.float32), pdf.astype(np.float32)

    def pdf(self, wo, wi, n):
        ok, co, ci, cvo, cvi, vh, pax = self._pair(wo, wi, n)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(ok, pax * ci / (4.0 * np.maximum(vh, 1e-12) * self.n_eff ** 2 * np.maximum(cvi, 1e-12)),
                            0.0).astype(np.float32)

    def sample(self, wo, n, u, edges, lam=None):
        """(wi (B, 3), weight = f cos / pdf ((B, n) or (B,)), pdf (B,), ok (B,)) for u (B, 2) in [0, 1)."""
        ne = self.n_eff
        wo, n = _f64(wo), _f64(n)
        vo, cvo = inside(wo, n, ne)
        m = vmf_sample(self.axis, self.kappa, u[:, 0].astype(np.float64), u[:, 1].astype(np.float64))
        vi = 2.0 * _dot(vo, m)[:, None] * m - vo
        wi, ci, ok = outside(vi, n, ne)
        ok &= _dot(wo, n) > 0
        wi = wi / np.maximum(np.linalg.norm(wi, axis=1), 1e-30)[:, None]
        pdf = self.pdf(wo, wi, n)
        ok &= pdf > 0
        cvi = _dot(vi, n)
        vh = np.abs(_dot(vo, m))
        scalar = np.where(ok, self._transmittance(_dot(wo, n)) * self._transmittance(ci) * cvi
                          / np.maximum(np.maximum(cvi, cvo), 1e-12), 0.0)
        r = self.band(vh, edges, lam)
        weight = r * scalar[:, None] if lam is None else r * scalar
        return wi.astype(np.float32), weight.astype(np.float32), pdf, ok

    def albedo(self, wo, n, edges, lam=None):
        """The lobe's directional albedo at wo, approximately: T(wo) T(wi) R at the mirror of the
        mean planes (the mosaic average left out); 0 where that mirror stays inside the stone.
        What the body under the planes is scaled by (1 - albedo) with."""
        ne = self.n_eff
        wo, n = _f64(wo), _f64(n)
        vo, cvo = inside(wo, n, ne)
        a = _f64(self.axis)
        vi = 2.0 * _dot(vo, a)[:, None] * a - vo
        wi, ci, ok = outside(vi, n, ne)
        ok &= _dot(wo, n) > 0
        vh = np.abs(_dot(vo, a))
        cvi = _dot(vi, n)
        scalar = np.where(ok, self._transmittance(_dot(wo, n)) * self._transmittance(ci) * cvi
                          / np.maximum(np.maximum(cvi, cvo), 1e-12), 0.0)
        r = self.band(vh, edges, lam)
        return (r * scalar[:, None] if lam is None else r * scalar).astype(np.float32)
