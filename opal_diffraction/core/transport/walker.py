"""Specular transport shared by the eye pass and the light pass: ray populations, hits, and one
bounce of mirror reflection, Fresnel-sampled refraction and dispersion.

A wavefront tracer: all rays of a batch advance one interaction at a time, in NumPy arrays, with
no Python loop per ray. Rays live in two populations:
- *white* rays carry the whole spectrum, a weight array (B, n) (``None``: all ones), or, for
  light-pass rays whose spectra are combinations of a few spectra the population shares (a
  light's spectrum; the world map's three RGB basis spectra), coefficients (B, k) over that
  ``basis`` (k, n): spectral weight = w @ basis. Colourless glass and mirrors and grey tints
  (reflectance constant over wavelength) scale the k coefficients instead of n samples; a
  coloured tint, a dispersive split and code that needs spectra expand them (``dense``), and
  the light pass's deposits take the coefficients (elements.IlluminationMap.deposit);
- *mono* rays carry one wavelength sample, a scalar weight (B,) and its index (B,).
A white ray stays white until it meets a dispersive dielectric; there it becomes mono rays:
``SPLIT`` makes one child per wavelength sample with the parent's weight at that wavelength (the
children's weights sum to the parent's: energy is conserved exactly), ``SAMPLE`` makes one child
with wavelength k drawn with probability p_k proportional to the parent's weight and weight
w_k / p_k (an unbiased one-sample estimator of the SPLIT sum, pbrt-v4's TerminateSecondary idea;
core/transport/wavelengths.py refines it: 4 hero wavelengths, a sensitivity pdf, white reflection).
Children inherit the parent's hit, so the split costs no extra ray cast.

At a dielectric the reflect / refract choice is sampled with probability equal to the Fresnel
reflectance, so the weight is unchanged (for mono rays the index is the one at their wavelength,
so total internal reflection differs per wavelength). Geometry is assumed closed with outward
normals (entering vs leaving a dielectric is read from the side of the hit).

Shading normals (docs/physics.md section 4.6): where the scene has per-corner normals, a hit's
``ns`` is their barycentric interpolation (Phong normal interpolation), normalised and put on the
side of the triangle's winding normal, then flipped with ``ng`` to face the incoming ray; mirror
reflection, Fresnel and refraction use it, while offsets and side tests keep ``ng``. Where ``ns``
would reflect a ray below the geometric surface it is first bent towards ``ng`` just enough that
the mirror direction leaves at a small angle above it (Cycles' ``ensure_valid_specular_reflection``,
intern/cycles/kernel/closure/bsdf_util.h, applied to every specular hit); a refracted direction
that would stay on the incident side is refracted about ``ng`` instead. Without corner normals
``ns`` is ``ng`` and nothing changes.

Subclasses say what happens where a path leaves the scene (``on_miss``) and at every surface it
hits (``on_hit``: direct light for the eye pass, deposits for the light pass), and whether a
path goes on (``survives``: bounce limit, Russian roulette). ``SpecularWalker``'s hooks (the
methods under "hooks") and its public operations (``hit_info``, ``specular_normal``,
``tinted_weight``, ``split_white``, ``spawn``, ``rays_cast``) are the only extension point: code
outside this module uses nothing else of it, so its internals may change freely.

Compiled kernels (core/util/jit.py; the NumPy lines stay the reference): ``hit_info`` (points,
facing normals, the shading normals' interpolation) and ``dielectric_bounce`` (Fresnel, the
sampled mirror or Snell direction, the offset) run one numba loop per batch when kernels are
on, doing the reference's float32 operations in its order (einsum's sequential dot products),
so their results are bit-identical (tests/transport/test_walker_kernels.py). A step's
continuing populations are joined with one concatenation per field.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..sampling import footprint
from . import wavelengths
from .path_state import PathState
from .rows import RowView, holds_none, join, pending_copy, subset
from ..materials.spectra import DIELECTRIC, DIFFUSE as DIFFUSE_KIND, MIRROR
from ..materials import thin_film
from ..spectral.optics import fresnel_dielectric, reflect, refract
from ..util.jit import kernels_enabled, njit

__all__ = ["Rays", "Hit", "SpecularWalker", "dense_weights", "shading_normals", "hit_shading_normals", "smooth_triangles", "light_spectrum_of", "valid_specular_normal", "MICROFACET", "GRATING"]

#: The kind a hit on a rough (or layered) mirror or glass gets in the walk: not a delta bounce;
#: the eye pass shades it with core/materials/bsdf.py, the light pass ends its path there.
MICROFACET = 99
#: The kind the light pass gives a hit where its path is diffracted by a grating
#: (core/gratings/order_sampling.py): neither a delta bounce nor a landing; ``scatter`` sends it on.
GRATING = 98


def _indices(mask):
    """Row indices of a bool mask (None: every row, nothing to copy) or an index array as is.
    Gathering rows by index (np.take) is several times faster than boolean indexing."""
    mask = np.asarray(mask)
    if mask.dtype != bool:
        return mask
    idx = mask.nonzero()[0]  # (B,) masks only: np.flatnonzero's ravel costs more than the call
    return None if len(idx) == len(mask) and len(idx) else idx


#: The fields of Rays gathered when first read (state and basis are not rows). The weights too:
#: the stages that scale them (Russian roulette) assign a new array (core/transport/rows.py's rule).
_RAY_ROWS = ("o", "d", "pix", "w", "lam", "depth", "u_lam")


def dense_weights(w, basis, b: int, n: int) -> np.ndarray:
    """(b, n) float32 spectral weights of white rows: ``w`` (b, n), or coefficients (b, k) over
    ``basis`` (k, n), or None (all ones)."""
    if w is None:
        return np.ones((b, n), np.float32)
    if basis is not None:
        return (w @ basis).astype(np.float32, copy=False)
    return w


@dataclass
class Rays(RowView):
    o: np.ndarray      # (B, 3) float32 origins
    d: np.ndarray      # (B, 3) float32 unit directions
    pix: np.ndarray    # (B,) int64 pixel index within the tile
    w: np.ndarray | None  # (B, n) white or (B,) mono, float32; None: white and all ones (camera rays)
    lam: np.ndarray | None  # (B,) int wavelength index for mono rays, None for white
    depth: np.ndarray  # (B,) int specular bounces so far
    u_lam: np.ndarray  # (B,) float: the sample's stratified number for choosing a wavelength
    # the eye pass's path state (core/transport/path_state.py: bounce counts, the last BSDF pdf
    # for MIS, ray differentials, ...); taken, concatenated and inherited with the rays. None: nothing.
    state: PathState | None = None
    # (k, n) float32 spectra shared by the population (k < n): w is (B, k) coefficients over
    # them (white light rays only); None: w is as above
    basis: np.ndarray | None = None

    def __len__(self):
        n = self.__dict__.get("_n")  # a subset's row count (its pix may not be gathered)
        return len(self.pix) if n is None else n

    def take(self, mask) -> "Rays":
        """The rays where ``mask`` (B,) bool is set, or at indices ``mask``: a subset whose fields
        are gathered when first read (core/transport/rows.py)."""
        idx = _indices(mask)
        if idx is None:
            return self
        new = subset(self, idx, _RAY_ROWS)
        nd = new.__dict__
        st = self.state
        nd["state"] = None if st is None else st.take(idx)
        nd["basis"] = self.basis
        nd["_n"] = len(idx)
        return new

    def moved(self, o, d, w, depth=None) -> "Rays":
        """The same paths (pixels, wavelengths, path state) continuing from o along d with weight w
        (coefficients over the same basis if w has the basis's k columns, else spectral)."""
        basis = self.basis if self.basis is not None and w is not None and w.ndim == 2 and \
            w.shape[1] == len(self.basis) else None
        new = object.__new__(Rays)
        nd, sd = new.__dict__, self.__dict__
        pending = sd.get("_pending")
        carried = {}
        for k in ("pix", "lam", "u_lam"):  # shared with these rays, gathered once if still pending
            if k in sd:
                nd[k] = sd[k]
            else:
                carried[k] = pending[k]
        nd["_pending"] = carried
        st = self.state
        nd.update(o=o, d=d, w=w, depth=self.depth + 1 if depth is None else depth,
                  state=None if st is None else st.copy(), basis=basis, _n=len(self))
        return new

    def weighted(self, x):
        """The ray weight times x (x itself for unit-weight camera rays)."""
        if self.w is None:
            return x
        return (self.dense_w(np.shape(x)[-1]) if self.basis is not None else self.w) * x

    def dense_w(self, n: int) -> np.ndarray:
        """The spectral weight (B, n) (white rays)."""
        return dense_weights(self.w, self.basis, len(self), n)

    def dense(self) -> "Rays":
        """These rays with spectral weights (B, n) instead of coefficients over a basis."""
        return self if self.basis is None else replace(self, w=self.dense_w(self.basis.shape[1]), basis=None)

    @staticmethod
    def concat(a: "Rays", b: "Rays") -> "Rays":
        basis = None
        if a.basis is not None or b.basis is not None:
            if a.basis is b.basis or (a.basis is not None and b.basis is not None and a.basis.shape == b.basis.shape
                                      and np.array_equal(a.basis, b.basis)):
                basis = a.basis  # coefficients over one basis: joined as they are
            else:
                a, b = a.dense(), b.dense()  # different bases: join as spectra
        if holds_none(a, "w") != holds_none(b, "w"):  # one side has implicit unit weights: make them explicit
            n = (a.w if a.w is not None else b.w).shape[1]
            a, b = a._with_w(a.dense_w(n)), b._with_w(b.dense_w(n))
        if (a.state is None) != (b.state is None):
            raise ValueError("cannot join ray populations that carry different state")
        if holds_none(a, "lam") != holds_none(b, "lam"):
            raise ValueError("cannot join white and mono rays")
        return _join([a, b], basis)

    def _with_w(self, w) -> "Rays":
        """These rays (their pending fields too) with weights w."""
        new = pending_copy(self)
        new.w = w
        return new

    @property
    def differentials(self) -> np.ndarray | None:
        """The rays' differentials (B, 5, 3) (core/sampling/footprint.py), or None where not carried."""
        return None if self.state is None else self.state.rd


def _concat_all(parts: list) -> Rays:
    """Rays.concat of parts[0], parts[1], ... in order: joined at once where they are alike
    (spectral or mono weights, no basis, the same state fields), else pairwise."""
    if len(parts) == 1:
        return parts[0]
    key = _join_key(parts[0])
    if key[0] or any(_join_key(r) != key for r in parts[1:]):
        nxt = parts[0]
        for r in parts[1:]:
            nxt = Rays.concat(nxt, r)
        return nxt
    return _join(parts)


def _join_key(r: Rays) -> tuple:
    """What must match for rays to join field by field (read without gathering anything)."""
    st = r.state
    return (r.basis is not None, holds_none(r, "w"), holds_none(r, "lam"), type(st), st is None or holds_none(st, "rd"))


def _join(parts: list, basis=None) -> Rays:
    """The rays of ``parts`` (alike: see _join_key) one after another, over ``basis``; fields
    still pending on one array in every part stay pending (core/transport/rows.py)."""
    a = parts[0]
    new = join(parts, _RAY_ROWS, object.__new__(Rays))
    nd = new.__dict__
    nd["state"] = None if a.state is None else PathState.join([r.state for r in parts])
    nd["basis"] = basis
    nd["_n"] = sum(len(r) for r in parts)
    return new


@dataclass
class Hit(RowView):
    p: np.ndarray     # (B, 3) float32 hit points
    ng: np.ndarray    # (B, 3) float32 geometric normal facing the incoming ray
    ns: np.ndarray    # (B, 3) float32 unit shading normal, on ng's side of the surface (ng itself when flat)
    cos_i: np.ndarray  # (B,) cosine between -d and ng (>= 0)
    front: np.ndarray  # (B,) bool: the ray arrived on the side the triangle's normal points to
    mat: np.ndarray   # (B,) material index
    eps: np.ndarray   # (B,) float32 self-intersection offset at the hit
    prim: np.ndarray  # (B,) triangle index
    bu: np.ndarray    # (B,) barycentric u (hit = (1-u-v) v0 + u v1 + v v2)
    bv: np.ndarray    # (B,) barycentric v

    _FIELDS = ("p", "ng", "ns", "cos_i", "front", "mat", "eps", "prim", "bu", "bv")

    def take(self, mask) -> "Hit":
        """The hits where ``mask`` (B,) bool is set, or at indices ``mask``: a subset whose fields
        are gathered when first read (core/transport/rows.py)."""
        idx = _indices(mask)
        if idx is None:
            return self
        new = subset(self, idx, self._FIELDS)
        d = self.__dict__
        if "ns" in d and d["ns"] is d.get("ng"):  # flat: one array for both, in the subset too
            new.__dict__["_pending"]["ns"] = "ng"
        return new

    @staticmethod
    def concat(a: "Hit", b: "Hit") -> "Hit":
        return Hit(*(np.concatenate([getattr(a, f), getattr(b, f)]) for f in Hit._FIELDS))


def light_spectrum_of(spectrum, live, rays: Rays):
    """A light sample's spectrum ((n,) or (B, n)) for ``rays`` = the rays at entries ``live``:
    (K, n) or (n,) for white rays, (K,) at their wavelengths for mono rays."""
    spec = spectrum if np.ndim(spectrum) == 1 else spectrum[live]
    if rays.lam is None:
        return spec
    return spec[rays.lam] if np.ndim(spec) == 1 else spec[np.arange(len(rays)), rays.lam]


def shading_normals(corner_normals: np.ndarray, prim, bu, bv, ng: np.ndarray) -> np.ndarray:
    """Unit shading normals (B, 3) at hits: the corner normals of triangle ``prim`` interpolated
    with the hit's barycentrics and normalised, on the side of ``ng`` (the triangle's winding
    normal, (B, 3)): a normal pointing into the other half-space (a bad custom normal) is
    negated, one that interpolates to zero (opposite corners) is ``ng``."""
    c = np.take(corner_normals, prim, axis=0)  # (B, 3, 3): a row gather, faster than c[prim]
    u = np.asarray(bu, c.dtype)
    v = np.asarray(bv, c.dtype)
    # geometry.interpolate_corners's (1 - u - v) c0 + u c1 + v c2 in one pass
    n = np.einsum("bk,bkj->bj", np.stack([1 - u - v, u, v], axis=1), c)
    l2 = np.einsum("ij,ij->i", n, n)
    # normalise and put on ng's side with one scale per row
    s = np.where(np.einsum("ij,ij->i", n, ng) < 0, np.float32(-1), np.float32(1)) / np.sqrt(
        np.maximum(l2, np.float32(1e-30)))
    n *= s.astype(n.dtype, copy=False)[:, None]
    flat = l2 <= np.float32(1e-12)  # interpolated to zero: ng
    if flat.any():
        n[flat] = ng[flat]
    return n.astype(np.float32, copy=False)


def smooth_triangles(corner_normals: np.ndarray) -> np.ndarray:
    """(T,) bool: the triangles whose three corner normals differ (smooth shading); on the others
    the shading normal is the (one) corner normal, with no interpolation. prepare() computes it
    once per scene (``PreparedScene.smooth_triangles``)."""
    c = corner_normals
    return ~((c[:, 0] == c[:, 1]).all(axis=1) & (c[:, 0] == c[:, 2]).all(axis=1))


def hit_shading_normals(corner_normals: np.ndarray, smooth: np.ndarray, prim, bu, bv, ng: np.ndarray) -> np.ndarray:
    """``shading_normals`` at hits, interpolating only on the ``smooth`` triangles (T,) bool
    (``smooth_triangles``): a flat-shaded triangle's normal is its corner normal (unit: prepared
    corner normals are validated), put on ng's side."""
    sm = np.take(smooth, prim)
    if sm.all():
        return shading_normals(corner_normals, prim, bu, bv, ng)
    # corner 0 = every corner there; unit already (scene validation normalises corner normals)
    n = np.take(corner_normals[:, 0], prim, axis=0)
    n *= np.where(np.einsum("ij,ij->i", n, ng) < 0, np.float32(-1), np.float32(1))[:, None]
    if sm.any():
        idx = np.flatnonzero(sm)
        n[idx] = shading_normals(corner_normals, prim[idx], np.asarray(bu)[idx], np.asarray(bv)[idx], ng[idx])
    return n.astype(np.float32, copy=False)


#: The mirror direction about a shading normal leaves at least this cosine above the geometric
#: surface (or 0.9 of the incoming ray's, if that is shallower): Cycles' threshold.
SPECULAR_MIN_COS = 0.01


def valid_specular_normal(wo: np.ndarray, ng: np.ndarray, ns: np.ndarray) -> np.ndarray:
    """The shading normal to reflect ``wo`` (unit, pointing away from the surface, wo . ng >= 0)
    about, for ``ns`` on ng's side: ``ns`` itself where the mirror direction R = 2 (ns . wo) ns - wo
    lies at least t = min(0.9 wo . ng, SPECULAR_MIN_COS) above the geometric surface, else ns
    rotated towards ``ng`` (in their common plane) until R . ng = t, as Cycles'
    ``ensure_valid_specular_reflection`` does. The rotated normal N' = sqrt(1 - z^2) X + z ng
    (X: ns's part perpendicular to ng) solves 2 (N' . wo) z - wo . ng = t; squared, a quadratic
    in z^2 (docs/physics.md section 4.6). Also fixes rays arriving behind ns (ns . wo < 0)."""
    iz = np.einsum("ij,ij->i", wo, ng)
    c = np.einsum("ij,ij->i", wo, ns)
    thresh = np.minimum(0.9 * iz, SPECULAR_MIN_COS)
    bad = 2 * c * np.einsum("ij,ij->i", ns, ng) - iz < thresh
    if not bad.any():
        return ns
    w, g, n = (x[bad].astype(np.float64) for x in (wo, ng, ns))
    izb, t = iz[bad].astype(np.float64), thresh[bad].astype(np.float64)
    x = n - np.einsum("ij,ij->i", n, g)[:, None] * g
    xl = np.linalg.norm(x, axis=1, keepdims=True)
    x = np.where(xl > 1e-12, x / np.maximum(xl, 1e-300), n)
    ix = np.einsum("ij,ij->i", w, x)
    a = np.maximum(ix * ix + izb * izb, 1e-300)
    b = 2 * (a + izb * t)
    root = np.sqrt(np.maximum(b * b - 4 * a * (t + izb) ** 2, 0))
    # of the two roots in z^2, the one that solves the unsquared equation: wo's X part and
    # t + wo.ng (1 - 2 z^2) have the same sign
    z2 = np.clip(np.where(ix < 0, b + root, b - root) / (4 * a), 0, 1)
    fixed = np.sqrt(1 - z2)[:, None] * x + np.sqrt(z2)[:, None] * g
    out = ns.copy()
    out[bad] = fixed
    return out


class SpecularWalker:
    """Advances ray populations through specular interactions; subclasses add the shading."""

    def __init__(self, prepared, rng: np.random.Generator):
        self.prepared = prepared
        self.n = prepared.grid.n
        self.rng = rng
        self.rays_cast = 0  # rays cast (a subclass adds its shadow rays)
        self.microfacet = prepared.microfacet  # (M,) bool, once per prepared scene
        self.any_microfacet = bool(self.microfacet.any())
        self._spawned: list[Rays] = []
        refl = prepared.materials.reflectance
        # (M,) reflectance constant over wavelength (clear glass and mirrors, grey tints): it
        # scales coefficient weights without expanding them to spectra
        self.grey = np.all(refl == refl[:, :1], axis=1) if refl.size else np.zeros(len(refl), bool)
        # hooks a subclass leaves as they are (the light pass's misses and segments) cost nothing
        self._hooks_segment = type(self).on_segment is not SpecularWalker.on_segment
        self._hooks_miss = type(self).on_miss is not SpecularWalker.on_miss
        self._hooks_media = False  # a subclass that traces media sets it (``through_media``)

    # hooks ----------------------------------------------------------------------------------
    def on_segment(self, rays: Rays, t: np.ndarray) -> None:
        """Every traced segment, before its hit or miss is handled: rays and the distance t (B,)
        to what they hit (inf: nothing) - where the eye pass finds the lights a ray passes."""

    def on_miss(self, rays: Rays) -> None:
        """Rays that left the scene."""

    def through_media(self, rays: Rays, h):
        """Every traced segment (after ``on_segment``) where ``_hooks_media`` is set: the media the
        segments cross (core/integrators/eye/medium_interaction.py). Returns (the rays going on to
        their hits, those hits, rays that scattered in a medium and go on from there, or None)."""
        return rays, h, None

    def on_hit(self, rays: Rays, hit: Hit, kind: np.ndarray, rng):
        """Every surface hit, before the specular bounce (kind: material kind per ray). What it
        returns (None by default) is handed to ``scatter`` of the same hits as ``shaded``: the
        shading it computed that the bounce reuses, passed explicitly."""

    def survives(self, rays: Rays, rng) -> np.ndarray:
        """Which rays may bounce again (default: the bounce limit)."""
        return rays.depth < self.prepared.settings.max_bounces

    def after_delta(self, rays: Rays, transmitted: np.ndarray) -> Rays:
        """Rays leaving a mirror or dielectric (``transmitted``: refracted rather than reflected),
        before they are traced on: a subclass counts bounces by kind and drops those over a limit."""
        return rays

    def scatter(self, rays: Rays, hit: Hit, kind: np.ndarray, can_bounce: np.ndarray, rng,
                shaded=None) -> Rays | None:
        """Rays continuing from the non-specular surfaces (diffuse, rough): None by default (the
        light pass ends its paths there; the eye pass samples a BSDF). ``shaded``: what
        ``on_hit`` returned for these hits. Mono rays returned for a white population (a
        grating's orders) join the mono population."""
        return None

    def choice_numbers(self, rays: Rays, rng) -> np.ndarray:
        """The numbers (B,) in [0, 1) of the reflect / refract choice of ``rays`` at smooth glass
        (default: ``rng``'s); the eye pass takes them from its pixel sampler."""
        return rng.random(len(rays))

    def classify(self, rays: Rays, hit: Hit, kind: np.ndarray, rng) -> np.ndarray:
        """The kind per hit the walk uses (default: the material's, rough ones MICROFACET); the
        light pass marks the paths a grating diffracts GRATING."""
        return kind

    # the loop -------------------------------------------------------------------------------
    @staticmethod
    def empty_mono() -> Rays:
        return Rays(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32), np.zeros(0, np.int64),
                    np.zeros(0, np.float32), np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros(0))

    def walk(self, rays: Rays, mono: Rays, tmax: np.ndarray | None = None) -> None:
        """Follow both populations until every path has ended. ``tmax`` (B,): how far the first
        segment of ``rays`` (camera rays) may reach (a camera's clip end; None: unbounded)."""
        rng = self.rng
        self._spawned = []  # mono rays a white population's scatter made (grating orders)
        first = tmax
        while len(rays) or len(mono):
            rays, children, child_hits = self._step(rays, None, rng, first)
            first = None
            for r in self._spawned:  # spawn()
                mono = Rays.concat(mono, r)
            self._spawned = []
            mono, _, _ = self._step(mono, (children, child_hits), rng)

    # ----------------------------------------------------------------- one bounce
    def _step(self, rays: Rays, pending, rng, tmax=None):
        """Advance a population by one interaction (``tmax``: its rays' reach, None: unbounded);
        returns (continuing rays, mono children, their hits)."""
        prepared = self.prepared
        hit = None
        in_medium = None  # rays scattered in a medium on this step's segments
        if len(rays):
            h = prepared.accel.intersect(rays.o, rays.d) if tmax is None else prepared.accel.intersect(rays.o, rays.d, tmax)
            self.rays_cast += len(rays)
            missed = h.prim < 0
            if self._hooks_segment:
                self.on_segment(rays, np.where(missed, np.float32(np.inf), h.t))
            if self._hooks_media:  # [volumes] participating media along the segments
                rays, h, in_medium = self.through_media(rays, h)
                missed = h.prim < 0
            keep = _indices(~missed)
            if self._hooks_miss and keep is not None:
                self.on_miss(rays.take(missed))
            if keep is None:
                hit = self.hit_info(rays, h.t, h.prim, h.u, h.v)
            else:
                rays = rays.take(keep)
                hit = self.hit_info(rays, h.t.take(keep), h.prim.take(keep), h.u.take(keep), h.v.take(keep))
        if pending is not None and pending[0] is not None and len(pending[0]):
            if hit is None:
                rays, hit = pending
            else:
                rays, hit = Rays.concat(rays, pending[0]), Hit.concat(hit, pending[1])
        if hit is None or len(rays) == 0:
            if in_medium is not None and len(in_medium):
                return in_medium, None, None
            return rays.take(np.zeros(len(rays), bool)), None, None

        kind = prepared.materials.kind.take(hit.mat)
        micro = self.microfacet.take(hit.mat) if self.any_microfacet else None
        if micro is not None:  # rough mirrors and glass leave the delta code; diffuse bases keep their kind
            kind = np.where(micro & (kind != DIFFUSE_KIND), MICROFACET, kind)
        kind = self.classify(rays, hit, kind, rng)
        shaded = self.on_hit(rays, hit, kind, rng)

        can_bounce = self.survives(rays, rng)
        children = child_hits = None
        out = []
        mirror = (kind == MIRROR) & can_bounce
        if np.count_nonzero(mirror):  # (counts cost a fifth of ndarray.any's call on small masks)
            r = self.mirror_bounce(rays.take(mirror), hit.take(mirror))
            out.append(self.after_delta(r, np.zeros(len(r), bool)))
        diel = (kind == DIELECTRIC) & can_bounce
        # white rays split at every dispersive glass, smooth or rough (mono children go on)
        is_white = holds_none(rays, "lam")
        white_split = (diel | ((kind == MICROFACET) & can_bounce)) if is_white else diel
        if np.count_nonzero(white_split):
            if is_white:
                disp = white_split & prepared.materials.dispersive.take(hit.mat)
                if np.count_nonzero(disp):  # core/transport/wavelengths.py: smooth glass reflects white, refracts mono
                    rd = rays.take(disp).dense()
                    children, child_hits, white = wavelengths.split_at_glass(self, rd, hit.take(disp), rng,
                                                                             self.choice_numbers(rd, rng))
                    if white is not None and len(white):
                        out.append(white)
                diel = diel & ~disp
            if np.count_nonzero(diel):
                r = rays.take(diel)
                r, transmitted = self.dielectric_bounce(r, hit.take(diel), rng, self.choice_numbers(r, rng))
                out.append(self.after_delta(r, transmitted))
        scattered = self.scatter(rays, hit, kind, can_bounce, rng, shaded)
        if scattered is not None and len(scattered):
            if scattered.differentials is not None:
                # a diffuse or rough bounce: no footprint any more (a point sample)
                scattered.state.rd = footprint.zero_differentials(len(scattered))
            if holds_none(scattered, "lam") == is_white:
                out.append(scattered)
            else:  # a white population's mono rays: traced with the mono population
                self.spawn(scattered)
        if in_medium is not None:
            out.append(in_medium)
        out = [r for r in out if len(r)]
        if not out:
            return rays.take(np.zeros(len(rays), bool)), children, child_hits
        return _concat_all(out), children, child_hits

    # ----------------------------------------------------------------- operations for subclasses and helpers
    def hit_info(self, rays: Rays, t, prim, bu, bv) -> Hit:
        """The hits (Hit) of ``rays`` at distances ``t`` on triangles ``prim`` with barycentrics
        (bu, bv): point, normals facing the ray, material, offset."""
        prepared = self.prepared
        if kernels_enabled() and _fits_hit_kernel(rays, t, prepared):
            return _hit_info_by_kernel(prepared, rays, t, prim, bu, bv)
        p = rays.o + t[:, None] * rays.d
        ng0 = np.take(prepared.tri_normal, prim, axis=0)  # row gathers: np.take is several times faster
        cos = -np.einsum("ij,ij->i", rays.d, ng0)
        front = cos > 0
        ng = ng0 * np.where(front, np.float32(1), np.float32(-1))[:, None]
        if prepared.corner_normals is None:
            ns = ng
        else:  # on the triangle's side first, then flipped with ng: both face the incoming ray's side
            ns = hit_shading_normals(prepared.corner_normals, prepared.smooth_triangles, prim, bu, bv, ng0)
            ns *= np.where(front, np.float32(1), np.float32(-1))[:, None]
        return Hit(p.astype(np.float32, copy=False), ng, ns, np.abs(cos), front, np.take(prepared.tri_material, prim),
                   np.take(prepared.tri_offset, prim), prim, bu, bv)

    @staticmethod
    def _per_ray(table, rows, lam):
        """table[rows] (B, n) for white rays, table[rows, lam] (B,) for mono rays."""
        return table[rows] if lam is None else table[rows, lam]

    def tinted_weight(self, rays: Rays, hit: Hit):
        """The weight after the surface's tint (skipped for clear glass and perfect mirrors)."""
        m = self.prepared.materials
        if m.clear[hit.mat].all():
            return rays.w
        if rays.basis is not None and self.grey[hit.mat].all():  # coefficients times a grey tint
            return rays.w * m.reflectance[hit.mat, :1]
        return rays.weighted(self._per_ray(m.reflectance, hit.mat, rays.lam))

    def specular_normal(self, rays: Rays, hit: Hit) -> np.ndarray:
        """The normal specular reflection and refraction use: ng when flat, else ns made valid."""
        if self.prepared.corner_normals is None:
            return hit.ng
        return valid_specular_normal(-rays.d, hit.ng, hit.ns)

    def mirror_bounce(self, rays: Rays, hit: Hit) -> Rays:
        """Rays reflected by the smooth mirrors they hit: about the specular normal, weight times
        the tint, differentials reflected (a hook: a subclass adds a grating layer's share)."""
        ns = self.specular_normal(rays, hit)
        d = reflect(rays.d, ns)
        o = hit.p + hit.eps[:, None] * hit.ng
        film = thin_film.film_rows(self.prepared.materials, hit.mat)
        w = self.tinted_weight(rays, hit) if film is None else self._filmed_mirror_weight(rays, hit, ns, film)
        out = rays.moved(o.astype(np.float32), d.astype(np.float32), w)
        if out.differentials is not None:  # ray differentials (core/sampling/footprint.py)
            out.state.rd = footprint.reflect_differentials(rays.differentials, rays.o, rays.d, hit.p, ns)
        return out

    def _filmed_mirror_weight(self, rays: Rays, hit: Hit, ns, film):
        """The weight after mirrors some of which (``film`` (B,) bool) carry a thin film: there the
        tint is the film-over-conductor reflectance at the ray's angle and wavelengths
        (core/materials/thin_film.py), elsewhere the tint (docs/physics.md section 2.8)."""
        m = self.prepared.materials
        table = np.array(self._per_ray(m.reflectance, hit.mat, rays.lam), np.float32)  # (B, n) or (B,)
        idx = np.flatnonzero(film)
        cos = np.abs(np.einsum("ij,ij->i", rays.d[idx], ns[idx]))
        table[idx] = thin_film.conductor_reflectance(m, self.prepared.grid.wavelengths, hit.mat[idx], cos,
                                                     None if rays.lam is None else rays.lam[idx])
        return rays.weighted(table)

    def _glass_fresnel(self, rays: Rays, hit: Hit, cos, n, fr):
        """``fr`` (B,) with the thin film's reflectance where the glass has one (None: no film)."""
        film = thin_film.film_rows(self.prepared.materials, hit.mat)
        if film is None:
            return fr
        idx = np.flatnonzero(film)
        lam = np.zeros(len(rays), np.int64) if rays.lam is None else rays.lam
        fr = np.array(fr, np.float32)
        fr[idx] = thin_film.glass_fresnel(self.prepared.materials, self.prepared.grid.wavelengths, hit.mat[idx],
                                          hit.front[idx], np.asarray(cos)[idx], np.asarray(n)[idx], lam[idx])
        return fr

    def dielectric_bounce(self, rays: Rays, hit: Hit, rng, u=None) -> tuple[Rays, np.ndarray]:
        """Fresnel-sampled reflection or refraction at smooth glass: (the rays going on, refracted
        (B,) bool); ``u`` (B,): the choice's numbers (reflect where u < F), None: drawn from
        ``rng``. A hook: a subclass may split both branches (core/integrators/eye/fresnel_split.py)
        or add a grating layer, calling this for the plain choice.

        Both directions are a d + b n about the specular normal n (the mirror: a = 1, b = 2 cos;
        Snell's law: a = eta, b = eta cos - cos_t; under total internal reflection fr = 1, so the
        mirror is chosen): one pass over (B, 3) for both branches."""
        prepared = self.prepared
        ior = prepared.materials.ior
        ns = self.specular_normal(rays, hit)
        film = thin_film.film_rows(prepared.materials, hit.mat)
        if kernels_enabled() and film is None and _fits_dielectric_kernel(rays, hit, ns, ior):
            d, o, transmitted = _dielectric_by_kernel(ior, rays, hit, ns, rng.random(len(rays)) if u is None else u)
            out = rays.moved(o, d, self.tinted_weight(rays, hit))
            if out.differentials is not None:  # ray differentials (core/sampling/footprint.py)
                e = _eta(ior, rays, hit)
                out.state.rd = footprint.refract_differentials(rays.differentials, rays.o, rays.d, hit.p, ns, d, e)
            return out, transmitted
        # constant over the grid for white rays
        n = np.take(ior[:, 0], hit.mat) if rays.lam is None else ior[hit.mat, rays.lam]
        eta = np.where(hit.front, 1.0 / n, n).astype(np.float32)
        cos_s = hit.cos_i if ns is hit.ng else -np.einsum("ij,ij->i", rays.d, ns)
        cos = np.asarray(cos_s, np.float32)
        fr, _ = fresnel_dielectric(np.abs(cos), np.where(hit.front, n, 1.0 / n).astype(np.float32))
        if film is not None:  # a thin film's interference (docs/physics.md section 2.8)
            fr = self._glass_fresnel(rays, hit, cos, n, fr)
        refl = (rng.random(len(rays)) if u is None else u) < fr
        cos_t = np.sqrt(np.maximum(np.float32(0), 1 - eta * eta * np.maximum(np.float32(0), 1 - cos * cos)))
        a = np.where(refl, np.float32(1), eta)
        b = np.where(refl, 2 * cos, eta * cos - cos_t)
        d = a[:, None] * rays.d + b[:, None] * ns
        dn = np.einsum("ij,ij->i", d, hit.ng)
        if ns is not hit.ng:
            # a refraction about ns that stays on the incident side is refracted about ng instead
            stay = ~refl & (dn >= 0)
            if stay.any():
                d[stay] = refract(rays.d[stay], hit.ng[stay], eta[stay])[0]
                dn[stay] = np.einsum("ij,ij->i", d[stay], hit.ng[stay])
        # offset to the side the new direction leaves on (a refraction about ng can be a TIR)
        side = np.where(dn > 0, np.float32(1), np.float32(-1))
        o = hit.p + (hit.eps * side)[:, None] * hit.ng
        out = rays.moved(o.astype(np.float32, copy=False), d.astype(np.float32, copy=False),
                         self.tinted_weight(rays, hit))
        if out.differentials is not None:  # ray differentials (core/sampling/footprint.py)
            out.state.rd = footprint.refract_differentials(rays.differentials, rays.o, rays.d, hit.p, ns, d, eta)
        return out, side < 0

    def spawn(self, mono: Rays) -> None:
        """Mono rays made from a white population during its step (a dispersive refraction, a
        grating's orders): the walk traces them with the mono population from its next step."""
        self._spawned.append(mono)

    def split_white(self, rays: Rays, hit: Hit, rng):
        """White rays at a dispersive interface -> mono rays (SPLIT or SAMPLE), keeping the hit.

        SAMPLE draws ``dispersion_branches`` (a setting) wavelengths per ray from the ray's stratified number,
        importance-sampled by the image's sensitivity (core/transport/wavelengths.py, docs/physics.md
        section 2.6); SPLIT makes one child per wavelength with the parent's weight there."""
        n, b = self.n, len(rays)
        if self.prepared.settings.dispersion_sampling != "SPLIT":
            s = self.prepared.settings
            parent, lam, w = wavelengths.draw(self.prepared.grid, rays.w, rays.u_lam, s.dispersion_branches,
                                              s.dispersion_importance)
        elif rays.w is None:  # unit weights: every wavelength alike
            parent, lam = np.repeat(np.arange(b), n), np.tile(np.arange(n), b)
            w = np.ones(b * n, np.float32)
        else:
            parent, lam = np.nonzero(rays.w > 0)
            w = rays.w[parent, lam]
        state = None if rays.state is None else rays.state.take(parent)
        wavelengths.child_split(state, w, parent, rays.w)  # Russian roulette's throughput of a mono child
        children = Rays(rays.o[parent], rays.d[parent], rays.pix[parent], w.astype(np.float32),
                         lam.astype(np.int64), rays.depth[parent], rays.u_lam[parent], state)
        return children, hit.take(parent)


# ---------------------------------------------------------------------------------- compiled kernels
_F32 = np.dtype(np.float32)


def _rows3(*arrays) -> bool:
    return all(isinstance(a, np.ndarray) and a.dtype == _F32 and a.ndim == 2 and a.shape[1:] == (3,) for a in arrays)


def _fits_hit_kernel(rays: Rays, t, prepared) -> bool:
    """The arrays _hit_kernel is compiled for: float32 rays, distances and normals."""
    return (len(rays) > 0 and _rows3(rays.o, rays.d, prepared.tri_normal) and isinstance(t, np.ndarray)
            and t.dtype == _F32 and prepared.tri_offset.dtype == _F32)


def _hit_info_by_kernel(prepared, rays: Rays, t, prim, bu, bv) -> Hit:
    """hit_info's lines by _hit_kernel (the shading normals by hit_shading_normals)."""
    b = len(rays)
    p, ng = np.empty((b, 3), np.float32), np.empty((b, 3), np.float32)
    cos_i, front = np.empty(b, np.float32), np.empty(b, np.bool_)
    mat, eps = np.empty(b, prepared.tri_material.dtype), np.empty(b, np.float32)
    _hit_kernel(rays.o, rays.d, t, prim, prepared.tri_normal, prepared.tri_material, prepared.tri_offset,
                p, ng, cos_i, front, mat, eps)
    cn = prepared.corner_normals
    if cn is None:
        ns = ng
    elif cn.dtype == _F32 and all(isinstance(x, np.ndarray) and x.dtype == _F32 for x in (bu, bv)):  # hit_shading_normals, then flipped with ng
        ns = np.empty((b, 3), np.float32)
        _shading_kernel(cn, prepared.smooth_triangles, prim, bu, bv, prepared.tri_normal, front, ns)
    else:  # on the triangle's side first, then flipped with ng: both face the incoming ray's side
        ns = hit_shading_normals(cn, prepared.smooth_triangles, prim, bu, bv, np.take(prepared.tri_normal, prim, axis=0))
        ns *= np.where(front, np.float32(1), np.float32(-1))[:, None]
    return Hit(p, ng, ns, cos_i, front, mat, eps, prim, bu, bv)


@njit
def _shading_kernel(cn, smooth, prim, bu, bv, tri_normal, front, ns):
    """hit_shading_normals' float32 lines per hit (einsum's sequential sums over the three
    corners and components), then the flip to the incoming ray's side."""
    one = np.float32(1.0)
    for i in range(prim.shape[0]):
        j = prim[i]
        g0, g1, g2 = tri_normal[j, 0], tri_normal[j, 1], tri_normal[j, 2]
        if smooth[j]:  # shading_normals: interpolated, normalised, on ng's side
            u, v = bu[i], bv[i]
            w0 = one - u - v
            n0 = (w0 * cn[j, 0, 0] + u * cn[j, 1, 0]) + v * cn[j, 2, 0]
            n1 = (w0 * cn[j, 0, 1] + u * cn[j, 1, 1]) + v * cn[j, 2, 1]
            n2 = (w0 * cn[j, 0, 2] + u * cn[j, 1, 2]) + v * cn[j, 2, 2]
            l2 = (n0 * n0 + n1 * n1) + n2 * n2
            sg = -one if (n0 * g0 + n1 * g1) + n2 * g2 < 0 else one
            sc = sg / np.sqrt(max(l2, np.float32(1e-30)))
            n0, n1, n2 = n0 * sc, n1 * sc, n2 * sc
            if l2 <= np.float32(1e-12):  # interpolated to zero: ng
                n0, n1, n2 = g0, g1, g2
        else:  # a flat-shaded triangle: its corner normal on ng's side
            n0, n1, n2 = cn[j, 0, 0], cn[j, 0, 1], cn[j, 0, 2]
            sg = -one if (n0 * g0 + n1 * g1) + n2 * g2 < 0 else one
            n0, n1, n2 = n0 * sg, n1 * sg, n2 * sg
        f = one if front[i] else -one
        ns[i, 0], ns[i, 1], ns[i, 2] = n0 * f, n1 * f, n2 * f


@njit
def _hit_kernel(o, d, t, prim, tri_normal, tri_material, tri_offset, p, ng, cos_i, front, mat, eps):
    """hit_info's NumPy lines per hit (float32, einsum's order of the dot product)."""
    for i in range(prim.shape[0]):
        j = prim[i]
        for k in range(3):
            p[i, k] = o[i, k] + t[i] * d[i, k]
        c = -((d[i, 0] * tri_normal[j, 0] + d[i, 1] * tri_normal[j, 1]) + d[i, 2] * tri_normal[j, 2])
        f = c > 0
        s = np.float32(1.0) if f else np.float32(-1.0)
        for k in range(3):
            ng[i, k] = tri_normal[j, k] * s
        cos_i[i], front[i], mat[i], eps[i] = abs(c), f, tri_material[j], tri_offset[j]


def _fits_dielectric_kernel(rays: Rays, hit: Hit, ns, ior) -> bool:
    """The arrays _dielectric_kernel is compiled for (float32 rays and hits, a float index table)."""
    return (len(rays) > 0 and _rows3(rays.d, hit.p, hit.ng, ns) and hit.eps.dtype == _F32
            and hit.cos_i.dtype == _F32 and ior.dtype.kind == "f")


def _eta(ior, rays: Rays, hit: Hit) -> np.ndarray:
    """(B,) float32 n_i / n_t of the rays (white ones: the grid's first wavelength)."""
    n = np.take(ior[:, 0], hit.mat) if rays.lam is None else ior[hit.mat, rays.lam]
    return np.where(hit.front, 1.0 / n, n).astype(np.float32)


def _dielectric_by_kernel(ior, rays: Rays, hit: Hit, ns, u):
    """dielectric_bounce's directions, origins and transmitted flags by _dielectric_kernel."""
    b = len(rays)
    d, o, transmitted = np.empty((b, 3), np.float32), np.empty((b, 3), np.float32), np.empty(b, np.bool_)
    lam = np.zeros(b, np.int64) if rays.lam is None else rays.lam
    cos_s = hit.cos_i if ns is hit.ng else -np.einsum("ij,ij->i", rays.d, ns)
    _dielectric_kernel(ior, ior.dtype.type(1.0), hit.mat, lam, hit.front, np.asarray(cos_s, np.float32),
                       np.asarray(u, np.float64), rays.d, ns, hit.ng, hit.p, hit.eps, ns is hit.ng, d, o, transmitted)
    return d, o, transmitted


@njit
def _dielectric_kernel(ior, one_n, mat, lam, front, cos_s, u, d, ns, ng, p, eps, flat, d_out, o_out, transmitted):
    """dielectric_bounce's NumPy lines per ray: the index at the ray's wavelength (in the table's
    precision), fresnel_dielectric in float32, the Fresnel-sampled mirror or Snell direction
    a d + b n, the refraction about ng where one about ns stays on the incident side, the offset."""
    one, two, zero, tiny = np.float32(1.0), np.float32(2.0), np.float32(0.0), np.float32(1e-30)
    half = one / (one + one)
    for i in range(mat.shape[0]):
        nn = ior[mat[i], lam[i]]
        inv = one_n / nn
        e = np.float32(inv if front[i] else nn)  # n_i / n_t
        fe = np.float32(nn if front[i] else inv)  # n_t / n_i, fresnel_dielectric's eta
        c = cos_s[i]
        ca = min(max(abs(c), zero), one)
        sin2_t = (one - ca * ca) / (fe * fe)
        ct = np.sqrt(max(one - sin2_t, zero))
        r_par = (fe * ca - ct) / max(fe * ca + ct, tiny)
        r_perp = (ca - fe * ct) / max(ca + fe * ct, tiny)
        fr = one if sin2_t >= one else half * (r_par * r_par + r_perp * r_perp)
        refl = u[i] < fr
        cos_t = np.sqrt(max(zero, one - e * e * max(zero, one - c * c)))
        a = one if refl else e
        bb = two * c if refl else e * c - cos_t
        for k in range(3):
            d_out[i, k] = a * d[i, k] + bb * ns[i, k]
        dn = (d_out[i, 0] * ng[i, 0] + d_out[i, 1] * ng[i, 1]) + d_out[i, 2] * ng[i, 2]
        if not flat and not refl and dn >= 0:  # about ns onto the incident side: about ng instead
            wavelengths._refract32(d[i], ng[i], e, d_out[i])
            dn = (d_out[i, 0] * ng[i, 0] + d_out[i, 1] * ng[i, 1]) + d_out[i, 2] * ng[i, 2]
        sd = one if dn > 0 else -one
        for k in range(3):
            o_out[i, k] = p[i, k] + (eps[i] * sd) * ng[i, k]
        transmitted[i] = sd < 0
