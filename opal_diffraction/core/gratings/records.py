"""Light-pass records at gratings that keep the direction structure of the arriving light.

docs/physics.md section 3.5. A light path that reached a grating through mirrors and glass is a
*virtual source* seen from the grating: two mirrors make two sources, a prism makes one source
per wavelength. One flux-weighted mean direction per element (the earlier record) merges them
into a phantom source between them and erases dispersion. Here each element keeps a sparse
directional histogram instead, in the manner of a photon map's direction-binned irradiance
cache (Jensen, *Realistic Image Synthesis Using Photon Mapping*, 2001, ch. 7; the bins are the
octahedral map of the sphere, Engelhardt & Dachsbacher 2008 / Cigolle et al. 2014 "A survey of
efficient representations for independent unit vectors"):

- a *lobe* is one (element, side, wavelength band, direction bin): the direction bin is a cell
  of a G x G grid over the octahedral map of the unit direction towards the source (G = 8: 64
  cells of ~0.2 sr); the band is 0 for white paths (the whole spectrum travelled together) and
  1 + one of NB bands of the wavelength grid for mono paths (dispersion came first, so each band
  has its own direction);
- each lobe holds its spectral flux (n,), the flux-weighted sum of the unit directions towards
  the source (3,), its deposit count, and the flux-weighted moments of the deposit points p and
  directions d (sum w, w p, w p p^T, w d p^T): a first-order model of the direction across the
  element, d(x) = d_mean + J (x - p_mean) with J = Cov(d, p) Cov(p, p)^+ (least squares in the
  element's plane; the irradiance-gradient idea of Ward & Heckbert 1992 and of Jarosz et al.
  2008 applied to the direction). A virtual point source at distance r turns its direction by
  ~ element / r across an element, which moves a sharp order by far more than its width
  lambda / (N D); the model makes the direction exact to first order at the shading point
  (itself, not the jittered lookup point), so neither the element size nor the lookup filter
  shifts the orders. Lobes with fewer than MIN_GRADIENT_DEPOSITS deposits use the mean only;
- the eye pass diffracts every lobe of the element with the lobe's direction at the shading
  point and its irradiance flux / element area;
- storage is sparse: only occupied lobes, as sorted int64 keys
  ``cell * S + (side * (NB + 1) + band) * G^2 + bin`` with rows of
  flux, direction and count. Deposits go to a pending buffer, compacted (one stable sort of the
  keys, np.bincount sums in arrival order) when the buffer outgrows the store, so memory stays
  O(occupied lobes) and the result depends only on the order of the deposit calls (lanes and
  the distributed replay give the same bits);
- both sides in one lookup: the lobe key holds the side the light arrived on (so a lobe never
  averages light from both sides: every direction in it has the same sign of cosine with the
  normal, and so has their mean), and the lookup returns the lobes of both sides; the eye pass
  keeps those on the viewer's side for a reflection grating and those on the far side for a
  transmission grating, by the sign of the lobe direction's cosine with the normal. Storing by
  arrival side and looking up only the viewing side (the earlier record) never finds light for
  a transmission grating;
- elements sized where grating flux lands (``record_layout``): a pilot light pass of a few
  percent of the paths (its own random stream) counts the grating hits per triangle and
  estimates the lit part of each triangle from the finest power-of-two subdivision at which the
  pilot still has >= PILOT_PER_CELL hits per occupied cell; each triangle is then cut so the
  full pass leaves about RECORD_DEPOSITS deposits per lit element;
- filtered lookup: the lookup point is jittered by up to one element in barycentric terms
  (folded back into the triangle), as the illumination map does (docs/physics.md section 4.4):
  over the eye samples a box filter over neighbouring elements.
"""

from __future__ import annotations

import numpy as np

from ..transport.elements import MAX_SUBDIVISION, ElementLayout
from ..util.geometry import triangle_areas

__all__ = ["GratingRecords", "record_layout", "octahedral_bin", "DIRECTION_GRID", "BANDS", "RECORD_DEPOSITS",
           "PILOT_FRACTION", "PILOT_MIN_PATHS", "PILOT_MAX_PATHS", "PILOT_PER_CELL", "PILOT_STREAM"]

DIRECTION_GRID = 8        # G: G x G octahedral direction bins over the sphere
BANDS = 16                # NB: wavelength bands for mono (dispersed) paths
RECORD_DEPOSITS = 32      # target mean deposits per lit record element (full pass)
PILOT_FRACTION = 0.05     # share of the light paths the pilot pass traces ...
PILOT_MIN_PATHS = 16384   # ... but at least this many (or all) ...
PILOT_MAX_PATHS = 1 << 20  # ... and at most this many
PILOT_PER_CELL = 4        # pilot hits per occupied cell at the level that measures the lit area
PILOT_STREAM = 3          # random stream id of the pilot (eye pass 1, light pass 2)
MAX_LOBE_PAIRS = 1 << 16  # (hit, lobe) pairs the eye pass diffracts per call, to bound memory
MIN_GRADIENT_DEPOSITS = 8  # deposits a lobe needs before its direction gradient is used
MAX_GRADIENT_TURN = 0.25   # largest change of the unit direction the gradient may make
_MOMENTS = 19              # sum w, w p (3), w p p^T (6: xx yy zz xy xz yz), w d p^T (9)
_CAP_FLOATS = 32_000_000  # rows x wavelengths the record layout aims to stay under


def octahedral_bin(d: np.ndarray, grid: int = DIRECTION_GRID) -> np.ndarray:
    """(B,) int64 cell of the unit directions d (B, 3) in a grid x grid octahedral map."""
    d = np.asarray(d, np.float64)
    l1 = np.maximum(np.abs(d).sum(axis=1), 1e-30)
    x, y, z = d[:, 0] / l1, d[:, 1] / l1, d[:, 2] / l1
    lower = z < 0  # fold the lower hemisphere over the diagonals
    fx = np.where(lower, (1 - np.abs(y)) * np.where(x >= 0, 1.0, -1.0), x)
    fy = np.where(lower, (1 - np.abs(x)) * np.where(y >= 0, 1.0, -1.0), y)
    ix = np.clip(np.floor((fx + 1) * 0.5 * grid).astype(np.int64), 0, grid - 1)
    iy = np.clip(np.floor((fy + 1) * 0.5 * grid).astype(np.int64), 0, grid - 1)
    return ix * grid + iy


def jitter_barycentrics(k, bu, bv, rng):
    """(bu, bv) moved uniformly by up to one element (1 / k) per coordinate, folded back into
    the triangle: over many lookups a box filter over neighbouring elements."""
    k = np.maximum(np.asarray(k), 1).astype(np.float64)
    bu = np.asarray(bu, np.float64) + (rng.random(len(k)) * 2 - 1) / k
    bv = np.asarray(bv, np.float64) + (rng.random(len(k)) * 2 - 1) / k
    bu, bv = np.abs(bu), np.abs(bv)  # fold across the u = 0 and v = 0 edges
    over = bu + bv > 1
    return np.where(over, 1 - bv, bu), np.where(over, 1 - bu, bv)  # and across u + v = 1


class GratingRecords:
    """Sparse directional records of the light that reached grating elements through specular
    paths: per lobe (element, arrival side, band, direction bin) the spectral flux (W per
    wavelength sample), the flux-weighted sum of directions towards the source, the deposit
    count and the moments of the direction model.

    The light pass calls ``deposit`` (IlluminationMap.deposit's interface plus the hit points:
    element indices of ``layout`` with their side bit, the side the light arrived on); lanes
    add with ``+=``; the eye pass calls ``lobes`` (read-only but for a cached direction model:
    safe from several threads, which at worst compute the same cache twice).
    """

    max_pairs = MAX_LOBE_PAIRS  # the eye pass diffracts (hit, lobe) pairs in chunks of this many

    def __init__(self, layout: ElementLayout, n: int, grid: int = DIRECTION_GRID, bands: int = BANDS):
        self.layout = layout
        self.n = int(n)
        self.grid = int(grid)
        self.bands = int(min(bands, self.n))
        self.stride = 2 * (self.bands + 1) * self.grid * self.grid  # lobe keys per element (both sides)
        self._keys = np.zeros(0, np.int64)
        self._flux = np.zeros((0, self.n), np.float32)
        self._dir = np.zeros((0, 3), np.float32)
        self._count = np.zeros(0, np.int64)
        self._mom = np.zeros((0, _MOMENTS), np.float64)
        self._model = None  # cached (p_mean, d_mean, J, use) of the lobes, after a compaction
        # (keys, flux (B, n) or (B,), lam or None, flux-weighted dirs (B, 3), deposit counts or None: 1 each,
        #  moments (B, _MOMENTS) or None)
        self._pending: list[tuple] = []
        self._pending_rows = 0

    @classmethod
    def empty(cls, layout: ElementLayout, n: int) -> "GratingRecords":
        return cls(layout, n)

    # -- the light pass ------------------------------------------------------------------------
    def deposit(self, elements: np.ndarray, flux: np.ndarray, lam: np.ndarray | None = None,
                towards_source: np.ndarray | None = None, at: np.ndarray | None = None) -> None:
        """Add flux (B, n) of white paths, or (B,) of mono paths at wavelength indices ``lam``,
        arriving along unit ``towards_source`` (B, 3) (from the element to the source) at
        ``elements`` (B,) of ``layout`` (their low bit: the side the light arrived on), at the
        world points ``at`` (B, 3) (None: no direction gradient for these deposits)."""
        if len(elements) == 0:
            return
        if towards_source is None:
            raise ValueError("grating records need the direction towards the source")
        elements = np.asarray(elements, np.int64)
        cell, side = elements >> 1, elements & 1
        d = np.asarray(towards_source, np.float32)
        if lam is None:
            flux = np.asarray(flux, np.float32)
            weight = flux.sum(axis=1)
            band = np.zeros(len(cell), np.int64)
        else:
            flux = np.asarray(flux, np.float32).reshape(-1)
            weight = flux
            band = 1 + np.asarray(lam, np.int64) * self.bands // self.n
        band = side * (self.bands + 1) + band
        keys = cell * self.stride + band * (self.grid * self.grid) + octahedral_bin(d, self.grid)
        mom = None
        if at is not None:
            pw = np.asarray(at, np.float64)
            w = weight.astype(np.float64)
            d64 = d.astype(np.float64)
            pp = np.stack([pw[:, 0] * pw[:, 0], pw[:, 1] * pw[:, 1], pw[:, 2] * pw[:, 2],
                           pw[:, 0] * pw[:, 1], pw[:, 0] * pw[:, 2], pw[:, 1] * pw[:, 2]], 1)
            dp = (d64[:, :, None] * pw[:, None, :]).reshape(-1, 9)
            mom = np.concatenate([np.ones((len(w), 1)), pw, pp, dp], axis=1) * w[:, None]
        self._pending.append((keys, flux, None if lam is None else np.asarray(lam, np.int64), d * weight[:, None],
                              None, mom))
        self._pending_rows += len(keys)
        if self._pending_rows > max(1 << 16, len(self._keys)):  # amortised: the store at most doubles
            self._compact()

    def _compact(self) -> None:
        """Fold the pending deposits into the sorted sparse store: the store's value plus the
        pending deposits summed in arrival order (np.bincount, float64), so the bits depend only
        on the sequence of deposit calls."""
        if not self._pending:
            return
        n = self.n
        keys = np.concatenate([self._keys] + [p[0] for p in self._pending])
        ukeys, inv = np.unique(keys, return_inverse=True)
        inv = inv.reshape(-1)
        m, old = len(ukeys), len(self._keys)
        idx, val, dirs, cnt, moms = [], [], [], [], []
        at = old
        for k, f, lam, wd, c, mo in self._pending:  # loop over deposit calls (a few per batch), not rays
            rows = inv[at:at + len(k)]
            at += len(k)
            if lam is None:
                idx.append((rows[:, None] * n + np.arange(n)).ravel())
                val.append(f.ravel())
            else:
                idx.append(rows * n + lam)
                val.append(f)
            dirs.append(wd)
            cnt.append(np.ones(len(k), np.int64) if c is None else c)
            moms.append(np.zeros((len(k), _MOMENTS)) if mo is None else mo)
        new_rows = inv[old:]
        flux = np.bincount(np.concatenate(idx), weights=np.concatenate(val).astype(np.float64),
                           minlength=m * n).reshape(m, n)
        d = np.concatenate(dirs).astype(np.float64)
        direction = np.stack([np.bincount(new_rows, weights=d[:, c], minlength=m) for c in range(3)], axis=1)
        count = np.bincount(new_rows, weights=np.concatenate(cnt).astype(np.float64), minlength=m)
        mo = np.concatenate(moms)
        mom = np.stack([np.bincount(new_rows, weights=mo[:, c], minlength=m) for c in range(_MOMENTS)], axis=1)
        if old:  # the store's rows (unique keys: a plain scatter)
            mine = inv[:old]
            flux[mine] += self._flux
            direction[mine] += self._dir
            count[mine] += self._count
            mom[mine] += self._mom
        self._flux, self._dir = flux.astype(np.float32), direction.astype(np.float32)
        self._count = count.astype(np.int64)
        self._mom = mom
        self._keys = ukeys.astype(np.int64)
        self._pending, self._pending_rows = [], 0
        self._model = None

    def __iadd__(self, other: "GratingRecords") -> "GratingRecords":
        other._compact()
        if len(other._keys):  # the other's lobes as pending rows (after this one's: a fixed order)
            self._pending.append((other._keys, other._flux, None, other._dir, other._count, other._mom))
            self._pending_rows += len(other._keys)
            self._compact()
        return self

    def scale(self, factor: float) -> None:
        """Multiply the flux by ``factor`` (a light pass stopped early: planned / traced paths)."""
        self._compact()
        self._flux *= np.float32(factor)
        self._dir *= np.float32(factor)
        self._mom *= float(factor)
        self._model = None

    # -- views -----------------------------------------------------------------------------------
    @property
    def keys(self) -> np.ndarray:
        """(M,) sorted lobe keys: cell * stride + (side * (NB + 1) + band) * G^2 + direction bin."""
        self._compact()
        return self._keys

    @property
    def flux(self) -> np.ndarray:
        """(M, n) spectral flux of each lobe."""
        self._compact()
        return self._flux

    @property
    def direction(self) -> np.ndarray:
        """(M, 3) flux-weighted sum of the unit directions towards the source of each lobe."""
        self._compact()
        return self._dir

    @property
    def count(self) -> np.ndarray:
        """(M,) deposits in each lobe."""
        self._compact()
        return self._count

    def arrays(self) -> dict:
        """The store as plain arrays (for the wire: core/render/distributed.py), exact to the bit."""
        self._compact()
        return {"n": self.n, "grid": self.grid, "bands": self.bands, "keys": self._keys, "flux": self._flux,
                "direction": self._dir, "count": self._count, "moments": self._mom}

    @classmethod
    def from_arrays(cls, layout: ElementLayout, d: dict) -> "GratingRecords":
        rec = cls(layout, d["n"], d["grid"], d["bands"])
        rec._keys, rec._flux = np.asarray(d["keys"], np.int64), np.asarray(d["flux"], np.float32)
        rec._dir, rec._count = np.asarray(d["direction"], np.float32), np.asarray(d["count"], np.int64)
        rec._mom = np.asarray(d["moments"], np.float64)
        return rec

    def stats(self) -> dict:
        """Occupied elements and lobes, deposits, and deposits per occupied element."""
        self._compact()
        cells = np.unique(self._keys // self.stride)
        deposits = int(self._count.sum())
        return {"record_elements": int(self.layout.total // 2), "record_occupied": int(len(cells)),
                "record_lobes": int(len(self._keys)), "record_deposits": deposits,
                "record_deposits_per_occupied": deposits / max(len(cells), 1)}

    # -- the eye pass ----------------------------------------------------------------------------
    def _direction_model(self):
        """(p_mean (M, 3), d_mean (M, 3), J (M, 3, 3), use (M,) bool) of the lobes: the least-
        squares first-order model of the unit direction across the element."""
        if self._model is None:
            mo = self._mom
            w = mo[:, 0]
            use = (self._count >= MIN_GRADIENT_DEPOSITS) & (w > 0)
            inv = np.where(use, 1.0 / np.where(w > 0, w, 1.0), 0.0)
            pm = mo[:, 1:4] * inv[:, None]
            dm = self._dir.astype(np.float64) * inv[:, None]
            xx, yy, zz, xy, xz, yz = (mo[:, 4 + c] * inv for c in range(6))
            spp = np.stack([np.stack([xx, xy, xz], 1), np.stack([xy, yy, yz], 1), np.stack([xz, yz, zz], 1)], 1)
            cpp = spp - pm[:, :, None] * pm[:, None, :]
            cdp = mo[:, 10:19].reshape(-1, 3, 3) * inv[:, None, None] - dm[:, :, None] * pm[:, None, :]
            jac = np.zeros_like(cpp)
            if use.any():  # the points lie in a plane: Cov(p, p) has rank 2, so the pseudo-inverse
                jac[use] = cdp[use] @ np.linalg.pinv(cpp[use], rcond=1e-6, hermitian=True)
            self._model = (pm, dm, jac, use)
        return self._model

    def lobes(self, prim, bu, bv, rng=None, at=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every lobe of the element at each hit, light from either side: (hit index (P,), spectral
        irradiance (P, n), unit direction towards the source (P, 3)), P >= 0 pairs over the B
        hits (the caller keeps the side it needs by the direction's cosine). With ``rng`` the
        lookup point is jittered by up to one element (a box filter over neighbours); with
        ``at`` (B, 3), the hits' world points, each lobe's direction is its first-order model
        evaluated there."""
        self._compact()
        prim = np.asarray(prim, np.int64)
        b = len(prim)
        if b == 0 or len(self._keys) == 0:
            return np.zeros(0, np.int64), np.zeros((0, self.n), np.float32), np.zeros((0, 3), np.float32)
        if rng is not None:
            bu, bv = jitter_barycentrics(self.layout.k[prim], bu, bv, rng)
        idx, valid = self.layout.index(prim, bu, bv, np.ones(b, bool))
        cell = idx >> 1
        lo = np.searchsorted(self._keys, cell * self.stride)
        hi = np.searchsorted(self._keys, (cell + 1) * self.stride)
        cnt = np.where(valid, hi - lo, 0)
        hit = np.repeat(np.arange(b), cnt)
        first = np.cumsum(cnt) - cnt
        row = lo[hit] + (np.arange(len(hit)) - first[hit])
        area = self.layout.element_area[prim[hit]].astype(np.float32)
        irr = self._flux[row] / area[:, None]
        d = self._dir[row]
        if at is not None and len(row):
            pm, dm, jac, use = self._direction_model()
            x = np.asarray(at, np.float64)[hit]
            turn = np.einsum("pij,pj->pi", jac[row], x - pm[row])
            size = np.linalg.norm(turn, axis=1)
            turn *= np.minimum(1.0, MAX_GRADIENT_TURN / np.maximum(size, 1e-300))[:, None]
            d = np.where(use[row][:, None], dm[row] + turn, d).astype(np.float32)  # normalised below
        norm = np.linalg.norm(d, axis=1)
        ok = norm > 0
        return hit[ok], irr[ok], (d[ok] / norm[ok, None]).astype(np.float32)


def _subdivide_all(area: np.ndarray, mask: np.ndarray, k_level: int) -> ElementLayout:
    """A layout with the same k on every masked triangle."""
    k = np.where(mask, k_level, 0).astype(np.int64)
    count = 2 * k * k
    offset = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):
        element_area = np.where(k > 0, area / np.maximum(k * k, 1), 0.0)
    return ElementLayout(k, offset, element_area, int(count.sum()))


def layout_from_hits(area: np.ndarray, mask: np.ndarray, prim: np.ndarray, bu: np.ndarray, bv: np.ndarray,
                     scale: float, target: float = RECORD_DEPOSITS, n: int = 1) -> ElementLayout:
    """Record elements from a pilot's grating hits (triangle ``prim``, barycentrics (bu, bv)),
    each standing for ``scale`` full-pass deposits: per triangle, the lit area is the occupied
    cells at the finest power-of-two subdivision with >= PILOT_PER_CELL pilot hits per occupied
    cell, and k makes the lit elements hold about ``target`` deposits each. Triangles the pilot
    did not reach get k = 1. The target grows if the lit elements x ``n`` wavelengths would pass
    the memory cap."""
    mask = np.asarray(mask, bool)
    t = len(area)
    hits = np.bincount(prim, minlength=t).astype(np.float64)
    lit_area = area.copy()
    best = np.zeros(t, bool)
    level = 1
    while level <= MAX_SUBDIVISION:  # loop over ~11 levels, each vectorised over all hits
        lay = _subdivide_all(area, mask, level)
        idx, _ = lay.index(prim, bu, bv, np.ones(len(prim), bool))
        cells = np.unique(idx)
        tri_of = np.searchsorted(lay.offset, cells, side="right") - 1
        occ = np.bincount(tri_of, minlength=t).astype(np.float64)
        good = (occ > 0) & (hits >= PILOT_PER_CELL * occ)
        lit_area = np.where(good, occ * area / (level * level), lit_area)
        best |= good
        if not good.any():
            break
        level *= 2
    expected = hits * scale
    while np.sum(expected / target) * n > _CAP_FLOATS and target < 1e12:
        target *= 2.0
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.sqrt(expected * area / np.maximum(lit_area * target, 1e-300))
    k = np.clip(np.ceil(np.nan_to_num(k, nan=1.0, posinf=MAX_SUBDIVISION)), 1, MAX_SUBDIVISION).astype(np.int64)
    k = np.where(mask, np.where(hits > 0, k, 1), 0)
    count = 2 * k * k
    offset = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64) if t else np.zeros(0, np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):
        element_area = np.where(k > 0, area / np.maximum(k * k, 1), 0.0)
    return ElementLayout(k, offset, element_area, int(count.sum()))


class _PilotHits:
    """A stand-in for the records of a light pass (``layout.index`` + ``deposit``) that keeps
    the hits themselves: the pilot needs their barycentrics, not element indices."""

    def __init__(self, mask: np.ndarray):
        self.layout = self
        self.mask = np.asarray(mask, bool)
        self._prim, self._bu, self._bv, self._used = [], [], [], []
        self._n = 0

    def index(self, prim, bu, bv, front):
        prim = np.asarray(prim, np.int64)
        ids = self._n + np.arange(len(prim))
        self._n += len(prim)
        self._prim.append(prim)
        self._bu.append(np.asarray(bu, np.float64))
        self._bv.append(np.asarray(bv, np.float64))
        return ids, self.mask[prim]

    def deposit(self, elements, flux, lam=None, towards_source=None, at=None) -> None:
        self._used.append(np.asarray(elements, np.int64))

    def hits(self):
        if not self._used:
            return np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
        used = np.concatenate(self._used)
        return (np.concatenate(self._prim)[used], np.concatenate(self._bu)[used], np.concatenate(self._bv)[used])


class _NoSink:
    """Caustic deposits of the pilot go nowhere."""

    def __init__(self, layout):
        self.layout = layout

    def deposit(self, *args, **kwargs) -> None:
        pass


def record_layout(prepared, n_paths: int, mask, trace, batch_paths: int) -> tuple[ElementLayout, str, dict]:
    """Grating-record elements for a light pass of ``n_paths`` paths, sized by a pilot pass.

    ``trace(light, batch, start, light_paths, illum, records)`` traces one batch of the pilot
    (walker.trace_batch on the PILOT_STREAM: the light pass hands it in, so this module does
    not import it) in batches of ``batch_paths``. Returns (layout, warning or "", pilot stats)."""
    mask = np.asarray(mask, bool)
    area = triangle_areas(prepared.scene.vertices, prepared.scene.triangles)
    pilot = int(min(n_paths, max(PILOT_MIN_PATHS, PILOT_FRACTION * n_paths), PILOT_MAX_PATHS))
    budgets = prepared.light_targets.budgets
    share = budgets / max(budgets.sum(), 1e-300)
    per_light = np.floor(share * pilot).astype(np.int64)
    sink = _PilotHits(mask)
    nothing = _NoSink(_subdivide_all(area, prepared.light_targets.receiver_mask, 1))
    for li, n_l in enumerate(per_light):  # loop over lights (a handful), then their batches
        for bi, start in enumerate(range(0, int(n_l), batch_paths)):
            trace(li, bi, start, int(n_l), nothing, sink)
    prim, bu, bv = sink.hits()
    traced = int(per_light.sum())
    layout = layout_from_hits(area, mask, prim, bu, bv, n_paths / max(traced, 1), n=prepared.grid.n)
    return layout, "", {"pilot_paths": traced, "pilot_grating_hits": int(len(prim))}
