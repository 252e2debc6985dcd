"""A round brilliant diamond in a photo studio: dispersion breaks the soft boxes of an
environment map into sparks of fire (spectral colours) on its facets.

    python examples/gem.py [--spp 64] [--out out/gem]

The gem is ``primitives.round_brilliant`` (Tolkowsky's proportions, 80 flat facets) cut from
diamond (the DIAMOND Sellmeier preset, dispersion 0.044 between B and G), on a dark grey
Principled-style floor; the world is ``environments.studio`` (three soft boxes in black), which
lights the scene by importance sampling and is seen in the facets. Writes out/gem.npz (the
scene), out/gem.exr and out/gem.png.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from opal_diffraction._scripts import load_example
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Materials, Scene
from opal_diffraction.core.scene.npz import save_scene


def build_scene(width: int = 480, height: int = 360) -> Scene:
    mats = Materials.from_list([
        {"name": "floor", "kind": "DIFFUSE", "color": (0.02, 0.02, 0.022), "specular_ior_level": 0.5,
         "roughness": 0.35},
        {"name": "diamond", "kind": "DIELECTRIC", "color": (1, 1, 1), "dispersion": "DIAMOND"},
    ])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (0.2, 0, 0), (0, 0.2, 0)), material=0)
    # a 1 cm stone (a 0.6-carat diamond is about 5.4 mm; a big one makes a clearer example),
    # table up, resting on its girdle's height above the floor
    s.add_mesh(*primitives.round_brilliant((0, 0, 0.0046), 0.01), material=1)
    s.camera = Camera.look_at((0.0, -0.028, 0.04), (0.0, 0.0, 0.004), lens=85.0, width=width, height=height)
    s.world_image = load_example("environments").studio()
    s.world_color = np.ones(3, np.float32)
    return s


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--resolution", type=int, nargs=2, default=(480, 360))
    ap.add_argument("--out", default="out/gem", help="output path without extension")
    args = ap.parse_args(argv)
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    scene = build_scene(*args.resolution)
    save_scene(scene, args.out + ".npz")
    from opal_diffraction.cli import main as cli

    return cli(["render", args.out + ".npz", "-o", args.out + ".exr", "--spp", str(args.spp),
                "--light-paths", "1000000"])


if __name__ == "__main__":
    sys.exit(main())
