"""F12 and headless renders on a Dask cluster: ``scene.opal.scheduler`` set, the engine renders
on its workers and Blender receives the image and passes a local render makes, bit for bit
(tests/render/test_distributed.py checks the core's side in depth)."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

import blender_scenes as bs


def _glass_scene():
    sc = bs.empty_scene(24, 16)
    bs.plane(half=4.0, mat=bs.material("floor", "DIFFUSE", (0.5, 0.5, 0.5)))
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 0.8))
    bpy.context.active_object.data.materials.append(bs.material("glass", "GLASS", (1, 1, 1), IOR=1.5))
    bs.light("POINT", (0.5, -1.0, 4.0), 1000.0)
    cam = bs.camera(location=(0, -6, 3))
    cam.rotation_euler = (math.radians(65), 0, 0)
    sc.opal.samples, sc.opal.light_paths, sc.opal.tile_size = 2, 40_000, 8
    return sc


@pytest.mark.slow
def test_f12_on_local_workers_is_the_local_render(last_render):
    pytest.importorskip("distributed")
    sc = _glass_scene()
    bpy.ops.render.render()
    assert last_render["status"] == "FINISHED"
    local = {"rgb": last_render["rgb"], **last_render["passes"]}
    assert "scheduler" not in last_render["stats"]
    sc.opal.scheduler = "local:2"
    bpy.ops.render.render()
    assert last_render["status"] == "FINISHED", last_render["message"]
    assert last_render["stats"]["workers"] == 2 and last_render["stats"]["light_tasks"] >= 1
    dist = {"rgb": last_render["rgb"], **last_render["passes"]}
    assert local.keys() == dist.keys()
    for k in local:
        np.testing.assert_array_equal(local[k], dist[k], err_msg=k)


def test_a_bad_scheduler_is_a_clear_error(capfd, last_render):
    pytest.importorskip("distributed")
    sc = _glass_scene()
    sc.opal.scheduler = "local:zero"
    with pytest.raises(RuntimeError):
        bpy.ops.render.render()
    assert last_render["status"] == "ERROR" and "local:N" in last_render["message"]
    assert "Traceback" not in capfd.readouterr().err
