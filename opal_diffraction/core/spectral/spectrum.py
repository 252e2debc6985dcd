"""Spectra and colour: the wavelength grid, spectrum -> XYZ -> linear RGB, RGB -> spectrum.

Everything tabulated comes from colour-science (Mansencal et al., colour-science.org):

- the CIE 1931 2 degree standard observer (``colour.MSDS_CMFS``),
- the CIE D65 illuminant (``colour.SDS_ILLUMINANTS``) and Planck's law (``colour.sd_blackbody``),
- the Rec.709/sRGB primaries (``colour.RGB_COLOURSPACES['sRGB']``),
- the basis functions of Mallett, I., & Yuksel, C. (2019). Spectral Primary Decomposition for
  Rendering with sRGB Reflectance. EGSR 2019. doi:10.2312/sr.20191216
  (``colour.recovery.MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019``): linear, bounded in [0, 1] for
  RGB in [0, 1], and exactly 1 for white, so it vectorises and conserves energy.

Units. A film value is a spectral radiance sample in "Y-normalised" units: a light of RGB colour
(1, 1, 1) emits ``e_white(lambda) = D65(lambda) / Y(D65)``, whose Y is exactly 1. Thus one
"watt" of a white light is one unit of Y, which is Cycles' RGB convention (docs/physics.md
section 1.5).

Grid points are bin centres: sample i stands for the bin [lambda_i - step/2, lambda_i + step/2].
The colour-matching weights are the CMFs integrated over each bin (not point samples), so that a
film holding bin averages (the diffraction kernel returns those) converts to XYZ without bias
even at 20 nm steps. Truncation to 400-700 nm loses a little of X, Y, Z (docs/physics.md
section 1.3); a per-channel white balance on the final matrix makes a flat reflector under
white light exactly neutral instead of slightly yellow.

RGB -> spectrum on the hot path (a light's colour, an environment lookup, per hit): where the
compiled kernels run (core/util/jit.py) ``reflectance_from_rgb`` and ``illuminant_from_rgb`` take
one pass per row over a tabulated basis, the Mallett-Yuksel basis and, for lights, that basis
already multiplied by the white illuminant (``emission_basis``), instead of NumPy's temporaries
and a (B, 3) @ (3, n) product; they agree with the NumPy lines to rounding (a few units in the
last place: the white factor is applied to the basis first, and the sum of three products is
not BLAS's).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..util.jit import kernels_enabled, njit

#: NumPy 2 renamed np.trapz to np.trapezoid (the same trapezoidal rule); NumPy 1.24-1.26 (Blender 4.2-5.0) has only trapz
_trapezoid = getattr(np, "trapezoid", None) or np.trapz

__all__ = ["WavelengthGrid", "SpectralConverter", "DEFAULT_GRID"]

_OBSERVER = "CIE 1931 2 Degree Standard Observer"
# The observer table colour-science ships spans 360-830 nm; the grid must stay inside.
_MIN_NM, _MAX_NM = 360.0, 830.0


def _colour():
    """Import colour-science quietly (it warns about optional matplotlib features)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    return colour


@dataclass(frozen=True)
class WavelengthGrid:
    """Wavelength samples lambda_i = lambda_min + i * step (nm), bin centres, both ends included."""

    lambda_min: float = 400.0
    lambda_max: float = 700.0
    step: float = 5.0

    def __post_init__(self):
        if not (np.isfinite(self.lambda_min) and np.isfinite(self.lambda_max) and np.isfinite(self.step)):
            raise ValueError("wavelength grid: bounds and step must be finite numbers")
        if self.step <= 0:
            raise ValueError(f"wavelength grid: step must be > 0 nm, got {self.step}")
        if self.lambda_min >= self.lambda_max:
            raise ValueError(
                f"wavelength grid: minimum {self.lambda_min} nm must be below maximum {self.lambda_max} nm"
            )
        if self.lambda_min < _MIN_NM or self.lambda_max > _MAX_NM:
            raise ValueError(
                f"wavelength grid: {self.lambda_min}-{self.lambda_max} nm is outside the observer's "
                f"{_MIN_NM:.0f}-{_MAX_NM:.0f} nm"
            )

    @cached_property
    def wavelengths(self) -> np.ndarray:
        """(n,) float64 nm."""
        n = int(np.floor((self.lambda_max - self.lambda_min) / self.step + 1e-9)) + 1
        return self.lambda_min + self.step * np.arange(n, dtype=np.float64)

    @property
    def n(self) -> int:
        return len(self.wavelengths)

    @cached_property
    def bin_edges(self) -> np.ndarray:
        """(n+1,) nm: the bin of sample i is [edges[i], edges[i+1]]."""
        return np.concatenate([self.wavelengths - self.step / 2, [self.wavelengths[-1] + self.step / 2]])


DEFAULT_GRID = WavelengthGrid()


def _bin_integrals(table_wl: np.ndarray, table_values: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Integral of a tabulated function (linear interpolation, zero outside) over each bin."""
    fine_step = 0.1
    out = np.empty((len(edges) - 1,) + table_values.shape[1:])
    for i in range(len(edges) - 1):  # loop over bins (tens), once per grid
        m = max(2, int(np.ceil((edges[i + 1] - edges[i]) / fine_step)) + 1)
        x = np.linspace(edges[i], edges[i + 1], m)
        cols = [np.interp(x, table_wl, table_values[:, k], left=0.0, right=0.0) for k in range(table_values.shape[1])]
        out[i] = _trapezoid(np.stack(cols, axis=1), x, axis=0)
    return out


@dataclass
class SpectralConverter:
    """Converts between spectra on a grid and linear Rec.709 RGB (D65 white)."""

    grid: WavelengthGrid = field(default_factory=WavelengthGrid)

    # --- tables on the grid --------------------------------------------------------------
    @cached_property
    def cmf_weights(self) -> np.ndarray:
        """(n, 3): integral of x-bar, y-bar, z-bar over each bin (so XYZ = spectrum @ weights)."""
        colour = _colour()
        cmfs = colour.MSDS_CMFS[_OBSERVER]
        return _bin_integrals(cmfs.wavelengths, cmfs.values, self.grid.bin_edges)

    @cached_property
    def d65(self) -> np.ndarray:
        """(n,) the D65 relative spectral power at the grid points."""
        colour = _colour()
        sd = colour.SDS_ILLUMINANTS["D65"]
        return np.interp(self.grid.wavelengths, sd.wavelengths, sd.values)

    @cached_property
    def white_illuminant(self) -> np.ndarray:
        """(n,) float64: the spectrum of a white (1, 1, 1) light of unit strength: D65 scaled to Y = 1."""
        return self.d65 / float(self.d65 @ self.cmf_weights[:, 1])

    @cached_property
    def xyz_to_rgb_matrix(self) -> np.ndarray:
        """3x3 XYZ -> linear Rec.709 RGB, derived from the primaries and D65 white point."""
        colour = _colour()
        cs = colour.RGB_COLOURSPACES["sRGB"]
        npm = colour.normalised_primary_matrix(cs.primaries, cs.whitepoint)
        return np.linalg.inv(npm)

    @cached_property
    def rgb_weights(self) -> np.ndarray:
        """(n, 3): spectrum @ rgb_weights = linear RGB, white-balanced so white light -> (1, 1, 1)."""
        w = self.cmf_weights @ self.xyz_to_rgb_matrix.T
        white_rgb = self.white_illuminant @ w
        return w / white_rgb[None, :]

    @cached_property
    def _mallett_basis(self) -> np.ndarray:
        """(n, 3): the Mallett-Yuksel reflectance basis for R, G, B at the grid points."""
        colour = _colour()
        basis = colour.recovery.MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019
        wl = basis.wavelengths
        # Outside 380-780 nm the basis is held constant (it is flat there anyway).
        cols = [np.interp(self.grid.wavelengths, wl, basis.values[:, k]) for k in range(3)]
        b = np.stack(cols, axis=1)
        b = b / b.sum(axis=1, keepdims=True)  # exactly 1 for white after interpolation
        # Point-sampled on our bins the basis no longer round-trips exactly (up to 0.9 % in R on
        # the 10 nm grid: docs/physics.md section 1.4). M[k, c] = RGB channel c of basis k under
        # the white illuminant; B M^-T round-trips every colour exactly. White's row of M is
        # (1, 1, 1) (rgb_weights' white balance), so the rows still sum to 1.
        # A grid that misses most of the visible (a fuzzed 360-365 nm) leaves M far from the
        # identity or singular: there the basis stays uncalibrated, as it stays bounded in [0, 1].
        m = (b * self.white_illuminant[:, None]).T @ self.rgb_weights
        if not np.all(np.isfinite(m)) or np.abs(m - np.eye(3)).max() > 0.05:
            return b
        cal = b @ np.linalg.inv(m).T
        return cal if cal.min() >= 0 and cal.max() <= 1 else b

    @cached_property
    def _reflectance_basis_t(self) -> np.ndarray:
        """(3, n) float64 contiguous: the Mallett-Yuksel basis, one row per channel (the kernel's table)."""
        return np.ascontiguousarray(self._mallett_basis.T)

    @cached_property
    def emission_basis(self) -> np.ndarray:
        """(3, n) float64: the basis times the white illuminant, one row per channel: a light of
        colour c with max(c) = 1 emits c @ emission_basis (the tabulated uplift of illuminant_from_rgb)."""
        return np.ascontiguousarray((self._mallett_basis * self.white_illuminant[:, None]).T)

    # --- conversions ---------------------------------------------------------------------
    def to_xyz(self, spectra: np.ndarray) -> np.ndarray:
        """(..., n) -> (..., 3) CIE XYZ."""
        return np.asarray(spectra, dtype=np.float64) @ self.cmf_weights

    def to_rgb(self, spectra: np.ndarray) -> np.ndarray:
        """(..., n) spectral radiance -> (..., 3) float32 linear Rec.709 RGB."""
        s = np.asarray(spectra)
        w = self.rgb_weights.astype(s.dtype if s.dtype in (np.float32, np.float64) else np.float64)
        return (s @ w).astype(np.float32)

    def reflectance_from_rgb(self, rgb) -> np.ndarray:
        """(..., 3) linear RGB reflectance -> (..., n) spectrum (Mallett & Yuksel 2019).

        Bounded in [0, 1] for inputs in [0, 1]; inputs are clipped to [0, 1] first, since a
        reflectance above 1 would create energy.
        """
        if kernels_enabled():
            rows = _rgb_rows(rgb)
            if rows is not None:
                return self._uplift(rgb, rows, self._reflectance_basis_t, False)
        rgb = np.clip(np.asarray(rgb, dtype=np.float64), 0.0, 1.0)
        return rgb @ self._mallett_basis.T

    def illuminant_from_rgb(self, rgb) -> np.ndarray:
        """(..., 3) linear RGB light colour -> (..., n) emission spectrum; (1, 1, 1) -> RGB (1, 1, 1).

        The colour is split into a scale (its maximum) times a [0, 1] reflectance-like spectrum
        that multiplies the white illuminant, so colours brighter than 1 keep their intensity.
        """
        if kernels_enabled():
            rows = _rgb_rows(rgb)
            if rows is not None:
                return self._uplift(rgb, rows, self.emission_basis, True)
        rgb = np.maximum(np.asarray(rgb, dtype=np.float64), 0.0)
        scale = rgb.max(axis=-1, keepdims=True)
        shape = np.where(scale > 0, rgb / np.where(scale > 0, scale, 1.0), 0.0)
        return scale * self.reflectance_from_rgb(shape) * self.white_illuminant

    def _uplift(self, rgb, rows: np.ndarray, basis_t: np.ndarray, as_light: bool) -> np.ndarray:
        """reflectance_from_rgb / illuminant_from_rgb by _uplift_kernel: (..., n) float64."""
        out = np.empty((rows.shape[0], basis_t.shape[1]))
        _uplift_kernel(rows, basis_t, as_light, out)
        return out.reshape(np.shape(rgb)[:-1] + (basis_t.shape[1],))

    def blackbody(self, temperature_k) -> np.ndarray:
        """Planck spectrum at temperature(s) T (K), scaled to Y = 1 like the white illuminant."""
        colour = _colour()
        temps = np.atleast_1d(np.asarray(temperature_k, dtype=np.float64))
        if np.any(~np.isfinite(temps)) or np.any(temps <= 0):
            raise ValueError(f"blackbody temperature must be a positive number of kelvin, got {temperature_k}")
        shape = colour.SpectralShape(self.grid.wavelengths[0], self.grid.wavelengths[-1], self.grid.step)
        rows = []
        for t in temps:
            import warnings

            with warnings.catch_warnings():  # "shape could not be honoured": colour rounds odd steps
                warnings.simplefilter("ignore")
                values = colour.sd_blackbody(t, shape).values[: self.grid.n]
            if len(values) < self.grid.n:  # colour's rounding dropped the last sample: Planck on the grid
                values = colour.colorimetry.planck_law(self.grid.wavelengths * 1e-9, t) * 1e-9
            rows.append(values)
        out = np.stack(rows)
        out = out / (out @ self.cmf_weights[:, 1])[:, None]
        return out.reshape(np.shape(temperature_k) + (self.grid.n,))


def _rgb_rows(rgb) -> np.ndarray | None:
    """``rgb`` (..., 3) as (B, 3) float32/float64 rows for _uplift_kernel (float32 stays float32:
    widening it in the kernel is exact); None for input the NumPy lines handle (or reject)."""
    a = np.asarray(rgb)
    if a.ndim == 0 or a.shape[-1] != 3:
        return None
    if a.dtype != np.float32:
        a = a.astype(np.float64, copy=False)
    return a.reshape(-1, 3)


@njit
def _uplift_kernel(rgb, basis_t, as_light, out):
    """Per row of ``rgb`` (B, 3): ``out[b] = rgb[b] @ basis_t`` with the colour clipped to [0, 1]
    (a reflectance), or, ``as_light``, split into its maximum s times a [0, 1] shape:
    ``s * (shape @ basis_t)`` (basis_t = emission_basis). NaN propagates as through the NumPy lines."""
    for b in range(rgb.shape[0]):
        r, g, bl = np.float64(rgb[b, 0]), np.float64(rgb[b, 1]), np.float64(rgb[b, 2])
        scale = 1.0
        if as_light:
            r, g, bl = (0.0 if r < 0.0 else r), (0.0 if g < 0.0 else g), (0.0 if bl < 0.0 else bl)
            scale = r
            if g > scale or g != g:
                scale = g
            if (bl > scale or bl != bl) and scale == scale:
                scale = bl
            if scale > 0.0:
                r, g, bl = r / scale, g / scale, bl / scale
            else:
                r = g = bl = 0.0
        r = 0.0 if r < 0.0 else (1.0 if r > 1.0 else r)
        g = 0.0 if g < 0.0 else (1.0 if g > 1.0 else g)
        bl = 0.0 if bl < 0.0 else (1.0 if bl > 1.0 else bl)
        for k in range(basis_t.shape[1]):
            out[b, k] = scale * (r * basis_t[0, k] + g * basis_t[1, k] + bl * basis_t[2, k])
