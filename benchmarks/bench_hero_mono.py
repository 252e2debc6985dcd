"""Hero wavelengths, measured first as mono camera rays (issue 24): camera rays that start with one
wavelength (K paths per sample, the dispersion sampler's importance pdf with its defensive share,
pbrt-v4's rotations of the pixel's number) against white camera rays (the whole grid): eye-pass
CPU seconds (one thread; the light pass run once per configuration and reused) and RMSE against
a white reference of many samples; efficiency 1 / (MSE x CPU s). The mono start is patched into
the eye pass's tile tracer here: an experiment, not a setting. Results: docs/benchmarks.md
("Issue 24: what the wavelength count and the batch size cost the eye pass").

    python benchmarks/bench_hero_mono.py [SCENE W H REFERENCE_SPP]   (default: prism 320 200 256)
"""
import sys, time
import numpy as np
from opal_diffraction._scripts import load_example
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.frame import render_prepared, render
from opal_diffraction.core.scene.validation import validate
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.integrators.eye import eye_pass as ep
from opal_diffraction.core.transport.walker import Rays
from opal_diffraction.core.transport import wavelengths as wl
from opal_diffraction.core.integrators.light.light_pass import run_light_pass
from opal_diffraction.core.render.plan import plan_render

MODE = {"mono": 0}
CDF = {}
orig_run = ep._TileTrace.run
def run(self, origins, directions, pix, u_lambda, wavelength_index=None, ids=None, differentials=None, tmax=None):
    k = MODE["mono"]
    if not k or wavelength_index is not None:
        return orig_run(self, origins, directions, pix, u_lambda, wavelength_index, ids, differentials, tmax)
    b = len(pix)
    grid = self.c.prepared.grid
    key = (grid.n, k)
    if key not in CDF:  # unit white camera rays share one pdf: the dispersion sampler's importance, defended
        q = wl.importance(grid, None, 1, True)
        p = wl._defended(q, True, np.ones_like(q, bool))[0]
        CDF[key] = (np.cumsum(p) / p.sum(), p / p.sum())
    cdf, p = CDF[key]
    u = wl.rotated(np.asarray(u_lambda, np.float64), k).ravel()
    lam = np.minimum(np.searchsorted(cdf, u, side="right"), grid.n - 1)
    parent = np.repeat(np.arange(b), k)
    weight = 1.0 / (k * p[lam])
    rays = Rays(origins, directions, pix.astype(np.int64), None, None, np.zeros(b, np.int32),
                np.asarray(u_lambda, np.float64), self._new_state(b))
    if ids is not None:
        rays.state.pid[:] = ids[0]; rays.state.sid[:] = ids[1]
    r = rays.take(parent)
    mono = Rays(np.ascontiguousarray(r.o), np.ascontiguousarray(r.d), np.asarray(r.pix), weight.astype(np.float32),
                lam.astype(np.int64), np.asarray(r.depth), np.asarray(r.u_lam), r.state)
    self._camera_segment = True
    self.walk(rays.take(np.zeros(b, bool)), mono, tmax)
    return self.out.result(self.rays_cast)
ep._TileTrace.run = run

def light_of(prepared):
    """The prepared scene's light pass (None where its plan runs none), for eye-only timings."""
    plan = plan_render(prepared)
    return run_light_pass(prepared, plan=plan) if plan.light_pass else None


args = sys.argv[1:] or ["prism", "320", "200", "256"]
name = args[0]; W, H = int(args[1]), int(args[2]); ref_spp = int(args[3])
render(validate(load_example("prism").build_scene(32, 20)).scene, RenderSettings(samples=1, threads=1))
sc = validate(load_example(name).build_scene(W, H)).scene
def go(spp, k, seed):
    MODE["mono"] = k
    p = prepare(sc, RenderSettings(samples=spp, threads=1, seed=seed))
    light = light_of(p)
    c0 = time.process_time(); r = render_prepared(p, light=light); t = time.process_time() - c0
    return r.rgb.astype(np.float64), t
ref, tref = go(ref_spp, 0, 99)
print(f"reference {ref_spp} spp white: {tref:.1f} s, mean {ref.mean():.4f}", flush=True)
for k, spps in ((0, (4, 8, 16)), (1, (8, 16, 32, 64)), (4, (4, 8))):
    for spp in spps:
        img, t = go(spp, k, 1)
        mse = float(np.mean((img - ref) ** 2))
        print(f"{'white' if k == 0 else f'mono x{k}'} {spp:3d} spp: cpu {t:6.2f} s  mean {img.mean():.4f}  rmse {mse**0.5:.4f}  efficiency 1/(mse t) {1/(mse*t):10.1f}", flush=True)
