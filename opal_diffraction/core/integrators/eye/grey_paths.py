"""Grey path weights in the eye pass: one coefficient instead of n spectral samples.

Method (docs/physics.md section 4.13): the light pass's coefficients over shared spectra
(section 4.7, ``transport.Rays.basis``) with the constant spectrum as the one basis row. A camera
path whose every scattering so far had a grey base colour (reflectance constant over wavelength:
Blender's white, grey and black materials, untextured) has a spectral throughput
W(lambda) = w * 1(lambda): it is carried as w (B, 1) over the basis ``ones (1, n)``. Everything
the path meets that is not grey (a coloured or textured surface, a tinted glass, a dispersive
split, a light's spectrum) multiplies the dense W = w @ basis, which is the same number for
every lambda; nothing is approximated. The gain is in the per-bounce work (row gathers, weight
products, film sums and the world's radiance added per pixel), which shrinks from n floats per
path to one.

Only the plain path tracer uses it (no gratings, opal lobes or grating layers, whose code reads
spectral weights directly): ``enabled``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...materials.spectra import DIFFUSE

__all__ = ["GreyPaths"]


class GreyPaths:
    """The grey materials of a prepared scene and the operations on grey-weighted rays."""

    def __init__(self, prepared, enabled: bool = True):
        refl = np.asarray(prepared.materials.reflectance, np.float32)
        n = prepared.grid.n
        tx = prepared.textures
        colour_tex = tx.bound("color") if tx.uses("color") else np.zeros(len(refl), bool)
        # (M,) a Lambertian material whose base colour is the same at every wavelength (bit for bit)
        grey = (np.all(refl == refl[:, :1], axis=1) if refl.size else np.zeros(len(refl), bool))
        self.grey = grey & ~colour_tex & (np.asarray(prepared.materials.kind) == DIFFUSE)
        self.value = (refl[:, 0].copy() if refl.size else np.zeros(0, np.float32)).astype(np.float32)
        self.basis = np.ones((1, n), np.float32)  # W(lambda) = w @ basis
        self.enabled = bool(enabled and self.grey.any())

    def is_grey(self, rays) -> bool:
        """These (white) rays' weights are all ones (None) or grey coefficients."""
        return rays.lam is None and (rays.w is None or rays.basis is self.basis)

    def albedo(self, rays, mat: np.ndarray) -> np.ndarray | None:
        """(B,) the grey base colours of hits on materials ``mat`` when every one is grey and the
        rays are white; None otherwise (the caller computes spectra)."""
        if not self.enabled or rays.lam is not None or len(mat) == 0 or not self.grey[mat].all():
            return None
        return self.value[mat]

    def scaled(self, rays, factor: np.ndarray, moved):
        """``moved`` (rays.moved(...) with weight placeholder) re-weighted: the grey weight of
        ``rays`` times the per-ray grey ``factor`` (B,), as coefficients over the basis."""
        w = factor[:, None].astype(np.float32) if rays.w is None else (rays.w * factor[:, None]).astype(np.float32)
        return replace(moved, w=w, basis=self.basis)

    def add_constant(self, film: np.ndarray, rays, spectrum: np.ndarray, n_pixels: int) -> bool:
        """film (P * n,) += sum over rays of W_ray(lambda) * spectrum(lambda) for grey rays: the
        coefficients summed per pixel, then one product with the spectrum per pixel. Returns
        False (nothing added) when the rays are not grey-weighted."""
        if rays.lam is not None or rays.w is None or rays.basis is not self.basis:
            return False
        sums = np.bincount(rays.pix, weights=rays.w[:, 0], minlength=n_pixels).astype(np.float32)
        film.reshape(n_pixels, -1)[:] += sums[:, None] * (self.basis[0] * spectrum)[None, :]
        return True
