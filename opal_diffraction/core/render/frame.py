"""One render, start to finish: prepare, plan, light pass, eye pass over tiles, film.

The pipeline is one-way; each step hands the next an immutable value and nothing writes back:

    Scene --prepare--> PreparedScene --plan_render--> RenderPlan
          --run_light_pass--> LightPassResult --EyePass over tiles x rounds--> Film --> RenderResult

``render`` runs all of it; ``render_prepared`` starts from a PreparedScene (and optionally a
finished LightPassResult), which is what the rendered viewport reuses while only the view
moves. The image is split into tiles and the samples into progressive rounds (tiles.py). Every
(round, tile) batch draws its random numbers from its own stream, ``SeedSequence([seed, pass,
round, tile])``, and writes only its own pixels, so the image is identical whatever the number
of threads, or machines: ``render(..., client=dask_client)`` runs the same units on a Dask
cluster (distributed.py, imported only then); rounds make time limits, cancellation and partial
previews cheap. With adaptive sampling (``settings.adaptive_threshold``, core/render/adaptive.py) a
tile's round traces only the pixels that have not converged, and a tile whose pixels all have
takes no more rounds; which pixels follows from the film after the tile's earlier rounds, so the
image is still the same for any thread count or cluster. The film sums RGB; it keeps the
(H, W, n) spectral image only when it is asked for (``spectral_film``; by default when
``settings.spectral_exr`` names a spectral EXR), so ``RenderResult.spectral`` is None otherwise
(film.py).
"""

from __future__ import annotations

import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from typing import Callable

from ..util.blas_threads import one_blas_thread
from ..sampling.camera import FilterSampler
from ..integrators.light.camera_splat import usable_splat
from ..integrators.eye.eye_pass import EyePass
from ..util.cancel import RenderCancelled
from ..util.jit import kernel_mode
from .film import Film, RenderResult, keeps_spectral
from ..integrators.light.light_pass import LightPassResult, run_light_pass
from .plan import RenderPlan, plan_render
from .prepare import PreparedScene, prepare
from ..scene.model import Scene
from ..scene.settings import RenderSettings
from ..spectral.spectrum import SpectralConverter
from .tiles import (EYE_PASS_STREAM, LIGHT_PASS_SHARE, MAX_TILE_RAYS, EyeWork, adaptive_of, is_half_a, round_size, trace_tile)

__all__ = ["RenderResult", "render", "render_prepared"]


class _Inline:
    """A future-like wrapper that runs its call lazily in the calling thread."""

    def __init__(self, fn, *args):
        self.fn, self.args = fn, args

    def result(self):
        return self.fn(*self.args)

    def cancel(self):
        pass


def render(
    scene: Scene,
    settings: RenderSettings | None = None,
    progress: Callable[[float, str], None] | None = None,
    should_cancel: Callable[[], bool] | None = None,
    on_round: Callable[[RenderResult], None] | None = None,
    region: tuple[int, int, int, int] | None = None,
    client=None,
    spectral_film: bool | None = None,
) -> RenderResult:
    """Render ``scene``; raises SceneError (a readable message) for unrenderable input.

    ``progress(fraction, message)`` is called after every tile; ``should_cancel()`` is polled
    between tiles and stops the render early (the result holds the finished rounds);
    ``on_round(result)`` receives the partial image after every round. ``region`` = (x0, y0, x1,
    y1) renders only those pixels of the camera's image (a border render; rows from the top); the
    result then has shape (y1 - y0, x1 - x0).

    ``client``: a ``dask.distributed.Client``; the light pass's batches and the eye pass's
    tiles x rounds then run on its workers and the image is the one this machine renders alone,
    bit for bit (core/render/distributed.py, docs/distributed.md). None: this process's threads.

    ``spectral_film``: keep the spectral image (``RenderResult.spectral``, (H, W, n)); None: only
    when ``settings.spectral_exr`` is set. Otherwise the film is RGB only and ``spectral`` is None.
    """
    t_start = time.perf_counter()
    try:
        with kernel_mode((settings or RenderSettings()).kernels):  # prepare's spectra take the render's path
            prepared = prepare(scene, settings, should_cancel=should_cancel)
    except RenderCancelled:
        return _cancelled_before_start(scene, settings or RenderSettings(), region, spectral_film)
    if client is not None:
        from .distributed import render_on_cluster  # dask only when asked for

        return render_on_cluster(client, scene, settings or RenderSettings(), prepared, progress, should_cancel,
                                 on_round, region, started_at=t_start, spectral_film=spectral_film)
    return render_prepared(prepared, None, progress, should_cancel, on_round, region, started_at=t_start,
                           spectral_film=spectral_film)


def _cancelled_before_start(scene: Scene, settings: RenderSettings, region, spectral_film=None) -> RenderResult:
    """The (black, zero-sample) result of a render cancelled while it was being prepared."""
    cam = scene.camera
    x0, y0, x1, y1 = region if region is not None else (0, 0, int(cam.width), int(cam.height))
    film = Film(x1 - x0, y1 - y0, SpectralConverter(settings.grid()), spectral=keeps_spectral(settings, spectral_film))
    plan = RenderPlan(eye_pass=False, notes=("cancelled while preparing the scene",))
    return film.result(plan, True, ["cancelled while preparing the scene"], {"rays": 0})


@one_blas_thread()  # the tile threads are the parallelism (core/util/blas_threads.py)
def render_prepared(
    prepared: PreparedScene,
    light: LightPassResult | None = None,
    progress: Callable[[float, str], None] | None = None,
    should_cancel: Callable[[], bool] | None = None,
    on_round: Callable[[RenderResult], None] | None = None,
    region: tuple[int, int, int, int] | None = None,
    started_at: float | None = None,
    spectral_film: bool | None = None,
) -> RenderResult:
    """Render a prepared scene (see ``render`` for the callbacks, ``region`` and ``spectral_film``).

    ``light``: a finished light pass of the same prepared scene (``prepared.with_view`` keeps it
    valid) to reuse; None runs the light pass when the plan asks for it. ``started_at``: the
    perf_counter time the time limit counts from (default: now). The passes run the compiled
    kernels or the NumPy reference as ``settings.kernels`` says (core/util/jit.py); the stats'
    ``kernels`` names which.
    """
    with kernel_mode(prepared.settings.kernels) as kernels:
        return _render_prepared(prepared, light, progress, should_cancel, on_round, region, started_at,
                                spectral_film, kernels)


def _render_prepared(prepared, light, progress, should_cancel, on_round, region, started_at, spectral_film,
                     kernels: str) -> RenderResult:
    """render_prepared's body, inside its kernel mode (``kernels``: the path taken, for the stats)."""
    t_start = time.perf_counter() if started_at is None else started_at
    settings = prepared.settings
    plan = plan_render(prepared)
    warnings = list(prepared.warnings) + list(plan.warnings)
    adaptive = adaptive_of(settings)
    (rx0, ry0, rx1, ry1), film = Film.for_region(prepared.scene.camera, region, prepared.conv, adaptive is not None,
                                                 keeps_spectral(settings, spectral_film))
    stats = {"rays": 0, "prepare_s": prepared.prepare_s, "backend": prepared.accel.name,
             "triangles": len(prepared.scene.triangles), "kernels": kernels}

    deadline = t_start + settings.time_limit if settings.time_limit else None
    if plan.light_pass and light is None:
        lp_progress = (lambda f, m: progress(LIGHT_PASS_SHARE * f, m)) if progress else None
        light = run_light_pass(prepared, None, lp_progress, should_cancel, deadline)
    elif not plan.light_pass:
        light = None
    if light is not None:
        warnings += light.warnings
        stats.update(light.stats)
        stats["rays"] += light.stats.get("light_rays", 0)
    cancelled = light is not None and light.cancelled  # Esc during the light pass
    t_eye = time.perf_counter()

    spp = int(settings.samples)
    work = EyeWork.of(prepared, (rx0, ry0, rx1, ry1))
    rounds, tiles = work.rounds, work.tiles
    filt = FilterSampler(settings.filter_width)
    eye = EyePass(prepared, light)
    threads = prepared.threads
    total_work = work.units

    def run_tile(r_index, t_index, pixels):
        return t_index, pixels, trace_tile(eye, filt, work, r_index, t_index, pixels)

    splat = usable_splat(prepared, light)  # the camera splat, if made for this view (else the map)
    splat_images = None if splat is None else splat.images(prepared.conv, (rx0, ry0, rx1, ry1))

    def finish(final=False):
        return film.result(plan, cancelled, warnings, stats, final=final, splat=splat_images)

    work_done = 0
    stop = "cancel" if cancelled else ""  # why the rounds ended early: "cancel" or "time"
    with ThreadPoolExecutor(max_workers=threads) as pool:
        for r_index, r_spp in enumerate(rounds):
            if stop:
                break
            # adaptive sampling: each tile's pixels that have not converged (None: all of them)
            jobs = [(ti, film.active_pixels(*tiles[ti][:4])) for ti in range(len(tiles))]
            jobs = [(ti, px) for ti, px in jobs if px is None or len(px)]
            work_done += len(tiles) - len(jobs)  # converged tiles: nothing left to do
            if not jobs:
                break  # every pixel has converged
            if threads > 1:
                pending = [pool.submit(run_tile, r_index, ti, px) for ti, px in jobs]
            else:  # in the calling thread: simpler to profile and debug
                pending = [_Inline(run_tile, r_index, ti, px) for ti, px in jobs]
            # each future is dropped once its tile is in the film: a round's futures would
            # otherwise hold every tile's (P, n) spectral sums until the round ends (1920x1080:
            # 510 tiles, over 1 GB)
            pending = deque(pending)
            while pending:
                fut = pending.popleft()
                if stop:
                    fut.cancel()
                    continue
                t_index, pixels, res = fut.result()
                x0, y0, x1, y1, _ = tiles[t_index]
                film.add_tile(x0, y0, x1, y1, res, r_spp, pixels, is_half_a(r_index))
                if adaptive is not None:
                    film.update_active(x0, y0, x1, y1, *adaptive)
                stats["rays"] += res.rays
                work_done += 1
                if progress:
                    base = LIGHT_PASS_SHARE if plan.light_pass else 0.0
                    progress(base + (1 - base) * work_done / total_work,
                             f"eye pass: round {r_index + 1}/{len(rounds)}, {stats['rays'] / 1e6:.1f} M rays")
                if should_cancel and should_cancel():
                    stop = "cancel"
                # the time limit ends a round between tiles too, once every pixel has a sample
                elif deadline is not None and r_index > 0 and time.perf_counter() > deadline:
                    stop = "time"
            # tiles finished in an interrupted round keep their extra samples (counts say so)
            if not stop:
                if on_round:
                    on_round(finish())
                if r_index + 1 < len(rounds) and deadline is not None and time.perf_counter() > deadline:
                    stop = "time"
            if stop:
                break
    cancelled = stop == "cancel"
    if stop == "time":
        warnings.append(f"time limit reached after {int(film.counts.min())} of {spp} samples per pixel")
    stats["render_s"] = time.perf_counter() - t_start
    stats["mrays_per_s"] = stats["rays"] / max(time.perf_counter() - t_eye + stats.get("light_pass_s", 0.0), 1e-9) / 1e6
    return finish(final=True)
