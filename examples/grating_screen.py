"""The classroom grating experiment, rendered with the core (no Blender needed).

A small white lamp shines through a slit in a black card onto a transmission grating of 600
lines/mm (slit width a = D/2) just behind the slit; a white screen 1 m behind the grating shows
the zeroth order (white: every wavelength goes straight on) and on either side the first-order
spectra, violet nearest the centre, at sin(theta) = m lambda / D (docs/physics.md section 3.10).
With a = D/2 the second orders are missing (sinc^2(pi m a / D) = 0 for even m): where they would
be, the screen shows only the blue end of the third orders. The light reaches the screen only by
diffraction, so the spectra are the light pass's caustics (the grating's orders sampled per path
and wavelength); the room is dark but for a faint grey world so the card and screen show.

The eye pass is run with no diffuse bounces: the light that reaches the eye through the screen
and then the grating is the light pass's caustic path already (an eye-pass split for paths
through gratings is future work, docs/physics.md section 3.10).

    python examples/grating_screen.py [--spp 16] [--light-paths 2000000] [--out out]
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.npz import save_scene

PERIOD_NM = 1e6 / 600.0  # 600 lines/mm


def grid_quad(x0, x1, y0, y1, z, cell):
    """An axis-aligned rectangle at depth z (normal +z) cut into squares of about ``cell``, so
    the illumination map's elements are about square."""
    nx, ny = max(1, int(round((x1 - x0) / cell))), max(1, int(round((y1 - y0) / cell)))
    xs, ys = np.linspace(x0, x1, nx + 1), np.linspace(y0, y1, ny + 1)
    xx, yy = np.meshgrid(xs, ys, indexing="ij")
    v = np.stack([xx, yy, np.full_like(xx, z)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    a = (i * (ny + 1) + j).ravel()
    b, c, d = a + (ny + 1), a + (ny + 1) + 1, a + 1
    return v, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int32)


def grating_screen_scene(width=640, height=360, slit_ratio=0.5, lamp_power=1000.0) -> Scene:
    mats = Materials.from_list([
        {"name": "grating", "kind": "DIFFUSE", "color": (0, 0, 0), "grating": 1, "grating_type": "TRANSMISSION",
         "period": PERIOD_NM, "slit_width": PERIOD_NM * slit_ratio, "slit_count": 6000,
         "coherence_length": 10000.0},
        {"name": "screen", "kind": "DIFFUSE", "color": (0.8, 0.8, 0.8)},
        {"name": "card", "kind": "DIFFUSE", "color": (0.02, 0.02, 0.02)},
    ])
    s = Scene(materials=mats)
    slit_w, slit_h = 0.004, 0.04  # the slit: narrow across the grating's lines (x), long along them (y)
    s.add_mesh(*primitives.quad((0, 0, 0), (slit_w, 0, 0), (0, slit_h, 0)), material=0, tangent=(1, 0, 0))
    # the black card around the slit, 2 mm in front of the grating: four quads leaving the slit
    # open, large enough that the lamp's shadow covers the screen
    zc, hx, hy = 0.002, 0.6, 0.3
    for centre, u, v in (((0, (hy + slit_h / 2) / 2, zc), (2 * hx, 0, 0), (0, hy - slit_h / 2, 0)),
                         ((0, -(hy + slit_h / 2) / 2, zc), (2 * hx, 0, 0), (0, hy - slit_h / 2, 0)),
                         (((hx + slit_w / 2) / 2, 0, zc), (hx - slit_w / 2, 0, 0), (0, slit_h, 0)),
                         ((-(hx + slit_w / 2) / 2, 0, zc), (hx - slit_w / 2, 0, 0), (0, slit_h, 0))):
        s.add_mesh(*primitives.quad(centre, u, v), material=2)
    s.add_mesh(*grid_quad(-1.3, 1.3, -0.35, 0.35, -1.0, 0.05), material=1)  # the screen, 1 m behind
    s.lights = Lights.from_list([{"kind": "POINT", "position": (0.0, 0.0, 0.5), "power": lamp_power,
                                  "radius": 0.002}])
    s.world_color = (0.004, 0.004, 0.004)
    # the camera on the lamp's side, looking past the card's lower edge at the screen
    s.camera = Camera.look_at((0.0, -0.75, 0.25), (0.0, 0.0, -1.0), lens=24.0, width=width, height=height)
    return s


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--light-paths", type=int, default=2_000_000)
    ap.add_argument("--out", default="out")
    ap.add_argument("--exposure", type=float, default=0.0)
    ap.add_argument("--resolution", type=int, nargs=2, default=(640, 360))
    args = ap.parse_args(argv)
    from opal_diffraction.cli import main as cli_main

    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, "grating_screen")
    save_scene(grating_screen_scene(*args.resolution), path + ".npz")
    rc = cli_main(["render", path + ".npz", "-o", path + ".exr", "--spp", str(args.spp), "--light-paths",
                   str(args.light_paths), "--diffuse-bounces", "0", "--exposure", str(args.exposure)])
    os.unlink(path + ".npz")
    return rc


if __name__ == "__main__":
    sys.exit(main())
