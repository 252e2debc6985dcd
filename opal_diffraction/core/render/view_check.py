"""A check of the camera before a render: does it see any of the scene's objects?

Why: a camera that sees nothing gives a black image (or only the world) without a word, and the
causes are settings an artist mistypes or carries over: a shift of 10 frames, a 1 mm lens whose
view squeezes the scene into a few pixels, an orthographic scale of 1e6 m. So before the passes
run, a grid of at most GRID x GRID camera rays through the frame (pixel centres on small images)
is cast against the scene; when none hits a surface the render says so, naming the settings to
check. An object no ray of the grid hits covers under about 1/GRID^2 of the frame.
"""

from __future__ import annotations

import numpy as np

from ..sampling.camera import camera_rays

__all__ = ["GRID", "camera_sees_nothing"]

#: rays per side of the grid cast through the frame (at most; fewer on smaller images)
GRID = 128


def camera_sees_nothing(prepared) -> str | None:
    """A warning when no camera ray of the grid hits a surface of ``prepared``'s scene, else None."""
    cam = prepared.scene.camera
    if cam is None or len(prepared.scene.triangles) == 0:
        return None
    nx, ny = min(int(cam.width), GRID), min(int(cam.height), GRID)
    x = (np.arange(nx) + 0.5) * (cam.width / nx)
    y = (np.arange(ny) + 0.5) * (cam.height / ny)
    xx, yy = np.meshgrid(x, y)
    o, d, tmax, valid = camera_rays(cam, xx.ravel(), yy.ravel())  # chief rays, within the clip range
    ok = np.isfinite(o).all(axis=1) & np.isfinite(d).all(axis=1)
    if valid is not None:
        ok &= valid
    if ok.any() and np.isfinite(prepared.accel.intersect(o[ok], d[ok], None if tmax is None else tmax[ok]).t).any():
        return None
    what = "only the world" if _world_lit(prepared) else "a black image"
    if cam.kind == "PANO":
        settings = f"panorama {cam.panorama_type.lower()}, clip {cam.clip_start:g} - {cam.clip_end:g} m"
    elif cam.kind == "ORTHO":
        settings = f"orthographic scale {cam.ortho_scale:g} m, shift {cam.shift_x:g} / {cam.shift_y:g}"
    else:
        settings = f"lens {cam.lens:g} mm, shift {cam.shift_x:g} / {cam.shift_y:g}"
    return (f"the camera sees none of the scene's objects ({what}): check its position, direction and "
            f"settings ({settings})")


def _world_lit(prepared) -> bool:
    return prepared.environment is not None or bool(np.any(np.asarray(prepared.scene.world_color) > 0))
