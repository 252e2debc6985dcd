"""Benchmark (not a test): the per-hit surface calls on the path tracer's batch size.

A batch of 2^18 hits on a floor and a sphere: the floor's material has a 1024 x 1024 colour
texture and a normal map (LINEAR, sRGB-encoded), the sphere's is plain. Times
``surface_reflectance`` (white and mono), ``shading_normal`` and ``surface_roughness`` with a
share of textured hits from 0 to 100 %, against the plain table gather they replace
(``materials.reflectance[hit.mat]``).

    python benchmarks/bench_textures.py
"""

from __future__ import annotations

import time

import numpy as np

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene.model import Camera, Materials, Scene
from opal_diffraction.core.materials.surface import shading_normal, surface_reflectance, surface_roughness
from opal_diffraction.core.transport.walker import Hit

B = 1 << 18


def scene() -> Scene:
    rng = np.random.default_rng(0)
    s = Scene(materials=Materials.from_list([
        {"color": (0.5, 0.5, 0.5), "color_texture": 0, "normal_texture": 1, "roughness_texture": 0},
        {"color": (0.8, 0.3, 0.2)}]))
    s.add_texture(rng.random((1024, 1024, 4)).astype(np.float32), "LINEAR", "REPEAT", "SRGB")
    s.add_texture(rng.random((1024, 1024, 4)).astype(np.float32), "LINEAR", "REPEAT", "LINEAR")
    v, t = primitives.quad((0, 0, 0), (20, 0, 0), (0, 20, 0))
    s.add_mesh(v, t, 0, uvs=np.asarray(v)[:, :2] / 4, uv_tangents=True)
    s.add_mesh(*primitives.icosphere((0, 0, 1), 1.0, 3), 1)
    s.camera = Camera.look_at((0, -6, 3), (0, 0, 0.8))
    return s


def hits(prepared, textured_share: float, rng) -> Hit:
    n_floor = len(primitives.quad((0, 0, 0), (1, 0, 0), (0, 1, 0))[1])
    t = len(prepared.tri_material)
    prim = np.where(rng.random(B) < textured_share, rng.integers(0, n_floor, B), rng.integers(n_floor, t, B))
    bu = rng.random(B).astype(np.float32)
    bv = (rng.random(B) * (1 - bu)).astype(np.float32)
    ng = prepared.tri_normal[prim]
    return Hit(np.zeros((B, 3), np.float32), ng, np.ones(B, np.float32), np.ones(B, bool),
               prepared.tri_material[prim], prepared.tri_offset[prim], prim, bu, bv)


def best(fn, repeat=3) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main():
    p = prepare(scene())
    rng = np.random.default_rng(1)
    lam = rng.integers(0, p.grid.n, B)
    print(f"{B} hits, {p.grid.n} wavelengths; ms per call (best of 3)")
    print(f"{'textured':>9} {'gather':>8} {'refl white':>11} {'refl mono':>10} {'normal':>8} {'roughness':>10}")
    for share in (0.0, 0.1, 0.5, 1.0):
        h = hits(p, share, rng)
        row = [best(lambda: p.materials.reflectance[h.mat]), best(lambda: surface_reflectance(p, h)),
               best(lambda: surface_reflectance(p, h, lam)), best(lambda: shading_normal(p, h)),
               best(lambda: surface_roughness(p, h))]
        print(f"{share:>8.0%} " + " ".join(f"{1e3 * x:>{w}.1f}" for x, w in zip(row, (8, 11, 10, 8, 10))))


if __name__ == "__main__":
    main()
