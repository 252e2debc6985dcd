"""The Camera Caustics property (scene.opal.caustic_splat) reaches the core's
RenderSettings.caustic_splat (docs/physics.md section 4.9), on by default as in the core."""

from __future__ import annotations

import bpy

from opal_diffraction.blender.settings import render_settings
from opal_diffraction.core.scene.settings import RenderSettings


def test_camera_caustics_reaches_the_core_settings():
    sc = bpy.context.scene
    o = sc.opal
    assert o.bl_rna.properties["caustic_splat"].default is RenderSettings().caustic_splat is True
    o.caustic_splat = True
    assert render_settings(o, sc).caustic_splat is True
    o.caustic_splat = False
    assert render_settings(o, sc).caustic_splat is False
    o.caustic_splat = True
