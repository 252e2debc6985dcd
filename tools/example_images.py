"""Render every example's scene at a fixed seed and save the spectral films, or compare two runs.

A refactor must not change images: run this before and after and compare. The renders run the
NumPy reference (``RenderSettings.kernels = 'numpy'``), not the compiled kernels.

    python tools/example_images.py render OUT.npz      # prism, fig5, cd (core); bpy prism, opal (exported)
    python tools/example_images.py compare A.npz B.npz # max |difference| per image

The scenes are the examples' own builders at a reduced size; the Blender ones are exported from
the depsgraph (as F12 would) and rendered with the core, so one number per image says whether
anything moved.
"""

from __future__ import annotations

import inspect
import os
import sys
from dataclasses import fields

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _core_scenes():
    from opal_diffraction._scripts import load_example  # the examples are scripts, not a package

    gratings = load_example("gratings")
    prism = load_example("prism")

    yield "prism", prism.build_scene(160, 100)
    yield "fig5", gratings.fig5_scene(120, 60)
    yield "cd", gratings.cd_scene(120, 90)


def _blender_scenes():
    import bpy  # noqa: F401

    import opal_diffraction
    from opal_diffraction._scripts import load_example
    from opal_diffraction.blender.export import export_scene

    opal_example = load_example("opal")
    render_example = load_example("render_example")

    opal_diffraction.register()
    try:
        render_example.build_scene(160, 100, spp=4)
        dg = bpy.context.evaluated_depsgraph_get()
        yield "bpy_prism", export_scene(dg).scene
        opal_example.build_scene(96, 96, spp=4)
        dg = bpy.context.evaluated_depsgraph_get()
        yield "bpy_opal", export_scene(dg).scene
    finally:
        opal_diffraction.unregister()


def render_all(out: str) -> None:
    import opal_diffraction
    from opal_diffraction.core.render.frame import render
    from opal_diffraction.core.scene.settings import RenderSettings

    tree = os.path.dirname(os.path.dirname(os.path.realpath(opal_diffraction.__file__)))
    if tree != os.path.realpath(ROOT):  # e.g. another checkout's venv (its editable install) or PYTHONPATH
        print(f"note: rendering opal_diffraction and examples/ of {tree}, not of {ROOT}", file=sys.stderr)

    # the spectral films are compared (a checkout from before the RGB films keeps them always)
    keep = {"spectral_film": True} if "spectral_film" in inspect.signature(render).parameters else {}
    # the NumPy reference, not the compiled kernels (core/util/jit.py): a refactor is checked bit
    # for bit against it (a checkout from before the kernels has only the reference)
    reference = {"kernels": "numpy"} if "kernels" in {f.name for f in fields(RenderSettings)} else {}
    films = {}
    for scenes in (_core_scenes, _blender_scenes):
        for name, scene in scenes():
            settings = RenderSettings(samples=4, light_paths=100_000, seed=3, threads=2, **reference)
            r = render(scene, settings, **keep)
            films[name] = r.spectral
            for k, v in r.passes.items():
                films[f"{name}:{k}"] = v
            print(f"{name}: {r.spectral.shape}, mean {float(r.spectral.mean()):.6g}")
    np.savez_compressed(out, **films)


def compare(a: str, b: str) -> int:
    fa, fb = np.load(a), np.load(b)
    worst = 0.0
    for k in sorted(set(fa.files) | set(fb.files)):
        if k not in fa.files or k not in fb.files:
            print(f"{k}: only in {'the first' if k in fa.files else 'the second'}")
            worst = np.inf
            continue
        x, y = fa[k], fb[k]
        if x.shape != y.shape:
            print(f"{k}: shapes differ {x.shape} vs {y.shape}")
            worst = np.inf
            continue
        d = float(np.max(np.abs(x.astype(np.float64) - y))) if x.size else 0.0
        scale = float(np.max(np.abs(x))) if x.size else 0.0
        print(f"{k}: max |diff| {d:.3g} (max value {scale:.3g})")
        worst = max(worst, d)
    print(f"largest difference: {worst:.3g}")
    return 0 if worst == 0 else 1


if __name__ == "__main__":
    if sys.argv[1:2] == ["render"]:
        render_all(sys.argv[2])
    elif sys.argv[1:2] == ["compare"]:
        sys.exit(compare(sys.argv[2], sys.argv[3]))
    else:
        sys.exit(__doc__)
