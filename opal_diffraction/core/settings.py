"""Render settings: the knobs of one render, with their defaults and validation.

The names match the Blender-facing contract (``scene.opal``), so the Blender layer copies them
one to one. Settings are frozen: a render's settings never change under it (``dataclasses.replace``
makes a variant).
"""

from __future__ import annotations

from dataclasses import dataclass

from .scene import SceneError
from .spectrum import WavelengthGrid

__all__ = ["RenderSettings", "DISPERSION_SAMPLING", "EYE_ONLY_SETTINGS"]

DISPERSION_SAMPLING = ("SPLIT", "SAMPLE")

#: Settings only the eye pass reads: changing them keeps a prepared scene and its light pass.
EYE_ONLY_SETTINGS = frozenset({"samples", "round_samples", "tile_size", "filter_width", "time_limit", "spectral_exr"})


@dataclass(frozen=True)
class RenderSettings:
    samples: int = 16                 # eye samples per pixel
    light_paths: int = 1_000_000      # light-pass paths (caustics)
    element_size: float = 0.0         # illumination-map element edge (m); 0: automatic from the paths
    wavelength_min: float = 400.0     # nm
    wavelength_max: float = 700.0     # nm
    wavelength_step: float = 5.0      # nm
    max_bounces: int = 8              # specular bounces along an eye path
    seed: int = 0
    dispersion_sampling: str = "SAMPLE"  # 'SPLIT': one ray per wavelength; 'SAMPLE': one stochastic wavelength
    spectral_exr: str = ""            # path of a spectral EXR to write; empty: off
    time_limit: float = 0.0           # seconds, 0: none (stops between sample rounds)
    threads: int = 0                  # 0: all cores
    backend: str = "auto"             # ray casting: 'auto' | 'embree' | 'numpy'
    tile_size: int = 64               # pixels per tile side
    round_samples: int = 8            # samples per pixel per progressive round
    filter_width: float = 1.5         # Blackman-Harris reconstruction filter width (pixels)

    def grid(self) -> WavelengthGrid:
        try:
            return WavelengthGrid(self.wavelength_min, self.wavelength_max, self.wavelength_step)
        except ValueError as e:
            raise SceneError(str(e)) from None

    def validate(self) -> None:
        """Raise SceneError with a readable message for settings that cannot work."""
        if int(self.samples) < 1:
            raise SceneError(f"samples must be at least 1, got {self.samples}")
        if int(self.light_paths) < 0 or self.element_size < 0:
            raise SceneError("light paths and element size must be >= 0")
        if int(self.max_bounces) < 0:
            raise SceneError(f"max bounces must be >= 0, got {self.max_bounces}")
        if self.dispersion_sampling not in DISPERSION_SAMPLING:
            raise SceneError(f"dispersion sampling must be SPLIT or SAMPLE, got {self.dispersion_sampling!r}")
        if self.time_limit < 0:
            raise SceneError("time limit must be >= 0 seconds")
        if int(self.tile_size) < 1 or int(self.round_samples) < 1:
            raise SceneError("tile size and round samples must be >= 1")
        self.grid()
