"""Benchmark (not a test): time against error of the opal example (examples/opal.py, the black
opal with its Bragg domains), the [opal] issue's "time-vs-error line".

Renders the example's scene through Blender (``bpy.ops.render.render``, 2 threads) at a
reference sample count with one seed and at 4, 8, 16, 32 samples with another, and prints each
render's wall time and its 8 x 8-box-filtered relative RMSE against the reference (the error of
tools/cycles_parity.py) on the display-referred image (linear values clipped to [0, 1], as the
PNG shows them): the lamp's reflection in the polished dome is a few pixels at up to ~800x the
image mean, so the unclipped error measures only how many samples land on that highlight. The
reference's own noise is measured from its two halves and printed, so the last rows' errors
can be read against it.

    .venv/bin/python benchmarks/bench_opal_example.py [--resolution 256 256] [--ref-spp 128]
"""

from __future__ import annotations

import argparse
import os
import tempfile

import numpy as np

from opal_diffraction._scripts import load_example, load_script


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, nargs=2, default=(256, 256))
    ap.add_argument("--ref-spp", type=int, default=128)
    ap.add_argument("--spp", type=int, nargs="+", default=[4, 8, 16, 32])
    args = ap.parse_args(argv)

    import opal_diffraction

    cp = load_script("tools/cycles_parity.py")
    example = load_example("opal")
    opal_diffraction.register()
    work = tempfile.mkdtemp()
    try:
        example.build_scene(*args.resolution, spp=args.spp[0])
        half = max(1, args.ref_spp // 2)
        a, ta = cp.render_once(cp.ENGINE, half, 101, os.path.join(work, "ref_a.exr"))
        b, tb = cp.render_once(cp.ENGINE, half, 102, os.path.join(work, "ref_b.exr"))
        a, b = np.clip(a, 0, 1), np.clip(b, 0, 1)  # display-referred (see the docstring)
        ref = (a + b) / 2
        m = cp.luminance(ref).mean()
        ref_noise = float(np.sqrt(np.mean(cp.box_filter((a - b) / 2) ** 2)) / m)
        print(f"opal example {args.resolution[0]}x{args.resolution[1]}: reference {2 * half} spp in "
              f"{ta + tb:.1f} s, its own filtered noise {ref_noise:.4f}")
        print("| spp | s | filtered rel. RMSE vs reference |\n|---|---|---|")
        for spp in args.spp:
            img, t = cp.render_once(cp.ENGINE, spp, 3, os.path.join(work, "ours.exr"))
            print(f"| {spp} | {t:.1f} | {cp.filtered_rel_rmse(np.clip(img, 0, 1), ref):.4f} |", flush=True)
    finally:
        opal_diffraction.unregister()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
