"""Peak RSS round by round: does a render's memory grow with its samples? (issue 14, Memory)

    .venv/bin/python benchmarks/bench_memory_rounds.py [--scene prism] [--width 320 --height 180]
        [--spp 64] [--spectral]

Renders the example in this process (``core.render.render``, the default 8 samples per round,
all threads, automatic light paths) and reads, at every progress report, the process's peak
RSS so far (``getrusage(RUSAGE_SELF).ru_maxrss``) and its current RSS (/proc/self/statm). The
film and the light-pass maps are allocated before the first round, so a flat peak from the end
of the first round to the last says the samples add no memory; a step per round would be a
leak. ``--spectral`` keeps the spectral film (as a spectral EXR does). Prints one row per
round (the first report at or after each round's end).
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time



def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="prism")
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=180)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--spectral", action="store_true")
    args = ap.parse_args(argv)

    from opal_diffraction._scripts import load_example
    from opal_diffraction.core.render.frame import render
    from opal_diffraction.core.scene.settings import RenderSettings

    scene = load_example(args.scene).build_scene(args.width, args.height)
    settings = RenderSettings(samples=args.spp)
    rounds = -(-args.spp // settings.round_samples)
    rows = []
    t0 = time.perf_counter()

    def progress(fraction, message):
        rows.append((time.perf_counter() - t0, time.process_time(), float(fraction), str(message),
                     resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**10, rss_mb()))

    print(f"{args.scene} {args.width}x{args.height}, {args.spp} spp ({rounds} rounds of {settings.round_samples}), "
          f"spectral film {args.spectral}; before the render: peak RSS "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**10:.0f} MB", flush=True)
    res = render(scene, settings, progress=progress, spectral_film=args.spectral)
    end = (time.perf_counter() - t0, time.process_time(), 1.0, "done",
           resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**10, rss_mb())
    rows.append(end)
    print(f"samples taken {res.samples}; {len(rows)} progress reports\n")
    print("| report | wall s | CPU s | progress | message | peak RSS MB | RSS MB |\n|---|---|---|---|---|---|---|")
    shown = set()
    for i, (w, c, f, m, peak, cur) in enumerate(rows):
        # the first report in each 1/(2 rounds) of the progress, and the last
        key = int(f * 2 * rounds)
        if key in shown and i != len(rows) - 1:
            continue
        shown.add(key)
        print(f"| {i} | {w:.1f} | {c:.1f} | {f:.3f} | {m[:40]} | {peak:.0f} | {cur:.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
