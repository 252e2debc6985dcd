"""Camera rays and pixel sampling.

Projection follows Blender's camera conventions (sensor fit, lens in mm, shift as a fraction of
the fitted dimension, orthographic scale). Pixel samples are stratified per axis (N-rooks /
Latin hypercube within each pixel) and shaped by filter importance sampling: each sample's
offset is drawn from the reconstruction filter itself and the sample counts fully for the pixel
it was drawn for, which is equivalent to filtering with that kernel but needs no splatting
across tiles (Ernst et al. 2006, "Filter Importance Sampling"; Cycles does the same). The filter
is a separable Blackman-Harris window with Cycles' convention: a filter width w spans +-w pixels
(Cycles doubles the Blackman-Harris range "for consistency with Blender Internal"), so the
default 1.5 px covers 3 px, and a frame edge darkens as it does in Cycles.

The rays (``camera_rays``) are Cycles' (intern/cycles/kernel/camera/camera.h, projection.h;
docs/physics.md sections 6.1 and 6.7-6.9): perspective, orthographic and panoramic cameras
(equirectangular, fisheye equidistant and equisolid, in Cycles' panorama space), a thin lens
for depth of field (the aperture a disk or Cycles' regular polygon of blades, turned and
squeezed by the anamorphic ratio; every ray aimed at the pinhole ray's point on the plane of
focus), and clip start / end (the near and far planes along the view axis; along the ray for
panoramas).

Motion blur (docs/physics.md section 6.13): a moving camera holds its matrices at N evenly spaced
times across the shutter; each camera ray takes a time in [0, 1] (``time_samples``: its own
stratified Sobol-Burley dimension, mapped through the shutter curve's inverse CDF) and the
camera interpolated as Cycles' transform_motion_array_interpolate (intern/cycles/util/transform.h):
the two steps around the time, the rotation by quaternion slerp along the shorter arc, the
position linearly.
"""

from __future__ import annotations

import numpy as np

from ..scene.model import Camera
from .sampler import sobol_owen_2d, sobol_owen_x

__all__ = ["FilterSampler", "camera_frame", "pixel_samples", "generate_rays", "camera_rays", "aperture_points",
           "panorama_directions", "panorama_sensor", "has_lens", "clips", "lens_samples", "LENS_KEY",
           "has_motion", "time_samples", "TIME_KEY", "shutter_times", "shutter_table", "motion_frames",
           "rotation_to_quaternion", "quaternion_to_rotation"]


class FilterSampler:
    """Inverse-CDF sampling of a 1D Blackman-Harris window spanning +-``width`` pixels."""

    def __init__(self, width: float = 1.5, table_size: int = 1024):
        self.width = float(width)
        if self.width <= 0:
            self._inv = None
            return
        x = np.linspace(0.0, 1.0, 4097)
        a0, a1, a2, a3 = 0.35875, 0.48829, 0.14128, 0.01168
        f = a0 - a1 * np.cos(2 * np.pi * x) + a2 * np.cos(4 * np.pi * x) - a3 * np.cos(6 * np.pi * x)
        cdf = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]))])
        cdf /= cdf[-1]
        u = np.linspace(0.0, 1.0, table_size)
        self._inv = ((np.interp(u, cdf, x) - 0.5) * 2.0 * self.width).astype(np.float64)

    def offsets(self, u: np.ndarray) -> np.ndarray:
        """Map uniform u in [0, 1) to offsets from the pixel centre (pixels)."""
        if self._inv is None:
            return np.zeros_like(u)
        pos = u * (len(self._inv) - 1)
        i = np.minimum(pos.astype(np.int64), len(self._inv) - 2)
        f = pos - i
        return self._inv[i] * (1 - f) + self._inv[i + 1] * f


def camera_frame(cam: Camera) -> tuple[float, float]:
    """Half-extents (x, y) of the image plane: at distance 1 for perspective, metres for ortho."""
    w, h = int(cam.width), int(cam.height)
    fit = cam.sensor_fit
    if fit == "AUTO":
        fit = "HORIZONTAL" if w >= h else "VERTICAL"
        sensor = cam.sensor_width
    else:
        sensor = cam.sensor_width if fit == "HORIZONTAL" else cam.sensor_height
    full = cam.ortho_scale if cam.kind == "ORTHO" else sensor / cam.lens
    if fit == "HORIZONTAL":
        return full / 2, full / 2 * h / w
    return full / 2 * w / h, full / 2


def _shift_extent(cam: Camera) -> float:
    """Full extent of the fitted dimension (what Blender's shift is a fraction of)."""
    hx, hy = camera_frame(cam)
    w, h = int(cam.width), int(cam.height)
    fit = cam.sensor_fit
    if fit == "AUTO":
        fit = "HORIZONTAL" if w >= h else "VERTICAL"
    return 2 * (hx if fit == "HORIZONTAL" else hy)


def pixel_samples(
    pixel_x: np.ndarray, pixel_y: np.ndarray, spp: int, rng: np.random.Generator, filt: FilterSampler,
    qmc: tuple[np.ndarray, int, int] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``spp`` stratified, filter-distributed samples per pixel.

    Returns (x, y, u_lambda, pixel_index): x, y continuous image coordinates (0 at the left /
    top edge, pixel centres at i + 0.5), u_lambda a third stratified dimension in [0, 1) for
    choosing a wavelength (so a pixel's samples cover the spectrum evenly), and pixel_index the
    position in the input pixel arrays.

    ``qmc`` = (pixel ids (P,), first sample numbers (P,) (or one for all), seed): the positions
    and u_lambda are the pixels' Sobol-Burley points (core/sampling/sampler.py, pairs 0 and 1) numbered
    from each pixel's first sample number on; None: N-rooks with ``rng``.
    """
    p = len(pixel_x)
    if qmc is not None:
        ids, first, seed = qmc
        pix = np.repeat(np.asarray(ids), spp)
        num = (np.broadcast_to(np.asarray(first, np.int64), (p,))[:, None] + np.arange(spp)[None, :]).ravel()
        ux, uy = sobol_owen_2d(pix, num, 0, seed)
        ul = sobol_owen_x(pix, num, 1, seed).astype(np.float64)  # the wavelength number: one coordinate
        x = np.repeat(pixel_x, spp) + 0.5 + filt.offsets(ux)
        y = np.repeat(pixel_y, spp) + 0.5 + filt.offsets(uy)
        return x, y, ul, np.repeat(np.arange(p), spp)
    strata = np.arange(spp, dtype=np.float64)[None, :]
    # N-rooks: x strata in order, y strata in a random permutation per pixel.
    strata_rows = np.broadcast_to(np.arange(spp, dtype=np.float64), (p, spp))
    perm = rng.permuted(strata_rows, axis=1)
    ux = (strata + rng.random((p, spp))) / spp
    uy = (perm + rng.random((p, spp))) / spp
    perm_l = rng.permuted(strata_rows, axis=1)
    ul = (perm_l + rng.random((p, spp))) / spp
    x = pixel_x[:, None] + 0.5 + filt.offsets(ux)
    y = pixel_y[:, None] + 0.5 + filt.offsets(uy)
    idx = np.repeat(np.arange(p), spp)
    return x.ravel(), y.ravel(), ul.ravel(), idx


#: The aperture's numbers are Sobol-Burley pair 1 (whose x is the wavelength number) under its own
#: scramble and shuffle keys (the seed xor this constant): independent of every pair a path uses,
#: and stratified over a pixel's samples in 2-D, without moving the path vertices' pairs.
LENS_KEY = 0x4C454E53  # "LENS"


def lens_samples(p: int, spp: int, rng: np.random.Generator, qmc=None) -> np.ndarray:
    """(p * spp, 2) uniform numbers for the aperture points of ``spp`` samples of ``p`` pixels,
    in pixel_samples' order: the pixels' Sobol-Burley points with ``qmc`` = (pixel ids, first
    sample numbers, seed) as pixel_samples takes it (pair 1 keyed by LENS_KEY), else ``rng``'s."""
    if qmc is None:
        return rng.random((p * spp, 2))
    ids, first, seed = qmc
    pix = np.repeat(np.asarray(ids), spp)
    num = (np.broadcast_to(np.asarray(first, np.int64), (p,))[:, None] + np.arange(spp)[None, :]).ravel()
    ux, uy = sobol_owen_2d(pix, num, 1, (int(seed) ^ LENS_KEY) & 0xFFFFFFFFFFFFFFFF)
    return np.stack([np.asarray(ux, np.float64), np.asarray(uy, np.float64)], axis=1)


#: The shutter times' numbers: Sobol-Burley pair 0's x under their own scramble (the seed xor this
#: constant), stratified over a pixel's samples and independent of the pixel position, the
#: wavelength, the aperture and the path's numbers (which use other keys)
TIME_KEY = 0x54494D45  # "TIME"


def has_motion(cam: Camera) -> bool:
    """Whether the camera moves during the shutter (at least two motion steps)."""
    m = getattr(cam, "motion", None)
    return m is not None and len(m) >= 2


def shutter_table(curve, size: int = 4096) -> np.ndarray:
    """The inverse CDF (``size`` times in [0, 1]) of a shutter curve: ``curve`` (M,) non-negative
    weights at M evenly spaced times from the shutter's opening to its closing (Blender's Shutter
    Curve, linear between them), as Cycles' shutter table (intern/cycles/scene/camera.cpp,
    util_cdf_inverted of shutter_curve_eval): a uniform number u -> the time whose CDF is u.
    Cycles' table has 256 entries; 4096 here, so that linear interpolation between entries does
    not over-expose the first and last instants of a curve that opens from zero (the inverse CDF
    rises as a square root there: 256 entries put 1.9 times the exposure in the first 2.5 % of a
    triangle shutter; tests/sampling/test_camera_motion.py)."""
    w = np.maximum(np.asarray(curve, np.float64).ravel(), 0.0)
    if w.size < 2 or not np.isfinite(w).all() or w.sum() <= 0:
        return np.zeros(0)
    x = np.linspace(0.0, 1.0, 4097)  # the curve, linear between its points, on a fine grid
    dens = np.interp(x, np.linspace(0.0, 1.0, w.size), w)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]))])
    cdf /= cdf[-1]
    rise = np.diff(cdf) > 0  # a flat stretch (zero weight) keeps only its two ends: never chosen inside
    keep = np.concatenate([[True], rise]) | np.concatenate([rise, [True]])
    return np.clip(np.interp(np.linspace(0.0, 1.0, int(size)), cdf[keep], x[keep]), 0.0, 1.0)


def shutter_times(cam: Camera, u: np.ndarray) -> np.ndarray:
    """Times in [0, 1] across the shutter for uniform numbers ``u``: through the camera's shutter
    table (linear between its entries) or, without one (a flat curve), ``u`` itself."""
    u = np.asarray(u, np.float64)
    table = np.asarray(getattr(cam, "shutter_table", np.zeros(0)), np.float64)
    if table.size < 2:
        return u
    return np.interp(u, np.linspace(0.0, 1.0, table.size), table)


def time_samples(p: int, spp: int, rng: np.random.Generator, qmc=None) -> np.ndarray:
    """(p * spp,) uniform numbers for the shutter times of ``spp`` samples of ``p`` pixels, in
    pixel_samples' order: the pixels' Sobol-Burley points with ``qmc`` = (pixel ids, first sample
    numbers, seed) as pixel_samples takes it (pair 0's x keyed by TIME_KEY), else stratified
    (one per stratum of 1 / spp, in random order) from ``rng``."""
    if qmc is None:
        strata = rng.permuted(np.broadcast_to(np.arange(spp, dtype=np.float64), (p, spp)), axis=1)
        return ((strata + rng.random((p, spp))) / spp).ravel()
    ids, first, seed = qmc
    pix = np.repeat(np.asarray(ids), spp)
    num = (np.broadcast_to(np.asarray(first, np.int64), (p,))[:, None] + np.arange(spp)[None, :]).ravel()
    return sobol_owen_x(pix, num, 0, (int(seed) ^ TIME_KEY) & 0xFFFFFFFFFFFFFFFF).astype(np.float64)


def rotation_to_quaternion(r: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) as (w, x, y, z) of rotation matrices (..., 3, 3) (Shepperd's
    method: the largest of the four squared components first, for accuracy)."""
    r = np.asarray(r, np.float64)
    tr = np.trace(r, axis1=-2, axis2=-1)
    cand = np.stack([tr, r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]], axis=-1)
    i = np.argmax(cand, axis=-1)
    q = np.empty(r.shape[:-2] + (4,))
    s = np.sqrt(np.maximum(1.0 + 2.0 * np.take_along_axis(cand, i[..., None], -1)[..., 0] - tr, 1e-300)) * 2.0
    r21, r12, r02, r20, r10, r01 = r[..., 2, 1], r[..., 1, 2], r[..., 0, 2], r[..., 2, 0], r[..., 1, 0], r[..., 0, 1]
    q0 = np.stack([s / 4, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s], -1)
    q1 = np.stack([(r21 - r12) / s, s / 4, (r01 + r10) / s, (r02 + r20) / s], -1)
    q2 = np.stack([(r02 - r20) / s, (r01 + r10) / s, s / 4, (r12 + r21) / s], -1)
    q3 = np.stack([(r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, s / 4], -1)
    q = np.choose(i[..., None], [q0, q1, q2, q3])
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quaternion_to_rotation(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) as (w, x, y, z) (normalised first)."""
    q = np.asarray(q, np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], -2)


def motion_frames(cam: Camera, time: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The moving camera's rotations (B, 3, 3) (unit axes as columns, scale dropped) and positions
    (B, 3) at shutter times ``time`` (B,) in [0, 1], as Cycles' transform_motion_array_interpolate
    (intern/cycles/util/transform.h): step = min(floor(t (N - 1)), N - 2), f = t (N - 1) - step,
    the rotation slerped from step to step + 1 (each quaternion's sign following the previous one's,
    transform_motion_decompose, so the arc is the shorter), the position lerped."""
    m = np.asarray(cam.motion, np.float64)
    n = len(m)
    rot = m[:, :3, :3] / np.linalg.norm(m[:, :3, :3], axis=1, keepdims=True)
    if np.linalg.det(rot[0]) < 0:  # a mirrored camera: interpolate its rotation, mirror after (x axis)
        flip = np.diag([-1.0, 1.0, 1.0])
        rot = rot @ flip
    else:
        flip = None
    q = rotation_to_quaternion(rot)
    for i in range(1, n):
        if q[i] @ q[i - 1] < 0:
            q[i] = -q[i]
    t = np.clip(np.asarray(time, np.float64), 0.0, 1.0) * (n - 1)
    step = np.minimum(t.astype(np.int64), n - 2)
    f = (t - step)[:, None]
    qa, qb = q[step], q[step + 1]
    cos = np.clip(np.sum(qa * qb, axis=1), -1.0, 1.0)[:, None]
    theta = np.arccos(cos)
    sin = np.sin(theta)
    near = sin < 1e-6  # (nearly) the same rotation: lerp, normalised below
    safe = np.where(near, 1.0, sin)
    wa = np.where(near, 1.0 - f, np.sin((1.0 - f) * theta) / safe)
    wb = np.where(near, f, np.sin(f * theta) / safe)
    r = quaternion_to_rotation(wa * qa + wb * qb)
    if flip is not None:
        r = r @ flip
    pos = (1.0 - f) * m[step, :3, 3] + f * m[step + 1, :3, 3]
    return r, pos


def aperture_points(u: np.ndarray, v: np.ndarray, blades: int = 0, rotation: float = 0.0,
                    ratio: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Points on the unit aperture (radius 1) from uniform (u, v) in [0, 1)^2, uniform in area:
    a disk when ``blades`` < 3 (Shirley & Chiu's concentric map, which keeps the numbers'
    stratification), else the regular polygon of ``blades`` corners on the unit circle at angles
    ``rotation`` + (2k + 1) pi / blades, as Cycles' regular_polygon_sample
    (intern/cycles/kernel/sample/mapping.h): u picks one of the polygon's isosceles wedges and,
    rescaled, the distance from the centre (sqrt for a uniform triangle), v the position across
    the wedge. The x coordinate is then divided by ``ratio`` (Cycles' inv_aperture_ratio, an
    anamorphic bokeh). docs/physics.md section 6.7."""
    u = np.asarray(u, np.float64)
    v = np.asarray(v, np.float64)
    if int(blades) < 3:
        a, b = 2.0 * u - 1.0, 2.0 * v - 1.0
        horiz = np.abs(a) > np.abs(b)
        r = np.where(horiz, a, b)
        safe_a = np.where(a == 0, 1.0, a)
        safe_b = np.where(b == 0, 1.0, b)
        phi = np.where(horiz, np.pi / 4 * (b / safe_a), np.pi / 2 - np.pi / 4 * (a / safe_b))
        x, y = r * np.cos(phi), r * np.sin(phi)
    else:
        n = float(int(blades))
        corner = np.floor(u * n)
        t = np.sqrt(u * n - corner)  # the wedge's radial coordinate (uniform over the triangle)
        s = v * t
        w = 1.0 - t
        half = np.pi / n
        px, py = (w + s) * np.cos(half), (w - s) * np.sin(half)
        rot = float(rotation) + corner * 2.0 * half
        cr, sr = np.cos(rot), np.sin(rot)
        x, y = cr * px - sr * py, sr * px + cr * py
    return x / float(ratio), y


def panorama_directions(cam: Camera, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Directions of a panoramic camera in Cycles' panorama space (x forward, y left, z up) for
    image coordinates (u, v) in [0, 1] (u to the right, v UP, Cycles' raster convention), and
    whether each is inside the projection (a fisheye's circle). The mappings are Cycles'
    (intern/cycles/kernel/camera/projection.h, docs/physics.md section 6.9):

    - equirectangular: phi = (lon_min - lon_max) u - lon_min, theta = (lat_min - lat_max) v -
      lat_min + pi / 2, d = (sin theta cos phi, sin theta sin phi, cos theta);
    - fisheye equidistant: (u', v') = 2 (u, v) - 1, r = |(u', v')| <= 1, theta = r fov / 2;
    - fisheye equisolid: (u', v') = ((u - 1/2) sensor_w, (v - 1/2) sensor_h) mm, r <= 2 f sin(fov / 4),
      theta = 2 asin(r / 2f); both d = (cos theta, -sin theta u'/r, sin theta v'/r)."""
    u = np.asarray(u, np.float64)
    v = np.asarray(v, np.float64)
    kind = cam.panorama_type
    if kind == "EQUIRECTANGULAR":
        phi = (cam.longitude_min - cam.longitude_max) * u - cam.longitude_min
        theta = (cam.latitude_min - cam.latitude_max) * v - cam.latitude_min + np.pi / 2
        st = np.sin(theta)
        d = np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)
        return d, np.ones(u.shape, bool)
    if kind == "FISHEYE_EQUIDISTANT":
        a, b = (u - 0.5) * 2.0, (v - 0.5) * 2.0
        r = np.hypot(a, b)
        valid = r <= 1.0
        theta = r * float(cam.fisheye_fov) * 0.5
    else:  # FISHEYE_EQUISOLID on Cycles' fitted sensor
        sw, sh = panorama_sensor(cam)
        a, b = (u - 0.5) * sw, (v - 0.5) * sh
        r = np.hypot(a, b)
        lens = float(cam.fisheye_lens)
        valid = r <= 2.0 * lens * np.sin(float(cam.fisheye_fov) * 0.25)
        theta = 2.0 * np.arcsin(np.clip(r / (2.0 * lens), 0.0, 1.0))
    safe = np.where(r > 0, r, 1.0)
    cphi = np.where(r > 0, a / safe, 1.0)
    sphi = np.where(r > 0, b / safe, 0.0)
    st = np.sin(theta)
    d = np.stack([np.cos(theta), -cphi * st, sphi * st], axis=-1)
    return d, valid


def panorama_sensor(cam: Camera) -> tuple[float, float]:
    """The sensor (width, height) in mm an equisolid fisheye spans, fitted as Cycles' blender_camera_sync
    does: the fitted side takes the sensor size, the other follows the image's aspect."""
    w, h = float(cam.width), float(cam.height)
    fit = cam.sensor_fit
    if fit == "AUTO":
        horizontal, size = w > h, cam.sensor_width
    elif fit == "HORIZONTAL":
        horizontal, size = True, cam.sensor_width
    else:
        horizontal, size = False, cam.sensor_height
    return (float(size), float(size) * h / w) if horizontal else (float(size) * w / h, float(size))


#: Cycles' panorama space (x forward, y left, z up) -> Blender camera space (x right, y up, -z
#: forward): intern/cycles/blender/camera.cpp blender_camera_matrix
_PANO_TO_LOCAL = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])


def has_lens(cam: Camera) -> bool:
    """Whether the camera has a thin lens (depth of field): a non-zero aperture radius."""
    return float(getattr(cam, "aperture_radius", 0.0)) > 0.0


def clips(cam: Camera) -> bool:
    """Whether the camera clips (a clip start above 0 or a finite clip end)."""
    return float(getattr(cam, "clip_start", 0.0)) > 0.0 or np.isfinite(float(getattr(cam, "clip_end", np.inf)))


def camera_rays(cam: Camera, x: np.ndarray, y: np.ndarray, lens_u: np.ndarray | None = None,
                time: np.ndarray | None = None):
    """World-space camera rays through image points (x, y) (pixels, 0 at the left / top edge):
    (origins (B, 3) float32, unit directions (B, 3) float32, tmax (B,) float32 or None for
    unbounded rays, valid (B,) bool or None when every ray is valid (a fisheye's corners are not)).

    ``lens_u`` (B, 2) uniform numbers for the aperture point (None: the lens centre, the chief
    ray). Cycles' camera_sample_perspective / _orthographic / _panorama
    (intern/cycles/kernel/camera/camera.h, docs/physics.md sections 6.7-6.9): a thin lens aims every
    ray at the point the pinhole ray meets the plane of focus; clip start moves the origin
    forward to the near plane (perspective: clip_start / cos of the pinhole ray off the view
    axis along the ray; panoramic: clip_start along it) and clip end bounds the ray there.
    ``time`` (B,) shutter times in [0, 1] for a moving camera (``has_motion``): each ray leaves
    the camera interpolated at its time (``motion_frames``); None, or a still camera: ``matrix``."""
    moving = time is not None and has_motion(cam)
    if cam.kind != "PANO" and not has_lens(cam) and not clips(cam) and not moving:
        o, d = _pinhole_rays(cam, x, y)
        return o, d, None, None
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    m = np.asarray(cam.matrix, np.float64)
    rot = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0, keepdims=True)
    eye = m[:3, 3]
    b = len(x)
    near = float(cam.clip_start)
    far = float(cam.clip_end)
    length = far - near if np.isfinite(far) else np.inf
    valid = None
    lens = None
    if has_lens(cam):
        if lens_u is None:
            lens = np.zeros((b, 2))
        else:
            lu = np.asarray(lens_u, np.float64).reshape(b, 2)
            lx, ly = aperture_points(lu[:, 0], lu[:, 1], cam.aperture_blades, cam.aperture_rotation, cam.aperture_ratio)
            lens = np.stack([lx, ly], axis=1) * float(cam.aperture_radius)
    focus = float(cam.focus_distance)
    if cam.kind == "PANO":
        u = x / int(cam.width) + float(cam.shift_x)
        v = 1.0 - y / int(cam.height) + float(cam.shift_y)
        dc, valid = panorama_directions(cam, u, v)
        p = np.zeros((b, 3))
        if lens is not None:  # Cycles: an aperture across the ray, aimed at its point at the focus distance
            uu = np.array([1.0, 0.0, 0.0]) - dc[:, :1] * dc
            uu /= np.maximum(np.linalg.norm(uu, axis=1, keepdims=True), 1e-12)
            vv = np.cross(dc, uu)
            p = uu * lens[:, :1] + vv * lens[:, 1:]
            dc = dc * focus - p
            dc /= np.linalg.norm(dc, axis=1, keepdims=True)
        local_p, local_d = p @ _PANO_TO_LOCAL.T, dc @ _PANO_TO_LOCAL.T
        start = np.full(b, near)
        tmax = np.full(b, length)
    else:
        hx, hy = camera_frame(cam)
        shift = _shift_extent(cam)
        w, h = int(cam.width), int(cam.height)
        px = (x * (2.0 / w) - 1.0) * hx + cam.shift_x * shift
        py = (1.0 - y * (2.0 / h)) * hy + cam.shift_y * shift
        if cam.kind == "ORTHO":
            local_d = np.broadcast_to(np.array([0.0, 0.0, -1.0]), (b, 3)).copy()
            local_p = np.stack([px, py, np.zeros(b)], axis=1)
            if lens is not None:  # aimed at (0, 0, -focus) from the lens point, moved to the near plane
                lp = np.stack([lens[:, 0], lens[:, 1], np.zeros(b)], axis=1)
                local_d = np.array([0.0, 0.0, -focus]) - lp
                local_d /= np.linalg.norm(local_d, axis=1, keepdims=True)
                local_p = local_p + lp
                start = near / -local_d[:, 2]
            else:
                start = np.full(b, near)
            tmax = np.full(b, length)
        else:
            chief = np.stack([px, py, -np.ones(b)], axis=1)
            cos_c = 1.0 / np.sqrt(px * px + py * py + 1.0)  # the pinhole ray's cosine off the view axis
            local_p = np.zeros((b, 3))
            local_d = chief * cos_c[:, None]
            if lens is not None:  # aimed at the pinhole ray's point on the plane of focus
                local_p = np.stack([lens[:, 0], lens[:, 1], np.zeros(b)], axis=1)
                local_d = chief * focus - local_p
                local_d /= np.linalg.norm(local_d, axis=1, keepdims=True)
            start = near / cos_c
            tmax = length / cos_c
    if moving:  # each ray's own camera frame (docs/physics.md section 6.13)
        rot, eye = motion_frames(cam, np.asarray(time, np.float64).reshape(b))
        d = np.einsum("bij,bj->bi", rot, local_d)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        o = np.einsum("bij,bj->bi", rot, local_p) + eye + start[:, None] * d
    else:
        d = local_d @ rot.T
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        o = local_p @ rot.T + eye + start[:, None] * d
    if valid is not None and not valid.all():
        d[~valid] = (0.0, 0.0, -1.0)  # traced nowhere (tmax 0): the caller drops them
        tmax = np.where(valid, tmax, 0.0)
    else:
        valid = None
    if valid is None and not np.isfinite(far):
        tmax = None  # unbounded
    else:
        tmax = np.minimum(tmax, np.finfo(np.float32).max).astype(np.float32)
    return np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32), tmax, valid


def generate_rays(cam: Camera, x: np.ndarray, y: np.ndarray, lens_u: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """World-space ray origins and unit directions (float32) through image points (x, y)
    (``camera_rays`` without the clip end and validity: for tools and tests; ``lens_u`` None:
    the chief rays through the lens centre)."""
    o, d, _, _ = camera_rays(cam, x, y, lens_u)
    return o, d


def _pinhole_rays(cam: Camera, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A pinhole perspective or orthographic camera's rays without clipping (float32 throughout)."""
    w, h = int(cam.width), int(cam.height)
    hx, hy = camera_frame(cam)
    shift = _shift_extent(cam)
    f32 = np.float32  # sub-pixel positions and directions need no more (pixels < 2^16)
    px = (np.asarray(x, f32) * f32(2.0 / w) - f32(1.0)) * f32(hx) + f32(cam.shift_x * shift)
    py = (f32(1.0) - np.asarray(y, f32) * f32(2.0 / h)) * f32(hy) + f32(cam.shift_y * shift)
    m = np.asarray(cam.matrix, np.float64)
    rot = (m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0, keepdims=True)).astype(f32)  # drop object scale
    eye = m[:3, 3]
    if cam.kind == "ORTHO":
        local_o = np.stack([px, py, np.zeros_like(px)], axis=1)
        origins = local_o @ rot.T + eye
        dirs = np.broadcast_to(-rot[:, 2], origins.shape)
    else:
        local_d = np.stack([px, py, -np.ones_like(px)], axis=1)
        dirs = local_d @ rot.T
        dirs /= np.sqrt(np.einsum("ij,ij->i", dirs, dirs))[:, None]
        origins = np.broadcast_to(eye, dirs.shape)
    return np.ascontiguousarray(origins, np.float32), np.ascontiguousarray(dirs, np.float32)
