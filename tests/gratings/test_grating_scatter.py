"""Gratings in the light pass (docs/physics.md section 3.10): core/gratings/order_sampling.py.

- The order sampler against the efficiencies: a chi-square over the order histogram per
  incidence angle, wavelength, period, slit ratio and side (reflection / transmission / into
  glass), the expected counts from the grating equation and (a/D)^2 sinc^2(pi m a/D) computed
  here independently (a loop over candidate orders with the sine condition), cells expecting
  < 5 pooled, the threshold Bonferroni-corrected (Mitsuba 3's chi2.py idea for discrete
  orders); every sample's direction satisfies the grating equation for its order and its
  weight is the sum of the propagating efficiencies (docs/physics.md section 3.2's power).
- The slit-length spread against sinc^2(pi x) integrated over each cell by quadrature, alone
  and through the order sampler (with the paths a spread past grazing ends).
- A transmission grating (600 lines/mm, a = D/2) under a sun, a white screen 1 m behind: the
  caustic map's flux centroid per wavelength and order sits at tan(asin(sin theta_i + m lambda/D))
  within one element, at normal and 45 degrees incidence; the flux of orders +-1 over order 0
  is sinc^2(pi a/D) (Z-test with the compound-Poisson variance of the deposits, and within 3 %);
  the zeroth order's absolute flux is E A cos theta_i (a/D)^2 K (Z-test; K the Harvey-Shack factor,
  counted here by brute force). Rendered (spectral
  image of an orthographic camera): the first order's centroid per wavelength within a pixel.
- Layering: a reflection grating over a mirror and over a diffuse base throws E A cos theta (a/D)^2
  sinc^2(pi m a/D) on a wall (a = D: the mirror); over glass, Fresnel and the orders replacing
  the refraction (an independent Fresnel and the internal-reflection series); SPLIT agrees.
"""

from __future__ import annotations

import zlib

import numpy as np
import pytest
from scipy import integrate
from scipy.stats import norm

from chi2 import pearson
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.gratings.order_sampling import SPREAD_LOBES, sample_orders, sample_sinc2
from opal_diffraction.core.integrators.light.light_pass import LightWork, DepositLog
from opal_diffraction.core.integrators.light.walker import trace_batch
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings

# (theta_i deg, lambda nm, D nm, a/D, side): side 'R' reflection, 'T' transmission, 'G' into glass n = 1.5
CASES = [(th, lam, d, r, side) for th in (0.0, 30.0, 60.0) for lam in (450.0, 650.0)
         for d, r in ((1600.0, 0.5), (740.0, 0.3), (5000.0, 0.4)) for side in ("R", "T", "G")]
IDS = [f"th{c[0]:.0f}-lam{c[1]:.0f}-D{c[2]:.0f}-r{c[3]}-{c[4]}" for c in CASES]
SIGNIFICANCE = 0.01 / len(CASES)
N_SAMPLES = 40_000


def frame_at(theta_deg, phi_deg=20.0):
    """A tilted grating frame (n, t, s) and an incoming direction w_i at theta from n, its plane
    at phi from t (so the slit direction sees a nonzero v too)."""
    n = np.array([0.2, -0.3, 0.93])
    n /= np.linalg.norm(n)
    t = np.cross(n, [0.0, 0.0, 1.0]) + np.array([0.1, 0.2, 0.0])
    t -= (t @ n) * n
    t /= np.linalg.norm(t)
    s = np.cross(n, t)
    th, ph = np.radians(theta_deg), np.radians(phi_deg)
    w_i = np.cos(th) * n + np.sin(th) * (np.cos(ph) * t + np.sin(ph) * s)
    return n, t, s, w_i


def expected_orders(w_i, n, t, s, lam, d, ratio, eta_i, eta_o):
    """{m: efficiency} of the propagating orders, by brute force over candidate m."""
    ut, vs = -(w_i @ t) * eta_i, -(w_i @ s) * eta_i
    out = {}
    for m in range(-400, 401):
        uo, vo = (ut + m * lam / d) / eta_o, vs / eta_o
        if uo * uo + vo * vo < 1:
            x = np.pi * m * ratio
            out[m] = ratio**2 * (1.0 if m == 0 else (np.sin(x) / x) ** 2)
    return out


def harvey_shack_per_bin(edges, u_in, ratio, eta_o=1.0, sub=11):
    """(K,) the Harvey-Shack factor K = (a/D) / sum_prop e averaged over each wavelength bin (the
    light pass draws the wavelength uniformly inside it), the propagating orders counted here
    by brute force with the sine condition |u_in + m lambda / D| < eta_o (normal along s)."""
    edges = np.asarray(edges, np.float64)
    lam = edges[:-1, None] + (edges[1:] - edges[:-1])[:, None] * (np.arange(sub) + 0.5)[None, :] / sub
    m = np.arange(-400, 401)[None, None, :]
    e = ratio**2 * np.sinc(m * ratio) ** 2
    prop = np.abs(u_in + m * lam[:, :, None] / PERIOD) < eta_o
    return (ratio / np.sum(np.where(prop, e, 0.0), axis=2)).mean(axis=1)


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_order_sampler_chi2(case):
    th, lam, d, ratio, side = case
    n, t, s, w_i = frame_at(th)
    eta_i, eta_o = (1.0, 1.5) if side == "G" else (1.0, 1.0)
    trans = side != "R"
    rng = np.random.default_rng(zlib.crc32(repr(case).encode()))
    b = N_SAMPLES
    rep = lambda x: np.tile(x, (b, 1))  # noqa: E731
    smp = sample_orders(rep(w_i), rep(n), rep(t), rep(s), np.full(b, d), np.full(b, d * ratio), np.full(b, lam),
                        trans, rng, eta_i=eta_i, eta_o=eta_o)
    eff = expected_orders(w_i, n, t, s, lam, d, ratio, eta_i, eta_o)
    total = sum(eff.values())
    assert np.allclose(smp.weight, total, rtol=1e-9)
    # every sample's direction: unit, tangential cosines from the grating equation, right side
    m = smp.order
    assert set(np.unique(m)) <= set(eff)
    u_exp = (-(w_i @ t) * eta_i + m * lam / d) / eta_o
    assert np.allclose(smp.direction @ t, u_exp, atol=1e-9)
    assert np.allclose(smp.direction @ s, -(w_i @ s) * eta_i / eta_o, atol=1e-9)
    assert np.allclose(np.linalg.norm(smp.direction, axis=1), 1.0, atol=1e-9)
    assert ((smp.direction @ n < 0) == trans).all()
    if not trans:  # the zeroth reflected order is the mirror direction
        zero = m == 0
        assert np.allclose(smp.direction[zero], 2 * (w_i @ n) * n - w_i, atol=1e-9)
    if side == "G":  # the zeroth transmitted order into glass is Snell's refraction
        zero = m == 0
        cos_t = np.sqrt(1 - (1 - (w_i @ n) ** 2) / 1.5**2)
        snell = -w_i / 1.5 + ((w_i @ n) / 1.5 - cos_t) * n
        assert np.allclose(smp.direction[zero], snell, atol=1e-9)
    assert_orders_chi2(m, eff, case)


def assert_orders_chi2(m, eff, case):
    """The sampled orders ``m`` against probabilities eff[k] / sum(eff) (cells with expected < 5
    pooled), at the family-wise SIGNIFICANCE."""
    b, total = len(m), sum(eff.values())
    orders = sorted(eff)
    expected = np.array([b * eff[k] / total for k in orders])
    observed = np.array([(m == k).sum() for k in orders], np.float64)
    pval, info = pearson(observed, expected)
    print(f"{case}: {len(orders)} orders, total {total:.4f}, {info}")
    assert pval > SIGNIFICANCE, info


@pytest.mark.parametrize("case", [(0.0, 450.0, 1600.0, 0.5, "R"), (30.0, 650.0, 1600.0, 0.3, "R"),
                                  (60.0, 450.0, 740.0, 0.5, "R")], ids=str)
def test_order_sampler_without_the_zeroth_order_chi2(case):
    """``exclude_zeroth`` (a mirror base carrying m = 0, docs/physics.md section 3.11): m = 0 is
    never drawn, the others in proportion to e_m, and the weight is the propagating sum less e_0."""
    th, lam, d, ratio, side = case
    n, t, s, w_i = frame_at(th)
    rng = np.random.default_rng(zlib.crc32(repr(case).encode()))
    b = N_SAMPLES
    rep = lambda x: np.tile(x, (b, 1))  # noqa: E731
    smp = sample_orders(rep(w_i), rep(n), rep(t), rep(s), np.full(b, d), np.full(b, d * ratio), np.full(b, lam),
                        False, rng, exclude_zeroth=True)
    eff = expected_orders(w_i, n, t, s, lam, d, ratio, 1.0, 1.0)
    eff.pop(0)
    assert len(eff) >= 2 and not np.any(smp.order == 0)
    assert np.allclose(smp.weight, sum(eff.values()), rtol=1e-9)
    assert_orders_chi2(smp.order, eff, case)


def test_power_table_of_section_3_2():
    """docs/physics.md section 3.2's table (D = 1600 nm, a = 800 nm, lambda = 550 nm, in air):
    the sampler's weight is the integrated power 0.4526, 0.4639, 0.3666 at 0, 30, 60 degrees."""
    rng = np.random.default_rng(1)
    for th, power in ((0.0, 0.4526), (30.0, 0.4639), (60.0, 0.3666)):
        n, t, s, _ = frame_at(0.0)
        w_i = np.cos(np.radians(th)) * n + np.sin(np.radians(th)) * t  # incidence plane across the slits
        smp = sample_orders(w_i[None], n[None], t[None], s[None], 1600.0, 800.0, 550.0, False, rng)
        assert abs(smp.weight[0] - power) < 6e-5, (th, smp.weight[0])


def test_slit_length_spread_chi2():
    """x from sample_sinc2 against the density sinc^2(pi x) / int sinc^2 over |x| <= SPREAD_LOBES,
    each cell's probability by adaptive quadrature."""
    rng = np.random.default_rng(7)
    b = 400_000
    x = sample_sinc2(rng.random(b))
    assert np.abs(x).max() <= SPREAD_LOBES
    f = lambda y: np.sinc(y) ** 2  # noqa: E731
    norm_total = 2 * sum(integrate.quad(f, k, k + 1, limit=200)[0] for k in range(SPREAD_LOBES))
    edges = np.concatenate([[-SPREAD_LOBES], np.arange(-6.0, 6.0 + 1e-9, 0.25), [SPREAD_LOBES]])
    prob = np.array([sum(integrate.quad(f, lo, hi, limit=400, points=None)[0]
                         for lo, hi in _pieces(a0, a1)) for a0, a1 in zip(edges[:-1], edges[1:])]) / norm_total
    observed = np.histogram(x, edges)[0].astype(np.float64)
    expected = prob * b
    assert abs(prob.sum() - 1) < 1e-6
    pval, info = pearson(observed, expected)
    print(f"sinc^2 spread: {info}")
    assert pval > 0.01, info


def test_orders_spread_along_the_slits_chi2():
    """sample_orders with a slit length L: each order's direction cosine along s is the
    incoming one plus x lambda / L (over eta_o), x distributed as sinc^2(pi x), and a spread past
    grazing ends the path (weight 0). Per order m = -1, 0, 1: the histogram of x recovered from
    the sampled directions, plus one cell for the ended paths, against sinc^2 integrated over
    each cell by quadrature (the propagating interval of x computed here from the grating
    equation). L = 20 um, lambda = 550 nm: lambda / L = 0.0275."""
    rng = np.random.default_rng(11)
    b = 200_000
    n, t, s, w_i = frame_at(20.0)
    rep = lambda x: np.tile(x, (b, 1))  # noqa: E731
    lam, length = 550.0, 20_000.0
    smp = sample_orders(rep(w_i), rep(n), rep(t), rep(s), PERIOD, PERIOD / 2, lam, True, rng, length=length)
    f = lambda y: np.sinc(y) ** 2  # noqa: E731
    total = 2 * sum(integrate.quad(f, k, k + 1, limit=200)[0] for k in range(SPREAD_LOBES))

    def cell(a0, a1):
        return sum(integrate.quad(f, lo, hi, limit=400)[0] for lo, hi in _pieces(a0, a1)) / total

    v_in = -(w_i @ s)
    for m in (-1, 0, 1):
        mine = smp.order == m
        u_o = -(w_i @ t) + m * lam / PERIOD
        r = np.sqrt(1 - u_o**2)
        x_lo, x_hi = (-r - v_in) * length / lam, (r - v_in) * length / lam
        edges = np.concatenate([[x_lo], np.arange(-4.0, 4.0 + 1e-9, 0.5), [x_hi]])
        prob = np.array([cell(a0, a1) for a0, a1 in zip(edges[:-1], edges[1:])])
        prob = np.append(prob, 1 - prob.sum())  # the ended paths
        ok = mine & (smp.weight > 0)
        x = (smp.direction[ok] @ s - v_in) * length / lam
        observed = np.append(np.histogram(x, edges)[0], (mine & (smp.weight == 0)).sum()).astype(np.float64)
        assert observed[:-1].sum() == ok.sum()  # every survivor inside the propagating interval
        expected = prob * mine.sum()
        pval, info = pearson(observed, expected)
        print(f"order {m} spread: x in [{x_lo:.1f}, {x_hi:.1f}], ended {observed[-1]:.0f} vs {expected[-1]:.1f}, {info}")
        assert pval > 0.01 / 3, info


def _pieces(a0, a1):
    """[a0, a1] cut at the integers (quadrature over one lobe at a time)."""
    cuts = np.concatenate([[a0], np.arange(np.ceil(a0), np.floor(a1) + 1), [a1]])
    cuts = np.unique(cuts)
    return list(zip(cuts[:-1], cuts[1:]))


# ------------------------------------------------------------------ a spectrum on a screen
PERIOD = 1e6 / 600.0  # 600 lines/mm
APERTURE = 0.01       # grating edge (m)
SCREEN_Z = -1.0
SCREEN_X = (-1.6, 3.2)  # the screen's extent along x (m)
ELEMENT = 0.001


def strip(x0, x1, z, height):
    """A strip of square quads (height x height) from x0 to x1 at depth z, normal +z: square
    triangles, so the map's elements are about square too."""
    n = int(round((x1 - x0) / height))
    xs = np.linspace(x0, x1, n + 1)
    top, bottom = np.stack([xs, np.full_like(xs, height / 2), np.full_like(xs, z)], 1), \
        np.stack([xs, np.full_like(xs, -height / 2), np.full_like(xs, z)], 1)
    v = np.concatenate([bottom, top])
    i = np.arange(n)
    tris = np.concatenate([np.stack([i, i + 1, n + 2 + i], 1), np.stack([i, n + 2 + i, n + 1 + i], 1)])
    return v, tris.astype(np.int32)


def screen_scene(theta_deg: float, ratio: float = 0.5, screen_x=SCREEN_X) -> Scene:
    """A 1 cm transmission grating (black diffuse base, a/D = ratio) in the z = 0 plane under a
    sun at theta_deg in the xz plane, a white screen 1 m behind it (z = -1), 2 cm tall."""
    mats = Materials.from_list([
        {"name": "grating", "kind": "DIFFUSE", "color": (0, 0, 0), "grating": 1, "grating_type": "TRANSMISSION",
         "period": PERIOD, "slit_width": PERIOD * ratio, "slit_count": 6000, "coherence_length": 10000.0},
        {"name": "screen", "kind": "DIFFUSE", "color": (0.8, 0.8, 0.8)}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (APERTURE, 0, 0), (0, APERTURE, 0)), material=0, tangent=(1, 0, 0))
    s.add_mesh(*strip(screen_x[0], screen_x[1], SCREEN_Z, 0.02), material=1)
    th = np.radians(theta_deg)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": (np.sin(th), 0, -np.cos(th)), "power": 1.0}])
    s.camera = Camera.look_at((0, -1, 0.5), (0, 0, -1), width=8, height=8)
    return s


def scene_deposits(scene, paths, seed=0, **settings):
    """Every caustic deposit of the light pass over ``scene``: (element centre (B, 3), flux,
    wavelength index), the prepared scene."""
    p = prepare(scene, RenderSettings(light_paths=paths, element_size=ELEMENT, seed=seed, **settings))
    work = LightWork.of(p)
    log = DepositLog(work.layout)
    for job in work.batches:
        trace_batch(p, job, log, None)
    tri, bu, bv = work.layout.barycentric_centres()
    v, t = p.scene.vertices.astype(np.float64), p.scene.triangles
    centre = (1 - bu - bv)[:, None] * v[t[tri, 0]] + bu[:, None] * v[t[tri, 1]] + bv[:, None] * v[t[tri, 2]]
    el = np.concatenate([c[0] for c in log.calls])
    flux = np.concatenate([c[1] for c in log.calls]).astype(np.float64)
    lam = np.concatenate([c[2] for c in log.calls])
    return centre[el], flux, lam, p


def deposits(theta_deg, paths, ratio=0.5, seed=0):
    """The screen scene's deposits: (x of the element centre, flux, wavelength index), the prepared scene."""
    pos, flux, lam, p = scene_deposits(screen_scene(theta_deg, ratio), paths, seed)
    return pos[:, 0], flux, lam, p


def order_x(theta_deg, m, lam_nm):
    """Where order m lands on the screen: x = |z| tan(asin(sin theta_i + m lambda / D)), nan if evanescent."""
    sn = np.sin(np.radians(theta_deg)) + m * np.asarray(lam_nm, np.float64) / PERIOD
    with np.errstate(invalid="ignore"):
        return np.where(np.abs(sn) < 1, -SCREEN_Z * np.tan(np.arcsin(sn)), np.nan)


@pytest.fixture(scope="module", params=[0.0, 45.0], ids=["normal", "45deg"])
def screen(request):
    th = request.param
    return th, deposits(th, 600_000)


def _order_masks(th, x, lam, grid):
    """Per order m (-2..2): the deposits within one aperture of the order's band on the screen, and
    which wavelength bins the order reaches in full (the whole bin propagating and on the screen)."""
    edges = grid.bin_edges
    out = {}
    on = lambda xs: np.isfinite(xs) & (xs > SCREEN_X[0] + 0.03) & (xs < SCREEN_X[1] - 0.03)  # noqa: E731
    for m in range(-2, 3):
        with np.errstate(invalid="ignore"):
            x_lo, x_hi = order_x(th, m, edges[:-1]), order_x(th, m, edges[1:])
            full = on(x_lo) & on(x_hi)
        if not full.any():
            continue
        ends = np.concatenate([x_lo[full], x_hi[full]])
        band_lo, band_hi = ends.min() - APERTURE, ends.max() + APERTURE
        sel = (x > band_lo) & (x < band_hi) & full[lam]
        out[m] = (sel, full)
    return out


def test_projected_spectrum_positions(screen):
    """The flux centroid per wavelength bin of each order on the screen vs the grating equation
    (averaged over the bin, as the light pass draws the wavelength uniformly inside it): within
    one element (1 mm) plus four standard deviations of the centroid's Monte Carlo error (which
    matters only where an order is near grazing and a 5 nm bin smears over centimetres), and a
    median error below half an element; the first orders are 0.25 - 3 m from the zeroth."""
    th, (x, flux, lam, p) = screen
    grid = p.grid
    errors = []
    for m, (sel, full) in _order_masks(th, x, lam, grid).items():
        if m == 0 or abs(m) == 2:  # zeroth: every bin at one place; +-2: no flux at a = D/2
            continue
        f_bin = np.bincount(lam[sel], flux[sel], minlength=grid.n)
        c_bin = np.bincount(lam[sel], flux[sel] * x[sel], minlength=grid.n)
        for k in np.flatnonzero(full & (f_bin > 0)):  # loop over wavelength bins (61)
            lo, hi = grid.bin_edges[k], grid.bin_edges[k + 1]
            expect = np.mean(order_x(th, m, np.linspace(lo, hi, 201)))  # the bin's mean position
            mean = c_bin[k] / f_bin[k]
            mine = sel & (lam == k)
            # the centroid's Monte Carlo error (compound Poisson, delta method)
            noise = np.sqrt(np.sum(flux[mine] ** 2 * (x[mine] - mean) ** 2)) / f_bin[k]
            err = abs(mean - expect)
            errors.append(err)
            assert err <= ELEMENT + 4 * noise, (m, grid.wavelengths[k], err, noise)
    # the zeroth order: straight through, at tan(theta_i)
    sel0 = _order_masks(th, x, lam, grid)[0][0]
    c0 = np.sum(flux[sel0] * x[sel0]) / np.sum(flux[sel0])
    assert abs(c0 - order_x(th, 0, 550.0)) <= ELEMENT
    print(f"theta {th}: {len(errors)} (order, bin) centroids, median error {np.median(errors) * 1e3:.3f} mm, "
          f"worst {max(errors) * 1e3:.3f} mm; zeroth {abs(c0 - order_x(th, 0, 550.0)) * 1e3:.3f} mm")
    assert len(errors) >= 61 * (2 if th == 0 else 1)
    assert np.median(errors) < ELEMENT / 2


def test_order_flux_ratios(screen):
    """Flux of order +-1 over order 0, over the wavelength bins both reach in full: sinc^2(pi a/D)
    = 0.4053 (a = D/2), Z-test (compound-Poisson variance: sum of squared deposits) and within
    3 %; order +-2 carries nothing (sinc^2(pi) = 0); the zeroth order's absolute flux is
    E A cos theta_i (a/D)^2 K per wavelength sample (E the sun's spectrum, K Harvey-Shack's factor)."""
    th, (x, flux, lam, p) = screen
    grid = p.grid
    masks = _order_masks(th, x, lam, grid)
    sel0 = masks[0][0]
    want = np.sinc(0.5) ** 2  # (sin(pi/2) / (pi/2))^2, numpy's normalised sinc
    checked_3pc = []
    for m in (-1, 1):
        if m not in masks:
            continue
        sel, full = masks[m]
        both = full[lam]
        f1, f0 = flux[sel & both].sum(), flux[sel0 & both].sum()
        v1, v0 = np.sum(flux[sel & both] ** 2), np.sum(flux[sel0 & both] ** 2)
        ratio = f1 / f0
        sigma = ratio * np.sqrt(v1 / f1**2 + v0 / f0**2)
        z = (ratio - want) / sigma
        print(f"theta {th} m {m}: ratio {ratio:.4f} +- {sigma:.4f} (sinc^2 {want:.4f}, z {z:.2f}, "
              f"{full.sum()} bins)")
        assert abs(z) < norm.isf(0.001 / 8), z
        if sigma < 0.01 * want:  # (at 45 degrees order +1 reaches the screen in one or two bins only)
            assert abs(ratio / want - 1) < 0.03
            checked_3pc.append(m)
    assert checked_3pc
    for m in (-2, 2):
        if m in masks:
            sel, _ = masks[m]
            # the +-2 band may hold the +-3 order's blue end; at a = D/2 the +-2 order itself is empty
            x2 = order_x(th, m, grid.wavelengths)
            x3 = order_x(th, 3 * np.sign(m), grid.wavelengths)
            own = sel & ~((x > np.nanmin(x3) - 0.02) & (x < np.nanmax(x3) + 0.02)) if np.isfinite(x3).any() else sel
            assert flux[own].sum() < 1e-3 * flux[sel0].sum(), (m, np.nanmin(x2))
    # absolute zeroth order: flux per wavelength sample = E_k A cos theta (a/D)^2 K_k (Harvey-Shack)
    e = p.lights.spectrum[0].astype(np.float64) * harvey_shack_per_bin(grid.bin_edges, np.sin(np.radians(th)), 0.5)
    f0 = flux[sel0].sum()
    expect = e.sum() * APERTURE**2 * np.cos(np.radians(th)) * 0.25
    sigma = np.sqrt(np.sum(flux[sel0] ** 2))
    z = (f0 - expect) / sigma
    print(f"theta {th}: zeroth order {f0:.4e} W vs {expect:.4e} (z {z:.2f})")
    assert abs(z) < norm.isf(0.001 / 8)


# ------------------------------------------------------------------ layering on mirror and glass
def vertical_strip(x, z0, z1, height):
    """A strip of square quads in the plane x = const, from z0 to z1, ``height`` wide in y."""
    n = int(round((z1 - z0) / height))
    zs = np.linspace(z0, z1, n + 1)
    v = np.concatenate([np.stack([np.full_like(zs, x), np.full_like(zs, -height / 2), zs], 1),
                        np.stack([np.full_like(zs, x), np.full_like(zs, height / 2), zs], 1)])
    i = np.arange(n)
    tris = np.concatenate([np.stack([i, n + 2 + i, i + 1], 1), np.stack([i, n + 1 + i, n + 2 + i], 1)])
    return v, tris.astype(np.int32)


def _z_test(measured, sigma, expected, what):
    z = (measured - expected) / sigma
    print(f"{what}: {measured:.5e} vs {expected:.5e} (z {z:.2f}, {sigma / expected:.2%})")
    assert abs(z) < norm.isf(0.001 / 12), (what, z)


@pytest.mark.parametrize("base", ["MIRROR", "DIFFUSE"])
@pytest.mark.parametrize("ratio", [0.5, 1.0])
def test_reflection_grating_on_a_wall(ratio, base):
    """A reflection grating under a sun at 30 degrees throws its orders on a vertical white wall
    at x = 1 m. Over a mirror base every path diffracts (the order replaces the mirror bounce,
    weight sum_prop e); over a (black) diffuse base, the CD's case, the strip fraction a/D does
    (weight sum_prop e / (a/D)). Either way the zeroth order's flux is E A cos theta (a/D)^2
    (x the mirror's reflectance) at z = cot(theta_r), and order +1's is that x sinc^2(pi a/D).
    In the mirror limit a = D the grating is the mirror: all the reflected power is specular."""
    th = 30.0
    mats = Materials.from_list([
        {"name": "grating", "kind": base, "color": (1, 1, 1) if base == "MIRROR" else (0, 0, 0), "grating": 1,
         "grating_type": "REFLECTION", "period": PERIOD, "slit_width": PERIOD * ratio, "slit_count": 6000,
         "coherence_length": 10000.0},
        {"name": "screen", "kind": "DIFFUSE", "color": (0.8, 0.8, 0.8)}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (APERTURE, 0, 0), (0, APERTURE, 0)), material=0, tangent=(1, 0, 0))
    s.add_mesh(*vertical_strip(1.0, 0.02, 2.4, 0.02), material=1)
    t = np.radians(th)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": (np.sin(t), 0, -np.cos(t)), "power": 1.0}])
    s.camera = Camera.look_at((0, -1, 0.5), (0, 0, 0), width=8, height=8)
    pos, flux, lam, p = scene_deposits(s, 400_000)
    z = pos[:, 2]
    tint = p.materials.reflectance[0] if base == "MIRROR" else 1.0
    e_inc = p.lights.spectrum[0].astype(np.float64) * APERTURE**2 * np.cos(t) * tint
    e_inc = e_inc * harvey_shack_per_bin(p.grid.bin_edges, np.sin(t), ratio)  # the orders carry a/D

    def z_of(m, lam_nm):
        u = np.sin(t) + m * np.asarray(lam_nm, np.float64) / PERIOD
        with np.errstate(invalid="ignore"):
            return np.where((u > 0) & (u < 1), np.sqrt(1 - u * u) / np.maximum(u, 1e-12), np.nan)

    z0 = float(z_of(0, 550.0))
    sel0 = np.abs(z - z0) < 0.03
    _z_test(flux[sel0].sum(), np.sqrt(np.sum(flux[sel0] ** 2)), e_inc.sum() * ratio**2, f"{base} a/D {ratio} zeroth")
    c0 = np.sum(flux[sel0] * z[sel0]) / flux[sel0].sum()
    assert abs(c0 - z0) < ELEMENT, (c0, z0)
    edges = p.grid.bin_edges
    lo, hi = z_of(1, edges[1:]), z_of(1, edges[:-1])  # +1 lands lower for longer wavelengths
    full = np.isfinite(lo) & np.isfinite(hi) & (lo > 0.05)
    sel1 = (z > np.nanmin(lo[full]) - 0.02) & (z < np.nanmax(hi[full]) + 0.02) & full[lam]
    e1 = ratio**2 * np.sinc(ratio) ** 2
    if ratio < 1:
        _z_test(flux[sel1].sum(), np.sqrt(np.sum(flux[sel1] ** 2)), e_inc[full].sum() * e1,
                f"{base} a/D {ratio} order +1")
    else:  # the mirror limit: nothing but the specular direction
        assert flux.sum() == pytest.approx(flux[sel0].sum(), rel=1e-12)


def glass_slab_scene() -> Scene:
    """A 2 x 2 cm glass slab (n = 1.5, 2 mm thick) whose top face is a transmission grating
    (600 lines/mm, a = D/2), under a sun at normal incidence through a 1 cm aperture in a black
    card 1 mm above; the white screen 1 m below the slab."""
    mats = Materials.from_list([
        {"name": "grating glass", "kind": "DIELECTRIC", "ior": 1.5, "color": (1, 1, 1), "grating": 1,
         "grating_type": "TRANSMISSION", "period": PERIOD, "slit_width": PERIOD / 2, "slit_count": 6000,
         "coherence_length": 10000.0},
        {"name": "glass", "kind": "DIELECTRIC", "ior": 1.5, "color": (1, 1, 1)},
        {"name": "screen", "kind": "DIFFUSE", "color": (0.8, 0.8, 0.8)},
        {"name": "card", "kind": "DIFFUSE", "color": (0, 0, 0)}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.box((0, 0, -0.001), (0.02, 0.02, 0.002)), material=1, tangent=(1, 0, 0))
    s.tri_material[[1, 7]] = 0  # the box's +z face (its quads' triangles 1 and 7) is the grating
    h, outer, zc = APERTURE / 2, 0.2, 0.001
    for centre, u, v in (((0, (outer + h) / 2, zc), (2 * outer, 0, 0), (0, outer - h, 0)),
                         ((0, -(outer + h) / 2, zc), (2 * outer, 0, 0), (0, outer - h, 0)),
                         (((outer + h) / 2, 0, zc), (outer - h, 0, 0), (0, 2 * h, 0)),
                         ((-(outer + h) / 2, 0, zc), (outer - h, 0, 0), (0, 2 * h, 0))):
        s.add_mesh(*primitives.quad(centre, u, v), material=3)
    s.add_mesh(*strip(-0.8, 0.8, SCREEN_Z - 0.002, 0.02), material=2)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": (0, 0, -1.0), "power": 1.0}])
    s.camera = Camera.look_at((0, -1, 0.5), (0, 0, -1), width=8, height=8)
    return s


def _fresnel(cos_i, n_i, n_t):
    """Unpolarised Fresnel reflectance from the s and p amplitudes (Hecht section 4.6.2)."""
    sin_t = n_i / n_t * np.sqrt(1 - cos_i**2)
    cos_t = np.sqrt(1 - sin_t**2)
    rs = (n_i * cos_i - n_t * cos_t) / (n_i * cos_i + n_t * cos_t)
    rp = (n_t * cos_i - n_i * cos_t) / (n_t * cos_i + n_i * cos_t)
    return 0.5 * (rs**2 + rp**2)


def test_glass_base_orders_replace_the_refraction():
    """Over glass, Fresnel picks reflection or transmission and the transmission grating's orders
    replace the refraction (the zeroth order is Snell's): order m leaves the slab at sin theta =
    m lambda / D (the slab keeps the tangential momentum) with flux
    E A (1 - F_0) e_m / (1 + F_m), F_m the glass-air reflectance at sin theta_g = m lambda / (n D)
    (the geometric series of internal reflections, (1 - F) / (1 - F^2)); Z-tests per order."""
    s = glass_slab_scene()
    pos, flux, lam, p = scene_deposits(s, 600_000)
    assert p.materials.clear[[0, 1]].all() and p.materials.ior[0].min() == p.materials.ior[0].max() == 1.5
    x = pos[:, 0]
    on_screen = pos[:, 2] < SCREEN_Z
    edges = p.grid.bin_edges
    # the orders into the glass (|m lambda / D| < 1.5) carry a/D: Harvey-Shack
    e_sun = p.lights.spectrum[0].astype(np.float64) * APERTURE**2 * harvey_shack_per_bin(edges, 0.0, 0.5, eta_o=1.5)
    f0 = _fresnel(1.0, 1.0, 1.5)
    for m in (-1, 0, 1):
        lam_fine = edges[:-1, None] + (edges[1:] - edges[:-1])[:, None] * (np.arange(11) + 0.5)[None, :] / 11
        sin_g = m * lam_fine / (1.5 * PERIOD)
        fm = _fresnel(np.sqrt(1 - sin_g**2), 1.5, 1.0).mean(axis=1)  # the bin's mean
        want = np.sum(e_sun * (1 - f0) * 0.25 * np.sinc(m * 0.5) ** 2 / (1 + fm))
        xm = (SCREEN_Z - 0.001) * -np.tan(np.arcsin(m * lam_fine / PERIOD))
        sel = on_screen & (x > xm.min() - APERTURE) & (x < xm.max() + APERTURE)
        _z_test(flux[sel].sum(), np.sqrt(np.sum(flux[sel] ** 2)), want, f"glass order {m}")


def test_split_dispersion_sampling_at_gratings():
    """With SPLIT (one mono path per wavelength sample, section 2.4) instead of SAMPLE, the
    screen's zeroth and first orders carry the same expected flux: E A (a/D)^2 and that x
    sinc^2(pi/2) (normal incidence; Z-tests)."""
    pos, flux, lam, p = scene_deposits(screen_scene(0.0), 20_000, dispersion_sampling="SPLIT")
    x = pos[:, 0]
    e = np.sum(p.lights.spectrum[0].astype(np.float64) * harvey_shack_per_bin(p.grid.bin_edges, 0.0, 0.5)) * APERTURE**2
    # the 61 children of one path share its start: the number of paths that reach the grating
    # (sun paths start on the caster's bounding disk, docs/physics.md section 4.1) is binomial,
    # a noise common to all children that the sum of squared deposits does not hold
    p_hit = APERTURE**2 / (np.pi * float(p.light_targets.objects.radius[0]) ** 2)
    rel_hit = np.sqrt((1 - p_hit) / (20_000 * p_hit))
    for m, (sel, full) in _order_masks(0.0, x, lam, p.grid).items():
        if abs(m) < 2:
            want = e * 0.25 * np.sinc(m * 0.5) ** 2
            got = flux[sel].sum()
            _z_test(got, np.sqrt(np.sum(flux[sel] ** 2) + (got * rel_hit) ** 2), want, f"SPLIT order {m}")


def test_a_line_grating_alone_runs_the_light_pass():
    """Line gratings are light-pass casters (paths are aimed at them) and a scene whose only
    caster is a grating runs the light pass; a HEXAGONAL grating is not scattered, so not aimed at."""
    from opal_diffraction.core.render.plan import plan_render

    p = prepare(screen_scene(0.0), RenderSettings(light_paths=1000))
    grating_tris = p.tri_material == 0
    assert p.light_targets.caster_mask[grating_tris].all() and not p.light_targets.caster_mask[~grating_tris].any()
    assert plan_render(p).light_pass
    s = screen_scene(0.0)
    s.materials.lattice[0] = 1  # HEXAGONAL
    p = prepare(s, RenderSettings(light_paths=1000))
    assert p.gratings.hexagonal[0] and not p.light_targets.caster_mask.any()
    assert not plan_render(p).light_pass


def test_rendered_spectrum_on_the_screen():
    """Through the whole renderer (light pass, then the eye pass's caustic lookup): a narrow spot
    lights the 600 lines/mm grating only (the screen stays in its shadow, so all it shows is
    diffracted light); an orthographic camera looks straight at the screen's first order, 1 mm per
    pixel. The centroid of every wavelength bin of the rendered spectral image sits within one
    pixel of the bin's mean of tan(asin(lambda / D)) (1 m behind the grating)."""
    from opal_diffraction.core.render.frame import render

    s = screen_scene(0.0, screen_x=(0.1, 0.6))  # the first order only
    s.lights = Lights.from_list([{"kind": "SPOT", "position": (0, 0, 1.0), "direction": (0, 0, -1.0),
                                  "power": 1000.0, "spot_size": 2 * np.arctan(0.004), "spot_blend": 0.0}])
    width, height, scale, cx = 300, 10, 0.3, 0.35
    m = np.eye(4)
    m[:3, 3] = (cx, 0.0, -0.5)
    s.camera = Camera(matrix=m, kind="ORTHO", ortho_scale=scale, width=width, height=height)
    res = render(s, RenderSettings(samples=4, light_paths=2_000_000, element_size=ELEMENT, diffuse_bounces=0), spectral_film=True)
    assert res.plan.light_pass
    row = res.spectral.sum(axis=0).astype(np.float64)  # (W, n)
    x_pix = cx + ((np.arange(width) + 0.5) * 2 / width - 1) * scale / 2  # pixel centres on the screen
    pixel = scale / width
    edges = res.wavelengths[0] - 2.5 + 5.0 * np.arange(len(res.wavelengths) + 1)
    errors = []
    for k in range(len(res.wavelengths)):  # loop over wavelength bins
        expect = np.mean(order_x(0.0, 1, np.linspace(edges[k], edges[k + 1], 201)))
        if not (x_pix[0] + 0.02 < expect < x_pix[-1] - 0.02):
            continue
        near = np.abs(x_pix - expect) < 0.03  # this order's spot (about 16 mm wide) and its margin
        c = np.sum(row[near, k] * x_pix[near]) / np.sum(row[near, k])
        errors.append(abs(c - expect))
    errors = np.array(errors)
    print(f"rendered first order: {len(errors)} bins, median error {np.median(errors) / pixel:.3f} px, "
          f"worst {errors.max() / pixel:.3f} px")
    assert len(errors) == len(res.wavelengths)
    assert errors.max() < pixel
