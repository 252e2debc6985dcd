"""Emissive meshes as lights: the triangles whose material emits, sampled like area lights.

The method is pbrt-v4's DiffuseAreaLight on triangles with a power-weighted light choice
(section 12.6, "Light sampling"), with Cycles' conventions (kernel/light/triangle.h,
scene/light.cpp ``device_update_distribution``): a triangle is chosen with probability
proportional to its area times its emitted luminance (the Y-weighted emission spectrum; Cycles'
distribution weighs by area, its light tree by energy), then a point on it. The emitter is
two-sided, as Cycles' Emission closure (``emissive_simple_eval`` takes |cos|) and its default
emission sampling "Auto" (front and back): each side emits radiance L, so a triangle of area A
emits 2 pi A L in total.

One 2-D sample (u0, u1) per next event (docs/physics.md section 7.11): u0 picks the triangle
from the cumulative distribution and is rescaled into [0, 1) within the chosen triangle's
interval, so (u0', u1) stay one stratified pair for the point (pbrt-v4's
SampleDiscrete-with-remapping). The point, as Cycles' triangle_light_sample:
- seen from far (the longest edge at most the distance to the triangle's plane): uniform by
  area, through Heitz's low-distortion square-to-triangle map (Heitz 2019, "A Low-Distortion
  Map Between Triangle and Square"), area pdf P(j) / A_j;
- seen from near: uniform in the solid angle the triangle subtends (Arvo 1995, "Stratified
  Sampling of Spherical Triangles"; pbrt-v4 SampleSphericalTriangle), pdf P(j) / Omega_j with
  Omega_j from Van Oosterom & Strackee's formula. The nearby points of a large panel (the
  walls under a ceiling light) no longer pay the 1 / d^2 spread of area sampling.

For a shading point p and a sample q on triangle j, with d = |q - p| and cos_l = |n_j . wi|:
- solid-angle pdf: P(j) d^2 / (A_j cos_l) (area sampling) or P(j) / Omega_j (solid angle);
- g = 1 / pdf: the irradiance before the receiver's cosine is g times the emission at q (the
  caller looks the emission up: textures).

Vectorised over the shading points: one cumulative distribution over the emitting triangles,
searched with ``np.searchsorted`` (docs/physics.md sections 7.6, 7.11).
"""

from __future__ import annotations

import numpy as np

__all__ = ["MeshLights"]


#: A nearby triangle subtending less than this solid angle (sr) is still sampled by area: its
#: spherical triangle is too thin for Arvo's construction (a point almost in its plane, where
#: the triangle sends next to nothing anyway).
MIN_SOLID_ANGLE = 1e-5


def _dot(a, b):
    """Row-wise dot products of (K, 3) arrays (``_d0``: of (3, K) arrays)."""
    return np.einsum("ij,ij->i", a, b)


def _d0(a, b):
    """Dot products of (3, K) arrays (one vector per column)."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross0(a, b):
    return np.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _unit0(v):
    return v / np.sqrt(np.maximum(_d0(v, v), 1e-300))


def _spherical_setup(a, b, c):
    """For unit corners a, b, c (3, K): (cos of the arc ab, the triple product |a . (b x c)|,
    the solid angle Omega (Van Oosterom & Strackee 1983: tan(Omega / 2) = |a . (b x c)| /
    (1 + a.b + b.c + c.a)), cos and sin of the angle at a)."""
    cos_a, cos_b, cos_c = _d0(b, c), _d0(a, c), _d0(a, b)  # the arcs opposite a, b, c
    triple = np.abs(_d0(a, _cross0(b, c)))
    omega = 2.0 * np.arctan2(triple, 1.0 + cos_a + cos_b + cos_c)
    # the angle at a: cos = (cos_a - cos_b cos_c) / (sin_b sin_c), sin = triple / (sin_b sin_c);
    # normalised together, so no sin_b sin_c and no inverse trigonometry
    num = cos_a - cos_b * cos_c
    r = np.sqrt(np.maximum(num * num + triple * triple, 1e-300))
    return cos_c, omega, num / r, triple / r


def _arvo(a, b, c, u0, u1, setup):
    """sample_spherical_triangle on (3, K) corners with their ``_spherical_setup``: (3, K)."""
    cos_ab, omega, cos_al, sin_al = setup
    sub = u0 * omega  # the sub-triangle's area
    sin_s, cos_s = np.sin(sub), np.cos(sub)
    s = sin_s * cos_al - cos_s * sin_al  # sin(sub - alpha)
    t = cos_s * cos_al + sin_s * sin_al  # cos(sub - alpha)
    uu = t - cos_al
    vv = s + sin_al * cos_ab
    with np.errstate(divide="ignore", invalid="ignore"):
        q = ((vv * t - uu * s) * cos_al - vv) / ((vv * s + uu * t) * sin_al)  # cos of the arc a c'
    q = np.clip(np.nan_to_num(q, nan=1.0), -1.0, 1.0)
    c2 = q * a + np.sqrt(np.maximum(1.0 - q * q, 0.0)) * _unit0(c - _d0(c, a) * a)
    z = 1.0 - u1 * (1.0 - _d0(c2, b))
    return z * b + np.sqrt(np.maximum(1.0 - z * z, 0.0)) * _unit0(c2 - _d0(c2, b) * b)


def solid_angle(a, b, c):
    """(K,) solid angles of the spherical triangles with unit corners a, b, c (K, 3): Van
    Oosterom & Strackee 1983, tan(Omega / 2) = |a . (b x c)| / (1 + a.b + b.c + c.a)."""
    return _spherical_setup(np.asarray(a, np.float64).T, np.asarray(b, np.float64).T,
                            np.asarray(c, np.float64).T)[1]


def sample_spherical_triangle(a, b, c, u0, u1):
    """Directions uniform in the spherical triangles with unit corners a, b, c (K, 3) from two
    uniform numbers (K,) each (Arvo 1995, "Stratified Sampling of Spherical Triangles"): u0
    chooses the sub-triangle (a, b, c') of area u0 Omega (the arc a c' from Arvo's closed form,
    with the angle at a from its cosine and sine), u1 a point on the arc from b to c' with the
    density that keeps the whole uniform. Returns unit (K, 3)."""
    a, b, c = (np.asarray(x, np.float64).T for x in (a, b, c))
    return _arvo(a, b, c, np.asarray(u0, np.float64), np.asarray(u1, np.float64), _spherical_setup(a, b, c)).T


def heitz_triangle(u0, u1):
    """Barycentric weights (b1, b2) of V1 and V2 for a uniform point on a triangle from a point
    of the unit square, by Heitz's low-distortion map (2019; Cycles' triangle_light_sample):
    nearby square points stay nearby, so stratified pairs stay stratified on the triangle."""
    upper = u1 > u0
    b1 = np.where(upper, 0.5 * u0, u0 - 0.5 * u1)
    b2 = np.where(upper, u1 - 0.5 * u0, 0.5 * u1)
    return b1, b2


class MeshLights:
    """The emitting triangles of one prepared scene and their power-proportional sampler."""

    def __init__(self, tri, v0, e1, e2, normal, area, weight, n_triangles: int):
        self.tri = tri                    # (E,) int64 scene triangle index of each emitter
        self.v0, self.e1, self.e2 = v0, e1, e2  # (E, 3) float64 corner and edges
        self.normal = normal              # (E, 3) float64 unit normals
        self.area = area                  # (E,) float64 m^2
        self.weight = weight              # (E,) float64 area x luminance of each emitter
        self._cdf = np.cumsum(weight)     # (E,) float64, last = total
        self.total = float(self._cdf[-1])
        self._cdf_lo = self._cdf - weight  # (E,) start of each emitter's interval
        self.prob = weight / self.total   # (E,) P(j)
        e3 = e2 - e1
        self.longest2 = np.maximum(np.maximum(_dot(e1, e1), _dot(e2, e2)), _dot(e3, e3))  # (E,) m^2
        self._plane = _dot(normal, v0)    # (E,) n . v0: the plane's offset
        # (3, E) copies, one vector per column: the per-sample geometry runs on (3, B) rows
        self._v0t, self._v1t, self._v2t = (np.ascontiguousarray(x.T) for x in (v0, v0 + e1, v0 + e2))
        self._e1t, self._e2t, self._nt = (np.ascontiguousarray(x.T) for x in (e1, e2, normal))
        # (T,) emitter index of each scene triangle, -1 where it does not emit
        self._emitter_of = np.full(int(n_triangles), -1, np.int32 if len(tri) < 2 ** 31 else np.int64)
        self._emitter_of[tri] = np.arange(len(tri))
        for a in (tri, v0, e1, e2, normal, area, weight, self._cdf, self._cdf_lo, self.prob, self.longest2,
                  self._plane, self._v0t, self._v1t, self._v2t, self._e1t, self._e2t, self._nt, self._emitter_of):
            a.flags.writeable = False  # part of a frozen PreparedScene, read from many threads

    @classmethod
    def build(cls, vertices, triangles, tri_material, emission_spectra,
              luminance_weights=None) -> "MeshLights | None":
        """The emitters among the scene's triangles, or None when no material emits.

        ``emission_spectra`` (M, n): each material's emitted radiance on the grid;
        ``luminance_weights`` (n,): the Y observer's bin weights (spectrum @ weights = luminance;
        default: the mean over the bins), which weigh the choice of triangle. The emitters'
        normals come from their corners, exactly the ones sampled with.
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
        return cls(tri, p[:, 0].copy(), e1, e2, normal, area, weight, len(t))

    def __len__(self):
        return len(self.tri)

    @property
    def power(self) -> float:
        """Luminous-weighted power of all emitters, W (both sides: 2 pi sum A Y)."""
        return 2 * np.pi * self.total

    def pick(self, u0) -> tuple[np.ndarray, np.ndarray]:
        """Emitters j (b,) with probability P(j) from uniform numbers ``u0`` (b,), and u0
        rescaled into [0, 1) within j's interval of the cumulative distribution (uniform and
        independent of j: the same number serves the point on j)."""
        x = np.asarray(u0, np.float64) * self.total
        j = np.minimum(np.searchsorted(self._cdf, x, side="right"), len(self.tri) - 1)
        r = (x - self._cdf_lo[j]) / self.weight[j]
        return j, np.clip(r, 0.0, np.nextafter(1.0, 0.0))

    def sample_points(self, rng: np.random.Generator, b: int):
        """``b`` emitter points by area: (q (b, 3) float64, index into the emitters (b,), area
        pdf P(j) / A_j (b,)). One pair of numbers per point: the triangle (``pick``) and, with
        the rescaled number, a uniform point on it (``heitz_triangle``)."""
        u = rng.random((b, 2))
        j, u0 = self.pick(u[:, 0])
        b1, b2 = heitz_triangle(u0, u[:, 1])
        q = self.v0[j] + b1[:, None] * self.e1[j] + b2[:, None] * self.e2[j]
        return q, j, self.prob[j] / self.area[j]

    def _near(self, pt, j):
        """Which (point, emitter) pairs sample by solid angle, by Cycles' heuristic (the longest
        edge longer than the distance to the triangle's plane), and for those the corners' unit
        directions (3, K each) and their ``_spherical_setup``: (near (b,) bool, a, b, c, setup).
        ``pt`` (3, b) float64 points, ``j`` (b,) emitters. Pairs whose solid angle is below
        MIN_SOLID_ANGLE stay with area sampling."""
        plane = _d0(pt, np.take(self._nt, j, axis=1)) - self._plane[j]
        near = self.longest2[j] > plane * plane
        idx = np.flatnonzero(near)
        if idx.size == 0:
            return near, None, None, None, None
        pn, jn = np.take(pt, idx, axis=1), j[idx]
        a = _unit0(np.take(self._v0t, jn, axis=1) - pn)
        b = _unit0(np.take(self._v1t, jn, axis=1) - pn)
        c = _unit0(np.take(self._v2t, jn, axis=1) - pn)
        setup = _spherical_setup(a, b, c)
        ok = setup[1] > MIN_SOLID_ANGLE
        if not ok.all():
            near[idx[~ok]] = False
            a, b, c = a[:, ok], b[:, ok], c[:, ok]
            setup = tuple(x[ok] for x in setup)
        return near, a, b, c, setup

    def sample(self, p, rng: np.random.Generator):
        """One emitter sample per shading point p (B, 3), from one pair of numbers.

        Returns (wi (B, 3) float32 unit towards the sample, dist (B,) float32, g = 1 / pdf (B,)
        float32, prim (B,) int64 scene triangle, pdf (B,) float32 solid-angle pdf); g and pdf are
        0 where the sample is seen edge-on or coincides with p.
        """
        pt = np.ascontiguousarray(np.asarray(p, np.float64).T)  # (3, B)
        b = pt.shape[1]
        u = rng.random((b, 2))
        j, u0 = self.pick(u[:, 0])
        u1 = u[:, 1]
        wi = np.empty((3, b))
        dist = np.empty(b)
        pdf = np.empty(b)
        near, a, bb, c, setup = self._near(pt, j)
        far = np.flatnonzero(~near)
        if far.size:  # by area: a point on the triangle (Heitz's map), pdf P(j) t^2 / (A_j cos_l)
            jf = j[far]
            b1, b2 = heitz_triangle(u0[far], u1[far])
            to_q = (np.take(self._v0t, jf, axis=1) + b1 * np.take(self._e1t, jf, axis=1)
                    + b2 * np.take(self._e2t, jf, axis=1) - np.take(pt, far, axis=1))
            d2 = _d0(to_q, to_q)
            t = np.sqrt(d2)
            w = to_q / np.maximum(t, 1e-300)
            cos_l = np.abs(_d0(w, np.take(self._nt, jf, axis=1)))
            with np.errstate(divide="ignore", invalid="ignore"):
                pdf[far] = np.where((cos_l > 0) & (d2 > 0), self.prob[jf] / self.area[jf] * d2 / cos_l, 0.0)
            wi[:, far], dist[far] = w, t
        if a is not None:  # by solid angle: a direction in the spherical triangle, then its point
            idx = np.flatnonzero(near)
            jn = j[idx]
            w = _arvo(a, bb, c, u0[idx], u1[idx], setup)
            nrm = np.take(self._nt, jn, axis=1)
            den = _d0(w, nrm)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (self._plane[jn] - _d0(np.take(pt, idx, axis=1), nrm)) / den
            good = np.isfinite(t) & (t > 0)
            wi[:, idx] = w
            dist[idx] = np.where(good, t, 0.0)
            pdf[idx] = np.where(good, self.prob[jn] / setup[1], 0.0)
        with np.errstate(divide="ignore"):
            g = np.where(pdf > 0, 1.0 / pdf, 0.0)
        return (np.ascontiguousarray(wi.T, np.float32), dist.astype(np.float32), g.astype(np.float32), self.tri[j],
                pdf.astype(np.float32))

    def pdf(self, prim, p_from, p_on) -> np.ndarray:
        """(B,) float32 solid-angle pdf with which ``sample`` draws the point ``p_on`` (B, 3) of
        scene triangle ``prim`` (B,) from ``p_from`` (B, 3); 0 for triangles that do not emit."""
        j = self._emitter_of[np.asarray(prim, np.int64)]
        out = np.zeros(len(j), np.float64)
        em = np.flatnonzero(j >= 0)
        if em.size == 0:
            return out.astype(np.float32)
        j = j[em]
        pt = np.ascontiguousarray(np.asarray(p_from, np.float64)[em].T)
        to_q = np.asarray(p_on, np.float64)[em].T - pt
        d2 = _d0(to_q, to_q)
        cos_l = np.abs(_d0(to_q, np.take(self._nt, j, axis=1))) / np.sqrt(np.maximum(d2, 1e-300))
        with np.errstate(divide="ignore", invalid="ignore"):
            val = np.where(cos_l > 0, self.prob[j] / self.area[j] * d2 / cos_l, 0.0)
        near, _, _, _, setup = self._near(pt, j)
        if setup is not None:
            val[near] = self.prob[j[near]] / setup[1]
        out[em] = val
        return out.astype(np.float32)
