"""The CD's speckle before and after the grating lobe's MIS (issue 26; docs/physics.md section 3.13).

Renders an example grating scene (examples/gratings.py, built from this checkout's file) with
whichever opal_diffraction is importable (PYTHONPATH: this branch, or an export of main for
"before"), one thread, and saves the linear RGB image; ``--compare REF IMG...`` prints each
image's relative RMSE against a high-sample reference (per pixel, over the reference's mean
luminance), the same after a 4 x 4 box filter, and the share of pixels whose luminance is more
than 1 (in units of the reference's mean) away from the reference's (speckle).

    PYTHONPATH=. python benchmarks/bench_cd_speckle.py render cd_room 80 60 16 1 after16.npy
    PYTHONPATH=/tmp/main python benchmarks/bench_cd_speckle.py render cd_room 80 60 16 1 before16.npy
    python benchmarks/bench_cd_speckle.py compare ref.npy before16.npy after16.npy
    PYTHONPATH=. python benchmarks/bench_cd_speckle.py docs cd_room 240 180 16 docs/cd_room.png

``docs``: the docs' image of an example (the PNG ``examples/gratings.py`` writes through the
CLI, exposure 0), after checking that the linear image has no negative and no non-finite pixel.
"""

import importlib.util
import os
import sys
import time

import numpy as np

Y = np.array([0.2126729, 0.7151522, 0.0721750])


def load_examples():
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "examples", "gratings.py")
    spec = importlib.util.spec_from_file_location("grating_examples", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def render_one(name, width, height, spp, seed, out):
    from opal_diffraction.core.render.frame import render
    from opal_diffraction.core.scene.settings import RenderSettings

    scene = load_examples().SCENES[name](width, height)
    t0 = time.process_time()
    res = render(scene, RenderSettings(samples=spp, threads=1, seed=seed))
    cpu = time.process_time() - t0
    rgb = np.asarray(res.rgb, np.float64)
    print(f"{name} {width}x{height} {spp} spp seed {seed}: CPU {cpu:.1f} s, min {rgb.min():.4g}, "
          f"finite {bool(np.isfinite(rgb).all())}, mean {rgb.mean():.5f}")
    np.save(out, rgb)


def box4(img):
    h, w = img.shape[0] // 4 * 4, img.shape[1] // 4 * 4
    return img[:h, :w].reshape(h // 4, 4, w // 4, 4).mean(axis=(1, 3))


def compare(ref_path, paths):
    ref = np.load(ref_path) @ Y
    scale = ref.mean()
    for p in paths:
        img = np.load(p) @ Y
        err = (img - ref) / scale
        rmse = np.sqrt(np.mean(err ** 2))
        rmse4 = np.sqrt(np.mean(((box4(img) - box4(ref)) / scale) ** 2))
        speckle = np.mean(np.abs(err) > 1.0)
        print(f"{os.path.basename(p)}: rel RMSE {rmse:.3f}, 4x4 {rmse4:.3f}, speckle (|dY| > mean) {speckle:.4f}, "
              f"mean / ref {img.mean() / ref.mean():.4f}")


def docs_image(name, width, height, spp, out):
    from opal_diffraction.core.render.output import write_png

    tmp = out + ".npy"
    render_one(name, width, height, spp, 0, tmp)
    rgb = np.load(tmp)
    os.unlink(tmp)
    if not (np.isfinite(rgb).all() and rgb.min() >= 0):
        raise SystemExit(f"{name}: negative or non-finite pixels (min {rgb.min()}), not written")
    write_png(out, rgb.astype(np.float32), 0.0)


if __name__ == "__main__":
    if sys.argv[1] == "docs":
        a = sys.argv[2:]
        docs_image(a[0], int(a[1]), int(a[2]), int(a[3]), a[4])
    elif sys.argv[1] == "render":
        a = sys.argv[2:]
        render_one(a[0], int(a[1]), int(a[2]), int(a[3]), int(a[4]), a[5])
    else:
        compare(sys.argv[2], sys.argv[3:])
