"""Preparation time per phase against the scene's triangle count (the [caustics] issue's Scale item).

    .venv/bin/python benchmarks/bench_prepare_scale.py [--sizes 0.1 1 3 10] [--profile 10] [--grating-every 8]

The scene: a grid of icospheres (core/scene/primitives.py, 20 x 4^s triangles each, copies of one
template laid out in a square) on a diffuse floor: a quarter glass, a quarter mirror, an eighth
diffuse with a line grating (per-triangle tangents), the rest diffuse; smooth corner normals on
half the spheres (the other half and the floor flat), per-corner UVs; a point light, a
sun, an emissive quad (a mesh light) and a world colour. Each size runs in its own subprocess
(so its peak RSS, ``resource.getrusage(RUSAGE_SELF).ru_maxrss``, is the preparation's alone);
the phases are timed by wrapping the functions core/render/prepare.py calls (the names it imported),
so the code measured is the code that runs. Prints two tables, wall-clock and CPU seconds
(``time.process_time``: every thread of the process, Embree's build threads included; on a
shared machine the number to compare) per phase x size with nanoseconds per triangle, the RSS,
and with ``--profile M`` pyinstrument's top lines for the M-million-triangle scene. Results in
docs/benchmarks.md ("Preparation at 10 M triangles", and the dated section after it).
"""

from __future__ import annotations

import argparse
import functools
import json
import resource
import subprocess
import sys
import time
from collections import defaultdict

import numpy as np

from opal_diffraction.core.integrators.light import targets as _targets
from opal_diffraction.core.render import prepare as _prep
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.lights.mesh_lights import MeshLights
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings

SETTINGS = RenderSettings(samples=16, light_paths=1_000_000, threads=2)


def scene_of(triangles: int, grating_every: int = 8) -> Scene:
    """About ``triangles`` triangles: icospheres of 20 480 (subdivision 5) in a square grid;
    sphere k is glass (k % 8 in 0, 4), a mirror (1, 5), diffuse, and one in ``grating_every``
    a diffuse grating instead (default 8: k % 8 == 2)."""
    sub = 5 if triangles >= 200_000 else 3
    tv, tt = primitives.icosphere((0, 0, 0), 1.0, sub)
    k = max(1, round(triangles / len(tt)))
    side = int(np.ceil(np.sqrt(k)))
    ij = np.stack(np.divmod(np.arange(k), side), 1).astype(np.float64)
    centres = np.concatenate([(ij - (side - 1) / 2) * 2.5, np.full((k, 1), 1.0)], 1)
    verts = (tv[None] * 1.0 + centres[:, None]).reshape(-1, 3)
    tris = (tt[None].astype(np.int64) + (np.arange(k) * len(tv))[:, None, None]).reshape(-1, 3)
    which = np.repeat(np.arange(k), len(tt))
    # material per sphere: 1 glass, 2 mirror, 3 grating, 0 diffuse
    sphere_mat = np.array([1, 2, 0, 0, 1, 2, 0, 0])[np.arange(k) % 8]
    sphere_mat[np.arange(k) % grating_every == 2] = 3
    tri_mat = sphere_mat[which]
    half = side * 1.25 + 1
    fv = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]], np.float64)
    lv = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float64) * 0.5 + [0, 0, 6]
    quad_t = np.array([[0, 1, 2], [0, 2, 3]])
    lquad_t = np.array([[0, 2, 1], [0, 3, 2]])  # facing down
    n_s = len(verts)
    v = np.concatenate([verts, fv, lv]).astype(np.float32)
    t = np.concatenate([tris, quad_t + n_s, lquad_t + n_s + 4]).astype(np.int32)
    tm = np.concatenate([tri_mat, [0, 0, 4, 4]]).astype(np.int32)
    # corner normals: smooth (radial) on even spheres, the face normal elsewhere
    p = v[t].astype(np.float64)
    face = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    face /= np.linalg.norm(face, axis=1, keepdims=True)
    cn = np.repeat(face[:, None, :], 3, axis=1)
    smooth = np.zeros(len(t), bool)
    smooth[: len(tris)] = (which % 2) == 0
    radial = (v[t[smooth]] - centres[which[smooth[: len(tris)]]][:, None, :]).astype(np.float64)
    cn[smooth] = radial / np.linalg.norm(radial, axis=2, keepdims=True)
    # UVs: planar (x, y) per corner
    uv = v[t][:, :, :2] * 0.1
    tangent = np.zeros((len(t), 3), np.float32)
    tangent[tm == 3] = (1, 0, 0)
    mats = Materials.from_list([
        {"kind": "DIFFUSE", "color": (0.6, 0.6, 0.6)},
        {"kind": "DIELECTRIC", "ior": 1.5, "color": (1, 1, 1)},
        {"kind": "MIRROR", "color": (0.9, 0.9, 0.9)},
        {"kind": "DIFFUSE", "color": (0.2, 0.3, 0.8), "grating": 1, "period": 1600.0, "slit_width": 800.0,
         "slit_count": 200, "coherence_length": 10.0},
        {"kind": "DIFFUSE", "color": (0, 0, 0), "emission": (5.0, 5.0, 5.0)},
    ])
    s = Scene(vertices=v, triangles=t, tri_material=tm, materials=mats, tri_tangent=tangent,
              corner_normals=cn.astype(np.float32), corner_uvs=uv.astype(np.float32),
              world_color=np.array([0.02, 0.02, 0.03], np.float32))
    s.lights = Lights.from_list([
        {"kind": "POINT", "position": (1.0, -1.0, 8.0), "power": 1000.0},
        {"kind": "SUN", "direction": (0.2, 0.3, -1.0), "power": 1.0},
    ])
    s.camera = Camera.look_at((0.0, -2 * half, half), (0, 0, 0), width=160, height=100)
    return s


# the functions core/render/prepare.py calls, by phase (wrapped in the modules whose names it calls)
PHASES = [
    ("validation", _prep, "validate"),
    ("materials/lights/gratings", _prep, "prepare_materials"),
    ("materials/lights/gratings", _prep, "prepare_lights"),
    ("materials/lights/gratings", _prep, "prepare_gratings"),
    ("textures", _prep, "prepare_textures"),
    ("normals", _prep, "triangle_normals"),
    ("normals", _prep, "normals_from_cross"),  # after this branch: from validation's cross products
    ("extent/offsets", _prep, "scene_extent"),
    ("extent/offsets", _prep, "triangle_offsets"),
    ("accelerator", _prep, "build_accelerator"),
    ("grating frames", _prep, "triangle_tangents"),
    ("grating frames", _prep, "smooth_corner_tangents"),
    ("mesh lights", MeshLights, "build"),
    ("light targets: caster objects", _targets, "caster_objects"),
    ("light targets: rest", _prep, "find_light_targets"),  # minus caster_objects, below
    ("freeze (read-only views)", _prep, "_read_only"),
]


def instrument(times: dict, cpu: dict):
    depth = defaultdict(int)

    def wrap(name, fn):
        @functools.wraps(fn)
        def timed(*a, **k):
            depth[name] += 1
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                return fn(*a, **k)
            finally:
                depth[name] -= 1
                if depth[name] == 0:  # recursion (_read_only) counted once
                    times[name] += time.perf_counter() - t0
                    cpu[name] += time.process_time() - c0
        return timed

    for name, owner, attr in PHASES:
        if attr not in owner.__dict__:  # an older core (benchmarking main against a branch)
            continue
        raw = owner.__dict__[attr]
        if isinstance(raw, classmethod):
            setattr(owner, attr, classmethod(wrap(name, raw.__func__)))
        else:
            setattr(owner, attr, wrap(name, raw))


def run_one(triangles: int, profile: bool, grating_every: int = 8) -> dict:
    t0 = time.perf_counter()
    scene = scene_of(triangles, grating_every)
    build_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    import colour  # noqa: F401  once per process (the first prepare_materials pays it): timed apart
    import_s = time.perf_counter() - t0
    rss_scene = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    times, cpus = defaultdict(float), defaultdict(float)
    instrument(times, cpus)
    prof = None
    if profile:
        from pyinstrument import Profiler
        prof = Profiler(interval=0.01, async_mode="disabled")
        prof.start()
    t0, c0 = time.perf_counter(), time.process_time()
    prepared = _prep.prepare(scene, SETTINGS)
    total, cpu = time.perf_counter() - t0, time.process_time() - c0
    out_prof = None
    if prof is not None:
        prof.stop()
        out_prof = prof.output_text(unicode=False, color=False, show_all=False)
    for d, whole in ((times, total), (cpus, cpu)):
        d["light targets: rest"] -= d["light targets: caster objects"]
        d["other"] = whole - sum(d.values())
    return {"triangles": len(scene.triangles), "build_s": build_s, "total_s": total, "cpu_s": cpu,
            "import_colour_s": import_s,
            "prepare_s": prepared.prepare_s, "phases": dict(times), "cpu_phases": dict(cpus), "rss_scene_mb": rss_scene,
            "rss_peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "objects": len(prepared.light_targets.objects),
            "grating_triangles": int(np.sum(prepared.gratings.enabled[prepared.tri_material])), "warnings": list(prepared.warnings),
            "profile": out_prof}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=float, nargs="+", default=[0.1, 1, 3, 10], help="millions of triangles")
    ap.add_argument("--profile", type=float, default=None, help="pyinstrument profile of this size (millions)")
    ap.add_argument("--grating-every", type=int, default=8, help="one sphere in this many is a grating")
    ap.add_argument("--json", default=None, help="also write the rows to this file")
    ap.add_argument("--one", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--with-profile", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one is not None:
        print(json.dumps(run_one(args.one, args.with_profile, args.grating_every)))
        return 0
    rows = []
    for m in args.sizes:
        cmd = [sys.executable, __file__, "--one", str(int(m * 1e6)), "--grating-every", str(args.grating_every)]
        if args.profile is not None and m == args.profile:
            cmd.append("--with-profile")
        r = json.loads(subprocess.run(cmd, check=True, stdout=subprocess.PIPE, text=True).stdout.strip().splitlines()[-1])
        rows.append(r)
        if args.json:
            with open(args.json, "w") as f:
                json.dump(rows, f)
        print(f"{r['triangles'] / 1e6:.2f} M triangles: prepare {r['total_s']:.2f} s (CPU {r['cpu_s']:.2f} s; colour-science import {r['import_colour_s']:.1f} s before), peak RSS {r['rss_peak_mb']:.0f} MB "
              f"(scene alone {r['rss_scene_mb']:.0f} MB), {r['objects']} caster groups, {r['grating_triangles']} grating triangles", flush=True)
        if r["profile"]:
            print("\n".join(r["profile"].splitlines()[:60]))
    names = list(dict.fromkeys([p[0] for p in PHASES] + ["other"]))
    for label, key, whole in (("wall-clock", "phases", "total_s"), ("CPU (process_time)", "cpu_phases", "cpu_s")):
        if not all(key in r for r in rows):
            continue
        print(f"\n{label} seconds per phase, and ns per triangle")
        print("| phase | " + " | ".join(f"{r['triangles'] / 1e6:.2f} M" for r in rows) + " | ns/triangle at each size |")
        print("|---" * (len(rows) + 2) + "|")
        for n in names + ["total"]:
            secs = [r[whole] if n == "total" else r[key].get(n, 0.0) for r in rows]
            ns = [1e9 * s / r["triangles"] for s, r in zip(secs, rows)]
            print(f"| {n} | " + " | ".join(f"{s:.3f}" for s in secs) + " | " + " / ".join(f"{x:.0f}" for x in ns) + " |")
    print()
    print("| peak RSS (MB) | " + " | ".join(f"{r['rss_peak_mb']:.0f}" for r in rows) + " | |")
    print("| RSS with the scene alone (MB) | " + " | ".join(f"{r['rss_scene_mb']:.0f}" for r in rows) + " | |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
