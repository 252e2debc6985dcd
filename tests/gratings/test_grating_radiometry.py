"""Grating radiometry against independent numbers (docs/physics.md sections 3.2, 3.3 and 3.4).

- Power: the code's radiance (gratings.diffracted_radiance) integrated numerically over the unit
  disk of exit direction cosines (du dv = cos theta_o d omega_o), on a composite midpoint grid at
  half the orders' widths around each order and coarse in the tails; compared with the mirror
  (a -> D: all of the incident power) and with Parseval's order sums counted by explicit loops.
- Harvey-Shack: with it on the integral is a / D at every incidence.
- Hexagonal lattice: the first order's position against a brute-force phasor sum over a
  hexagon-shaped patch built from rows (sqrt 3 / 2) D apart.
- Layering: white furnaces (core Scene, small renders) with the expected values from Fresnel,
  Snell and the order sums computed here.
"""

import numpy as np
import pytest

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.sampling.camera import generate_rays
from opal_diffraction.core.gratings.kernel import harvey_shack_factor, propagating_power
from opal_diffraction.core.gratings.radiance import PreparedGratings, diffracted_radiance
from opal_diffraction.core.gratings.layering import base_scale, strip_fraction
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings

LAM = 550.0
EDGES = np.array([LAM - 0.5, LAM + 0.5])
T, S, NRM = np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0])


def lines(d, a, n, length_um, hexagonal=False):
    one = lambda x: np.array([x])  # noqa: E731
    return PreparedGratings(one(True), one(False), one(hexagonal), one(float(d)), one(float(a)), one(int(n)),
                            one(length_um * 1e3), np.ones(1), np.zeros(1))


def order_sum(d, a, alpha_i, beta_i=0.0, lam=LAM):
    """sum over propagating m of (a/D)^2 sinc^2(pi m a/D), by a plain loop (the reference)."""
    rho = a / d
    total = 0.0
    for m in range(-200, 201):
        ao = m * lam / d - alpha_i
        if ao * ao + beta_i * beta_i <= 1.0:
            x = np.pi * m * rho
            total += rho * rho * (1.0 if m == 0 else (np.sin(x) / x) ** 2)
    return total


def composite_axis(centres, half, fine, coarse):
    """Midpoint nodes and weights on [-1, 1]: spacing ``fine`` within ``half`` of each centre,
    ``coarse`` elsewhere."""
    iv = sorted((max(-1.0, c - half), min(1.0, c + half)) for c in centres if -1 < c + half and c - half < 1)
    merged = []
    for lo, hi in iv:
        if merged and lo <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], hi)
        else:
            merged.append([lo, hi])
    segs, x = [], -1.0
    for lo, hi in merged:
        if lo > x:
            segs.append((x, lo, coarse))
        segs.append((lo, hi, fine))
        x = hi
    if x < 1.0:
        segs.append((x, 1.0, coarse))
    nodes, weights = [], []
    for lo, hi, h in segs:
        k = max(1, int(np.ceil((hi - lo) / h)))
        nodes.append(lo + (np.arange(k) + 0.5) * (hi - lo) / k)
        weights.append(np.full(k, (hi - lo) / k))
    return np.concatenate(nodes), np.concatenate(weights)


def hemisphere_power(g, theta_i, renormalise, d, n, length_um):
    """iint L_o d(alpha) d(beta) over the unit disk: the reflected power per unit irradiance.

    The grid resolves every order (half its width lambda / (N D) in u, lambda / L in v) within
    30-60 widths of it; beyond, the tails are sampled at a spacing incommensurate with their
    side lobes."""
    w_i = np.array([np.sin(theta_i), 0.0, np.cos(theta_i)])
    wu, wv = LAM / (n * d), LAM / (length_um * 1e3)
    orders = [m * LAM / d - w_i[0] for m in range(-100, 101) if abs(m * LAM / d - w_i[0]) < 1]
    an, aw = composite_axis(orders, 60 * wu, wu / 2, 0.0073)
    bn, bw = composite_axis([0.0], 30 * wv, wv / 2, 0.0073)
    total = 0.0
    for j0 in range(0, len(bn), 64):  # rows of beta at a time
        bb, ww = np.meshgrid(bn[j0:j0 + 64], an, indexing="ij")[0], np.outer(bw[j0:j0 + 64], aw)
        aa = np.broadcast_to(an, bb.shape)
        inside = aa**2 + bb**2 < 1.0
        a_, b_, w_ = aa[inside], bb[inside], ww[inside]
        w_o = np.stack([a_, b_, np.sqrt(1 - a_**2 - b_**2)], 1)
        k = len(a_)
        rad = diffracted_radiance(g, 0, w_o, np.broadcast_to(w_i, (k, 3)), np.broadcast_to(T, (k, 3)),
                                  np.broadcast_to(S, (k, 3)), np.broadcast_to(NRM, (k, 3)), np.full(k, float(d)),
                                  EDGES, None, renormalise=renormalise)
        total += float(np.sum(rad[:, 0].astype(np.float64) * w_))
    return total


def renormalisation_ratio(g, theta_i, d):
    """The code's renormalised / plain radiance at many exit directions: one constant K."""
    rng = np.random.default_rng(1)
    k = 400
    w_i = np.array([np.sin(theta_i), 0.0, np.cos(theta_i)])
    m = rng.integers(-3, 4, k)
    a_ = np.clip(m * LAM / d - w_i[0] + rng.normal(0, 1e-4, k), -0.99, 0.99)  # near the orders
    b_ = rng.normal(0, 1e-4, k)
    w_o = np.stack([a_, b_, np.sqrt(1 - a_**2 - b_**2)], 1)
    args = (w_o, np.tile(w_i, (k, 1)), np.tile(T, (k, 1)), np.tile(S, (k, 1)), np.tile(NRM, (k, 1)),
            np.full(k, float(d)), EDGES, None)
    on = diffracted_radiance(g, 0, *args, renormalise=True).astype(np.float64)[:, 0]
    off = diffracted_radiance(g, 0, *args, renormalise=False).astype(np.float64)[:, 0]
    ok = off > 1e-6 * off.max()
    ratio = on[ok] / off[ok]
    np.testing.assert_allclose(ratio, np.median(ratio), rtol=1e-5)  # a constant per incidence
    return float(np.median(ratio))


@pytest.mark.slow
@pytest.mark.parametrize("theta_deg", [0, 45, 60, 75])
def test_mirror_limit_reflects_the_incident_power(theta_deg):
    """a = 0.999 D: the grating is a mirror; power within 1 % of the incident at 0-75 degrees
    (docs/physics.md section 3.2; the old 1/cos theta_o gave 1.00, 1.41, 2.01, 3.83)."""
    d, n, length_um = 1600.0, 1000, 1000.0
    g = lines(d, 0.999 * d, n, length_um)
    theta = np.radians(theta_deg)
    plain = hemisphere_power(g, theta, False, d, n, length_um)
    assert plain == pytest.approx(1.0, rel=0.01), plain
    renormalised = plain * renormalisation_ratio(g, theta, d)
    assert renormalised == pytest.approx(1.0, rel=0.01), renormalised
    print(f"mirror limit {theta_deg} deg: {plain:.5f} (Harvey-Shack {renormalised:.5f})")


def test_oblique_order_sums_match_the_documented_table():
    """docs/physics.md section 3.2's table (D = 1600 nm, a = 800 nm, 550 nm)."""
    for theta, ref in ((0, 0.4526), (30, 0.4639), (60, 0.3666)):
        assert order_sum(1600.0, 800.0, np.sin(np.radians(theta))) == pytest.approx(ref, abs=5e-5)


@pytest.mark.slow
@pytest.mark.parametrize("d", [1600.0, 740.0, 600.0])
def test_oblique_incidence_power_is_the_propagating_order_sum(d):
    """a = D/2: iint L_o = sum over propagating orders of (a/D)^2 sinc^2(pi m a/D) within 1 %, at
    0, 30 and 60 degrees; with Harvey-Shack on, a / D."""
    n, length_um = 300, 300.0
    g = lines(d, d / 2, n, length_um)
    for theta_deg in (0, 30, 60):
        theta = np.radians(theta_deg)
        ref = order_sum(d, d / 2, np.sin(theta))
        plain = hemisphere_power(g, theta, False, d, n, length_um)
        assert plain == pytest.approx(ref, rel=0.01), (theta_deg, plain, ref)
        renormalised = plain * renormalisation_ratio(g, theta, d)
        assert renormalised == pytest.approx(0.5, rel=0.01), (theta_deg, renormalised)
        print(f"D = {d:.0f} nm, {theta_deg} deg: {plain:.5f} vs order sum {ref:.5f} (Harvey-Shack {renormalised:.5f})")


def test_propagating_power_and_harvey_shack_factor_match_the_order_loop():
    rng = np.random.default_rng(3)
    for d, ratio in ((1600.0, 0.5), (740.0, 0.3), (600.0, 0.7), (5000.0, 0.25)):
        alpha = rng.uniform(-1, 1, 40)
        beta = rng.uniform(-1, 1, 40) * np.sqrt(1 - alpha**2)
        lam = rng.uniform(380, 780, 40)
        got = propagating_power(alpha, beta, lam, ratio, d)
        ref = [order_sum(d, ratio * d, a_, b_, l_) for a_, b_, l_ in zip(alpha, beta, lam)]
        np.testing.assert_allclose(got, ref, rtol=1e-12)
        np.testing.assert_allclose(harvey_shack_factor(alpha, beta, lam, ratio, d), ratio / np.array(ref), rtol=1e-12)


# ----------------------------------------------------------------- hexagonal lattice (section 3.4)
def hexagon_patch(d, radius):
    """Lattice points of a hexagonal lattice built from rows (sqrt 3 / 2) D apart, each row's points
    D apart and every other row shifted by D / 2, within ``radius`` of the origin."""
    k = int(radius / d) + 2
    rows, cols = np.meshgrid(np.arange(-2 * k, 2 * k + 1), np.arange(-2 * k, 2 * k + 1), indexing="ij")
    x = (cols + 0.5 * (rows % 2)) * d
    y = rows * (np.sqrt(3) / 2) * d
    keep = x**2 + y**2 <= radius**2
    return x[keep], y[keep]


def test_hexagonal_first_order_sits_at_two_lambda_over_root3_d():
    """D = 250 nm, |q| = 0.9 (q along the slit direction s, a first-order direction): the first
    order is at lambda = sqrt 3 D |q| / 2 = 194.9 nm, by a phasor sum over a hexagon of ~1400
    points and in the code's pattern; the LINES reading (lambda = D |q| = 225 nm) is not a peak."""
    d, q = 250.0, 0.9
    expected = np.sqrt(3) * d * q / 2
    assert expected == pytest.approx(194.86, abs=0.01)
    assert np.sqrt(3) * 550.1 * q / 2 == pytest.approx(428.8, abs=0.05)
    lam = np.arange(150.0, 300.0, 0.02)
    x, y = hexagon_patch(d, 20 * d)
    brute = np.abs(np.exp(2j * np.pi * (q * y)[None, :] / lam[:, None]).sum(axis=1)) ** 2 / len(x) ** 2
    assert lam[np.argmax(brute)] == pytest.approx(expected, abs=0.1)
    # the code (N = 40 per side): one ray, very narrow bins, Airy envelope of small disks
    g = lines(d, 0.2 * d, 40, 10.0, hexagonal=True)
    edges = np.stack([lam, lam + 1e-6], 1).ravel()  # bins [lam, lam + 1e-6] and gaps between them
    w_i = NRM[None, :]
    w_o = np.array([[0.0, q, np.sqrt(1 - q * q)]])
    rad = diffracted_radiance(g, 0, w_o, w_i, T[None, :], S[None, :], NRM[None, :], np.array([d]), edges,
                              np.random.default_rng(0), renormalise=False)[0, ::2]
    assert lam[np.argmax(rad)] == pytest.approx(expected, abs=0.1)
    lines_reading = np.argmin(np.abs(lam - d * q))
    assert rad[lines_reading] < 1e-2 * rad.max() and brute[lines_reading] < 1e-2 * brute.max()  # side lobes only
    # and the six first orders: the same |q| at 30 degrees from t (a reciprocal-lattice direction)
    w_o30 = np.array([[q * np.cos(np.pi / 6), -q * np.sin(np.pi / 6), np.sqrt(1 - q * q)]])
    rad30 = diffracted_radiance(g, 0, w_o30, w_i, T[None, :], S[None, :], NRM[None, :], np.array([d]), edges,
                                np.random.default_rng(0), renormalise=False)[0, ::2]
    assert lam[np.argmax(rad30)] == pytest.approx(expected, abs=0.1)


def test_strip_fraction_and_base_share():
    g = PreparedGratings(np.array([True, True, False]), np.zeros(3, bool), np.array([False, True, False]),
                         np.array([1600.0, 500.0, 1000.0]), np.array([400.0, 250.0, 500.0]), np.full(3, 10),
                         np.full(3, 1e4), np.ones(3), np.zeros(3))
    np.testing.assert_allclose(strip_fraction(g), [0.25, np.pi * 0.25 / (2 * np.sqrt(3)), 0.0])
    np.testing.assert_allclose(base_scale(g), [0.75, 1 - np.pi * 0.25 / (2 * np.sqrt(3)), 1.0], rtol=1e-6)


# ----------------------------------------------------------------- white furnaces (section 3.3)
D_F, A_F = 740.0, 370.0  # orders +-1 turn evanescent inside the visible range: Rayleigh jumps


def furnace_scene(base: dict, grating_type="REFLECTION", pixels=12):
    mat = dict(base, grating=1, grating_type=grating_type, period=D_F, slit_width=A_F, slit_count=N_F,
               coherence_length=100.0)
    s = Scene(materials=Materials.from_list([mat]))
    s.add_mesh(*primitives.quad((0, 0, 0), (40.0, 0, 0), (0, 40.0, 0)), material=0, tangent=(1, 0, 0))
    s.camera = Camera.look_at((0.3, -0.8, 1.2), (0, 0, 0), lens=20, width=pixels, height=pixels)
    s.world_color = np.array([1.0, 1.0, 1.0], np.float32)
    return s


def pixel_centre_rays(cam):
    px, py = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    o, d = generate_rays(cam, px.ravel(), py.ravel())
    return o.astype(np.float64), d.astype(np.float64)


N_F = 300  # the furnace gratings' slit count


def _finite_pattern_cumulative(n, ratio, eta_max, per_lobe=64):
    """W(eta) = ratio^2 / (N pi) int_0^eta sinc^2(ratio x) (sin N x / sin x)^2 dx by the
    trapezoid rule on the pattern evaluated pointwise (``per_lobe`` nodes per pi / N)."""
    eta = np.linspace(-eta_max, eta_max, int(2 * eta_max / (np.pi / (per_lobe * n))) | 1)
    sn = np.sin(eta)
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.where(np.abs(sn) < 1e-12, float(n * n), (np.sin(n * eta) / sn) ** 2)
    dens = ratio * ratio / (n * np.pi) * np.sinc(ratio * eta / np.pi) ** 2 * f
    w = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(eta))])
    return eta, w - np.interp(0.0, eta, w)


def zeroth_efficiency_reference(directions, edges, sub=32):
    """(a/D)^2 K for light from ``directions`` (P, 3) onto the z = 0 grating with t = x: K of
    the finite-N pattern (slit count N_F) the eye pass renormalises, a / D over the bin's mean
    (``sub`` wavelengths) of the pattern's power inside the disk of exit cosines, the pattern
    integrated pointwise here (docs/physics.md section 3.2)."""
    rho = A_F / D_F
    edges = np.asarray(edges, np.float64)
    eta, w = _finite_pattern_cumulative(N_F, rho, np.pi * D_F * 2.0 / edges[0] + 1.0)
    lam = edges[:-1, None] + (edges[1:] - edges[:-1])[:, None] * (np.arange(sub) + 0.5)[None, :] / sub
    out = np.empty((len(directions), len(edges) - 1))
    for i, dvec in enumerate(np.asarray(directions, np.float64)):
        r = np.sqrt(max(1.0 - dvec[1] ** 2, 0.0))
        hi, lo = np.interp(np.pi * D_F * (dvec[0] + r) / lam, eta, w), np.interp(np.pi * D_F * (dvec[0] - r) / lam, eta, w)
        out[i] = rho * rho * rho / (hi - lo).mean(axis=1)
    return out


def world_orders_reference(directions, edges, sub=6, exclude_zeroth=False, eta=1.0):
    """(P, K) the world a reflection grating (z = 0, t = x, s = y) diffracts towards the viewer
    along ``directions`` (P, 3, travel), per wavelength bin: sum over the orders m that
    propagate of e_m K(w_src,m), each order's source direction from the grating equation and its
    Harvey-Shack factor f / (the propagating sum from there, ``order_sum``); averaged over
    ``sub`` wavelengths per bin (docs/physics.md section 3.11). Orders enumerated one by one.
    ``eta``: the index on the source's side (a grating over glass, the viewer in air): the
    source's index-scaled cosines (u, v) obey the same equation and propagate where
    u^2 + v^2 < eta^2; K is then the viewer's direction's, f / (the sum of e_m over those same
    orders, the zeroth included): the light pass's K for light going the other way."""
    rho = A_F / D_F
    w_o = -np.asarray(directions, np.float64)
    out = np.zeros((len(w_o), len(edges) - 1))
    for k in range(len(edges) - 1):
        lams = edges[k] + (np.arange(sub) + 0.5) / sub * (edges[k + 1] - edges[k])
        for i, w in enumerate(w_o):
            total = 0.0
            for lam in lams:
                picked = every = 0.0
                for m in range(-12, 13):
                    u, v = m * lam / D_F - w[0], -w[1]  # the source direction's cosines
                    if u * u + v * v >= eta * eta:
                        continue
                    x = np.pi * m * rho
                    e = rho * rho * (1.0 if m == 0 else (np.sin(x) / x) ** 2)
                    every += e
                    if exclude_zeroth and m == 0:
                        continue
                    picked += e
                    if eta == 1.0:
                        total += e * rho / order_sum(D_F, A_F, u, v, lam)
                if eta != 1.0:
                    total += picked * rho / every
            out[i, k] = total / sub
    return out


def assert_matches_in_the_mean(ratio, expected, label):
    """Z-test of the image's mean ratio against the expected mean, the noise from the spread of
    the per-pixel means (the world orders' one wavelength bin per sample is the only noise)."""
    diff = (ratio - expected).mean(axis=1)  # per pixel, over the bins
    sigma = diff.std(ddof=1) / np.sqrt(len(diff))
    z = diff.mean() / max(sigma, 1e-12)
    assert abs(z) < 4.0, (label, diff.mean(), sigma)
    assert abs(diff.mean()) < 0.01 * expected.mean(), (label, diff.mean())


def test_white_furnace_grating_on_white_lambertian():
    """Lambertian base: the base keeps 1 - a/D (one bounce into the world, exact) and the strips
    diffract the world into every order, the zeroth included (section 3.11): per pixel and bin
    (1 - a/D) + sum_m e_m K(w_src,m), computed here order by order."""
    s = furnace_scene({"kind": "DIFFUSE", "color": (1, 1, 1)}, pixels=8)
    st = RenderSettings(samples=64, threads=1, filter_width=0.0, blue_noise=False)  # independent pixels (the Z-test)
    res = render(s, st, spectral_film=True)
    ctx = prepare(s, st)
    ratio = (res.spectral / ctx.world_spectrum[None, None, :]).reshape(-1, ctx.grid.n)
    o, d = pixel_centre_rays(s.camera)
    expected = (1 - A_F / D_F) + world_orders_reference(d, ctx.grid.bin_edges)
    assert_matches_in_the_mean(ratio, expected, "lambertian")
    # Harvey-Shack's K is not reciprocal: from a uniform world some views get a few % more than
    # the world where an order turns evanescent (section 3.11); far from those it is at most 1
    assert np.median(expected) <= 1.0 + 1e-9 and expected.max() < 1.1


def test_white_furnace_grating_on_white_mirror():
    """Mirror base: the grating is the mirror, its zeroth order the specular continuation with the
    zeroth-order efficiency (a/D)^2 K(continuation direction, lambda), and the world's other
    orders are sampled from the viewer (section 3.11). The continuation is exact per pixel (the
    Diffraction pass holds the rest); the sum matches the order-by-order reference in the mean."""
    s = furnace_scene({"kind": "MIRROR", "color": (1, 1, 1)}, pixels=8)
    st = RenderSettings(samples=64, threads=1, filter_width=0.0, blue_noise=False)  # independent pixels (the Z-test)
    res = render(s, st, spectral_film=True)
    ctx = prepare(s, st)
    ratio = (res.spectral / ctx.world_spectrum[None, None, :]).reshape(-1, ctx.grid.n)
    o, d = pixel_centre_rays(s.camera)
    assert (d[:, 2] < 0).all()  # every pixel sees the grating
    refl = d * np.array([1, 1, -1.0])  # the mirror direction: the light comes from there
    zeroth = zeroth_efficiency_reference(refl, ctx.grid.bin_edges)
    orders = world_orders_reference(d, ctx.grid.bin_edges, exclude_zeroth=True)
    assert_matches_in_the_mean(ratio, zeroth + orders, "mirror")
    # the strips' share (K: section 3.11); the zeroth order's K is the finite-N pattern's (N = 300,
    # section 3.2), the sampled orders' the order sums': they differ by < 1e-4 here
    assert np.median(zeroth + orders) <= A_F / D_F * (1 + 1e-4)
    assert zeroth.max() > 1.2 * zeroth.min()  # the Rayleigh jumps are in view
    # the continuation alone: the spectral image minus the Diffraction pass, exactly
    diffraction = res.passes["Diffraction"].reshape(-1, 3)
    rest = res.rgb.reshape(-1, 3) - diffraction
    expected_rest = ctx.conv.to_rgb((zeroth * ctx.world_spectrum[None, :]).astype(np.float32))
    # (one wavelength per sample: a pixel's Diffraction may lie outside the gamut; the film then
    # desaturates the pixel and its parts together, section 10.2: the luminance is kept exactly,
    # the chroma scaled by s in [0, 1])
    y709 = np.array([0.2126729, 0.7151522, 0.0721750])
    y_rest, y_want = rest.astype(np.float64) @ y709, expected_rest.astype(np.float64) @ y709
    np.testing.assert_allclose(y_rest, y_want, rtol=2e-3, atol=1e-5)
    c0, c1 = expected_rest - y_want[:, None], rest - y_rest[:, None]
    k = np.sum(c0 * c1, axis=1) / np.maximum(np.sum(c0 * c0, axis=1), 1e-30)
    # (plus the gamut map's rounding rule, section 10.2: channels within 1e-5 of the pixel's
    # largest are rounding, so a chroma of |c0| moves by up to 1e-5 |rgb| / |c0| in k)
    tol = 2e-3 + 2e-5 * np.abs(res.rgb.reshape(-1, 3)).max(axis=1) / np.sqrt(np.maximum(np.sum(c0 * c0, axis=1), 1e-30))
    assert ((k > -tol) & (k < 1 + tol)).all(), k[(k <= -tol) | (k >= 1 + tol)]
    np.testing.assert_allclose(c1, k[:, None] * c0, atol=2e-3 * float(np.abs(expected_rest).max()))
    same = res.stats.get("out_of_gamut_pixels", 0) == 0
    if same:
        np.testing.assert_allclose(rest, expected_rest, rtol=2e-3, atol=1e-5)
    assert diffraction.mean() > 0.1 * rest.mean()


def test_transmission_grating_before_the_world_gives_its_order_sum():
    """A transmission grating on a black base (air on both sides) in a uniform world: the camera
    sees the world behind it through every order, the zeroth included: per pixel and bin
    sum_m e_m K(w_src,m) over the orders that propagate to the far side, computed order by order
    (the tangential map is the reflection's, so ``world_orders_reference`` holds); the base
    adds nothing. Before, the world behind a transmission grating was not diffracted (black)."""
    s = furnace_scene({"kind": "DIFFUSE", "color": (0, 0, 0)}, grating_type="TRANSMISSION", pixels=8)
    st = RenderSettings(samples=64, threads=1, filter_width=0.0, blue_noise=False)  # independent pixels (the Z-test)
    res = render(s, st, spectral_film=True)
    ctx = prepare(s, st)
    ratio = (res.spectral / ctx.world_spectrum[None, None, :]).reshape(-1, ctx.grid.n)
    o, d = pixel_centre_rays(s.camera)
    assert (d[:, 2] < 0).all()  # every pixel sees the grating
    expected = world_orders_reference(d, ctx.grid.bin_edges)
    assert_matches_in_the_mean(ratio, expected, "transmission")
    assert expected.mean() > 0.4


def test_white_furnace_transmission_grating_on_glass_is_unbiased():
    """Glass base under a transmission grating: the Fresnel reflection keeps its weight, the
    refraction is the zeroth transmitted order (weight (a/D)^2 K of the refracted direction),
    and the path continues along the other orders into the glass (section 3.13): the world
    behind the glass diffracted. Expected per pixel F + (1 - F) eta_0 + sum_{m != 0} e_m K(w_src,m)
    over the orders that propagate into the glass (n = 1.5: the source's index-scaled cosines
    inside the unit disk times n; Fresnel, Snell and the orders computed here; the orders'
    Fresnel loss is neglected, section 3.3). The image mean passes a Z-test over the pixels;
    the Fresnel branch plus the zeroth order alone (the image less its Diffraction pass) per bin
    as before (a Z-test with the Bernoulli variance of the reflect / refract choice, Bonferroni)."""
    s = furnace_scene({"kind": "DIELECTRIC", "color": (1, 1, 1), "ior": 1.5}, grating_type="TRANSMISSION", pixels=10)
    spp = 64
    st = RenderSettings(samples=spp, threads=1, filter_width=0.0, blue_noise=False)  # independent pixels (the Z-test)
    res = render(s, st, spectral_film=True)
    ctx = prepare(s, st)
    ratio = (res.spectral / ctx.world_spectrum[None, None, :]).reshape(-1, ctx.grid.n)
    o, d = pixel_centre_rays(s.camera)
    cos_i = -d[:, 2]
    eta = 1 / 1.5
    sin_t = eta * np.sqrt(1 - cos_i**2)
    cos_t = np.sqrt(1 - sin_t**2)
    rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    fr = 0.5 * (rs**2 + rp**2)
    t_dir = eta * d + (eta * cos_i - cos_t)[:, None] * np.array([0, 0, 1.0])  # Snell, normal +z
    eta0 = zeroth_efficiency_reference(t_dir, ctx.grid.bin_edges)
    specular = fr[:, None] + (1 - fr[:, None]) * eta0
    orders = world_orders_reference(d, ctx.grid.bin_edges, exclude_zeroth=True, eta=1.5)
    assert orders.mean() > 0.1  # the first orders propagate into the glass
    assert_matches_in_the_mean(ratio, specular + orders, "glass")
    # the specular part alone: the image less its Diffraction pass (luminance: the film's gamut
    # map keeps it, section 10.2), per pixel against F + (1 - F) eta_0, Bernoulli noise
    y709 = np.array([0.2126729, 0.7151522, 0.0721750])
    rest = (res.rgb.reshape(-1, 3) - res.passes["Diffraction"].reshape(-1, 3)).astype(np.float64) @ y709
    want = ctx.conv.to_rgb((specular * ctx.world_spectrum[None, :]).astype(np.float32)).astype(np.float64) @ y709
    white = ctx.conv.to_rgb(ctx.world_spectrum[None, :].astype(np.float32)).astype(np.float64) @ y709
    var = (fr * (1 - fr) * (1 - eta0.mean(axis=1)) ** 2 / spp) * float(white[0]) ** 2
    z = (rest.mean() - want.mean()) / np.sqrt(var.sum() / len(d) ** 2)
    assert abs(z) < 4.0, z
    assert (specular <= 1 + 1e-9).all()


def test_hexagonal_harvey_shack_factor_matches_an_order_loop():
    """K = f / sum over propagating (m1, m2) of f^2 [2 J1(x)/x]^2, orders enumerated one by one from
    the rows construction's reciprocal lattice b1 = (1, -1/sqrt 3) / D, b2 = (0, 2/sqrt 3) / D."""
    from scipy.special import j1

    from opal_diffraction.core.gratings.kernel import hexagonal_harvey_shack_factor

    rng = np.random.default_rng(5)
    for d, ratio in ((250.0, 0.5), (550.0, 0.9), (1200.0, 0.3)):
        alpha = rng.uniform(-1, 1, 25)
        beta = rng.uniform(-1, 1, 25) * np.sqrt(1 - alpha**2)
        lam = rng.uniform(380, 780, 25)
        got = hexagonal_harvey_shack_factor(alpha, beta, lam, ratio, d)
        fill = np.pi * ratio**2 / (2 * np.sqrt(3))
        b1, b2 = np.array([1.0, -1 / np.sqrt(3)]) / d, np.array([0.0, 2 / np.sqrt(3)]) / d
        for i in range(25):
            total = 0.0
            for p in range(-12, 13):
                for q in range(-12, 13):
                    g_vec = p * b1 + q * b2
                    h = g_vec * lam[i]
                    if (h[0] - alpha[i]) ** 2 + (h[1] - beta[i]) ** 2 <= 1.0:
                        x = np.pi * ratio * d * np.linalg.norm(g_vec)
                        total += fill**2 * (1.0 if x == 0 else (2 * j1(x) / x) ** 2)
            assert got[i] == pytest.approx(fill / total, rel=1e-9), (d, i)


def test_mirror_base_sees_a_sized_light_once_in_the_zeroth_order():
    """A sphere light seen in a white mirror with a reflection grating: the zeroth order comes
    only through the specular continuation, weighted (a/D)^2 K (the diffraction leaves it out),
    so the pixels that see the light's reflection equal the plain mirror's times (a/D)^2 K of
    the mirror direction; before the layering they got the mirror's full image plus the
    diffracted zeroth order on top (docs/physics.md section 3.3)."""
    from opal_diffraction.core.scene.model import Lights

    def scene(grating):
        base = {"kind": "MIRROR", "color": (1, 1, 1)}
        mat = dict(base, grating=1, grating_type="REFLECTION", period=D_F, slit_width=A_F, slit_count=N_F,
                   coherence_length=100.0) if grating else base
        s = Scene(materials=Materials.from_list([mat]))
        s.add_mesh(*primitives.quad((0, 0, 0), (40.0, 0, 0), (0, 40.0, 0)), material=0, tangent=(1, 0, 0))
        # radius 0.15 m: the light spans |u| < 0.3 about its mirror image, so no other order of it
        # (the first at u = lambda / D >= 0.54) falls on the pixels that see its reflection
        s.lights = Lights.from_list([{"kind": "POINT", "position": (0.0, 0.5, 1.0), "power": 10.0, "radius": 0.15}])
        s.camera = Camera.look_at((0.0, -0.5, 1.0), (0, 0, 0), lens=50, width=40, height=40)
        return s

    st = RenderSettings(samples=1, threads=1, filter_width=0.0, light_paths=0)
    plain = render(scene(False), st, spectral_film=True).spectral.reshape(-1, prepare(scene(False), st).grid.n)
    res = render(scene(True), st, spectral_film=True)
    layered = res.spectral.reshape(plain.shape)
    seen = plain.max(axis=1) > 0
    assert 10 < seen.sum() < len(seen)  # the light's reflection covers part of the view
    o, d = pixel_centre_rays(scene(True).camera)
    expected = zeroth_efficiency_reference(d[seen] * np.array([1, 1, -1.0]), prepare(scene(True), st).grid.bin_edges)
    np.testing.assert_allclose(layered[seen], plain[seen] * expected, rtol=1e-3, atol=1e-6 * plain.max())


def test_exclude_zeroth_removes_only_the_zeroth_order_period():
    """fraunhofer_pattern_binned(..., exclude_zeroth=True): 0 where every wavelength of the bin has
    |u| < lambda / (2 D) (the zeroth order's period of the N-slit factor), the full pattern
    where none has, and in between no more than the full pattern."""
    from opal_diffraction.core.gratings.kernel import fraunhofer_pattern_binned

    d, a, n, length = 1600.0, 800.0, 500, 2e4
    edges = np.array([540.0, 545.0, 550.0])
    u = np.linspace(-0.9, 0.9, 20001)
    v = np.zeros_like(u)
    full = fraunhofer_pattern_binned(u, v, edges, a, d, n, length)
    cut = fraunhofer_pattern_binned(u, v, edges, a, d, n, length, exclude_zeroth=True)
    inner = np.abs(u) < 539.0 / (2 * d)
    outer = np.abs(u) > 551.0 / (2 * d)
    assert full[inner].max() > 0.5 and np.abs(cut[inner]).max() < 1e-12
    np.testing.assert_allclose(cut[outer], full[outer], rtol=1e-9, atol=1e-15)
    assert (cut <= full + 1e-12).all() and (cut >= 0).all()


def test_harvey_shack_factor_clamps_rounding_only_and_rejects_other_cosines():
    """Direction cosines just past the unit circle from float rounding are put on it (the zeroth
    order then propagates, K is finite: the value on the circle, computed here from the order
    loop at the grazing direction itself); further out, or not finite, is an error, never a
    silent clamp (issue 26)."""
    from opal_diffraction.core.gratings.kernel import DISK_ROUNDING

    lam, ratio, d = 550.0, 0.5, 1600.0
    # grazing along t: the orders m with |m lam / d - 1| <= 1 propagate (m = 0 .. 5 here)
    expected = ratio / sum(ratio * ratio * (np.sinc(m * ratio) ** 2) for m in range(0, 6))
    for excess in (1e-16, 1e-7, 0.5 * DISK_ROUNDING):
        alpha = np.sqrt(1.0 + excess)
        k = harvey_shack_factor(np.array([alpha]), np.array([0.0]), lam, ratio, d)
        assert np.isfinite(k).all() and abs(k[0] - expected) < 1e-9 * expected
        k_n = harvey_shack_factor(np.array([alpha]), np.array([0.0]), lam, ratio, d, n=300)
        assert np.isfinite(k_n).all() and k_n[0] >= 1.0
    for alpha, beta in ((1.01, 0.0), (0.8, 0.8), (np.nan, 0.0), (np.inf, 0.0)):
        with pytest.raises(ValueError, match="unit disk"):
            harvey_shack_factor(np.array([alpha]), np.array([beta]), lam, ratio, d)
        with pytest.raises(ValueError, match="unit disk"):
            harvey_shack_factor(np.array([alpha]), np.array([beta]), lam, ratio, d, n=300)
