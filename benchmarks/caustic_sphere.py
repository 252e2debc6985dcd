"""Benchmark (not a test): the caustic under a glass sphere, RMSE against wall time (issue 4).

A glass sphere (IOR 1.5, no dispersion, radius 1, centre at z = 1: resting on the floor; the
same flat-shaded icosphere mesh in every renderer) on a grey diffuse floor (albedo 0.5) under a
white point light above and behind it, 256 x 256. Compared with:

- Mitsuba 3 (pip ``mitsuba``, a benchmark-only dependency, benchmarks/requirements.txt): the
  reference for floor pixels is its ``ptracer`` (light tracing: it renders the caustic, but
  shows the glass black) at a high sample count, for sphere pixels its ``path`` integrator; its
  ``ptracer`` at increasing samples is the peer on the timing curve.
- Cycles (bpy, CPU) in the same run, Shadow Caustics (MNEE) off and on.

Every image is filtered the same way: ours and Cycles' with a Blackman-Harris pixel filter of
width 1.5 px (Cycles' convention, spanning +-1.5 px); Mitsuba renders 4x supersampled with a box
filter and the benchmark applies that Blackman-Harris filter while downsampling (Mitsuba has no
Blackman-Harris filter). RMSE is over linear Rec.709 RGB, separately for pixels whose whole
filter footprint sees the floor and those whose footprint sees only the sphere (masks by ray
casting our camera with our own accelerator).

    python benchmarks/caustic_sphere.py [--quick] [--no-cycles] [--no-llvm] [--profile] [--replot]

Writes docs/caustics.md's numbers: docs/caustics_rmse_vs_time.png, docs/caustics_table.csv and
docs/caustics_table.md (plus images under out/caustic_sphere/, where the references are cached:
``--fresh-reference`` recomputes them). Every timed configuration runs twice and the best time
is kept (the machine is shared).
"""

from __future__ import annotations

import argparse
import csv
import datetime
import hashlib
import json
import os
import platform
import sys
import time
from dataclasses import asdict, dataclass

import numpy as np

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.accel import build_accelerator
from opal_diffraction.core.sampling.camera import generate_rays
from opal_diffraction.core.integrators.light.light_pass import run_light_pass
from opal_diffraction.core.render.plan import plan_render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.frame import render_prepared
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.validation import validate
from opal_diffraction.core.scene.settings import RenderSettings

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
LLVM_CANDIDATES = ("/usr/lib/x86_64-linux-gnu/libLLVM-19.so", "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1",
                   "/usr/lib/aarch64-linux-gnu/libLLVM-19.so")
if "DRJIT_LIBLLVM_PATH" not in os.environ:  # Mitsuba's LLVM variants need a libLLVM newer than 15
    for _p in LLVM_CANDIDATES:
        if os.path.exists(_p):
            os.environ["DRJIT_LIBLLVM_PATH"] = _p
            break

FILTER_WIDTH = 1.5  # Blackman-Harris, +-1.5 px (ours and Cycles' default)
SS = 4              # Mitsuba's supersampling factor (box filter, then Blackman-Harris)
FLOOR, SPHERE = 0, 1
GOAL_FLOOR, GOAL_SPHERE = 0.05, 0.02


@dataclass(frozen=True)
class Spec:
    floor_size: float = 6.0                  # m, a square centred at the origin, z = 0
    sphere_subdivisions: int = 5             # icosphere: 20 * 4**5 = 20480 flat triangles
    ior: float = 1.5
    albedo: float = 0.5
    light: tuple = (-2.0, 3.0, 6.0)
    power: float = 1500.0                    # W: radiant intensity power / (4 pi) = 119.4 W/sr
    eye: tuple = (0.0, -6.0, 4.0)
    target: tuple = (0.0, -0.4, 0.5)
    lens: float = 50.0                       # mm, sensor width 36 mm, fit AUTO (square image)
    res: int = 256
    smooth: bool = False                     # the sphere shaded smooth: exact radial vertex normals
    sphere_mesh: str = "ico"                 # "ico": the icosphere above; "uv32": a UV sphere, 32 segments x 16
                                             # rings (Blender's default, 960 triangles; benchmarks/caustic_ball.py)

    @property
    def intensity(self) -> float:
        return self.power / (4 * np.pi)

    @property
    def fov_x_deg(self) -> float:
        return float(np.degrees(2 * np.arctan(18.0 / self.lens)))

    def key(self) -> str:
        d = asdict(self)
        if not d["smooth"]:
            d.pop("smooth")  # the flat scene keeps the key its cached references were made under
        if d["sphere_mesh"] == "ico":
            d.pop("sphere_mesh")  # so does the icosphere
        return hashlib.sha1(json.dumps(d, sort_keys=True).encode()).hexdigest()[:10]


def vertex_normals(spec: Spec, name: str, v) -> np.ndarray | None:
    """The shading normals per vertex (the sphere's radial ones when shaded smooth), or None: flat."""
    if name != "sphere" or not spec.smooth:
        return None
    n = np.asarray(v, np.float64) - np.array([0.0, 0.0, 1.0])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def meshes(spec: Spec, plane_only=False):
    """[(name, vertices, triangles, material)] shared by all three renderers."""
    h = spec.floor_size
    out = [("floor", *primitives.quad((0, 0, 0), (h, 0, 0), (0, h, 0)), FLOOR)]
    if not plane_only:
        out.append(("sphere", *(primitives.uv_sphere((0, 0, 1.0), 1.0, 32, 16) if spec.sphere_mesh == "uv32" else
                                primitives.icosphere((0, 0, 1.0), 1.0, spec.sphere_subdivisions)), SPHERE))
    return out


def camera(spec: Spec) -> Camera:
    return Camera.look_at(spec.eye, spec.target, lens=spec.lens, width=spec.res, height=spec.res)


# ---------------------------------------------------------------------------------------- ours
def our_scene(spec: Spec, plane_only=False) -> Scene:
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (spec.albedo,) * 3},
                                {"kind": "DIELECTRIC", "ior": spec.ior, "color": (1, 1, 1)}])
    s = Scene(materials=mats)
    for name, v, t, m in meshes(spec, plane_only):
        s.add_mesh(v, t, material=m, normals=vertex_normals(spec, name, v))
    s.lights = Lights.from_list([{"kind": "POINT", "position": spec.light, "power": spec.power}])
    s.camera = camera(spec)
    return s


def run_ours(spec: Spec, light_paths: int, samples: int, threads=2, plane_only=False, element_size=0.0, seed=0,
             wavelength_step=5.0, caustic_splat=True, **extra):
    """Our render: (RGB, wall seconds, RenderResult). ``res.stats`` gains ``cpu_s`` (process CPU
    time of the whole render, both threads), ``cpu_prepare_s``, ``cpu_light_s`` and ``cpu_eye_s``
    (the machine is shared: CPU time is what the render itself used). ``extra``: more
    RenderSettings (adaptive_threshold, adaptive_min_samples, ...)."""
    scene = our_scene(spec, plane_only)
    st = RenderSettings(samples=samples, light_paths=light_paths, threads=threads, element_size=element_size, seed=seed,
                        wavelength_step=wavelength_step, caustic_splat=caustic_splat, **extra)
    t0, c0 = time.perf_counter(), time.process_time()
    prepared = prepare(scene, st)
    c1 = time.process_time()
    plan = plan_render(prepared)
    light = run_light_pass(prepared, plan=plan) if plan.light_pass else None
    c2 = time.process_time()
    res = render_prepared(prepared, light, started_at=t0)
    dt, c3 = time.perf_counter() - t0, time.process_time()
    res.stats.update({"cpu_s": c3 - c0, "cpu_prepare_s": c1 - c0, "cpu_light_s": c2 - c1, "cpu_eye_s": c3 - c2})
    return res.rgb.astype(np.float64), dt, res


def masks(spec: Spec, plane_only=False, grid=7):
    """(H, W) labels: FLOOR or SPHERE where every point of the pixel's filter footprint (+-1.5
    px) sees that object, -1 elsewhere (edges, background, the 2-px image border)."""
    ms = meshes(spec, plane_only)
    v = np.concatenate([m[1] for m in ms])
    offs = np.cumsum([0] + [len(m[1]) for m in ms])
    t = np.concatenate([m[2] + o for m, o in zip(ms, offs)])
    tri_obj = np.concatenate([np.full(len(m[2]), m[3]) for m in ms])
    acc = build_accelerator(v.astype(np.float32), t.astype(np.int32))
    cam = camera(spec)
    n = spec.res
    ys, xs = np.mgrid[0:n, 0:n]
    o1 = np.linspace(-FILTER_WIDTH, FILTER_WIDTH, grid)
    ox, oy = np.meshgrid(o1, o1)
    x = (xs.ravel()[:, None] + 0.5 + ox.ravel()[None, :]).ravel()
    y = (ys.ravel()[:, None] + 0.5 + oy.ravel()[None, :]).ravel()
    o, d = generate_rays(cam, x, y)
    h = acc.intersect(o, d)
    obj = np.where(h.prim >= 0, tri_obj[np.maximum(h.prim, 0)], -1).reshape(n * n, -1)
    lab = np.where(np.all(obj == obj[:, :1], axis=1), obj[:, 0], -1).reshape(n, n)
    lab[:2], lab[-2:], lab[:, :2], lab[:, -2:] = -1, -1, -1, -1
    return lab


# ---------------------------------------------------------------------------------------- filters
def bh_matrix(n_low: int, ss: int, width=FILTER_WIDTH, first_low=0) -> np.ndarray:
    """(n_low, n_low * ss) weights: Blackman-Harris over +-width low-res pixels of the box-filtered
    high-res pixels' centres (rows normalised; low-res pixel i of a crop starting at first_low)."""
    hi = (np.arange(n_low * ss) + 0.5) / ss
    c = np.arange(n_low)[:, None] + 0.5
    x = (hi[None, :] - c) / (2 * width) + 0.5
    a0, a1, a2, a3 = 0.35875, 0.48829, 0.14128, 0.01168
    f = a0 - a1 * np.cos(2 * np.pi * x) + a2 * np.cos(4 * np.pi * x) - a3 * np.cos(6 * np.pi * x)
    f = np.where((x > 0) & (x < 1), f, 0.0)
    return f / f.sum(axis=1, keepdims=True)


def downsample(img_hi: np.ndarray, ss=SS) -> np.ndarray:
    """Blackman-Harris downsampling of an (H ss, W ss, 3) box-filtered render to (H, W, 3)."""
    h, w = img_hi.shape[0] // ss, img_hi.shape[1] // ss
    my, mx = bh_matrix(h, ss), bh_matrix(w, ss)
    tmp = np.einsum("yi,ijc->yjc", my, img_hi.astype(np.float64), optimize=True)
    return np.einsum("yjc,xj->yxc", tmp, mx, optimize=True)


def rmse(img, ref, mask) -> float:
    return float(np.sqrt(np.mean((img[mask] - ref[mask]) ** 2)))


# ---------------------------------------------------------------------------------------- Mitsuba
def write_ply(path, v, t, normals=None):
    v = np.ascontiguousarray(v, np.float32)
    props = "property float x\nproperty float y\nproperty float z\n"
    if normals is not None:  # per-vertex shading normals (Mitsuba interpolates them when face_normals is off)
        v = np.ascontiguousarray(np.concatenate([v, np.asarray(normals, np.float32)], axis=1))
        props += "property float nx\nproperty float ny\nproperty float nz\n"
    rec = np.zeros(len(t), dtype=[("n", "u1"), ("i", "<i4", 3)])
    rec["n"], rec["i"] = 3, t
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\n{props}"
            f"element face {len(t)}\nproperty list uchar int vertex_indices\nend_header\n")
    with open(path, "wb") as f:
        f.write(head.encode() + v.tobytes() + rec.tobytes())


def mitsuba_scene(spec: Spec, variant: str, integrator: str, cache: str, plane_only=False, crop=None, max_depth=64):
    """The same scene in Mitsuba 3: the same meshes as PLY (face normals, i.e. flat facets),
    intensity = power / (4 pi) W/sr, the same camera (fov along x), box filter at SS x the
    resolution. ``crop`` = (x0, y0, w, h) in low-res pixels."""
    import mitsuba as mi

    mi.set_variant(variant)
    mi.set_log_level(mi.LogLevel.Warn)
    shapes = {}
    for name, v, t, m in meshes(spec, plane_only):
        path = os.path.join(cache, f"{name}_{spec.key()}.ply")
        normals = vertex_normals(spec, name, v)
        if not os.path.exists(path):
            write_ply(path, v, t, normals)
        bsdf = ({"type": "diffuse", "reflectance": {"type": "rgb", "value": [spec.albedo] * 3}} if m == FLOOR else
                {"type": "dielectric", "int_ior": spec.ior, "ext_ior": 1.0})
        shapes[name] = {"type": "ply", "filename": path, "face_normals": normals is None, "bsdf": bsdf}
    n = spec.res * SS
    film = {"type": "hdrfilm", "width": n, "height": n, "rfilter": {"type": "box"}, "pixel_format": "rgb",
            "component_format": "float32"}
    if crop is not None:
        x0, y0, w, h = crop
        film.update(crop_offset_x=x0 * SS, crop_offset_y=y0 * SS, crop_width=w * SS, crop_height=h * SS)
    integ = {"type": integrator, "max_depth": max_depth}
    if integrator == "ptracer":
        integ["hide_emitters"] = True
    return mi.load_dict({
        "type": "scene",
        "integrator": integ,
        "sensor": {"type": "perspective", "fov": spec.fov_x_deg, "fov_axis": "x",
                   "to_world": mi.ScalarTransform4f().look_at(origin=list(spec.eye), target=list(spec.target), up=[0, 0, 1]),
                   "film": film, "sampler": {"type": "independent", "sample_count": 1}},
        **shapes,
        "light": {"type": "point", "position": list(spec.light), "intensity": {"type": "rgb", "value": [spec.intensity] * 3}},
    })


def run_mitsuba(spec: Spec, variant: str, integrator: str, spp: int, cache: str, seed=0, plane_only=False,
                crop=None, passes=1, max_depth=64):
    """(Blackman-Harris filtered RGB (H, W, 3) or the crop's, seconds incl. scene loading)."""
    import mitsuba as mi

    t0 = time.perf_counter()
    scene = mitsuba_scene(spec, variant, integrator, cache, plane_only, crop, max_depth)
    acc = None
    for p in range(passes):  # big references in several passes (bounded memory, progress)
        img = np.array(mi.render(scene, spp=spp, seed=seed * 1000 + p), np.float64)[..., :3]
        acc = img if acc is None else acc + img
    dt = time.perf_counter() - t0
    return downsample(acc / passes), dt


def mitsuba_llvm_ok() -> bool:
    if os.environ.get("MITSUBA_NO_LLVM"):  # e.g. only libLLVM 15 installed: its JIT aborts the process
        return False
    try:
        import mitsuba as mi

        mi.set_variant("llvm_ad_rgb")
        return True
    except Exception:
        return False


# ---------------------------------------------------------------------------------------- Cycles
def run_cycles(spec: Spec, samples: int, shadow_caustics: bool, cache: str, plane_only=False, seed=1, threads=2):
    """Cycles (CPU) through bpy on a factory-empty file; (linear RGB (H, W, 3), seconds of
    bpy.ops.render.render: sync, BVH, render and writing the EXR).

    With Shadow Caustics the sphere is shaded smooth: Cycles' manifold next-event estimation finds
    no caustic at all through flat facets (checked: 0.07 % of the caustic's energy flat, 47 %
    smooth, at 16 spp), so that curve renders interpolated normals on the same mesh."""
    import bpy

    from opal_diffraction.core.render.output import read_exr

    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    cy = sc.cycles
    cy.device = "CPU"
    cy.samples = samples
    cy.use_adaptive_sampling = False
    cy.use_denoising = False
    cy.seed = seed
    cy.max_bounces = cy.transmission_bounces = cy.glossy_bounces = cy.transparent_max_bounces = 64
    cy.diffuse_bounces = 8
    cy.caustics_refractive = cy.caustics_reflective = True
    cy.blur_glossy = 0.0
    cy.sample_clamp_direct = cy.sample_clamp_indirect = 0.0
    cy.pixel_filter_type = "BLACKMAN_HARRIS"
    cy.filter_width = FILTER_WIDTH
    sc.render.threads_mode = "FIXED"
    sc.render.threads = threads
    sc.render.resolution_x = sc.render.resolution_y = spec.res
    sc.render.resolution_percentage = 100
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.look = "None"
    sc.view_settings.exposure = 0.0
    sc.view_settings.gamma = 1.0
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"

    def material(name, kind):
        mat = bpy.data.materials.new(name)
        mat.use_nodes = True
        nt = mat.node_tree
        nt.nodes.clear()
        out = nt.nodes.new("ShaderNodeOutputMaterial")
        if kind == FLOOR:
            b = nt.nodes.new("ShaderNodeBsdfDiffuse")
            b.inputs["Color"].default_value = (spec.albedo, spec.albedo, spec.albedo, 1.0)
            b.inputs["Roughness"].default_value = 0.0
        else:
            b = nt.nodes.new("ShaderNodeBsdfGlass")
            b.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
            b.inputs["IOR"].default_value = spec.ior
            b.inputs["Roughness"].default_value = 0.0
        nt.links.new(b.outputs[0], out.inputs["Surface"])
        return mat

    for name, v, t, m in meshes(spec, plane_only):
        me = bpy.data.meshes.new(name)
        me.from_pydata(v.tolist(), [], t.tolist())
        me.update()
        for poly in me.polygons:
            poly.use_smooth = shadow_caustics and m == SPHERE  # flat facets as in ours and Mitsuba, but see above
        me.materials.append(material(name, m))
        ob = bpy.data.objects.new(name, me)
        sc.collection.objects.link(ob)
        ob.cycles.is_caustics_caster = shadow_caustics and m == SPHERE
        ob.cycles.is_caustics_receiver = shadow_caustics and m == FLOOR
    ld = bpy.data.lights.new("light", "POINT")
    ld.energy = spec.power
    ld.shadow_soft_size = 0.0
    ld.use_soft_falloff = False
    ld.cycles.is_caustics_light = shadow_caustics
    lo = bpy.data.objects.new("light", ld)
    lo.location = spec.light
    sc.collection.objects.link(lo)
    cd = bpy.data.cameras.new("camera")
    cd.lens, cd.sensor_width, cd.sensor_fit = spec.lens, 36.0, "AUTO"
    co = bpy.data.objects.new("camera", cd)
    from mathutils import Matrix

    co.matrix_world = Matrix(camera(spec).matrix.tolist())
    sc.collection.objects.link(co)
    sc.camera = co
    path = os.path.join(cache, f"cycles_{samples}_{int(shadow_caustics)}_{int(plane_only)}.exr")
    sc.render.filepath = path
    if os.path.exists(path):
        os.remove(path)
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    dt = time.perf_counter() - t0
    ch = read_exr(path)
    return np.stack([ch["R"], ch["G"], ch["B"]], axis=-1).astype(np.float64), dt


# ---------------------------------------------------------------------------------------- checks
def edge_positions(img, lab_plane, spec):
    """Sub-pixel positions of the floor's directly lit left and far edges: per row (left edge)
    and per column (far edge) where the luminance crosses half the lit floor's level nearby."""
    lum = img @ np.array([0.2126, 0.7152, 0.0722])
    out = {}
    n = spec.res
    rows = [y for y in range(n // 4, n - 4) if np.any(lab_plane[y] == FLOOR)]
    xs = []
    for y in rows:  # left edge: first crossing from dark (background) to the floor, left to right
        line = lum[y]
        fl = np.flatnonzero(lab_plane[y] == FLOOR)
        if len(fl) == 0 or fl[0] < 4:
            continue
        level = 0.5 * np.median(line[fl[0]:fl[0] + 8])
        i = np.flatnonzero((line[:-1] < level) & (line[1:] >= level))
        i = i[i < fl[0] + 2]
        if len(i):
            i = i[-1]
            xs.append(i + (level - line[i]) / max(line[i + 1] - line[i], 1e-12))
    out["left_edge_x"] = float(np.mean(xs)) if xs else float("nan")
    ys = []
    for x in range(n // 4, 3 * n // 4):  # far edge: from the top down
        col = lum[:, x]
        fl = np.flatnonzero(lab_plane[:, x] == FLOOR)
        if len(fl) == 0 or fl[0] < 4:
            continue
        level = 0.5 * np.median(col[fl[0]:fl[0] + 8])
        i = np.flatnonzero((col[:-1] < level) & (col[1:] >= level))
        i = i[i < fl[0] + 2]
        if len(i):
            i = i[-1]
            ys.append(i + (level - col[i]) / max(col[i + 1] - col[i], 1e-12))
    out["far_edge_y"] = float(np.mean(ys)) if ys else float("nan")
    return out


def unit_check(spec, cache, log, with_cycles):
    """A plane-only scene: the directly lit floor in every renderer (ratios) and its edges."""
    lab = masks(spec, plane_only=True)
    fl = lab == FLOOR
    ours, t_ours, _ = run_ours(spec, 0, 64, plane_only=True)
    mit, t_mit = run_mitsuba(spec, "scalar_rgb", "path", 16, cache, plane_only=True)
    res = {"ours": ours, "mitsuba": mit}
    if with_cycles:
        res["cycles"], _ = run_cycles(spec, 64, False, cache, plane_only=True)
    out = {"floor_pixels": int(fl.sum())}
    for k, img in res.items():
        out[k] = {"mean_rgb": img[fl].mean(axis=0).round(6).tolist(),
                  **{e: round(x, 3) for e, x in edge_positions(img, lab, spec).items()}}
    for k in res:
        if k != "mitsuba":
            out[f"{k}/mitsuba"] = (res[k][fl].mean(axis=0) / res["mitsuba"][fl].mean(axis=0)).round(5).tolist()
            out[f"{k}-mitsuba edge px"] = [round(out[k]["left_edge_x"] - out["mitsuba"]["left_edge_x"], 3),
                                          round(out[k]["far_edge_y"] - out["mitsuba"]["far_edge_y"], 3)]
    # the analytic radiance at the floor's centre pixel: albedo / pi * I cos / d^2
    log(f"unit check (plane only): {json.dumps(out)}")
    return out, res


# ---------------------------------------------------------------------------------------- references
def references(spec, cache, lab, quick, fresh, log, glass=True, spp=(512, 256)):
    """Floor: Mitsuba ptracer, sphere: Mitsuba path (each as two halves with different seeds, so
    their own noise can be measured). Cached in ``cache`` by the scene's key and sample counts.
    ``glass``: also the estimate of the caustic seen through the glass (flat facets only)."""
    variant = "llvm_ad_rgb" if mitsuba_llvm_ok() else "scalar_rgb"
    spp_pt, spp_path = spp  # per half, at 4x supersampling: 16 x that many light paths per pixel
    if quick and not all(os.path.exists(os.path.join(cache, f"ref_{n}_{spec.key()}_{s}.npz"))
                         for n, s in (("pt", spp_pt), ("path", spp_path))):
        spp_pt, spp_path = 64, 64  # a quick run without the cached full references: noisier ones
    ys, xs = np.nonzero(lab == SPHERE)
    pad = 3
    crop = (int(xs.min()) - pad, int(ys.min()) - pad, int(xs.max() - xs.min()) + 1 + 2 * pad,
            int(ys.max() - ys.min()) + 1 + 2 * pad)
    out = {}
    for name, integ, spp, cr in (("pt", "ptracer", spp_pt, None), ("path", "path", spp_path, crop)):
        path = os.path.join(cache, f"ref_{name}_{spec.key()}_{spp}.npz")
        if os.path.exists(path) and not fresh:
            z = np.load(path)
            out.update({k: z[k] for k in z.files})
            log(f"reference {integ} from {path} ({z['variant']}, {float(z[name + '_seconds']):.0f} s)")
            continue
        passes = max(1, spp // 128)  # several renders per half: bounded film memory
        halves, secs = [], 0.0
        for h in range(2):
            img, dt = run_mitsuba(spec, variant, integ, spp // passes, cache, seed=100 + h, crop=cr, passes=passes)
            halves.append(img)
            secs += dt
            log(f"reference {integ} half {h}: {spp} spp at {SS}x, {variant}, {dt:.1f} s")
        a, b = halves
        if cr is not None:
            x0, y0, w, h_ = cr
            fa, fb = np.full((spec.res, spec.res, 3), np.nan), np.full((spec.res, spec.res, 3), np.nan)
            fa[y0:y0 + h_, x0:x0 + w], fb[y0:y0 + h_, x0:x0 + w] = a, b
            a, b = fa, fb
        one = {name: 0.5 * (a + b), name + "_halfdiff": a - b, name + "_seconds": np.array(secs),
               name + "_spp": np.array(2 * spp), "variant": np.array(variant)}
        np.savez_compressed(path, **one)
        out.update(one)
    if not glass:
        return out
    path = os.path.join(cache, f"ref_glass_{spec.key()}_{int(out['pt_spp'])}.npz")
    if os.path.exists(path) and not fresh:
        z = np.load(path)
        out.update({k: z[k] for k in z.files})
    else:
        t0 = time.perf_counter()
        floor_direct, _ = run_mitsuba(spec, variant, "path", 32, cache, seed=7)  # direct + indirect, no caustics
        glass, unseen = caustics_through_glass(spec, lab, out["pt"] - floor_direct)
        one = {"glass": glass, "glass_unseen": np.array(unseen), "glass_seconds": np.array(time.perf_counter() - t0)}
        np.savez_compressed(path, **one)
        out.update(one)
    log(f"caustics seen through the glass (estimate): mean {out['glass'][lab == SPHERE].mean():.4f} over sphere "
        f"pixels, max {out['glass'].max():.2f}; {float(out['glass_unseen']):.0%} of the weight ends on floor the camera "
        f"does not see (counted as 0)")
    return out


def caustics_through_glass(spec: Spec, lab, caustic_floor, samples=256, seed=1):
    """An estimate of what Mitsuba's path reference lacks on sphere pixels: the caustic light on
    the floor seen through (or reflected in) the glass. Camera rays (our camera, Blackman-Harris
    weighted over +-1.5 px) follow the glass with Fresnel-sampled reflection and refraction,
    independently of our renderer's transport code (only the ray casting is shared); where one
    reaches the floor at a point the camera also sees directly, it takes the caustic part of the
    floor's radiance there from the Mitsuba images (ptracer minus path, bilinear at that point's
    pixel). Floor points the camera does not see count as 0 (the estimate is a lower bound);
    returns (estimate (H, W, 3), fraction of the weight that ended on such unseen floor points)."""
    cam = camera(spec)
    ms = meshes(spec)
    v = np.concatenate([m[1] for m in ms])
    offs = np.cumsum([0] + [len(m[1]) for m in ms])
    t = np.concatenate([m[2] + o for m, o in zip(ms, offs)])
    obj = np.concatenate([np.full(len(m[2]), m[3]) for m in ms])
    p3 = v[t]
    nrm = np.cross(p3[:, 1] - p3[:, 0], p3[:, 2] - p3[:, 0])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    acc = build_accelerator(v.astype(np.float32), t.astype(np.int32))
    rot, eye = np.asarray(cam.matrix)[:3, :3], np.asarray(cam.matrix)[:3, 3]
    half = 18.0 / spec.lens
    n_px = spec.res

    def project(x):  # world points -> continuous pixel coordinates (inverse of generate_rays)
        loc = (x - eye) @ rot
        return ((loc[:, 0] / -loc[:, 2]) / half + 1) * n_px / 2, (1 - (loc[:, 1] / -loc[:, 2]) / half) * n_px / 2

    def bilinear(img, x, y):
        x, y = np.clip(x - 0.5, 0, n_px - 1.001), np.clip(y - 0.5, 0, n_px - 1.001)
        x0, y0 = x.astype(int), y.astype(int)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]
        return (img[y0, x0] * (1 - fx) * (1 - fy) + img[y0, x0 + 1] * fx * (1 - fy)
                + img[y0 + 1, x0] * (1 - fx) * fy + img[y0 + 1, x0 + 1] * fx * fy)

    a = (0.35875, 0.48829, 0.14128, 0.01168)
    bh = lambda u: a[0] - a[1] * np.cos(2 * np.pi * u) + a[2] * np.cos(4 * np.pi * u) - a[3] * np.cos(6 * np.pi * u)  # noqa: E731
    rng = np.random.default_rng(seed)
    ys, xs = np.nonzero(lab == SPHERE)
    est, wsum, unseen = np.zeros((len(xs), 3)), np.zeros(len(xs)), np.zeros(len(xs))
    per = 16
    for _ in range(samples // per):  # batches of 16 samples per pixel
        ux, uy = rng.random((len(xs), per)), rng.random((len(xs), per))
        w = (bh(ux) * bh(uy)).ravel()
        x = (xs[:, None] + 0.5 + (ux - 0.5) * 2 * FILTER_WIDTH).ravel()
        y = (ys[:, None] + 0.5 + (uy - 0.5) * 2 * FILTER_WIDTH).ravel()
        pix = np.repeat(np.arange(len(xs)), per)
        o, d = (a_.astype(np.float64) for a_ in generate_rays(cam, x, y))
        alive = np.ones(len(pix), bool)
        val, uns = np.zeros((len(pix), 3)), np.zeros(len(pix))
        for depth in range(32):
            idx = np.flatnonzero(alive)
            if len(idx) == 0:
                break
            h = acc.intersect(o[idx].astype(np.float32), d[idx].astype(np.float32))
            miss = h.prim < 0
            alive[idx[miss]] = False
            idx, prim, tt = idx[~miss], h.prim[~miss], h.t[~miss].astype(np.float64)
            p = o[idx] + tt[:, None] * d[idx]
            on_floor = obj[prim] == FLOOR
            if on_floor.any():
                fi, pf = idx[on_floor], p[on_floor]
                if depth > 0:
                    px, py = project(pf)
                    dv = pf - eye
                    dist = np.linalg.norm(dv, axis=1)
                    hv = acc.intersect(np.broadcast_to(eye, pf.shape).astype(np.float32), (dv / dist[:, None]).astype(np.float32))
                    seen = (np.abs(hv.t - dist) < 1e-3) & (px > 2) & (px < n_px - 2) & (py > 2) & (py < n_px - 2)
                    val[fi[seen]] = bilinear(caustic_floor, px[seen], py[seen])
                    uns[fi[~seen]] = 1.0
                alive[fi] = False
            g = ~on_floor
            idx, p, prim = idx[g], p[g], prim[g]
            n, dd = nrm[prim], d[idx]
            c = -(dd * n).sum(1)
            front = c > 0
            n, c = np.where(front[:, None], n, -n), np.abs(c)
            eta = np.where(front, 1 / spec.ior, spec.ior)
            s2 = eta ** 2 * (1 - c ** 2)
            ct = np.sqrt(np.maximum(0, 1 - s2))
            r_s, r_p = (eta * c - ct) / (eta * c + ct), (c - eta * ct) / (c + eta * ct)
            fres = np.where(s2 >= 1, 1.0, 0.5 * (r_s ** 2 + r_p ** 2))
            refl = rng.random(len(idx)) < fres
            nd = np.where(refl[:, None], dd + 2 * c[:, None] * n, eta[:, None] * dd + (eta * c - ct)[:, None] * n)
            d[idx] = nd / np.linalg.norm(nd, axis=1, keepdims=True)
            o[idx] = p + np.where(refl, 1e-5, -1e-5)[:, None] * n
        np.add.at(est, pix, val * w[:, None])
        np.add.at(wsum, pix, w)
        np.add.at(unseen, pix, uns * w)
    out = np.zeros((n_px, n_px, 3))
    out[ys, xs] = est / wsum[:, None]
    return out, float(np.sum(unseen) / np.sum(wsum))


# ---------------------------------------------------------------------------------------- main
def best_of(n, fn):
    best = None
    for _ in range(n):
        r = fn()
        if best is None or r[1] < best[1]:
            best = r
    return best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer and smaller configurations (a few minutes)")
    ap.add_argument("--no-cycles", action="store_true")
    ap.add_argument("--no-llvm", action="store_true", help="skip Mitsuba's LLVM ptracer curve")
    ap.add_argument("--fresh-reference", action="store_true")
    ap.add_argument("--repeats", type=int, default=2, help="runs per timed configuration (best time kept)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--cache", default=os.path.join(ROOT, "out", "caustic_sphere"))
    ap.add_argument("--docs", default=os.path.join(ROOT, "docs"))
    ap.add_argument("--profile", action="store_true", help="pyinstrument profile of our light pass only")
    ap.add_argument("--replot", action="store_true", help="redo the plot and tables from the last run's results")
    ap.add_argument("--ref-spp", type=int, default=512, help="--splat: the ptracer reference's spp per half at 4x "
                    "(the path reference's: half that)")
    ap.add_argument("--shading", choices=("flat", "smooth", "both"), default="both", help="--splat: which spheres")
    ap.add_argument("--splat", action="store_true",
                    help="the camera splat (caustic_splat) on flat and smooth spheres against Mitsuba ptracer only")
    args = ap.parse_args(argv)
    os.makedirs(args.cache, exist_ok=True)
    spec = Spec()
    t_all = time.perf_counter()
    log_lines = []

    def log(msg):
        line = f"[{time.perf_counter() - t_all:7.1f} s] {msg}"
        print(line, flush=True)
        log_lines.append(line)

    if args.profile:
        return profile_light_pass(spec, 1_000_000)
    if args.splat:
        return splat_benchmark(args, log)
    results = os.path.join(args.cache, f"results{'_quick' if args.quick else ''}.json")
    if args.replot:
        with open(results) as f:
            r = json.load(f)
        write_outputs(args, spec, r["rows"], r["check"], {k: np.array(v) for k, v in r["ref"].items()}, r["noise_floor"],
                      r["noise_sphere"], [], r["total_s"])
        return 0

    lab = masks(spec)
    floor, sphere = lab == FLOOR, lab == SPHERE
    log(f"scene {spec}; masks: {int(floor.sum())} floor px, {int(sphere.sum())} sphere px")
    check, check_imgs = unit_check(spec, args.cache, log, not args.no_cycles)
    ref = references(spec, args.cache, lab, args.quick, args.fresh_reference, log)
    ref_floor, ref_sphere = ref["pt"], ref["path"]
    ref_sphere_full = np.nan_to_num(ref_sphere) + ref["glass"]  # + the caustic seen through the glass (estimate)
    noise_floor = float(np.sqrt(np.mean(ref["pt_halfdiff"][floor] ** 2)) / 2)
    noise_sphere = float(np.sqrt(np.mean(ref["path_halfdiff"][sphere] ** 2)) / 2)
    log(f"reference noise (RMSE of the mean, from its two halves): floor {noise_floor:.4f}, sphere {noise_sphere:.4f}")

    rows = []

    def record(renderer, config, img, secs, extra=None):
        r = {"renderer": renderer, "config": config, "seconds": round(secs, 2),
             "floor_rmse": round(rmse(img, ref_floor, floor), 4), "sphere_rmse": round(rmse(img, ref_sphere, sphere), 4),
             "sphere_rmse_vs_path_plus_glass": round(rmse(img, ref_sphere_full, sphere), 4)}
        r.update(extra or {})
        rows.append(r)
        log(f"{renderer:24s} {config:28s} {secs:7.2f} s  floor {r['floor_rmse']:.4f}  sphere {r['sphere_rmse']:.4f}"
            + (f"  {extra}" if extra else ""))
        return r

    images = {}
    # ours: light paths and eye samples together; defaults (automatic element size, 5 nm), then
    # tuned for this achromatic scene: a 30 nm wavelength step, so the element cap (64 M floats over all
    # wavelengths) allows finer elements (4 mm asked for, 5.7 mm granted: the cap still coarsens them)
    series = [("ours (defaults)", 0.0, 5.0,
               [(250_000, 4), (1_000_000, 16), (4_000_000, 64)] if args.quick else
               [(250_000, 4), (500_000, 8), (1_000_000, 16), (2_000_000, 32), (4_000_000, 64)]),
              ("ours (element_size 4 mm, 30 nm step)", 0.004, 30.0,
               [(1_000_000, 16), (4_000_000, 64)] if args.quick else
               [(500_000, 8), (1_000_000, 16), (2_000_000, 32), (4_000_000, 64)])]
    for label, es, step, cfgs in series:
        for lp, spp in cfgs:
            img, dt, res = best_of(args.repeats, lambda: run_ours(spec, lp, spp, args.threads, element_size=es,
                                                                  wavelength_step=step))
            caus = res.passes["Caustics"].astype(np.float64)
            record(label, f"{lp / 1e6:g} M paths, {spp} spp", img, dt,
                   {"light_pass_s": round(res.stats.get("light_pass_s", 0.0), 2), "elements": res.stats.get("elements"),
                    "sphere_rmse_without_caustics": round(rmse(img - caus, ref_sphere, sphere), 4)})
            images[f"ours_{es}_{step}_{lp}_{spp}"] = img
            images[f"ours_{es}_{step}_{lp}_{spp}_caustics"] = caus
    # Mitsuba ptracer (the peer for the floor), and path (for the sphere)
    variants = (["llvm_ad_rgb"] if not args.no_llvm and mitsuba_llvm_ok() else []) + ["scalar_rgb"]
    for var in variants:
        spps = ([1, 4, 16] if args.quick else [1, 4, 16, 64]) if var.startswith("llvm") else \
            ([1, 4] if args.quick else [1, 2, 4, 8, 16, 32])
        for spp in spps:
            img, dt = best_of(args.repeats, lambda: run_mitsuba(spec, var, "ptracer", spp, args.cache, seed=spp))
            record(f"mitsuba ptracer {var}", f"{spp} spp at {SS}x ({spp * SS * SS} paths/px)", img, dt)
            images[f"mitsuba_pt_{var}_{spp}"] = img
    var = variants[0]
    for spp in ([1, 4] if args.quick else [1, 4, 16]):
        img, dt = best_of(args.repeats, lambda: run_mitsuba(spec, var, "path", spp, args.cache, seed=spp))
        record(f"mitsuba path {var}", f"{spp} spp at {SS}x", img, dt)
    if not args.no_cycles:
        for sc_on in (False, True):
            for spp in ([16, 128] if args.quick else [16, 64, 256, 1024] if not sc_on else [16, 64, 256]):
                img, dt = best_of(args.repeats, lambda: run_cycles(spec, spp, sc_on, args.cache))
                record(f"cycles shadow caustics {'on' if sc_on else 'off'}", f"{spp} spp", img, dt)
                images[f"cycles_{int(sc_on)}_{spp}"] = img

    np.savez_compressed(os.path.join(args.cache, "images.npz"), ref_floor=ref_floor, ref_sphere=ref_sphere, labels=lab,
                        **images)
    total = time.perf_counter() - t_all
    with open(results, "w") as f:
        json.dump({"rows": rows, "check": check, "noise_floor": noise_floor, "noise_sphere": noise_sphere, "total_s": total,
                   "ref": {k: ref[k].tolist() for k in ("pt_spp", "path_spp", "variant", "glass_unseen")}}, f, indent=1)
    write_outputs(args, spec, rows, check, ref, noise_floor, noise_sphere, log_lines, total)
    log(f"done in {time.perf_counter() - t_all:.0f} s")
    return 0


def splat_benchmark(args, log) -> int:
    """Flat facets and the smooth-shaded sphere: ours with the camera splat (caustic_splat, the
    default) and without, against Mitsuba 3 ptracer (LLVM if available) in the same run, best of
    ``--repeats``. Floor RMSE against the ptracer reference, sphere RMSE against the path
    reference (also without our Caustics pass: the part the path reference cannot have).
    Writes docs/caustics_splat_table.md and PNGs under out/caustic_sphere/."""
    from opal_diffraction.core.render.output import write_png

    rows = []
    var = "llvm_ad_rgb" if not args.no_llvm and mitsuba_llvm_ok() else "scalar_rgb"
    for smooth in {"flat": (False,), "smooth": (True,), "both": (False, True)}[args.shading]:
        spec = Spec(smooth=smooth)
        shade = "smooth" if smooth else "flat"
        lab = masks(spec)
        floor, sphere = lab == FLOOR, lab == SPHERE
        log(f"{shade}: references ({args.ref_spp} spp per half)")
        ref = references(spec, args.cache, lab, False, args.fresh_reference, log, glass=False,
                         spp=(args.ref_spp, args.ref_spp // 2))
        noise_floor = float(np.sqrt(np.mean(ref["pt_halfdiff"][floor] ** 2)) / 2)
        noise_sphere = float(np.sqrt(np.nanmean(ref["path_halfdiff"][sphere] ** 2)) / 2)
        log(f"{shade}: reference noise floor {noise_floor:.4f}, sphere {noise_sphere:.4f} ({ref['variant']})")
        shown = {"mitsuba ptracer reference": ref["pt"]}

        def record(renderer, config, img, secs, caus=None, extra=None):
            r = {"shading": shade, "renderer": renderer, "config": config, "seconds": round(secs, 2),
                 "floor_rmse": round(rmse(img, ref["pt"], floor), 4),
                 "sphere_rmse": round(rmse(img, ref["path"], sphere), 4)}
            if caus is not None:
                r["sphere_rmse_without_caustics"] = round(rmse(img - caus, ref["path"], sphere), 4)
            r.update(extra or {})
            rows.append(r)
            log(f"{shade:6s} {renderer:26s} {config:24s} {secs:7.2f} s (CPU {r.get('cpu_s', 0):6.2f} s)  floor "
                f"{r['floor_rmse']:.4f}  sphere {r['sphere_rmse']:.4f}  {r.get('sphere_rmse_without_caustics', '')}")

        def cpu_timed(fn):  # (result..., CPU seconds of this process: every thread, not the other jobs')
            def run():
                c0 = time.process_time()
                out = fn()
                return (*out, time.process_time() - c0)
            return run

        # (light paths, spp, splat, Fresnel split at the first glass hit)
        cfgs = [(100_000, 16, True, True), (100_000, 24, True, True), (250_000, 8, True, True),
                (250_000, 32, True, True), (100_000, 24, True, False), (250_000, 32, False, True)]
        if not args.quick:
            cfgs += [(1_000_000, 64, True, True)]
        for lp, spp, splat, split in cfgs:
            img, dt, res = best_of(args.repeats, lambda: run_ours(spec, lp, spp, args.threads, caustic_splat=splat,
                                                                  fresnel_split=split))
            caus = res.passes["Caustics"].astype(np.float64)
            st = res.stats
            label = f"ours, splat {'on' if splat else 'off'}" + ("" if split else ", no Fresnel split")
            record(label, f"{lp / 1e6:g} M paths, {spp} spp", img, dt, caus,
                   {"light_pass_s": round(st.get("light_pass_s", 0.0), 2), "cpu_s": round(st["cpu_s"], 2),
                    "cpu_light_s": round(st["cpu_light_s"], 2), "cpu_eye_s": round(st["cpu_eye_s"], 2)})
            shown[f"ours splat {'on' if splat else 'off'}{'' if split else ' nosplit'} {lp / 1e6:g}M {spp}spp"] = img
        for spp in ([4, 16] if args.quick else [4, 16, 64]):
            img, dt, cpu = best_of(args.repeats, cpu_timed(lambda: run_mitsuba(spec, var, "ptracer", spp, args.cache,
                                                                               seed=spp)))
            record(f"mitsuba ptracer {var}", f"{spp} spp at {SS}x", img, dt, extra={"cpu_s": round(cpu, 2)})
            shown[f"mitsuba ptracer {spp}spp"] = img
        for name, img in shown.items():
            fn = os.path.join(args.cache, f"splat_{shade}_{name.replace(' ', '_')}.png")
            write_png(fn, np.nan_to_num(img).astype(np.float32))
    with open(os.path.join(args.docs, f"caustics_splat_table{'' if args.shading == 'both' else '_' + args.shading}.md"),
              "w") as f:
        f.write(f"Camera splat benchmark, {datetime.date.today()}, `benchmarks/caustic_sphere.py --splat"
                f"{' --quick' if args.quick else ''}` (best of {args.repeats}; Mitsuba {var}).\n\n")
        f.write("| shading | renderer | configuration | wall (s) | CPU (s) | CPU light / eye (s) | floor RMSE | "
                "sphere RMSE vs path | sphere, ours minus its Caustics pass |\n"
                "|---|---|---|---:|---:|---:|---:|---:|---:|\n")
        for r in rows:
            split = f"{r['cpu_light_s']:.2f} / {r['cpu_eye_s']:.2f}" if "cpu_eye_s" in r else ""
            f.write(f"| {r['shading']} | {r['renderer']} | {r['config']} | {r['seconds']:.2f} | {r.get('cpu_s', 0):.2f} | "
                    f"{split} | {r['floor_rmse']:.4f} | {r['sphere_rmse']:.4f} | "
                    f"{r.get('sphere_rmse_without_caustics', '')} |\n")
    with open(os.path.join(args.cache, f"splat_results_{args.shading}.json"), "w") as f:
        json.dump(rows, f, indent=1)
    return 0


def profile_light_pass(spec: Spec, paths: int) -> int:
    from pyinstrument import Profiler

    from opal_diffraction.core.integrators.light.light_pass import run_light_pass
    from opal_diffraction.core.render.prepare import prepare

    scene = validate(our_scene(spec)).scene
    st = RenderSettings(samples=1, light_paths=paths, threads=1)
    ctx = prepare(scene, st)
    prof = Profiler(interval=0.002)
    prof.start()
    run_light_pass(ctx, paths, plan=plan_render(ctx))
    prof.stop()
    print(prof.output_text(unicode=False, color=False, show_all=False))
    return 0


def write_outputs(args, spec, rows, check, ref, noise_floor, noise_sphere, log_lines, total_s):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(args.docs, exist_ok=True)
    suffix = "_quick" if args.quick else ""
    keys = ["renderer", "config", "seconds", "floor_rmse", "sphere_rmse", "sphere_rmse_without_caustics",
            "sphere_rmse_vs_path_plus_glass", "light_pass_s",
            "elements"]
    with open(os.path.join(args.docs, f"caustics_table{suffix}.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, keys, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    with open(os.path.join(args.docs, f"caustics_table{suffix}.md"), "w") as f:
        import subprocess

        try:
            commit = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                    check=True).stdout.strip()
        except Exception:
            commit = os.environ.get("OPAL_COMMIT", "unknown")
        f.write(f"Measured {datetime.date.today().isoformat()} at commit {commit} on {platform.machine()} with "
                f"{os.cpu_count()} cores "
                f"(shared: best of {args.repeats} runs per configuration), `python benchmarks/caustic_sphere.py"
                f"{' --quick' if args.quick else ''}`, {total_s / 60:.1f} min in all.\n\n")
        f.write(f"Reference: floor = Mitsuba ptracer {int(ref['pt_spp'])} spp at {SS}x ({ref['variant']}), "
                f"own noise {noise_floor:.4f}; sphere = Mitsuba path {int(ref['path_spp'])} spp at {SS}x, own noise "
                f"{noise_sphere:.4f}; the caustic seen through the glass (last column) is an estimate from the "
                f"ptracer image, a lower bound: {float(ref['glass_unseen']):.0%} of the weight through the glass ends on "
                f"floor the camera does not see directly, counted as 0.\n\n")
        f.write("| renderer | configuration | time (s) | floor RMSE | sphere RMSE | sphere RMSE, our image minus its "
                "Caustics pass | sphere RMSE vs path + caustics seen through the glass |\n|---|---|---:|---:|---:|---:|---:|\n")
        for r in rows:
            extra = r.get("sphere_rmse_without_caustics")
            f.write(f"| {r['renderer']} | {r['config']} | {r['seconds']:.2f} | {r['floor_rmse']:.4f} | "
                    f"{r['sphere_rmse']:.4f} | {'' if extra is None else f'{extra:.4f}'} | "
                    f"{r['sphere_rmse_vs_path_plus_glass']:.4f} |\n")
        f.write("\nFirst measured configuration that reaches the goal (floor <= %.2f vs ptracer, sphere <= %.2f vs "
                "path), per renderer, and the time at which its floor RMSE crosses %.2f (log-log interpolation "
                "between measured configurations):\n\n| renderer | floor goal | floor %.2f reached at | sphere goal | "
                "both |\n|---|---|---|---|---|\n" % (GOAL_FLOOR, GOAL_SPHERE, GOAL_FLOOR, GOAL_FLOOR))
        groups = {}
        for r in rows:
            groups.setdefault(r["renderer"], []).append(r)
        for name, rs in groups.items():
            def first(ok):
                hit = [r for r in sorted(rs, key=lambda r: r["seconds"]) if ok(r)]
                return f"{hit[0]['seconds']:.1f} s ({hit[0]['config']})" if hit else "not reached"
            def crossing(key, goal):
                rr = sorted(rs, key=lambda r: r["seconds"])
                for a, b in zip(rr, rr[1:]):
                    if a[key] > goal >= b[key]:
                        f_ = np.log(a[key] / goal) / np.log(a[key] / b[key])
                        return f"~{np.exp(np.log(a['seconds']) + f_ * np.log(b['seconds'] / a['seconds'])):.1f} s"
                return f"{rr[0]['seconds']:.1f} s or less" if rr[0][key] <= goal else "-"
            f.write(f"| {name} | {first(lambda r: r['floor_rmse'] <= GOAL_FLOOR)} | {crossing('floor_rmse', GOAL_FLOOR)} | "
                    f"{first(lambda r: r['sphere_rmse'] <= GOAL_SPHERE)} | "
                    f"{first(lambda r: r['floor_rmse'] <= GOAL_FLOOR and r['sphere_rmse'] <= GOAL_SPHERE)} |\n")
        f.write("\nUnit check (plane only, mean over directly lit floor pixels):\n\n```\n"
                + json.dumps(check, indent=1) + "\n```\n")
    fig, axes = plt.subplots(1, 3, figsize=(16, 5.6))
    groups = {}
    for r in rows:
        groups.setdefault(r["renderer"], []).append(r)
    style = {"ours (defaults)": ("C3", "o"), "ours (element_size 4 mm, 30 nm step)": ("C5", "o"),
             "mitsuba ptracer scalar_rgb": ("C0", "s"), "mitsuba ptracer llvm_ad_rgb": ("C9", "s"),
             "mitsuba path scalar_rgb": ("C2", "^"), "mitsuba path llvm_ad_rgb": ("C2", "^"),
             "cycles shadow caustics off": ("C7", "v"), "cycles shadow caustics on": ("C1", "D")}
    panels = ((axes[0], "floor_rmse", GOAL_FLOOR, noise_floor, "floor pixels, vs Mitsuba ptracer"),
              (axes[1], "sphere_rmse", GOAL_SPHERE, noise_sphere, "sphere pixels, vs Mitsuba path\n"
               "(which cannot show the caustic seen through the glass)"),
              (axes[2], "sphere_rmse_vs_path_plus_glass", GOAL_SPHERE, noise_sphere,
               "sphere pixels, vs Mitsuba path + the caustic seen\nthrough the glass (estimate from ptracer)"))
    for ax, key, goal, noise, title in panels:
        for name, rs in groups.items():
            c, m = style.get(name, ("k", "x"))
            ax.plot([r["seconds"] for r in rs], [r[key] for r in rs], marker=m, color=c, label=name)
        for name in [g for g in groups if g.startswith("ours")] if key == "sphere_rmse" else []:
            rs = groups[name]
            ax.plot([r["seconds"] for r in rs], [r["sphere_rmse_without_caustics"] for r in rs], ls="--", marker="o",
                    mfc="none", color=style.get(name, ("k", ""))[0], label=name + " minus its Caustics pass")
        ax.axhline(goal, color="k", ls=":", lw=1, label="goal")
        ax.axhline(noise, color="0.6", ls="-.", lw=1, label="reference's own noise")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time (s), best of %d, 2 shared cores" % args.repeats)
        ax.set_ylabel("RMSE (linear Rec.709 RGB)")
        ax.set_title(title, fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
    handles = {}
    for ax in axes:
        for h, lab_ in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(lab_, h)
    fig.legend(list(handles.values()), list(handles.keys()), loc="lower center", ncol=4, fontsize=8)
    fig.suptitle(f"Glass sphere caustic, {spec.res}x{spec.res}: RMSE against wall time", fontsize=11)
    fig.tight_layout(rect=(0, 0.13, 1, 1))
    fig.savefig(os.path.join(args.docs, f"caustics_rmse_vs_time{suffix}.png"), dpi=110)
    if log_lines:
        with open(os.path.join(args.cache, f"log{suffix}.txt"), "w") as f:
            f.write("\n".join(log_lines) + "\n")


if __name__ == "__main__":
    sys.exit(main())
