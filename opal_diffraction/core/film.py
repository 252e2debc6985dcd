"""The film: per-pixel sums of the eye pass's tiles, and the finished image they make.

Tiles add their spectral sums (and the parts that are not Direct light, already in RGB) into
the film with the number of samples they took; ``result()`` divides by each pixel's count, so a
partial image after a cancel or a time limit is a correct mean of the samples that were taken.

Passes (AOVs for the compositor, (H, W, 3) linear Rec.709): Direct (light reaching diffuse
surfaces by shadow rays, also seen through mirrors and glass), Caustics (the light pass),
Diffraction (gratings). Combined = Direct + Caustics + Diffraction + emitted light seen (the
world and emissive surfaces, directly or via specular paths).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .plan import RenderPlan
from .scene import SceneError
from .spectrum import SpectralConverter

__all__ = ["Film", "RenderResult", "tile_parts_rgb"]

PARTS = ("background", "indirect", "caustics", "diffraction")  # a TileResult's non-Direct parts


def tile_parts_rgb(conv: SpectralConverter, tile) -> dict:
    """An eye_pass.TileResult's non-Direct parts as (P, 3) RGB (None where it wrote none)."""
    return {name: None if getattr(tile, name) is None else conv.to_rgb(getattr(tile, name)) for name in PARTS}


@dataclass
class RenderResult:
    spectral: np.ndarray          # (H, W, n) float32 mean spectral radiance, row 0 at the top
    rgb: np.ndarray               # (H, W, 3) float32 linear Rec.709
    wavelengths: np.ndarray       # (n,) nm
    samples: int                  # samples per pixel actually taken (the minimum over pixels)
    cancelled: bool
    plan: RenderPlan
    warnings: list[str] = field(default_factory=list)
    stats: dict = field(default_factory=dict)
    passes: dict = field(default_factory=dict)  # 'Direct', 'Indirect', 'Caustics', 'Diffraction': (H, W, 3)


class Film:
    """Accumulates tiles of one render (``height`` x ``width`` pixels, ``conv``'s grid)."""

    def __init__(self, width: int, height: int, conv: SpectralConverter):
        self.conv = conv
        self.spectral = np.zeros((height, width, conv.grid.n), np.float32)
        # RGB sums of the parts of the spectral sum that are not Direct light
        self.parts = {name: np.zeros((height, width, 3), np.float32) for name in PARTS}
        self.counts = np.zeros((height, width), np.float32)  # samples per pixel so far

    @classmethod
    def for_region(cls, camera, region, conv: SpectralConverter):
        """((x0, y0, x1, y1), an empty Film) for ``region`` of ``camera``'s image (None: all of
        it; rows from the top). SceneError for a region outside the image."""
        w, h = int(camera.width), int(camera.height)
        x0, y0, x1, y1 = region if region is not None else (0, 0, w, h)
        if not (0 <= x0 < x1 <= w and 0 <= y0 < y1 <= h):
            raise SceneError(f"render region {region} is outside the {camera.width}x{camera.height} image")
        return (x0, y0, x1, y1), cls(x1 - x0, y1 - y0, conv)

    def add_tile(self, x0: int, y0: int, x1: int, y1: int, tile, samples: int) -> None:
        """Add an eye_pass.TileResult covering pixels [x0, x1) x [y0, y1) with ``samples`` each."""
        self.add_converted(x0, y0, x1, y1, tile.film, tile_parts_rgb(self.conv, tile), samples)

    def add_converted(self, x0: int, y0: int, x1: int, y1: int, film: np.ndarray, parts_rgb: dict,
                      samples: int) -> None:
        """``add_tile`` for a tile whose non-Direct parts are already RGB (``tile_parts_rgb``;
        a Dask worker converts them, so only the spectral sums and RGB parts cross the wire)."""
        h, w = y1 - y0, x1 - x0
        self.spectral[y0:y1, x0:x1] += film.reshape(h, w, -1)
        for name, arr in self.parts.items():
            part = parts_rgb.get(name)
            if part is not None:
                arr[y0:y1, x0:x1] += part.reshape(h, w, 3)
        self.counts[y0:y1, x0:x1] += samples

    def result(self, plan: RenderPlan, cancelled: bool, warnings, stats) -> RenderResult:
        """The mean image so far, with its passes."""
        scale = (1.0 / np.maximum(self.counts, 1.0))[..., None]
        spectral = self.spectral * scale
        rgb = self.conv.to_rgb(spectral)
        caustics = self.parts["caustics"] * scale
        diffraction = self.parts["diffraction"] * scale
        indirect = self.parts["indirect"] * scale
        passes = {"Direct": rgb - self.parts["background"] * scale - indirect - diffraction - caustics,
                  "Indirect": indirect, "Caustics": caustics, "Diffraction": diffraction}
        samples = int(self.counts.min()) if self.counts.size else 0
        return RenderResult(spectral, rgb, self.conv.grid.wavelengths.copy(), samples, cancelled, plan,
                            list(warnings), dict(stats), passes)
