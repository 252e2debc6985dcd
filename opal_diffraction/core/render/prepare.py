"""Preparation: a validated scene and its settings turned into everything the passes read.

``prepare(scene, settings) -> PreparedScene`` is the first step of the one-way pipeline

    Scene --prepare--> PreparedScene --plan--> RenderPlan --light pass--> LightPassResult
          --eye pass (tiles x rounds)--> Film --> RenderResult

(render.py orchestrates it). A PreparedScene is frozen and its arrays are read-only: the passes
read it from any number of threads (and, later, machines) and nothing writes back into it. It
holds the acceleration structure, the spectra of materials, lights and world on the wavelength
grid, per-triangle normals, offsets and grating frames, the shading normals per corner (None for
a flat scene), and the light pass's targets (which
objects bend light, which receive it, how much light each lamp sends their way), so the plan
can decide without running anything. With object motion blur, a ray caster and triangle frames
per time bin of the shutter (``motion_bins``, docs/physics.md section 6.13).

The camera and the eye-only settings (samples, rounds, tiles, filter, time limit) do not change
any of that: ``with_view`` swaps them and keeps the rest, which is what the rendered viewport
does when only the view moves (the light pass's result stays valid: same ``key``).
"""

from __future__ import annotations

import itertools
import threading
import time
from dataclasses import dataclass, fields, is_dataclass, replace

import numpy as np

from ..accel import build_accelerator, default_threads
from ..util.cancel import OutOfTime, check, run_cancellable
from ..lights.environment import EnvironmentMap
from ..util.geometry import normals_from_cross, triangle_normals
from ..gratings.radiance import PreparedGratings, prepare_gratings, triangle_tangents
from ..gratings.layering import attach_layering
from ..gratings.directions import smooth_corner_tangents
from ..integrators.light.targets import LightTargets, find_light_targets
from ..lights.sources import PreparedLights, prepare_lights
from ..materials.spectra import PreparedMaterials, prepare_materials
from ..materials.bsdf import microfacet_materials
from ..lights.mesh_lights import MeshLights
from ..opal.volume import VolumeDomains
from ..scene.model import Camera, Scene
from ..scene.validation import _validate_camera, validate
from ..scene.settings import AUTO_LIGHT_PATHS_RANGE, EYE_ONLY_SETTINGS, RenderSettings, auto_light_paths
from ..spectral.spectrum import SpectralConverter, WavelengthGrid
from ..materials.textures import PreparedTextures, prepare_textures
from ..transport.walker import smooth_triangles

__all__ = ["PreparedScene", "prepare", "scene_extent", "OFFSET_RELATIVE"]

#: Self-intersection offset: this fraction of the scene's extent, plus float32 rounding of each
#: triangle's coordinates.
OFFSET_RELATIVE = 1e-5
#: Scenes smaller than this (m) are cast with the NumPy BVH: Embree's epsilons are absolute.
EMBREE_MIN_EXTENT = 1e-10

_keys = itertools.count(1)  # one key per preparation: a light-pass result belongs to one key


def _read_only(x):
    """``x`` with every array in it read-only: arrays become read-only views (the arrays they
    view, which may be the caller's, keep their flags), dataclasses are frozen field by field."""
    if isinstance(x, np.ndarray):
        if x.flags.writeable:
            x = x.view()
            x.flags.writeable = False
        return x
    if is_dataclass(x) and not isinstance(x, (type, Scene, RenderSettings)):
        for f in fields(x):
            object.__setattr__(x, f.name, _read_only(getattr(x, f.name)))
    return x


@dataclass(frozen=True)
class PreparedScene:
    """A scene ready to trace. Read-only; build it with :func:`prepare`."""

    scene: Scene                       # the validated scene
    settings: RenderSettings           # validated
    threads: int                       # the thread budget every pool of this render shares
    conv: SpectralConverter            # the wavelength grid, CMFs, RGB <-> spectrum
    accel: object                      # accel.Accelerator: ray casting over scene.triangles
    materials: PreparedMaterials       # spectra and kinds per material
    lights: PreparedLights             # frames, areas and emission spectra per light
    gratings: PreparedGratings         # grating parameters per material
    tri_normal: np.ndarray             # (T, 3) float32 unit geometric normals
    tri_offset: np.ndarray             # (T,) float32 self-intersection offset per triangle
    tri_material: np.ndarray           # (T,) int32
    tri_grating_tangent: np.ndarray    # (T, 3) float32 unit grating vectors of grating triangles (other rows
    #                                    zero); (0, 3) without gratings
    tri_period: np.ndarray             # (T,) float32 nm per-triangle period override (0: the material's), or (0,)
    world_spectrum: np.ndarray         # (n,) float32 radiance of a uniform world; with a map, the map's
    #                                    mean over the sphere (what does not sample the map yet uses)
    environment: EnvironmentMap | None  # the world map (radiance = world colour x image), or None: uniform
    textures: PreparedTextures         # images and per-material bindings (core/materials/textures.py, core/materials/surface.py)
    corner_uvs: np.ndarray             # (T, 3, 2) float32 per-corner UVs, or (0, 3, 2)
    corner_tangents: np.ndarray        # (T, 3, 4) float32 per-corner tangent + bitangent sign, or (0, 3, 4)
    extent: float                      # metres: the scene's size (prepare.scene_extent)
    offset_base: float                 # metres: the scene-scaled part of the offsets
    light_targets: LightTargets        # what the light pass aims at and who receives
    mesh_lights: MeshLights | None     # the emitting triangles as lights (None: no material emits)
    warnings: tuple[str, ...]          # from validation (dropped triangles, ...)
    prepare_s: float                   # seconds spent validating and preparing
    key: int                           # identity of the geometry, materials and lights
    corner_normals: np.ndarray | None = None  # (T, 3, 3) float32 unit shading normals per corner; None: flat
    # (T,) bool: triangles whose corner normals differ (transport.smooth_triangles); None: flat
    smooth_triangles: np.ndarray | None = None
    # (M,) bool: rough and layered materials, shaded with core/materials/bsdf.py (bsdf.microfacet_materials)
    microfacet: np.ndarray | None = None
    # opal volume domains (core/opal/volume.py: lookup(points, prim)); None: the scene has none
    opal_domains: VolumeDomains | None = None
    # (T, 3, 3) float32 smooth grating tangents per corner of grating triangles (core/gratings/directions.py;
    # other rows zero), or None
    corner_grating_tangent: np.ndarray | None = None
    # object motion blur (docs/physics.md section 6.13): per time bin of scene.motion_vertices, its
    # ray caster and triangle frames (MotionBin); empty: the geometry does not move
    motion_bins: tuple = ()

    @property
    def grid(self) -> WavelengthGrid:
        return self.conv.grid

    def with_view(self, camera: Camera | None = None, **eye_settings) -> "PreparedScene":
        """The same prepared scene seen through ``camera`` and/or with other eye-only settings
        (``samples``, ``round_samples``, ``tile_size``, ``filter_width``, ``time_limit``,
        ``spectral_exr``). Nothing is rebuilt; the light pass's result stays valid."""
        bad = set(eye_settings) - EYE_ONLY_SETTINGS
        if bad:
            raise ValueError(f"with_view changes only eye-pass settings, not {sorted(bad)}: prepare again")
        # the camera is checked as validate() checks a whole scene's (and so made the same: a
        # camera given here renders as a fresh preparation with it would)
        scene = self.scene if camera is None else replace(self.scene, camera=_validate_camera(camera))
        settings = replace(self.settings, **eye_settings) if eye_settings else self.settings
        if eye_settings:
            settings.validate()
        return replace(self, scene=scene, settings=settings)


def scene_extent(v: np.ndarray) -> float:
    """The scene's size (m): the longest side of its bounding box, or its distance from the
    origin for a flat point, 1 for an empty scene. Epsilons scale with it, so a scene renders
    the same at 1e-9 m and at 1e9 m."""
    if len(v) == 0:
        return 1.0
    extent = float(np.max(np.ptp(v, axis=0)))
    return extent if extent > 0 else max(float(np.max(np.abs(v))), 1e-30)


@dataclass(frozen=True)
class MotionBin:
    """One time bin of object motion: the geometry at the bin's centre (docs/physics.md section 6.13)."""

    accel: object            # accel.Accelerator over the bin's vertices (the same triangles)
    tri_normal: np.ndarray   # (T, 3) float32
    tri_offset: np.ndarray   # (T,) float32, as PreparedScene.tri_offset


def motion_bins(scene: Scene, t: np.ndarray, base: float, backend: str, stopped=None) -> tuple:
    """The MotionBin of each of ``scene.motion_vertices``' bins (empty: none)."""
    mv = np.asarray(scene.motion_vertices, np.float32)
    out = []
    for vk in (mv if mv.size else ()):
        check(stopped)
        out.append(MotionBin(accel=build_accelerator(vk, t, backend, threads=1, stopped=stopped),
                             tri_normal=triangle_normals(vk, t).astype(np.float32),
                             tri_offset=triangle_offsets(vk, t, base)))
    return tuple(out)


def triangle_offsets(v: np.ndarray, t: np.ndarray, base: float) -> np.ndarray:
    """Self-intersection offset per triangle: scene-scaled ``base`` plus float32 rounding of its
    largest |coordinate| (looked up per hit, so no per-hit reduction)."""
    if len(t) == 0:
        return np.zeros(0, np.float32)
    # the largest |coordinate| per vertex, then per triangle (the same maxima, no (T, 3, 3) gather),
    # column by column: a reduction over a short last axis is several times slower
    a = np.abs(v)
    per_vertex = np.maximum(np.maximum(a[:, 0], a[:, 1]), a[:, 2])
    del a
    m = per_vertex[t[:, 0]]
    np.maximum(m, per_vertex[t[:, 1]], out=m)
    np.maximum(m, per_vertex[t[:, 2]], out=m)
    return (base + 4e-7 * m).astype(np.float32)


def _equal(a, b) -> bool:
    """Deep equality of scene data: arrays by value, dataclasses field by field."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.shape(a) == np.shape(b) and np.array_equal(a, b)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):  # Scene.textures
        return len(a) == len(b) and all(_equal(x, y) for x, y in zip(a, b))
    if is_dataclass(a) and type(a) is type(b):
        return all(_equal(getattr(a, f.name), getattr(b, f.name)) for f in fields(a))
    return a == b


def _same_geometry(a: Scene, b: Scene) -> bool:
    return _equal(a.vertices, b.vertices) and _equal(a.triangles, b.triangles)


def _same_shading(a: Scene, b: Scene) -> bool:
    """The shading normals (part of the geometry the light pass bends light with)."""
    return _equal(np.asarray(a.corner_normals), np.asarray(b.corner_normals))


def _same_for_light_pass(a: Scene, b: Scene) -> bool:
    """Everything but the camera (the world is a light of the light pass: its colour, map and
    rotation count)."""
    return all(_equal(getattr(a, f.name), getattr(b, f.name)) for f in fields(a) if f.name != "camera")


def _same_world(a: Scene, b: Scene) -> bool:
    return all(_equal(getattr(a, k), getattr(b, k)) for k in ("world_color", "world_image", "world_rotation"))


def world_environment(scene: Scene, reuse: PreparedScene | None = None) -> EnvironmentMap | None:
    """The scene's world map as an EnvironmentMap of radiance world_color x image (None: a
    uniform world, or a black one); an earlier preparation's map when the world is unchanged."""
    if reuse is not None and _same_world(reuse.scene, scene):
        return reuse.environment
    color = np.asarray(scene.world_color, np.float32)
    if scene.world_image.size == 0 or not np.any(color > 0):
        return None
    return EnvironmentMap(scene.world_image * color[None, None, :], scene.world_rotation)


def _light_pass_settings(s: RenderSettings) -> dict:
    return {f.name: getattr(s, f.name) for f in fields(s) if f.name not in EYE_ONLY_SETTINGS}


def prepare(scene: Scene, settings: RenderSettings | None = None, conv: SpectralConverter | None = None,
            reuse: PreparedScene | None = None, should_cancel=None, deadline: float | None = None) -> PreparedScene:
    """Validate ``scene`` and ``settings`` (SceneError with a readable message) and prepare them.

    ``conv``: a SpectralConverter for the same grid to reuse.
    ``reuse``: an earlier preparation (the rendered viewport's, before an edit): whatever depends
    only on unchanged inputs is taken from it (the acceleration structure and triangle frames
    when the geometry is the same, the spectra when the grid is), and when nothing the light pass
    reads has changed the result keeps its ``key``, so the earlier light-pass result stays valid.
    ``should_cancel()``: polled every cancel.POLL_S while preparing; raises cancel.RenderCancelled.
    ``deadline``: a time.perf_counter() time (the render's time limit): checked between the stages
    after validation (so bad input is still named) and while the ray caster builds; raises
    cancel.OutOfTime once passed.
    """
    armed = threading.Event()  # set at the first check after validation: the deadline applies from there
    return run_cancellable(lambda stopped: _prepare(scene, settings, conv, reuse, _with_deadline(stopped, deadline, armed)),
                           should_cancel, deadline, armed)


def _with_deadline(stopped, deadline: float | None, armed: threading.Event):
    """``stopped`` that also raises OutOfTime once ``deadline`` has passed, and sets ``armed``
    when first called (after validation: from then on the calling thread enforces the deadline
    too, within cancel.POLL_S, while a long stage such as the ray caster's build runs)."""
    if deadline is None:
        return stopped

    def check_both() -> bool:
        armed.set()
        if stopped():
            return True
        if time.perf_counter() > deadline:
            raise OutOfTime()
        return False
    return check_both


def _film_warnings(m) -> list[str]:
    """A thin film the transport leaves out (docs/physics.md section 2.8): under a grating layer
    or an opal's Bragg lattice, whose own Fresnel terms stay the plain ones."""
    from ..spectral.thin_film import THIN_FILM_CUTOFF_NM

    film = np.asarray(m.thin_film_thickness, np.float64) > THIN_FILM_CUTOFF_NM
    return [f"material '{m.name[i]}': its thin film is not rendered under its grating layer (plain Fresnel there)"
            for i in np.flatnonzero(film & (np.asarray(m.grating) != 0))]


def _prepare(scene, settings, conv, reuse, stopped) -> PreparedScene:
    t0 = time.perf_counter()
    settings = settings or RenderSettings()
    settings.validate()
    checked = validate(scene)
    scene, warnings = checked.scene, checked.warnings
    warnings.extend(_film_warnings(scene.materials))
    cross, cross_norm = checked.triangle_cross, checked.triangle_cross_norm  # validation's products
    del checked  # cross and cross_norm are freed below, once the normals are made
    if settings.light_paths is None:  # automatic: sized to the image (settings.auto_light_paths)
        cam = scene.camera
        settings = replace(settings, light_paths=auto_light_paths(cam.width, cam.height, settings.samples) if cam is not None
                           else AUTO_LIGHT_PATHS_RANGE[1])
    check(stopped)
    grid = settings.grid()
    if conv is None and reuse is not None:
        conv = reuse.conv
    conv = conv if conv is not None and conv.grid == grid else SpectralConverter(grid)
    threads = int(settings.threads) or default_threads()
    v = np.asarray(scene.vertices, np.float32)
    t = np.asarray(scene.triangles, np.int32)
    tri_material = np.asarray(scene.tri_material, np.int32)
    materials = prepare_materials(scene.materials, conv)
    lights = prepare_lights(scene.lights, conv)
    gratings = prepare_gratings(scene.materials)
    textures = prepare_textures(scene, conv)
    same_geometry = (reuse is not None and reuse.settings.backend == settings.backend
                     and _same_geometry(reuse.scene, scene))
    if same_geometry:
        cross = None
        accel, nrm64, tri_normal = reuse.accel, None, reuse.tri_normal
        tri_offset, base, extent = reuse.tri_offset, reuse.offset_base, reuse.extent
    else:
        if cross is None or len(cross) != len(t):
            nrm64 = triangle_normals(v, t)
        else:  # validation's products divided in place by their norms (it took them for the areas)
            nrm64 = normals_from_cross(cross, cross_norm, in_place=True)
        cross = cross_norm = None
        tri_normal = nrm64.astype(np.float32)
        extent = scene_extent(v)
        base = OFFSET_RELATIVE * extent
        tri_offset = triangle_offsets(v, t, base)
        check(stopped)
        backend = settings.backend
        if extent < EMBREE_MIN_EXTENT and backend in ("auto", "embree") and len(t):
            # measured: Embree misses or double-counts hits in scenes of ~1e-12 m (its own
            # epsilons are absolute); the NumPy BVH is scale-free
            warnings.append(f"the scene is {extent:.1e} m across, too small for Embree: ray casting with the NumPy BVH")
            backend = "numpy"
        # the passes parallelise over tiles and light-pass lanes with the whole budget, so the
        # caster itself runs on one thread (no pools nested inside pools)
        accel = build_accelerator(v, t, backend, threads=1, stopped=stopped)
        check(stopped)
    if gratings.any:  # only a scene with gratings pays for their frames
        nrm64 = triangle_normals(v, t) if nrm64 is None else nrm64
        grating_tri = gratings.enabled[tri_material]
        # the frames of grating triangles only (only grating hits read them; other rows zero)
        tri_grating_tangent = triangle_tangents(nrm64, scene.tri_tangent, rows=grating_tri)
        corner_grating_tangent = smooth_corner_tangents(v, t, nrm64, tri_grating_tangent, tri_material, grating_tri)
    else:
        tri_grating_tangent = np.zeros((0, 3), np.float32)
        corner_grating_tangent = None
    if len(scene.corner_normals) == 0:
        corner_normals = smooth = None
    elif same_geometry and reuse.corner_normals is not None and _same_shading(reuse.scene, scene):
        corner_normals, smooth = reuse.corner_normals, reuse.smooth_triangles
    else:
        corner_normals = np.asarray(scene.corner_normals, np.float32)  # unit length (validated)
        smooth = smooth_triangles(corner_normals)
    mesh_lights = MeshLights.build(v, t, tri_material, materials.emission, luminance_weights=conv.cmf_weights[:, 1])
    environment = world_environment(scene, reuse)
    if environment is None:
        world_spectrum = conv.illuminant_from_rgb(np.asarray(scene.world_color, np.float64)).astype(np.float32)
    else:
        world_spectrum = conv.illuminant_from_rgb(environment.mean_rgb()).astype(np.float32)
    same_for_light = (same_geometry and _same_shading(reuse.scene, scene) and _same_for_light_pass(reuse.scene, scene)
                      and _light_pass_settings(reuse.settings) == _light_pass_settings(settings))
    microfacet = microfacet_materials(materials, textures)
    gratings = attach_layering(gratings, materials.kind, microfacet)  # docs/physics.md section 3.3
    if same_for_light:
        targets, key = reuse.light_targets, reuse.key
    else:
        targets = find_light_targets(v, t, tri_material, materials, gratings, lights, conv, settings.light_paths,
                                     mesh_lights=mesh_lights, world_spectrum=world_spectrum, microfacet=microfacet)
        key = next(_keys)
    check(stopped)
    prepared = PreparedScene(
        scene=scene,
        settings=settings,
        threads=threads,
        conv=conv,
        accel=accel,
        materials=materials,
        lights=lights,
        gratings=gratings,
        tri_normal=tri_normal,
        tri_offset=tri_offset,
        tri_material=tri_material,
        tri_grating_tangent=tri_grating_tangent,
        tri_period=np.asarray(scene.tri_period, np.float32).reshape(-1),
        world_spectrum=world_spectrum,
        environment=environment,
        textures=textures,
        corner_uvs=textures.corner_uvs,
        corner_tangents=textures.corner_tangents,
        extent=extent,
        offset_base=base,
        light_targets=targets,
        mesh_lights=mesh_lights,
        warnings=tuple(warnings),
        prepare_s=0.0,
        key=key,
        corner_normals=corner_normals,
        smooth_triangles=smooth,
        microfacet=microfacet,
        opal_domains=scene.volume_domains(),
        corner_grating_tangent=corner_grating_tangent,
        motion_bins=motion_bins(scene, t, base, "numpy" if extent < EMBREE_MIN_EXTENT else settings.backend, stopped),
    )
    frozen = {f.name: _read_only(getattr(prepared, f.name)) for f in fields(prepared)}
    frozen["prepare_s"] = time.perf_counter() - t0
    return PreparedScene(**frozen)
