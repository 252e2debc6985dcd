"""Render the Cycles comparison scenes (tests/blender/parity_scenes.py) with Cycles and with
OPAL_DIFFRACTION in one bpy session and measure how far apart they are.

    python tools/cycles_parity.py [--ref-spp 4096] [--spp 64 256] [SCENE ...]   # a table for the scenes
    python tools/cycles_parity.py --png [SCENE ...]                              # plus side-by-side PNGs

The metrics (the [scenes] issue's "Must show", issue 10):

- **mean ratio**: mean Rec.709 luminance (0.2126 R + 0.7152 G + 0.0722 B) of ours over Cycles';
- **filtered relative RMSE**: both images box-filtered over 8 x 8 pixel blocks (block means of
  linear R, G, B), the RMS over blocks and channels of (ours - reference) divided by the
  reference's mean over blocks and channels. The box filter keeps the comparison about the
  image (shading, shadows, textures) and not about pixel noise;
- **noise floor**: the filtered relative RMSE that Monte Carlo noise alone gives. Each image is
  the mean of two renders with independent seeds at half the samples, A and B; (A - B) / 2 has
  the same variance as the noise of their mean (A + B) / 2, so per image the block noise is
  s = RMS_blocks((A - B) / 2), and the expected squared filtered error of two unbiased images is
  s_ours^2 + s_ref^2: floor = sqrt(s_ours^2 + s_ref^2) / mean(ref). What the measured error has
  beyond it is bias: bias = sqrt(max(E^2 - floor^2, 0)). The standard error of the mean ratio
  follows the same way from the luminance block noise over sqrt(blocks) (blocks are independent:
  the pixel filter reaches 1.5 px).

The Cycles reference (CPU, fixed seeds 101 and 102, denoiser and adaptive sampling off, no
clamping: parity_scenes.match_engines) is cached in out/parity/<scene>_cycles_<spp>_<key>.npz,
keyed by a hash of the scene sources (parity_scenes.py, blender_scenes.py) and the Blender
version, so reruns are fast. Times are wall-clock seconds of ``bpy.ops.render.render`` with 2
threads for both engines (ours includes the export from Blender and any light pass).
"""

from __future__ import annotations

import argparse
import hashlib
import os
import sys
import tempfile
import time
from dataclasses import dataclass

import numpy as np

from opal_diffraction._scripts import REPO_ROOT, load_script

LUMA = np.array([0.2126, 0.7152, 0.0722])
BLOCK = 8
OUT = os.path.join(REPO_ROOT, "out", "parity")
ENGINE = "OPAL_DIFFRACTION"
#: The two seeds of the Cycles reference's halves and of ours.
REF_SEEDS = (101, 102)
OUR_SEEDS = (1, 2)
#: Cycles at low samples in the table, for scale (another seed pair than the reference's).
CYCLES_LOW = 64
LOW_SEEDS = (7, 8)


def scenes_module():
    return load_script(os.path.join("tests", "blender", "parity_scenes.py"))


# ---------------------------------------------------------------------------- metrics
def luminance(img: np.ndarray) -> np.ndarray:
    return img[..., :3] @ LUMA


def box_filter(img: np.ndarray, block: int = BLOCK) -> np.ndarray:
    """Means over ``block`` x ``block`` pixel blocks of an (H, W, C) image (H, W multiples of block)."""
    h, w = img.shape[:2]
    if h % block or w % block:
        raise ValueError(f"image {w}x{h} is not a whole number of {block}x{block} blocks")
    return img.reshape(h // block, block, w // block, block, -1).mean(axis=(1, 3))


def filtered_rel_rmse(img: np.ndarray, ref: np.ndarray, block: int = BLOCK) -> float:
    """RMS over blocks and channels of box_filter(img - ref), over the mean of ref."""
    d = box_filter(img - ref, block)
    return float(np.sqrt(np.mean(d * d)) / box_filter(ref, block).mean())


@dataclass
class Render:
    """The mean of two renders at half the samples each, their half difference, and the time."""

    image: np.ndarray       # (H, W, 3) linear RGB, row 0 at the top
    half_diff: np.ndarray   # (A - B) / 2: noise of ``image`` without its signal
    samples: int
    seconds: float          # wall time of both halves

    def block_noise(self, block: int = BLOCK) -> float:
        """RMS over blocks and channels of the box-filtered noise of ``image``."""
        d = box_filter(self.half_diff, block)
        return float(np.sqrt(np.mean(d * d)))

    def luma_block_noise(self, block: int = BLOCK) -> float:
        d = box_filter(luminance(self.half_diff)[..., None], block)
        return float(np.sqrt(np.mean(d * d)))


@dataclass
class Comparison:
    scene: str
    mean_ratio: float
    mean_ratio_sigma: float     # standard error of mean_ratio from the noise of both images
    rel_rmse: float             # 8x8-box-filtered relative RMSE, ours vs reference
    noise_floor: float          # its expected value from noise alone
    ref: Render
    ours: Render                # the image compared (ours, or Cycles at low samples for scale)
    renderer: str = "ours"

    @property
    def bias(self) -> float:
        return float(np.sqrt(max(self.rel_rmse ** 2 - self.noise_floor ** 2, 0.0)))

    def row(self) -> str:
        return (f"| {self.scene} | {self.renderer} | {self.ours.samples} | {self.mean_ratio:.3f} +- "
                f"{self.mean_ratio_sigma:.3f} | "
                f"{self.rel_rmse:.3f} | {self.noise_floor:.3f} | {self.ours.seconds:.1f} | "
                f"{self.ref.samples} | {self.ref.seconds:.1f} |")


TABLE_HEAD = ("| scene | renderer | spp | mean ratio | filtered rel. RMSE | noise floor | s | reference spp | "
              "reference s |\n|---|---|---|---|---|---|---|---|---|")


def compare(scene: str, ours: Render, ref: Render, block: int = BLOCK, renderer: str = "ours") -> Comparison:
    """The metrics of ``ours`` against ``ref`` (see the module docstring)."""
    ref_mean = box_filter(ref.image, block).mean()
    floor = np.hypot(ours.block_noise(block), ref.block_noise(block)) / ref_mean
    lum_ref = luminance(ref.image).mean()
    n_blocks = (ref.image.shape[0] // block) * (ref.image.shape[1] // block)
    sigma = np.hypot(ours.luma_block_noise(block), ref.luma_block_noise(block)) / np.sqrt(n_blocks) / lum_ref
    return Comparison(scene, float(luminance(ours.image).mean() / lum_ref), float(sigma),
                      filtered_rel_rmse(ours.image, ref.image, block), float(floor), ref, ours, renderer)


# ---------------------------------------------------------------------------- rendering
def render_once(engine: str, samples: int, seed: int, path: str) -> tuple[np.ndarray, float]:
    """Render the current scene with ``engine`` at ``samples`` and ``seed`` to a float EXR and read
    it back: ((H, W, 3) linear RGB with row 0 at the top, wall seconds)."""
    import bpy

    from opal_diffraction.core.render.output import read_exr

    sc = bpy.context.scene
    sc.render.engine = engine
    if engine == "CYCLES":
        sc.cycles.samples = samples
        sc.cycles.seed = seed
        sc.cycles.use_animated_seed = False
    else:
        sc.opal.samples = samples
        sc.opal.seed = seed
        sc.opal.use_animated_seed = False
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    sc.render.filepath = path
    if os.path.exists(path):
        os.remove(path)
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    seconds = time.perf_counter() - t0
    ch = read_exr(path)
    return np.stack([ch["R"], ch["G"], ch["B"]], axis=-1).astype(np.float64), seconds


def render_pair(engine: str, samples: int, seeds: tuple[int, int], work_dir: str) -> Render:
    """Two renders of ``samples // 2`` with the two seeds: their mean is an image of ``samples``."""
    half = max(1, samples // 2)
    a, ta = render_once(engine, half, seeds[0], os.path.join(work_dir, f"{engine}_a.exr"))
    b, tb = render_once(engine, half, seeds[1], os.path.join(work_dir, f"{engine}_b.exr"))
    return Render((a + b) / 2, (a - b) / 2, 2 * half, ta + tb)


def build(scene: str, work_dir: str):
    """Build ``scene`` in the current bpy session (images saved in ``work_dir``)."""
    return scenes_module().build(scene, work_dir)


def warm_up(work_dir: str) -> None:
    """One render of each engine at 1 sample (the first scene), so the first timed render does not
    pay for imports and first-use setup (Embree, OpenEXR, kernels)."""
    build(next(iter(scenes_module().SCENES)), work_dir)
    for engine in ("CYCLES", ENGINE):
        render_once(engine, 1, 0, os.path.join(work_dir, "warm_up.exr"))


def cache_key(scene: str, samples: int) -> str:
    """A hash of the scene sources, the scene's name, the reference's samples and seeds and the
    Blender version: a cached reference is reused only for the same scene and renderer."""
    import bpy

    h = hashlib.sha256()
    for rel in ("tests/blender/parity_scenes.py", "tests/blender/blender_scenes.py"):
        with open(os.path.join(REPO_ROOT, rel), "rb") as f:
            h.update(f.read())
    h.update(f"{scene} {samples} {REF_SEEDS} {bpy.app.version_string}".encode())
    return h.hexdigest()[:12]


def cycles_reference(scene: str, samples: int, work_dir: str, cache_dir: str | None = OUT) -> Render:
    """Cycles' reference of the scene built in the session: from the cache when there, else
    rendered (two halves with REF_SEEDS) and cached. ``cache_dir`` None: no cache."""
    path = None
    if cache_dir is not None:
        path = os.path.join(cache_dir, f"{scene}_cycles_{samples}_{cache_key(scene, samples)}.npz")
        if os.path.exists(path):
            z = np.load(path)
            return Render(z["image"], z["half_diff"], int(z["samples"]), float(z["seconds"]))
    ref = render_pair("CYCLES", samples, REF_SEEDS, work_dir)
    if path is not None:
        os.makedirs(cache_dir, exist_ok=True)
        np.savez(path + ".tmp.npz", image=ref.image, half_diff=ref.half_diff, samples=ref.samples,
                 seconds=ref.seconds)
        os.replace(path + ".tmp.npz", path)
    return ref


def measure(scene: str, our_samples: int, ref_samples: int, work_dir: str | None = None,
            cache_dir: str | None = OUT, seeds: tuple[int, int] = OUR_SEEDS) -> Comparison:
    """Build ``scene``, get Cycles' reference at ``ref_samples`` and render ours at ``our_samples``
    (two halves with ``seeds``); the comparison."""
    with tempfile.TemporaryDirectory(prefix="parity_") as tmp:
        work = work_dir or tmp
        build(scene, work)
        ref = cycles_reference(scene, ref_samples, work, cache_dir)
        ours = render_pair(ENGINE, our_samples, seeds, work)
    return compare(scene, ours, ref)


# ---------------------------------------------------------------------------- pictures
def side_by_side_png(path: str, ref: np.ndarray, ours: np.ndarray, scale: int = 4) -> None:
    """A PNG of Cycles | ours | difference, each ``scale`` x enlarged (nearest). Both images go
    through the same exposure (the reference's 99th luminance percentile maps to 1) and the sRGB
    curve; the difference panel shows ours - Cycles in luminance, red where ours is brighter,
    blue where darker, at the same exposure."""
    from opal_diffraction.core.render.output import write_png

    scale_to = 1.0 / max(np.percentile(luminance(ref), 99), 1e-6)
    d = (luminance(ours) - luminance(ref)) * scale_to
    diff = np.stack([np.clip(d, 0, None), np.zeros_like(d), np.clip(-d, 0, None)], axis=-1)
    gap = np.ones((ref.shape[0], 2, 3))
    panel = np.concatenate([ref * scale_to, gap, ours * scale_to, gap, diff], axis=1)
    panel = np.repeat(np.repeat(panel, scale, axis=0), scale, axis=1)
    write_png(path, panel.astype(np.float32))


# ---------------------------------------------------------------------------- main
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="*", help="scene names (default: all)")
    ap.add_argument("--ref-spp", type=int, default=4096, help="Cycles reference samples (cached)")
    ap.add_argument("--spp", type=int, nargs="+", default=[64, 256], help="our samples (one row each)")
    ap.add_argument("--png", action="store_true", help="write out/parity/<scene>.png (Cycles | ours | diff)")
    ap.add_argument("--no-cache", action="store_true", help="render the reference even when cached")
    args = ap.parse_args(argv)

    import opal_diffraction

    opal_diffraction.register()
    try:
        names = args.scenes or list(scenes_module().SCENES)
        print(f"Cycles reference {args.ref_spp} spp; ours at {args.spp} spp and Cycles at {CYCLES_LOW} spp against "
              "it; 8x8-box-filtered metrics; seconds for both half renders\n")
        with tempfile.TemporaryDirectory(prefix="parity_") as work:
            warm_up(work)
        print(TABLE_HEAD)
        for name in names:
            with tempfile.TemporaryDirectory(prefix="parity_") as work:
                build(name, work)
                ref = cycles_reference(name, args.ref_spp, work, None if args.no_cache else OUT)
                for spp in args.spp:
                    c = compare(name, render_pair(ENGINE, spp, OUR_SEEDS, work), ref)
                    print(c.row(), flush=True)
                print(compare(name, render_pair("CYCLES", CYCLES_LOW, LOW_SEEDS, work), ref,
                              renderer="Cycles").row(), flush=True)
            if args.png:
                os.makedirs(OUT, exist_ok=True)
                side_by_side_png(os.path.join(OUT, f"{name}.png"), c.ref.image, c.ours.image)
    finally:
        opal_diffraction.unregister()
    return 0


if __name__ == "__main__":
    sys.exit(main())
