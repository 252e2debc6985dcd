"""Benchmark (not a test): the whole eye pass's ray throughput against the raw backend's.

The issue's target: the eye pass, shading included, runs at no less than half the raw
ray-casting throughput, i.e. spectral shading is not the bottleneck. For each scene we render
once (threads as given), count the rays the eye pass cast, and time the same numbers of camera
rays (closest hit) and shadow rays (any hit) cast directly on the backend.

    python benchmarks/bench_eye_pass.py [--threads 2] [--backend auto]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from opal_diffraction._scripts import load_example
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.sampling.camera import generate_rays
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.validation import validate
from opal_diffraction.core.scene.settings import RenderSettings


def diffuse_scene(pixels=512) -> Scene:
    """A 20k-triangle sphere and a floor, all diffuse, one point light."""
    s = Scene(materials=Materials.from_list([{"color": (0.5, 0.5, 0.5)}, {"color": (0.8, 0.3, 0.2)}]))
    s.add_mesh(*primitives.quad((0, 0, 0), (20, 0, 0), (0, 20, 0)), material=0)
    s.add_mesh(*primitives.icosphere((0, 0, 1), 1.0, 5), material=1)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (3, -3, 5), "power": 2000}])
    s.camera = Camera.look_at((0, -6, 3), (0, 0, 0.8), width=pixels, height=pixels)
    return s


def raw_throughput(scene: Scene, settings: RenderSettings, n_rays: int, shadow_fraction: float) -> float:
    """Mrays/s of the backend alone, casting camera rays and shadow rays in the eye pass's mix."""
    scene = validate(scene).scene
    ctx = prepare(scene, settings)
    cam = scene.camera
    rng = np.random.default_rng(0)
    n_cam = int(n_rays * (1 - shadow_fraction))
    x, y = rng.random(n_cam) * cam.width, rng.random(n_cam) * cam.height
    o, d = generate_rays(cam, x, y)
    from concurrent.futures import ThreadPoolExecutor

    chunks = np.array_split(np.arange(n_cam), max(1, n_cam // 32768))
    threads = settings.threads or os.cpu_count()
    t0 = time.perf_counter()
    with ThreadPoolExecutor(threads) as pool:
        hits = list(pool.map(lambda c: ctx.accel.intersect(o[c], d[c]), chunks))
    t_cam = time.perf_counter() - t0
    t = np.concatenate([h.t for h in hits])
    ok = np.isfinite(t)
    p = (o[ok] + t[ok, None] * d[ok]).astype(np.float32)
    n_sh = int(n_rays * shadow_fraction)
    p = p[rng.integers(0, len(p), n_sh)]
    light = np.asarray(scene.lights.position[0], np.float32)
    wi = light - p
    dist = np.linalg.norm(wi, axis=1)
    wi = (wi / dist[:, None]).astype(np.float32)
    p = p + 1e-4 * wi
    chunks = np.array_split(np.arange(n_sh), max(1, n_sh // 32768))
    t0 = time.perf_counter()
    with ThreadPoolExecutor(threads) as pool:
        list(pool.map(lambda c: ctx.accel.occluded(p[c], wi[c], dist[c] - 2e-4), chunks))
    t_sh = time.perf_counter() - t0
    return (n_cam + n_sh) / (t_cam + t_sh) / 1e6


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--backend", default="auto")
    ap.add_argument("--spp", type=int, default=4)
    args = ap.parse_args()
    build_scene = load_example("prism").build_scene

    scenes = {"diffuse 20k tris 512x512": diffuse_scene(512), "prism example 640x400": build_scene(640, 400)}
    print(f"{'scene':28s} {'backend':8s} {'rays (M)':>9s} {'eye pass Mrays/s':>17s} {'raw Mrays/s':>12s} {'ratio':>6s}")
    for name, scene in scenes.items():
        st = RenderSettings(samples=args.spp, threads=args.threads, backend=args.backend)
        render(scene, RenderSettings(samples=1, threads=1, backend=args.backend))  # warm up imports
        res = render(scene, st)
        s = res.stats
        eye = s["rays"] / (s["render_s"] - s["prepare_s"]) / 1e6
        # the eye pass's mix: roughly one shadow ray per diffuse hit per light
        raw = raw_throughput(scene, st, s["rays"], shadow_fraction=0.45)
        print(f"{name:28s} {s['backend']:8s} {s['rays'] / 1e6:9.2f} {eye:17.2f} {raw:12.2f} {eye / raw:6.2f}")


if __name__ == "__main__":
    main()
