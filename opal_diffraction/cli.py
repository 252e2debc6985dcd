"""Command line: render an exported scene file without Blender.

    python -m opal_diffraction render SCENE.npz -o OUT.exr [--spp N] [--seed S] [--wavelength-step NM] ...

Writes a float RGB EXR, an 8-bit PNG preview next to it, and optionally a spectral EXR. Same
seed, same image.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

__all__ = ["main"]


class _ProgressBar:
    """A one-line progress bar on stderr (redrawn at most ten times a second)."""

    def __init__(self, stream=sys.stderr, width: int = 30):
        self.stream, self.width, self.last, self.t0 = stream, width, 0.0, time.perf_counter()

    def __call__(self, fraction: float, message: str) -> None:
        now = time.perf_counter()
        if fraction < 1.0 and now - self.last < 0.1:
            return
        self.last = now
        filled = int(round(self.width * fraction))
        bar = "#" * filled + "-" * (self.width - filled)
        self.stream.write(f"\r[{bar}] {100 * fraction:5.1f}% {now - self.t0:6.1f}s {message[:60]:<60}")
        if fraction >= 1.0:
            self.stream.write("\n")
        self.stream.flush()


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m opal_diffraction", description="opal_diffraction spectral renderer")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render a scene file (.npz) to an EXR and a PNG preview")
    r.add_argument("scene", help="scene file written by Scene.save or Blender's export operator")
    r.add_argument("-o", "--output", required=True, help="output RGB EXR path (a .png preview is written beside it)")
    r.add_argument("--spp", type=int, default=16, help="eye samples per pixel (default 16)")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--wavelength-min", type=float, default=400.0)
    r.add_argument("--wavelength-max", type=float, default=700.0)
    r.add_argument("--wavelength-step", type=float, default=5.0)
    r.add_argument("--max-bounces", type=int, default=8)
    r.add_argument("--light-paths", type=int, default=1_000_000, help="light-pass paths for caustics (0: off)")
    r.add_argument("--dispersion-sampling", choices=["SPLIT", "SAMPLE"], default="SAMPLE")
    r.add_argument("--resolution", type=int, nargs=2, metavar=("W", "H"), help="override the camera's resolution")
    r.add_argument("--spectral-exr", default="", help="also write a spectral EXR (JCGT 2021 layout) here")
    r.add_argument("--time-limit", type=float, default=0.0, help="seconds; 0: none")
    r.add_argument("--threads", type=int, default=0, help="0: all cores")
    r.add_argument("--backend", choices=["auto", "embree", "numpy"], default="auto")
    r.add_argument("--scheduler", default="", help="render on a Dask cluster, the same image: tcp://HOST:PORT of "
                   "a scheduler, or local:N for N worker processes here (needs requirements-dask.txt)")
    r.add_argument("--exposure", type=float, default=0.0, help="stops applied to the PNG preview only")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    return p


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    from .core.output import write_png, write_rgb_exr, write_spectral_exr
    from .core.render import render
    from .core.scene import Scene, SceneError
    from .core.settings import RenderSettings

    try:
        scene = Scene.load(args.scene)
        if args.resolution:
            if scene.camera is None:
                raise SceneError("the scene has no camera")
            scene.camera.width, scene.camera.height = args.resolution
        settings = RenderSettings(
            samples=args.spp, seed=args.seed, wavelength_min=args.wavelength_min,
            wavelength_max=args.wavelength_max, wavelength_step=args.wavelength_step,
            max_bounces=args.max_bounces, dispersion_sampling=args.dispersion_sampling, light_paths=args.light_paths,
            spectral_exr=args.spectral_exr, time_limit=args.time_limit, threads=args.threads,
            backend=args.backend,
        )
        bar = None if args.quiet else _ProgressBar()
        if args.scheduler:
            from .core.distributed import connect

            with connect(args.scheduler) as client:
                result = render(scene, settings, progress=bar, client=client)
        else:
            result = render(scene, settings, progress=bar)
    except SceneError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("\ninterrupted", file=sys.stderr)
        return 130
    for w in result.warnings:
        print(f"warning: {w}", file=sys.stderr)
    write_rgb_exr(args.output, result.rgb)
    png = os.path.splitext(args.output)[0] + ".png"
    write_png(png, result.rgb, args.exposure)
    if args.spectral_exr:
        write_spectral_exr(args.spectral_exr, result.spectral, result.wavelengths, result.rgb)
    s = result.stats
    if not args.quiet:
        print(f"{result.plan.summary()}", file=sys.stderr)
        print(f"wrote {args.output} and {png}: {s['render_s']:.2f} s, {s['rays'] / 1e6:.2f} M rays "
              f"({s['mrays_per_s']:.2f} Mrays/s, {s['backend']})", file=sys.stderr)
    return 0
