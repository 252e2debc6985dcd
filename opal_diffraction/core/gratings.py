"""Diffraction gratings at surface hits: the grating frame and the diffracted radiance of a light.

The model is the source paper's (Kobayashi & Kawai; docs/physics.md section 3): a patch of N
slits (period D, width a, length L) under spectral irradiance E_i(lambda) from direction w_i
sends, towards w_o,

    L_o(lambda) = E_i(lambda) * a^2 L N / (lambda^2 D cos theta_o) * P(u, v, lambda),
    u = (w_o + w_i) . t,  v = (w_o + w_i) . s,  s = n x t,

with P the normalised Fraunhofer pattern of ``diffraction.py``, averaged over each wavelength
bin in closed form (so orders narrower than a bin are neither missed nor flickering).
Known deviation: the specification's radiance has no 1/cos theta_o (docs/physics.md section
3.2, tracked by the [diffraction] issue); the factors below still have it.

A HEXAGONAL lattice (opal-like) is the product of two N-slit factors along t and t rotated by
60 degrees, with the Airy envelope of disk apertures of diameter a: P = [2 J1(x)/x]^2 *
F_N(eta_1) * F_N(eta_2), x = pi a q / lambda, q = |(w_o + w_i) tangential|; its radiance factor
is A^2 N^2 / (lambda^2 A_cell cos theta_o) with A = pi a^2 / 4 and A_cell = (sqrt 3 / 2) D^2
(the same Fraunhofer normalisation as the slits: the pattern integrates to the power through
the openings). The product of two sharp factors has no closed-form bin average, so each bin
takes one stratified random wavelength per sample: unbiased, it converges with the samples
per pixel (the LINES case is exact per sample). Its first orders sit at
|q| = 2 lambda / (sqrt 3 D) (docs/physics.md section 3.4).

A reflection grating diffracts light arriving on the viewer's side, a transmission grating light
arriving from the other side; the grating is layered on the base material, whose own response
(diffuse, glass, ...) is computed as usual (known deviation: docs/physics.md section 3.3 takes
the diffracted power from the base instead).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import j1

from .enums import GratingType, Lattice
from .diffraction import fraunhofer_pattern_binned, multislit

__all__ = ["PreparedGratings", "prepare_gratings", "triangle_tangents", "grating_frame", "diffracted_radiance"]

NM = 1e-9
UM = 1e-6


@dataclass
class PreparedGratings:
    enabled: np.ndarray       # (M,) bool
    transmission: np.ndarray  # (M,) bool
    hexagonal: np.ndarray     # (M,) bool
    period: np.ndarray        # (M,) nm
    slit_width: np.ndarray    # (M,) nm
    slit_count: np.ndarray    # (M,) int
    length: np.ndarray        # (M,) nm (coherence length)
    cos_rot: np.ndarray       # (M,)
    sin_rot: np.ndarray       # (M,)
    bragg: np.ndarray | None = None  # (M,) bool: the BRAGG lattice (core/opal/bragg_shading.py), not a surface grating

    @property
    def any(self) -> bool:
        return bool(self.enabled.any())


def prepare_gratings(m) -> PreparedGratings:
    rot = np.asarray(m.rotation, np.float64)
    return PreparedGratings(
        enabled=(np.asarray(m.grating) != 0) & (np.asarray(m.lattice) != Lattice.BRAGG),  # BRAGG: a volume lobe
        transmission=np.asarray(m.grating_type) == GratingType.TRANSMISSION,
        hexagonal=np.asarray(m.lattice) == Lattice.HEXAGONAL,
        period=np.asarray(m.period, np.float64),
        slit_width=np.asarray(m.slit_width, np.float64),
        slit_count=np.asarray(m.slit_count, np.int64),
        length=np.asarray(m.coherence_length, np.float64) * 1e3,  # um -> nm
        cos_rot=np.cos(rot),
        sin_rot=np.sin(rot),
        bragg=(np.asarray(m.grating) != 0) & (np.asarray(m.lattice) == Lattice.BRAGG),
    )


def triangle_tangents(tri_normal: np.ndarray, tri_tangent: np.ndarray) -> np.ndarray:
    """Unit grating vectors in each triangle's plane (T, 3) float32.

    The given tangent (the exporter's UV U direction, object axis or per-face attribute) is
    projected onto the plane; where none is given (zero) or it is parallel to the normal, the
    world X axis is projected instead (then Y), so neighbouring coplanar triangles agree.
    """
    n = np.asarray(tri_normal, np.float64)
    t_count = len(n)
    given = np.asarray(tri_tangent, np.float64).reshape(-1, 3)
    if len(given) != t_count:
        given = np.zeros((t_count, 3))
    out = np.zeros((t_count, 3))
    todo = np.ones(t_count, bool)
    for cand in (given, np.array([[1.0, 0, 0]]), np.array([[0.0, 1, 0]])):
        c = np.broadcast_to(cand, (t_count, 3))
        proj = c - np.sum(c * n, axis=1, keepdims=True) * n
        norm = np.linalg.norm(proj, axis=1)
        ok = todo & (norm > 1e-6)
        out[ok] = proj[ok] / norm[ok, None]
        todo &= ~ok
    return out.astype(np.float32)


def grating_frame(tangent: np.ndarray, normal: np.ndarray, cos_rot, sin_rot):
    """(t, s) at hits: the triangle's tangent rotated about the normal, and s = n x t."""
    nxt = np.cross(normal, tangent)
    t = cos_rot[:, None] * tangent + sin_rot[:, None] * nxt
    return t, np.cross(normal, t)


def _airy(x):
    x = np.asarray(x, np.float64)
    small = np.abs(x) < 1e-6
    safe = np.where(small, 1.0, x)
    return np.where(small, 1.0, (2 * j1(safe) / safe) ** 2)


def diffracted_radiance(g: PreparedGratings, mat: int, w_o, w_i, t, s, normal, period, edges_nm, rng):
    """Radiance per unit irradiance (1/sr) towards w_o, per wavelength bin: (B, K).

    ``mat``: the material (one grating's parameters per call); w_o, w_i, t, s, normal: (B, 3);
    ``period``: (B,) nm (a per-triangle override, else the material's); the slit width keeps the
    material's ratio a / D. ``edges_nm``: (K + 1,) bin edges.
    """
    d = np.asarray(period, np.float64)[:, None]
    a = d * (g.slit_width[mat] / g.period[mat])
    n = int(g.slit_count[mat])
    h = np.asarray(w_o, np.float64) + np.asarray(w_i, np.float64)
    cos_o = np.abs(np.sum(np.asarray(w_o, np.float64) * normal, axis=1))[:, None]
    cos_o = np.maximum(cos_o, 1e-3)  # grazing exits stay finite
    u = np.sum(h * t, axis=1)
    edges = np.asarray(edges_nm, np.float64)
    if not g.hexagonal[mat]:
        v = np.sum(h * s, axis=1)
        length = g.length[mat]
        # the bin mean of P / lambda^2 (lambda in nm), then the factor's lengths in metres
        p = fraunhofer_pattern_binned(u, v, edges, a, d, n, length, lam_power=-2) / NM**2
        factor = (a * NM) ** 2 * (length * NM) * n / ((d * NM) * cos_o)
        return (factor * p).astype(np.float32)
    # hexagonal lattice: one stratified random wavelength per bin and sample
    t2 = 0.5 * t + (np.sqrt(3) / 2) * np.cross(normal, t)
    u2 = np.sum(h * t2, axis=1)
    q = np.linalg.norm(h - np.sum(h * normal, axis=1, keepdims=True) * normal, axis=1)
    lam = edges[:-1][None, :] + (edges[1:] - edges[:-1])[None, :] * rng.random((len(u), len(edges) - 1))
    p = (_airy(np.pi * a * q[:, None] / lam) * multislit(np.pi * d * u[:, None] / lam, n)
         * multislit(np.pi * d * u2[:, None] / lam, n))
    area = np.pi * (a * NM) ** 2 / 4
    cell = np.sqrt(3) / 2 * (d * NM) ** 2
    factor = area**2 * n * n / ((lam * NM) ** 2 * cell * cos_o)
    return (factor * p).astype(np.float32)
