"""RGB / Float Curves' table lookup, Wavelength and Blackbody (core/materials/shader_eval.py;
docs/physics.md section 13.6): the compiled lookup kernel against its NumPy reference bit for
bit, the reference against an independent piecewise-linear interpolation / extrapolation, the
Wavelength colour against colour-science's CIE 1931 observer, the Blackbody colour against
Planck's law integrated with it. (Against Cycles: tests/blender/test_shader_curves_cycles.py.)"""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.materials import shader_eval as E
from opal_diffraction.core.materials.shader_kernels import curve_lookup_kernel
from opal_diffraction.core.util.jit import AVAILABLE

F = np.float32


def table_and_points(c=3, n=257, seed=3):
    rng = np.random.default_rng(seed)
    table = np.cumsum(rng.uniform(-0.02, 0.03, (n, c)), axis=0).astype(F)
    rel = rng.uniform(-0.6, 1.6, (5000, c)).astype(F)
    rel[:20] = np.float32([0, 1])[rng.integers(0, 2, (20, c))]
    rel[20:25] = np.nan
    return table, rel


@pytest.mark.skipif(not AVAILABLE, reason="numba is not available: only the reference runs")
@pytest.mark.parametrize("extrapolate", [True, False])
@pytest.mark.parametrize("c", [1, 3])
def test_curve_kernel_equals_the_reference_bit_for_bit(extrapolate, c):
    table, rel = table_and_points(c)
    out = np.empty_like(rel)
    curve_lookup_kernel(table, rel, extrapolate, out)
    ref = E.curve_lookup_reference(table, rel, extrapolate)
    assert np.array_equal(out.view(np.uint32), ref.view(np.uint32))


@pytest.mark.parametrize("extrapolate", [True, False])
def test_curve_lookup_is_piecewise_linear_with_linear_ends(extrapolate):
    table, rel = table_and_points(3)
    rel = rel[25:]
    got = E.curve_lookup_reference(table, rel, extrapolate).astype(np.float64)
    x = np.linspace(0.0, 1.0, len(table))
    for c in range(3):
        t = table[:, c].astype(np.float64)
        want = np.interp(rel[:, c], x, t)  # holds the ends outside [0, 1]
        if extrapolate:
            h = 1.0 / (len(t) - 1)
            want = np.where(rel[:, c] < 0, t[0] + (t[1] - t[0]) / h * rel[:, c], want)
            want = np.where(rel[:, c] > 1, t[-1] + (t[-1] - t[-2]) / h * (rel[:, c] - 1), want)
        np.testing.assert_allclose(got[:, c], want, atol=2e-6)


def test_curve_op_mixes_by_fac_over_the_x_range():
    """The op reads the input relative to [min_x, max_x] and mixes with it by Fac."""
    from opal_diffraction.core.scene.shader_programs import ProgramBuilder, program_problems
    b = ProgramBuilder("t")
    table = np.linspace(-1.0, 3.0, 257) ** 2  # the curve y = x^2 sampled over x in [-1, 3]
    v = b.op("coord", kind="generated")[0]
    x = b.op("separate", [v])[0]
    fac = b.op("separate", [v])[1]
    b.outputs["roughness"] = b.op("float_curve", [fac, x], table=[float(t) for t in table], min_x=-1.0, max_x=3.0,
                                  extrapolate=True)[0]
    prog = b.finish()
    assert program_problems(prog) is None
    g = np.random.default_rng(1).uniform(0, 1, (2000, 3)).astype(F)
    g[:, 0] = g[:, 0] * 6 - 2  # x in [-2, 4]: both ends extrapolated
    got = E.evaluate(prog, "roughness", {"generated": g}, len(g))
    xx, ff = g[:, 0].astype(np.float64), g[:, 1].astype(np.float64)
    h = 4.0 / 256
    y = np.where(xx < -1, 1 + (xx + 1) * ((-1 + h) ** 2 - 1) / h,          # the first chord's slope
                 np.where(xx > 3, 9 + (xx - 3) * (9 - (3 - h) ** 2) / h, xx ** 2))
    want = (1 - ff) * xx + ff * y
    # inside, the chords of x^2 lie above it by at most h^2 / 4
    np.testing.assert_allclose(got, want, atol=h * h / 4 + 1e-5)


def test_wavelength_is_the_cie_observer_in_rec709():
    from opal_diffraction.core.spectral.spectrum import _colour
    colour = _colour()
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    nm = np.arange(380.0, 780.0, 1.7, dtype=np.float32)
    xyz = np.stack([np.interp(nm, cmfs.wavelengths, cmfs.values[:, i]) for i in range(3)], axis=1)
    m = colour.models.RGB_COLOURSPACE_sRGB.matrix_XYZ_to_RGB
    want = np.maximum(xyz @ m.T / 2.52, 0.0)
    got = E.wavelength_rgb(nm)
    # Cycles' table has 4 decimals and 5 nm steps: linear interpolation between 5 nm samples
    # of the observer deviates from the 1 nm table by up to ~0.02 in z near its peak
    np.testing.assert_allclose(got, want, atol=0.03)
    assert np.abs(got - want).mean() < 2e-3
    # Cycles truncates (380 - 379) / 5 towards zero: 379 nm reads the 380 nm row, 374 nm is black
    assert (E.wavelength_rgb(np.float32([370.0, 780.0, 900.0, np.nan])) == 0).all()


def test_blackbody_is_plancks_colour():
    """Cycles' fit against Planck's law through the CIE observer, as chromaticity (each colour
    divided by its Rec.709 luminance) from 1000 K to 11500 K, and its constants outside."""
    from opal_diffraction.core.spectral.spectrum import _colour
    colour = _colour()
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    wl = cmfs.wavelengths * 1e-9
    m = colour.models.RGB_COLOURSPACE_sRGB.matrix_XYZ_to_RGB
    luma = np.array([0.2126729, 0.7151522, 0.0721750])
    temps = np.linspace(1000.0, 11500.0, 43).astype(F)
    got = E.blackbody_rgb(temps).astype(np.float64)
    h, c, k = 6.62607015e-34, 2.99792458e8, 1.380649e-23
    for t, g in zip(temps, got):
        planck = 1.0 / (wl ** 5 * np.expm1(h * c / (wl * k * float(t))))
        rgb = m @ (cmfs.values.T @ planck)
        want = rgb / (rgb @ luma)
        np.testing.assert_allclose(g / (g @ luma), np.maximum(want, 0), rtol=0.02, atol=0.01, err_msg=f"{t} K")
    hot, cold = E.blackbody_rgb(F([12000.0, 30000.0])), E.blackbody_rgb(F([799.0, 10.0]))
    assert np.array_equal(hot[0], hot[1]) and np.array_equal(cold[0], cold[1]) and (cold >= 0).all()


@pytest.mark.parametrize("params,why", [
    (dict(table=[0.0], min_x=0.0, max_x=1.0, extrapolate=True), "one entry"),
    (dict(table=[0.0, float("nan")], min_x=0.0, max_x=1.0, extrapolate=True), "NaN entry"),
    (dict(table=[0.0, 1.0], min_x=1.0, max_x=1.0, extrapolate=True), "empty x range"),
    (dict(table=[0.0, 1.0], min_x=0.0, max_x=1.0, extrapolate=1), "extrapolate not a boolean"),
    (dict(table=[[0.0, 1.0], [1.0, 0.0]], min_x=0.0, max_x=1.0, extrapolate=False), "two columns")])
def test_bad_curve_parameters_are_one_line(params, why):
    from opal_diffraction.core.scene.shader_programs import ProgramBuilder, program_problems
    b = ProgramBuilder("t")
    fac = b.const(1.0)
    b.outputs["roughness"] = b.op("float_curve", [fac, b.const(0.5)], **params)[0]
    msg = program_problems(b.finish())
    assert msg is not None and "\n" not in msg and "curve" in msg, why
    b = ProgramBuilder("t")
    b.outputs["color"] = b.op("curves", [b.const(1.0), b.const([0.5, 0.5, 0.5])], **{**params, "table": [[0.0] * 3] * 3
                                                                                      if why == "two columns" else
                                                                                      [[v] * 3 for v in params["table"]]})[0]
    msg = program_problems(b.finish())
    assert (msg is None) == (why in ("two columns",)), why
