"""Command line: render an exported scene file without Blender.

    python -m opal_diffraction render SCENE.npz -o OUT.exr [--spp N] [--seed S] [--wavelength-step NM] ...

Writes a float RGB EXR, an 8-bit PNG preview next to it (or at ``--preview``), and optionally a
spectral EXR. Same seed, same image. ``--adaptive-threshold T`` stops sampling pixels whose noise
is below T (Cycles' Noise Threshold, core/render/adaptive.py); ``--denoise`` runs Open Image Denoise
(the optional pyoidn wheel, core/render/denoise.py) on the RGB image, guided by the albedo and normal
feature passes, and writes the noisy image beside it as OUT.noisy.exr.

Everything the user gives is checked before the render starts: the arguments, the scene file
(a missing, empty, corrupted or malformed file, wrong arrays), the settings, the output paths
(extensions, distinct files, writable folders) and the memory the image needs. Any problem is
one line ``error: ...`` on stderr and exit status 2. Ctrl-C stops the render at the next tile
(exit 130; ``--save-partial`` writes the image rendered so far); a second Ctrl-C, or SIGTERM
(exit 143), stops at once. Images are written to temporary files that are renamed when complete
and removed on every way out, so an interrupted run never leaves a ``.tmp_*`` file or a
truncated image behind. Exit 1 is a failure of the renderer itself (``OPAL_DEBUG=1`` shows the
traceback, and the NumPy / colour-science warnings that are otherwise silenced).
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import tempfile
import threading
import time
import warnings
from contextlib import nullcontext

__all__ = ["main", "CliError"]

EXIT_OK, EXIT_FAILURE, EXIT_USAGE, EXIT_INTERRUPTED, EXIT_TERMINATED = 0, 1, 2, 130, 143


class CliError(Exception):
    """Bad input or arguments: printed as ``error: ...``, exit status 2."""


class _Stop(BaseException):
    """Raised by the signal handlers to stop at once (BaseException: no ``except Exception``
    swallows it, and the output writer removes its temporary file)."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


class _UsageExit(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (``error: ...``, exit 2) instead of usage + message."""

    def error(self, message):
        raise _UsageExit(message)


def _light_paths(text: str) -> int | None:
    """--light-paths: a whole number >= 0, or 'auto' (None: sized to the image)."""
    if text.strip().lower() == "auto":
        return None
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number or 'auto', got {text!r}") from None


class _ProgressBar:
    """A one-line progress bar on stderr (redrawn at most ten times a second)."""

    def __init__(self, stream=None, width: int = 30):
        self.stream = stream if stream is not None else sys.stderr
        self.width, self.last, self.t0, self.drawn = width, 0.0, time.perf_counter(), False

    def __call__(self, fraction: float, message: str) -> None:
        now = time.perf_counter()
        if fraction < 1.0 and now - self.last < 0.1:
            return
        self.last = now
        fraction = min(max(float(fraction), 0.0), 1.0)
        filled = int(round(self.width * fraction))
        bar = "#" * filled + "-" * (self.width - filled)
        self.stream.write(f"\r[{bar}] {100 * fraction:5.1f}% {now - self.t0:6.1f}s {message[:60]:<60}")
        self.drawn = fraction < 1.0
        if fraction >= 1.0:
            self.stream.write("\n")
        self.stream.flush()

    def end_line(self) -> None:
        """Finish a half-drawn bar so the next message starts on its own line."""
        if self.drawn:
            self.stream.write("\n")
            self.stream.flush()
            self.drawn = False


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="python -m opal_diffraction", description="opal_diffraction spectral renderer")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    r = sub.add_parser("render", help="render a scene file (.npz) to an EXR and a PNG preview")
    r.add_argument("scene", help="scene file written by Scene.save or Blender's export operator")
    r.add_argument("-o", "--output", required=True, help="output RGB EXR path, ending in .exr (a .png preview "
                   "is written beside it)")
    r.add_argument("--preview", default=None, help="PNG preview path (default: the output path with .png)")
    r.add_argument("--no-preview", action="store_true", help="do not write the PNG preview")
    r.add_argument("--spp", type=int, default=16, help="eye samples per pixel (default 16)")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--wavelength-min", type=float, default=400.0)
    r.add_argument("--wavelength-max", type=float, default=700.0)
    r.add_argument("--wavelength-step", type=float, default=5.0)
    r.add_argument("--max-bounces", type=int, default=12, help="bounces of every kind (Cycles' Max Bounces)")
    r.add_argument("--diffuse-bounces", type=int, default=4)
    r.add_argument("--glossy-bounces", type=int, default=4)
    r.add_argument("--transmission-bounces", type=int, default=12)
    r.add_argument("--light-paths", type=_light_paths, default=None, metavar="N|auto",
                   help="light-pass paths for caustics (0: off; default auto: 1 per camera sample, 65 536 to 1 000 000)")
    r.add_argument("--dispersion-sampling", choices=["SPLIT", "SAMPLE"], default="SAMPLE")
    r.add_argument("--resolution", type=int, nargs=2, metavar=("W", "H"), help="override the camera's resolution")
    r.add_argument("--spectral-exr", default="", help="also write a spectral EXR (JCGT 2021 layout) here")
    r.add_argument("--time-limit", type=float, default=0.0, help="seconds; 0: none")
    r.add_argument("--adaptive-threshold", type=float, default=0.0, metavar="T",
                   help="adaptive sampling as Cycles' Noise Threshold: pixels stop sampling once their noise is "
                        "below T (Cycles' default 0.01); 0: off (default)")
    r.add_argument("--adaptive-min-samples", type=int, default=0, metavar="N",
                   help="samples every pixel takes before adaptive sampling may stop it; 0: automatic as Cycles "
                        "(64 at T = 0.01)")
    r.add_argument("--denoise", action="store_true", help="denoise the RGB image with Open Image Denoise (needs "
                   "requirements-denoise.txt: pyoidn); the noisy image is written as OUT.noisy.exr")
    r.add_argument("--no-blue-noise", action="store_true", help="each pixel samples its own low-discrepancy "
                   "sequence instead of a block of one shared, blue-noise ordered sequence (docs/physics.md section 6.6)")
    r.add_argument("--no-grating-footprint", action="store_true", help="point-sample grating patterns instead of "
                   "integrating them over each pixel's footprint (docs/physics.md section 3.7)")
    r.add_argument("--no-caustic-splat", action="store_true", help="look caustics seen directly up in the "
                   "caustic map instead of splatting the light paths into the image (docs/physics.md section 4.9)")
    r.add_argument("--transparent", action="store_true", help="Film > Transparent: the world seen directly is "
                   "black and the EXR gets an alpha channel, each pixel's coverage (docs/physics.md section 6.11)")
    r.add_argument("--threads", type=int, default=0, help="0: all cores")
    r.add_argument("--backend", choices=["auto", "embree", "numpy"], default="auto")
    r.add_argument("--scheduler", default="", help="render on a Dask cluster, the same image: tcp://HOST:PORT of "
                   "a scheduler, or local:N for N worker processes here (needs requirements-dask.txt)")
    r.add_argument("--exposure", type=float, default=0.0, help="stops applied to the PNG preview only")
    r.add_argument("--save-partial", action="store_true", help="on Ctrl-C, write the image rendered so far")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    return p


# ------------------------------------------------------------------------------ output paths
def _same_file(a: str, b: str) -> bool:
    ra, rb = os.path.normcase(os.path.realpath(a)), os.path.normcase(os.path.realpath(b))
    if ra == rb:
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _check_writable(path: str, what: str, created: list) -> None:
    """``path`` can be written: not a directory, and its folder takes new files (tried with a
    temporary file). Missing folders are created as the writer would (appended to ``created``,
    so a run that writes nothing removes them again)."""
    if path == "" or path.endswith(os.sep) or (os.altsep and path.endswith(os.altsep)):
        raise CliError(f"{what} {path!r} is not a file name")
    if os.path.isdir(path):
        raise CliError(f"{what} {path} is a directory")
    if os.path.lexists(path) and not os.path.isfile(path):
        raise CliError(f"{what} {path} exists and is not a regular file")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        missing, f = [], folder
        while not os.path.lexists(f):
            missing.append(f)
            parent = os.path.dirname(f)
            if parent == f:
                break
            f = parent
        if not os.path.isdir(f):
            raise CliError(f"cannot write {what} {path}: {f} is not a folder")
        for d in reversed(missing):
            try:
                os.mkdir(d)
            except OSError as e:
                raise CliError(f"cannot write {what} {path}: cannot create the folder {d} ({e.strerror})") from None
            created.append(d)
    try:
        fd, probe = tempfile.mkstemp(prefix=".tmp_", suffix=".probe", dir=folder)
    except OSError as e:
        raise CliError(f"cannot write {what} {path}: the folder {folder} is not writable ({e.strerror})") from None
    os.close(fd)
    os.unlink(probe)


def _remove_created(created: list) -> None:
    """Remove the folders the checks created, if they are still empty (newest first)."""
    for d in reversed(created):
        try:
            os.rmdir(d)
        except OSError:
            pass
    created.clear()


def _output_paths(args, created: list) -> dict:
    """{'exr': path, 'png': path or None, 'spectral': path or None, 'noisy': path or None},
    checked (CliError)."""
    out = args.output
    if not out.lower().endswith(".exr"):
        raise CliError(f"output {out!r} must end in .exr (the RGB image is an OpenEXR file; the PNG preview "
                       f"is written beside it)")
    noisy = os.path.splitext(out)[0] + ".noisy.exr" if args.denoise else None
    png = None if args.no_preview else (args.preview or os.path.splitext(out)[0] + ".png")
    if png is not None and not png.lower().endswith(".png"):
        raise CliError(f"preview {png!r} must end in .png")
    spectral = args.spectral_exr or None
    if spectral is not None and not spectral.lower().endswith(".exr"):
        raise CliError(f"spectral EXR {spectral!r} must end in .exr")
    named = [("output", out), ("preview", png), ("spectral EXR", spectral), ("noisy image", noisy)]
    for i, (wa, a) in enumerate(named):
        if a is None:
            continue
        if _same_file(a, args.scene):
            raise CliError(f"{wa} {a} is the scene file: it would be overwritten")
        for wb, b in named[i + 1:]:
            if b is not None and _same_file(a, b):
                raise CliError(f"{wb} {b} is the same file as the {wa}: give them different paths")
    for what, path in named:
        if path is not None:
            _check_writable(path, what, created)
    return {"exr": out, "png": png, "spectral": spectral, "noisy": noisy}


def _physical_memory() -> int | None:
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def _check_memory(prepared) -> None:
    from .core.scene.settings import film_bytes

    cam = prepared.scene.camera
    spectral = bool(prepared.settings.spectral_exr)  # the film keeps (H, W, n) sums only for a spectral EXR
    need = film_bytes(cam.width, cam.height, prepared.grid.n, spectral)
    have = _physical_memory()
    if have and need > 0.75 * have:
        what = (f"{cam.width}x{cam.height} pixels x {prepared.grid.n} wavelengths for the spectral EXR" if spectral
                else f"{cam.width}x{cam.height} pixels")
        hint = ("lower the resolution, use a coarser wavelength step or write no spectral EXR" if spectral
                else "lower the resolution")
        raise CliError(f"the image needs {need / 2**30:.1f} GiB for its film ({what}), more than this machine's "
                       f"{have / 2**30:.1f} GiB allow: {hint}")


# ------------------------------------------------------------------------------ signals
class _Signals:
    """SIGINT / SIGTERM handling by phase. While rendering, the first signal asks the render to
    stop at the next tile (the render's ``should_cancel``; tiles already running finish); in
    every other phase, and for a second signal, the handler raises _Stop at once. Handlers are
    restored on exit (main() may run inside another program)."""

    def __init__(self):
        self.phase = "setup"
        self.cancel_signal: int | None = None
        self.old = {}

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                try:
                    self.old[sig] = signal.signal(sig, self._handle)
                except (ValueError, OSError):  # pragma: no cover - no signals here
                    pass
        return self

    def __exit__(self, *exc):
        for sig, handler in self.old.items():
            signal.signal(sig, handler)
        return False

    def _handle(self, signum, frame):
        if self.phase == "render" and self.cancel_signal is None:
            self.cancel_signal = signum  # stop at the next tile; a second signal stops at once
            return
        raise _Stop(signum)

    def should_cancel(self) -> bool:
        return self.cancel_signal is not None


def _error(message: str) -> None:
    print("error: " + " ".join(str(message).split()), file=sys.stderr)


def _one_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0][:300]}" if text else type(e).__name__


# ------------------------------------------------------------------------------ main
def _sampled_fraction(result) -> float:
    """The fraction of the image's pixels that took at least one sample."""
    counts = result.sample_counts
    if counts is None or not counts.size:
        return 1.0 if result.samples > 0 else 0.0
    return float((counts > 0).sum()) / counts.size


def _partial_samples(result, requested: int) -> str:
    """How many samples a partial image's pixels have, e.g. '16 of 64 samples per pixel' or
    '0-16 of 64 samples per pixel; 31 % of the pixels have none'."""
    counts = result.sample_counts
    if counts is None or not counts.size or counts.min() == counts.max():
        return f"{result.samples} of {requested} samples per pixel"
    text = f"{int(counts.min())}-{int(counts.max())} of {requested} samples per pixel"
    none = 1.0 - _sampled_fraction(result)
    return text + (f"; {100 * none:.0f} % of the pixels have none" if none > 0 else "")


def main(argv=None) -> int:
    try:
        args = _parser().parse_args(argv)
    except _UsageExit as e:
        _error(e)
        return EXIT_USAGE
    created: list = []  # output folders the checks made, removed again unless an image is written
    with _Signals() as sig, warnings.catch_warnings():
        if not os.environ.get("OPAL_DEBUG"):  # NumPy's and colour's RuntimeWarnings are not for users
            warnings.simplefilter("ignore")
        try:
            code = _render(args, sig, created)
            if code == EXIT_OK or sig.phase == "done" and code == EXIT_INTERRUPTED and args.save_partial:
                created.clear()
            return code
        except CliError as e:
            _error(e)
            return EXIT_USAGE
        except _Stop as e:
            if e.signum == signal.SIGTERM:
                print("\nterminated", file=sys.stderr)
                return EXIT_TERMINATED
            print("\ninterrupted" + (" while writing: no file was left half-written" if sig.phase == "write" else ""),
                  file=sys.stderr)
            return EXIT_INTERRUPTED
        except KeyboardInterrupt:  # a Ctrl-C before the handlers were installed
            print("\ninterrupted", file=sys.stderr)
            return EXIT_INTERRUPTED
        except MemoryError:
            _error("out of memory: lower the resolution, the samples per round or use a coarser wavelength step")
            return EXIT_FAILURE
        except Exception as e:  # a failure of the renderer itself: one line, the traceback on request
            if os.environ.get("OPAL_DEBUG"):
                import traceback

                traceback.print_exc()
            _error(f"the render failed ({_one_line(e)}); set OPAL_DEBUG=1 for the traceback")
            return EXIT_FAILURE
        finally:
            _remove_created(created)


def _render(args, sig: _Signals, created: list) -> int:
    from .core.render.output import write_png, write_rgb_exr, write_spectral_exr
    from .core.render.prepare import prepare
    from .core.render.distributed import DaskExecutor, connect
    from .core.render.frame import render_prepared
    from .core.util.cancel import OutOfTime
    from .core.scene.npz import load_scene
    from .core.scene.checks import SceneError
    from .core.scene.settings import RenderSettings

    t_start = time.perf_counter()
    if not math.isfinite(args.exposure) or abs(args.exposure) > 100:
        raise CliError(f"exposure must be a finite number of stops within +-100, got {args.exposure}")
    paths = _output_paths(args, created)
    if args.denoise:
        from .core.render.denoise import available, INSTALL_HINT

        if not available():  # before the render, not after it
            raise CliError(f"--denoise needs Open Image Denoise's Python binding pyoidn, which is not installed: "
                           f"{INSTALL_HINT}")
    try:
        scene = load_scene(args.scene)
        if args.resolution:
            if scene.camera is None:
                raise SceneError("the scene has no camera")
            scene.camera.width, scene.camera.height = args.resolution
        settings = RenderSettings(
            samples=args.spp, seed=args.seed, wavelength_min=args.wavelength_min,
            wavelength_max=args.wavelength_max, wavelength_step=args.wavelength_step,
            max_bounces=args.max_bounces, diffuse_bounces=args.diffuse_bounces,
            glossy_bounces=args.glossy_bounces, transmission_bounces=args.transmission_bounces,
            dispersion_sampling=args.dispersion_sampling, light_paths=args.light_paths,
            spectral_exr=args.spectral_exr, time_limit=args.time_limit, threads=args.threads,
            backend=args.backend, adaptive_threshold=args.adaptive_threshold,
            adaptive_min_samples=args.adaptive_min_samples, grating_footprint=not args.no_grating_footprint,
            blue_noise=not args.no_blue_noise,
            caustic_splat=not args.no_caustic_splat, film_transparent=bool(args.transparent),
        )
        settings.validate()
        sig.phase = "prepare"
        prepared = prepare(scene, settings, deadline=t_start + args.time_limit if args.time_limit else None)
    except SceneError as e:
        raise CliError(str(e)) from None
    except OutOfTime:
        raise CliError(f"the time limit ({args.time_limit:g} s) ran out while preparing the scene "
                       f"({len(scene.triangles)} triangles): nothing rendered; allow more time") from None
    _check_memory(prepared)
    for w in settings.warnings():
        print(f"warning: {w}", file=sys.stderr)

    bar = None if args.quiet else _ProgressBar()
    sig.phase = "render"
    try:
        with connect(args.scheduler) if args.scheduler else nullcontext() as client:
            # on a Dask cluster the same image (core/render/distributed.py), else this process's threads
            executor = None if client is None else DaskExecutor(client, scene)
            result = render_prepared(prepared, progress=bar, should_cancel=sig.should_cancel, started_at=t_start,
                                     executor=executor)
    except SceneError as e:
        raise CliError(str(e)) from None
    finally:
        if bar is not None:
            bar.end_line()
    interrupted = sig.cancel_signal is not None
    if sig.cancel_signal == signal.SIGTERM:
        sig.phase = "done"
        print("terminated: nothing written", file=sys.stderr)
        return EXIT_TERMINATED
    if interrupted and not args.save_partial:
        sig.phase = "done"
        print("interrupted: nothing written (--save-partial writes the image rendered so far)", file=sys.stderr)
        return EXIT_INTERRUPTED
    if interrupted and _sampled_fraction(result) == 0.0:
        sig.phase = "done"  # an all-black "partial image" would only mislead
        print("interrupted before any pixel had a sample: nothing written", file=sys.stderr)
        return EXIT_INTERRUPTED
    for w in result.warnings:
        print(f"warning: {w}", file=sys.stderr)

    if args.denoise and result.samples > 0:
        from .core.render.denoise import denoise_result

        sig.phase = "denoise"
        try:
            result = denoise_result(result)
        except SceneError as e:
            raise CliError(str(e)) from None

    sig.phase = "write"
    try:
        if paths["noisy"] and "Noisy Image" in result.passes:
            write_rgb_exr(paths["noisy"], result.passes["Noisy Image"])
        write_rgb_exr(paths["exr"], result.rgb, result.alpha if args.transparent else None)
        if paths["png"]:
            write_png(paths["png"], result.rgb, args.exposure)
        if paths["spectral"]:
            write_spectral_exr(paths["spectral"], result.spectral, result.wavelengths, result.rgb)
    except OSError as e:
        _error(f"cannot write the image: {e.strerror or e} ({e.filename or paths['exr']})")
        return EXIT_FAILURE
    sig.phase = "done"
    written = " and ".join(p for p in (paths["exr"], paths["noisy"], paths["png"], paths["spectral"]) if p)
    if interrupted:
        print(f"interrupted: wrote the partial image ({_partial_samples(result, settings.samples)}) to {written}",
              file=sys.stderr)
        return EXIT_INTERRUPTED
    s = result.stats
    if not args.quiet:
        print(f"{result.plan.summary()}", file=sys.stderr)
        print(f"wrote {written}: {s['render_s']:.2f} s, {s['rays'] / 1e6:.2f} M rays "
              f"({s['mrays_per_s']:.2f} Mrays/s, {s['backend']}, {s.get('kernels', 'numpy')} kernels)", file=sys.stderr)
        if settings.adaptive_threshold > 0:
            print(f"adaptive sampling: {s['samples_min']} to {s['samples_max']} samples per pixel, "
                  f"{s['samples_mean']:.1f} on average", file=sys.stderr)
    return EXIT_OK
