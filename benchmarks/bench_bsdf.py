"""core/materials/bsdf.py throughput: the one-off table build, then sample() and evaluate() per lobe.

    .venv/bin/python benchmarks/bench_bsdf.py [--hits 200000] [--k 61]

White rays (k spectral samples per hit), random roughness in [0.05, 1] and random view angles.
Prints seconds and hits per second; nothing is asserted.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from opal_diffraction.core.materials import bsdf as B


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hits", type=int, default=200_000)
    ap.add_argument("--k", type=int, default=61)
    a = ap.parse_args()
    t = time.perf_counter()
    B._tables()
    print(f"tables (first use): {time.perf_counter() - t:.2f} s")
    rng = np.random.default_rng(0)
    n, k = a.hits, a.k
    mu = rng.uniform(0.05, 1.0, n)
    wo = np.stack([np.sqrt(1 - mu * mu), np.zeros(n), mu], 1).astype(np.float32)
    ns = np.tile(np.float32([0, 0, 1]), (n, 1))
    u = rng.random((n, 3), dtype=np.float32)
    for name, lobe in (("LAMBERT", B.LAMBERT), ("CONDUCTOR", B.CONDUCTOR), ("DIELECTRIC", B.DIELECTRIC),
                       ("PLASTIC", B.PLASTIC), ("GLOSSY", B.GLOSSY)):
        p = B.SurfaceParams(np.full(n, lobe, np.int32), rng.random((n, k), dtype=np.float32),
                            np.ones((n, k), np.float32), rng.uniform(0.05, 1.0, n).astype(np.float32) ** 2,
                            np.full(n, 1.5, np.float32), np.full(n, 0.04, np.float32), np.ones((n, k), np.float32))
        t = time.perf_counter()
        wi, w, pdf, fl = B.sample(p, wo, ns, ns, u)
        ts = time.perf_counter() - t
        t = time.perf_counter()
        B.evaluate(p, wo, wi, ns, ns)
        te = time.perf_counter() - t
        print(f"{name:10s} sample {ts:.3f} s ({n / ts / 1e6:.2f} M hits/s)  evaluate {te:.3f} s ({n / te / 1e6:.2f} M hits/s)")


if __name__ == "__main__":
    main()
