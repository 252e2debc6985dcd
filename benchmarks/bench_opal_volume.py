"""Opal volume domains: generation and lookup times for the presets' layouts (not a test).

    .venv/bin/python benchmarks/bench_opal_volume.py [--points 262144] [--repeat 3]

On the example's cabochon (18 x 13 x 6 mm, 55 874 triangles): the seconds to generate each
preset's domains (seeds by rejection in the volume), to build the lookup's k-d trees, and to look
up one batch of points on the surface (``VolumeDomains.lookup``, what the eye pass calls per
batch of hits), with the fraction of points that needed a widened search (the additive weights).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from opal_diffraction.core.opal import cabochon
from opal_diffraction.core.opal.domains import sample_surface_points
from opal_diffraction.core.opal.volume import VolumeDomains, generate_volume_domains

LAYOUTS = {"harlequin": (25, 0.3), "black": (300, 0.5), "pinfire": (4000, 0.8)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=262144)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    v, t = cabochon(0.018, 0.013, 0.006, 96)
    pts, tri = sample_surface_points(v, t, args.points, np.random.default_rng(0))
    print(f"cabochon: {len(t)} triangles; {args.points} surface points per lookup")
    for name, (count, spread) in LAYOUTS.items():
        t0 = time.perf_counter()
        seeds, weight, axis, diameter = generate_volume_domains(v, t, count, 7, spread, "LAYERED", (0, 0, 1), 25.0)
        gen = time.perf_counter() - t0
        vd = VolumeDomains(seeds, weight, axis, diameter, np.zeros(count, np.int32), np.zeros(len(t), np.int32))
        t0 = time.perf_counter()
        vd.lookup(pts[:1], tri[:1])  # builds the tree
        build = time.perf_counter() - t0
        times = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            vd.lookup(pts, tri)
            times.append(time.perf_counter() - t0)
        from scipy.spatial import cKDTree

        d, j = cKDTree(seeds).query(pts, k=min(4, count))
        d, j = d.reshape(len(pts), -1), j.reshape(len(pts), -1)
        val = d - weight[j]
        widened = float(np.mean(d[:, -1] - weight.max() < val.min(axis=1))) if count > 4 else 0.0
        print(f"{name:10s} {count:5d} domains: generate {gen:.3f} s, tree {build * 1e3:.1f} ms, lookup "
              f"{min(times):.3f} s ({min(times) / len(pts) * 1e9:.0f} ns/point), widened {widened:.1%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
