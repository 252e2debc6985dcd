"""Benchmark (not a test): light samples per second, per kind of light, and for emissive meshes.

What the path tracer's next-event estimation pays per shading point: ``lights.sample_light``
for delta and sized lights (docs/physics.md section 7.5), ``lights.light_pdf`` and
``lights.intersect_lights`` for MIS, and ``MeshLights.sample`` over a mesh of many emitting
triangles (section 7.6: one searchsorted over the cumulative distribution, no loop per triangle).

    python benchmarks/bench_lights.py [--points 1000000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.lights.sources import intersect_lights, light_pdf, prepare_lights, sample_light
from opal_diffraction.core.lights.mesh_lights import MeshLights
from opal_diffraction.core.scene.model import Lights
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.spectral.spectrum import SpectralConverter

ROWS = {
    "point (delta)": {"kind": "POINT", "position": (0, 0, 3)},
    "sphere": {"kind": "POINT", "position": (0, 0, 3), "radius": 0.3},
    "soft-falloff disk": {"kind": "POINT", "position": (0, 0, 3), "radius": 0.3, "soft_falloff": 1},
    "spot sphere": {"kind": "SPOT", "position": (0, 0, 3), "radius": 0.3},
    "sun (delta)": {"kind": "SUN"},
    "sun 10 deg": {"kind": "SUN", "angle": 0.1745},
    "area rectangle": {"kind": "AREA_RECT", "position": (0, 0, 3)},
}


def rate(fn, n) -> float:
    fn()  # warm up
    t0 = time.perf_counter()
    fn()
    return n / (time.perf_counter() - t0) / 1e6


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=1_000_000)
    n = ap.parse_args().points
    conv = SpectralConverter(RenderSettings().grid())
    rng = np.random.default_rng(0)
    p = (rng.random((n, 3)) * 4 - 2).astype(np.float32)
    p[:, 2] = 0
    print(f"{'light':<20} {'sample M/s':>11} {'pdf M/s':>9} {'intersect M/s':>14}")
    for name, row in ROWS.items():
        pl = prepare_lights(Lights.from_list([row]), conv)
        wi, _, _ = sample_light(pl, 0, p, rng)
        s = rate(lambda: sample_light(pl, 0, p, rng), n)
        q = rate(lambda: light_pdf(pl, 0, p, wi), n)
        x = rate(lambda: intersect_lights(pl, p, wi, np.full(n, np.inf, np.float32)), n)
        print(f"{name:<20} {s:>11.2f} {q:>9.2f} {x:>14.2f}")
    v, t = primitives.icosphere((0, 0, 3), 1.0, 6)  # 81920 emitting triangles
    ml = MeshLights.build(v, t, np.zeros(len(t), np.int32), np.ones((1, conv.grid.n)),
                          luminance_weights=conv.cmf_weights[:, 1])
    t0 = time.perf_counter()
    MeshLights.build(v, t, np.zeros(len(t), np.int32), np.ones((1, conv.grid.n)))
    build_s = time.perf_counter() - t0
    print(f"MeshLights over {len(ml)} triangles: build {build_s * 1e3:.1f} ms, "
          f"sample {rate(lambda: ml.sample(p, rng), n):.2f} M/s")


if __name__ == "__main__":
    main()
