"""Render settings: the knobs of one render, with their defaults and validation.

The names match the Blender-facing contract (``scene.opal``), so the Blender layer copies them
one to one. Settings are frozen: a render's settings never change under it (``dataclasses.replace``
makes a variant). Numbers given as NumPy scalars become Python numbers, and whole floats given
for counts become ints (``samples=16.0`` is 16), so equal settings compare and hash equal;
everything else is checked by ``validate`` (a SceneError naming the setting and the rule).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields

import numpy as np

from .checks import COORD_LIMIT, SceneError, as_number as _number, number_text as _g
from ..spectral.spectrum import _MAX_NM, _MIN_NM, WavelengthGrid
from ..util.jit import KERNEL_MODES

__all__ = ["RenderSettings", "DISPERSION_SAMPLING", "EYE_ONLY_SETTINGS", "BACKENDS", "MAX_WAVELENGTHS",
           "MIN_WAVELENGTHS", "FEW_WAVELENGTHS", "film_bytes", "AUTO_LIGHT_PATHS_PER_SAMPLE",
           "AUTO_LIGHT_PATHS_RANGE", "auto_light_paths"]

DISPERSION_SAMPLING = ("SPLIT", "SAMPLE")
BACKENDS = ("auto", "embree", "numpy", "brute")

#: Settings only the eye pass reads: changing them keeps a prepared scene and its light pass.
EYE_ONLY_SETTINGS = frozenset({"samples", "round_samples", "tile_size", "filter_width", "time_limit", "spectral_exr",
                               "diffuse_bounces", "glossy_bounces", "transmission_bounces", "volume_bounces", "adaptive_threshold",
                               "adaptive_min_samples", "grating_footprint", "blue_noise", "fresnel_split",
                               "film_transparent", "film_transparent_glass"})

#: The wavelength grid holds 2 to 4001 samples (360-830 nm at 0.1175 nm at most); below 16 the
#: colours are coarse (a warning, not an error).
MIN_WAVELENGTHS, MAX_WAVELENGTHS, FEW_WAVELENGTHS = 2, 4001, 16

# name -> (lowest, highest) for the integer settings
_INT_RANGES = {
    "samples": (1, 1 << 24),
    "light_paths": (0, 10**10),
    "max_bounces": (0, 1024),
    "diffuse_bounces": (0, 1024),
    "glossy_bounces": (0, 1024),
    "transmission_bounces": (0, 1024),
    "volume_bounces": (0, 1024),
    "seed": (0, 2**64 - 1),
    "threads": (0, 1024),
    "tile_size": (1, 65536),
    "round_samples": (1, 1 << 16),
    "adaptive_min_samples": (0, 1 << 24),
    "dispersion_branches": (1, 1024),
}
_FLOAT_FIELDS = ("element_size", "wavelength_min", "wavelength_max", "wavelength_step", "time_limit", "filter_width",
                 "adaptive_threshold")
_WORDS = {"samples": "samples", "light_paths": "light paths", "max_bounces": "max bounces", "seed": "seed",
          "diffuse_bounces": "diffuse bounces", "glossy_bounces": "glossy bounces",
          "transmission_bounces": "transmission bounces", "volume_bounces": "volume bounces",
          "threads": "threads", "tile_size": "tile size", "round_samples": "round samples",
          "element_size": "element size", "wavelength_min": "wavelength min", "wavelength_max": "wavelength max",
          "wavelength_step": "wavelength step", "time_limit": "time limit", "filter_width": "filter width",
          "adaptive_threshold": "adaptive threshold", "adaptive_min_samples": "adaptive min samples",
          "dispersion_branches": "dispersion branches"}
_BOOL_FIELDS = ("grating_footprint", "caustic_splat", "blue_noise", "film_transparent", "film_transparent_glass",
                "dispersion_importance",
                "dispersion_white_reflection", "fresnel_split", "splat_bounce")
FILTER_WIDTH_MAX = 100.0  # pixels

#: light_paths=None (automatic): this many light paths per camera sample (pixels x samples),
#: within the range. A caustic's noise in a pixel goes with the light paths landing in it, and
#: the eye pass's with the samples, so the two stay in proportion: a 64 x 64 preview at up to
#: 16 samples takes 65 536 paths (about a tenth of a second), any full-size render the 1 M cap.
#: Measured on the Cycles parity mirror sphere (64 x 64, 32 samples, 4 seeds; docs/benchmarks.md
#: "Cycles parity on an idle machine", item 2): the floor's error with its glossy caustic 0.00417 / 0.00278 /
#: 0.00243 at 0.25 / 1 / 4 paths per sample (Cycles' at 64 samples: 0.012), for 0.44 / 0.59 /
#: 1.38 CPU s: past one path per sample the eye pass's noise dominates and the paths only cost.
AUTO_LIGHT_PATHS_PER_SAMPLE = 1
AUTO_LIGHT_PATHS_RANGE = (65_536, 1_000_000)


def auto_light_paths(width: int, height: int, samples: int) -> int:
    """The light paths of an automatic setting for a ``width`` x ``height`` image at ``samples``."""
    lo, hi = AUTO_LIGHT_PATHS_RANGE
    return int(min(max(AUTO_LIGHT_PATHS_PER_SAMPLE * int(width) * int(height) * int(samples), lo), hi))


def _wavelength_count(lo: float, hi: float, step: float) -> float:
    """Samples lo + i * step <= hi (as WavelengthGrid counts them), in float so it cannot overflow."""
    return math.floor((hi - lo) / step + 1e-9) + 1 if (hi - lo) / step < 1e15 else math.inf


def _step_text(step: float, ok) -> str:
    """``step`` for a message with the fewest digits (3 or more) whose printed value ``ok`` still accepts
    (``step`` itself is accepted): a bound the user can type, never one the check refuses."""
    for digits in range(3, 18):
        text = f"{step:.{digits}g}"
        if ok(float(text)):
            return text
    return repr(step)


def film_bytes(width: int, height: int, wavelengths: int, spectral: bool = False) -> int:
    """Memory (bytes) of a render's film (core/render/film.py), per pixel: the RGB sums of the image,
    of its four non-Direct parts and of the two denoising features, adaptive sampling's half
    buffer (8 float32 triples), the finished image's RGB and six passes (7 triples), 3 triples of
    temporaries while it is made, and the counts (4 floats). With ``spectral`` (a spectral EXR is
    written) also two (H, W, n) float32 arrays: the spectral sums, plus either a partial
    result's copy (previews) or the EXR's contiguous channels (the final result divides the sums
    in place)."""
    px = int(width) * int(height)
    return px * ((2 * 4 * int(wavelengths) if spectral else 0) + 4 * 3 * (8 + 7 + 3) + 4 * 4)


@dataclass(frozen=True)
class RenderSettings:
    samples: int = 16                 # eye samples per pixel
    light_paths: int | None = None    # light-pass paths (caustics); None: automatic (auto_light_paths)
    element_size: float = 0.0         # illumination-map element edge (m); 0: automatic from the paths
    wavelength_min: float = 400.0     # nm
    wavelength_max: float = 700.0     # nm
    wavelength_step: float = 5.0      # nm
    # bounces along a path, as Cycles counts them (defaults: Cycles'): all kinds together, and
    # per kind (mirror and glossy reflection, refraction, diffuse); 0 diffuse bounces = direct light only
    max_bounces: int = 12
    diffuse_bounces: int = 4
    glossy_bounces: int = 4
    transmission_bounces: int = 12
    # scatterings in participating media (Cycles' Volume bounces, default 0: single scattering,
    # the scattered path only gathers emission; docs/physics.md section 15)
    volume_bounces: int = 0
    seed: int = 0
    dispersion_sampling: str = "SAMPLE"  # 'SPLIT': one ray per wavelength; 'SAMPLE': one stochastic wavelength
    spectral_exr: str = ""            # path of a spectral EXR to write; empty: off
    time_limit: float = 0.0           # seconds, 0: none (stops between sample rounds)
    threads: int = 0                  # 0: all cores
    backend: str = "auto"             # ray casting: 'auto' | 'embree' | 'numpy' | 'brute' (tests)
    tile_size: int = 64               # pixels per tile side
    round_samples: int = 16           # samples per pixel per progressive round (docs/physics.md section 9.1)
    filter_width: float = 1.5         # Blackman-Harris reconstruction filter width (pixels)
    # adaptive sampling (Cycles' Noise Threshold, core/render/adaptive.py): pixels stop sampling once
    # their error estimate is below the threshold; 0: off (every pixel takes every sample).
    # Cycles' default when on is 0.01. Min samples 0: automatic, as Cycles (64 at 0.01)
    adaptive_threshold: float = 0.0
    adaptive_min_samples: int = 0
    # gratings: average the pattern over each sample's pixel footprint (ray differentials,
    # docs/physics.md section 3.7); False: point-sample it at the sample's (u, v)
    grating_footprint: bool = True
    # caustics seen directly by the camera: light paths joined to the camera and splatted into
    # the image (core/integrators/light/camera_splat.py, docs/physics.md section 4.9); False: looked up in the
    # caustic map like every other caustic
    caustic_splat: bool = True
    # Film > Transparent (Cycles): camera rays that meet no surface see nothing (black) and the
    # result's alpha is each pixel's coverage (RenderResult.alpha; docs/physics.md section 6.11)
    film_transparent: bool = False
    # ... and Cycles' Transparent Glass: the world seen through smooth glass (only refractions
    # since the camera) is transparent too, alpha lowered by the mean throughput (section 6.11)
    film_transparent_glass: bool = False
    # pixels share one low-discrepancy sequence in a blue-noise order, as Cycles' default
    # pattern (core/sampling/sampler.py, docs/physics.md section 6.6); False: each pixel its own sequence
    blue_noise: bool = True
    # the estimator's choices below are on by default; each switch exists so a benchmark or a test
    # can measure a render without it (benchmarks/bench_dispersion.py, benchmarks/caustic_sphere.py)
    # SAMPLE at dispersive glass (core/transport/wavelengths.py, docs/physics.md section 2.6): mono
    # rays per white ray (pbrt-v4's hero wavelengths), the wavelengths importance-sampled by the
    # image's sensitivity (False: uniform over the grid), and the reflect / refract choice made on
    # the white ray at smooth glass (False: the white ray splits at the hit, each child chooses)
    dispersion_branches: int = 4
    dispersion_importance: bool = True
    dispersion_white_reflection: bool = True
    # camera rays take both Fresnel branches at their first smooth glass hit
    # (core/integrators/eye/fresnel_split.py, docs/physics.md section 4.12); False: one branch by F
    fresnel_split: bool = True
    # light paths landing after glass continue by a diffuse bounce and splat where they land again
    # (core/integrators/light/splat_bounce.py, docs/physics.md section 4.11; only with the camera
    # splat); False: the eye pass reads that light from the caustic map after its own bounce
    splat_bounce: bool = True
    # the hot NumPy functions' compiled kernels (core/util/jit.py): 'auto' runs them where numba is
    # available, 'numpy' forces the NumPy reference (the tests' and tools/example_images.py's
    # bit-for-bit check of refactors); the stats line names the path that ran
    kernels: str = "auto"

    def __post_init__(self):
        # normalise number types only (never raise here: validate() names what is wrong)
        for f in fields(self):
            val = getattr(self, f.name)
            if isinstance(val, (bool, np.bool_)):
                continue
            new = val
            if f.name in _INT_RANGES:
                if isinstance(val, np.integer):
                    new = int(val)
                elif isinstance(val, (float, np.floating)) and math.isfinite(val) and float(val).is_integer():
                    new = int(val)
            elif f.name in _FLOAT_FIELDS:
                if isinstance(val, (np.integer, np.floating)) and not isinstance(val, np.complexfloating):
                    new = float(val)
            elif isinstance(val, np.str_):
                new = str(val)
            if new is not val:
                object.__setattr__(self, f.name, new)

    def grid(self) -> WavelengthGrid:
        self._validate_grid()
        try:
            return WavelengthGrid(self.wavelength_min, self.wavelength_max, self.wavelength_step)
        except ValueError as e:
            raise SceneError(str(e)) from None

    def _validate_grid(self) -> int:
        lo = _number(self.wavelength_min, "wavelength min")
        hi = _number(self.wavelength_max, "wavelength max")
        step = _number(self.wavelength_step, "wavelength step")
        if step <= 0:
            raise SceneError(f"wavelength grid: step must be > 0 nm, got {step}")
        if lo >= hi:
            raise SceneError(f"wavelength grid: minimum {lo} nm must be below maximum {hi} nm")
        if lo < _MIN_NM or hi > _MAX_NM:
            raise SceneError(f"wavelength grid: {lo}-{hi} nm is outside the observer's {_MIN_NM:.0f}-{_MAX_NM:.0f} nm")
        n = _wavelength_count(lo, hi, step)
        def enough(s): return _wavelength_count(lo, hi, s) >= FEW_WAVELENGTHS  # noqa: E704
        def not_too_many(s): return _wavelength_count(lo, hi, s) <= MAX_WAVELENGTHS  # noqa: E704
        if n < MIN_WAVELENGTHS:
            raise SceneError(f"wavelength step {step:g} nm leaves {n} sample from {_g(lo)} to {_g(hi)} nm: at "
                             f"least {MIN_WAVELENGTHS} are needed, and fewer than {FEW_WAVELENGTHS} make colours "
                             f"coarse (use a step of at most {_step_text((hi - lo) / (FEW_WAVELENGTHS - 1), enough)} nm)")
        if n > MAX_WAVELENGTHS:
            shown = f"{n:.0f}" if n < 1e15 else "over 1e15"
            raise SceneError(f"wavelength step {step:g} nm gives {shown} samples from {_g(lo)} to {_g(hi)} nm, "
                             f"more than the {MAX_WAVELENGTHS} allowed (use a step of at least "
                             f"{_step_text((hi - lo) / (MAX_WAVELENGTHS - 1), not_too_many)} nm)")
        return int(n)

    def warnings(self) -> list[str]:
        """Things about valid settings the user should know (call after validate)."""
        out = []
        n = _wavelength_count(float(self.wavelength_min), float(self.wavelength_max), float(self.wavelength_step))
        if n < FEW_WAVELENGTHS:
            out.append(f"wavelength step {_g(self.wavelength_step)} nm leaves only {n} samples from "
                       f"{_g(self.wavelength_min)} to {_g(self.wavelength_max)} nm: colours are coarse below "
                       f"{FEW_WAVELENGTHS} (use a step of at most "
                       f"{_g((self.wavelength_max - self.wavelength_min) / (FEW_WAVELENGTHS - 1))} nm)")
        return out

    def validate(self) -> None:
        """Raise SceneError with a readable message for settings that cannot work: every
        setting's type (counts are whole numbers, lengths and times finite numbers, names
        strings) and range, the wavelength grid (2-4001 samples inside 360-830 nm) and the
        backend (known, and importable)."""
        vals = {}
        for name, (lo, hi) in _INT_RANGES.items():
            if name == "light_paths" and self.light_paths is None:
                continue  # automatic
            v = _number(getattr(self, name), _WORDS[name], integer=True)
            if v < lo:
                rule = {"samples": "at least 1", "tile_size": "at least 1", "round_samples": "at least 1",
                        "dispersion_branches": "at least 1"}.get(name, ">= 0")
                raise SceneError(f"{_WORDS[name]} must be {rule}, got {v}")
            if v > hi:
                raise SceneError(f"{_WORDS[name]} {v} is above the maximum {hi}")
            vals[name] = v
        for name in _FLOAT_FIELDS:
            vals[name] = _number(getattr(self, name), _WORDS[name])
        if vals["element_size"] < 0 or vals["element_size"] > COORD_LIMIT:
            raise SceneError(f"element size must be >= 0 m (0: automatic) and at most {COORD_LIMIT:g} m, "
                             f"got {vals['element_size']}")
        if vals["time_limit"] < 0:
            raise SceneError("time limit must be >= 0 seconds")
        if not 0 <= vals["filter_width"] <= FILTER_WIDTH_MAX:
            raise SceneError(f"filter width must be between 0 and {FILTER_WIDTH_MAX:g} pixels, got {vals['filter_width']}")
        if not 0 <= vals["adaptive_threshold"] <= 1:
            raise SceneError(f"adaptive threshold (noise threshold) must be between 0 (off) and 1, got "
                             f"{vals['adaptive_threshold']} (Cycles' default is 0.01)")
        if not isinstance(self.dispersion_sampling, str) or self.dispersion_sampling not in DISPERSION_SAMPLING:
            raise SceneError(f"dispersion sampling must be SPLIT or SAMPLE, got {self.dispersion_sampling!r}")
        if not isinstance(self.spectral_exr, (str, os.PathLike)):
            raise SceneError(f"spectral EXR must be a path (a string), got {type(self.spectral_exr).__name__}")
        for name in _BOOL_FIELDS:
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise SceneError(f"{name.replace('_', ' ')} must be True or False, got {getattr(self, name)!r}")
        if not isinstance(self.kernels, str) or self.kernels not in KERNEL_MODES:
            raise SceneError(f"kernels must be one of {', '.join(KERNEL_MODES)}, got {self.kernels!r}")
        _validate_backend(self.backend)
        self._validate_grid()


def _validate_backend(backend) -> None:
    if not isinstance(backend, str) or backend.strip().lower() not in BACKENDS:
        raise SceneError(f"unknown ray-casting backend {backend!r}: expected one of {', '.join(BACKENDS)}")
    b = backend.strip().lower()
    if b == "auto":
        env = os.environ.get("OPAL_ACCEL", "").strip().lower()
        if env and env != "auto" and env not in BACKENDS:
            raise SceneError(f"OPAL_ACCEL={env!r}: expected 'embree', 'numpy' or 'brute'")
        b = env if env and env != "auto" else b
    if b == "embree":
        from ..accel import available_backends

        if "embree" not in available_backends():
            raise SceneError("backend 'embree' requested but embreex cannot be imported (pip install embreex)")
