"""Surface elements and the illumination map: where the light pass leaves caustic flux.

Every receiving triangle is cut into k x k equal sub-triangles (k from a target element area),
and each sub-triangle has two elements, one per side, since surfaces are two-sided. The
element a hit falls in follows in O(1) from the triangle id and barycentrics (u, v):
i = floor(k u), j = floor(k v), the cell's upper half when frac(k u) + frac(k v) > 1, and
row i of the triangle holds 2 (k - i) - 1 cells starting at 2 k i - i^2. No per-element Python
objects: the map is one (E, n) array of spectral flux that partial maps simply add to.

A white deposit sums each element's rows in their order and adds the sum to the map once
(core/util/row_sums.py: a compiled pass where the kernels run, the same bits as the NumPy lines).
The light pass's landings go in through ``deposit_hits`` (the element of each hit, then
``deposit``): on the kernels one compiled pass indexes them (``element_of``) and, for mono
landings, sums each (element, wavelength)'s flux in float64 in the landings' order (np.bincount's)
and adds it to the map: the same bits as the NumPy lines, with the GIL released (the lanes of the
light pass run on threads). The eye pass's lookup (``irradiance``: jitter, element index, flux over area) is one compiled
pass too where the kernels run (``_irradiance_kernel`` over ``element_of``, the same float64
steps as the NumPy lines, so the same bits); the eye pass's caustic stage calls ``element_of``
inside its own fused kernel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..util.geometry import triangle_areas
from ..util.jit import kernels_enabled, njit
from ..util.row_sums import add_row_sums

__all__ = ["ElementLayout", "IlluminationMap", "MAX_SUBDIVISION", "element_of"]

MAX_SUBDIVISION = 1024  # k per triangle at most


@dataclass
class ElementLayout:
    k: np.ndarray             # (T,) int64 subdivisions per edge (0: the triangle receives no flux)
    offset: np.ndarray        # (T,) int64 index of the triangle's first element
    element_area: np.ndarray  # (T,) float64 area of one element of the triangle (m^2)
    total: int                # number of elements

    @classmethod
    def build(cls, vertices, triangles, receivers: np.ndarray, target_area: float) -> "ElementLayout":
        """Elements of about ``target_area`` m^2 on the triangles where ``receivers`` is True."""
        return cls.from_areas(triangle_areas(vertices, triangles), receivers, target_area)

    @staticmethod
    def subdivisions(area: np.ndarray, receivers: np.ndarray, target_area: float) -> np.ndarray:
        """(T,) k per triangle for elements of about ``target_area`` (0 off the receivers)."""
        k = np.ceil(np.sqrt(area / max(float(target_area), 1e-30)))
        k = np.clip(np.nan_to_num(k, nan=1.0), 1, MAX_SUBDIVISION).astype(np.int64)  # clip before the cast
        return np.where(np.asarray(receivers, bool), k, 0)

    @classmethod
    def from_areas(cls, area: np.ndarray, receivers: np.ndarray, target_area: float) -> "ElementLayout":
        """``build`` from the triangles' areas (T,), computed once by the caller."""
        k = cls.subdivisions(area, receivers, target_area)
        count = 2 * k * k
        offset = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64) if len(k) else np.zeros(0, np.int64)
        with np.errstate(divide="ignore", invalid="ignore"):
            element_area = np.where(k > 0, area / np.maximum(k * k, 1), 0.0)
        return cls(k, offset, element_area, int(count.sum()))

    def barycentric_centres(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(triangle, u, v) of every element's centre, in element order (for tools and tests)."""
        tri = np.zeros(self.total, np.int64)
        bu = np.zeros(self.total)
        bv = np.zeros(self.total)
        for k in np.unique(self.k[self.k > 0]):  # loop over distinct subdivision levels
            tris = np.flatnonzero(self.k == k)
            i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
            keep = i + j <= k - 1
            i, j = i[keep], j[keep]
            cells = []
            for upper in (0, 1):
                ok = (j < k - 1 - i) if upper else np.ones_like(i, bool)
                ii, jj = i[ok], j[ok]
                local = 2 * k * ii - ii * ii + 2 * jj + upper
                off = (1 + upper) / 3.0
                cells.append((local, (ii + off) / k, (jj + off) / k))
            local = np.concatenate([c[0] for c in cells])
            cu = np.concatenate([c[1] for c in cells])
            cv = np.concatenate([c[2] for c in cells])
            for side in (0, 1):
                idx = self.offset[tris][:, None] + 2 * local[None, :] + side
                tri[idx] = tris[:, None]
                bu[idx] = cu[None, :]
                bv[idx] = cv[None, :]
        return tri, bu, bv

    def index(self, prim, bu, bv, front) -> tuple[np.ndarray, np.ndarray]:
        """(element index, valid) for hits on triangles ``prim`` at barycentrics (bu, bv)."""
        prim = np.asarray(prim)
        k = self.k.take(prim)
        valid = k > 0
        kf = k.astype(np.float64)
        x = np.clip(np.asarray(bu, np.float64), 0, 1) * kf
        y = np.clip(np.asarray(bv, np.float64), 0, 1) * kf
        km1 = np.maximum(k - 1, 0)
        i = np.minimum(x.astype(np.int64), km1)  # x >= 0: the cast is the floor
        j = np.minimum(y.astype(np.int64), np.maximum(km1 - i, 0))
        upper = ((x - i) + (y - j) > 1.0) & (j < km1 - i)
        local = (2 * k - i) * i + 2 * j + upper
        return self.offset.take(prim) + 2 * local + ~np.asarray(front, bool), valid


@dataclass
class IlluminationMap:
    """Spectral flux (W per wavelength sample) deposited on each element by the light pass."""

    layout: ElementLayout
    flux: np.ndarray  # (E, n) float32

    @classmethod
    def empty(cls, layout: ElementLayout, n: int) -> "IlluminationMap":
        return cls(layout, np.zeros((layout.total, n), np.float32))

    def deposit(self, elements: np.ndarray, flux: np.ndarray, lam: np.ndarray | None = None,
                basis: np.ndarray | None = None) -> None:
        """Add flux (B, n) white or (B,) at wavelengths ``lam`` to the elements (B,); with
        ``basis`` (k, n), ``flux`` is (B, k) coefficients over it (white flux = flux @ basis: a
        light's spectrum times a scalar, k = 1), summed per element and expanded once per
        element."""
        if len(elements) == 0:
            return
        elements = np.asarray(elements, np.int64)
        if basis is not None:
            self._deposit_coefficients(elements, flux, basis)
            return
        if lam is not None:
            # per (element, wavelength) sums in float64 by bincount (np.add.at is ~10x slower)
            n = self.flux.shape[1]
            keys, inv = np.unique(elements * n + np.asarray(lam, np.int64), return_inverse=True)
            sums = np.bincount(inv.reshape(-1), weights=np.asarray(flux, np.float64).reshape(-1), minlength=len(keys))
            flat = self.flux.reshape(-1)
            flat[keys] += sums.astype(np.float32)
            return
        add_row_sums(self.flux, elements, flux)

    def deposit_hits(self, prim, bu, bv, front, flux, lam=None, basis=None) -> int:
        """``deposit`` at the elements of hits on triangles ``prim`` at barycentrics (bu, bv) on
        side ``front`` (ElementLayout.index), the hits off the map skipped: ``flux`` (B, n), (B,)
        at wavelengths ``lam``, or (B, k) coefficients over ``basis``, one row per hit. Returns
        the number of hits deposited."""
        if len(prim) == 0:
            return 0
        lay = self.layout
        if kernels_enabled():
            # the fused deposits only where ``deposit`` is this class's (a subclass that overrides it gets its calls)
            fused = type(self).deposit is IlluminationMap.deposit
            if fused and lam is not None and basis is None:  # index and (element, wavelength) sums in one pass
                return int(_deposit_mono_kernel(lay.k, lay.offset, np.asarray(prim, np.int64), np.asarray(bu),
                                                np.asarray(bv), np.asarray(front, np.bool_), np.asarray(flux),
                                                np.asarray(lam, np.int64), self.flux.reshape(-1), self.flux.shape[1]))
            if fused and basis is not None and len(basis) == 1 and np.ndim(flux) == 2 and np.shape(flux)[1] == 1:
                # one spectrum times a scalar per landing: the per-element sum times the spectrum is one
                # product per sample (the reference's (E, 1) @ (1, n)), so the kernel gives its bits
                return int(_deposit_scaled_kernel(lay.k, lay.offset, np.asarray(prim, np.int64), np.asarray(bu),
                                                  np.asarray(bv), np.asarray(front, np.bool_),
                                                  np.ascontiguousarray(flux[:, 0]),
                                                  np.asarray(basis[0], np.float64), self.flux))
            idx = np.empty(len(prim), np.int64)
            m = _index_kernel(lay.k, lay.offset, np.asarray(prim, np.int64), np.asarray(bu), np.asarray(bv),
                              np.asarray(front, np.bool_), idx)
            if m == len(prim):
                self.deposit(idx, flux, lam, basis=basis)
            elif m:
                keep = np.flatnonzero(idx >= 0)
                self.deposit(idx[keep], np.take(flux, keep, axis=0), None if lam is None else lam[keep], basis=basis)
            return int(m)
        idx, valid = lay.index(prim, bu, bv, front)
        if not valid.any():
            return 0
        self.deposit(idx[valid], flux[valid], None if lam is None else lam[valid], basis=basis)
        return int(valid.sum())

    def lit_triangles(self) -> np.ndarray:
        """(T,) bool: the triangles with flux on any of their elements (a finished map's hits
        elsewhere need no lookup: they receive no caustic)."""
        lay = self.layout
        lit = np.zeros(len(lay.k), bool)
        held = np.flatnonzero(lay.k > 0)
        if len(held) and lay.total:
            has = np.any(self.flux != 0, axis=1)
            counts = np.add.reduceat(has.astype(np.int64), lay.offset[held])  # held triangles' elements are contiguous
            lit[held] = counts > 0
        return lit

    def _deposit_coefficients(self, elements, coeff, basis) -> None:
        basis = np.asarray(basis, np.float64)
        k = len(basis)
        coeff = np.asarray(coeff, np.float64).reshape(len(elements), k)
        cells, inv = np.unique(elements, return_inverse=True)
        inv = inv.reshape(-1)
        # per element and coefficient sums (one bincount over element * k + c), in float64
        sums = np.bincount((inv[:, None] * k + np.arange(k)).reshape(-1), weights=coeff.reshape(-1),
                           minlength=len(cells) * k).reshape(len(cells), k)
        self.flux[cells] += (sums @ basis).astype(np.float32)

    def irradiance(self, prim, bu, bv, front, rng=None) -> np.ndarray:
        """Spectral irradiance (B, n) at hits: the element's flux over its area (0 off the map).

        With ``rng`` the lookup point is jittered uniformly by up to one element in barycentric
        terms (folded back into the triangle): over many eye samples that box-filters the map
        over neighbouring elements, so element edges do not show as triangles.
        """
        if kernels_enabled():
            b = len(np.asarray(prim))
            out = np.empty((b, self.flux.shape[1]), np.float32)
            r1 = rng.random(b) if rng is not None else np.zeros(0)
            r2 = rng.random(b) if rng is not None else np.zeros(0)
            lay = self.layout
            _irradiance_kernel(lay.k, lay.offset, lay.element_area, self.flux, np.asarray(prim, np.int64),
                               np.asarray(bu, np.float64), np.asarray(bv, np.float64), np.asarray(front, np.bool_),
                               r1, r2, rng is not None, out)
            return out
        if rng is not None:
            k = np.maximum(self.layout.k[np.asarray(prim)], 1).astype(np.float64)
            bu = np.asarray(bu, np.float64) + (rng.random(len(k)) * 2 - 1) / k
            bv = np.asarray(bv, np.float64) + (rng.random(len(k)) * 2 - 1) / k
            bu, bv = np.abs(bu), np.abs(bv)  # fold across the u = 0 and v = 0 edges
            over = bu + bv > 1
            bu, bv = np.where(over, 1 - bv, bu), np.where(over, 1 - bu, bv)  # and across u + v = 1
        idx, valid = self.layout.index(prim, bu, bv, front)
        out = np.zeros((len(idx), self.flux.shape[1]), np.float32)
        if valid.any():
            area = self.layout.element_area[np.asarray(prim)[valid]]
            out[valid] = self.flux[idx[valid]] / area[:, None].astype(np.float32)
        return out

    def __iadd__(self, other: "IlluminationMap") -> "IlluminationMap":
        self.flux += other.flux
        return self


@njit
def element_of(k_tri, offset, prim, bu, bv, front, r1, r2, jitter):
    """(element index, valid) of one hit: ``irradiance``'s jitter (numbers r1, r2 in [0, 1),
    ``jitter``) and ``ElementLayout.index`` for one row, in the same float64 steps."""
    kt = k_tri[prim]
    if jitter:
        kj = np.float64(kt if kt > 1 else 1)
        bu = bu + (r1 * 2.0 - 1.0) / kj
        bv = bv + (r2 * 2.0 - 1.0) / kj
        bu, bv = abs(bu), abs(bv)
        if bu + bv > 1.0:
            bu, bv = 1.0 - bv, 1.0 - bu
    if kt <= 0:
        return np.int64(0), False
    kf = np.float64(kt)
    x = (0.0 if bu < 0.0 else (1.0 if bu > 1.0 else bu)) * kf
    y = (0.0 if bv < 0.0 else (1.0 if bv > 1.0 else bv)) * kf
    if x != x:  # NaN barycentrics (the NumPy lines index out of range there): the first cell
        x = 0.0
    if y != y:
        y = 0.0
    km1 = kt - 1
    i = min(np.int64(x), km1)
    lim = km1 - i
    j = min(np.int64(y), lim if lim > 0 else np.int64(0))
    upper = 1 if ((x - i) + (y - j) > 1.0) and (j < km1 - i) else 0
    local = (2 * kt - i) * i + 2 * j + upper
    return offset[prim] + 2 * local + (0 if front else 1), True


@njit
def _irradiance_kernel(k_tri, offset, element_area, flux, prim, bu, bv, front, r1, r2, jitter, out):
    """IlluminationMap.irradiance per row: out[b] = flux[element] / float32(area), 0 off the map."""
    n = flux.shape[1]
    for b in range(len(prim)):
        e, ok = element_of(k_tri, offset, prim[b], bu[b], bv[b], front[b],
                           r1[b] if jitter else 0.0, r2[b] if jitter else 0.0, jitter)
        if not ok:
            out[b, :] = 0.0
            continue
        area = np.float32(element_area[prim[b]])
        for kk in range(n):
            out[b, kk] = flux[e, kk] / area


@njit
def _index_kernel(k_tri, offset, prim, bu, bv, front, idx):
    """ElementLayout.index per hit (``element_of``): idx[b] = the element, or -1 off the map;
    returns the number on the map."""
    m = 0
    for b in range(len(prim)):
        e, ok = element_of(k_tri, offset, prim[b], bu[b], bv[b], front[b], 0.0, 0.0, False)
        idx[b] = e if ok else -1
        m += 1 if ok else 0
    return m


@njit
def _deposit_mono_kernel(k_tri, offset, prim, bu, bv, front, w, lam, flat, n):
    """deposit_hits of mono landings: the element of each hit (``element_of``), then per
    (element, wavelength) key the float64 sum of its landings' flux in their order (a stable
    sort keeps equal keys in input order: np.bincount's sums), rounded to float32 and added to
    the map ``flat`` (E * n,); returns the number of landings on the map."""
    b = len(prim)
    keys = np.empty(b, np.int64)
    vals = np.empty(b, np.float64)
    m = 0
    for i in range(b):
        e, ok = element_of(k_tri, offset, prim[i], bu[i], bv[i], front[i], 0.0, 0.0, False)
        if ok:
            keys[m] = e * n + lam[i]
            vals[m] = np.float64(w[i])
            m += 1
    keys, vals = keys[:m], vals[:m]
    order = np.argsort(keys, kind="mergesort")
    i = 0
    while i < m:  # runs of one key, in input order
        key = keys[order[i]]
        s = 0.0
        while i < m and keys[order[i]] == key:
            s += vals[order[i]]
            i += 1
        flat[key] += np.float32(s)
    return m


@njit
def _deposit_scaled_kernel(k_tri, offset, prim, bu, bv, front, coeff, spectrum, flux):
    """deposit_hits of white landings whose flux is coeff * spectrum (one basis spectrum): per
    element (``element_of``) the float64 sum of its landings' coefficients in their order
    (np.bincount's), times the spectrum in float64, rounded to float32 and added to its row of
    ``flux`` (E, n): ``_deposit_coefficients``' lines at k = 1. Returns the landings on the map."""
    b = len(prim)
    keys = np.empty(b, np.int64)
    vals = np.empty(b, np.float64)
    m = 0
    for i in range(b):
        e, ok = element_of(k_tri, offset, prim[i], bu[i], bv[i], front[i], 0.0, 0.0, False)
        if ok:
            keys[m] = e
            vals[m] = np.float64(coeff[i])
            m += 1
    keys, vals = keys[:m], vals[:m]
    order = np.argsort(keys, kind="mergesort")
    n = flux.shape[1]
    i = 0
    while i < m:  # runs of one element, in input order
        key = keys[order[i]]
        s = 0.0
        while i < m and keys[order[i]] == key:
            s += vals[order[i]]
            i += 1
        for j in range(n):
            flux[key, j] += np.float32(s * spectrum[j])
    return m
