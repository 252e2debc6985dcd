"""What one tile of the eye pass writes: its film parts, denoising features and shadow-ray count.

The film deposit stage of the tile tracer (core/integrators/eye/eye_pass.py). A contribution goes
to the part its path's diffuse-vertex count says (docs/physics.md section 4.5): emitted light seen
through mirrors and glass (Background), one diffuse vertex (Direct), more (Indirect), and the
Caustics and Diffraction parts; parts other than Direct are allocated when first written. Per
pixel sums are formed run by run (rays of a pixel are contiguous after a stable sort), or, for
unit-weight rays, factored per (material, light) combination (``accumulate_factored``,
section 4.10).

Where the kernels run (core/util/jit.py) the deposits are one compiled pass (``_deposit_kernel``;
the denoising features ``_features_kernel``, np.bincount's float64 sums in ray order)
instead of the argsort, ``np.add.reduceat`` and fancy-indexed add: a stable counting sort of the
rays by (film part, pixel), then each pixel's run summed as ``np.add.reduceat`` sums it (its first
row plus NumPy's pairwise sum of the others, ``_pairwise_rows``) and added to the film row; mono
rays are added one by one in order, as ``np.add.at`` adds them. The same operations in the same
order and precision: the same bits as the NumPy lines, with no (B, n) temporaries.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...transport.walker import Hit, Rays
from ...util.jit import kernels_enabled, njit

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
    # coverage: per pixel, the number of samples whose camera ray hit a surface (Film > Transparent's alpha)
    alpha: np.ndarray | None = None


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
        self.alpha = np.zeros(n_pixels, np.float32)  # camera rays that hit a surface, per pixel

    def add_alpha(self, pix: np.ndarray, hit: np.ndarray) -> None:
        """Coverage of camera rays at tile pixels ``pix``: ``hit`` (B,) bool, a surface within the clip range."""
        if len(pix):
            self.alpha += np.bincount(np.asarray(pix)[hit], minlength=self.n_pixels).astype(np.float32)

    def lower_alpha(self, pix: np.ndarray, amount: np.ndarray) -> None:
        """Transparent glass: paths at tile pixels ``pix`` that reached the world through smooth
        refractions only take ``amount`` (B,) (their mean throughput) off the coverage."""
        if len(pix):
            self.alpha -= np.bincount(np.asarray(pix), weights=np.asarray(amount, np.float64),
                                      minlength=self.n_pixels).astype(np.float32)

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
        if kernels_enabled() and self._deposit(rays, contrib, None, nd):
            return
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
        if kernels_enabled() and self._deposit(rays, contrib, film, None):
            return
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

    def _deposit(self, rays: Rays, contrib, film, nd) -> bool:
        """``accumulate`` (into ``film``) or ``add_by_vertices`` (``nd``: the rays' diffuse-vertex
        counts) by _deposit_kernel; False (nothing added) for input the NumPy lines handle."""
        n, b = self.n, len(rays)
        c = contrib if isinstance(contrib, np.ndarray) else np.asarray(contrib)
        mono = rays.lam is not None
        if c.dtype not in (np.float32, np.float64) or c.shape != ((b,) if mono else (b, n)):
            return False
        if mono and c.dtype != np.float32:  # np.add.at casts the values first: not done here
            return False
        if b == 0:
            return True
        if nd is None:
            films, nd, groups = (film, film, film), _NO_PART, 1
        else:
            lo, hi = int(nd.min()), int(nd.max())
            if lo < 0:
                return False
            # the parts written, allocated in add_by_vertices' order (ascending counts)
            films = tuple(self.light_film(k) if min(lo, 2) <= k <= min(hi, 2) else self.film for k in range(3))
            groups = hi + 1
        if not all(f.dtype == np.float32 and f.flags.c_contiguous and f.size == self.n_pixels * n for f in films):
            return False
        films = tuple(f.reshape(self.n_pixels, n) for f in films)
        # False: a pixel or wavelength index out of range (nothing written; the NumPy lines raise)
        return _deposit_kernel(rays.pix, nd, groups, rays.lam if mono else _NO_PART, c.reshape(b, 1) if mono else c,
                               films[0], films[1], films[2], self.n_pixels)

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
        if kernels_enabled() and self._features(rays, hit, albedo_rgb, grey):
            return
        albedo = albedo_rgb[hit.mat] * grey[:, None]
        normal = hit.ns
        for arr, val in ((self.albedo, albedo), (self.normal, normal)):
            for c in range(3):
                arr[:, c] += np.bincount(rays.pix, weights=val[:, c], minlength=self.n_pixels).astype(np.float32)

    def _features(self, rays: Rays, hit: Hit, albedo_rgb, grey) -> bool:
        """denoising_features' sums by _features_kernel; False for input the NumPy lines handle."""
        b = len(rays)
        arrays = (albedo_rgb, grey, hit.ns)
        if not all(isinstance(a, np.ndarray) and a.dtype == np.float32 for a in arrays) or \
                albedo_rgb.ndim != 2 or albedo_rgb.shape[1] != 3 or grey.shape != (b,) or hit.ns.shape != (b, 3):
            return False
        return _features_kernel(rays.pix, hit.mat, grey, albedo_rgb, hit.ns, self.albedo, self.normal)

    def result(self, rays_cast: int) -> TileResult:
        """The tile's TileResult; ``rays_cast``: the walk's own rays (the shadow rays are added)."""
        shape = (self.n_pixels, self.n)
        total = self.film
        for part in self.parts.values():
            total = total + part
        get = lambda k: self.parts[k].reshape(shape) if k in self.parts else None  # noqa: E731
        return TileResult(total.reshape(shape), get("background"), get("indirect"), get("diffraction"),
                          get("caustics"), rays_cast + self.shadow_rays, self.albedo, self.normal, self.alpha)


_NO_PART = np.zeros(0, np.int64)


@njit
def _pairwise_rows(c, rows, lo, hi, out, acc):
    """``out[:] = `` NumPy's pairwise sum (``pairwise_sum`` of numpy/core/src/umath/loops_utils.h,
    as every add reduction of a float array uses it) of the rows ``c[rows[lo:hi]]``, column by
    column: under 8 rows one after another from -0.0; up to 128 eight partial sums (the rows
    i mod 8) combined as ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7)), then the rest; longer
    runs split in two halves (the first a multiple of 8 long). ``acc`` (8, n): scratch."""
    n = c.shape[1]
    m = hi - lo
    if m < 8:
        for k in range(n):
            out[k] = -0.0
        for i in range(lo, hi):
            r = rows[i]
            for k in range(n):
                out[k] += c[r, k]
        return
    if m <= 128:
        for j in range(8):
            r = rows[lo + j]
            for k in range(n):
                acc[j, k] = c[r, k]
        i = lo + 8
        end = hi - m % 8
        while i < end:
            for j in range(8):
                r = rows[i + j]
                for k in range(n):
                    acc[j, k] += c[r, k]
            i += 8
        for k in range(n):
            out[k] = ((acc[0, k] + acc[1, k]) + (acc[2, k] + acc[3, k])) + \
                ((acc[4, k] + acc[5, k]) + (acc[6, k] + acc[7, k]))
        while i < hi:
            r = rows[i]
            for k in range(n):
                out[k] += c[r, k]
            i += 1
        return
    half = m // 2
    half -= half % 8
    second = np.empty_like(out)
    _pairwise_rows(c, rows, lo, lo + half, out, acc)
    _pairwise_rows(c, rows, lo + half, hi, second, acc)
    for k in range(n):
        out[k] += second[k]


@njit
def _deposit_kernel(pix, nd, groups, lam, c, f0, f1, f2, n_pixels):
    """Add rays' contributions ``c`` to films f0, f1, f2 (P, n): to f[min(nd, 2)] by the rays'
    diffuse-vertex counts ``nd`` (0 to ``groups`` - 1), or all to f0 (``nd`` empty). Mono rays
    (``lam`` given; c (B, 1)) one by one, as np.add.at; white rays (c (B, n)) grouped per
    (count, pixel) in ray order (a stable counting sort), each group's sum formed as
    np.add.reduceat forms it (its first row + the pairwise sum of the rest) and added to its
    film row, the groups of one film in ascending counts (add_by_vertices' order). Returns False,
    having written nothing, if a pixel or wavelength index is out of range."""
    b = pix.shape[0]
    has_part = nd.shape[0] > 0
    mono = lam.shape[0] > 0
    for i in range(b):
        if pix[i] < 0 or pix[i] >= n_pixels or (mono and (lam[i] < 0 or lam[i] >= f0.shape[1])):
            return False
    if mono:
        for i in range(b):
            k = nd[i] if has_part else 0
            f = f0 if k == 0 else (f1 if k == 1 else f2)
            f[pix[i], lam[i]] += c[i, 0]
        return True
    n = c.shape[1]
    keys = groups * n_pixels
    start = np.zeros(keys + 1, np.int64)
    for i in range(b):
        key = (nd[i] if has_part else 0) * n_pixels + pix[i]
        start[key + 1] += 1
    for key in range(keys):
        start[key + 1] += start[key]
    fill = start[:-1].copy()
    rows = np.empty(b, np.int64)
    for i in range(b):
        key = (nd[i] if has_part else 0) * n_pixels + pix[i]
        rows[fill[key]] = i
        fill[key] += 1
    acc = np.empty((8, n), c.dtype)
    rest = np.empty(n, c.dtype)
    for key in range(keys):
        lo, hi = start[key], start[key + 1]
        if hi == lo:
            continue
        k = key // n_pixels
        f = f0 if k == 0 else (f1 if k == 1 else f2)
        p = key - k * n_pixels
        first = rows[lo]
        if hi - lo == 1:
            for q in range(n):
                f[p, q] += c[first, q]
            continue
        _pairwise_rows(c, rows, lo + 1, hi, rest, acc)
        for q in range(n):
            f[p, q] += c[first, q] + rest[q]
    return True


@njit
def _features_kernel(pix, mat, grey, albedo_rgb, ns, albedo, normal):
    """denoising_features' NumPy lines: per pixel the float64 sums (np.bincount's, in ray order)
    of albedo_rgb[mat] * grey (float32 products) and of the normals, rounded to float32 and added
    to every pixel's row. False, having written nothing, for an index out of range."""
    p_count, m_count = albedo.shape[0], albedo_rgb.shape[0]
    for i in range(pix.shape[0]):
        if pix[i] < 0 or pix[i] >= p_count or mat[i] < -m_count or mat[i] >= m_count:
            return False
    sums = np.zeros((p_count, 6))
    for i in range(pix.shape[0]):
        p, m = pix[i], mat[i]
        if m < 0:
            m += m_count  # NumPy's negative index
        for c in range(3):
            sums[p, c] += np.float64(albedo_rgb[m, c] * grey[i])
            sums[p, 3 + c] += np.float64(ns[i, c])
    for p in range(p_count):
        for c in range(3):
            albedo[p, c] += np.float32(sums[p, c])
            normal[p, c] += np.float32(sums[p, 3 + c])
    return True
