"""Benchmark (not a test): what gratings cost in the light pass (docs/physics.md section 3.10).

- ``sample_orders`` throughput: samples per second for a 600 lines/mm grating in air (a handful
  of propagating orders) and for a 100 lines/mm one (about 40 orders: the (path x order) table
  is wider).
- The classroom scene (examples/grating_screen.py): the light pass's paths per second, the rays
  it casts per path and the caustic deposits (most paths end on the card: the slit is a small
  part of the disk the grating's bounding sphere casts, and half the sized lamp's surface
  points face away).

    python benchmarks/bench_grating_scatter.py [--paths 1000000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from opal_diffraction._scripts import load_example
from opal_diffraction.core.gratings.order_sampling import sample_orders
from opal_diffraction.core.integrators.light.light_pass import run_light_pass
from opal_diffraction.core.render.plan import plan_render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene.settings import RenderSettings


def sampler_rate(period_nm: float, n: int = 1_000_000) -> float:
    rng = np.random.default_rng(0)
    w = np.tile([0.3, 0.0, np.sqrt(1 - 0.09)], (n, 1))
    nrm, t, s = (np.tile(v, (n, 1)) for v in ([0, 0, 1.0], [1.0, 0, 0], [0, 1.0, 0]))
    lam = rng.uniform(400, 700, n)
    t0 = time.perf_counter()
    sample_orders(w, nrm, t, s, period_nm, period_nm / 2, lam, True, rng, length=np.full(n, 1e7))
    return n / (time.perf_counter() - t0)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", type=int, default=1_000_000)
    args = ap.parse_args(argv)
    for lines in (600, 100):
        print(f"sample_orders, {lines} lines/mm: {sampler_rate(1e6 / lines) / 1e6:.2f} M samples/s")
    ex = load_example("grating_screen")
    scene = ex.grating_screen_scene()
    p = prepare(scene, RenderSettings(light_paths=args.paths))
    t0 = time.perf_counter()
    res = run_light_pass(p, plan=plan_render(p))
    dt = time.perf_counter() - t0
    st = res.stats
    print(f"classroom light pass: {st['light_paths'] / 1e6:.2f} M paths in {dt:.2f} s "
          f"({st['light_paths'] / dt / 1e6:.2f} M paths/s), {st['light_rays'] / max(st['light_paths'], 1):.2f} "
          f"rays/path, {st['light_deposits'] / 1e6:.2f} M caustic deposits")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
