"""Diagnostic (not a test): where the caustic-sphere benchmark's noise comes from, per path type.

Renders benchmarks/caustic_sphere.py's scene with the eye pass instrumented (monkeypatched in
this process only): every contribution a camera sample adds is also summed, per sample, into
one of a few path classes, so the per-pixel sample variance of each class (and of their sum)
can be read off one render (sample variance over the N samples of a pixel: the variance of the
pixel estimate is that / N). Classes:

    film part    Direct (one diffuse vertex), Indirect (two or more), Caustics (the map)
    x first event at the glass: R (Fresnel reflection), T (refraction), - (the floor first)
    x TIR: whether the path met total internal reflection before the contribution

The value is the mean of linear R, G, B (white light, white glass, grey floor: every channel
alike). Also reports the speckles: samples whose contribution exceeds a threshold, by
class and by diffuse-vertex count.

    python benchmarks/sphere_noise.py [--shading flat|smooth] [--paths 250000] [--spp 32]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

import numpy as np

from opal_diffraction import _scripts
from opal_diffraction.core.integrators.eye import eye_pass as ep
from opal_diffraction.core.integrators.eye.tile_output import TileOutput
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.transport.path_state import PathState

cs = _scripts.load_script("benchmarks/caustic_sphere.py")

FILMS = ("direct", "indirect", "caustics", "background")
FIRST = ("floor", "R", "T")


@dataclasses.dataclass
class TaggedState(PathState):
    """The eye pass's path state with each path's first event at the glass and whether it met
    total internal reflection (carried by take / concat / moved as the other fields)."""
    first: np.ndarray | None = None  # int8 0: floor first (or nothing), 1: R, 2: T
    tir: np.ndarray | None = None    # int8 total internal reflection met
    row: np.ndarray | None = None    # int64 the input row of a dielectric bounce's output (a split makes two)


def instrument(n_pix: int, spp: int):
    """Patch eye_pass._TileTrace and TileOutput to record per-sample class sums; returns the
    (classes, P, spp) array and a function that undoes the patches."""
    acc = np.zeros((len(FILMS) * len(FIRST) * 2, n_pix * spp), np.float64)
    orig_state, orig_diel = ep._TileTrace._new_state, ep._TileTrace.dielectric_bounce
    orig_acc, orig_fact = TileOutput.accumulate, TileOutput.accumulate_factored

    def new_state(self, b):
        st = orig_state(self, b)
        return TaggedState(**{f.name: getattr(st, f.name) for f in dataclasses.fields(st)},
                           first=np.zeros(b, np.int8), tir=np.zeros(b, np.int8))

    def dielectric(self, rays, hit, rng, u=None):
        st = rays.state
        first = (st.first == 0) & (st.nd == 0)
        # total internal reflection: no transmitted direction (Fresnel = 1)
        n = np.take(self.prepared.materials.ior[:, 0], hit.mat)
        eta = np.where(hit.front, 1.0 / n, n)
        ns = self.specular_normal(rays, hit)
        cos = -np.einsum("ij,ij->i", rays.d, ns)
        tir = eta * eta * (1 - cos * cos) >= 1
        st.row = np.arange(len(rays))
        out, transmitted = orig_diel(self, rays, hit, rng, u)
        row, out.state.row, st.row = out.state.row, None, None
        out.state.first = np.where(first[row], np.where(transmitted, 2, 1), st.first[row]).astype(np.int8)
        out.state.tir = (st.tir[row] | tir[row]).astype(np.int8)
        return out, transmitted

    def accumulate(self, rays, contrib, film=None):
        orig_acc(self, rays, contrib, film)
        if len(rays) == 0:
            return
        film = self.film if film is None else film
        part = 0 if film is self.film else next(
            (FILMS.index(k) for k, v in self.parts.items() if v is film), None)
        if part is None:
            return
        val = np.asarray(contrib, np.float64)
        w = self.conv.rgb_weights.mean(axis=1)  # the mean of R, G, B, per wavelength sample
        val = val @ w if val.ndim == 2 else val * w[rays.lam]
        st = rays.state
        cls = (part * len(FIRST) + st.first.astype(np.int64)) * 2 + st.tir.astype(np.int64)
        idx = st.pid.astype(np.int64) * spp + st.sid.astype(np.int64)
        np.add.at(acc, (cls, idx), val)

    def trace_init(self, eye, *a, **k):
        orig_init(self, eye, *a, **k)
        self.out.conv = eye.prepared.conv  # the spectral converter, for accumulate's RGB weights

    orig_init = ep._TileTrace.__init__
    TileOutput.accumulate_factored = lambda self, *a: False  # the same estimate, through accumulate
    ep._TileTrace.__init__ = trace_init
    ep._TileTrace._new_state = new_state
    ep._TileTrace.dielectric_bounce = dielectric
    TileOutput.accumulate = accumulate
    return acc.reshape(len(acc), n_pix, spp), lambda: (setattr(ep._TileTrace, "_new_state", orig_state),
                                                         setattr(ep._TileTrace, "dielectric_bounce", orig_diel),
                                                         setattr(ep._TileTrace, "__init__", orig_init),
                                                         setattr(TileOutput, "accumulate", orig_acc),
                                                         setattr(TileOutput, "accumulate_factored", orig_fact))


def label(c: int) -> str:
    tir, c = c % 2, c // 2
    return f"{FILMS[c // len(FIRST)]}/{FIRST[c % len(FIRST)]}{'/TIR' if tir else ''}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--shading", choices=("flat", "smooth"), default="flat")
    ap.add_argument("--paths", type=int, default=250_000)
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--speckle", type=float, default=2.0, help="a sample above this (luminance) is a speckle")
    a = ap.parse_args(argv)
    spec = cs.Spec(smooth=a.shading == "smooth")
    lab = cs.masks(spec)
    n_pix = spec.res * spec.res
    acc, undo = instrument(n_pix, a.spp)
    st = RenderSettings(samples=a.spp, light_paths=a.paths, threads=1, seed=3)
    t0 = time.perf_counter()
    res = render(cs.our_scene(spec), st)
    print(f"render {time.perf_counter() - t0:.1f} s  stats: light_pass_s {res.stats.get('light_pass_s')}")
    undo()
    total = acc.sum(axis=0)  # (P, spp): each sample's whole contribution
    mean_img = res.rgb.mean(axis=2).ravel()
    for name, m in (("sphere", lab.ravel() == cs.SPHERE), ("floor", lab.ravel() == cs.FLOOR)):
        npx = m.sum()
        no_caus = total[m] - acc[[c for c in range(len(acc)) if label(c).startswith("caustics")]][:, m].sum(axis=0)
        v_tot = total[m].var(axis=1, ddof=1).mean()
        v_nc = no_caus.var(axis=1, ddof=1).mean()
        print(f"\n{name}: {npx} px, mean {total[m].mean():.4f} (film {mean_img[m].mean():.4f}); per-sample variance "
              f"{v_tot:.4f} (without Caustics {v_nc:.4f}); RMSE at {a.spp} spp from it: {np.sqrt(v_tot / a.spp):.4f} "
              f"(without Caustics {np.sqrt(v_nc / a.spp):.4f})")
        print(f"  {'class':28s} {'mean':>8s} {'var/sample':>11s} {'share':>6s} {'hit rate':>8s} {'speckles':>8s}")
        for c in range(len(acc)):
            x = acc[c][m]
            if not x.any():
                continue
            v = x.var(axis=1, ddof=1).mean()
            print(f"  {label(c):28s} {x.mean():8.4f} {v:11.5f} {v / v_tot:6.1%} {(x != 0).mean():8.3f} "
                  f"{(x > a.speckle).sum():8d}")
    # the speckles: which samples, which classes
    big = total > a.speckle
    print(f"\nsamples above {a.speckle}: {big.sum()} (floor px {(big & (lab.ravel() == cs.FLOOR)[:, None]).sum()}, "
          f"sphere px {(big & (lab.ravel() == cs.SPHERE)[:, None]).sum()})")
    for c in range(len(acc)):
        k = (acc[c] > a.speckle).sum()
        if k:
            print(f"  {label(c):28s} {k:6d} samples above, max {acc[c].max():.2f}")
    np.savez_compressed(os.path.join(cs.ROOT, "out", f"sphere_noise_{a.shading}.npz"),
                        var=acc.var(axis=2, ddof=1).astype(np.float32), mean=acc.mean(axis=2).astype(np.float32),
                        total_var=total.var(axis=1, ddof=1).astype(np.float32), lab=lab)
    return 0


if __name__ == "__main__":
    sys.exit(main())
