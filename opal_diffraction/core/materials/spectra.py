"""Materials on the wavelength grid: reflectance / tint spectra and refractive-index spectra.

Three kinds (scene.MATERIAL_KINDS): Lambertian diffuse (BRDF rho / pi, two-sided), tinted
specular mirror, and a smooth dielectric (Fresnel reflection, Snell refraction, total internal
reflection) whose index may vary with wavelength (optics.ior_spectrum). A glass's colour tints
reflected and transmitted light alike; its tint spectrum is the square root of the uplifted
colour of one pass through a closed object (docs/physics.md section 2.7: Base Color for
Principled, glass_tint PASS; Color^2 for the Glass BSDF, glass_tint REFRACTION), so that two
refractions give that colour's RGB exactly, as Cycles' RGB product does.

Rough surfaces and Principled's layers (core/materials/bsdf.py, docs/physics.md section 14) read the
per-material roughness, the layer weights metallic and transmission, the specular layer's F0
(spec_f0 = ((ior - 1) / (ior + 1))^2 x 2 x IOR level, Cycles' Principled v2), the specular /
edge tint spectrum and whether a metal uses the F82-tint Fresnel (else its colour is constant).

A thin film (docs/physics.md section 2.8, core/spectral/thin_film.py) marks its smooth glass
dispersive (the reflectance varies over the grid) and is read by ``film_fresnel`` below: the
Fresnel reflectance of glass and of mirrors / metals with the film's Airy interference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..spectral.optics import DISPERSION_MODELS, ior_spectrum
from ..spectral.thin_film import THIN_FILM_CUTOFF_NM
from ..util.enums import ConductorFresnel, GlassTint, MaterialKind
from ..scene.model import Materials
from ..spectral.spectrum import SpectralConverter

__all__ = ["PreparedMaterials", "prepare_materials", "glass_tint_spectra", "DIFFUSE", "MIRROR", "DIELECTRIC"]

DIFFUSE, MIRROR, DIELECTRIC = (int(k) for k in (MaterialKind.DIFFUSE, MaterialKind.MIRROR, MaterialKind.DIELECTRIC))
_MODEL_NAMES = {code: name for name, code in DISPERSION_MODELS.items()}


@dataclass
class PreparedMaterials:
    kind: np.ndarray         # (M,) int
    reflectance: np.ndarray  # (M, n) float32: albedo / tint spectrum (a glass's: per refraction, glass_tint_spectra)
    ior: np.ndarray          # (M, n) float32: refractive index per wavelength (1 for non-dielectrics)
    dispersive: np.ndarray   # (M,) bool: index varies over the grid
    emission: np.ndarray     # (M, n) float32 emitted spectral radiance (zero for most)
    emissive: np.ndarray     # (M,) bool
    clear: np.ndarray        # (M,) bool: reflectance 1 at every wavelength (untinted glass/mirror)
    roughness: np.ndarray = None      # (M,) float32 Blender roughness (GGX alpha = roughness^2)
    metallic: np.ndarray = None       # (M,) float32 weight of the conductor layer
    transmission: np.ndarray = None   # (M,) float32 weight of the glass layer (of what the metal leaves)
    spec_f0: np.ndarray = None        # (M,) float32 F0 of the base's specular layer (0: pure Lambert)
    specular_tint: np.ndarray = None  # (M, n) float32 specular tint / metal edge tint spectrum
    conductor_f82: np.ndarray = None  # (M,) bool: the metal uses the F82-tint Fresnel (else constant colour)
    glass_tint: np.ndarray = None     # (M, n) float32 the glass layer's tint per refraction (glass_tint_spectra)
    color_textured: np.ndarray = None  # (M,) bool: a texture gives the colour per hit (its glass keeps that tint)
    film: np.ndarray = None            # (M,) bool: a thin film over the surface (thickness above the cutoff)
    film_thickness: np.ndarray = None  # (M,) float64 the film's thickness (nm; 0 where none)
    film_ior: np.ndarray = None        # (M,) float64 the film's index
    wavelengths: np.ndarray = None     # (n,) float64 the grid's wavelengths (nm), for the films' phases
    # shader mixes as lobe mixtures (docs/physics.md section 14.8; core/materials/mixtures.py)
    metal_reflectance: np.ndarray = None  # (M, n) float32 the metal layer's own colour (None: no row has one)
    own_metal: np.ndarray = None          # (M,) bool: the row's metal layer has its own colour
    layer_fac: np.ndarray = None          # (M,) int LayerFac: where a two-layer mix's weights come from per hit
    layer_fac_value: np.ndarray = None    # (M,) float32 the Fresnel node's IOR / the Layer Weight's Blend
    layer_fac_from: np.ndarray = None     # (M,) int the layer (0 base, 1 metal, 2 glass) weighted 1 - Fac
    layer_fac_to: np.ndarray = None       # (M,) int the layer weighted Fac
    diffuse_roughness: np.ndarray = None  # (M,) float32 Oren-Nayar's sigma of a rough Diffuse BSDF (0: Lambert)
    holdout: np.ndarray = None            # (M,) float32 a Holdout's weight (Film > Transparent: alpha taken off)
    # Principled's coat and sheen over the rest (docs/physics.md section 14.10; core/materials/mixtures.py)
    layered: np.ndarray = None            # (M,) bool: the row has a coat or a sheen (None: no row has one)
    coat_weight: np.ndarray = None        # (M,) float32
    coat_roughness: np.ndarray = None     # (M,) float32
    coat_ior: np.ndarray = None           # (M,) float32
    coat_tint: np.ndarray = None          # (M, n) float32 the coat's tint spectrum (through unit thickness)
    sheen_weight: np.ndarray = None       # (M,) float32
    sheen_roughness: np.ndarray = None    # (M,) float32
    sheen_tint: np.ndarray = None         # (M, n) float32 the sheen's tint spectrum
    sheen_tint_max: np.ndarray = None     # (M,) float32 the tint's largest RGB channel (Cycles' layering weight)


def glass_tint_spectra(color, glass_tint, conv: SpectralConverter) -> np.ndarray:
    """(G, n) float64: the tint per refraction of glasses of linear RGB ``color`` (G, 3) whose
    colour is the colour of ``glass_tint`` (G,) (GlassTint codes; docs/physics.md section 2.7).

    The colour of one pass (two refractions) is uplifted and its square root taken, so a pass's
    spectrum is the uplift of the pass colour, whose RGB under white light is that colour
    (Mallett-Yuksel's calibrated round trip): Base Color for PASS (Principled), Color^2 for
    REFRACTION (the Glass BSDF: Cycles multiplies Color per refraction in RGB, and the uplifts'
    product would not be the RGB product for a saturated colour)."""
    rgb = np.clip(np.asarray(color, np.float64).reshape(-1, 3), 0.0, 1.0)
    per_pass = np.where((np.asarray(glass_tint) == int(GlassTint.PASS))[:, None], rgb, rgb * rgb)
    return np.sqrt(conv.reflectance_from_rgb(per_pass))


def prepare_materials(m: Materials, conv: SpectralConverter) -> PreparedMaterials:
    wl = conv.grid.wavelengths
    kind = np.asarray(m.kind, np.int32)
    refl = conv.reflectance_from_rgb(np.asarray(m.color, np.float64).reshape(-1, 3))
    transmission, metallic = np.asarray(m.transmission), np.asarray(m.metallic)
    # every row with a glass layer: its tint per refraction (the rough and layered BSDF's glass lobe)
    layer_fac = np.asarray(m.layer_fac, np.int32)
    lf_from, lf_to = np.asarray(m.layer_fac_from, np.int32), np.asarray(m.layer_fac_to, np.int32)
    per_hit = layer_fac != 0
    layer = ((transmission > 0) & (metallic < 1)) | (per_hit & ((lf_from == 2) | (lf_to == 2)))
    glass_tint = refl.copy()
    glass_rgb = np.asarray(m.glass_color, np.float64).reshape(-1, 3)
    glass_rgb = np.where((glass_rgb >= 0).all(axis=1)[:, None], glass_rgb, np.asarray(m.color).reshape(-1, 3))
    if layer.any():
        glass_tint[layer] = glass_tint_spectra(glass_rgb[layer], np.asarray(m.glass_tint)[layer], conv)
    # pure glass (no metal or base layer sharing the row): the tint is the row's colour everywhere
    pure = (kind == DIELECTRIC) & (transmission >= 1) & (metallic <= 0)
    refl[pure] = glass_tint[pure]
    ior = np.ones((len(kind), len(wl)))
    for i in np.flatnonzero(kind == DIELECTRIC):  # one row per material, not per ray
        ior[i] = ior_spectrum(wl, _MODEL_NAMES[int(m.dispersion[i])], float(m.ior[i]), float(m.abbe[i]))
    film_d = np.asarray(m.thin_film_thickness, np.float64)
    film = film_d > THIN_FILM_CUTOFF_NM
    # a thin film makes smooth glass's Fresnel vary over the grid: white rays split there as at a
    # dispersive index (reflect white with the film's spectrum, refract mono; docs/physics.md section 2.8)
    dispersive = (kind == DIELECTRIC) & ((np.ptp(ior, axis=1) > 0) | film) if len(kind) else np.zeros(0, bool)
    emission = conv.illuminant_from_rgb(np.asarray(m.emission, np.float64).reshape(-1, 3)).astype(np.float32)
    refl32 = refl.astype(np.float32)
    clear = np.all(refl32 == 1.0, axis=1) if len(refl32) else np.zeros(0, bool)
    n_d = np.asarray(m.ior, np.float64)
    spec_f0 = ((n_d - 1.0) / (n_d + 1.0)) ** 2 * 2.0 * np.asarray(m.specular_ior_level, np.float64)
    tint = conv.reflectance_from_rgb(np.asarray(m.specular_tint, np.float64).reshape(-1, 3)).astype(np.float32)
    metal_rgb = np.asarray(m.metal_color, np.float64).reshape(-1, 3)
    own_metal = (metal_rgb >= 0).all(axis=1)
    metal_refl = conv.reflectance_from_rgb(np.where(own_metal[:, None], metal_rgb, 0.0)).astype(np.float32) \
        if own_metal.any() else None
    coat_w = np.asarray(getattr(m, "coat_weight", np.zeros(len(kind))), np.float32)
    sheen_w = np.asarray(getattr(m, "sheen_weight", np.zeros(len(kind))), np.float32)
    layered = (coat_w > 0) | (sheen_w > 0)
    coat = {}
    if layered.any():
        coat_rgb = np.asarray(m.coat_tint, np.float64).reshape(-1, 3)
        sheen_rgb = np.asarray(m.sheen_tint, np.float64).reshape(-1, 3)
        coat = dict(layered=layered, coat_weight=coat_w, coat_roughness=np.asarray(m.coat_roughness, np.float32),
                    coat_ior=np.asarray(m.coat_ior, np.float32),
                    coat_tint=conv.reflectance_from_rgb(coat_rgb).astype(np.float32), sheen_weight=sheen_w,
                    sheen_roughness=np.asarray(m.sheen_roughness, np.float32),
                    sheen_tint=conv.reflectance_from_rgb(sheen_rgb).astype(np.float32),
                    sheen_tint_max=sheen_rgb.max(axis=1).astype(np.float32))
    return PreparedMaterials(kind, refl32, ior.astype(np.float32), dispersive,
                             emission, emission.any(axis=1), clear,
                             roughness=np.asarray(m.roughness, np.float32),
                             metallic=np.asarray(m.metallic, np.float32),
                             transmission=np.asarray(m.transmission, np.float32),
                             spec_f0=spec_f0.astype(np.float32), specular_tint=tint,
                             conductor_f82=np.asarray(m.conductor_fresnel) == int(ConductorFresnel.F82_TINT),
                             glass_tint=glass_tint.astype(np.float32),
                             color_textured=(np.asarray(m.color_texture) >= 0) | (np.asarray(m.shader_program) >= 0),
                             film=film, film_thickness=np.where(film, film_d, 0.0),
                             film_ior=np.asarray(m.thin_film_ior, np.float64),
                             wavelengths=np.asarray(wl, np.float64),
                             metal_reflectance=metal_refl, own_metal=own_metal, layer_fac=layer_fac,
                             layer_fac_value=np.asarray(m.layer_fac_value, np.float32),
                             layer_fac_from=lf_from, layer_fac_to=lf_to,
                             diffuse_roughness=np.asarray(m.diffuse_roughness, np.float32),
                             holdout=np.asarray(getattr(m, "holdout", np.zeros(len(m.metallic))), np.float32),
                             **coat)
