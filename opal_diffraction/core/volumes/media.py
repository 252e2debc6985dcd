"""Homogeneous media on the wavelength grid: the materials' Volume outputs and the world's volume
as spectra of scattering, absorption and emission (docs/physics.md section 15.1).

A medium belongs to a material row (the columns ``volume_*`` of core/scene/model.py Materials):
sigma_s(lambda) = scatter density * S(lambda), sigma_a(lambda) = absorption density * A(lambda),
where S and A are the linear-RGB colours uplifted per wavelength as surface colours are
(Mallett & Yuksel 2019, spectral.SpectralConverter.reflectance_from_rgb), so a coloured medium
is exact per wavelength rather than three RGB channels; the emission coefficient (radiance per
metre, Cycles' volume emission) is uplifted as a light's colour. The world's volume is the row
``Scene.world_volume`` names.

Which medium a segment crosses (section 15.2) is read from where it ends: a segment ending on
the back face of a surface whose material has a medium ran inside that medium; every other
segment (ending on a front face or leaving the scene) ran in the world's medium. That is Cycles'
volume stack for media that do not nest beyond one level (closed meshes in the world's fog,
glass with an absorbing interior, a fog box in the world), and needs no per-path state.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PreparedMedia", "prepare_media", "has_media"]


@dataclass(frozen=True)
class PreparedMedia:
    """The scene's media per material row (M rows; rows without a medium are zero)."""

    sigma_s: np.ndarray    # (M, n) float64 scattering coefficient, 1/m
    sigma_a: np.ndarray    # (M, n) float64 absorption coefficient, 1/m
    g: np.ndarray          # (M,) float64 Henyey-Greenstein anisotropy
    emission: np.ndarray   # (M, n) float64 emitted spectral radiance per metre
    has: np.ndarray        # (M,) bool: the row has a medium
    world: int             # the row of the world's medium, -1: a vacuum outside the meshes
    warnings: tuple = ()

    @property
    def sigma_t(self) -> np.ndarray:
        return self.sigma_s + self.sigma_a

    @property
    def scatters(self) -> np.ndarray:
        """(M,) bool: the medium scatters at some wavelength."""
        return (self.sigma_s > 0).any(axis=1)

    @property
    def emits(self) -> np.ndarray:
        return (self.emission > 0).any(axis=1)

    def segment_medium(self, mat: np.ndarray, front: np.ndarray, missed: np.ndarray) -> np.ndarray:
        """(B,) the medium row of segments ending on material ``mat`` (front: on its front face;
        missed: leaving the scene): the material's own medium behind a back face, else the
        world's (-1: none)."""
        inside = ~missed & ~front & self.has[np.where(missed, 0, mat)]
        return np.where(inside, mat, self.world).astype(np.int64)


def has_media(scene) -> bool:
    """Whether a material row of ``scene`` (core/scene/model.Scene) holds a medium."""
    m = scene.materials
    if len(m) == 0:
        return False
    return bool((np.asarray(m.volume_scatter_density) > 0).any() or (np.asarray(m.volume_absorption_density) > 0).any()
                or (np.asarray(m.volume_emission) > 0).any())


def prepare_media(scene, conv) -> PreparedMedia | None:
    """The media of a validated scene on ``conv``'s grid (spectral.SpectralConverter), or None
    when no material and no world has one."""
    m = scene.materials
    if len(m) == 0:
        return None
    ds = np.asarray(m.volume_scatter_density, np.float64)
    da = np.asarray(m.volume_absorption_density, np.float64)
    em_rgb = np.asarray(m.volume_emission, np.float64)
    has = (ds > 0) | (da > 0) | (em_rgb > 0).any(axis=1)
    if not has.any():
        return None
    sigma_s = ds[:, None] * np.asarray(conv.reflectance_from_rgb(np.asarray(m.volume_scatter_color, np.float64)),
                                       np.float64)
    sigma_a = da[:, None] * np.asarray(conv.reflectance_from_rgb(np.asarray(m.volume_absorption_color, np.float64)),
                                       np.float64)
    emission = np.asarray(conv.illuminant_from_rgb(em_rgb), np.float64)
    emission = np.where(has[:, None], np.maximum(emission, 0.0), 0.0)
    world = int(getattr(scene, "world_volume", -1))
    if world >= 0 and not has[world]:
        world = -1
    warns = []
    if world >= 0 and (emission[world] > 0).any() and ((sigma_s[world] + sigma_a[world]) <= 0).any():
        # an emitting world volume that does not attenuate at some wavelength: an infinite sum
        emission[world] = np.where(sigma_s[world] + sigma_a[world] > 0, emission[world], 0.0)
        warns.append("the world volume emits but does not absorb or scatter at some wavelengths: its emission "
                     "there is left out (it would be infinite)")
    return PreparedMedia(sigma_s, sigma_a, np.clip(np.asarray(m.volume_anisotropy, np.float64), -0.999, 0.999),
                         emission, has, world, tuple(warns))
