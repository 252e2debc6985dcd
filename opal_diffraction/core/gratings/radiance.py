"""Diffraction gratings at surface hits: the grating frame and the diffracted radiance of a light.

The model is the source paper's (Kobayashi & Kawai; docs/physics.md section 3): a patch of N
slits (period D, width a, length L) under spectral irradiance E_i(lambda) from direction w_i
sends, towards w_o,

    L_o(lambda) = E_i(lambda) * a^2 L N / (lambda^2 D) * P(u, v, lambda),
    u = (w_o + w_i) . t,  v = (w_o + w_i) . s,  s = n x t,

with P the normalised Fraunhofer pattern of ``diffraction.py``, averaged over each wavelength
bin in closed form (so orders narrower than a bin are neither missed nor flickering). The pattern
lives in direction cosines (du dv = cos theta_o d omega_o), so there is no 1/cos theta_o
(docs/physics.md section 3.2; Harvey et al., Appl. Opt. 38, 6469, 1999): the orders together
carry a / D of the incident power. With ``renormalise`` (the default: the grating then
delivers exactly the power its layering takes from the surface budget, a / D, and energy does not
silently vanish where an order turns evanescent; docs/physics.md section 3.2 argues the choice) the
propagating orders are rescaled by the Harvey-Shack factor so that they carry all of it
(kernel.harvey_shack_factor).

A HEXAGONAL lattice (opal-like) is the product of two N-slit factors along t and t rotated by
60 degrees, with the Airy envelope of disk apertures of diameter a: P = [2 J1(x)/x]^2 *
F_N(eta_1) * F_N(eta_2), x = pi a q / lambda, q = |(w_o + w_i) tangential|; its radiance factor
is A^2 N^2 / (lambda^2 A_cell) with A = pi a^2 / 4 and A_cell = (sqrt 3 / 2) D^2 (the same
Fraunhofer normalisation as the slits: the pattern integrates to the power through the
openings, the fill fraction A / A_cell). The product of two sharp factors has no closed-form bin
average, so each bin takes one stratified random wavelength per sample: unbiased, it converges
with the samples per pixel (the LINES case is exact per sample). Nearest neighbours are D apart
and rows (sqrt 3 / 2) D, so its first orders sit at |q| = 2 lambda / (sqrt 3 D) (docs/physics.md
section 3.4; tests/gratings/test_grating_radiometry.py checks it against a phasor sum over a patch).

With a ``footprint`` (core/sampling/footprint.py: ray differentials), the LINES pattern is averaged over
each sample's pixel footprint in (u, v) as well, in closed form
(``diffraction.fraunhofer_pattern_footprint``; docs/physics.md section 3.7).

A reflection grating diffracts light arriving on the viewer's side, a transmission grating light
arriving from the other side. Its layering on the base material (grating_layering.py,
docs/physics.md section 3.3): where the base's specular lobe is the zeroth order (a mirror under a
reflection grating, glass under a transmission grating) the diffraction here leaves the zeroth
order out and the base's continuation carries it; elsewhere the base keeps 1 - a/D of its
response and the grating diffracts all its orders.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import j1

from ..util.enums import GratingType, Lattice
from .kernel import (fraunhofer_pattern_binned, fraunhofer_pattern_footprint, harvey_shack_factor, hexagonal_harvey_shack_factor, multislit)

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
    # the layering on the base (grating_layering.attach_layering; None until prepare sets it):
    # the zeroth order is the base's specular continuation, so the diffraction leaves it out
    zeroth_in_base: np.ndarray | None = None  # (M,) bool
    bragg: np.ndarray | None = None  # (M,) bool: the BRAGG lattice (core/integrators/bragg_shading.py), not a surface grating

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


def triangle_tangents(tri_normal: np.ndarray, tri_tangent: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
    """Unit grating vectors in each triangle's plane (T, 3) float32.

    The given tangent (the exporter's UV U direction, object axis or per-face attribute) is
    projected onto the plane; where none is given (zero) or it is parallel to the normal, the
    world X axis is projected instead (then Y), so neighbouring coplanar triangles agree.

    ``rows``: (T,) bool, only these triangles (the gratings': nothing reads the others' rows);
    the other rows are zero. The rows computed hold the same values as without ``rows``.
    """
    if rows is not None:
        rows = np.asarray(rows, bool)
        out = np.zeros((len(rows), 3), np.float32)  # calloc'd: untouched pages cost nothing
        idx = np.flatnonzero(rows)
        if len(idx):
            given = np.asarray(tri_tangent).reshape(-1, 3)
            out[idx] = triangle_tangents(np.asarray(tri_normal)[idx], given[idx] if len(given) == len(rows)
                                         else np.zeros((0, 3), np.float32))
        return out
    n = np.asarray(tri_normal, np.float64)
    t_count = len(n)
    given = np.asarray(tri_tangent, np.float64).reshape(-1, 3)
    if len(given) != t_count:
        given = np.zeros((t_count, 3))
    out = np.zeros((t_count, 3), np.float32)

    def project(c, nn):  # the candidate in the plane, normalised, where it is long enough
        proj = c - np.sum(c * nn, axis=1, keepdims=True) * nn
        norm = np.linalg.norm(proj, axis=1)
        ok = norm > 1e-6
        return ok, proj[ok] / norm[ok, None]

    # each candidate only on the rows still without a tangent, with the same per-row arithmetic
    # as over all rows (a zero given tangent projects to zero: those rows go straight to X)
    left = np.ones(t_count, bool)
    rows = np.flatnonzero(np.any(given != 0, axis=1))
    if len(rows):
        ok, unit = project(given[rows], n[rows])
        out[rows[ok]] = unit
        left[rows[ok]] = False
    todo = np.flatnonzero(left)
    for cand in (np.array([[1.0, 0, 0]]), np.array([[0.0, 1, 0]])):
        if len(todo) == 0:
            break
        ok, unit = project(np.broadcast_to(cand, (len(todo), 3)), n[todo])
        out[todo[ok]] = unit
        todo = todo[~ok]
    return out


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


def diffracted_radiance(g: PreparedGratings, mat: int, w_o, w_i, t, s, normal, period, edges_nm, rng,
                        renormalise: bool = True, exclude_zeroth: bool | None = None, footprint=None):
    """Radiance per unit irradiance (1/sr) towards w_o, per wavelength bin: (B, K).

    ``mat``: the material (one grating's parameters per call); w_o, w_i, t, s, normal: (B, 3);
    ``period``: (B,) nm (a per-triangle override, else the material's); the slit width keeps the
    material's ratio a / D. ``edges_nm``: (K + 1,) bin edges. ``renormalise``: the Harvey-Shack
    factor (per sample and bin; LINES: of the finite-N pattern, its propagating integral averaged
    over the bin, kernel.finite_propagating_power). ``exclude_zeroth``:
    leave the zeroth order out (None: as the material's layering says, ``g.zeroth_in_base``).
    ``footprint``: (du, dv), each (B,), the extent of each sample's pixel footprint in (u, v)
    (core/sampling/footprint.py), optionally with (su, sv), each (B,), the shift from the sample's (u, v)
    to the footprint's centre: the LINES pattern is then averaged over it as well
    (docs/physics.md section 3.7); None: at the point (u, v). The HEXAGONAL lattice ignores it.
    """
    if exclude_zeroth is None:
        exclude_zeroth = g.zeroth_in_base is not None and bool(g.zeroth_in_base[mat])
    d = np.asarray(period, np.float64)[:, None]
    ratio = g.slit_width[mat] / g.period[mat]
    a = d * ratio
    n = int(g.slit_count[mat])
    w_i = np.asarray(w_i, np.float64)
    h = np.asarray(w_o, np.float64) + w_i
    u = np.sum(h * t, axis=1)
    edges = np.asarray(edges_nm, np.float64)
    if not g.hexagonal[mat]:
        v = np.sum(h * s, axis=1)
        if footprint is not None and len(footprint) == 4:  # the footprint's centre (core/sampling/footprint.py)
            u, v = u + footprint[2], v + footprint[3]
        length = g.length[mat]
        # the bin mean of P / lambda^2 (lambda in nm), then the factor's lengths in metres
        if footprint is not None and (np.any(footprint[0]) or np.any(footprint[1])):
            p = fraunhofer_pattern_footprint(u, v, footprint[0], footprint[1], edges, a, d, n, length, lam_power=-2,
                                             exclude_zeroth=exclude_zeroth) / NM**2
        else:
            p = fraunhofer_pattern_binned(u, v, edges, a, d, n, length, lam_power=-2,
                                          exclude_zeroth=exclude_zeroth) / NM**2
        factor = (a * NM) ** 2 * (length * NM) * n / (d * NM)
        if renormalise:
            # K of the finite-N pattern averaged over each bin (kernel.finite_propagating_power), so
            # the bin's propagating integral is a/D exactly, near Rayleigh anomalies too
            centre = 0.5 * (edges[1:] + edges[:-1])[None, :]
            factor = factor * harvey_shack_factor(np.sum(w_i * t, axis=1)[:, None], np.sum(w_i * s, axis=1)[:, None],
                                                  centre, ratio, d, n=n, bin_width=np.diff(edges)[None, :])
        return (factor * p).astype(np.float32)
    # hexagonal lattice: one stratified random wavelength per bin and sample
    t2 = 0.5 * t + (np.sqrt(3) / 2) * np.cross(normal, t)
    u2 = np.sum(h * t2, axis=1)
    q = np.linalg.norm(h - np.sum(h * normal, axis=1, keepdims=True) * normal, axis=1)
    lam = edges[:-1][None, :] + (edges[1:] - edges[:-1])[None, :] * rng.random((len(u), len(edges) - 1))
    eta1, eta2 = np.pi * d * u[:, None] / lam, np.pi * d * u2[:, None] / lam
    p = _airy(np.pi * a * q[:, None] / lam) * multislit(eta1, n) * multislit(eta2, n)
    if exclude_zeroth:  # the (0, 0) order's cell of the reciprocal lattice
        p = np.where((np.round(eta1 / np.pi) == 0) & (np.round(eta2 / np.pi) == 0), 0.0, p)
    area = np.pi * (a * NM) ** 2 / 4
    cell = np.sqrt(3) / 2 * (d * NM) ** 2
    factor = area**2 * n * n / ((lam * NM) ** 2 * cell)
    if renormalise:
        factor = factor * hexagonal_harvey_shack_factor(np.sum(w_i * t, axis=1)[:, None],
                                                        np.sum(w_i * s, axis=1)[:, None], lam, ratio, d)
    return (factor * p).astype(np.float32)
