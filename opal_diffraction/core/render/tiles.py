"""The eye pass's units of work: rounds of samples x tiles of pixels, each with its own stream.

The image is split into tiles and the samples into progressive rounds. Every (round, tile) unit
draws its random numbers from its own stream, ``SeedSequence([seed, EYE_PASS_STREAM, round,
tile])``, and writes only its own pixels; the film adds the units round by round, so the image
is the same whatever runs them: threads or Dask workers (the executors of scheduler.py).
``EyeWork`` is the split (a pure function of the prepared scene and the region), ``trace_tile``
runs one unit. With adaptive sampling (core/render/adaptive.py) a unit may trace only some of its
tile's pixels: which ones follows from the film after the tile's earlier rounds, so it is the
same wherever the units run; the even rounds are the "A" half of the error estimate
(``is_half_a``). With motion blur each camera sample takes a time across the shutter, and with
object motion (``PreparedScene.motion_bins``) each path is traced in its time bin's geometry
(docs/physics.md section 6.13).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, fields, replace

import numpy as np

from ..sampling.camera import (FilterSampler, camera_rays, has_lens, has_motion, lens_samples, pixel_samples,
                               shutter_times, time_samples)
from ..sampling.footprint import camera_differentials, filter_box_width
from ..sampling.sampler import blue_noise_numbers
from ..scene.settings import RenderSettings
from .adaptive import min_samples

__all__ = ["EYE_PASS_STREAM", "LIGHT_PASS_SHARE", "MAX_TILE_RAYS", "round_size", "tiles_of", "EyeWork",
           "trace_tile", "is_half_a", "adaptive_of", "adaptive_rounds"]

EYE_PASS_STREAM = 1  # stream ids keep the passes' random numbers independent
LIGHT_PASS_SHARE = 0.25  # of the progress bar, when the light pass runs
MAX_TILE_RAYS = 1 << 18  # camera rays of one tile in one round (bounds memory and the work a stop drops)
#: The cap with a spectral EXR, whose (H, W, n) films leave less room for the rounds' rays: a
#: 64 x 64 tile at 8 samples. Full HD at 61 wavelengths: peak RSS 2.08 GiB with rounds of 16
#: samples, 1.82 GiB with 8 (docs/benchmarks.md, "Memory with rounds of 16 samples").
MAX_TILE_RAYS_SPECTRAL = 1 << 15


def tile_ray_cap(settings: RenderSettings) -> int:
    """The most camera rays one tile's round may cast under these settings."""
    return MAX_TILE_RAYS_SPECTRAL if getattr(settings, "spectral_exr", "") else MAX_TILE_RAYS


def round_size(settings: RenderSettings) -> int:
    """Samples per pixel per round: the setting, capped so one tile's round casts at most
    tile_ray_cap camera rays (a round is the unit of memory, and of the work a cancel or time
    limit drops: scheduler.py)."""
    tile_pixels = int(settings.tile_size) ** 2
    return max(1, min(int(settings.round_samples), tile_ray_cap(settings) // tile_pixels))


def is_half_a(r_index: int) -> bool:
    """Whether round ``r_index``'s samples go into adaptive sampling's half A (the even rounds)."""
    return r_index % 2 == 0


def adaptive_of(settings: RenderSettings):
    """(threshold, min samples) of adaptive sampling, or None when it is off."""
    t = float(settings.adaptive_threshold)
    return None if t <= 0 else (t, min_samples(t, int(settings.adaptive_min_samples)))


def adaptive_rounds(spp: int, per_round: int, min_spp: int, cap: int) -> tuple[int, ...]:
    """Round sizes with adaptive sampling: ``per_round`` samples up to the minimum, then rounds
    of a quarter of the samples taken so far (at least ``per_round``, at most ``cap``), so the
    pixels that go on sampling do so in a few larger rounds (each round of a tile is one call of
    the tracer, whose fixed cost dominates when few pixels are left), overshooting what they
    need by at most a quarter."""
    rounds, taken = [], 0
    while taken < spp:
        n = per_round if taken < min_spp else max(per_round, min(cap, taken // 4))
        n = min(n, spp - taken)
        rounds.append(n)
        taken += n
    return tuple(rounds)


def tiles_of(width: int, height: int, size: int, region):
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


@dataclass(frozen=True)
class EyeWork:
    """The eye pass of one render: samples per round, tiles (x0, y0, x1, y1, stream) in region
    coordinates, the region (x0, y0, x1, y1) of the camera's image, the seed, and whether pixels
    share one blue-noise ordered sequence (settings.blue_noise)."""

    rounds: tuple[int, ...]
    tiles: tuple[tuple[int, int, int, int, int], ...]
    region: tuple[int, int, int, int]
    seed: int
    blue_noise: bool = False

    @classmethod
    def of(cls, prepared, region=None) -> "EyeWork":
        settings, cam = prepared.settings, prepared.scene.camera
        region = tuple(region) if region is not None else (0, 0, int(cam.width), int(cam.height))
        spp, per_round = int(settings.samples), round_size(settings)
        adaptive = adaptive_of(settings)
        if adaptive is None and float(settings.time_limit) > 0 and spp > 1:
            # a time limit may stop the render in any round (scheduler.py): a first round of one
            # sample gives the whole image a sample 1/per_round of a round's time after the start
            rounds = (1,) + tuple(min(per_round, spp - 1 - s) for s in range(0, spp - 1, per_round))
        elif adaptive is None:
            rounds = tuple(min(per_round, spp - s) for s in range(0, spp, per_round))
        else:
            rounds = adaptive_rounds(spp, per_round, adaptive[1], tile_ray_cap(settings) // int(settings.tile_size) ** 2)
        tiles = tuple(tiles_of(int(cam.width), int(cam.height), int(settings.tile_size), region))
        return cls(rounds, tiles, region, int(settings.seed), bool(getattr(settings, "blue_noise", True)))

    @property
    def units(self) -> int:
        return len(self.rounds) * len(self.tiles)


def trace_tile(eye, filt: FilterSampler, work: EyeWork, r_index: int, t_index: int, pixels=None):
    """Trace tile ``t_index`` of round ``r_index`` with ``eye`` (an eye_pass.EyePass):
    its eye_pass.TileResult. ``pixels``: the tile's flat pixel indices (row-major) to sample,
    the others take no sample this round (adaptive sampling); the result's rows are those
    pixels, in that order. None: every pixel (the same stream either way)."""
    x0, y0, x1, y1, stream = work.tiles[t_index]
    rx0, ry0 = work.region[:2]
    rng = np.random.default_rng(np.random.SeedSequence([work.seed, EYE_PASS_STREAM, r_index, stream]))
    ys, xs = np.mgrid[y0 + ry0:y1 + ry0, x0 + rx0:x1 + rx0]
    xs, ys = xs.ravel(), ys.ravel()
    if pixels is not None:
        xs, ys = xs[pixels], ys[pixels]
    # low-discrepancy numbers per pixel (core/sampling/sampler.py), numbered on across rounds
    cam = eye.prepared.scene.camera
    ids = (ys.astype(np.int64) * int(cam.width) + xs).astype(np.uint32)
    first = int(sum(work.rounds[:r_index]))
    spp = work.rounds[r_index]
    starts = np.full(len(xs), first, np.uint32)
    if work.blue_noise:  # one shared sequence, a block per pixel in blue-noise order (core/sampling/sampler.py)
        blocks = blue_noise_numbers(xs, ys, cam.width, cam.height, sum(work.rounds), work.seed)
        if blocks is not None:
            ids, starts = np.zeros(len(xs), np.uint32), blocks + np.uint32(first)
    sx, sy, sl, pidx = pixel_samples(xs.astype(np.float64), ys.astype(np.float64), spp, rng, filt,
                                     qmc=(ids, starts, work.seed))
    lens = lens_samples(len(xs), spp, rng, (ids, starts, work.seed)) if has_lens(cam) else None
    # motion blur: each sample's time across the shutter (docs/physics.md section 6.13)
    bins = getattr(eye.prepared, "motion_bins", ())
    moving = has_motion(cam) or len(bins) > 0
    times = shutter_times(cam, time_samples(len(xs), spp, rng, (ids, starts, work.seed))) if moving else None
    # thin lens, clipping, panoramas, motion (core/sampling/camera.py); tmax: clip end, None: unbounded
    o, d, tmax, valid = camera_rays(cam, sx, sy, lens, times)
    rd = None
    if eye.wants_differentials:  # ray differentials for gratings (core/sampling/footprint.py)
        rd = camera_differentials(cam, d, (sx - xs[pidx] - 0.5, sy - ys[pidx] - 0.5), filter_box_width(filt.width))
    sids = (ids[pidx], (starts[:, None] + np.arange(spp, dtype=np.uint32)).ravel(), work.seed)
    if valid is not None:  # a fisheye's samples outside its circle see nothing (count as black)
        o, d, pidx, sl, tmax = o[valid], d[valid], pidx[valid], sl[valid], tmax[valid]
        sids = (sids[0][valid], sids[1][valid], sids[2])
        rd = None if rd is None else rd[valid]
        times = None if times is None else times[valid]
    if len(bins) and len(o):  # object motion: each ray in its time bin's geometry
        return _trace_bins(eye, bins, times, o, d, pidx, len(xs), rng, sl, sids, rd, tmax)
    return eye.trace(o, d, pidx, len(xs), rng, u_lambda=sl, sampler_ids=sids, differentials=rd, tmax=tmax)


def _bin_eye(eye, bins, k: int):
    """``eye`` seeing time bin ``k``'s geometry (its ray caster and triangle frames; the rest of the
    prepared scene, and the light pass's result, the frame's), made once per eye pass."""
    cache = eye.__dict__.setdefault("_motion_eyes", {})
    if k not in cache:
        b = bins[k]
        e = copy.copy(eye)
        e.prepared = replace(eye.prepared, accel=b.accel, tri_normal=b.tri_normal, tri_offset=b.tri_offset)
        e.constants = replace(eye.constants, prepared=e.prepared)  # next-event shadow rays read it there
        cache[k] = e
    return cache[k]


def _trace_bins(eye, bins, times, o, d, pidx, n_pixels, rng, sl, sids, rd, tmax):
    """Object motion (docs/physics.md section 6.13): the rays of time t traced by the eye of bin
    floor(t K); the tile's sums are the bins' sums added."""
    k_of = np.minimum((np.asarray(times) * len(bins)).astype(np.int64), len(bins) - 1)
    parts = []
    for k in np.unique(k_of):
        sel = np.flatnonzero(k_of == k)
        parts.append(_bin_eye(eye, bins, int(k)).trace(
            o[sel], d[sel], pidx[sel], n_pixels, rng, u_lambda=sl[sel],
            sampler_ids=(sids[0][sel], sids[1][sel], sids[2]),
            differentials=None if rd is None else rd[sel], tmax=None if tmax is None else tmax[sel]))
    return _add_results(parts)


def _add_results(parts):
    """One TileResult of several over the same pixels: every per-pixel sum and the ray counts added
    (a part without a pass contributes nothing to it)."""
    if len(parts) == 1:
        return parts[0]
    out = {}
    for f in fields(parts[0]):
        vals = [getattr(p, f.name) for p in parts]
        have = [v for v in vals if v is not None]
        if not have:
            out[f.name] = None
        elif isinstance(have[0], np.ndarray):
            total = np.array(have[0], copy=True)
            for v in have[1:]:
                total = total + v
            out[f.name] = total
        else:
            out[f.name] = sum(have)
    return type(parts[0])(**out)
