"""Environment maps: construction, lookup and sampling speed, and the light pass's world emission.

    .venv/bin/python benchmarks/bench_environment.py [--width 4096]

Builds an EnvironmentMap of ``--width`` x ``--width / 2`` texels (a smooth sky with a small
bright sun), times the construction (luminance, cell means, CDFs), 1 M lookups, 1 M samples
and 1 M pdf evaluations, then a light pass of 1 M world paths through a glass sphere over a
floor (core/integrators/light/light_pass.py ``_emit_world``). Prints the numbers (docs/physics.md section 7.6).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.lights.environment import EnvironmentMap
from opal_diffraction.core.integrators.light.light_pass import run_light_pass
from opal_diffraction.core.render.plan import plan_render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene.model import Camera, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings


def sky(width: int) -> np.ndarray:
    h = width // 2
    v = (np.arange(h) + 0.5) / h
    img = np.zeros((h, width, 3), np.float32)
    img[...] = (0.3 + 0.7 * v)[:, None, None] * np.array([0.4, 0.6, 1.0], np.float32)
    j, i = int(0.8 * h), int(0.3 * width)
    img[j:j + max(h // 256, 1), i:i + max(width // 512, 1)] = 20000.0
    return img


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--width", type=int, default=4096)
    args = ap.parse_args()
    img = sky(args.width)
    t = time.perf_counter()
    env = EnvironmentMap(img, np.eye(3))
    print(f"construction {img.shape[1]} x {img.shape[0]}: {time.perf_counter() - t:.2f} s")
    rng = np.random.default_rng(0)
    d = rng.normal(size=(1_000_000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    for name, fn in (("radiance_rgb", lambda: env.radiance_rgb(d)), ("pdf", lambda: env.pdf(d)),
                     ("sample", lambda: env.sample(rng.random(len(d)), rng.random(len(d))))):
        t = time.perf_counter()
        fn()
        print(f"{name}: {(time.perf_counter() - t) * 1e3:.0f} ms per 1 M")
    mats = Materials.from_list([{"kind": "DIFFUSE"}, {"kind": "DIELECTRIC", "ior": 1.5}])
    s = Scene(materials=mats, world_color=np.ones(3, np.float32), world_image=img)
    s.add_mesh(*primitives.quad((0, 0, 0), (6, 0, 0), (0, 6, 0)), material=0)
    s.add_mesh(*primitives.icosphere((0, 0, 1.0), 0.5, 4), material=1)
    s.camera = Camera(width=4, height=4)
    prepared = prepare(s, RenderSettings(light_paths=1_000_000, wavelength_step=10.0))
    t = time.perf_counter()
    lp = run_light_pass(prepared, plan=plan_render(prepared))
    print(f"light pass, 1 M world paths: {time.perf_counter() - t:.2f} s "
          f"({lp.stats['light_deposits']} deposits, {prepared.threads} threads)")
    # the same light pass from a SUN (the emission's own cost is the difference)
    from opal_diffraction.core.scene.model import Lights

    s.world_image = np.zeros((0, 0, 3), np.float32)
    s.world_color = np.zeros(3, np.float32)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": (0.3, 0.2, -1.0), "power": 3.0}])
    prepared = prepare(s, RenderSettings(light_paths=1_000_000, wavelength_step=10.0))
    t = time.perf_counter()
    lp = run_light_pass(prepared, plan=plan_render(prepared))
    print(f"light pass, 1 M sun paths: {time.perf_counter() - t:.2f} s ({lp.stats['light_deposits']} deposits)")


if __name__ == "__main__":
    main()
