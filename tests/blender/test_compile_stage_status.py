"""F12's status during the compile stage (core/render/frame.py ``compile_stage``): the process's
first render on the kernels shows "compiling kernels" right after the export, before the light
pass or any tile; the next render goes straight to its passes. A fresh warm-up state stands for
a new Blender session."""

from __future__ import annotations

import bpy
import pytest

import blender_scenes as bs
from opal_diffraction.core.util import jit

pytestmark = pytest.mark.skipif(not jit.AVAILABLE, reason=f"no JIT: {jit.UNAVAILABLE_REASON}")


def test_first_f12_shows_the_compile_stage_and_the_second_does_not(monkeypatch, last_render):
    monkeypatch.setattr(jit, "_warm", {"started": False, "finished": False})
    bs.empty_scene(16, 12)
    bs.plane(half=4.0, mat=bs.material("floor", "DIFFUSE", (0.5, 0.5, 0.5)))
    bs.light("POINT", (1.0, -2.0, 4.0), 800.0)
    bs.camera(location=(0, 0, 6))
    bpy.context.scene.opal.samples = 1
    bpy.ops.render.render()
    log = last_render["stats_log"]
    assert log[0] == "Exporting scene" and log[1].startswith(jit.COMPILE_STAGE + " | "), log[:3]
    assert last_render["status"] == "FINISHED" and "compile_s" in last_render["stats"]
    bpy.ops.render.render()
    assert not any(s.startswith(jit.COMPILE_STAGE) for s in last_render["stats_log"])
    assert "compile_s" not in last_render["stats"]
