"""Persistent Data: the seconds of frames 1 and 2 of an animation whose camera moves, on the
prism example.

    .venv/bin/python benchmarks/bench_persistent_data.py [--resolution 320 200] [--spp 8] [--light-paths 1000000] [--sphere 0]

Builds examples/render_example.py's scene in the bpy module, keyframes its camera 0.3 m to the
side between frames 1 and 2, renders one throwaway frame (so the compile stage is not timed),
then frames 1 and 2 with Persistent Data on, and frame 2 once more with it off (what every
frame cost before: export, preparation and light pass again). Each with the camera splat off
(the light pass is kept on frame 2) and on (the default: the light pass keeps the splat's
light-path vertices and frame 2 splats them into its camera, core/integrators/light/splat_vertices.py).
Prints wall and CPU seconds per frame, what was reused, the kept vertices (count, MB) and the
re-splat's seconds; checks that frame 2 equals the fresh render bit for bit. ``--repeat N``
renders the frame-2 pair (persistent, off) N times, interleaved, and prints each. The numbers go
in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from opal_diffraction._scripts import load_example


def _frame(bpy, last_render, sc, frame, persistent):
    if sc.render.use_persistent_data != persistent:
        sc.render.use_persistent_data = persistent
    sc.frame_set(frame)
    w0, c0 = time.perf_counter(), time.process_time()
    bpy.ops.render.render()
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    assert last_render["status"] == "FINISHED", last_render.get("message")
    stats = last_render["stats"]
    pers = last_render["persistent"]
    kept = pers.get("splat_vertices") if pers["on"] else None
    resplat = pers.get("resplat") if pers["on"] else None
    return {"wall": wall, "cpu": cpu, "rgb": last_render["rgb"].copy(), "reused": pers["reused"],
            "export_s": last_render["export"]["export_s"], "prepare_s": stats.get("prepare_s", 0.0),
            "light_s": stats.get("light_pass_s", 0.0) if pers["light_pass_ran"] else 0.0,
            "resplat_s": resplat["resplat_s"] if resplat else 0.0,
            "kept": "-" if not kept else (f"{kept['vertices'] / 1e6:.2f} M, {kept['bytes'] / 2**20:.1f} MB"
                                          + (" (over the cap)" if kept["over_cap"] else ""))}


def _sphere(bpy, segments: int) -> None:
    bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=max(segments // 2, 3), radius=0.6,
                                         location=(-2.0, 2.0, 0.6))
    ob = bpy.context.object
    ob.data.materials.append(bpy.data.materials["floor"])
    ob.data.shade_smooth()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, nargs=2, default=(320, 200))
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--light-paths", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=1, help="frame-2 pairs (persistent, off), interleaved")
    ap.add_argument("--splat", choices=("both", "off", "on"), default="both", help="camera splat settings to run")
    ap.add_argument("--sphere", type=int, default=0, metavar="SEGMENTS",
                    help="add a diffuse UV sphere of SEGMENTS x SEGMENTS/2 quads behind the prism (a mesh to export "
                         "and build a ray caster for; 0: none)")
    args = ap.parse_args(argv)

    import bpy

    import opal_diffraction
    from opal_diffraction.blender.engine import last_render

    opal_diffraction.register()
    rows = []
    for splat in {"both": (False, True), "off": (False,), "on": (True,)}[args.splat]:
        sc = load_example("render_example").build_scene(*args.resolution, spp=args.spp, light_paths=args.light_paths)
        sc.opal.light_paths_auto = False
        if args.sphere:
            _sphere(bpy, args.sphere)
        sc.opal.caustic_splat = splat
        sc.render.threads_mode = "FIXED"
        sc.render.threads = 2
        cam = sc.camera
        cam.keyframe_insert("location", frame=1)
        cam.location.x += 0.3
        cam.keyframe_insert("location", frame=2)
        _frame(bpy, last_render, sc, 1, False)  # the compile stage, once per process
        for rep in range(args.repeat):
            f1 = _frame(bpy, last_render, sc, 1, True)
            f2 = _frame(bpy, last_render, sc, 2, True)
            fresh = _frame(bpy, last_render, sc, 2, False)
            same = bool(np.array_equal(f2["rgb"], fresh["rgb"]))
            for name, r in (("frame 1 (persistent)", f1), ("frame 2 (persistent)", f2), ("frame 2 (off)", fresh)):
                rows.append((f"{'on' if splat else 'off'}", name, r["wall"], r["cpu"], r["export_s"], r["prepare_s"],
                             r["light_s"], r["resplat_s"], r["kept"], ", ".join(r["reused"]) or "-", same))
    tris = last_render["stats"].get("triangles", 0)
    print(f"prism example {args.resolution[0]}x{args.resolution[1]}, {args.spp} spp, {args.light_paths} light paths, "
          f"{tris} triangles")
    print("| camera splat | frame | wall s | CPU s | export s | prepare s | light pass s | re-splat s | splat vertices kept "
          "| reused | frame 2 = fresh |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for splat, name, wall, cpu, exp, prep, light, rs, kept, reused, same in rows:
        print(f"| {splat} | {name} | {wall:.2f} | {cpu:.2f} | {exp:.3f} | {prep:.3f} | {light:.2f} | {rs:.2f} | {kept} "
              f"| {reused} | {same} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
