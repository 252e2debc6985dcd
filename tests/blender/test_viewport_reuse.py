"""The rendered viewport keeps what it built: a camera move re-renders only the eye pass, an
update that changes nothing restarts nothing, and an edit re-reads only the mesh it touched."""

from __future__ import annotations

import math
import types

import bpy
import numpy as np

import blender_scenes as bs
from opal_diffraction.blender import viewport
from opal_diffraction.core.render import scheduler
from opal_diffraction.blender.engine import OpalRenderEngine


class _Engine:
    _viewport = None
    _viewport_session = OpalRenderEngine._viewport_session

    def update_stats(self, *a):
        pass


def _context(cam, w=48, h=32, dx=0.0):
    from mathutils import Matrix

    dg = bpy.context.evaluated_depsgraph_get()
    m = Matrix.Translation((dx, 0.0, 0.0)) @ cam.matrix_world
    rv3d = types.SimpleNamespace(view_matrix=m.inverted(), window_matrix=cam.calc_matrix_camera(dg, x=w, y=h),
                                 is_perspective=True)
    return types.SimpleNamespace(region=types.SimpleNamespace(width=w, height=h), region_data=rv3d)


def _glass_scene():
    bs.empty_scene(48, 32)
    sc = bpy.context.scene
    sc.opal.preview_samples, sc.opal.preview_start_scale = 1, 2
    sc.opal.wavelength_step, sc.opal.light_paths = 20.0, 20_000
    cam = bs.camera(location=(0, -6, 4), rotation=(math.radians(55), 0, 0))
    bs.light("POINT", (0.5, -0.5, 4.0), 800.0)
    floor = bs.plane("floor", half=4.0, z=0.0, mat=bs.material("grey"))
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 1.0))
    bpy.context.active_object.data.materials.append(bs.material("glass", "GLASS", (1, 1, 1), IOR=1.5, Roughness=0.0))
    return cam, floor


def test_camera_moves_reuse_the_preparation_and_the_light_pass(monkeypatch):
    monkeypatch.setattr(viewport.ViewportSession, "_draw_frame", lambda *a, **k: None)
    cam, floor = _glass_scene()
    eng = _Engine()
    OpalRenderEngine.view_update(eng, _context(cam), bpy.context.evaluated_depsgraph_get())
    session = eng._viewport
    assert session.renderer.wait(120.0) and session.renderer.done and not session.renderer.error
    prepared, light = session.prepared, session.light
    assert light is not None and light.key == prepared.key  # the light pass ran once, and was kept
    reads = session.mesh_cache.reads
    light_runs = []
    monkeypatch.setattr(scheduler, "run_light_pass", lambda *a, **k: light_runs.append(1))

    # the view moves: a new preview with the same preparation and light pass, and no re-export
    restarts = session.restarts
    OpalRenderEngine.view_draw(eng, _context(cam, dx=0.3), bpy.context.evaluated_depsgraph_get())
    assert session.restarts == restarts + 1
    assert session.renderer.wait(120.0) and session.renderer.done and not session.renderer.error
    assert session.prepared is prepared and session.light is light and not light_runs
    assert session.mesh_cache.reads == reads

    # an update with nothing changed (a selection, say): re-exported from the cache, no restart
    OpalRenderEngine.view_update(eng, _context(cam, dx=0.3), bpy.context.evaluated_depsgraph_get())
    assert session.restarts == restarts + 1 and session.mesh_cache.reads == reads
    assert session.prepared.key == prepared.key and session.prepared.accel is prepared.accel
    session.free()
    assert session.renderer.wait(30.0)


def test_an_edit_rereads_only_its_mesh_and_reruns_the_light_pass(monkeypatch):
    monkeypatch.setattr(viewport.ViewportSession, "_draw_frame", lambda *a, **k: None)
    cam, floor = _glass_scene()
    eng = _Engine()
    OpalRenderEngine.view_update(eng, _context(cam), bpy.context.evaluated_depsgraph_get())
    session = eng._viewport
    assert session.renderer.wait(120.0) and session.light is not None
    old_key, old_accel = session.prepared.key, session.prepared.accel
    reads = session.mesh_cache.reads
    assert reads == 2

    # Blender calls view_update while it evaluates the edit, where depsgraph.updates is readable
    def handler(scene, depsgraph):
        OpalRenderEngine.view_update(eng, _context(cam), depsgraph)

    floor.data.vertices[0].co.z += 0.25
    floor.data.update()
    bpy.app.handlers.depsgraph_update_post.append(handler)
    try:
        bpy.context.evaluated_depsgraph_get()
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(handler)
    assert session.mesh_cache.reads == reads + 1  # the floor only, not the cube
    assert session.prepared.key != old_key and session.prepared.accel is not old_accel
    z = np.asarray(session.prepared.scene.vertices)[:, 2]
    assert np.isclose(z, 0.25, atol=1e-6).sum() == 1  # the moved floor vertex (the rest: 0, 0.5, 1.5)
    assert session.renderer.wait(120.0) and session.renderer.done
    assert session.light is not None and session.light.key == session.prepared.key  # rerun for the new key
    session.free()
    assert session.renderer.wait(30.0)
