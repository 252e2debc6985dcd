"""Diffraction grating examples, rendered with the core (no Blender needed).

- ``fig5``: the source paper's (Kobayashi & Kawai, docs/physics.md) Fig. 5 set-up: a
  transmission grating (period 1.6 um) between a point light at 10 degrees incidence and the
  camera; the camera sees the zeroth order (the light through the grating) and the spectra of
  the orders beside it.
- ``cd``: a compact disc (track pitch 1.6 um, circular grooves, so the grating vector is radial,
  tracks coherent over L = 1000 um) under a point light: the rainbow arcs of the first orders.
  The footprint integral (docs/physics.md section 3.7) keeps such long tracks free of speckle,
  and the per-facet radial directions are smoothed across the 256 segments (section 3.1).
- ``cd_studio``: the same disc lit only by a photo studio's environment map (four soft boxes, no
  lamps): the world seen in the grating (docs/physics.md section 3.11).
- ``cd_room``: the disc on a desk in a room: a white ceiling lit by the lamp and a monitor-like
  emissive panel behind the disc. The disc diffracts both: the panel by the grating's next event
  and its order lobe weighted by the power heuristic, the ceiling through the lobe
  (docs/physics.md section 3.13).

    python examples/gratings.py [--which fig5 cd cd_studio cd_room] [--spp 16] [--out docs]
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.npz import save_scene


def fig5_scene(width=480, height=240, slit_count=1000) -> Scene:
    mats = Materials.from_list([{
        "name": "transmission grating", "kind": "DIFFUSE", "color": (0, 0, 0), "grating": 1,
        "grating_type": "TRANSMISSION", "period": 1600.0, "slit_width": 640.0, "slit_count": slit_count,
        "coherence_length": 20.0}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (0.6, 0, 0), (0, 0.6, 0)), material=0, tangent=(1, 0, 0))
    inc = np.radians(10.0)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (np.sin(inc), 0.0, -np.cos(inc)), "power": 4 * np.pi}])
    m = np.eye(4)
    m[2, 3] = 0.05
    s.camera = Camera(matrix=m, lens=14.0, sensor_width=36.0, width=width, height=height)
    return s


def annulus(r_in, r_out, segments=256, rings=24):
    """A flat annulus in the xy plane, normal +z, with per-triangle radial tangents."""
    r = np.linspace(r_in, r_out, rings + 1)
    ph = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    rr, pp = np.meshgrid(r, ph, indexing="ij")
    v = np.stack([rr * np.cos(pp), rr * np.sin(pp), np.zeros_like(rr)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(rings), np.arange(segments), indexing="ij")
    a = (i * segments + j).ravel()
    b = (i * segments + (j + 1) % segments).ravel()
    c, d = a + segments, b + segments
    tris = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)]).astype(np.int32)
    centre = v[tris].mean(axis=1)
    tangent = centre / np.linalg.norm(centre, axis=1, keepdims=True)  # radial: across circular grooves
    return v, tris, tangent


def _cd_materials(slit_count):
    return [
        {"name": "table", "kind": "DIFFUSE", "color": (0.08, 0.08, 0.09)},
        {"name": "CD", "kind": "DIFFUSE", "color": (0.25, 0.25, 0.27), "grating": 1, "grating_type": "REFLECTION",
         "period": 1600.0, "slit_width": 800.0, "slit_count": slit_count, "coherence_length": 1000.0},
    ]


def cd_scene(width=480, height=360, slit_count=1000) -> Scene:
    s = Scene(materials=Materials.from_list(_cd_materials(slit_count)))
    s.add_mesh(*primitives.quad((0, 0, -0.002), (1.0, 0, 0), (0, 1.0, 0)), material=0)
    v, t, tangent = annulus(0.0075, 0.06)
    s.add_mesh(v, t, material=1, tangent=tangent)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (-0.25, 0.05, 0.35), "power": 3.0}])
    s.camera = Camera.look_at((0.22, -0.05, 0.2), (0.0, 0.0, 0.0), lens=50.0, width=width, height=height)
    return s


def cd_studio_scene(width=480, height=360, slit_count=1000) -> Scene:
    from opal_diffraction._scripts import load_example

    s = cd_scene(width, height, slit_count)
    s.lights = Lights.from_list([])
    s.world_image = load_example("environments").studio(512, 256)
    s.world_color = np.ones(3, np.float32)
    return s


def cd_room_scene(width=480, height=360, slit_count=1000) -> Scene:
    s = cd_scene(width, height, slit_count)
    ceiling, monitor = 2, 3
    s.materials = Materials.from_list(_cd_materials(slit_count) + [
        {"name": "ceiling", "kind": "DIFFUSE", "color": (0.8, 0.8, 0.78)},
        {"name": "monitor", "kind": "DIFFUSE", "color": (0, 0, 0), "emission": (2.7, 2.85, 3.0)},
    ])
    s.add_mesh(*primitives.quad((0, 0, 0.8), (3.0, 0, 0), (0, -3.0, 0)), material=ceiling)
    # a 40 x 25 cm screen behind the disc, facing it and the camera
    s.add_mesh(*primitives.quad((-0.35, 0.0, 0.205), (0, 0.4, 0), (0, 0, 0.25)), material=monitor)
    return s


SCENES = {"fig5": fig5_scene, "cd": cd_scene, "cd_studio": cd_studio_scene, "cd_room": cd_room_scene}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--which", nargs="+", default=["fig5", "cd"], choices=sorted(SCENES))
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--out", default="docs")
    ap.add_argument("--exposure", type=float, default=0.0)
    args = ap.parse_args(argv)
    from opal_diffraction.cli import main as cli_main

    os.makedirs(args.out, exist_ok=True)
    for name in args.which:
        scene = SCENES[name]()
        path = os.path.join(args.out, name)
        save_scene(scene, path + ".npz")
        rc = cli_main(["render", path + ".npz", "-o", path + ".exr", "--spp", str(args.spp),
                       "--exposure", str(args.exposure)])
        if rc:
            return rc
        os.unlink(path + ".npz")
        os.unlink(path + ".exr")
    return 0


if __name__ == "__main__":
    sys.exit(main())
