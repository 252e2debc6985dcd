"""The camera and the image: render size, the border region, and the camera object -> core Camera.

The image size is the resolution times its percentage and the border rectangle is truncated to
pixels as Blender does, so the render fills exactly the pixels Blender expects. Perspective and
orthographic cameras keep their lens, sensor size and fit, orthographic scale and shift;
panoramic ones their type (equirectangular, fisheye equidistant or equisolid) and its ranges;
every camera its clip start / end and depth of field (aperture from the f-number, blades,
rotation, ratio, focus distance or object), as Cycles reads them (intern/cycles/blender/camera.cpp).
What the core cannot do is named: other panorama types (an error), non-square pixels and
motion blur (warnings).
"""

from __future__ import annotations

import numpy as np

from ...core.scene.model import Camera
from ...core.scene.checks import SceneError
from .messages import Warnings

__all__ = ["render_size", "render_region", "camera_from_object", "export_camera", "focus_distance", "PANORAMA_TYPES"]


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


#: Blender's panorama types the core renders (Cycles' mappings: core/sampling/camera.py)
PANORAMA_TYPES = ("EQUIRECTANGULAR", "FISHEYE_EQUIDISTANT", "FISHEYE_EQUISOLID")


def focus_distance(cam_ob, m: np.ndarray) -> float:
    """Cycles' focal distance (intern/cycles/blender/camera.cpp blender_camera_focal_distance):
    the Focus Distance, or with a Focus Object (and bone) the distance from the camera to it
    along the camera's view axis, |view . (camera - object)|."""
    dof = cam_ob.data.dof
    target = dof.focus_object
    if target is None:
        return float(dof.focus_distance)
    tm = np.array(target.matrix_world, np.float64)
    sub = getattr(dof, "focus_subtarget", "")
    if sub and getattr(target, "pose", None) is not None and sub in target.pose.bones:
        tm = tm @ np.array(target.pose.bones[sub].matrix, np.float64)
    view = m[:3, 2] / np.linalg.norm(m[:3, 2])
    return float(abs(view @ (m[:3, 3] - tm[:3, 3])))


def camera_from_object(cam_ob, width: int, height: int, scene, warn) -> Camera:
    """The core camera of the evaluated camera object ``cam_ob`` for a ``width`` x ``height``
    image: perspective, orthographic or panoramic (equirectangular, fisheye equidistant or
    equisolid), with depth of field and clip start / end read as Cycles reads them."""
    cam = cam_ob.data
    if cam_ob.type != "CAMERA":
        raise SceneError(f"the active camera '{cam_ob.name}' is not a camera object")
    if cam.type not in ("PERSP", "ORTHO", "PANO"):
        raise SceneError(f"camera '{cam_ob.name}': {cam.type.lower()} cameras are not supported; use a perspective, "
                         "orthographic or panoramic camera")
    pano = str(getattr(cam, "panorama_type", "EQUIRECTANGULAR"))
    if cam.type == "PANO" and pano not in PANORAMA_TYPES:
        raise SceneError(f"camera '{cam_ob.name}': the {pano.replace('_', ' ').lower()} panorama is not supported; use "
                         "equirectangular, fisheye equidistant or fisheye equisolid")
    m = np.array(cam_ob.matrix_world, np.float64)
    if not np.isfinite(m).all():
        raise SceneError(f"camera '{cam_ob.name}': its transform is NaN or infinite")
    r = scene.render
    if abs(r.pixel_aspect_x - r.pixel_aspect_y) > 1e-6:
        warn("non-square pixel aspect is not supported: rendered with square pixels")
    if getattr(r, "use_motion_blur", False):
        warn("motion blur is not rendered: the frame is rendered at its own time, without blur")
    lens = {}
    dof = getattr(cam, "dof", None)
    if dof is not None and dof.use_dof:
        fstop = max(float(dof.aperture_fstop), 1e-5)
        # Cycles: the aperture radius from the f-number, lens / (2 N) (orthographic: 1 / (2 N) m)
        radius = 1.0 / (2.0 * fstop) if cam.type == "ORTHO" else float(cam.lens) * 1e-3 / (2.0 * fstop)
        lens = dict(aperture_radius=radius, focus_distance=max(focus_distance(cam_ob, m), 1e-5),
                    aperture_blades=int(dof.aperture_blades), aperture_rotation=float(dof.aperture_rotation),
                    aperture_ratio=float(dof.aperture_ratio))
    if getattr(cam_ob.data, "type", "") == "PANO":
        lens.update(panorama_type=pano, fisheye_fov=float(cam.fisheye_fov), fisheye_lens=float(cam.fisheye_lens),
                    latitude_min=float(cam.latitude_min), latitude_max=float(cam.latitude_max),
                    longitude_min=float(cam.longitude_min), longitude_max=float(cam.longitude_max))
    return Camera(
        matrix=m, kind=cam.type, lens=float(cam.lens), sensor_width=float(cam.sensor_width),
        sensor_height=float(cam.sensor_height), sensor_fit=cam.sensor_fit, ortho_scale=float(cam.ortho_scale),
        shift_x=float(cam.shift_x), shift_y=float(cam.shift_y), width=int(width), height=int(height),
        clip_start=float(cam.clip_start), clip_end=float(cam.clip_end), **lens,
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
