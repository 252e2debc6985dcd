"""Materials on the wavelength grid: reflectance / tint spectra and refractive-index spectra.

Three kinds (scene.MATERIAL_KINDS): Lambertian diffuse (BRDF rho / pi, two-sided), tinted
specular mirror, and a smooth dielectric (Fresnel reflection, Snell refraction, total internal
reflection) whose index may vary with wavelength (optics.ior_spectrum). A dielectric's colour
tints reflected and transmitted light alike, as Blender's Glass BSDF does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .optics import DISPERSION_MODELS, ior_spectrum
from .enums import MaterialKind
from .scene import Materials
from .spectrum import SpectralConverter

__all__ = ["PreparedMaterials", "prepare_materials", "DIFFUSE", "MIRROR", "DIELECTRIC"]

DIFFUSE, MIRROR, DIELECTRIC = (int(k) for k in (MaterialKind.DIFFUSE, MaterialKind.MIRROR, MaterialKind.DIELECTRIC))
_MODEL_NAMES = {code: name for name, code in DISPERSION_MODELS.items()}


@dataclass
class PreparedMaterials:
    kind: np.ndarray         # (M,) int
    reflectance: np.ndarray  # (M, n) float32: albedo / tint spectrum
    ior: np.ndarray          # (M, n) float32: refractive index per wavelength (1 for non-dielectrics)
    dispersive: np.ndarray   # (M,) bool: index varies over the grid
    emission: np.ndarray     # (M, n) float32 emitted spectral radiance (zero for most)
    emissive: np.ndarray     # (M,) bool
    clear: np.ndarray        # (M,) bool: reflectance 1 at every wavelength (untinted glass/mirror)

    @property
    def has_dispersion(self) -> bool:
        return bool(self.dispersive.any())


def prepare_materials(m: Materials, conv: SpectralConverter) -> PreparedMaterials:
    wl = conv.grid.wavelengths
    kind = np.asarray(m.kind, np.int32)
    refl = conv.reflectance_from_rgb(np.asarray(m.color, np.float64).reshape(-1, 3))
    ior = np.ones((len(kind), len(wl)))
    for i in np.flatnonzero(kind == DIELECTRIC):  # one row per material, not per ray
        ior[i] = ior_spectrum(wl, _MODEL_NAMES[int(m.dispersion[i])], float(m.ior[i]), float(m.abbe[i]))
    dispersive = (kind == DIELECTRIC) & (np.ptp(ior, axis=1) > 0) if len(kind) else np.zeros(0, bool)
    emission = conv.illuminant_from_rgb(np.asarray(m.emission, np.float64).reshape(-1, 3)).astype(np.float32)
    refl32 = refl.astype(np.float32)
    clear = np.all(refl32 == 1.0, axis=1) if len(refl32) else np.zeros(0, bool)
    return PreparedMaterials(kind, refl32, ior.astype(np.float32), dispersive,
                             emission, emission.any(axis=1), clear)
