"""Colour error of the float32 hot path: the ColorChecker render against its float64 reference.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_colour_precision.py [--samples 128] [--repeats 3]

The scene, the reference and the noise's reach are tests/system/test_colour_precision.py's (it
is imported): the 24 ColorChecker patches (colour-science's xyY after Nov 2014, Bradford to D65,
linear Rec.709, clipped to [0, 1]) as diffuse quads facing an orthographic camera under a world
of radiance 1 (uniform colour, or a constant 8 x 16 map), rendered on the kernels and on the
NumPy reference; the reference is each patch's spectrum rho(lambda) W(lambda) through the
observer in float64, from colour-science's tables (docs/physics.md sections 1.2-1.4).

Prints, per world: the per-patch table (rendered RGB on the kernels, the float64 reference,
CIEDE2000 of the kernels, of the NumPy reference, between the two, and the noise's reach at
z = 4.6); the same measure for deliberately degraded hot paths (the uncalibrated uplift,
reflectance spectra rounded to float16's and bfloat16's significands); the render times
(kernels vs NumPy, interleaved, medians); and the cost of float32 against float64 for the
spectral arithmetic of one bounce in NumPy (the engine has no float64 render to time: its
hot path is float32 on both paths). The numbers go in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from opal_diffraction._scripts import load_script
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.util import jit

cp = load_script("tests/system/test_colour_precision.py")  # the scene, the reference, the noise


def fmt(c) -> str:
    return "(" + ", ".join(f"{x:.5f}" for x in c) + ")"


def patch_table(world: str, imgs: dict) -> None:
    names = cp.colorchecker()[0]
    k_path = "auto" if "auto" in imgs else "numpy"
    a, b = cp.measure(imgs[k_path]), cp.measure(imgs["numpy"])
    between = cp.delta_e(a["mean"], b["mean"])
    print(f"\n## {world} world: {k_path} (kernels) and numpy vs float64\n")
    print("| patch | rendered (kernels) | float64 reference | dE2000 kernels | dE2000 numpy | dE kernels-numpy "
          "| noise reach |")
    print("|---|---|---|---:|---:|---:|---:|")
    for k in range(24):
        print(f"| {names[k]} | {fmt(a['mean'][k])} | {fmt(a['ref'][k])} | {a['de'][k]:.5f} | {b['de'][k]:.5f} | "
              f"{between[k]:.5f} | {a['reach'][k]:.4f} |")
    for label, f in (("max", np.max), ("mean", np.mean)):
        print(f"| **{label}** | | | {f(a['de']):.2e} | {f(b['de']):.2e} | {f(between):.2e} | {f(a['reach']):.4f} |")
    print(f"per-pixel std over the patches (max): {a['std'].max():.3g} (kernels), {b['std'].max():.3g} (numpy); "
          f"within budget: {cp.within_budget(a)} / {cp.within_budget(b)}; kernels' image the same bits as numpy's "
          f"(same seed): {bool(np.array_equal(imgs[k_path], imgs['numpy']))}")


class _Patch:
    """A minimal monkeypatch (setattr with undo) for the degraded runs."""

    def __init__(self):
        self.undo = []

    def setattr(self, obj, name, value):
        self.undo.append((obj, name, obj.__dict__.get(name, None) if isinstance(obj, type) else getattr(obj, name)))
        setattr(obj, name, value)

    def restore(self):
        for obj, name, old in reversed(self.undo):
            setattr(obj, name, old)
        self.undo.clear()


def degraded(samples: int) -> None:
    """The measure on deliberately degraded hot paths (uniform world, NumPy reference, 1 sample:
    it has no noise)."""
    from opal_diffraction.core.spectral.spectrum import SpectralConverter

    def run():
        return cp.measure(render(cp.colorchecker_scene(False), cp.settings("numpy", samples=1)).rgb)

    names = cp.colorchecker()[0]
    print("\n## degraded hot paths (uniform world, NumPy reference)\n")
    print("| hot path | max dE2000 (patch) | mean dE2000 | within 0.1 |")
    print("|---|---|---:|---|")
    rows = [("as is (float32)", None)]
    rows.append(("uncalibrated uplift (basis point-sampled, no B M^-T)", ("basis", cp.wrong_basis(0.0))))
    rows.append(("uncalibrated uplift read 5 nm off", ("basis", cp.wrong_basis(5.0))))
    rows += [(f"reflectance spectra rounded to {b} significant bits ({n})", ("bits", b))
             for b, n in ((11, "float16"), (8, "bfloat16"))]
    for label, how in rows:
        mp = _Patch()
        try:
            if how is not None and how[0] == "basis":
                mp.setattr(SpectralConverter, "_mallett_basis", how[1])
            elif how is not None:
                cp._rounded_reflectances(mp, how[1])
            m = run()
        finally:
            mp.restore()
        k = int(np.argmax(m["de"]))
        print(f"| {label} | {m['de'].max():.3g} ({names[k]}) | {m['de'].mean():.3g} | {cp.within_budget(m)} |")


def timings(samples: int, repeats: int) -> dict:
    """{(world, path): [seconds]} interleaved, and the last images."""
    paths = (["auto"] if jit.AVAILABLE else []) + ["numpy"]
    for p in paths:  # warm-up: JIT load, colour-science import, caches
        render(cp.colorchecker_scene(True), cp.settings(p, samples=1))
    times, imgs = {}, {}
    for _ in range(repeats):
        for world in ("uniform", "map"):
            for p in paths:
                t = time.perf_counter()
                res = render(cp.colorchecker_scene(world == "map"), cp.settings(p, samples=samples))
                times.setdefault((world, p), []).append(time.perf_counter() - t)
                imgs.setdefault(world, {})[p] = res.rgb
    return times, imgs


def spectral_ops(dtype, b: int = 100_000, n: int = 61, reps: int = 5) -> float:
    """Median seconds of one bounce's spectral arithmetic in NumPy at ``dtype``: uplift
    (B, 3) @ (3, n), throughput x reflectance x illuminant, to RGB (B, n) @ (n, 3)."""
    rng = np.random.default_rng(1)
    rgb = rng.random((b, 3)).astype(dtype)
    basis = rng.random((3, n)).astype(dtype)
    w = rng.random((b, n)).astype(dtype)
    ill = rng.random(n).astype(dtype)
    to_rgb = rng.random((n, 3)).astype(dtype)
    out = []
    for _ in range(reps):
        t = time.perf_counter()
        spec = rgb @ basis
        spec *= w
        spec *= ill
        _ = spec @ to_rgb
        out.append(time.perf_counter() - t)
    return statistics.median(out)


def _per_texel_kernel():
    """A compiled lookup of per-texel spectra (the alternative to the code's per-ray uplift): per
    direction the map's (u, v) and bilinear weights as EnvironmentMap's kernels compute them, the
    four texels' (n,) spectra blended, times the power heuristic against the map's density."""
    from opal_diffraction.core.lights.environment import _uv_one
    from opal_diffraction.core.util.jit import njit

    @njit
    def kernel(m, spectra, density, w, h, p_bsdf, out):
        wf, hf, half, one = np.float32(w), np.float32(h), np.float32(0.5), np.float32(1.0)
        for b in range(m.shape[0]):
            u, v = _uv_one(m[b, 0], m[b, 1], m[b, 2])
            x, y = u * wf - half, v * hf - half
            fi0, fj0 = np.floor(x), np.floor(y)
            fx, fy = np.float32(x - fi0), np.float32(y - fj0)
            i0, j0 = np.int64(fi0) % w, np.int64(fj0) % h
            i1, j1 = (i0 + 1) % w, (j0 + 1) % h
            i = np.int64(np.floor(u * wf)) % w
            j = min(max(np.int64(np.floor(v * hf)), 0), h - 1)
            pa, pb = p_bsdf[b], np.float32(density[j, i])
            mis = pa * pa / (pa * pa + pb * pb) if pa > 0 else one
            for k in range(spectra.shape[1]):
                top = spectra[j1 * w + i0, k] * (one - fx) + spectra[j1 * w + i1, k] * fx
                bottom = spectra[j0 * w + i0, k] * (one - fx) + spectra[j0 * w + i1, k] * fx
                out[b, k] = (bottom * (one - fy) + top * fy) * mis

    return kernel


def world_map_lookups(rays: int = 100_000, repeats: int = 7) -> None:
    """The world seen by escaping rays, two ways, compiled, on random maps and directions: the
    code's (EnvironmentMap.lookup: the RGB texels blended, then _world_contrib_kernel: the blend
    uplifted with the 3-row emission basis, times MIS) and per-texel spectra (every texel's
    spectrum precomputed, (H W, n) float32, four spectra blended per ray)."""
    if not jit.AVAILABLE:
        return
    from opal_diffraction.core.integrators.eye.emission import _EMPTY_W, _NO_LAM, _world_contrib_kernel
    from opal_diffraction.core.lights.environment import EnvironmentMap
    from opal_diffraction.core.spectral.spectrum import SpectralConverter

    conv = SpectralConverter()
    basis_t = conv.emission_basis
    per_texel = _per_texel_kernel()
    rng = np.random.default_rng(3)
    d = rng.normal(size=(rays, 3)).astype(np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    p_bsdf = rng.random(rays).astype(np.float32)
    print(f"\n## world map seen by {rays} escaping rays (compiled, 1 thread, median of {repeats}, interleaved)\n")
    print("| map | per-ray uplift (the code) | per-texel spectra | map memory: RGB / spectra | max rel. difference |")
    print("|---|---:|---:|---:|---:|")
    for w in (256, 1024, 2048):
        h = w // 2
        env = EnvironmentMap(rng.random((h, w, 3)).astype(np.float32) * 2)
        spectra = np.ascontiguousarray((env.rgb.reshape(-1, 3).astype(np.float64) @ basis_t).astype(np.float32))
        a_out, b_out = np.empty((rays, conv.grid.n), np.float32), np.empty((rays, conv.grid.n), np.float32)

        def code():
            rgb, p_env = env.lookup(d)
            _world_contrib_kernel(rgb, p_env, p_bsdf, basis_t, _EMPTY_W, _NO_LAM, a_out)

        def texel():
            per_texel(d, spectra, env.density, w, h, p_bsdf, b_out)

        code(), texel()  # compile / load
        ta, tb = [], []
        for _ in range(repeats):
            for f, ts in ((code, ta), (texel, tb)):
                t = time.perf_counter()
                f()
                ts.append(time.perf_counter() - t)
        rel = float(np.max(np.abs(a_out - b_out) / np.maximum(np.abs(a_out), 1e-6)))
        print(f"| {w} x {h} | {statistics.median(ta) * 1e3:.2f} ms | {statistics.median(tb) * 1e3:.2f} ms | "
              f"{env.rgb.nbytes / 2**20:.1f} / {spectra.nbytes / 2**20:.0f} MiB | {rel:.1e} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=cp.SPP)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    times, imgs = timings(args.samples, args.repeats)
    print(f"# ColorChecker, {cp.COLS * cp.CELL} x {cp.ROWS * cp.CELL} px, {args.samples} spp, 1 thread, "
          f"{(cp.PATCH - 2 * cp.INNER) ** 2} interior pixels per patch")
    for world in ("uniform", "map"):
        patch_table(world, imgs[world])
    degraded(args.samples)
    world_map_lookups()
    print("\n## times (median of %d, interleaved)\n" % args.repeats)
    for (world, p), ts in times.items():
        print(f"- {world} world, {p}: {statistics.median(ts):.3f} s")
    t0 = time.perf_counter()
    for _ in range(100):
        cp.reference_rgb(cp.patch_colours())
    print(f"- the float64 reference of the 24 patches (tables cached): {(time.perf_counter() - t0) / 100 * 1e6:.0f} us")
    a, b = [], []
    for _ in range(5):  # interleaved
        a.append(spectral_ops(np.float32))
        b.append(spectral_ops(np.float64))
    f32, f64 = statistics.median(a), statistics.median(b)
    print(f"- one bounce's spectral arithmetic on 1e5 rows x 61 (NumPy): float32 {f32 * 1e3:.2f} ms, "
          f"float64 {f64 * 1e3:.2f} ms ({f64 / f32:.2f}x)")


if __name__ == "__main__":
    main()
