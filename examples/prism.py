"""The first example: a dispersive glass prism on a floor, in front of a striped wall, under a
point light and a daylight sky (an environment map with a sun). Looking through the prism, the
stripes' edges split into rainbow fringes (dispersion in the eye pass); the lamp and the sun
throw spectral caustics through it onto the floor (the light pass); the sky fills the shadows.

    python examples/prism.py [--spp 32] [--out out/prism]

Writes out/prism.npz (the scene, re-renderable with ``python -m opal_diffraction render``),
out/prism.exr (linear RGB) and out/prism.png (preview).
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from opal_diffraction._scripts import load_example
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.npz import save_scene


#: The sky's strength (a multiplier of examples/environments.py's sky).
SKY_STRENGTH = 0.025


def build_scene(width=640, height=400) -> Scene:
    mats = Materials.from_list([
        {"name": "floor", "kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
        {"name": "white stripe", "kind": "DIFFUSE", "color": (0.9, 0.9, 0.9)},
        {"name": "black stripe", "kind": "DIFFUSE", "color": (0.02, 0.02, 0.02)},
        # a dense flint (n_d 1.72, V_d 29): strong dispersion, via the artist's IOR + Abbe number
        {"name": "flint glass", "kind": "DIELECTRIC", "color": (1, 1, 1), "ior": 1.72, "dispersion": "ABBE", "abbe": 29.0},
    ])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (12, 0, 0), (0, 12, 0)), material=0)
    # a wall of horizontal stripes 3 m behind the prism: the prism bends light vertically, so
    # through it the stripes' edges fan out into spectra
    n_stripes, height_m = 16, 8.0
    for i in range(n_stripes):
        z = (i + 0.5) * height_m / n_stripes
        s.add_mesh(*primitives.quad((0.0, 3.0, z), (10.0, 0, 0), (0, 0, height_m / n_stripes)), material=1 + i % 2)
    # a 60-degree prism lying along X, apex down: it bends the view up onto the striped wall
    s.add_mesh(*primitives.prism((0, 0, 0.75), side=1.2, length=2.4, axis="X", rotation_deg=180.0), material=3)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (2.0, -3.0, 5.0), "power": 1500.0}])
    s.camera = Camera.look_at((0.0, -5.5, 3.6), (0.0, 0.5, 1.1), lens=50.0, width=width, height=height)
    # a daylight sky (examples/environments.py) at a tenth of its strength, with a low sun in
    # front to the right: it lights the scene beside the lamp and throws its own prism caustic
    s.world_image = load_example("environments").sky(256, 128)
    s.world_color = np.full(3, SKY_STRENGTH, np.float32)
    return s


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--out", default="out/prism", help="output path without extension")
    ap.add_argument("--resolution", type=int, nargs=2, default=(640, 400))
    args = ap.parse_args(argv)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    scene = build_scene(*args.resolution)
    save_scene(scene, args.out + ".npz")
    from opal_diffraction.cli import main as cli_main

    return cli_main(["render", args.out + ".npz", "-o", args.out + ".exr", "--spp", str(args.spp)])


if __name__ == "__main__":
    sys.exit(main())
