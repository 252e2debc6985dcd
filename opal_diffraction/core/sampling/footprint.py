"""Ray differentials: each camera sample's pixel footprint, carried through mirrors and glass to
the gratings, where it becomes the extent (du, dv) of the footprint in the grating's direction
cosines (docs/physics.md section 3.7).

Method: Igehy, "Tracing Ray Differentials" (SIGGRAPH 1999), as pbrt-v4 section 10.1 has it. A
ray x(t) = o + t d carries the derivatives (do/dx, dd/dx) and (do/dy, dd/dy) of its origin and
unit direction with respect to one pixel step in x and y. At a surface with normal n:

- transfer to the hit plane: dp = do + t dd + dt d, dt = -((do + t dd) . n) / (d . n);
- mirror reflection d' = d - 2 (d . n) n (a flat facet: dn = 0): dd' = dd - 2 (dd . n) n, do' = dp;
- refraction d' = eta d + mu n, mu = eta c_i - c_t, c_i = -d . n, c_t = -d' . n (n facing the
  incoming ray): dd' = eta dd + dmu n, dmu = (eta - eta^2 c_i / c_t) dc_i, dc_i = -dd . n.

The normal's own derivative (curved mirrors: interpolated shading normals) is neglected, so a
footprint is carried through a curved mirror as through a flat one (named in docs/physics.md
section 3.7). Rays without differentials (the light pass, paths after a diffuse or rough
bounce) carry zeros: a zero footprint is a point sample, today's behaviour.

The differentials live in ``PathState.rd`` (core/transport/path_state.py): (B, 5, 3) float32 = (do/dx, dd/dx, do/dy, dd/dy,
(ox, oy, width)), present only when the scene has gratings and footprint integration is on;
(ox, oy) is the sample's offset from its pixel centre in pixels, width the footprint's in pixels.

At a grating hit, with u = (w_o + w_i) . t and v = (w_o + w_i) . s, w_o = -d and
w_i = (x_l - p) / |x_l - p| for a light at distance r (dw_i = -(dp - w_i (w_i . dp)) / r; 0 for
distant lights and records), du/dx = (dw_o + dw_i) . t, and so on. The pixel square maps to a
parallelogram in (u, v); its separable box approximation keeps each marginal's variance:
du = sqrt((du/dx)^2 + (du/dy)^2), dv likewise (a uniform box of width w has variance w^2 / 12,
the marginal of the parallelogram (|du/dx| + |du/dy| wide, a trapezoid) has
((du/dx)^2 + (du/dy)^2) / 12). The change of t-hat itself across the footprint (a CD's radial
frame turns) is neglected.

The footprint is the reconstruction filter's, centred at the pixel centre: samples are drawn
from the filter (filter importance sampling, core/sampling/camera.py), so a pixel's value is the
filter-weighted integral of the image; for the pattern that integral is taken in closed form,
with the filter replaced by the box of equal variance (``filter_box_width``: 1.47 px for
Cycles' default 1.5 px Blackman-Harris) about the pixel centre's (u, v) = the sample's (u, v)
minus the gradients times the sample's offset. A sub-pixel glint (a point light's zeroth order)
then adds the same to every sample of a pixel instead of to the few that land near it. Width 0
(samples at the pixel centres) integrates over the pixel's own square.
"""

from __future__ import annotations

import numpy as np

from .camera import camera_frame

#: NumPy 2 renamed np.trapz to np.trapezoid (the same trapezoidal rule); NumPy 1.24-1.26 (Blender 4.2-5.0) has only trapz
_trapezoid = getattr(np, "trapezoid", None) or np.trapz

__all__ = ["filter_box_width", "camera_differentials", "zero_differentials", "transfer", "reflect_differentials",
           "refract_differentials", "grating_footprint"]

def zero_differentials(b: int) -> np.ndarray:
    return np.zeros((b, 5, 3), np.float32)


_BH = (0.35875, 0.48829, 0.14128, 0.01168)


def filter_box_width(filter_width: float) -> float:
    """The width (pixels) of the box with the variance of core/sampling/camera.py's Blackman-Harris filter
    of ``filter_width`` (it spans +-filter_width pixels): sqrt(12) sigma. Width 0 (samples at
    the pixel centres): one pixel, the pixel's own area."""
    if filter_width <= 0:
        return 1.0
    x = np.linspace(0.0, 1.0, 4097)
    f = _BH[0] - _BH[1] * np.cos(2 * np.pi * x) + _BH[2] * np.cos(4 * np.pi * x) - _BH[3] * np.cos(6 * np.pi * x)
    var = _trapezoid(f * (x - 0.5) ** 2, x) / _trapezoid(f, x)
    return float(np.sqrt(12 * var) * 2 * filter_width)


def camera_differentials(cam, directions: np.ndarray, offsets=None, box_width: float = 1.0) -> np.ndarray:
    """(B, 5, 3) float32 differentials of camera rays per pixel step (core/sampling/camera.py's
    projection: the image-plane point moves by 2 hx / width per pixel in x and by -2 hy / height
    per pixel in y, at distance 1 for a perspective camera, in metres for an orthographic one),
    and in row 4 (ox, oy, box_width): the sample's offset from its pixel centre ``offsets``
    (2, B) in pixels (None: 0) and the footprint's width in pixels (``filter_box_width``).
    A thin lens keeps its pinhole's differentials (as Cycles' camera_sample_perspective does: the
    footprint is the pixel's, not the blur's); a panoramic camera gets zeros with width 0 (point
    samples of the pattern)."""
    if cam.kind == "PANO":  # no differentials for panoramas: point samples (docs/physics.md section 6.10)
        out = np.zeros((len(directions), 5, 3), np.float32)
        out[:, 4, 2] = 0.0
        return out
    w, h = int(cam.width), int(cam.height)
    hx, hy = camera_frame(cam)
    m = np.asarray(cam.matrix, np.float64)
    rot = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0, keepdims=True)
    step_x = rot[:, 0] * (2.0 * hx / w)   # world-space image-plane step per pixel in x
    step_y = -rot[:, 1] * (2.0 * hy / h)  # y grows downwards in the image
    d = np.asarray(directions, np.float64)
    out = np.zeros((len(d), 5, 3), np.float64)
    if cam.kind == "ORTHO":
        out[:, 0] = step_x
        out[:, 2] = step_y
    else:
        # d = l / |l| with l the image-plane point at distance 1 along -z: |l| = 1 / (d . -z)
        depth = -(d @ rot[:, 2])
        inv_len = np.maximum(depth, 1e-12)  # 1 / |l|
        for j, step in ((1, step_x), (3, step_y)):
            dl = np.broadcast_to(step, d.shape)
            out[:, j] = (dl - d * (d @ step)[:, None]) * inv_len[:, None]
    if offsets is not None:
        out[:, 4, 0], out[:, 4, 1] = offsets[0], offsets[1]
    out[:, 4, 2] = box_width
    return out.astype(np.float32)


def transfer(rd: np.ndarray, o: np.ndarray, d: np.ndarray, p: np.ndarray, n: np.ndarray):
    """Position differentials at the hit p on the plane with normal n: (dp/dx, dp/dy), (B, 3) each."""
    d64 = np.asarray(d, np.float64)
    t = np.einsum("ij,ij->i", np.asarray(p, np.float64) - o, d64)[:, None]
    dn = np.einsum("ij,ij->i", d64, n)
    dn = np.where(np.abs(dn) < 1e-8, np.copysign(1e-8, dn), dn)[:, None]
    out = []
    for j in (0, 2):
        q = rd[:, j].astype(np.float64) + t * rd[:, j + 1]
        out.append(q - (np.einsum("ij,ij->i", q, n)[:, None] / dn) * d64)
    return out


def reflect_differentials(rd, o, d, p, n) -> np.ndarray:
    """The differentials of the mirror-reflected rays (B, 4, 3) (n: the normal reflected about)."""
    n = np.asarray(n, np.float64)
    dpx, dpy = transfer(rd, o, d, p, n)
    out = rd.copy()  # row 4 (pixel offset and footprint width) goes on unchanged
    out[:, 0], out[:, 2] = dpx, dpy
    for j in (1, 3):
        dd = rd[:, j].astype(np.float64)
        out[:, j] = dd - 2.0 * np.einsum("ij,ij->i", dd, n)[:, None] * n
    return out


def refract_differentials(rd, o, d, p, n, d_new, eta) -> np.ndarray:
    """The differentials of rays leaving a dielectric along ``d_new`` (B, 4, 3): refracted where
    d_new crosses the plane of n (relative index ``eta`` (B,), incident over transmitted),
    mirror-reflected where it stays on the incident side."""
    n = np.asarray(n, np.float64)
    d64 = np.asarray(d, np.float64)
    dnew = np.asarray(d_new, np.float64)
    n = np.where((np.einsum("ij,ij->i", d64, n) > 0)[:, None], -n, n)  # facing the incoming ray
    dpx, dpy = transfer(rd, o, d, p, n)
    out = rd.copy()
    out[:, 0], out[:, 2] = dpx, dpy
    c_i = -np.einsum("ij,ij->i", d64, n)
    c_t = -np.einsum("ij,ij->i", dnew, n)
    refracted = c_t > 1e-6
    eta = np.asarray(eta, np.float64)
    k = np.where(refracted, eta - eta * eta * c_i / np.where(refracted, c_t, 1.0), 0.0)
    for j in (1, 3):
        dd = rd[:, j].astype(np.float64)
        ddn = np.einsum("ij,ij->i", dd, n)
        refr = eta[:, None] * dd + (k * -ddn)[:, None] * n
        refl = dd - 2.0 * ddn[:, None] * n
        out[:, j] = np.where(refracted[:, None], refr, refl)
    return out


def grating_footprint(rd, o, d, p, n, t, s, w_i, dist=None):
    """The footprint of each ray's pixel in the grating's (u, v) at its hit p (plane normal n,
    frame t, s) for light from w_i (unit, towards the light) at distance ``dist`` (B,) (inf or
    None: a distant light, w_i constant): (du, dv, su, sv), each (B,): its extent, and the shift
    from the sample's (u, v) to the footprint's centre (the pixel centre's (u, v), to first
    order: the sample's offset from it times the gradients)."""
    dpx, dpy = transfer(rd, o, d, p, n)
    w_i = np.asarray(w_i, np.float64)
    t = np.asarray(t, np.float64)
    s = np.asarray(s, np.float64)
    inv_r = None
    if dist is not None:
        r = np.asarray(dist, np.float64)
        inv_r = np.where(np.isfinite(r) & (r > 0), 1.0 / np.where(np.isfinite(r) & (r > 0), r, 1.0), 0.0)[:, None]
    grads = []
    for dp, j in ((dpx, 1), (dpy, 3)):
        dh = -rd[:, j].astype(np.float64)  # d w_o = -dd
        if inv_r is not None:
            dh = dh - (dp - w_i * np.einsum("ij,ij->i", w_i, dp)[:, None]) * inv_r
        grads.append((np.einsum("ij,ij->i", dh, t), np.einsum("ij,ij->i", dh, s)))
    width = rd[:, 4, 2].astype(np.float64)
    du = np.hypot(grads[0][0], grads[1][0]) * width
    dv = np.hypot(grads[0][1], grads[1][1]) * width
    ox, oy = rd[:, 4, 0].astype(np.float64), rd[:, 4, 1].astype(np.float64)
    su = -(grads[0][0] * ox + grads[1][0] * oy)
    sv = -(grads[0][1] * ox + grads[1][1] * oy)
    return du, dv, su, sv
