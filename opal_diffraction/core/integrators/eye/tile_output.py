"""What one tile of the eye pass writes: its film parts, denoising features and shadow-ray count.

The film deposit stage of the tile tracer (core/integrators/eye/eye_pass.py). A contribution goes
to the part its path's diffuse-vertex count says (docs/physics.md section 4.5): emitted light seen
through mirrors and glass (Background), one diffuse vertex (Direct), more (Indirect), and the
Caustics and Diffraction parts; parts other than Direct are allocated when first written. Per
pixel sums are formed run by run (rays of a pixel are contiguous after a stable sort), or, for
unit-weight rays, factored per (material, light) combination (``accumulate_factored``,
section 4.10).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...transport.walker import Hit, Rays

__all__ = ["TileResult", "TileOutput"]


@dataclass
class TileResult:
    film: np.ndarray  # (P, n) sum of sample contributions per pixel (everything)
    # the parts of film (P, n) that are not Direct, or None where nothing was written:
    background: np.ndarray | None  # emitted light seen (world, emitters), directly or through mirrors and glass
    indirect: np.ndarray | None  # light that reached the eye through two or more diffuse vertices
    diffraction: np.ndarray | None  # diffracted by gratings
    caustics: np.ndarray | None  # caustic light from the light pass
    rays: int         # rays cast (camera, secondary and shadow)
    # denoising features, per-pixel sums over samples (P, 3), as Cycles' Denoising Albedo and
    # Denoising Normal passes: the first diffuse surface's linear RGB albedo times the
    # (grey) throughput of the mirrors and glass before it, and its world-space shading normal
    albedo: np.ndarray | None = None
    normal: np.ndarray | None = None


class TileOutput:
    """The accumulators of one tile of ``n_pixels`` pixels and ``n`` wavelength samples."""

    def __init__(self, n_pixels: int, n: int):
        self.n_pixels, self.n = n_pixels, n
        self.film = self._new_film()  # light reflected by diffuse surfaces from direct lighting
        # the other parts of the film, allocated when first written (most scenes use a few):
        self.parts: dict[str, np.ndarray] = {}  # 'background' (world and emitters seen),
        #                                        'indirect', 'diffraction', 'caustics'
        self.albedo = np.zeros((n_pixels, 3), np.float32)
        self.normal = np.zeros((n_pixels, 3), np.float32)
        self.shadow_rays = 0  # shadow rays the stages cast

    def _new_film(self) -> np.ndarray:
        return np.zeros(self.n_pixels * self.n, np.float32)

    def part(self, name: str) -> np.ndarray:
        arr = self.parts.get(name)
        if arr is None:
            arr = self.parts[name] = self._new_film()
        return arr

    @property
    def background(self) -> np.ndarray:
        return self.part("background")

    @property
    def diffraction(self) -> np.ndarray:
        return self.part("diffraction")

    @property
    def caustics(self) -> np.ndarray:
        return self.part("caustics")

    @property
    def indirect(self) -> np.ndarray:
        return self.part("indirect")

    def light_film(self, vertices: int) -> np.ndarray:
        """The film part for light reaching the eye after ``vertices`` diffuse (non-specular)
        vertices: 0 emitted light seen (through mirrors and glass), 1 direct, 2+ indirect."""
        return self.background if vertices == 0 else self.film if vertices == 1 else self.part("indirect")

    def add_by_vertices(self, rays: Rays, contrib):
        """Accumulate light found at the end of a path segment into the part its diffuse-vertex
        count says (``light_film``)."""
        nd = rays.state.nd
        if len(nd) and (nd == nd[0]).all():
            self.accumulate(rays, contrib, self.light_film(min(int(nd[0]), 2)))
            return
        for k in np.unique(nd):
            sel = nd == k
            self.accumulate(rays.take(sel), contrib[sel], self.light_film(min(int(k), 2)))

    def accumulate(self, rays: Rays, contrib, film=None):
        """Add per-ray contributions to their pixels: (B, n) for white rays, (B,) for mono."""
        n = self.n
        if len(rays) == 0:
            return
        film = self.film if film is None else film
        if rays.lam is not None:
            np.add.at(film, rays.pix * n + rays.lam, contrib)
            return
        pix = rays.pix
        if len(pix) > 1 and np.any(pix[1:] < pix[:-1]):
            order = np.argsort(pix, kind="stable")
            pix, contrib = pix[order], contrib[order]
        # rays of a pixel are contiguous: sum each run once, then add the (few) runs to the film
        starts = np.flatnonzero(np.concatenate([[True], pix[1:] != pix[:-1]]))
        sums = np.add.reduceat(contrib, starts, axis=0)
        film.reshape(self.n_pixels, n)[pix[starts]] += sums

    def accumulate_factored(self, prepared, pix, mat, factors, film) -> bool:
        """Direct light of unit-weight white rays without a per-ray spectrum.

        Each such ray adds factor_l * albedo[mat] * light_l(lambda) / pi, a sum over a few
        (material, light) spectra. Sum the scalar factors per pixel and combination first, then
        expand to spectra once per pixel: O(B L + P U n) instead of O(B n). Returns False (and
        does nothing) when the tile holds too many combinations for this to pay off.
        """
        b, nl = factors.shape
        ray, light = np.nonzero(factors)
        if ray.size == 0:
            return True
        combo = mat[ray].astype(np.int64) * nl + light
        present = np.bincount(combo, minlength=len(prepared.materials.kind) * nl) > 0  # O(B), no sort
        uniq = np.flatnonzero(present)
        u = (np.cumsum(present) - 1)[combo]
        if len(uniq) * self.n_pixels > b * nl:
            return False
        g = np.bincount(pix[ray] * len(uniq) + u, weights=factors[ray, light],
                        minlength=self.n_pixels * len(uniq)).reshape(self.n_pixels, len(uniq))
        spectra = prepared.materials.reflectance[uniq // nl] * prepared.lights.spectrum[uniq % nl] * np.float32(1 / np.pi)
        film += (g @ spectra).ravel()
        return True

    def denoising_features(self, rays: Rays, hit: Hit, albedo_rgb: np.ndarray):
        """Albedo (``albedo_rgb`` (M, 3) of the materials) and normal of the first diffuse surface
        a sample sees (mono rays count with the throughput divided by the wavelength count: their
        weight is the whole spectrum's)."""
        if rays.w is None:
            grey = np.ones(len(rays), np.float32)
        elif rays.lam is None:
            grey = rays.w.mean(axis=1)
        else:
            grey = rays.w / np.float32(self.n)
        albedo = albedo_rgb[hit.mat] * grey[:, None]
        normal = hit.ns
        for arr, val in ((self.albedo, albedo), (self.normal, normal)):
            for c in range(3):
                arr[:, c] += np.bincount(rays.pix, weights=val[:, c], minlength=self.n_pixels).astype(np.float32)

    def result(self, rays_cast: int) -> TileResult:
        """The tile's TileResult; ``rays_cast``: the walk's own rays (the shadow rays are added)."""
        shape = (self.n_pixels, self.n)
        total = self.film
        for part in self.parts.values():
            total = total + part
        get = lambda k: self.parts[k].reshape(shape) if k in self.parts else None  # noqa: E731
        return TileResult(total.reshape(shape), get("background"), get("indirect"), get("diffraction"),
                          get("caustics"), rays_cast + self.shadow_rays, self.albedo, self.normal)
