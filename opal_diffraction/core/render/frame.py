"""One render, start to finish: prepare, plan, light pass, eye pass over tiles, film.

The pipeline is one-way; each step hands the next an immutable value and nothing writes back:

    Scene --prepare--> PreparedScene --plan_render--> RenderPlan
          --light pass--> LightPassResult --EyePass over tiles x rounds--> Film --> RenderResult

``render`` runs all of it; ``render_prepared`` starts from a PreparedScene (and optionally a
finished LightPassResult), which is what the rendered viewport reuses while only the view
moves. The image is split into tiles and the samples into progressive rounds (tiles.py). Every
(round, tile) batch draws its random numbers from its own stream, ``SeedSequence([seed, pass,
round, tile])``, and writes only its own pixels, so the image is identical whatever runs the
units: the scheduler (scheduler.py) decides which units run, in what order they enter the film
and when the render stops (cancel, time limit, adaptive sampling), and its executor runs them,
on this process's threads (``LocalExecutor``) or on a Dask cluster (``render(...,
client=dask_client)``: distributed.DaskExecutor); rounds make time limits, cancellation and
partial previews cheap. With adaptive sampling (``settings.adaptive_threshold``,
core/render/adaptive.py) a tile's round traces only the pixels that have not converged, and a
tile whose pixels all have takes no more rounds; which pixels follows from the film after the
tile's earlier rounds, so the image is still the same for any thread count or cluster. The film
sums RGB; it keeps the (H, W, n) spectral image only when it is asked for (``spectral_film``; by
default when ``settings.spectral_exr`` names a spectral EXR), so ``RenderResult.spectral`` is
None otherwise (film.py). A light pass cancelled midway ends the render with a black image.

The compile stage: before a process's first render on the compiled kernels (core/util/jit.py),
``compile_stage`` renders a built-in tiny scene (``warm_up_scene``: 4 x 4 pixels, 1 sample, a few
thousand light paths; flat and smooth triangles, diffuse, a mirror, a dispersive glass, a point
and an area light, an environment map) so numba compiles the kernels on those
paths (or loads them from its cache), and reports it as the progress stage "compiling kernels":
the first render after an install shows that stage instead of standing at 0 %. It runs once per
process (``jit.warm_up``); renders on the NumPy reference skip it, and so do renders on a Dask
cluster (its workers compile what they run). The render that paid for it
has ``compile_s``, ``kernels_compiled`` and ``kernels_loaded`` in its stats. A render's cancel
check is polled during the stage (it runs in a worker thread, util/cancel.run_cancellable): a
cancel returns a black, zero-sample result within util/cancel.POLL_S, the warm-up stops at its
next check and the next render runs the stage again; ``render_prepared``'s time limit (counted
from ``started_at``, as the CLI's includes the preparation) counts the stage too, ``render``'s
starts after it.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Callable

import numpy as np

from ..util.blas_threads import one_blas_thread
from ..integrators.light.camera_splat import usable_splat
from ..integrators.light.splat_vertices import resplat, resplat_note
from ..util.cancel import OutOfTime, RenderCancelled
from .distributed import DaskExecutor
from ..util.jit import kernel_mode, warm_up
from .film import Film, RenderResult, keeps_spectral
from ..integrators.light.light_pass import LightPassResult
from .plan import RenderPlan, plan_render
from .prepare import PreparedScene, prepare
from .scheduler import Executor, LocalExecutor, RenderControl, run_eye_pass
from ..scene import primitives
from ..scene.model import Camera, Lights, Materials, Scene
from ..scene.settings import RenderSettings
from ..spectral.spectrum import SpectralConverter
from .tiles import LIGHT_PASS_SHARE, EyeWork, adaptive_of
from .view_check import camera_sees_nothing

__all__ = ["RenderResult", "LightPassResult", "render", "render_prepared", "reusable_light", "light_reuse",
           "compile_stage", "warm_up_scene"]


def render(
    scene: Scene,
    settings: RenderSettings | None = None,
    progress: Callable[[float, str], None] | None = None,
    should_cancel: Callable[[], bool] | None = None,
    on_round: Callable[[RenderResult], None] | None = None,
    region: tuple[int, int, int, int] | None = None,
    client=None,
    spectral_film: bool | None = None,
    reuse: PreparedScene | None = None,
    light: LightPassResult | None = None,
    on_prepared: Callable[[PreparedScene], None] | None = None,
    on_light: Callable[[LightPassResult], None] | None = None,
    keep_splat: int = 0,
) -> RenderResult:
    """Render ``scene``; raises SceneError (a readable message) for unrenderable input.

    ``progress(fraction, message)`` is called after every tile (the fraction increases and ends
    at 1 unless cancelled; the process's first render on the kernels first reports (0,
    'compiling kernels'): ``compile_stage``); ``should_cancel()`` is polled between tiles (and while waiting for
    one) and stops the render early (the result holds the tiles added so far);
    ``on_round(result)`` receives the partial image after every round. ``region`` = (x0, y0, x1,
    y1) renders only those pixels of the camera's image (a border render; rows from the top); the
    result then has shape (y1 - y0, x1 - x0).

    ``client``: a ``dask.distributed.Client``; the light pass's batches and the eye pass's
    tiles x rounds then run on its workers and the image is the one this machine renders alone,
    bit for bit (core/render/distributed.py, docs/distributed.md). None: this process's threads.

    ``spectral_film``: keep the spectral image (``RenderResult.spectral``, (H, W, n)); None: only
    when ``settings.spectral_exr`` is set. Otherwise the film is RGB only and ``spectral`` is None.

    Between renders of one scene (the engine's persistent data, blender/persistent.py):
    ``reuse``, an earlier PreparedScene, is handed to ``prepare`` (what depends only on unchanged
    inputs is taken from it: the ray caster when the geometry is the same, and its ``key`` when
    nothing the light pass reads changed); ``light``, that earlier render's light pass, is reused
    where ``reusable_light`` allows (same key; where the plan splats, a splat made for this view
    or the splat's kept vertices, splatted again into this view: ``render_prepared``).
    ``on_prepared(prepared)`` and ``on_light(result)`` receive what this render prepared and the
    light pass it ran (or re-splatted), for the next render. ``keep_splat``: bytes of camera-splat
    vertices the light pass may keep for another view (run_light_pass's ``keep_vertices``; 0:
    none). The image is the one a render without them makes.
    """
    # before prepare's kernels run; a cluster's workers compile their own (the stage is this process's)
    try:
        with one_blas_thread():  # as the render itself (its progress callback may look)
            compiled = (compile_stage((settings or RenderSettings()).kernels, progress, should_cancel)
                        if client is None else None)
    except RenderCancelled:
        return _cancelled_before_start(scene, settings or RenderSettings(), region, spectral_film,
                                       cancelled_in="while compiling the kernels")
    t_start = time.perf_counter()  # the time limit counts from here (compile_s is in the stats)
    limit = _time_limit_before_validation(settings or RenderSettings())
    try:
        with kernel_mode((settings or RenderSettings()).kernels):  # prepare's spectra take the render's path
            prepared = prepare(scene, settings, reuse=reuse, should_cancel=should_cancel,
                               deadline=t_start + limit if limit > 0 else None)
    except OutOfTime:
        return _cancelled_before_start(scene, settings or RenderSettings(), region, spectral_film,
                                       f"time limit ({limit:g} s) reached while preparing the scene: nothing rendered")
    except RenderCancelled:
        return _cancelled_before_start(scene, settings or RenderSettings(), region, spectral_film)
    if client is None and prepared.microfacet.any():  # the GGX kernels' own stage, once per process
        try:
            with one_blas_thread():
                compiled = _add_stage_stats(compiled, compile_stage(prepared.settings.kernels, progress, should_cancel,
                                                                    rough=True, core=False))
        except RenderCancelled:
            return _cancelled_before_start(scene, prepared.settings, region, spectral_film,
                                           cancelled_in="while compiling the kernels")
    if on_prepared is not None:
        on_prepared(prepared)
    executor = None if client is None else DaskExecutor(client, scene)
    with one_blas_thread():  # the tile threads are the parallelism (core/util/blas_threads.py)
        return _render_in_mode(prepared, reusable_light(prepared, light), progress, should_cancel, on_round, region,
                               t_start, spectral_film, executor, time.perf_counter, compiled, on_light, keep_splat)


def reusable_light(prepared: PreparedScene, light: LightPassResult | None) -> LightPassResult | None:
    """``light`` (an earlier render's light pass) if the eye pass of ``prepared`` may read it as
    the light pass ``prepared`` would run itself, else None (run it again): ``light_reuse``."""
    return light_reuse(prepared, light)[0]


def light_reuse(prepared: PreparedScene, light: LightPassResult | None) -> tuple[LightPassResult | None, str]:
    """(``light`` or None, why not): ``light`` (an earlier render's light pass) is reusable by
    ``prepared``'s render if it belongs to the same preparation (``key``: the geometry,
    materials, lights, world and light-pass settings are unchanged), it ran to the end (not
    cancelled, not cut short by a time limit, whose share of the paths depends on the clock),
    and where the plan splats light paths into the camera (core/integrators/light/camera_splat.py)
    its splat was made for this view (``usable_splat``) or it kept the splat's vertices, which
    ``render_prepared`` splats again into this view (core/integrators/light/splat_vertices.py):
    the caustic map, the grating records and the vertices do not depend on the camera, the splat
    does. The reason is "" when it is reusable or belongs to another preparation (nothing to say:
    the scene changed), else a phrase for the stats ("the kept light pass was cancelled", ...)."""
    if light is None or light.key != prepared.key:
        return None, ""
    if light.cancelled:
        return None, "the kept light pass was cancelled"
    if any("time limit" in w for w in light.warnings):
        return None, "the kept light pass was cut short by the time limit"
    if plan_render(prepared).camera_splat and usable_splat(prepared, light) is None:
        why = resplat_note(light.vertices)
        if why:
            return None, why
    return light, ""


def _time_limit_before_validation(settings: RenderSettings) -> float:
    """settings.time_limit as seconds (0: none) where the settings are not validated yet (the
    render's time limit counts preparation): a value that is not one finite number counts as
    none here, and preparation's validation then names it (SceneError) before anything runs."""
    try:
        limit = float(settings.time_limit or 0.0)
    except (TypeError, ValueError):  # an array, a string, ...: validate() says what is wrong
        return 0.0
    return limit if math.isfinite(limit) and limit > 0 else 0.0


def warm_up_scene() -> Scene:
    """The compile stage's scene: 4 x 4 pixels seeing a diffuse floor (flat triangles), a gold
    mirror sphere and a diffuse sphere (smooth triangles) and a dispersive flint prism, lit by a
    point light, an area light and an environment map: the paths a render's kernels take. No
    rough (GGX) surface: the first rough material of a process builds the multiple-scattering
    tables (materials/bsdf.py, seconds of NumPy), which a scene without one never needs; the
    GGX kernels compile (or load) in a stage of their own (``rough_warm_up_scene``) before the
    first render that has one."""
    s = Scene(materials=Materials.from_list([
        {"kind": "DIFFUSE", "color": (0.6, 0.6, 0.6)},
        {"kind": "MIRROR", "color": (0.9, 0.7, 0.3)},
        {"kind": "DIELECTRIC", "ior": 1.72, "dispersion": "ABBE", "abbe": 29.0},
        {"kind": "DIFFUSE", "color": (0.2, 0.4, 0.8)},
    ]))
    s.add_mesh(*primitives.quad((0, 0, 0), (6, 0, 0), (0, 6, 0)), material=0)
    for centre, mat in (((-0.8, 0.3, 0.5), 1), ((0.8, 0.3, 0.5), 3)):
        v, t = primitives.uv_sphere(centre, 0.5, segments=12, rings=6)
        s.add_mesh(v, t, material=mat, normals=(v - np.asarray(centre, np.float32)) / 0.5)
    s.add_mesh(*primitives.prism((0, -0.6, 0.4), side=0.6, length=1.0, axis="X", rotation_deg=180.0), material=2)
    s.lights = Lights.from_list([
        {"kind": "POINT", "position": (1.0, -1.5, 3.0), "power": 300.0},
        {"kind": "AREA_RECT", "position": (-1.0, 0.0, 2.5), "direction": (0, 0, -1), "power": 100.0},
    ])
    s.world_image = np.linspace(0.2, 1.0, 8 * 4 * 3, dtype=np.float32).reshape(4, 8, 3)
    s.world_color = np.full(3, 0.3, np.float32)
    s.camera = Camera.look_at((0.0, -4.0, 2.0), (0.0, 0.0, 0.5), lens=35.0, width=4, height=4)
    return s


#: The rough stage's materials (rough_warm_up_scene): every lobe of materials/bsdf.py.
_ROUGH_MATERIALS = (
    {"kind": "MIRROR", "color": (0.95, 0.7, 0.4), "roughness": 0.3, "metallic": 1.0, "conductor_fresnel": "F82_TINT"},
    {"kind": "DIFFUSE", "color": (0.8, 0.2, 0.2), "roughness": 0.5, "specular_ior_level": 0.5},
    {"kind": "DIELECTRIC", "ior": 1.5, "roughness": 0.2, "dispersion": "ABBE", "abbe": 40.0},
    {"kind": "MIRROR", "color": (0.9, 0.9, 0.9), "roughness": 0.4},
)


def rough_warm_up_scene(only: int | None = None) -> Scene:
    """The rough surfaces' compile stage's scene: 8 x 8 pixels seeing a rough gold conductor, a
    Principled plastic (specular over a diffuse base), rough glass and a Glossy BSDF (GGX with a
    constant Fresnel), spheres side by side on a diffuse floor (each about 2 pixels wide), under a
    point light, an area light and a world map: every lobe of materials/bsdf.py's kernels
    (evaluate, sample, with_outgoing, the parameters) for white and mono rays, in batches of
    several materials. ``only``: just that one of ``_ROUGH_MATERIALS``, a sphere filling the view
    (batches of one material: the parameters' broadcast rows, other array types)."""
    mats = [{"kind": "DIFFUSE", "color": (0.6, 0.6, 0.6)}] + [dict(m) for m in _ROUGH_MATERIALS]
    s = Scene(materials=Materials.from_list(mats))
    s.add_mesh(*primitives.quad((0, 0, 0), (6, 0, 0), (0, 6, 0)), material=0)
    spheres = [((x, 0.0, 0.3), k + 1) for k, x in enumerate((-0.9, -0.3, 0.3, 0.9))]
    if only is not None:
        spheres = [((0.0, 0.0, 0.3), only + 1)]
    for centre, mat in spheres:
        v, t = primitives.uv_sphere(centre, 0.3, segments=10, rings=5)
        s.add_mesh(v, t, material=mat, normals=(v - np.asarray(centre, np.float32)) / 0.3)
    s.lights = Lights.from_list([
        {"kind": "POINT", "position": (1.0, -1.5, 3.0), "power": 300.0},
        {"kind": "AREA_RECT", "position": (-1.0, 0.0, 2.5), "direction": (0, 0, -1), "power": 100.0},
    ])
    s.world_image = np.linspace(0.2, 1.0, 8 * 4 * 3, dtype=np.float32).reshape(4, 8, 3)
    s.world_color = np.full(3, 0.3, np.float32)
    eye = (0.0, -2.5, 0.8) if only is None else (0.0, -0.9, 0.45)
    s.camera = Camera.look_at(eye, (0.0, 0.0, 0.3), lens=35.0, width=8, height=8)
    return s


def _warm_up_render(stopped: Callable[[], bool] | None = None) -> None:
    """The compile stage's render; ``stopped``: its cancel check (it stops between its stages,
    units and ray casts, so between the kernels it compiles)."""
    render(warm_up_scene(), RenderSettings(samples=1, threads=1, light_paths=4096, seed=0), should_cancel=stopped)


def _rough_warm_up_render(stopped: Callable[[], bool] | None = None) -> None:
    """The rough surfaces' compile stage's renders (as ``_warm_up_render``): the scene of all
    rough materials, then each alone."""
    for only in (None, *range(len(_ROUGH_MATERIALS))):
        render(rough_warm_up_scene(only), RenderSettings(samples=1, threads=1, light_paths=4096, seed=0),
               should_cancel=stopped)


#: jit.warm_up's name of the rough surfaces' stage.
ROUGH_STAGE = "rough surfaces"


def _add_stage_stats(a: dict | None, b: dict | None) -> dict | None:
    """Two compile stages' stats as one (seconds and counts added)."""
    if a is None or b is None:
        return a if b is None else b
    out = {**a, **b}
    for k in ("compile_s", "kernels_compiled", "kernels_loaded"):
        out[k] = a.get(k, 0) + b.get(k, 0)
    return out


def compile_stage(mode: str, progress: Callable[[float, str], None] | None = None,
                  should_cancel: Callable[[], bool] | None = None, rough: bool = False,
                  core: bool = True) -> dict | None:
    """The compile stage of a render whose RenderSettings.kernels is ``mode``: once per process,
    when it takes the kernels, ``progress(0, 'compiling kernels')`` and a render of
    ``warm_up_scene`` (jit.warm_up); its stats ({'compile_s', 'kernels_compiled',
    'kernels_loaded'}) or None when it did not run. ``should_cancel``: the render's cancel check,
    polled while the stage runs (RenderCancelled within util/cancel.POLL_S; the stage then runs
    again in the next render). ``rough``: the scene has rough (GGX) surfaces: then also, once per
    process, the stage of ``rough_warm_up_scene`` (the GGX kernels: tens of seconds of compiling
    after an install, about 3 s from the cache, most of it the multiple-scattering tables the
    render needs anyway). ``core``: run the first stage (False: only the rough one). The rough
    stage is polled for a cancel, not for the time limit (it runs once per process)."""
    out = warm_up(_warm_up_render, progress, mode, should_cancel) if core else None
    if rough:
        out = _add_stage_stats(out, warm_up(_rough_warm_up_render, progress, mode, should_cancel, stage=ROUGH_STAGE))
    return out


def _cancelled_before_start(scene: Scene, settings: RenderSettings, region, spectral_film=None,
                            reason: str | None = None, cancelled_in: str = "while preparing the scene") -> RenderResult:
    """The (black, zero-sample) result of a render stopped before its first sample: cancelled
    (``cancelled_in`` says when), or out of time (``reason`` says so; the result is then not
    marked cancelled)."""
    cam = scene.camera
    x0, y0, x1, y1 = region if region is not None else (0, 0, int(cam.width), int(cam.height))
    film = Film(x1 - x0, y1 - y0, SpectralConverter(settings.grid()), spectral=keeps_spectral(settings, spectral_film))
    why = reason or f"cancelled {cancelled_in}"
    plan = RenderPlan(eye_pass=False, notes=(why,))
    return film.result(plan, reason is None, [why], {"rays": 0})


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
    executor: Executor | None = None,
    clock: Callable[[], float] = time.perf_counter,
    on_light: Callable[[LightPassResult], None] | None = None,
    keep_splat: int = 0,
) -> RenderResult:
    """Render a prepared scene (see ``render`` for the callbacks, ``region``, ``spectral_film``
    and ``keep_splat``).

    ``light``: a finished light pass of the same prepared scene (``prepared.with_view`` keeps it
    valid) to reuse; None runs the light pass when the plan asks for it. Where the plan splats
    and ``light``'s splat was made for another view, its kept splat vertices are splatted into
    this view (core/integrators/light/splat_vertices.py ``resplat``: shadow rays, no light paths;
    ``on_light`` receives the result, whose ``resplat`` holds the re-splat's stats, also in this
    render's: ``resplat_s``, ``resplat_vertices``, ``resplat_bytes``, ``resplat_rays``); without kept vertices the
    eye pass looks the caustic map up everywhere instead (``frame.light_reuse`` says when a
    caller should rather run the light pass again). ``started_at``: the
    ``clock()`` time the time limit counts from (default: now). ``executor``: where the units
    run (core/render/scheduler.py; default: a LocalExecutor on ``prepared.threads``;
    distributed.DaskExecutor for a cluster). ``clock``: the scheduler's clock, in seconds. The
    passes run the compiled kernels or the NumPy reference as ``settings.kernels`` says
    (core/util/jit.py); the stats' ``kernels`` names which. The process's first render on the
    kernels starts with the compile stage (``compile_stage``). ``on_light(result)``: receives the
    light pass's result when this render ran it (or re-splatted a given ``light``), so a caller can
    keep it for another render of the same prepared scene (the engine's persistent data between
    animation frames: blender/persistent.py).
    """
    local = executor is None or isinstance(executor, LocalExecutor)
    limit = float(prepared.settings.time_limit or 0.0)
    deadline = None if not limit else (time.perf_counter() if started_at is None or clock is not time.perf_counter
                                       else float(started_at)) + limit
    stop = None
    if should_cancel is not None or deadline is not None:  # polled while compiling (the time limit counts it here)
        def stop():
            return (should_cancel is not None and should_cancel()) or (deadline is not None and time.perf_counter() > deadline)
    try:
        compiled = compile_stage(prepared.settings.kernels, progress, stop,
                                 rough=bool(prepared.microfacet.any())) if local else None
    except RenderCancelled:
        out_of_time = deadline is not None and time.perf_counter() > deadline and not (should_cancel and should_cancel())
        return _cancelled_before_start(prepared.scene, prepared.settings, region, spectral_film,
                                       f"time limit ({limit:g} s) reached while compiling the kernels: nothing rendered"
                                       if out_of_time else None, cancelled_in="while compiling the kernels")
    return _render_in_mode(prepared, light, progress, should_cancel, on_round, region, started_at, spectral_film,
                           executor, clock, compiled, on_light, keep_splat)


def _render_in_mode(prepared, light, progress, should_cancel, on_round, region, started_at, spectral_film,
                    executor, clock, compiled, on_light=None, keep_splat: int = 0) -> RenderResult:
    """render_prepared after its compile stage (``compiled``: that stage's stats, or None)."""
    with kernel_mode(prepared.settings.kernels) as kernels:
        return _render_prepared(prepared, light, progress, should_cancel, on_round, region, started_at,
                                spectral_film, executor, clock, kernels, compiled, on_light, keep_splat)


def _render_prepared(prepared, light, progress, should_cancel, on_round, region, started_at, spectral_film,
                     executor, clock, kernels: str, compiled: dict | None = None, on_light=None,
                     keep_splat: int = 0) -> RenderResult:
    """render_prepared's body, inside its kernel mode (``kernels``: the path taken, for the stats;
    ``compiled``: the compile stage's stats when this render ran it)."""
    settings = prepared.settings
    control = RenderControl(should_cancel, progress, settings.time_limit, started_at, clock)
    plan = plan_render(prepared)
    warnings = list(prepared.warnings) + list(plan.warnings)
    blind = camera_sees_nothing(prepared)
    if blind is not None:
        warnings.append(blind)
    adaptive = adaptive_of(settings)
    spectral = keeps_spectral(settings, spectral_film)
    (rx0, ry0, rx1, ry1), film = Film.for_region(prepared.scene.camera, region, prepared.conv, adaptive is not None,
                                                 spectral)
    stats = {"rays": 0, "prepare_s": prepared.prepare_s, "backend": prepared.accel.name,
             "triangles": len(prepared.scene.triangles), "kernels": kernels, **(compiled or {})}
    executor = LocalExecutor() if executor is None else executor
    splat_images = None  # the light pass's camera splat over the region, once it ran

    def finish(cancelled, final=False):
        return film.result(plan, cancelled, warnings, stats, final=final, splat=splat_images)

    with executor:
        started = executor.start(prepared, (rx0, ry0, rx1, ry1), spectral, control)
        stats.update(executor.stats)
        if not started:  # cancelled while it got ready (waiting for workers)
            return finish(True, final=True)
        eye_from = 0.0  # where the eye pass's share of the progress starts
        if plan.light_pass and light is None:
            eye_from = LIGHT_PASS_SHARE
            light = executor.light_pass(prepared, plan, control, control.stage(0.0, LIGHT_PASS_SHARE),
                                        keep_vertices=keep_splat)
            if on_light is not None:
                on_light(light)
        elif not plan.light_pass:
            light = None
        elif (plan.camera_splat and not light.cancelled and usable_splat(prepared, light) is None
              and light.vertices is not None and light.vertices.usable):
            # a kept light pass seen through another camera: its splat vertices splatted into this view
            control.report(0.0, f"re-splatting {light.vertices.vertices / 1e6:.2f} M light-path vertices to the camera")
            again = resplat(prepared, light, should_cancel=control.cancelled)
            if again is None:  # cancelled: as a light pass cancelled midway, a black image
                light = replace(light, cancelled=True)
            else:
                light = again
                stats.update(light.resplat)
                stats["rays"] += light.resplat["resplat_rays"]
                if on_light is not None:
                    on_light(light)
        if light is not None:
            warnings += light.warnings
            stats.update(light.stats)
            stats["rays"] += light.stats.get("light_rays", 0)
        t_eye = clock()
        stop = "cancel" if light is not None and light.cancelled else ""  # Esc during the light pass
        if not stop:
            splat = usable_splat(prepared, light)  # the camera splat, if made for this view (else the map)
            splat_images = None if splat is None else splat.images(prepared.conv, (rx0, ry0, rx1, ry1))
            work = EyeWork.of(prepared, (rx0, ry0, rx1, ry1))
            executor.start_eye(prepared, plan, light, work)
            outcome = run_eye_pass(work, film, executor, control, adaptive,
                                   None if on_round is None else lambda: on_round(finish(False)),
                                   eye_from, stats["rays"])
            stats["rays"] += outcome.rays
            stop = outcome.stop
        stats.update(executor.stats)
    if stop == "time":
        warnings.append(f"time limit reached after {int(film.counts.min())} of {int(settings.samples)} samples per pixel")
    stats["render_s"] = clock() - control.started_at
    stats["mrays_per_s"] = stats["rays"] / max(clock() - t_eye + stats.get("light_pass_s", 0.0), 1e-9) / 1e6
    return finish(stop == "cancel", final=True)
