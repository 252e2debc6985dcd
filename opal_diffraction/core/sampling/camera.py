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
"""

from __future__ import annotations

import numpy as np

from ..scene.model import Camera
from .sampler import sobol_owen_2d, sobol_owen_x

__all__ = ["FilterSampler", "camera_frame", "pixel_samples", "generate_rays"]


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


def generate_rays(cam: Camera, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World-space ray origins and unit directions (float32) through image points (x, y)."""
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
