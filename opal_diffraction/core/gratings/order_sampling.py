"""Gratings in the light pass: sampling a diffraction order and its direction (docs/physics.md section 3.10).

Method. A plane wave of vacuum wavelength lambda meeting a grating of period D (slits of width
a along s, grating vector t, normal n) leaves in discrete orders m whose tangential direction
cosines obey the grating equation (Born & Wolf, *Principles of Optics*, section 8.6.1; Hecht,
*Optics*, section 10.2.8; in direction-cosine space as Harvey & Vernold's linear systems
formulation of scatter writes it):

    eta_o (w_o . t) = eta_i (d . t) + m lambda / D,     eta_o (w_o . s) = eta_i (d . s) + dv,

with d = -w_i the incoming travel direction, eta_i / eta_o the indices on the incident side and
the side the order leaves into (1 / 1 for a grating in air; into glass the zeroth order is then
exactly Snell's refraction, the first orders are the grating equation with refraction), and
w_o . n = +-sqrt(1 - (w_o . t)^2 - (w_o . s)^2): + for reflection, - for transmission. Only
orders with a real normal component propagate. The scalar Fraunhofer order efficiencies are
(docs/physics.md section 3.2; by Parseval they sum to a/D over all m)

    e_m = (a/D)^2 sinc^2(pi m a / D),

and the sampler draws m among the propagating orders with probability e_m / sum_prop e, with
weight sum_prop e: its expected power is the integrated power of section 3.2, with no 1/cos
theta_o. The light pass (``scatter_at_gratings``) multiplies it by the Harvey-Shack factor
K = (a/D) / sum_prop e of the incident direction (``renormalise``), as the eye pass renormalises
its radiance, so both passes deliver a/D (one order distribution, docs/physics.md section 3.10). The slit-length factor
sinc^2(pi L v / lambda) (section 3.1) spreads each order along s by dv = x lambda / L with x
drawn from sinc^2(pi x) (a tabulated inverse CDF over |x| <= SPREAD_LOBES, exact at the
table's nodes; the tail beyond holds 1 / (pi^2 SPREAD_LOBES) = 0.04 % of the power and is left
out); a spread that leaves the propagating disk ends the path (that power is evanescent). The
finite-N order width lambda / (N D) in u is not sampled: it is far below an illumination-map
element (N = 1000, D = 1.6 um: 3e-4 rad, 0.3 mm at 1 m).

``scatter_at_gratings`` is the light pass's layering (section 3.3): over a mirror base the
sampled order replaces the mirror bounce (the zeroth order is the specular direction); over a
diffuse base a path diffracts with probability a/D (the strip fraction, ``diffracting``) and
weight sum_prop e / (a/D), else it lands on the base as before; over glass the Fresnel
reflectance of the surface chooses reflection or transmission and the grating's type says
which of the two branches it diffracts (a transmission grating's orders replace the
refraction). White rays first become mono rays with the transport's SPLIT / SAMPLE machinery
(section 2.4), the wavelength then drawn uniformly inside the sample's bin so the orders do not
fall on a comb of 5 nm lines. HEXAGONAL lattices (two-dimensional orders) are not scattered:
they behave as their base material in the light pass.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kernel import sinc2_integral
from .radiance import grating_frame
from ..materials.spectra import DIELECTRIC, DIFFUSE, MIRROR
from ..spectral.optics import fresnel_dielectric, reflect, refract

__all__ = ["OrderSample", "order_efficiencies", "sample_orders", "sample_sinc2", "SPREAD_LOBES",
           "scattering_materials", "diffracting", "scatter_at_gratings"]

#: The slit-length spread is sampled over |x| <= SPREAD_LOBES lobes of sinc^2(pi x).
SPREAD_LOBES = 256
#: At most this many (ray, order) cells are held at once (rays are taken in chunks).
_CELLS = 1 << 21


def _spread_table():
    # nodes: 64 per lobe near the centre, geometric further out; CDF from the closed form
    # int_0^x sinc^2(pi t) dt = Si(2 pi x) / pi - sin^2(pi x) / (pi^2 x)
    inner = np.linspace(0.0, 16.0, 16 * 64 + 1)
    outer = np.geomspace(16.0, SPREAD_LOBES, 2049)[1:]
    x = np.concatenate([inner, outer])
    half = sinc2_integral(np.pi * x) / np.pi
    x = np.concatenate([-x[:0:-1], x])
    cdf = np.concatenate([-half[:0:-1], half])
    cdf = (cdf - cdf[0]) / (cdf[-1] - cdf[0])
    return x, cdf


_SPREAD_X, _SPREAD_CDF = _spread_table()


def sample_sinc2(u: np.ndarray) -> np.ndarray:
    """x with density proportional to sinc^2(pi x) on |x| <= SPREAD_LOBES, from uniforms u (B,)
    (inverse CDF, linear between the table's nodes)."""
    return np.interp(np.asarray(u, np.float64), _SPREAD_CDF, _SPREAD_X)


def order_efficiencies(m, a_over_d) -> np.ndarray:
    """e_m = (a/D)^2 sinc^2(pi m a/D) (docs/physics.md section 3.2); sum over all m = a/D."""
    r = np.asarray(a_over_d, np.float64)
    return r * r * np.sinc(np.asarray(m, np.float64) * r) ** 2  # np.sinc(x) = sin(pi x) / (pi x)


@dataclass(frozen=True)
class OrderSample:
    direction: np.ndarray    # (B, 3) float64 unit outgoing directions (zero where weight is 0)
    order: np.ndarray        # (B,) int64 sampled order m
    weight: np.ndarray       # (B,) float64 sum of the propagating orders' efficiencies, times K with renormalise (0: nothing leaves)
    total: np.ndarray        # (B,) float64 the same sum before the spread's evanescent part is cut


def sample_orders(w_i, n, t, s, period, slit_width, wavelength, transmission, rng, *, eta_i=1.0, eta_o=1.0,
                  length=None, exclude_zeroth: bool = False, renormalise: bool = False) -> OrderSample:
    """Sample an outgoing order of a LINES grating for B incoming directions.

    ``w_i`` (B, 3): unit directions from the surface towards where the light came from; ``n``
    (B, 3): unit normal on w_i's side; ``t``, ``s`` (B, 3): grating vector and slit direction in
    the surface; ``period``, ``slit_width``, ``wavelength`` (B,) nm (vacuum wavelength);
    ``transmission`` (B,) bool or scalar: the order leaves through the surface; ``eta_i``,
    ``eta_o``: (B,) or scalar indices of the incident side and of the side the order leaves into;
    ``length`` (B,) nm slit length for the sinc^2 spread along s (None or 0: no spread).
    m is drawn with probability e_m / sum_prop e over the orders with (w_o . t)^2 + (w_o . s)^2 < 1
    at the unspread v; the weight is sum_prop e (docs/physics.md section 3.10). ``exclude_zeroth``:
    m = 0 is neither drawn nor summed (a base whose specular lobe carries it, section 3.3).
    ``renormalise``: the weight times the Harvey-Shack factor of the incident direction,
    K = (a/D) / sum_prop e (the zeroth order included whatever ``exclude_zeroth`` says), so
    the orders carry a/D as in the eye pass (docs/physics.md sections 3.2, 3.10).
    """
    w_i = np.asarray(w_i, np.float64)
    b = len(w_i)
    n, t, s = (np.asarray(x, np.float64) for x in (n, t, s))
    d_nm = np.broadcast_to(np.asarray(period, np.float64), (b,))
    ratio = np.broadcast_to(np.asarray(slit_width, np.float64), (b,)) / d_nm
    lam = np.broadcast_to(np.asarray(wavelength, np.float64), (b,))
    ei = np.broadcast_to(np.asarray(eta_i, np.float64), (b,))
    eo = np.broadcast_to(np.asarray(eta_o, np.float64), (b,))
    trans = np.broadcast_to(np.asarray(transmission, bool), (b,))
    u_in = -np.einsum("ij,ij->i", w_i, t) * ei  # eta_i (d . t), d = -w_i
    v_in = -np.einsum("ij,ij->i", w_i, s) * ei
    v_c = v_in / eo
    r = np.sqrt(np.maximum(1.0 - v_c * v_c, 0.0)) * (1 - 1e-12)  # grazing exits excluded
    step = lam / d_nm  # u shift per order (in eta_o u_o)
    m_lo = np.ceil((-eo * r - u_in) / step).astype(np.int64)
    m_hi = np.floor((eo * r - u_in) / step).astype(np.int64)
    count = np.where(r > 0, np.maximum(m_hi - m_lo + 1, 0), 0)
    order = np.zeros(b, np.int64)
    total = np.zeros(b)
    with_zeroth = np.zeros(b)
    k_max = int(count.max()) if b else 0
    u_draw = rng.random(b)
    if k_max > 0:
        rows = max(1, _CELLS // k_max)
        for c0 in range(0, b, rows):  # chunks of rays (a handful), bounded memory
            sl = slice(c0, c0 + rows)
            m = m_lo[sl, None] + np.arange(k_max)[None, :]
            e = np.where(np.arange(k_max)[None, :] < count[sl, None], order_efficiencies(m, ratio[sl, None]), 0.0)
            with_zeroth[sl] = e.sum(axis=1)
            if exclude_zeroth:
                e = np.where(m == 0, 0.0, e)
            cdf = np.cumsum(e, axis=1)
            tot = cdf[:, -1]
            pick = np.minimum((cdf < (u_draw[sl] * tot)[:, None]).sum(axis=1), np.maximum(count[sl] - 1, 0))
            order[sl] = m_lo[sl] + pick
            total[sl] = tot
    uo = (u_in + order * step) / eo
    vo = v_c
    if length is not None:
        ln = np.broadcast_to(np.asarray(length, np.float64), (b,))
        spread = ln > 0
        if spread.any():
            dv = sample_sinc2(rng.random(b)) * lam / np.where(spread, ln, 1.0)
            vo = np.where(spread, (v_in + dv) / eo, v_c)
    nz2 = 1.0 - uo * uo - vo * vo
    ok = (total > 0) & (nz2 > 0)
    nz = np.sqrt(np.maximum(nz2, 0.0)) * np.where(trans, -1.0, 1.0)
    direction = uo[:, None] * t + vo[:, None] * s + nz[:, None] * n
    direction = np.where(ok[:, None], direction, 0.0)
    weight = total
    if renormalise:  # K = (a/D) / sum_prop e: the propagating orders carry a/D (section 3.2)
        weight = total * ratio / np.where(with_zeroth > 0, with_zeroth, np.inf)
    return OrderSample(direction, order, np.where(ok, weight, 0.0), total)


def _slit_ratio(g, mat):
    return g.slit_width[mat] / g.period[mat]


def scattering_materials(gratings, material_kind, microfacet=None) -> np.ndarray:
    """(M,) bool: the materials whose grating the light pass scatters (``diffracting``): LINES
    gratings over a smooth mirror or glass or a diffuse base (rough and layered mirrors and
    glass, ``microfacet`` (M,) and not DIFFUSE, are kind MICROFACET in the walk). The light
    pass aims at them; an eye pass that reads the caustic map must leave out its own
    diffuse -> grating -> light paths at them (docs/physics.md section 3.10)."""
    kind = np.asarray(material_kind)
    ok = np.asarray(gratings.enabled, bool) & ~np.asarray(gratings.hexagonal, bool)
    ok &= (kind == MIRROR) | (kind == DIELECTRIC) | (kind == DIFFUSE)
    if microfacet is not None:
        ok &= ~(np.asarray(microfacet, bool) & (kind != DIFFUSE))
    return ok


def diffracting(prepared, hit, kind: np.ndarray, rng) -> np.ndarray:
    """(B,) bool: the light paths at these hits that a grating diffracts (section 3.3): every
    path at a LINES grating over a smooth mirror or glass (the grating replaces that bounce),
    and the strip fraction a/D of those at a LINES grating over a diffuse base (the rest land
    on the base). Rough and layered bases (kind MICROFACET) and HEXAGONAL lattices: none."""
    g = prepared.gratings
    on = g.enabled[hit.mat] & ~g.hexagonal[hit.mat]
    on &= (kind == MIRROR) | (kind == DIELECTRIC) | (kind == DIFFUSE)
    if not on.any():
        return on
    strip = (kind == DIFFUSE) & on
    if strip.any():
        on &= ~strip | (rng.random(len(kind)) < _slit_ratio(g, hit.mat))
    return on


def scatter_at_gratings(prepared, rays, hit, rng, split_white):
    """Mono rays leaving the grating hits ``hit`` of ``rays`` (all of them diffract, see
    ``diffracting``): white rays are split first (``split_white(rays, hit, rng) -> (mono rays,
    their hits)``, the walker's SPLIT or SAMPLE: transport.SpecularWalker.split_white, section
    2.4), then each path takes one order (``sample_orders``), or the plain Fresnel branch of a
    glass base that the grating does not act on. Returns mono Rays (weight 0 paths dropped)."""
    if rays.lam is None:
        rays, hit = split_white(rays, hit, rng)
    b = len(rays)
    g, mats = prepared.gratings, prepared.materials
    kind = mats.kind[hit.mat]
    edges = prepared.grid.bin_edges
    lam_nm = edges[rays.lam] + rng.random(b) * (edges[rays.lam + 1] - edges[rays.lam])
    over = prepared.tri_period[hit.prim] if len(prepared.tri_period) else np.zeros(b, np.float32)
    period = np.where(over > 0, over, g.period[hit.mat]).astype(np.float64)
    slit = period * _slit_ratio(g, hit.mat)
    t, s = grating_frame(prepared.tri_grating_tangent[hit.prim].astype(np.float64), hit.ng.astype(np.float64),
                         g.cos_rot[hit.mat], g.sin_rot[hit.mat])
    w_i = -rays.d.astype(np.float64)
    trans_type = g.transmission[hit.mat]
    glass = kind == DIELECTRIC
    ior = mats.ior[hit.mat, rays.lam].astype(np.float64)
    eta_i = np.where(glass & ~hit.front, ior, 1.0)
    eta_t = np.where(glass & hit.front, ior, 1.0)
    # over glass, Fresnel (of the zeroth order, at the geometric normal) picks the branch
    fr = np.where(glass, fresnel_dielectric(np.abs(hit.cos_i.astype(np.float64)), eta_t / eta_i)[0], 0.0)
    reflected = glass & (rng.random(b) < fr)
    grating_acts = ~glass | (reflected != trans_type)
    transmits = np.where(glass, ~reflected, trans_type)
    eta_o = np.where(transmits, eta_t, eta_i)
    smp = sample_orders(w_i, hit.ng, t, s, period, slit, lam_nm, transmits, rng, eta_i=eta_i, eta_o=eta_o,
                        length=g.length[hit.mat], renormalise=True)
    factor = smp.weight / np.where(kind == DIFFUSE, _slit_ratio(g, hit.mat), 1.0)
    d = smp.direction
    plain = ~grating_acts  # the glass branch the grating does not act on: plain reflection / refraction
    if plain.any():
        dr = np.where(reflected[plain, None], reflect(rays.d[plain].astype(np.float64), hit.ng[plain]),
                      refract(rays.d[plain].astype(np.float64), hit.ng[plain], eta_i[plain] / eta_t[plain])[0])
        d = d.copy()
        d[plain] = dr
        factor = np.where(plain, 1.0, factor)
    tint = np.where((kind == DIFFUSE) | mats.clear[hit.mat], 1.0, mats.reflectance[hit.mat, rays.lam])
    w = (rays.w * factor * tint).astype(np.float32)
    keep = w > 0
    side = np.where(transmits, -1.0, 1.0)
    o = hit.p + (hit.eps * side)[:, None] * hit.ng
    out = rays.moved(o.astype(np.float32), d.astype(np.float32), w)
    return out.take(keep)
