"""The film: per-pixel sums of the eye pass's tiles, and the finished image they make.

Tiles add their sums (and the parts that are not Direct light) into the film with the number of
samples they took; ``result()`` divides by each pixel's count, so a partial image after a cancel
or a time limit is a correct mean of the samples that were taken.

The film sums linear Rec.709 RGB: a tile's (P, n) spectral sums are converted when the tile is
added (``SpectralConverter.to_rgb``, one (n, 3) matrix), which is exact up to float32 rounding
because the RGB image is a linear map of the spectrum (sum of conversions = conversion of the
sum). RGB rather than CIE XYZ because everything read from the film is RGB (the image, the
passes, adaptive sampling's error estimate), so nothing is converted twice. The (H, W, n)
spectral sums (61 float32 per pixel: 506 MB at 1920x1080) are kept only when a spectral image is
asked for (``spectral=True``: a spectral EXR is written, or a caller wants
``RenderResult.spectral``); otherwise ``RenderResult.spectral`` is None. The RGB image is summed
the same way in both cases, so it does not depend on whether the spectral film is kept. The
spectral sums are stored wavelength-major, (n, H, W), and ``RenderResult.spectral`` is the
(H, W, n) view of them (``np.moveaxis``), so each wavelength's image is already the contiguous
(H, W) plane a spectral EXR's channel needs (core/render/output.py copies nothing), and the final
result divides the sums in place: a spectral render holds one (n, H, W) array, not three.

The last check of every result (``black_non_finite``): a pixel holding a NaN or an infinity in
the image, a pass or the spectrum is set to black in all of them, and the result's warnings say
how many (an overflow the grating or light arithmetic did not prevent is never a silent success;
the CLI prints every warning, with ``-q`` too).

Then ``into_gamut``: a pixel whose spectrum lies outside the Rec.709 gamut (a grating's
spectral colours) has a negative linear-RGB channel; it is desaturated towards its own
luminance until none is negative (luminance and hue kept), its passes with it, and the
result's stats count such pixels (``out_of_gamut_pixels``; docs/physics.md section 10.2). The
spectral image is not changed: it is never negative.

Passes (AOVs for the compositor, (H, W, 3) linear Rec.709): Direct (light reaching diffuse
surfaces by shadow rays, also seen through mirrors and glass), Caustics (the light pass),
Diffraction (gratings). Combined = Direct + Caustics + Diffraction + emitted light seen (the
world and emissive surfaces, directly or via specular paths). Denoising Albedo and Denoising
Normal are Cycles' feature passes (intern/cycles/kernel/film/denoising_passes.h), the mean over
a pixel's samples of the first diffuse surface's albedo (linear RGB, times the throughput of the
mirrors and glass before it) and of its shading normal in Cycles' camera space (x right, y up,
z forward; not renormalised after averaging, zero where a sample saw no diffuse surface), which
is what OpenImageDenoise and Blender's Denoise node take (docs/physics.md section 10.6).

With adaptive sampling (core/render/adaptive.py) the film also keeps the RGB sum of the samples of the
even rounds (the "A" half of Cycles' adaptive buffer) and each pixel's state: a round's tile may
cover only its active pixels (``pixels``), and ``update_active`` decides which pixels sample in
the tile's next round.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import adaptive as _adaptive
from .plan import RenderPlan
from ..scene.checks import SceneError
from ..spectral.spectrum import SpectralConverter

__all__ = ["Film", "RenderResult", "black_non_finite", "into_gamut", "tile_parts_rgb", "camera_space_rotation", "FEATURE_PASSES", "NO_SPECTRAL",
           "keeps_spectral"]

#: Cycles' names of the denoising feature passes (a compositor Denoise node links to them)
FEATURE_PASSES = ("Denoising Albedo", "Denoising Normal")

PARTS = ("background", "indirect", "caustics", "diffraction")  # a TileResult's non-Direct parts

#: why a result has no spectral image (RenderResult.spectral is None)
NO_SPECTRAL = ("this render kept no spectral film (only RGB): set RenderSettings.spectral_exr, or pass "
               "spectral_film=True to render / render_prepared, to keep the spectral image")


def keeps_spectral(settings, spectral_film: bool | None = None) -> bool:
    """Whether a render with ``settings`` (settings.RenderSettings) keeps its (H, W, n) spectral
    film: ``spectral_film`` if given, else whether the settings write a spectral EXR."""
    return bool(settings.spectral_exr) if spectral_film is None else bool(spectral_film)


def tile_parts_rgb(conv: SpectralConverter, tile) -> dict:
    """An eye_pass.TileResult's non-Direct parts as (P, 3) RGB (None where it wrote none)."""
    return {name: None if getattr(tile, name) is None else conv.to_rgb(getattr(tile, name)) for name in PARTS}


@dataclass
class RenderResult:
    spectral: np.ndarray | None   # (H, W, n) float32 mean spectral radiance, row 0 at the top (a view
    #                               of (n, H, W) planes); None unless the render kept its spectral film
    rgb: np.ndarray               # (H, W, 3) float32 linear Rec.709
    wavelengths: np.ndarray       # (n,) nm
    samples: int                  # samples per pixel actually taken (the minimum over pixels)
    cancelled: bool
    plan: RenderPlan
    warnings: list[str] = field(default_factory=list)
    stats: dict = field(default_factory=dict)
    passes: dict = field(default_factory=dict)  # 'Direct', 'Indirect', 'Caustics', 'Diffraction',
    #                                             'Denoising Albedo', 'Denoising Normal': (H, W, 3)
    sample_counts: np.ndarray | None = None  # (H, W) float32 samples each pixel took (adaptive sampling varies them)
    # (H, W) float32 coverage: the share of a pixel's samples whose camera ray hit a surface
    # within the clip range (Film > Transparent's alpha; the world seen directly is 0)
    alpha: np.ndarray | None = None


def camera_space_rotation(camera) -> np.ndarray:
    """(3, 3) world -> Cycles camera space (x right, y up, z the view direction: Blender's camera
    axes with z flipped, intern/cycles/blender/camera.cpp blender_camera_matrix), for normals."""
    m = np.asarray(camera.matrix, np.float64)[:3, :3]
    rot = m / np.linalg.norm(m, axis=0, keepdims=True)
    return (rot * np.array([1.0, 1.0, -1.0])).T.astype(np.float32)


class Film:
    """Accumulates tiles of one render (``height`` x ``width`` pixels, ``conv``'s grid).

    ``to_camera``: the (3, 3) world -> camera rotation of the Denoising Normal pass (identity if
    None). ``adaptive``: keep the half buffer and pixel states of adaptive sampling.
    ``spectral``: keep the (H, W, n) spectral sums too (for a spectral EXR); otherwise
    ``self.spectral`` is None and only RGB is summed."""

    def __init__(self, width: int, height: int, conv: SpectralConverter, to_camera=None, adaptive: bool = False,
                 spectral: bool = False):
        self.conv = conv
        self.rgb = np.zeros((height, width, 3), np.float32)  # linear Rec.709 sums of everything
        # wavelength-major (n, H, W): each wavelength's plane is one contiguous EXR channel
        self.spectral = np.zeros((conv.grid.n, height, width), np.float32) if spectral else None
        # RGB sums of the parts of the spectral sum that are not Direct light
        self.parts = {name: np.zeros((height, width, 3), np.float32) for name in PARTS}
        self.counts = np.zeros((height, width), np.float32)  # samples per pixel so far
        self.albedo = np.zeros((height, width, 3), np.float32)  # denoising feature sums
        self.normal = np.zeros((height, width, 3), np.float32)
        self.alpha = np.zeros((height, width), np.float32)  # coverage sums (samples that hit a surface)
        self.to_camera = np.eye(3, dtype=np.float32) if to_camera is None else np.asarray(to_camera, np.float32)
        self.adaptive = bool(adaptive)
        if self.adaptive:
            self.rgb_a = np.zeros((height, width, 3), np.float32)  # RGB sum of the even rounds' samples
            self.counts_a = np.zeros((height, width), np.float32)
            self.active = np.ones((height, width), bool)  # pixels that sample in their tile's next round

    @classmethod
    def for_region(cls, camera, region, conv: SpectralConverter, adaptive: bool = False, spectral: bool = False):
        """((x0, y0, x1, y1), an empty Film) for ``region`` of ``camera``'s image (None: all of
        it; rows from the top). SceneError for a region outside the image."""
        w, h = int(camera.width), int(camera.height)
        x0, y0, x1, y1 = region if region is not None else (0, 0, w, h)
        if not (0 <= x0 < x1 <= w and 0 <= y0 < y1 <= h):
            raise SceneError(f"render region {region} is outside the {camera.width}x{camera.height} image")
        return (x0, y0, x1, y1), cls(x1 - x0, y1 - y0, conv, camera_space_rotation(camera), adaptive, spectral)

    def add_tile(self, x0: int, y0: int, x1: int, y1: int, tile, samples: int, pixels=None,
                 half_a: bool = False) -> None:
        """Add an eye_pass.TileResult covering pixels [x0, x1) x [y0, y1) with ``samples`` each
        (``pixels``: the tile's flat pixel indices it traced, None: all; ``half_a``: its samples
        belong to adaptive sampling's half A)."""
        self.add_converted(x0, y0, x1, y1, self.conv.to_rgb(tile.film), tile_parts_rgb(self.conv, tile), samples,
                           tile.albedo, tile.normal, pixels, half_a,
                           spectral=tile.film if self.spectral is not None else None, alpha=getattr(tile, "alpha", None))

    def add_converted(self, x0: int, y0: int, x1: int, y1: int, rgb: np.ndarray, parts_rgb: dict,
                      samples: int, albedo=None, normal=None, pixels=None, half_a: bool = False,
                      spectral=None, alpha=None) -> None:
        """``add_tile`` for a tile already converted to RGB: ``rgb`` (P, 3) = ``conv.to_rgb`` of
        its spectral sums, its non-Direct parts as ``tile_parts_rgb``, and its (P, n) spectral
        sums ``spectral`` (needed, and only read, when this film keeps a spectral image), ``alpha``
        its (P,) coverage sums (TileResult.alpha; None: none hit). A Dask
        worker converts, so only RGB (and the spectral sums when asked) crosses the wire."""
        if self.spectral is not None and spectral is None:
            raise ValueError("this film keeps a spectral image: add_converted needs the tile's spectral sums")
        h, w = y1 - y0, x1 - x0
        if pixels is None:
            where = (slice(y0, y1), slice(x0, x1))
            shape = (h, w)
        else:  # a subset of the tile's pixels (distinct indices: fancy-index += is exact)
            pixels = np.asarray(pixels, np.int64)
            where = (y0 + pixels // w, x0 + pixels % w)
            shape = (len(pixels),)
        self.rgb[where] += rgb.reshape(*shape, 3)
        if self.spectral is not None:
            self.spectral[(slice(None),) + where] += np.moveaxis(spectral.reshape(*shape, -1), -1, 0)
        for name, arr in self.parts.items():
            part = parts_rgb.get(name)
            if part is not None:
                arr[where] += part.reshape(*shape, 3)
        for arr, feature in ((self.albedo, albedo), (self.normal, normal)):
            if feature is not None:
                arr[where] += feature.reshape(*shape, 3)
        if alpha is not None:
            self.alpha[where] += np.asarray(alpha, np.float32).reshape(shape)
        self.counts[where] += samples
        if self.adaptive and half_a:
            self.rgb_a[where] += rgb.reshape(*shape, 3)
            self.counts_a[where] += samples

    def active_pixels(self, x0: int, y0: int, x1: int, y1: int):
        """The tile's flat indices of the pixels that sample in its next round (None: all of
        them, or no adaptive sampling)."""
        if not self.adaptive:
            return None
        act = self.active[y0:y1, x0:x1]
        return None if act.all() else np.flatnonzero(act)

    def update_active(self, x0: int, y0: int, x1: int, y1: int, threshold: float, min_spp: int) -> int:
        """After a tile's round: which of its pixels go on sampling (core/render/adaptive.py); returns
        how many."""
        tile = (slice(y0, y1), slice(x0, x1))
        act = self.active[tile]
        if not act.any():
            return 0
        err = _adaptive.error_estimate(self.rgb[tile], self.counts[tile], self.rgb_a[tile], self.counts_a[tile])
        new = _adaptive.next_active(act, err, self.counts[tile], threshold, min_spp)
        self.active[tile] = new
        return int(new.sum())

    def sample_stats(self) -> dict:
        """Samples per pixel taken: min, mean, max."""
        c = self.counts
        if not c.size:
            return {"samples_min": 0, "samples_mean": 0.0, "samples_max": 0}
        return {"samples_min": int(c.min()), "samples_mean": float(c.mean()), "samples_max": int(c.max())}

    def result(self, plan: RenderPlan, cancelled: bool, warnings, stats, final: bool = False,
               splat=None) -> RenderResult:
        """The mean image so far, with its passes. ``final``: nothing is added after this, so
        the spectral mean is divided in place in the film's own buffer (no second (H, W, n)
        copy; the film keeps no spectral sums afterwards). ``splat``: the light pass's camera
        splat over this film's pixels, (RGB (H, W, 3), spectrum (H, W, n) or None)
        (core/integrators/light/camera_splat.py), added once to Combined and Caustics: it is not an eye-pass sample."""
        scale = (1.0 / np.maximum(self.counts, 1.0))[..., None]
        spectral = None
        if self.spectral is not None:
            if final:
                spectral, self.spectral = self.spectral, None
                spectral *= scale[..., 0]
            else:
                spectral = self.spectral * scale[..., 0]
            spectral = np.moveaxis(spectral, 0, -1)  # (H, W, n) view of the (n, H, W) planes
            if splat is not None and splat[1] is not None:
                spectral += splat[1]
        rgb = self.rgb * scale
        caustics = self.parts["caustics"] * scale
        if splat is not None:  # the RGB film sums RGB either way: the splat's RGB goes to it
            caustics = caustics + splat[0]
            rgb = rgb + splat[0]
        diffraction = self.parts["diffraction"] * scale
        indirect = self.parts["indirect"] * scale
        passes = {"Direct": rgb - self.parts["background"] * scale - indirect - diffraction - caustics,
                  "Indirect": indirect, "Caustics": caustics, "Diffraction": diffraction,
                  "Denoising Albedo": self.albedo * scale,
                  "Denoising Normal": (self.normal * scale) @ self.to_camera.T}
        samples = int(self.counts.min()) if self.counts.size else 0
        stats = dict(stats, **self.sample_stats())
        warnings = list(warnings)
        bad = black_non_finite(rgb, spectral, passes)
        mapped = into_gamut(rgb, passes)
        if mapped:
            stats["out_of_gamut_pixels"] = mapped
        if bad:
            warnings.append(f"{bad} pixel{'s' if bad != 1 else ''} of {rgb.shape[0] * rgb.shape[1]} had a non-finite "
                            f"value (NaN or infinite radiance: an overflow from the scene's numbers) and "
                            f"{'are' if bad != 1 else 'is'} black in the image and every pass")
            stats["non_finite_pixels"] = bad
        return RenderResult(spectral, rgb, self.conv.grid.wavelengths.copy(), samples, cancelled, plan,
                            warnings, stats, passes, self.counts.copy(),
                            np.minimum(self.alpha * scale[..., 0], 1.0))


#: Rec.709 luminance of linear RGB (the Y row of the RGB -> XYZ matrix)
_LUMINANCE = np.array([0.2126729, 0.7151522, 0.0721750], np.float32)
#: the radiance passes (the feature passes are not colours)
_COLOUR_PASSES = ("Direct", "Indirect", "Caustics", "Diffraction")


def _gamut_scale(px: np.ndarray, tol: np.ndarray) -> np.ndarray:
    """(P,) the largest s in [0, 1] with Y + s (rgb - Y) >= 0 in every channel, for (P, 3)
    float64 colours, channels above -tol (P,) counted as 0 (1 where none is negative; 0 where
    Y <= 0)."""
    px = np.where((px < 0) & (px > -tol[:, None]), 0.0, px)
    y = px @ _LUMINANCE.astype(np.float64)
    low = px.min(axis=1)
    s = np.where(low >= 0, 1.0, np.clip(y / np.maximum(y - low, 1e-300), 0.0, 1.0))
    return np.where((low < 0) & (y <= 0), 0.0, s)


def _desaturate(arr: np.ndarray, mask: np.ndarray, s: np.ndarray) -> None:
    """arr[mask] = Y + s (arr[mask] - Y), its own luminance Y, in place."""
    px = arr[mask].astype(np.float64)
    y = (px @ _LUMINANCE.astype(np.float64))[:, None]
    arr[mask] = (y + s[:, None] * (px - y)).astype(arr.dtype)


#: A channel counts as negative below -ROUNDING x the pixel's largest |channel|: the parts of an
#: image (its passes, and the rest: the emission seen) are float32 sums whose difference from the
#: image is rounding, and a rest of 0 that rounds to -1e-9 must not grey its whole pixel.
ROUNDING = 1e-5


def _negative(arr: np.ndarray, tol: np.ndarray) -> np.ndarray:
    """(..., ) bool: a channel of the (..., 3) colours is below -tol (three strided minima: a
    reduction over the short last axis costs several times more)."""
    return np.minimum(np.minimum(arr[..., 0], arr[..., 1]), arr[..., 2]) < -tol


def into_gamut(rgb: np.ndarray, passes: dict) -> int:
    """Pixels whose colour (or one of its parts) lies outside the Rec.709 gamut, desaturated into
    it (in place); returns how many (docs/physics.md section 10.2).

    Spectral radiance is never negative, but the narrow spectra of a grating's orders (a 5 nm
    band is a spectral colour) lie outside any RGB gamut: their linear RGB has a negative
    channel, which breaks compositing. Such a pixel moves towards its own luminance
    Y (Rec.709 weights): rgb' = Y + s (rgb - Y), hue and luminance kept, saturation reduced.
    The same affine map with the same s applies to each radiance pass and to the rest of the
    image (the emission seen: rgb less the passes), so they still add up to the image exactly;
    s is the largest value in [0, 1] that leaves no channel of any of them negative (the
    minimum over them). A part with negative luminance cannot be mapped: it is black. Channels
    within ROUNDING of 0 are rounding, not colour: they are set to 0 and map nothing."""
    names = [k for k in _COLOUR_PASSES if passes.get(k) is not None]
    parts = [passes[k] for k in names]
    others = parts + ([rgb - sum(parts)] if parts else [])  # the passes and the rest of the image
    a = np.abs(rgb)
    tol = ROUNDING * np.maximum(np.maximum(a[..., 0], a[..., 1]), a[..., 2])
    bad = _negative(rgb, tol)
    for arr in others:
        bad |= _negative(arr, tol)
    count = int(bad.sum())
    if count:
        tb = tol[bad].astype(np.float64)
        s = _gamut_scale(rgb[bad].astype(np.float64), tb)
        for arr in others:
            s = np.minimum(s, _gamut_scale(arr[bad].astype(np.float64), tb))
        for arr in [rgb] + parts:
            _desaturate(arr, bad, s)
    for arr in [rgb] + parts:  # rounding, and a part whose luminance is negative (s = 0 leaves Y < 0)
        np.maximum(arr, 0.0, out=arr)
    return count


def black_non_finite(rgb: np.ndarray, spectral, passes: dict) -> int:
    """The last finite check of a film's mean: the pixels where the image, a pass or the spectrum
    holds a NaN or an infinity are set to 0 in all of them (in place); returns how many (the
    caller warns with the count: never a silent success). Finite images are left untouched."""
    arrays = [rgb, *passes.values()] + ([spectral] if spectral is not None else [])
    # first one sum per array (a NaN or an infinity anywhere makes it non-finite; float32 values
    # cannot overflow a float64 sum): the per-pixel test below only where one is not finite
    if all(np.isfinite(np.add.reduce(a, axis=None, dtype=np.float64)) for a in arrays):
        return 0
    bad = ~np.isfinite(rgb).all(axis=-1)
    for arr in passes.values():
        bad |= ~np.isfinite(arr).all(axis=-1)
    if spectral is not None:
        bad |= ~np.isfinite(spectral).all(axis=-1)
    count = int(bad.sum())
    if count:
        for arr in arrays:
            arr[bad] = 0.0
    return count
