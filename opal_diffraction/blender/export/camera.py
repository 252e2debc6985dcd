"""The camera and the image: render size, the border region, and the camera object -> core Camera.

The image size is the resolution times its percentage and the border rectangle is truncated to
pixels as Blender does, so the render fills exactly the pixels Blender expects. Perspective and
orthographic cameras keep their lens, sensor size and fit, orthographic scale and shift; what
the core's pinhole camera cannot do (panoramic cameras: an error; depth of field, non-square
pixels, and clip start / end where they would hide part of the scene in Cycles: warnings) is named.
"""

from __future__ import annotations

import numpy as np

from ...core.scene.model import Camera
from ...core.scene.checks import SceneError
from .messages import Warnings

__all__ = ["render_size", "render_region", "camera_from_object", "export_camera", "clipped_share", "warn_clipping"]


def render_size(scene) -> tuple[int, int]:
    """Rendered image size in pixels: resolution times percentage, as Blender computes it."""
    r = scene.render
    pct = int(r.resolution_percentage)
    return max(1, int(r.resolution_x) * pct // 100), max(1, int(r.resolution_y) * pct // 100)


def render_region(scene, width: int, height: int) -> tuple[int, int, int, int] | None:
    """The border-render rectangle in pixels, (x0, y0, x1, y1) with rows counted from the BOTTOM
    (Blender's convention), or None for the full frame. Matches Blender's own truncation."""
    r = scene.render
    if not r.use_border:
        return None
    x0, x1 = int(r.border_min_x * width), int(r.border_max_x * width)
    y0, y1 = int(r.border_min_y * height), int(r.border_max_y * height)
    x0, y0 = max(0, min(x0, width)), max(0, min(y0, height))
    x1, y1 = max(0, min(x1, width)), max(0, min(y1, height))
    if x1 <= x0 or y1 <= y0 or (x0, y0, x1, y1) == (0, 0, width, height):
        return None
    return x0, y0, x1, y1


def camera_from_object(cam_ob, width: int, height: int, scene, warn) -> Camera:
    """The core camera of the evaluated camera object ``cam_ob`` for a ``width`` x ``height`` image."""
    cam = cam_ob.data
    if cam_ob.type != "CAMERA":
        raise SceneError(f"the active camera '{cam_ob.name}' is not a camera object")
    if cam.type not in ("PERSP", "ORTHO"):
        raise SceneError(f"camera '{cam_ob.name}': {cam.type.lower()} cameras are not supported; use a perspective "
                         "or orthographic camera")
    m = np.array(cam_ob.matrix_world, np.float64)
    if not np.isfinite(m).all():
        raise SceneError(f"camera '{cam_ob.name}': its transform is NaN or infinite")
    r = scene.render
    if abs(r.pixel_aspect_x - r.pixel_aspect_y) > 1e-6:
        warn("non-square pixel aspect is not supported: rendered with square pixels")
    if getattr(cam, "dof", None) is not None and cam.dof.use_dof:
        warn(f"camera '{cam_ob.name}': depth of field is not rendered (pinhole camera)")
    return Camera(
        matrix=m, kind=cam.type, lens=float(cam.lens), sensor_width=float(cam.sensor_width),
        sensor_height=float(cam.sensor_height), sensor_fit=cam.sensor_fit, ortho_scale=float(cam.ortho_scale),
        shift_x=float(cam.shift_x), shift_y=float(cam.shift_y), width=int(width), height=int(height),
    )


def export_camera(depsgraph, *, width: int | None = None, height: int | None = None, camera=None,
                  warn: Warnings | None = None) -> Camera | None:
    """The core camera alone, as :func:`export_scene` makes it: ``camera`` (an object) or the
    scene's, for ``width`` x ``height`` (default :func:`render_size`); None without a camera.
    ``warn``: collects the warnings (default: dropped)."""
    scene = depsgraph.scene
    if width is None or height is None:
        width, height = render_size(scene)
    cam_ob = camera if camera is not None else scene.camera
    if cam_ob is None:
        return None
    cam_eval = cam_ob.evaluated_get(depsgraph) if not cam_ob.is_evaluated else cam_ob
    return camera_from_object(cam_eval, width, height, scene, warn if warn is not None else Warnings())


def clipped_share(camera: Camera, vertices: np.ndarray, clip_start: float, clip_end: float) -> float:
    """The share of the vertices in the camera's view that lie nearer than ``clip_start`` or
    farther than ``clip_end`` (depths along the view axis, as Cycles clips: planes, not spheres)."""
    from ...core.sampling.camera import camera_frame

    v = np.asarray(vertices, np.float64).reshape(-1, 3)
    if not len(v):
        return 0.0
    m = np.asarray(camera.matrix, np.float64)
    rot = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0, keepdims=True)
    local = (v - m[:3, 3]) @ rot  # camera space: x right, y up, looking down -z
    depth = -local[:, 2]
    hx, hy = camera_frame(camera)
    extent = 2 * (hx if (camera.sensor_fit == "HORIZONTAL" or camera.sensor_fit == "AUTO"
                        and camera.width >= camera.height) else hy)
    if camera.kind == "ORTHO":
        px, py, ahead = local[:, 0], local[:, 1], np.ones(len(v), bool)
    else:
        ahead = depth > 0
        safe = np.where(ahead, depth, 1.0)
        px, py = local[:, 0] / safe, local[:, 1] / safe
    seen = (ahead & (np.abs(px - camera.shift_x * extent) <= hx) & (np.abs(py - camera.shift_y * extent) <= hy))
    if not seen.any():
        return 0.0
    clipped = seen & ((depth < clip_start) | (depth > clip_end))
    return float(clipped.sum()) / float(seen.sum())


def warn_clipping(cam_ob, camera: Camera | None, vertices: np.ndarray, warn) -> None:
    """Warn when the camera object's clip start / end would hide part of what it sees (the core
    renders without clipping: it shows what Cycles would cut away)."""
    if cam_ob is None or camera is None or getattr(cam_ob, "type", None) != "CAMERA":
        return
    start, end = float(cam_ob.data.clip_start), float(cam_ob.data.clip_end)
    share = clipped_share(camera, vertices, start, end)
    if share > 0:
        warn(f"camera '{cam_ob.name}': clip start {start:g} m / end {end:g} m would hide {100 * share:.0f} % of the "
             "scene's vertices in view (as Cycles clips); clipping is not rendered yet: shown unclipped")
