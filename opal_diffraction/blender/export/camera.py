"""The camera and the image: render size, the border region, and the camera object -> core Camera.

The image size is the resolution times its percentage and the border rectangle is truncated to
pixels as Blender does, so the render fills exactly the pixels Blender expects. Perspective and
orthographic cameras keep their lens, sensor size and fit, orthographic scale and shift;
panoramic ones their type (equirectangular, fisheye equidistant or equisolid) and its ranges;
every camera its clip start / end and depth of field (aperture from the f-number, blades,
rotation, ratio, focus distance or object), as Cycles reads them (intern/cycles/blender/camera.cpp).
Motion blur (Render > Motion Blur, docs/physics.md section 6.13) as Cycles syncs it
(intern/cycles/blender/sync.cpp sync_motion, object.cpp object_motion_steps): the camera's matrix
at 2^(motion steps) + 1 evenly spaced times across the shutter (frames, placed by Position: start,
centre or end on the frame), read by re-evaluating the render's depsgraph at each sub-frame
(RenderEngine.frame_set, then back to the frame), and the Shutter Curve as an inverse CDF.
Objects' motion: export/motion.py. What the core cannot do is named: other panorama types (an
error), non-square pixels, motion blur outside final renders, a rolling shutter (warnings).
"""

from __future__ import annotations

import numpy as np

from ...core.sampling.camera import shutter_table
from ...core.scene.model import Camera
from ...core.scene.checks import SceneError
from .messages import Warnings

__all__ = ["render_size", "render_region", "camera_from_object", "export_camera", "focus_distance", "PANORAMA_TYPES",
           "motion_times", "camera_motion", "SHUTTER_TABLE_SIZE"]


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


#: Points at which the shutter curve is read (Cycles' SHUTTER_TABLE_SIZE is 256)
SHUTTER_TABLE_SIZE = 256


def motion_times(scene, steps: int) -> list[float]:
    """The scene times (frames, with sub-frames) of ``steps`` evenly spaced motion steps across
    the shutter, as Cycles' sync_motion: the shutter of Shutter frames centred on the frame,
    or starting / ending on it (Position), step i at centre + (2 i / (steps - 1) - 1) shutter / 2."""
    r = scene.render
    shutter = float(r.motion_blur_shutter)
    centre = float(scene.frame_current) + float(getattr(scene, "frame_subframe", 0.0))
    position = str(getattr(r, "motion_blur_position", "CENTER"))
    centre += {"START": 0.5 * shutter, "END": -0.5 * shutter}.get(position, 0.0)
    return [centre + (2.0 * i / (steps - 1) - 1.0) * 0.5 * shutter for i in range(steps)]


def _moving_objects(depsgraph, camera_name: str) -> dict:
    """{name: world matrix} of the depsgraph's objects other than the camera, for spotting object motion."""
    out = {}
    for ob in depsgraph.objects:
        if ob.type in ("MESH", "CURVE", "SURFACE", "META", "FONT", "LIGHT") and ob.name != camera_name:
            out[ob.name] = np.array(ob.matrix_world, np.float64)
    return out


def camera_motion(depsgraph, cam_ob, frame_set, warn, objects_checked: bool = False) -> dict:
    """``cam_ob``: the camera object (original). Camera fields for motion blur (``motion``, ``shutter_table``), {} without: Render > Motion
    Blur off, a zero shutter, the camera's own Motion Blur off (Object > Motion Blur, as Cycles),
    or no ``frame_set(frame, subframe)`` to re-evaluate the depsgraph with (outside final renders:
    a warning, as Cycles blurs final renders only). Objects whose transforms change across the
    shutter are named in a warning: their motion is not rendered."""
    scene = depsgraph.scene
    r = scene.render
    if not getattr(r, "use_motion_blur", False) or float(r.motion_blur_shutter) <= 0:
        return {}
    if frame_set is None:
        warn("motion blur is rendered in final renders only: this image is at the frame's own time")
        return {}
    cyc = getattr(scene, "cycles", None)
    if cyc is not None and str(getattr(cyc, "rolling_shutter_type", "NONE")) != "NONE":
        warn("the rolling shutter is not rendered: the whole image is exposed over the shutter at once")
    ob_cycles = getattr(cam_ob, "cycles", None)
    use = bool(getattr(ob_cycles, "use_motion_blur", True)) if ob_cycles is not None else True
    steps = max(1, int(getattr(ob_cycles, "motion_steps", 1))) if ob_cycles is not None else 1
    n = (2 << (steps - 1)) + 1  # Cycles' object_motion_steps: 2^steps + 1, one step on the frame
    frame, sub = int(scene.frame_current), float(getattr(scene, "frame_subframe", 0.0))
    name = cam_ob.name
    mats, objects = [], []
    try:
        for t in motion_times(scene, n):
            f = int(np.floor(t))
            frame_set(f, t - f)
            mats.append(np.array(cam_ob.evaluated_get(depsgraph).matrix_world, np.float64))
            objects.append(_moving_objects(depsgraph, name))
    finally:
        frame_set(frame, sub)
    moving = [] if objects_checked else sorted(k for k in objects[0] if any(k in o and not np.allclose(o[k], objects[0][k], atol=1e-7)
                                                 for o in objects[1:]))
    if moving:
        shown = ", ".join(f"'{k}'" for k in moving[:3]) + (f" and {len(moving) - 3} more" if len(moving) > 3 else "")
        warn(f"object motion blur is not rendered (only the camera's): {shown} "
             f"{'moves' if len(moving) == 1 else 'move'} during the shutter and {'is' if len(moving) == 1 else 'are'} "
             "rendered at the frame's position")
    out = {}
    m = np.stack(mats)
    if use and not np.allclose(m, m[0], atol=1e-9) and np.isfinite(m).all():
        out["motion"] = m
    curve = getattr(r, "motion_blur_shutter_curve", None)
    if curve is not None:  # the shutter's curve times objects' motion too, the camera's or not
        try:
            curve.initialize()
            w = [curve.evaluate(curve.curves[0], float(x)) for x in np.linspace(0.0, 1.0, SHUTTER_TABLE_SIZE)]
        except (AttributeError, IndexError, RuntimeError, TypeError):
            w = []
        w = np.asarray(w, np.float64)
        if w.size and not np.allclose(w, w[0]):  # a flat curve needs no table
            table = shutter_table(w)
            if table.size:
                out["shutter_table"] = table
            else:
                warn("the shutter curve is zero everywhere: motion blur uses a flat shutter")
    return out


def camera_from_object(cam_ob, width: int, height: int, scene, warn, motion: dict | None = None) -> Camera:
    """The core camera of the evaluated camera object ``cam_ob`` for a ``width`` x ``height``
    image: perspective, orthographic or panoramic (equirectangular, fisheye equidistant or
    equisolid), with depth of field and clip start / end read as Cycles reads them. ``motion``:
    :func:`camera_motion`'s fields (motion blur)."""
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
        clip_start=float(cam.clip_start), clip_end=float(cam.clip_end), **lens, **(motion or {}),
    )


def export_camera(depsgraph, *, width: int | None = None, height: int | None = None, camera=None,
                  warn: Warnings | None = None, frame_set=None, objects_checked: bool = False) -> Camera | None:
    """The core camera alone, as :func:`export_scene` makes it: ``camera`` (an object) or the
    scene's, for ``width`` x ``height`` (default :func:`render_size`); None without a camera.
    ``warn``: collects the warnings (default: dropped). ``frame_set(frame, subframe)``: re-evaluates
    ``depsgraph`` at a sub-frame (a final render's RenderEngine.frame_set) for motion blur; None:
    no motion blur (a warning when it is on). ``objects_checked``: the objects' motion is exported
    (export/motion.py), so moving objects are not warned about here."""
    scene = depsgraph.scene
    if width is None or height is None:
        width, height = render_size(scene)
    cam_ob = camera if camera is not None else scene.camera
    if cam_ob is None:
        return None
    original = cam_ob.original if cam_ob.is_evaluated else cam_ob
    warn = warn if warn is not None else Warnings()
    motion = camera_motion(depsgraph, original, frame_set, warn, objects_checked)
    cam_eval = original.evaluated_get(depsgraph)  # (again: frame_set re-evaluates) at the frame's time
    return camera_from_object(cam_eval, width, height, scene, warn, motion)
