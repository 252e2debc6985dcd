"""Equirectangular environment maps: radiance lookup and importance sampling of directions.

Convention (Cycles, ``intern/cycles/kernel/camera/projection.h``: ``direction_to_equirectangular``
with the range (-2 pi, pi, -pi, pi)): a direction m = (x, y, z) in the map's frame has

    u = 0.5 - atan2(y, x) / (2 pi),    v = 1 - acos(z) / pi,

so u = 0 and 1 look along -X, u = 0.25 along +Y, u = 0.5 along +X, v = 0 straight down (-Z) and
v = 1 straight up; the image's row 0 is at the bottom (Blender's order), so row j spans
v in [j / H, (j + 1) / H]. The texel lookup is Cycles' (``kernel/svm/image.h``): bilinear with
texel centres at (i + 0.5) / W, or the nearest texel, and EXTENSION_REPEAT in both directions
(``EnvironmentTextureNode::image_params``). A world direction d is looked up at m = R d, R the
map's rotation (the Mapping node's, blender/export/world.py).

Sampling (pbrt-v4 section 12.5.2, ``ImageInfiniteLight`` with ``PiecewiseConstant2D``; Cycles'
background importance map, ``scene/light.cpp``): each texel gets a weight
w_ij = Y_ij * Omega_j, the luminance of the texel (for bilinear lookups its average over the
texel's cell, the separable kernel (1/8, 3/4, 1/8), so every direction with a non-zero lookup has
a non-zero density) times the texel's exact solid angle Omega_j = (2 pi / W) (cos theta_top -
cos theta_bottom). A row is chosen from the marginal over rows, a texel from that row's
conditional, and within the texel the direction is uniform in (phi, cos theta): the density in
solid angle is constant over each texel,

    pdf(d) = w_ij / (sum w * Omega_j) = Y_ij / sum_kl Y_kl Omega_l,

which is pbrt's p(u, v) / (2 pi^2 sin theta) with p constant in (u, cos theta) rather than in
(u, v): no infinite density at the poles (docs/physics.md section 7.9). An all-black map samples
the sphere uniformly (density 1 / 4 pi) and returns zero radiance.

The texel lookup runs as a compiled kernel where the kernels run (core/util/jit.py): the NumPy
lines' operations in their order and precisions, one pass per direction (four texel gathers and
the bilinear blend) instead of a dozen (B, 3) temporaries; the same bits. So do the lookups of
float32 directions (``radiance_rgb``, ``pdf``, ``lookup``: rotation, (u, v), texel and density
in one pass, ``_directions_kernel``) and ``sample`` (``_sample_kernel``: per number a binary
search of the marginal CDF and one of the chosen row's conditional CDF, which finds the entry
NumPy's searchsorted of the whole stacked CDF finds, in the callers' order, with no sort).
One exception to "the same bits": the float32 angles of a direction's (u, v) are libm's atan2f
and acosf in the kernels and NumPy's in the reference, which on AVX-512 machines are SVML's
(within 2 ulps of libm's, and even differing with an element's place in its array); everything
after the angles is the reference's arithmetic (tests/lights/test_environment_kernels.py).
"""

from __future__ import annotations

import numpy as np

from ..util.jit import kernels_enabled, njit

__all__ = ["EnvironmentMap", "LUMINANCE", "direction_to_uv", "uv_to_direction", "INTERPOLATIONS"]

#: Rec.709 luminance weights (the Y row of the RGB -> XYZ matrix), for the sampling weights.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
#: Texel lookups Cycles offers that are done here (CUBIC and SMART are exported as LINEAR).
INTERPOLATIONS = ("LINEAR", "CLOSEST")

_TWO_PI = 2.0 * np.pi


def direction_to_uv(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cycles' equirectangular (u, v) of map-frame directions m (B, 3) (any length > 0), in
    float32 for float32 input, else float64."""
    m = np.asarray(m)
    if kernels_enabled() and m.dtype == np.float32 and m.ndim == 2 and m.shape[1] == 3:
        u, v = np.empty(len(m), np.float32), np.empty(len(m), np.float32)
        _uv_kernel(m, u, v)
        return u, v
    if m.dtype != np.float32:
        m = m.astype(np.float64, copy=False)
    ln = np.sqrt(np.einsum("ij,ij->i", m, m))
    z = np.clip(m[:, 2] / np.where(ln > 0, ln, 1), -1, 1)
    one, pi, two_pi = (m.dtype.type(x) for x in (1.0, np.pi, _TWO_PI))
    u = one / 2 - np.arctan2(m[:, 1], m[:, 0]) / two_pi
    v = one - np.arccos(z) / pi
    return u, v


def uv_to_direction(u, v) -> np.ndarray:
    """The map-frame unit direction (B, 3) of (u, v): phi = pi - 2 pi u, theta = pi (1 - v)."""
    phi = np.pi - _TWO_PI * np.asarray(u)
    theta = np.pi * (1.0 - np.asarray(v))
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=-1)


class EnvironmentMap:
    """An equirectangular radiance map (W/m^2/sr per linear Rec.709 unit) and its sampling.

    ``rgb`` (H, W, 3) linear Rec.709 radiance, row 0 at the bottom; ``rotation`` (3, 3) orthogonal,
    world direction -> map direction; ``interpolation`` 'LINEAR' or 'CLOSEST'. Immutable after
    construction (its arrays are read-only), so threads share it.
    """

    def __init__(self, rgb: np.ndarray, rotation: np.ndarray | None = None, interpolation: str = "LINEAR"):
        rgb = np.asarray(rgb, np.float32)
        if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[0] < 1 or rgb.shape[1] < 1:
            raise ValueError(f"an environment map is (H, W, 3), got shape {rgb.shape}")
        if not np.isfinite(rgb).all() or (rgb < 0).any():
            raise ValueError("an environment map's radiance must be finite and non-negative")
        if interpolation not in INTERPOLATIONS:
            raise ValueError(f"interpolation {interpolation!r} is not one of {INTERPOLATIONS}")
        rot = np.eye(3) if rotation is None else np.asarray(rotation, np.float64)
        if rot.shape != (3, 3) or not np.allclose(rot @ rot.T, np.eye(3), atol=1e-5):
            raise ValueError("an environment map's rotation must be an orthogonal 3x3 matrix")
        self.rgb = np.ascontiguousarray(rgb)
        # texels padded to 16 bytes and viewed as complex128: one np.take per corner gathers a
        # whole texel (fancy indexing of (H, W, 3) by two index arrays is ~10x slower)
        padded = np.zeros((rgb.shape[0] * rgb.shape[1], 4), np.float32)
        padded[:, :3] = self.rgb.reshape(-1, 3)
        self._texels = padded.view(np.complex128).ravel()
        self.rotation = rot
        self.interpolation = interpolation
        h, w = rgb.shape[:2]
        self.height, self.width = h, w
        # row j spans v in [j/H, (j+1)/H], i.e. z = cos(theta) in [-cos(pi j/H), -cos(pi (j+1)/H)]
        z_edges = -np.cos(np.pi * np.arange(h + 1) / h)
        z_edges[0], z_edges[-1] = -1.0, 1.0
        self._z_lo = z_edges[:-1]
        self._dz = np.diff(z_edges)
        omega_row = (_TWO_PI / w) * self._dz                      # (H,) solid angle of a texel
        lum = self.rgb.astype(np.float64) @ LUMINANCE              # (H, W)
        if interpolation == "LINEAR":  # the mean of the bilinear lookup over each texel's cell
            lum = _cell_mean(lum)
        weights = lum * omega_row[:, None]
        total = float(weights.sum())
        #: The map is black: sampling falls back to the uniform sphere.
        self.black = not total > 0
        if self.black:
            weights = np.broadcast_to(omega_row[:, None], (h, w)).copy()
            total = float(weights.sum())  # 4 pi up to rounding
        row = weights.sum(axis=1)
        self._row_cdf = np.concatenate([[0.0], np.cumsum(row)]) / total
        self._row_cdf[-1] = 1.0
        safe = np.where(row > 0, row, 1.0)
        cond = np.concatenate([np.zeros((h, 1)), np.cumsum(weights, axis=1)], axis=1) / safe[:, None]
        cond[:, -1] = 1.0
        cond[row <= 0] = np.linspace(0.0, 1.0, w + 1)  # never chosen; kept monotone
        # rows stacked as [j, j + 1] so one searchsorted serves every row
        self._cond_flat = (cond + np.arange(h)[:, None]).ravel()
        #: (H, W) float64 solid-angle density of each texel (sample() and pdf()).
        self.density = weights / (total * omega_row[:, None])
        self._omega_row = omega_row
        #: The rotation is the identity: the kernels rotate float32 directions themselves (d * 1 + 0s,
        #: as the matrix product does), else the NumPy product does (BLAS' operation order).
        self._identity = bool(np.array_equal(rot, np.eye(3)))
        self._rot32 = np.ascontiguousarray(rot.T.astype(np.float32))  # d @ _rot32 is _map_dirs(d)
        for a in (self.rgb, self._texels, self.rotation, self._row_cdf, self._cond_flat, self.density, self._z_lo, self._dz):
            a.flags.writeable = False

    # ----------------------------------------------------------------- lookups
    def _map_dirs(self, d) -> np.ndarray:
        """Map-frame directions of world directions d (B, 3), in d's precision (float32 rays
        stay float32: a texel of a 16 k map is 4e-4 rad, float32 resolves 1e-7)."""
        d = np.asarray(d)
        dtype = np.float32 if d.dtype == np.float32 else np.float64
        return d.reshape(-1, 3).astype(dtype, copy=False) @ self.rotation.T.astype(dtype)

    def _texel_values(self, j: np.ndarray, i: np.ndarray) -> np.ndarray:
        """(B, 3) float32 texels at rows j, columns i (in range)."""
        return np.take(self._texels, j * self.width + i).view(np.float32).reshape(-1, 4)[:, :3]

    def _lookup(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Texel lookup at (u, v) (B,), Cycles' way: (B, 3) float32."""
        h, w = self.height, self.width
        if kernels_enabled():
            u, v = np.asarray(u), np.asarray(v)
            if u.ndim == 1 and u.shape == v.shape and u.dtype == v.dtype and u.dtype in (np.float32, np.float64):
                out = np.empty((len(u), 3), np.float32)
                _lookup_kernel(u, v, self.rgb.reshape(-1, 3), u.dtype.type(w), u.dtype.type(h), w, h,
                               self.interpolation == "CLOSEST", out)
                return out
        x = np.asarray(u) * w
        y = np.asarray(v) * h
        if self.interpolation == "CLOSEST":
            i = np.floor(x).astype(np.int64) % w
            j = np.floor(y).astype(np.int64) % h
            return np.ascontiguousarray(self._texel_values(j, i))
        x, y = x - 0.5, y - 0.5
        i0, j0 = np.floor(x), np.floor(y)
        fx, fy = (x - i0).astype(np.float32)[:, None], (y - j0).astype(np.float32)[:, None]
        i0, j0 = i0.astype(np.int64) % w, j0.astype(np.int64) % h
        i1, j1 = (i0 + 1) % w, (j0 + 1) % h
        top = self._texel_values(j1, i0) * (1 - fx) + self._texel_values(j1, i1) * fx
        bottom = self._texel_values(j0, i0) * (1 - fx) + self._texel_values(j0, i1) * fx
        return bottom * (1 - fy) + top * fy

    def radiance_rgb(self, d) -> np.ndarray:
        """(B, 3) float32 radiance arriving from world directions ``d`` (B, 3) (the direction the
        light comes from, i.e. a ray's direction when it escapes)."""
        if kernels_enabled():
            got = self._kernel_lookup(d, True, False)
            if got is not None:
                return got[0]
        u, v = direction_to_uv(self._map_dirs(d))
        return self._lookup(u, v)

    def lookup(self, d) -> tuple[np.ndarray, np.ndarray]:
        """(radiance_rgb(d), pdf(d)): both in one pass where the kernels run."""
        if kernels_enabled():
            got = self._kernel_lookup(d, True, True)
            if got is not None:
                return got
        return self.radiance_rgb(d), self.pdf(d)

    def _kernel_lookup(self, d, want_rgb: bool, want_pdf: bool):
        """(rgb (B, 3) float32, pdf (B,) float64) of float32 directions ``d`` (B, 3) by
        _directions_kernel (an array not asked for is empty); None for other input."""
        d = np.asarray(d)
        if d.dtype != np.float32 or d.ndim != 2 or d.shape[1] != 3:
            return None
        b = len(d)
        m = d if self._identity else self._map_dirs(d)
        rgb = np.empty((b if want_rgb else 0, 3), np.float32)
        pdf = np.empty(b if want_pdf else 0)
        _directions_kernel(m, self._rot32, self._identity, self.rgb.reshape(-1, 3), self.density,
                           self.width, self.height, self.interpolation == "CLOSEST", rgb, pdf)
        return rgb, pdf

    def _texel(self, u, v) -> tuple[np.ndarray, np.ndarray]:
        i = np.floor(np.asarray(u) * self.width).astype(np.int64) % self.width
        j = np.clip(np.floor(np.asarray(v) * self.height).astype(np.int64), 0, self.height - 1)
        return i, j

    def pdf(self, d) -> np.ndarray:
        """(B,) float64: the solid-angle density with which :meth:`sample` draws world direction d."""
        if kernels_enabled():
            got = self._kernel_lookup(d, False, True)
            if got is not None:
                return got[1]
        u, v = direction_to_uv(self._map_dirs(d))
        i, j = self._texel(u, v)
        return np.take(self.density, j * self.width + i)

    # ----------------------------------------------------------------- sampling
    def sample(self, u1, u2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Directions for uniform numbers u1, u2 (B,) in [0, 1): world directions (B, 3) float64,
        their solid-angle pdf (B,) float64 and radiance (B, 3) float32. Stratified numbers stay
        stratified (one number picks the row and the height within it, the other the column
        and the azimuth within the texel)."""
        u1 = np.asarray(u1, np.float64).ravel()
        u2 = np.asarray(u2, np.float64).ravel()
        h, w = self.height, self.width
        if kernels_enabled() and len(u1) == len(u2):
            b = len(u1)
            m, pdf, rgb = np.empty((b, 3)), np.empty(b), np.empty((b, 3), np.float32)
            _sample_kernel(u1, u2, self._row_cdf, self._cond_flat, self._z_lo, self._dz, self.density,
                           self.rgb.reshape(-1, 3), w, h, self.interpolation == "CLOSEST", self.black, m, pdf, rgb)
            return m @ self.rotation, pdf, rgb
        j = np.clip(np.searchsorted(self._row_cdf, u1, side="right") - 1, 0, h - 1)
        x = j + u2
        # work in texel order: the search over the H (W + 1) conditional CDF entries and the
        # texel lookups then walk memory in order (measured 20x faster on a 4 k map than
        # random order); the results go back to the callers' order at the end
        order = np.argsort(x)
        u1, j, x = u1[order], j[order], x[order]
        lo, hi = self._row_cdf[j], self._row_cdf[j + 1]
        t1 = np.clip((u1 - lo) / np.where(hi > lo, hi - lo, 1.0), 0.0, 1.0)
        k = np.clip(np.searchsorted(self._cond_flat, x, side="right") - 1, j * (w + 1), j * (w + 1) + w - 1)
        i = k - j * (w + 1)
        clo, chi = self._cond_flat[k], self._cond_flat[k + 1]
        t2 = np.clip((x - clo) / np.where(chi > clo, chi - clo, 1.0), 0.0, 1.0)
        u = (i + t2) / w
        z = np.clip(self._z_lo[j] + t1 * self._dz[j], -1.0, 1.0)
        v = np.clip(1.0 - np.arccos(z) / np.pi, j / h, (j + 1) / h)  # stay in the texel's row
        phi = np.pi - _TWO_PI * u
        s = np.sqrt(np.maximum(0.0, 1.0 - z * z))
        m = np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)
        pdf = np.take(self.density, j * w + i)
        rgb = np.zeros((len(u1), 3), np.float32) if self.black else self._lookup(u, v)
        back = np.empty_like(order)
        back[order] = np.arange(len(order))
        # R^T m as row vectors; np.take: row gathers by fancy indexing are several times slower
        return np.take(m, back, axis=0) @ self.rotation, np.take(pdf, back), np.take(rgb, back, axis=0)

    # ----------------------------------------------------------------- totals
    def mean_rgb(self) -> np.ndarray:
        """(3,) float64: the map's radiance averaged over the sphere (texel values times their
        solid angle, / 4 pi): the uniform world of the same total power."""
        return np.einsum("hwc,h->c", self.rgb.astype(np.float64), self._omega_row) / (4 * np.pi)

    def integral_rgb(self) -> np.ndarray:
        """(3,) float64: the radiance integrated over the sphere (W/m^2 per RGB unit): what a
        disk of unit area facing every direction in turn collects, the world's power per unit
        of cross-section."""
        return 4 * np.pi * self.mean_rgb()


def _cell_mean(a: np.ndarray) -> np.ndarray:
    """The mean of the bilinear interpolant of ``a`` (H, W) over each texel's cell, with wrap-around
    in both directions: the separable kernel (1/8, 3/4, 1/8)."""
    a = 0.75 * a + 0.125 * (np.roll(a, 1, axis=1) + np.roll(a, -1, axis=1))
    return 0.75 * a + 0.125 * (np.roll(a, 1, axis=0) + np.roll(a, -1, axis=0))


@njit
def _lookup_one(x, y, half, texels, w, h, closest, out, b):
    """One direction of EnvironmentMap._lookup's NumPy lines: x = u * W and y = v * H in u's
    precision (``half``: 0.5 in it), the blend weights in float32, the indices wrapped (Python's
    modulo, as NumPy's); ``texels`` (H W, 3) float32; the texel into out[b]."""
    one = np.float32(1.0)
    if closest:
        i = np.int64(np.floor(x)) % w
        j = np.int64(np.floor(y)) % h
        for c in range(3):
            out[b, c] = texels[j * w + i, c]
        return
    x, y = x - half, y - half
    fi0, fj0 = np.floor(x), np.floor(y)
    fx, fy = np.float32(x - fi0), np.float32(y - fj0)
    i0, j0 = np.int64(fi0) % w, np.int64(fj0) % h
    i1, j1 = (i0 + 1) % w, (j0 + 1) % h
    for c in range(3):
        top = texels[j1 * w + i0, c] * (one - fx) + texels[j1 * w + i1, c] * fx
        bottom = texels[j0 * w + i0, c] * (one - fx) + texels[j0 * w + i1, c] * fx
        out[b, c] = bottom * (one - fy) + top * fy


@njit
def _lookup_kernel(u, v, texels, wf, hf, w, h, closest, out):
    """EnvironmentMap._lookup's NumPy lines per direction (``_lookup_one``): u * W and v * H in
    u's precision (``wf``, ``hf``)."""
    half = wf / (wf + wf)
    for b in range(u.shape[0]):
        _lookup_one(u[b] * wf, v[b] * hf, half, texels, w, h, closest, out, b)


@njit
def _uv_one(x, y, z):
    """direction_to_uv's NumPy lines for one float32 direction (einsum's sum of squares in order,
    the float32 arctan2 and arccos): (u, v) float32."""
    one = np.float32(1.0)
    ln = np.sqrt(x * x + y * y + z * z)
    zc = z / (ln if ln > 0 else one)
    zc = np.float32(-1.0) if zc < -1 else (one if zc > 1 else zc)
    u = one / np.float32(2.0) - np.arctan2(y, x) / np.float32(_TWO_PI)
    v = one - np.arccos(zc) / np.float32(np.pi)
    return u, v


@njit
def _uv_kernel(m, u, v):
    """direction_to_uv of float32 directions m (B, 3) into u, v (B,)."""
    for b in range(m.shape[0]):
        u[b], v[b] = _uv_one(m[b, 0], m[b, 1], m[b, 2])


@njit
def _directions_kernel(m, rot, rotate, texels, density, w, h, closest, rgb, pdf):
    """radiance_rgb and pdf of float32 directions m (B, 3), in one pass: rotated by ``rot`` (R^T
    as float32: x R00 + y R10 + z R20, as the float32 matrix product sums an identity's exact
    products) when ``rotate``, else already in the map's frame; (u, v) as direction_to_uv; the
    texel as _lookup (into ``rgb`` unless it is empty) and the density as pdf's _texel (into
    ``pdf`` unless empty)."""
    wf, hf = np.float32(w), np.float32(h)
    want_rgb, want_pdf = rgb.shape[0] > 0, pdf.shape[0] > 0
    for b in range(m.shape[0]):
        x, y, z = m[b, 0], m[b, 1], m[b, 2]
        if rotate:
            x, y, z = (x * rot[0, 0] + y * rot[1, 0] + z * rot[2, 0], x * rot[0, 1] + y * rot[1, 1] + z * rot[2, 1],
                       x * rot[0, 2] + y * rot[1, 2] + z * rot[2, 2])
        u, v = _uv_one(x, y, z)
        if want_rgb:
            _lookup_one(u * wf, v * hf, np.float32(0.5), texels, w, h, closest, rgb, b)
        if want_pdf:
            i = np.int64(np.floor(u * wf)) % w
            j = np.int64(np.floor(v * hf))
            j = 0 if j < 0 else (h - 1 if j > h - 1 else j)
            pdf[b] = density[j, i]


@njit
def _count_le(a, lo, hi, x):
    """lo + the number of entries of the sorted a[lo:hi] at most x (np.searchsorted(..., 'right'))."""
    while lo < hi:
        mid = lo + ((hi - lo) >> 1)
        if a[mid] <= x:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit
def _clip(x, lo, hi):
    """np.clip for one number (NaN stays NaN)."""
    return lo if x < lo else (hi if x > hi else x)


@njit
def _sample_kernel(u1, u2, row_cdf, cond_flat, z_lo, dz, density, texels, w, h, closest, black, m, pdf, rgb):
    """EnvironmentMap.sample's NumPy lines per number pair, in float64: the row by the marginal
    CDF, the texel by the row's part [j (W + 1), j (W + 1) + W] of the stacked conditional CDF
    (the entry the whole array's search finds: entries before the row are at most j <= x, after it
    at least j + 1; x = j + u2 rounded up to j + 1 takes the row's last texel, as a search of
    a sorted array would: the row's last steps may round above j + 1 before its end, set to
    j + 1 exactly, and a binary search would stop there), the direction uniform in (phi, cos theta) within the texel; the texel
    looked up (``_lookup_one``) unless the map is ``black``. m (B, 3) map-frame directions."""
    wf, hf = np.float64(w), np.float64(h)
    for b in range(u1.shape[0]):
        a, c = u1[b], u2[b]
        j = _clip(_count_le(row_cdf, 0, h + 1, a) - 1, 0, h - 1)
        x = j + c
        lo, hi = row_cdf[j], row_cdf[j + 1]
        t1 = _clip((a - lo) / (hi - lo if hi > lo else 1.0), 0.0, 1.0)
        base = j * (w + 1)
        if x >= cond_flat[base + w]:
            k = base + w - 1
        else:
            k = _clip(_count_le(cond_flat, base, base + w + 1, x) - 1, base, base + w - 1)
        i = k - base
        clo, chi = cond_flat[k], cond_flat[k + 1]
        t2 = _clip((x - clo) / (chi - clo if chi > clo else 1.0), 0.0, 1.0)
        u = (i + t2) / w
        z = _clip(z_lo[j] + t1 * dz[j], -1.0, 1.0)
        v = _clip(1.0 - np.arccos(z) / np.pi, j / h, (j + 1) / h)
        phi = np.pi - _TWO_PI * u
        q = 1.0 - z * z
        s = np.sqrt(0.0 if q < 0.0 else q)
        m[b, 0] = s * np.cos(phi)
        m[b, 1] = s * np.sin(phi)
        m[b, 2] = z
        pdf[b] = density[j, i]
        if black:
            rgb[b, 0] = rgb[b, 1] = rgb[b, 2] = 0.0
        else:
            _lookup_one(u * wf, v * hf, 0.5, texels, w, h, closest, rgb, b)
