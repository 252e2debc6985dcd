"""One render: validate, prepare, plan the passes, run them over tiles, and return the film.

The image is split into tiles and the samples into progressive rounds. Every (round, tile) batch
draws its random numbers from its own stream, ``SeedSequence([seed, pass, round, tile])``, and
writes only its own pixels, so the image is identical whatever the number of threads (and,
later, machines); rounds make time limits, cancellation and partial previews cheap.
"""

from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .accel import build_accelerator
from .camera import FilterSampler, generate_rays, pixel_samples
from .eye_pass import EyePass
from .gratings import prepare_gratings, triangle_tangents
from .lights import prepare_lights
from .materials import prepare_materials
from .light_pass import LightPass
from .plan import RenderPlan, plan_render
from .scene import Scene, SceneError
from .settings import RenderSettings
from .spectrum import SpectralConverter

__all__ = ["RenderContext", "RenderResult", "render"]

EYE_PASS_STREAM = 1  # stream ids keep the passes' random numbers independent
LIGHT_PASS_SHARE = 0.25  # of the progress bar, when the light pass runs


@dataclass
class RenderContext:
    """A validated scene prepared for tracing: acceleration structure, spectra, offsets."""

    scene: Scene
    settings: RenderSettings
    conv: SpectralConverter
    accel: object
    materials: object
    lights: object
    tri_normal: np.ndarray
    tri_offset: np.ndarray  # (T,) float32 self-intersection offset per triangle
    tri_material: np.ndarray
    gratings: object              # gratings.PreparedGratings
    tri_grating_tangent: np.ndarray  # (T, 3) unit grating vectors in each triangle's plane
    tri_period: np.ndarray        # (T,) nm per-triangle period override (0: the material's), or empty
    world_spectrum: np.ndarray
    offset_base: float
    caustics: object = None  # elements.IlluminationMap from the light pass, or None
    grating_records: object = None  # elements.IlluminationMap with directions, at gratings, or None

    @property
    def grid(self):
        return self.conv.grid

    @staticmethod
    def triangle_offsets(v: np.ndarray, t: np.ndarray, base: float) -> np.ndarray:
        """Self-intersection offset per triangle: scene-scaled ``base`` plus float32 rounding of
        its largest |coordinate| (looked up per hit, so no per-hit reduction)."""
        if len(t) == 0:
            return np.zeros(0, np.float32)
        return (base + 4e-7 * np.abs(v[t]).max(axis=(1, 2))).astype(np.float32)

    @classmethod
    def prepare(cls, scene: Scene, settings: RenderSettings, conv: SpectralConverter | None = None) -> "RenderContext":
        conv = conv or SpectralConverter(settings.grid())
        v = np.asarray(scene.vertices, np.float32)
        t = np.asarray(scene.triangles, np.int32)
        p = v[t].astype(np.float64)
        nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]) if len(t) else np.zeros((0, 3))
        nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)
        extent = float(np.max(np.ptp(v, axis=0))) if len(v) else 1.0
        base = 1e-5 * max(extent, 1e-3)
        gratings = prepare_gratings(scene.materials)
        return cls(
            scene=scene,
            settings=settings,
            conv=conv,
            accel=build_accelerator(v, t, settings.backend),
            materials=prepare_materials(scene.materials, conv),
            lights=prepare_lights(scene.lights, conv),
            tri_normal=nrm.astype(np.float32),
            tri_offset=cls.triangle_offsets(v, t, base),
            tri_material=np.asarray(scene.tri_material, np.int32),
            gratings=gratings,
            # only a scene with gratings pays for their frames
            tri_grating_tangent=(triangle_tangents(nrm, scene.tri_tangent) if gratings.any
                                 else np.zeros((0, 3), np.float32)),
            tri_period=np.asarray(scene.tri_period, np.float32).reshape(-1),
            world_spectrum=conv.illuminant_from_rgb(np.asarray(scene.world_color, np.float64)).astype(np.float32),
            offset_base=base,
        )


@dataclass
class RenderResult:
    spectral: np.ndarray          # (H, W, n) float32 mean spectral radiance, row 0 at the top
    rgb: np.ndarray               # (H, W, 3) float32 linear Rec.709
    wavelengths: np.ndarray       # (n,) nm
    samples: int                  # samples per pixel actually taken
    cancelled: bool
    plan: RenderPlan
    warnings: list[str] = field(default_factory=list)
    stats: dict = field(default_factory=dict)
    # AOVs for the compositor, (H, W, 3) linear RGB: Direct (light reaching diffuse surfaces by
    # shadow rays, also seen through mirrors and glass), Caustics (the light pass; zero until it
    # lands), Diffraction (gratings; zero until they land). Combined = Direct + Caustics +
    # Diffraction + emitted light seen (the world and emissive surfaces, directly or via specular).
    passes: dict = field(default_factory=dict)


class _Inline:
    """A future-like wrapper that runs its call lazily in the calling thread."""

    def __init__(self, fn, *args):
        self.fn, self.args = fn, args

    def result(self):
        return self.fn(*self.args)

    def cancel(self):
        pass


def _tiles(width: int, height: int, size: int, region):
    """Tiles of the full image's grid that meet ``region``, clipped to it, in region coordinates,
    each with its stream id (its index in the full grid, so a region render aligned to tile
    boundaries reproduces the full render's pixels exactly)."""
    rx0, ry0, rx1, ry1 = region
    per_row = -(-width // size)
    out = []
    for ty in range(ry0 // size, -(-ry1 // size)):
        for tx in range(rx0 // size, -(-rx1 // size)):
            x0, y0 = max(tx * size, rx0), max(ty * size, ry0)
            x1, y1 = min((tx + 1) * size, rx1), min((ty + 1) * size, ry1)
            out.append((x0 - rx0, y0 - ry0, x1 - rx0, y1 - ry0, ty * per_row + tx))
    return out


def render(
    scene: Scene,
    settings: RenderSettings | None = None,
    progress: Callable[[float, str], None] | None = None,
    should_cancel: Callable[[], bool] | None = None,
    on_round: Callable[[RenderResult], None] | None = None,
    region: tuple[int, int, int, int] | None = None,
) -> RenderResult:
    """Render ``scene``; raises SceneError (a readable message) for unrenderable input.

    ``progress(fraction, message)`` is called after every tile; ``should_cancel()`` is polled
    between tiles and stops the render early (the result holds the finished rounds);
    ``on_round(result)`` receives the partial image after every round. ``region`` = (x0, y0, x1,
    y1) renders only those pixels of the camera's image (a border render; rows from the top); the
    result then has shape (y1 - y0, x1 - x0).
    """
    settings = settings or RenderSettings()
    settings.validate()
    t_start = time.perf_counter()
    scene, warnings = scene.validated()
    ctx = RenderContext.prepare(scene, settings)
    light_pass = LightPass(ctx)
    plan = plan_render(ctx, light_pass)
    warnings += plan.warnings
    cam = scene.camera
    rx0, ry0, rx1, ry1 = region if region is not None else (0, 0, int(cam.width), int(cam.height))
    if not (0 <= rx0 < rx1 <= int(cam.width) and 0 <= ry0 < ry1 <= int(cam.height)):
        raise SceneError(f"render region {region} is outside the {cam.width}x{cam.height} image")
    w, h, nl = rx1 - rx0, ry1 - ry0, ctx.grid.n
    film = np.zeros((h, w, nl), np.float32)
    background_rgb = np.zeros((h, w, 3), np.float32)  # for the Direct pass: Combined minus emitted light
    diffraction_rgb = np.zeros((h, w, 3), np.float32)  # the Diffraction pass
    caustics_rgb = np.zeros((h, w, 3), np.float32)  # the Caustics pass
    counts = np.zeros((h, w), np.float32)  # samples per pixel so far (tiles may differ after a cancel)
    t_prep = time.perf_counter() - t_start

    spp = int(settings.samples)
    rounds = [min(settings.round_samples, spp - s) for s in range(0, spp, settings.round_samples)]
    tiles = _tiles(int(cam.width), int(cam.height), int(settings.tile_size), (rx0, ry0, rx1, ry1))
    filt = FilterSampler(settings.filter_width)
    eye = EyePass(ctx)
    threads = settings.threads or os.cpu_count() or 1
    stats = {"rays": 0, "prepare_s": t_prep, "backend": ctx.accel.name, "triangles": len(scene.triangles)}
    if plan.light_pass:
        t0 = time.perf_counter()
        lp_progress = (lambda f, m: progress(LIGHT_PASS_SHARE * f, m)) if progress else None
        ctx.caustics, ctx.grating_records, lp_stats = light_pass.run(int(settings.light_paths), lp_progress,
                                                                     should_cancel)
        if lp_stats.pop("warning", ""):
            warnings.append(light_pass.coarsened)
        stats.update(lp_stats)
        stats["rays"] += lp_stats["light_rays"]
        stats["light_pass_s"] = time.perf_counter() - t0
    done_samples, cancelled = 0, bool(stats.get("cancelled"))  # Esc during the light pass
    total_work = len(rounds) * len(tiles)

    def run_tile(r_index, r_spp, t_index):
        x0, y0, x1, y1, stream = tiles[t_index]
        rng = np.random.default_rng(np.random.SeedSequence([int(settings.seed), EYE_PASS_STREAM, r_index, stream]))
        ys, xs = np.mgrid[y0 + ry0:y1 + ry0, x0 + rx0:x1 + rx0]
        sx, sy, sl, pidx = pixel_samples(xs.ravel().astype(np.float64), ys.ravel().astype(np.float64), r_spp, rng, filt)
        o, d = generate_rays(cam, sx, sy)
        res = eye.trace(o, d, pidx, (y1 - y0) * (x1 - x0), rng, u_lambda=sl)
        return t_index, res

    def finish():
        scale = (1.0 / np.maximum(counts, 1.0))[..., None]
        spectral = film * scale
        rgb = ctx.conv.to_rgb(spectral)
        diffraction = diffraction_rgb * scale
        caustics = caustics_rgb * scale
        passes = {"Direct": rgb - background_rgb * scale - diffraction - caustics, "Caustics": caustics,
                  "Diffraction": diffraction}
        return RenderResult(spectral, rgb, ctx.grid.wavelengths.copy(), int(counts.min()) if counts.size else 0,
                            cancelled, plan, warnings, dict(stats), passes)

    work_done = 0
    with ThreadPoolExecutor(max_workers=threads) as pool:
        for r_index, r_spp in enumerate(rounds):
            if cancelled:
                break
            if plan.eye_pass:
                if threads > 1:
                    pending = [pool.submit(run_tile, r_index, r_spp, ti) for ti in range(len(tiles))]
                else:  # in the calling thread: simpler to profile and debug
                    pending = [_Inline(run_tile, r_index, r_spp, ti) for ti in range(len(tiles))]
                for fut in pending:
                    if cancelled:
                        fut.cancel()
                        continue
                    t_index, res = fut.result()
                    x0, y0, x1, y1, _ = tiles[t_index]
                    film[y0:y1, x0:x1] += res.film.reshape(y1 - y0, x1 - x0, nl)
                    if res.caustics is not None:
                        caustics_rgb[y0:y1, x0:x1] += ctx.conv.to_rgb(res.caustics).reshape(y1 - y0, x1 - x0, 3)
                    if res.diffraction is not None:
                        diffraction_rgb[y0:y1, x0:x1] += ctx.conv.to_rgb(res.diffraction).reshape(y1 - y0, x1 - x0, 3)
                    if res.background is not None:
                        background_rgb[y0:y1, x0:x1] += ctx.conv.to_rgb(res.background).reshape(y1 - y0, x1 - x0, 3)
                    counts[y0:y1, x0:x1] += r_spp
                    stats["rays"] += res.rays
                    work_done += 1
                    if progress:
                        base = LIGHT_PASS_SHARE if plan.light_pass else 0.0
                        progress(base + (1 - base) * work_done / total_work,
                                 f"eye pass: round {r_index + 1}/{len(rounds)}, {stats['rays'] / 1e6:.1f} M rays")
                    if should_cancel and should_cancel():
                        cancelled = True
                if cancelled:
                    break  # tiles finished in this round keep their extra samples (counts say so)
            done_samples += r_spp
            if on_round:
                on_round(finish())
            if settings.time_limit and time.perf_counter() - t_start > settings.time_limit and r_index + 1 < len(rounds):
                warnings.append(f"time limit reached after {done_samples} of {spp} samples per pixel")
                break
    stats["render_s"] = time.perf_counter() - t_start
    stats["mrays_per_s"] = stats["rays"] / max(stats["render_s"] - t_prep, 1e-9) / 1e6
    return finish()
