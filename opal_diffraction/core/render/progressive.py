"""Progressive previews: one prepared scene rendered level after level, coarse to fine.

The rendered viewport's schedule (opal_diffraction/blender/viewport.py draws the images): first
at 1/8 of the view's resolution with one sample (the first image comes quickly), then 1/4, 1/2,
and the full resolution refined round after round up to the preview samples
(``preview_levels``). Every level is a ``render_prepared`` of the same preparation seen at that
size (``prepared.with_view``: the acceleration structure and the light pass stay valid), so the
scheduler's rules hold for each (core/render/scheduler.py); the levels share one light pass and
one cancel check, polled between levels as between tiles. When the plan asks for a light pass
and none is given, the first level is drawn at once by the eye pass alone (no caustics: the
plan of the same scene with no light paths), then the light pass runs and the levels go on with
its caustics, so the first image does not wait the seconds a light pass takes. A preview has no
time limit and keeps no spectral film.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

from .film import RenderResult
from .frame import render_prepared
from .plan import plan_render
from .prepare import PreparedScene
from .scheduler import LocalExecutor, RenderControl
from ..integrators.light.light_pass import LightPassResult

__all__ = ["preview_levels", "level_size", "level_view", "render_levels"]


def preview_levels(samples: int, start_scale: int = 8) -> list[tuple[int, int]]:
    """The progressive schedule: (downscale factor, samples per pixel) per level.

    Powers of two from ``start_scale`` down to 2 with one sample each (quick, coarse images),
    then the full resolution with ``samples`` (refined round by round).
    """
    levels = []
    s = 1
    while s * 2 <= max(int(start_scale), 1):
        s *= 2
    while s > 1:
        levels.append((s, 1))
        s //= 2
    levels.append((1, max(int(samples), 1)))
    return levels


def level_size(width: int, height: int, scale: int) -> tuple[int, int]:
    """Image size of a level: the region divided by ``scale``, rounded up, at least 1x1."""
    return max(1, -(-int(width) // scale)), max(1, -(-int(height) // scale))


def level_view(prepared: PreparedScene, scale: int, samples: int) -> PreparedScene:
    """``prepared`` seen at 1/``scale`` of its camera's size with ``samples`` per pixel, in
    rounds of at most 4 (an image after each), with no time limit and no spectral EXR."""
    cam = prepared.scene.camera
    w, h = level_size(cam.width, cam.height, scale)
    return prepared.with_view(replace(cam, width=w, height=h), samples=int(samples),
                              round_samples=max(1, min(int(samples), 4)), spectral_exr="", time_limit=0.0)


def render_levels(prepared: PreparedScene, levels: list[tuple[int, int]], light: LightPassResult | None = None,
                  should_cancel: Callable[[], bool] | None = None,
                  on_round: Callable[[int, RenderResult], None] | None = None,
                  on_light: Callable[[LightPassResult], None] | None = None) -> RenderResult | None:
    """Render ``prepared`` at each (scale, samples) of ``levels`` in turn.

    ``light``: its finished light pass, if one is at hand (else it runs here first when the plan
    asks, and ``on_light(result)`` receives it for reuse). ``on_round(level index, image)``: after
    every round of every level. Returns the last level's result, or None when cancelled before
    it finished (``should_cancel`` said so) or when there is no level."""
    control = RenderControl(should_cancel)
    plan = plan_render(prepared)
    first = 0  # the first level still to render
    if light is None and plan.light_pass:
        if levels:  # a first image at once, from the eye pass alone (no light paths: no caustics)
            scale, _ = levels[0]
            eye_only = replace(prepared, settings=replace(prepared.settings, light_paths=0))
            quick = render_prepared(level_view(eye_only, scale, 1), None, should_cancel=control.cancelled,
                                    on_round=None if on_round is None else (lambda r: on_round(0, r)))
            if control.cancelled() or quick is None:
                return None
            first = 1 if levels[0][1] == 1 and len(levels) > 1 else 0  # that level is drawn unless it refines
        with LocalExecutor() as executor:
            executor.start(prepared, None, False, control)
            light = executor.light_pass(prepared, plan, control, None)
        if light.cancelled:
            return None
        if on_light is not None:
            on_light(light)
    result = None
    for li, (scale, spp) in enumerate(levels):
        if li < first:
            continue
        if control.cancelled():
            return None
        each_round = None if on_round is None else (lambda r, li=li: on_round(li, r))
        result = render_prepared(level_view(prepared, scale, spp), light, should_cancel=control.cancelled,
                                 on_round=each_round)
    return None if control.cancelled() else result
