"""Light paths connected to the camera (light tracing's t = 1 strategy), splatted into a film.

Where a light path lands on a diffuse surface after one or more specular bounces (the landings
``walker.LightWalker.on_hit`` deposits into the caustic map), it is also joined to the
pinhole camera by a shadow ray and its contribution is splatted into the pixels whose
reconstruction filter covers the point it projects to: Veach 1997, section 10.2 (light tracing),
pbrt-v4 section 5.2.3 (``PerspectiveCamera::SampleWi``, the importance W_e of a pinhole) and
Mitsuba 3's ``ptracer`` (``sample_direction`` plus ``ImageBlock::put``). The estimate of pixel j
is (docs/physics.md section 4.9)

    I_j += Phi(lambda) * rho(lambda) / pi * |cos theta_y| / (d^2 cos^3 theta_c a_pix) * h(x - c_j)

(perspective; orthographic: |cos theta_y| / a_pix), with Phi the path's flux per wavelength
sample (what the map would receive), rho / pi the Lambertian BRDF (core/materials/surface.py: textures
too), theta_y the angle between the geometric normal and the direction to the camera, d the
distance, theta_c the angle off the optical axis, a_pix one pixel's area on the image plane at
distance 1 (metres for orthographic) and h the eye pass's reconstruction filter as a density
(core/sampling/camera.py FilterSampler: separable Blackman-Harris over +-width px, unit integral; the density
of its tabulated inverse CDF, ``filter_density``): the
same pixel integral the eye pass's filter-importance samples estimate, so the splat converges
to the caustic radiance the eye pass would otherwise look up in the map.

The path-space split (docs/physics.md section 4.9): the splat covers caustic light seen
*directly* (camera -> diffuse surface, no vertex between) on plain diffuse materials
(``direct_materials``: not rough or layered, not a grating or an opal); the eye pass leaves the
caustic map out exactly there and still looks it up behind mirrors and glass and after
diffuse or glossy bounces. The split holds only for the camera the splat was made for
(``view_key``: the camera and the filter width); another view (``PreparedScene.with_view``)
falls back to the map everywhere, unless the light pass kept the splat's vertices, which
core/integrators/light/splat_vertices.py connects to the new camera (``resplat``).

Accumulation is deterministic: a batch's splats are summed per pixel (a bincount per channel, float64)
into a sparse (pixels, values) pair, and a lane's film adds the batches' pairs in lane order, on
this machine or replayed from Dask workers alike (core/render/distributed.py), so both give the same
film bit for bit. The film holds the spectrum when a spectral EXR is asked or when W x H x n
floats fit the caustic map's per-lane cap (SPECTRAL_CAP: 32 M, e.g. 512 x 512 at 61
wavelengths), else linear Rec.709 RGB (spectrum -> RGB at splat time; RenderResult.spectral
then lacks the splat, its RGB, passes and EXR have it).

The connection's geometry (projection, facing test, shadow rays), the footprint, a batch's per-pixel
sums and the film's add have compiled twins (core/util/jit.py; the section "kernels" at the end),
chosen inside the same functions; the sums and the footprint are the reference's bits, and with
the kernels a mono landing on a spectral film carries one channel (``MonoContributions``), not a
row of n with one non-zero entry.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...materials.spectra import DIFFUSE
from ...materials.surface import surface_reflectance
from ...util.jit import kernels_enabled, njit

__all__ = ["CameraConnection", "CameraSplat", "SplatBatch", "SplatLog", "view_key", "direct_materials",
           "blackman_harris_density", "filter_density", "usable_splat", "applies", "MonoContributions"]

_BH = (0.35875, 0.48829, 0.14128, 0.01168)
SPECTRAL_CAP = 32_000_000  # floats per lane: a spectral splat film up to this size (the caustic map's cap)


def blackman_harris_density(t: np.ndarray, width: float) -> np.ndarray:
    """The 1-D Blackman-Harris window over [-width, width] px as a density (unit integral):
    the distribution FilterSampler draws its offsets from."""
    t = np.asarray(t, np.float64)
    a0, a1, a2, a3 = _BH
    x = t / (2.0 * width) + 0.5
    f = a0 - a1 * np.cos(2 * np.pi * x) + a2 * np.cos(4 * np.pi * x) - a3 * np.cos(6 * np.pi * x)
    return np.where(np.abs(t) < width, f / (2.0 * width * a0), 0.0)


def filter_density(t: np.ndarray, sampler) -> np.ndarray:
    """The density of ``sampler``'s (camera.FilterSampler) offsets at t (pixels): its inverse CDF
    is a table interpolated linearly, so the offsets are uniform between neighbouring entries,
    density 1 / ((T - 1) (inv[i + 1] - inv[i])) there. This, not the ideal window
    (``blackman_harris_density``; they differ in the last 0.3 % of the tails), is the filter
    the eye pass integrates each pixel with."""
    inv = sampler._inv
    t = np.asarray(t, np.float64)
    seg = np.diff(inv)
    dens = np.where(seg > 0, 1.0 / ((len(inv) - 1) * np.where(seg > 0, seg, 1.0)), 0.0)
    i = np.clip(np.searchsorted(inv, t, side="right") - 1, 0, len(seg) - 1)
    return np.where((t >= inv[0]) & (t < inv[-1]), dens[i], 0.0)


def view_key(camera, filter_width: float) -> tuple:
    """What a splat depends on in the view: the camera (pose, projection, image size) and the
    reconstruction filter. Two views with equal keys see the same splat."""
    from dataclasses import fields

    m = tuple(float(x) for x in np.asarray(camera.matrix, np.float64).ravel())
    rest = tuple((f.name, _hashable(getattr(camera, f.name))) for f in fields(camera) if f.name != "matrix")
    return (m,) + rest + (float(filter_width),)


def _hashable(value):
    """An array field (the camera's motion steps, shutter table) as a tuple of its shape and numbers."""
    if isinstance(value, np.ndarray):
        return (value.shape,) + tuple(float(x) for x in value.ravel())
    return value


def direct_materials(prepared) -> np.ndarray:
    """(M,) bool: the materials whose directly seen caustics the splat carries: plain Lambertian
    ones (kind DIFFUSE, not rough or layered, no grating, no opal), where the eye pass's caustic
    lookup is exactly irradiance * rho / pi (eye/next_event.caustic_light)."""
    mats = prepared.materials
    ok = np.asarray(mats.kind) == DIFFUSE
    if prepared.microfacet is not None:
        ok &= ~np.asarray(prepared.microfacet, bool)
    g = prepared.gratings
    ok &= ~np.asarray(g.enabled, bool)
    if getattr(g, "bragg", None) is not None:
        ok &= ~np.asarray(g.bragg, bool)
    return ok


def applies(prepared) -> bool:
    """Whether the light pass splats for ``prepared``'s view (render/plan.py's ``camera_splat``):
    the setting is on, the filter has a width (a zero width point-samples pixel centres, which a
    splat cannot estimate), the camera is a pinhole (perspective or orthographic, no depth of
    field: the connection is to its one eye point) and some material takes the splat (``direct_materials``)."""
    from ...sampling.camera import has_lens, has_motion

    s = prepared.settings
    if not s.caustic_splat or float(s.filter_width) <= 0:
        return False
    cam = prepared.scene.camera
    if cam is None or cam.kind == "PANO" or has_lens(cam):  # a pinhole's connection only (docs/physics.md section 6.10)
        return False
    if has_motion(cam):  # a moving camera has no one eye point: the eye pass looks the caustics up (section 6.13)
        return False
    return bool(direct_materials(prepared).any())


def usable_splat(prepared, light) -> "CameraSplat | None":
    """The light pass's camera splat if it was made for ``prepared``'s view (camera and filter
    width) and holds the spectrum when a spectral EXR is asked; None: the eye pass looks up the
    caustic map everywhere (another view of a kept light pass, or no splat)."""
    splat = None if light is None else getattr(light, "splat", None)
    if splat is None or not splat.matches(prepared.scene.camera, prepared.settings.filter_width):
        return None
    if prepared.settings.spectral_exr and not splat.spectral:
        return None
    return splat


@dataclass(frozen=True)
class CameraConnection:
    """The camera as the light pass connects to it: pose, image-plane extent, filter."""

    eye: np.ndarray       # (3,) camera position
    rot: np.ndarray       # (3, 3) camera axes as columns (local -z: the view direction)
    ortho: bool
    hx: float             # image-plane half extents (at distance 1; metres for ortho)
    hy: float
    sx: float             # lens shift on the image plane
    sy: float
    width: int
    height: int
    filter_width: float
    filt: object          # camera.FilterSampler: the eye pass's filter, whose density the splat weights are
    key: tuple
    materials: np.ndarray  # (M,) bool: direct_materials
    rgb_weights: np.ndarray | None  # (n, 3) spectrum -> RGB; None: the film keeps the spectrum
    channels: int
    dens: np.ndarray | None = None  # filter_density's per-segment densities of filt's table (the kernels')
    near: float = 0.0      # the camera's clip start and end: depths along the view axis it sees
    far: float = float("inf")

    @classmethod
    def of(cls, prepared) -> "CameraConnection":
        """The connection for ``prepared``'s camera (made where the plan's ``camera_splat``
        is on: ``applies``)."""
        from ...sampling.camera import FilterSampler, _shift_extent, camera_frame

        s = prepared.settings
        mats = direct_materials(prepared)
        cam = prepared.scene.camera
        hx, hy = camera_frame(cam)
        shift = _shift_extent(cam)
        m = np.asarray(cam.matrix, np.float64)
        rot = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0, keepdims=True)
        n = prepared.grid.n
        # the spectrum when a spectral EXR is asked or when it fits the map's per-lane cap, so
        # RenderResult.spectral holds the splat too; else RGB (3 floats per pixel)
        spectral = bool(s.spectral_exr) or int(cam.width) * int(cam.height) * n <= SPECTRAL_CAP
        filt = FilterSampler(s.filter_width)
        return cls(m[:3, 3].copy(), rot, cam.kind == "ORTHO", float(hx), float(hy), float(cam.shift_x * shift),
                   float(cam.shift_y * shift), int(cam.width), int(cam.height), float(s.filter_width),
                   filt, view_key(cam, s.filter_width), mats,
                   None if spectral else prepared.conv.rgb_weights.astype(np.float64), n if spectral else 3,
                   None if filt._inv is None else _density_table(filt._inv),
                   float(getattr(cam, "clip_start", 0.0)), float(getattr(cam, "clip_end", np.inf)))

    def in_clip(self, p: np.ndarray) -> np.ndarray | None:
        """Whether points p (K, 3) lie between the clip planes (Cycles clips at depths along the
        view axis, as camera.camera_rays); None when the camera does not clip."""
        if self.near <= 0 and not np.isfinite(self.far):
            return None
        depth = -((np.asarray(p, np.float64) - self.eye) @ self.rot[:, 2])
        return (depth >= self.near) & (depth <= self.far)

    def empty(self) -> "CameraSplat":
        return CameraSplat(self.key, np.zeros((self.height, self.width, self.channels), np.float32),
                           self.rgb_weights is None)

    def project(self, p: np.ndarray):
        """Image positions of world points p (B, 3): (x, y) in pixels (0 at the left / top edge),
        unit directions towards the camera (B, 3), the shadow-ray length, the factor
        1 / (d^2 cos^3 theta_c a_pix) (ortho: 1 / a_pix), and whether the point is in front of
        the camera and within a filter's reach of the image."""
        v = np.asarray(p, np.float64) - self.eye
        local = v @ self.rot  # camera coordinates
        depth = -local[:, 2]
        front = depth > 0
        a_pix = (2 * self.hx / self.width) * (2 * self.hy / self.height)
        if self.ortho:
            px, py = local[:, 0], local[:, 1]
            to_cam = np.broadcast_to(self.rot[:, 2], v.shape)
            dist = depth
            factor = np.full(len(v), 1.0 / a_pix)
        else:
            z = np.where(front, depth, 1.0)
            px, py = local[:, 0] / z, local[:, 1] / z
            dist = np.sqrt(np.einsum("ij,ij->i", v, v))
            to_cam = -v / np.maximum(dist, 1e-300)[:, None]
            cos_c = z / np.maximum(dist, 1e-300)
            factor = 1.0 / (np.maximum(dist, 1e-300) ** 2 * cos_c**3 * a_pix)
        x = ((px - self.sx) / self.hx + 1.0) * (0.5 * self.width)
        y = (1.0 - (py - self.sy) / self.hy) * (0.5 * self.height)
        fw = self.filter_width
        ok = front & (x > -fw) & (x < self.width + fw) & (y > -fw) & (y < self.height + fw)
        return x, y, to_cam, dist, factor, ok

    def footprint(self, x: np.ndarray, y: np.ndarray):
        """The pixels each image point's filter covers: flat pixel indices (B, K*K) and the
        filter density weights (B, K*K), zero outside the filter or the image."""
        fw = self.filter_width
        k = int(np.ceil(2 * fw)) + 1
        if kernels_enabled():
            return _footprint(self, np.ascontiguousarray(x, np.float64), np.ascontiguousarray(y, np.float64), k)
        off = np.arange(k)
        ix = np.floor(x - fw - 0.5).astype(np.int64)[:, None] + 1 + off  # pixel columns (B, K)
        iy = np.floor(y - fw - 0.5).astype(np.int64)[:, None] + 1 + off
        # the eye pass's sample at offset t from pixel c counts for c: weight = density(x - c)
        wx = filter_density(x[:, None] - (ix + 0.5), self.filt) * ((ix >= 0) & (ix < self.width))
        wy = filter_density(y[:, None] - (iy + 0.5), self.filt) * ((iy >= 0) & (iy < self.height))
        idx = np.clip(iy, 0, self.height - 1)[:, :, None] * self.width + np.clip(ix, 0, self.width - 1)[:, None, :]
        w = wy[:, :, None] * wx[:, None, :]
        return idx.reshape(len(x), -1), w.reshape(len(x), -1)

    def connect(self, prepared, rays, hit, n: int, rows=None):
        """The splats of light-path landings (``rays``, ``hit``: transport.Rays / Hit at diffuse
        hits after a specular bounce; ``rows``: the landings' indices into them, None: all):
        shadow rays to the camera, the contribution of docs/physics.md section 4.9, the filter
        footprint. Returns ((pixels (K, F), filter weights (K, F), contributions (K, channels)
        float64) or None, shadow rays cast): landing k adds weight[k, f] * contribution[k] to
        pixel pixels[k, f]."""
        kernels = kernels_enabled()
        if rows is not None and not kernels:
            rays, hit, rows = rays.take(rows), hit.take(rows), None
        sel = self.materials[hit.mat if rows is None else hit.mat.take(rows)]
        if not sel.any():
            return None, 0
        if kernels:  # projection, facing test and shadow rays in one pass (_geometry_kernel)
            # the rays and hits are taken once, at the landings splatted
            at = np.flatnonzero(sel) if rows is None else rows[sel]
            if len(at) == len(hit.mat):
                x, y, to_cam, factor, cos_y, ok, o, tmax = _connect_geometry(self, hit.p, hit.ng, hit.eps)
            else:
                x, y, to_cam, factor, cos_y, ok, o, tmax = _connect_geometry(
                    self, hit.p.take(at, axis=0), hit.ng.take(at, axis=0), hit.eps.take(at))
            clip = self.in_clip(hit.p.take(at, axis=0))
            if clip is not None:
                ok &= clip
            keep = np.flatnonzero(ok)
            if keep.size == 0:
                return None, 0
            occ = prepared.accel.occluded(o.take(keep, axis=0), to_cam.take(keep, axis=0), tmax.take(keep))
            shadow_rays = len(keep)
            keep = keep[~occ]
            if keep.size == 0:
                return None, shadow_rays
            r, h = _Landings.of(rays, hit, at.take(keep))  # only what the contribution reads
        else:
            r, h = rays.take(sel), hit.take(sel)
            x, y, to_cam, dist, factor, ok = self.project(h.p)
            ng = h.ng.astype(np.float64)
            cos_y = np.einsum("ij,ij->i", to_cam, ng)  # ng faces the side the light arrived from
            ok &= cos_y > 0
            clip = self.in_clip(h.p)
            if clip is not None:
                ok &= clip
            keep = np.flatnonzero(ok)
            if keep.size == 0:
                return None, 0
            eps = h.eps[keep].astype(np.float64)
            o = h.p[keep] + eps[:, None] * ng[keep]
            tmax = np.maximum(dist[keep] - 2 * eps, 0.0)
            occ = prepared.accel.occluded(o.astype(np.float32), np.ascontiguousarray(to_cam[keep], np.float32),
                                          tmax.astype(np.float32))
            shadow_rays = len(keep)
            keep = keep[~occ]
            if keep.size == 0:
                return None, shadow_rays
            r, h = r.take(keep), h.take(keep)
        g = cos_y[keep] * factor[keep] / np.pi  # rho / pi and the camera's importance
        rho = surface_reflectance(prepared, h, r.lam)
        if r.lam is None:
            c = r.dense_w(n) * rho  # (K, n) float32
            if self.rgb_weights is not None:  # to RGB before the per-pixel work: 3 channels, not n
                c = c @ self.rgb_weights.astype(np.float32)
            c = c.astype(np.float64) * g[:, None]
        else:
            v = r.w.astype(np.float64) * rho * g  # (K,) at wavelength r.lam
            if self.rgb_weights is not None:
                c = v[:, None] * self.rgb_weights[r.lam]
            elif kernels:  # one channel per landing: (wavelength, value), summed by _add_mono
                c = MonoContributions(np.ascontiguousarray(r.lam, np.int64), v)
            else:
                c = np.zeros((len(v), n))
                c[np.arange(len(v)), r.lam] = v
        if kernels:
            k = int(np.ceil(2 * self.filter_width)) + 1
            idx, w = _footprint(self, x.take(keep), y.take(keep), k)
        else:
            idx, w = self.footprint(x[keep], y[keep])
        return (idx, w, c), shadow_rays


@dataclass(frozen=True)
class _Landings:
    """The fields of light-path landings (Rays and Hit rows) the splat's contribution reads:
    the weights and wavelengths, and what surface_reflectance looks up (material, triangle,
    barycentrics); gathered once, without the rest of the rays and hits."""

    w: np.ndarray | None
    lam: np.ndarray | None
    basis: np.ndarray | None
    mat: np.ndarray
    prim: np.ndarray
    bu: np.ndarray
    bv: np.ndarray

    @classmethod
    def of(cls, rays, hit, rows: np.ndarray) -> tuple["_Landings", "_Landings"]:
        take = lambda a: None if a is None else a.take(rows, axis=0)  # noqa: E731
        out = cls(take(rays.w), take(rays.lam), rays.basis, take(hit.mat), take(hit.prim), take(hit.bu), take(hit.bv))
        return out, out

    def dense_w(self, n: int) -> np.ndarray:
        """transport.Rays.dense_w of these landings."""
        if self.w is None:
            return np.ones((len(self.mat), n), np.float32)
        if self.basis is not None:
            return (self.w @ self.basis).astype(np.float32, copy=False)
        return self.w


class SplatBatch:
    """One batch's splats, summed per pixel at the end (``finish``): deterministic whatever runs it."""

    def __init__(self, connection: CameraConnection):
        self.connection = connection
        self._calls: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # (pixels, weights, contributions)
        self.shadow_rays = 0

    def connect(self, prepared, rays, hit, n: int, rows=None) -> None:
        """CameraConnection.connect of the landings ``rows`` of ``rays`` at ``hit`` (None: all), kept."""
        out, cast = self.connection.connect(prepared, rays, hit, n, rows)
        self.shadow_rays += cast
        if out is not None and len(out[0]):
            self._calls.append(out)

    def finish(self) -> tuple[np.ndarray, np.ndarray]:
        """(distinct flat pixel indices (U,) int64, their summed values (U, channels) float32)."""
        c = self.connection.channels
        if not self._calls:
            return np.zeros(0, np.int64), np.zeros((0, c), np.float32)
        if kernels_enabled():
            return _finish(self._calls, self.connection.width * self.connection.height, c)
        self._calls = [(p, q, v.dense(c) if isinstance(v, MonoContributions) else v) for p, q, v in self._calls]
        idx = np.concatenate([p.ravel() for p, _, _ in self._calls])
        w = np.concatenate([q.ravel() for _, q, _ in self._calls])
        contrib = np.concatenate([v for _, _, v in self._calls])
        rows = np.repeat(np.arange(len(contrib)), self._calls[0][0].shape[1])
        keep = w > 0
        idx, w, rows = idx[keep], w[keep], rows[keep]
        # the touched pixels (a sort of integers), then one bincount per channel over them: no
        # (entries x channels) array, so a spectral film costs little more than an RGB one
        pixels, inv = np.unique(idx, return_inverse=True)
        out = np.empty((len(pixels), c), np.float32)
        per_channel = np.ascontiguousarray(contrib.T)  # (channels, K): contiguous gathers below
        for k in range(c):  # loop over channels (3, or the wavelengths)
            out[:, k] = np.bincount(inv, weights=w * per_channel[k][rows], minlength=len(pixels))
        return pixels, out


class SplatLog:
    """A sink that keeps a batch's (pixels, values) for a Dask worker to send back (``calls``)."""

    def __init__(self):
        self.calls: list[tuple[np.ndarray, np.ndarray]] = []

    def add(self, pixels: np.ndarray, values: np.ndarray) -> None:
        if len(pixels):
            self.calls.append((pixels, values))


@dataclass
class CameraSplat:
    """A light pass's camera film: the summed splats of its paths, for the view ``key``
    (``view_key``). ``image`` (H, W, 3) linear Rec.709 RGB, or (H, W, n) the spectrum when
    ``spectral``; None on a Dask worker, which needs only the key."""

    key: tuple
    image: np.ndarray | None
    spectral: bool = False

    def add(self, pixels: np.ndarray, values: np.ndarray) -> None:
        """Add a batch's ``SplatBatch.finish()`` (distinct pixels, so fancy-index += is exact)."""
        if len(pixels):
            flat = self.image.reshape(-1, self.image.shape[-1])
            if kernels_enabled():
                _add_rows_kernel(flat, np.ascontiguousarray(pixels, np.int64), np.ascontiguousarray(values, np.float32))
            else:
                flat[pixels] += values

    def add_batch(self, batch: "SplatBatch") -> None:
        """``self.add(*batch.finish())``; on the kernels the batch's float64 sums are rounded and added
        to the film in one pass (the same float32 additions, the same bits)."""
        if not kernels_enabled() or not batch._calls:
            self.add(*batch.finish())
            return
        pixels, acc = _sums(batch._calls, batch.connection.width * batch.connection.height, batch.connection.channels)
        _add_rounded_rows_kernel(self.image.reshape(-1, self.image.shape[-1]), pixels, acc)

    def __iadd__(self, other: "CameraSplat") -> "CameraSplat":
        self.image += other.image
        return self

    def matches(self, camera, filter_width: float) -> bool:
        """Whether this splat was made for that view."""
        return self.key == view_key(camera, filter_width)

    def images(self, conv, region=None) -> tuple[np.ndarray, np.ndarray | None]:
        """(RGB (h, w, 3), spectrum (h, w, n) or None) over ``region`` = (x0, y0, x1, y1) (None:
        the whole image), for Film.result."""
        img = self.image
        if region is not None:
            x0, y0, x1, y1 = region
            img = img[y0:y1, x0:x1]
        if self.spectral:
            return conv.to_rgb(img), img
        return img, None


# ------------------------------------------------------------------------------ kernels
# The compiled twins (core/util/jit.py) of the footprint, the per-pixel sums of ``finish`` and the
# film's ``add``: the reference's operations in its order and precision, so the same bits
# (tests/integrators/light/test_light_pass_kernels.py). ``finish`` adds each landing's weight x contribution
# per channel in float64 in the order the landings came, which is np.bincount's order; a mono
# landing's zero channels are skipped (adding 0.0 leaves a non-negative sum's bits unchanged).


@dataclass(frozen=True)
class MonoContributions:
    """Contributions of mono landings to a spectral film, one channel each: the kernels' form of
    the reference's (K, n) rows with one non-zero entry."""

    lam: np.ndarray   # (K,) int64 wavelength index (the channel)
    value: np.ndarray  # (K,) float64

    def __len__(self) -> int:
        return len(self.value)

    def dense(self, channels: int) -> np.ndarray:
        c = np.zeros((len(self.value), channels))
        c[np.arange(len(self.value)), self.lam] = self.value
        return c


@njit
def _geometry_kernel(p, ng, eps, eye, rot, ortho, hx, hy, sx, sy, width, height, fw, a_pix,
                     x, y, to_cam, factor, cos_y, ok, o, tmax):
    """CameraConnection.project, the facing test and the shadow rays' origins and lengths, per landing."""
    for i in range(len(p)):  # loop over landings
        v0, v1, v2 = np.float64(p[i, 0]) - eye[0], np.float64(p[i, 1]) - eye[1], np.float64(p[i, 2]) - eye[2]
        l0 = v0 * rot[0, 0] + v1 * rot[1, 0] + v2 * rot[2, 0]  # camera coordinates
        l1 = v0 * rot[0, 1] + v1 * rot[1, 1] + v2 * rot[2, 1]
        depth = -(v0 * rot[0, 2] + v1 * rot[1, 2] + v2 * rot[2, 2])
        front = depth > 0
        if ortho:
            px, py = l0, l1
            t0, t1, t2 = rot[0, 2], rot[1, 2], rot[2, 2]
            dist = depth
            factor[i] = 1.0 / a_pix
        else:
            z = depth if front else 1.0
            px, py = l0 / z, l1 / z
            dist = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
            dd = max(dist, 1e-300)
            t0, t1, t2 = -v0 / dd, -v1 / dd, -v2 / dd
            cos_c = z / dd
            factor[i] = 1.0 / (dd * dd * (cos_c * cos_c * cos_c) * a_pix)
        xi = ((px - sx) / hx + 1.0) * (0.5 * width)
        yi = (1.0 - (py - sy) / hy) * (0.5 * height)
        x[i], y[i] = xi, yi
        n0, n1, n2 = np.float64(ng[i, 0]), np.float64(ng[i, 1]), np.float64(ng[i, 2])
        c = t0 * n0 + t1 * n1 + t2 * n2  # ng faces the side the light arrived from
        cos_y[i] = c
        ok[i] = front and xi > -fw and xi < width + fw and yi > -fw and yi < height + fw and c > 0
        to_cam[i, 0], to_cam[i, 1], to_cam[i, 2] = t0, t1, t2
        e = np.float64(eps[i])
        o[i, 0] = np.float64(p[i, 0]) + e * n0
        o[i, 1] = np.float64(p[i, 1]) + e * n1
        o[i, 2] = np.float64(p[i, 2]) + e * n2
        tmax[i] = max(dist - 2 * e, 0.0)


def _connect_geometry(conn: CameraConnection, p, ng, eps):
    """(x, y, to_cam (K, 3) float32, factor, cos_y, ok, shadow origins (K, 3) float32, lengths float32)
    of hits at points p, geometric normals ng, offsets eps on the kernel: CameraConnection.project and
    the facing test of ``connect``."""
    k = len(p)
    x, y, factor, cos_y = np.empty(k), np.empty(k), np.empty(k), np.empty(k)
    to_cam, o = np.empty((k, 3), np.float32), np.empty((k, 3), np.float32)
    tmax, ok = np.empty(k, np.float32), np.empty(k, np.bool_)
    a_pix = (2 * conn.hx / conn.width) * (2 * conn.hy / conn.height)
    _geometry_kernel(np.ascontiguousarray(p), np.ascontiguousarray(ng), np.ascontiguousarray(eps),
                     conn.eye.astype(np.float64), np.ascontiguousarray(conn.rot, np.float64), bool(conn.ortho),
                     conn.hx, conn.hy, conn.sx, conn.sy, conn.width, conn.height, conn.filter_width, a_pix,
                     x, y, to_cam, factor, cos_y, ok, o, tmax)
    return x, y, to_cam, factor, cos_y, ok, o, tmax


def _density_table(inv: np.ndarray) -> np.ndarray:
    """filter_density's per-segment densities of the inverse-CDF table ``inv``."""
    seg = np.diff(inv)
    return np.where(seg > 0, 1.0 / ((len(inv) - 1) * np.where(seg > 0, seg, 1.0)), 0.0)


@njit
def _density_at(t, inv, dens):
    """filter_density at one offset t (pixels)."""
    if not (t >= inv[0] and t < inv[-1]):
        return 0.0
    i = np.searchsorted(inv, t, side="right") - 1
    i = min(max(i, 0), len(dens) - 1)
    return dens[i]


@njit
def _footprint_kernel(x, y, fw, k, width, height, inv, dens, idx, w):
    wx = np.empty(k)
    cx = np.empty(k, np.int64)
    for i in range(len(x)):  # loop over landings
        bx = np.int64(np.floor(x[i] - fw - 0.5)) + 1
        by = np.int64(np.floor(y[i] - fw - 0.5)) + 1
        for b in range(k):  # the columns' weights once per landing
            ix = bx + b
            wx[b] = _density_at(x[i] - (ix + 0.5), inv, dens) * (1.0 if (ix >= 0 and ix < width) else 0.0)
            cx[b] = min(max(ix, 0), width - 1)
        for a in range(k):
            iy = by + a
            wy = _density_at(y[i] - (iy + 0.5), inv, dens) * (1.0 if (iy >= 0 and iy < height) else 0.0)
            cy = min(max(iy, 0), height - 1)
            for b in range(k):
                idx[i, a * k + b] = cy * width + cx[b]
                w[i, a * k + b] = wy * wx[b]


def _footprint(conn: CameraConnection, x: np.ndarray, y: np.ndarray, k: int):
    """CameraConnection.footprint on the kernel."""
    inv = np.ascontiguousarray(conn.filt._inv, np.float64)
    dens = _density_table(inv) if conn.dens is None else conn.dens
    idx = np.empty((len(x), k * k), np.int64)
    w = np.empty((len(x), k * k), np.float64)
    _footprint_kernel(x, y, float(conn.filter_width), k, conn.width, conn.height, inv, dens, idx, w)
    return idx, w


@njit
def _mark_kernel(idx, w, slot):
    """slot[pixel] = 1 where some landing's weight on it is positive."""
    for i in range(idx.shape[0]):
        for f in range(idx.shape[1]):
            if w[i, f] > 0:
                slot[idx[i, f]] = 1


@njit
def _number_kernel(slot):
    """The marked pixels in increasing order (np.unique's), and slot[pixel] = its row among them."""
    m = 0
    for p in range(len(slot)):
        if slot[p]:
            m += 1
    pixels = np.empty(m, np.int64)
    m = 0
    for p in range(len(slot)):
        if slot[p]:
            pixels[m] = p
            slot[p] = m
            m += 1
    return pixels


@njit
def _add_dense_kernel(idx, w, c, slot, acc):
    for i in range(idx.shape[0]):  # the landings in order: np.bincount's order per pixel
        for f in range(idx.shape[1]):
            wf = w[i, f]
            if wf > 0:
                row = slot[idx[i, f]]
                for ch in range(c.shape[1]):
                    acc[row, ch] += wf * c[i, ch]


@njit
def _add_mono_kernel(idx, w, lam, value, slot, acc):
    for i in range(idx.shape[0]):
        for f in range(idx.shape[1]):
            wf = w[i, f]
            if wf > 0:
                acc[slot[idx[i, f]], lam[i]] += wf * value[i]


def _finish(calls, pixels_total: int, channels: int):
    """SplatBatch.finish on the kernels."""
    pixels, acc = _sums(calls, pixels_total, channels)
    return pixels, acc.astype(np.float32)


def _sums(calls, pixels_total: int, channels: int):
    """(distinct pixels, their float64 sums (U, channels)) of a batch's splat calls."""
    slot = np.zeros(pixels_total, np.int64)
    for p, q, _ in calls:
        _mark_kernel(p, q, slot)
    pixels = _number_kernel(slot)
    acc = np.zeros((len(pixels), channels), np.float64)
    for p, q, v in calls:
        if isinstance(v, MonoContributions):
            _add_mono_kernel(p, q, v.lam, v.value, slot, acc)
        else:
            _add_dense_kernel(p, q, np.ascontiguousarray(v, np.float64), slot, acc)
    return pixels, acc


@njit
def _add_rows_kernel(flat, pixels, values):
    for i in range(len(pixels)):  # distinct pixels
        for ch in range(flat.shape[1]):
            flat[pixels[i], ch] += values[i, ch]


@njit
def _add_rounded_rows_kernel(flat, pixels, acc):
    """flat[pixels] += acc rounded to float32 (finish's astype, then add's float32 sums)."""
    for i in range(len(pixels)):  # distinct pixels
        for ch in range(flat.shape[1]):
            flat[pixels[i], ch] += np.float32(acc[i, ch])
