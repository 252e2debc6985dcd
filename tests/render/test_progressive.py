"""core/render/progressive.py: the rendered viewport's levels, and its first image before the
light pass (an eye-only image of the first level, then the levels with the caustics)."""

from __future__ import annotations

import numpy as np

from opal_diffraction._scripts import load_example
from opal_diffraction.core.render.plan import plan_render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.progressive import preview_levels, render_levels
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.scene.validation import validate


def _prism(w=64, h=40):
    scene = validate(load_example("prism").build_scene(w, h)).scene
    return prepare(scene, RenderSettings(samples=2, threads=1, light_paths=40_000))


def test_the_first_image_comes_before_the_light_pass_and_the_levels_then_use_it():
    prepared = _prism()
    assert plan_render(prepared).light_pass
    levels = preview_levels(2, start_scale=4)  # (4, 1), (2, 1), (1, 2)
    events, lights = [], []

    def on_round(level, r):
        events.append(("round", level, r.rgb.shape, float(r.rgb.sum())))

    def on_light(light):
        events.append(("light",))
        lights.append(light)

    last = render_levels(prepared, levels, None, on_round=on_round, on_light=on_light)
    assert last is not None
    # one quick eye-only image of the first level, then the light pass, then the other levels
    assert events[0][:2] == ("round", 0) and events[0][2] == (10, 16, 3)
    assert events[1] == ("light",)
    assert [e[1] for e in events[2:]] == [1, 2]  # the first level (1 sample) is not drawn twice
    assert all(np.isfinite(e[3]) and e[3] > 0 for e in events if e[0] == "round")
    # the levels after the light pass are those of a preview given that light pass: same bits
    again = render_levels(prepared, levels, lights[0])
    np.testing.assert_array_equal(last.rgb, again.rgb)
    assert lights[0].caustics is not None and lights[0].caustics.flux.any()  # the scene has caustics to wait for


def test_a_cancel_during_the_first_image_stops_before_the_light_pass():
    prepared = _prism()
    events = []
    out = render_levels(prepared, preview_levels(2, start_scale=4), None,
                        should_cancel=lambda: len(events) > 0,
                        on_round=lambda level, r: events.append(level), on_light=lambda light: events.append("light"))
    assert out is None and "light" not in events
