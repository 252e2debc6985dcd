"""Emissive meshes as lights: the triangles whose material emits, sampled like area lights.

The method is pbrt-v4's DiffuseAreaLight on triangles with a power-weighted light choice
(section 12.6, "Light sampling"), with Cycles' conventions (kernel/light/triangle.h,
scene/light.cpp ``device_update_distribution``): a triangle is chosen with probability
proportional to its area times its emitted luminance (the Y-weighted emission spectrum; Cycles'
distribution weighs by area, its light tree by energy), then a uniform point on it. The emitter
is two-sided, as Cycles' Emission closure (``emissive_simple_eval`` takes |cos|) and its default
emission sampling "Auto" (front and back): each side emits radiance L, so a triangle of area A
emits 2 pi A L in total.

For a shading point p and a sample q on triangle j, with d = |q - p| and cos_l = |n_j . wi|:
- area pdf of q: P(j) / A_j = Y_j / sum_k(A_k Y_k);
- solid-angle pdf: pdf_area d^2 / cos_l;
- g = cos_l / (d^2 pdf_area): the irradiance before the receiver's cosine is g times the
  emission at q (the caller looks the emission up: textures).

Vectorised over the shading points: one cumulative distribution over the emitting triangles,
searched with ``np.searchsorted`` (docs/physics.md section 7.6).
"""

from __future__ import annotations

import numpy as np

__all__ = ["MeshLights"]


class MeshLights:
    """The emitting triangles of one prepared scene and their power-proportional sampler."""

    def __init__(self, tri, v0, e1, e2, normal, area, weight, area_pdf_by_tri, tri_normal):
        self.tri = tri                    # (E,) int64 scene triangle index of each emitter
        self.v0, self.e1, self.e2 = v0, e1, e2  # (E, 3) float64 corner and edges
        self.normal = normal              # (E, 3) float64 unit normals
        self.area = area                  # (E,) float64 m^2
        self.weight = weight              # (E,) float64 area x luminance of each emitter
        self._cdf = np.cumsum(weight)     # (E,) float64, last = total
        self.total = float(self._cdf[-1])
        self._area_pdf = area_pdf_by_tri  # (T,) float64: area pdf of a point on scene triangle t (0: not an emitter)
        self._tri_normal = tri_normal     # (T, 3) float64 unit normals of all scene triangles
        for a in (tri, v0, e1, e2, normal, area, weight, self._cdf, area_pdf_by_tri, tri_normal):
            a.flags.writeable = False  # part of a frozen PreparedScene, read from many threads

    @classmethod
    def build(cls, vertices, triangles, tri_material, emission_spectra, tri_normal,
              luminance_weights=None) -> "MeshLights | None":
        """The emitters among the scene's triangles, or None when no material emits.

        ``emission_spectra`` (M, n): each material's emitted radiance on the grid;
        ``luminance_weights`` (n,): the Y observer's bin weights (spectrum @ weights = luminance;
        default: the mean over the bins), which weigh the choice of triangle.
        """
        t = np.asarray(triangles).reshape(-1, 3)
        tm = np.asarray(tri_material).reshape(-1)
        em = np.asarray(emission_spectra, np.float64)
        if len(t) == 0 or em.size == 0:
            return None
        w = (np.full(em.shape[1], 1.0 / em.shape[1]) if luminance_weights is None
             else np.asarray(luminance_weights, np.float64))
        lum = np.maximum(em @ w, 0.0)
        # per material, then looked up per triangle (never a (T, n) array of spectra)
        emits = ((lum > 0) & np.any(em > 0, axis=1))[tm]
        if not emits.any():
            return None
        tri = np.flatnonzero(emits)
        p = np.asarray(vertices)[np.asarray(t[tri], np.int64)].astype(np.float64)  # the emitters' corners only
        e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
        cr = np.cross(e1, e2)
        area = 0.5 * np.linalg.norm(cr, axis=1)
        keep = area > 0
        if not keep.any():
            return None
        tri, p, e1, e2, cr, area = tri[keep], p[keep], e1[keep], e2[keep], cr[keep], area[keep]
        normal = cr / (2 * area)[:, None]
        weight = area * lum[tm[tri]]
        area_pdf = np.zeros(len(t))
        area_pdf[tri] = lum[tm[tri]] / weight.sum()  # P(j) / A_j
        tn = np.asarray(tri_normal, np.float64).reshape(-1, 3)
        tn = tn.copy() if len(tn) == len(t) else np.zeros((len(t), 3))
        tn[tri] = normal  # exactly the normals sampled with
        return cls(tri, p[:, 0].copy(), e1, e2, normal, area, weight, area_pdf, tn)

    def __len__(self):
        return len(self.tri)

    @property
    def power(self) -> float:
        """Luminous-weighted power of all emitters, W (both sides: 2 pi sum A Y)."""
        return 2 * np.pi * self.total

    def sample_points(self, rng: np.random.Generator, b: int):
        """``b`` emitter points: (q (b, 3) float64, index into the emitters (b,), area pdf (b,)).
        A triangle with probability proportional to area x luminance, a uniform point on it
        (barycentrics (1 - sqrt u1, sqrt u1 (1 - u2), sqrt u1 u2): Shirley's square-root map)."""
        j = np.searchsorted(self._cdf, rng.random(b) * self.total, side="right")
        j = np.minimum(j, len(self.tri) - 1)
        su = np.sqrt(rng.random(b))
        u2 = rng.random(b)
        b1, b2 = su * (1 - u2), su * u2
        q = self.v0[j] + b1[:, None] * self.e1[j] + b2[:, None] * self.e2[j]
        return q, j, self._area_pdf[self.tri[j]]

    def sample(self, p, rng: np.random.Generator):
        """One emitter sample per shading point p (B, 3).

        Returns (wi (B, 3) float32 unit towards the sample, dist (B,) float32, g (B,) float32,
        prim (B,) int64 scene triangle, pdf (B,) float32 solid-angle pdf); g and pdf are 0 where
        the sample is seen edge-on or coincides with p.
        """
        p = np.asarray(p, np.float64)
        q, j, pa = self.sample_points(rng, len(p))
        to_q = q - p
        d2 = np.einsum("ij,ij->i", to_q, to_q)
        dist = np.sqrt(d2)
        wi = to_q / np.maximum(dist, 1e-300)[:, None]
        cos_l = np.abs(np.einsum("ij,ij->i", wi, self.normal[j]))
        ok = (cos_l > 0) & (d2 > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.where(ok, cos_l / (d2 * pa), 0.0)
            pdf = np.where(ok, pa * d2 / cos_l, 0.0)
        return (wi.astype(np.float32), dist.astype(np.float32), g.astype(np.float32), self.tri[j],
                pdf.astype(np.float32))

    def pdf(self, prim, p_from, p_on) -> np.ndarray:
        """(B,) float32 solid-angle pdf with which ``sample`` draws the point ``p_on`` (B, 3) of
        scene triangle ``prim`` (B,) from ``p_from`` (B, 3); 0 for triangles that do not emit."""
        prim = np.asarray(prim, np.int64)
        to_q = np.asarray(p_on, np.float64) - np.asarray(p_from, np.float64)
        d2 = np.einsum("ij,ij->i", to_q, to_q)
        cos_l = np.abs(np.einsum("ij,ij->i", to_q, self._tri_normal[prim])) / np.sqrt(np.maximum(d2, 1e-300))
        pa = self._area_pdf[prim]
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.where((cos_l > 0) & (pa > 0), pa * d2 / cos_l, 0.0)
        return out.astype(np.float32)
