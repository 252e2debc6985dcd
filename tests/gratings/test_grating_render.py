"""Gratings through the whole renderer: the source paper's (Kobayashi & Kawai, docs/physics.md)
Fig. 5 set-up (a transmission grating between a point light at 10 degrees incidence and the
camera), compared with the grating equation and with a brute-force evaluation of the Fraunhofer
formula (fine wavelength quadrature of the point kernel, itself checked against phasor sums in
test_diffraction.py); docs/physics.md section 3.9."""

import numpy as np
import pytest

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.gratings.kernel import fraunhofer_pattern
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings

#: NumPy 2 renamed np.trapz to np.trapezoid (the same trapezoidal rule); NumPy 1.24-1.26 (Blender 4.2-5.0) has only trapz
_trapezoid = getattr(np, "trapezoid", None) or np.trapz

D, A, N, L_UM = 1600.0, 480.0, 100, 20.0
INCIDENCE = np.radians(10.0)
LIGHT_DIST = 1.0
CAM_H = 0.05
W, H = 241, 21


def fig5_scene(lattice="LINES", grating=True):
    mats = Materials.from_list([{
        "kind": "DIFFUSE", "color": (0, 0, 0), "grating": int(grating), "grating_type": "TRANSMISSION",
        "lattice": lattice, "period": D, "slit_width": A, "slit_count": N, "coherence_length": L_UM}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (0.4, 0, 0), (0, 0.4, 0)), material=0, tangent=(1, 0, 0))
    light_pos = LIGHT_DIST * np.array([np.sin(INCIDENCE), 0.0, -np.cos(INCIDENCE)])
    s.lights = Lights.from_list([{"kind": "POINT", "position": light_pos, "power": 4 * np.pi}])
    m = np.eye(4)
    m[2, 3] = CAM_H
    s.camera = Camera(matrix=m, lens=18.0, sensor_width=36.0, width=W, height=H)
    return s


def centre_row_geometry():
    """Grating points seen by the centre row's pixel centres, and u, v, cos(theta_o) there."""
    half = 18.0 / 18.0  # tan(half fov) = (sensor / 2) / lens
    xs = (2 * (np.arange(W) + 0.5) / W - 1) * half * CAM_H  # on the plane z = 0
    p = np.stack([xs, np.zeros(W), np.zeros(W)], 1)
    w_o = np.array([0, 0, CAM_H]) - p
    w_o /= np.linalg.norm(w_o, axis=1, keepdims=True)
    light = LIGHT_DIST * np.array([np.sin(INCIDENCE), 0.0, -np.cos(INCIDENCE)])
    to_l = light - p
    dist = np.linalg.norm(to_l, axis=1)
    w_i = to_l / dist[:, None]
    h = w_o + w_i
    return h[:, 0], h[:, 1], w_o[:, 2], np.abs(w_i[:, 2]) / dist**2


@pytest.fixture(scope="module")
def rendered():
    s = fig5_scene()
    # point samples at the pixel centres (the footprint integral is tested in test_grating_footprint.py)
    st = RenderSettings(samples=1, filter_width=0.0, threads=1, grating_footprint=False)
    res = render(s, st, spectral_film=True)
    ctx = prepare(s, st)
    return res, ctx


def brute_force_row(ctx, bin_index):
    u, v, cos_o, e_geo = centre_row_geometry()
    lo, hi = ctx.grid.bin_edges[bin_index], ctx.grid.bin_edges[bin_index + 1]
    lam = np.linspace(lo, hi, 4001)
    p = fraunhofer_pattern(u[:, None], v[:, None], lam[None, :], A, D, N, L_UM * 1e3)
    mean = _trapezoid(p / (lam * 1e-9) ** 2, lam, axis=1) / (hi - lo)
    # docs/physics.md section 3.2: no 1/cos(theta_o); the Harvey-Shack factor (on by default)
    # rescales the propagating orders to carry a / D, counted here order by order at the bin centre
    factor = (A * 1e-9) ** 2 * (L_UM * 1e-6) * N / (D * 1e-9)
    intensity = 1.0  # W/sr: power 4 pi
    return intensity * e_geo * factor * harvey_shack_reference(0.5 * (lo + hi)) * mean * ctx.lights.spectrum[0, bin_index]


def harvey_shack_reference(lam):
    """(a/D) / sum over propagating orders of (a/D)^2 sinc^2(pi m a/D), per centre-row pixel:
    order m leaves with direction cosine m lambda / D - alpha_i (beta_i = 0 on the centre row)."""
    light = LIGHT_DIST * np.array([np.sin(INCIDENCE), 0.0, -np.cos(INCIDENCE)])
    half = 18.0 / 18.0
    xs = (2 * (np.arange(W) + 0.5) / W - 1) * half * CAM_H
    out = np.empty(W)
    rho = A / D
    for i, x in enumerate(xs):  # a reference: plain loops
        w_i = light - np.array([x, 0.0, 0.0])
        alpha = w_i[0] / np.linalg.norm(w_i)
        total = 0.0
        for m in range(-20, 21):
            if abs(m * lam / D - alpha) <= 1.0:
                arg = np.pi * m * rho
                total += rho**2 * (1.0 if m == 0 else (np.sin(arg) / arg) ** 2)
        out[i] = rho / total
    return out


def test_row_matches_brute_force_fraunhofer(rendered):
    res, ctx = rendered
    k = int(np.argmin(np.abs(ctx.grid.wavelengths - 550)))
    row = res.spectral[H // 2, :, k]
    ref = brute_force_row(ctx, k)
    assert ref.max() > 0
    np.testing.assert_allclose(row, ref, rtol=2e-2, atol=2e-3 * ref.max())
    assert not np.isnan(res.spectral).any()
    # everything seen is diffraction: the base is black and nothing else is lit
    np.testing.assert_allclose(res.passes["Diffraction"], res.rgb, rtol=1e-5, atol=1e-7)


def test_orders_sit_where_the_grating_equation_puts_them(rendered):
    res, ctx = rendered
    k = int(np.argmin(np.abs(ctx.grid.wavelengths - 550)))
    lam = ctx.grid.wavelengths[k]
    row = res.spectral[H // 2, :, k]
    u, _, _, _ = centre_row_geometry()
    px = np.arange(W) + 0.5
    found = 0
    for m in (-1, 0, 1, 2):  # m = -2 would need u = -0.69, outside this camera's view
        target = m * lam / D
        assert u.min() < target < u.max()
        # u increases monotonically along the row: interpolate the predicted pixel position
        order = np.argsort(u)
        predicted = np.interp(target, u[order], px[order])
        win = (px > predicted - 4) & (px < predicted + 4)
        centroid = np.sum(px[win] * row[win]) / np.sum(row[win])
        assert abs(centroid - predicted) < 0.5, (m, centroid, predicted)
        found += 1
    assert found == 4


def test_relative_order_intensities(rendered):
    res, ctx = rendered
    k = int(np.argmin(np.abs(ctx.grid.wavelengths - 550)))
    row = res.spectral[H // 2, :, k]
    ref = brute_force_row(ctx, k)
    u, _, _, _ = centre_row_geometry()
    px = np.arange(W) + 0.5
    order = np.argsort(u)
    sums, sums_ref = [], []
    for m in (-1, 0, 1, 2):
        c = np.interp(m * 550.0 / D, u[order], px[order])
        win = np.abs(px - c) < 5
        sums.append(row[win].sum())
        sums_ref.append(ref[win].sum())
    np.testing.assert_allclose(np.array(sums) / sums[1], np.array(sums_ref) / sums_ref[1], rtol=0.02)
    # second order weaker than first (envelope sinc^2(pi a m / D), a / D = 0.3)
    assert sums[3] < sums[2]


def test_no_grating_no_grating_work():
    s = fig5_scene(grating=False)
    res = render(s, RenderSettings(samples=1, threads=1))
    assert not res.plan.gratings and "no grating work" in res.plan.summary()
    assert not res.passes["Diffraction"].any()


def test_hexagonal_lattice_renders_finite_and_energy_bounded():
    s = fig5_scene(lattice="HEXAGONAL")
    res = render(s, RenderSettings(samples=4, threads=1), spectral_film=True)
    assert np.isfinite(res.spectral).all() and res.spectral.min() >= 0 and res.spectral.max() > 0
