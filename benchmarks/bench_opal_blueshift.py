"""Measurement (not a test): the blue shift of the opal example's flashes as the camera orbits
(the [opal] issue's "patches ... blue-shift as the camera orbits 10 degrees").

Renders examples/opal.py's black opal from camera elevations 35 and 45 degrees (the example's
orbit frames) with the spectral EXR on, finds the flashing pixels of each frame (spectral peak
over 8x the pixel's median and in the image's brightest 3 %), and prints the median ratio of
the spectral centroids (above the pixel's median) on the pixels that flash in both frames,
beside the Bragg law's ratio for the mean geometry: planes at the mirror of lamp and camera
(lamp 50 degrees up from +Y, camera from -Y), half-angle theta = (180 - 50 - elevation) / 2,
lambda proportional to sqrt(n_eff^2 - sin^2 theta) (docs/physics.md section 5.2).

    .venv/bin/python benchmarks/bench_opal_blueshift.py [--resolution 256 256] [--spp 16]
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile

import numpy as np

from opal_diffraction._scripts import load_example

N_EFF_BLACK = 1.4198  # the Black preset: silica spheres, water voids (docs/opal.md)


def spectral_image(path: str) -> tuple[np.ndarray, np.ndarray]:
    """(wavelengths (K,), spectra (H, W, K)) of a spectral EXR the engine wrote."""
    from opal_diffraction.core.render.output import read_exr

    ch = read_exr(path)
    names = sorted((k for k in ch if k.startswith("S0.")), key=lambda k: float(k[3:-2].replace(",", ".")))
    lam = np.array([float(k[3:-2].replace(",", ".")) for k in names])
    return lam, np.stack([np.asarray(ch[k], np.float64) for k in names], -1)


def flashes(lam: np.ndarray, spectra: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(flashing mask (H, W), spectral centroid above the median (H, W))."""
    base = np.median(spectra, axis=-1, keepdims=True)
    peak = spectra.max(-1)
    mask = (peak > 8 * np.maximum(base[..., 0], 1e-12)) & (peak > np.percentile(peak, 97))
    w = np.clip(spectra - base, 0, None)
    return mask, (w * lam).sum(-1) / np.maximum(w.sum(-1), 1e-30)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, nargs=2, default=(256, 256))
    ap.add_argument("--spp", type=int, default=16)
    args = ap.parse_args(argv)

    import opal_diffraction

    ex = load_example("opal")
    opal_diffraction.register()
    work = tempfile.mkdtemp()
    try:
        sc, _opal, _lights = ex.build_scene(*args.resolution, spp=args.spp, lighting="lamp")  # the lamp geometry below
        out = {}
        for elev in (ex.CAMERA_ELEVATION - 5, ex.CAMERA_ELEVATION + 5):
            ex.place_camera(sc.camera, elev)
            sc.opal.spectral_exr = os.path.join(work, f"s{elev:g}.exr")
            ex.render(os.path.join(work, f"r{elev:g}.png"))
            out[elev] = flashes(*spectral_image(sc.opal.spectral_exr))
    finally:
        opal_diffraction.unregister()
    (lo, (m_lo, c_lo)), (hi, (m_hi, c_hi)) = sorted(out.items())
    both = m_lo & m_hi
    half = {e: math.radians((180 - ex.LAMP_ELEVATION - e) / 2) for e in (lo, hi)}
    law = math.sqrt(N_EFF_BLACK**2 - math.sin(half[hi]) ** 2) / math.sqrt(N_EFF_BLACK**2 - math.sin(half[lo]) ** 2)
    print(f"flashing pixels: {m_lo.sum()} at {lo:g} deg, {m_hi.sum()} at {hi:g} deg, {both.sum()} in both")
    print(f"median centroid over each frame's flashes: {np.median(c_lo[m_lo]):.1f} nm at {lo:g} deg, "
          f"{np.median(c_hi[m_hi]):.1f} nm at {hi:g} deg")
    print(f"median centroid ratio {hi:g} / {lo:g} deg on the shared pixels: {np.median(c_hi[both] / c_lo[both]):.4f} "
          f"(Bragg law for the mean geometry: {law:.4f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
