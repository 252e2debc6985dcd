"""The render engine ``OPAL_DIFFRACTION``: F12, ``bpy.ops.render.render`` and ``blender -b -f``.

One render: export the evaluated depsgraph (polling Esc), hand the scene to the core's
``render`` with callbacks for progress, cancellation and partial results, and copy the film into
Blender's render result with ``foreach_set`` on float32 arrays (rows flipped: the core's row 0
is the top of the image, Blender's the bottom). Combined is in the blend file's linear working
space, so Blender's colour management (view transform, look, exposure) applies as for Cycles.
Direct, Indirect, Caustics and Diffraction are registered as passes for the compositor, with
Cycles' Denoising Albedo and Denoising Normal (same names, so a compositor Denoise node links to
them), Noisy Image when the render is denoised (``scene.opal.use_denoising``: Open Image Denoise
through pyoidn, core/render/denoise.py; without pyoidn a warning says so and the image stays noisy), and
Debug Sample Count (samples per pixel) with adaptive sampling.

Errors in the scene are reported once with ``report({'ERROR'}, message)`` (the status bar, the
Info editor, the operator's RuntimeError from a script) and shown in the render window's stats
line as "Error: message": the operator fails, no traceback, no image written. (``error_set`` is
not used: Blender would report its text a second time from ``bpy.ops.render.render``.) Every
warning, from the export, the settings and the core, is reported once (the Info editor lists
them all; the console too in background mode); the stats line counts them and shows the first.
A cancelled render (Esc, Ctrl-C) ends with status 'CANCELLED' and a stats line that starts with
"Cancelled".

With Persistent Data on (``scene.render.use_persistent_data``) Blender keeps the engine between
frames and calls ``update`` before each render: the engine notes the depsgraph's updates and
keeps, per view layer, the exported scene, the preparation and the light pass (persistent.py);
a frame whose only change is the camera exports the camera alone and renders the kept
preparation through it, keeping the light pass and splatting its kept camera-splat vertices
into the new view (core/render/frame.py ``light_reuse``, core/integrators/light/splat_vertices.py;
the light pass runs again only where none were kept, e.g. over their memory cap); other changes
re-export and prepare with the kept preparation as ``reuse``. The stats line ends with what was
reused.

The rendered viewport (``view_update`` / ``view_draw``) is viewport.ViewportSession: a
progressive preview in a background thread, drawn through the ``gpu`` module.
"""

from __future__ import annotations

import os
import re
import sys
import time
import traceback
from contextlib import nullcontext
from dataclasses import replace

import bpy
import numpy as np

from ..core.render import denoise as _denoise
from ..core.render.distributed import connect
from ..core.render.output import write_spectral_exr
from ..core.render.frame import light_reuse, render as core_render, render_prepared, reusable_light
from ..core.scene.checks import SceneError
from ..core.scene.npz import save_scene
from ..core.scene.validation import validate
from .export import (ExportCancelled, ExportResult, Warnings, export_camera, export_scene, rec709_to_working_space,
                     render_region)
from . import persistent as _persistent
from .persistent import Kept, PersistentData, settings_key
from .settings import render_settings
from . import viewport
from .viewport import ViewportSession

__all__ = ["OpalRenderEngine", "AOV_PASSES", "VECTOR_PASSES", "NOISY_PASS", "SAMPLE_COUNT_PASS", "DENOISER_MISSING",
           "render_settings", "output_path", "warning_summary", "last_render", "register", "unregister"]

ENGINE_ID = "OPAL_DIFFRACTION"
#: Passes besides Combined, in the order the core fills them.
AOV_PASSES = ("Direct", "Indirect", "Caustics", "Diffraction", "Denoising Albedo", "Denoising Normal")
#: Passes that hold vectors, not colours (no colour-space conversion; Blender's type VECTOR)
VECTOR_PASSES = ("Denoising Normal",)
NOISY_PASS = _denoise.NOISY_PASS  # Cycles' name of the image before denoising
SAMPLE_COUNT_PASS = "Debug Sample Count"  # Cycles' name: samples each pixel took
#: The fallback's warning when use_denoising is on and pyoidn cannot be imported in Blender's Python
DENOISER_MISSING = ("denoising needs Open Image Denoise's Python binding pyoidn in Blender's Python, which is not "
                    "installed: the image is not denoised. Install it into Blender's Python (pip install "
                    "pyoidn==2.5.1.0), or denoise in the compositor: a Denoise node with Image from Combined, "
                    "Normal from Denoising Normal and Albedo from Denoising Albedo")

#: What the last render did, for scripts and tests (Blender's Render Result image cannot be read
#: back in background mode): status 'FINISHED' | 'CANCELLED' | 'ERROR', message, warnings,
#: stats, and the pixels (rgb (H, W, 3) linear Rec.709, row 0 at the top; passes likewise).
last_render: dict = {}


def output_path(path: str, frame: int, ext: str = ".exr", what: str = "spectral EXR") -> str:
    """Absolute output path: '//' relative to the .blend, '#'s replaced by the frame number,
    ``ext`` added when the name has no extension; "" for an empty path.

    Raises SceneError when a '//' path cannot be resolved because the .blend was never saved.
    """
    if not path:
        return ""
    if path.startswith("//") and not bpy.data.filepath:
        raise SceneError(f"the {what} path '{path}' is relative to the .blend file, which has not been saved: "
                         "save the file or use an absolute path")
    out = bpy.path.abspath(path)
    out = re.sub(r"#+", lambda m: f"{frame:0{len(m.group(0))}d}", out)
    if not os.path.splitext(out)[1]:
        out += ext
    return os.path.normpath(out)


def warning_summary(warnings: list[str]) -> str:
    """The stats line's tail for a render's warnings: how many, and the first (every one of them
    is reported, so the Info editor lists them all)."""
    if not warnings:
        return ""
    if len(warnings) == 1:
        return f" | 1 warning: {warnings[0]}"
    return f" | {len(warnings)} warnings (all in the Info editor): {warnings[0]}"


class OpalRenderEngine(bpy.types.RenderEngine):
    """Spectral rendering of dispersion and diffraction."""

    bl_idname = ENGINE_ID
    bl_label = "Opal Diffraction"
    bl_use_preview = False
    bl_use_postprocess = True
    bl_use_eevee_viewport = True  # Material Preview shading uses EEVEE
    bl_use_shading_nodes_custom = False  # our materials are Blender's own shader nodes

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._viewport = None  # a ViewportSession once the engine draws a 3D view
        # what a final render keeps with Persistent Data on, per view layer (persistent.py)
        self._persistent: dict[str, PersistentData] = {}

    def __del__(self):
        # the engine is freed (Rendered mode left, or a render finished): stop the preview thread
        try:
            vp = getattr(self, "_viewport", None)
            if vp is not None:
                vp.free()
            parent = getattr(super(), "__del__", None)
            if parent is not None:
                parent()
        except ReferenceError:  # Blender already removed the engine's RNA struct: nothing to stop
            pass

    # ---------------------------------------------------------------- viewport
    def _viewport_session(self) -> ViewportSession:
        vp = getattr(self, "_viewport", None)
        if vp is None:
            vp = self._viewport = ViewportSession()
        return vp

    def view_update(self, context, depsgraph):
        """The scene changed (or Rendered mode started): export it and restart the preview."""
        try:
            self._viewport_session().update(self, context, depsgraph)
        except Exception as e:  # never take the UI down
            traceback.print_exc(file=sys.stderr)
            self.update_stats("", f"Error: internal error ({type(e).__name__}: {e})")

    def view_draw(self, context, depsgraph):
        """Draw the newest preview image; restart the preview when the view moved."""
        try:
            self._viewport_session().draw(self, context, depsgraph)
        except Exception as e:
            traceback.print_exc(file=sys.stderr)
            self.update_stats("", f"Error: internal error ({type(e).__name__}: {e})")

    # ---------------------------------------------------------------- final render
    def update(self, data, depsgraph):
        """Before each final render of a view layer: note the depsgraph's updates (what changed
        since the frame before, with Persistent Data on: the engine instance is kept between
        frames, and each view layer's depsgraph too)."""
        try:
            if depsgraph.scene.render.use_persistent_data:
                self._persistent_data(depsgraph.view_layer.name).note_updates(depsgraph.updates)
        except Exception:  # never fail here: the render then exports everything
            traceback.print_exc(file=sys.stderr)
            for pd in self._persistent_layers().values():
                pd.updates = None

    def _persistent_layers(self) -> dict:
        layers = getattr(self, "_persistent", None)
        if layers is None:
            layers = self._persistent = {}
        return layers

    def _persistent_data(self, layer: str) -> PersistentData:
        """The kept state of one view layer (each has its own depsgraph, export and light pass)."""
        layers = self._persistent_layers()
        pd = layers.get(layer)
        if pd is None:
            pd = layers[layer] = PersistentData()
        return pd

    # ---------------------------------------------------------------- passes
    def update_render_passes(self, scene=None, renderlayer=None):
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        for name in AOV_PASSES:
            if name in VECTOR_PASSES:
                self.register_pass(scene, renderlayer, name, 3, "XYZ", "VECTOR")
            else:
                self.register_pass(scene, renderlayer, name, 3, "RGB", "COLOR")
        opal = getattr(scene, "opal", None)
        if opal is not None and opal.use_denoising:
            self.register_pass(scene, renderlayer, NOISY_PASS, 4, "RGBA", "COLOR")
        if opal is not None and opal.use_adaptive_sampling:
            self.register_pass(scene, renderlayer, SAMPLE_COUNT_PASS, 1, "X", "VALUE")

    # ---------------------------------------------------------------- render
    def render(self, depsgraph):
        last_render.clear()
        last_render.update(status="RUNNING", message="", warnings=[], stats={}, progress=[], stats_log=[])
        try:
            self._render(depsgraph)
        except ExportCancelled:
            self._cancelled("cancelled while exporting the scene")
        except KeyboardInterrupt:  # Ctrl-C in a terminal (the bpy module, blender -b): stop cleanly
            self._cancelled("interrupted")
        except SceneError as e:
            self._fail(str(e))
        except MemoryError:
            self._fail("out of memory: lower the resolution, the samples or the wavelength count")
        except Exception as e:  # a bug: tell the user plainly, keep the details for the console
            traceback.print_exc(file=sys.stderr)
            self._fail(f"internal error ({type(e).__name__}: {e}); details are in the system console")

    # The seams below are plain Python methods so scripts and tests can observe or drive them
    # (RNA functions such as test_break cannot be overridden from Python).
    def _should_stop(self) -> bool:
        """Esc pressed (Blender's test_break): polled between export batches and render tiles."""
        return bool(self.test_break())

    def _status(self, message: str) -> None:
        log = last_render.setdefault("stats_log", [])
        if len(log) < 10000:
            log.append(message)
        self.update_stats("", message)

    def _progress(self, fraction: float) -> None:
        log = last_render.setdefault("progress", [])
        if len(log) < 10000:
            log.append(float(fraction))
        self.update_progress(float(fraction))

    def _fail(self, message: str) -> None:
        last_render.update(status="ERROR", message=message)
        self._status(f"Error: {message}")
        self.report({"ERROR"}, f"Opal Diffraction: {message}")

    def _cancelled(self, message: str) -> None:
        last_render.update(status="CANCELLED", message=message)
        self._status("Cancelled")

    def _render(self, depsgraph):
        t0 = time.perf_counter()
        scene = depsgraph.scene
        opal = scene.opal
        width, height = int(self.resolution_x), int(self.resolution_y)
        spectral_path = output_path(opal.spectral_exr, scene.frame_current)
        npz_path = output_path(opal.scene_npz, scene.frame_current, ".npz", "scene file")
        settings = render_settings(opal, scene, spectral_path)
        settings.validate()  # bad settings fail before the export, with a clear message

        # Persistent Data (persistent.py): keep the export, the preparation and the light pass
        # between frames; off, or rendering on a cluster, keeps nothing
        pd = self._persistent_data(depsgraph.view_layer.name)
        persistent = bool(scene.render.use_persistent_data) and not opal.scheduler.strip()
        if not persistent:  # every view layer's kept state is freed
            for other in self._persistent_layers().values():
                other.free()
        updates = pd.take_updates()
        cam_ob = self.camera_override if self.camera_override is not None else scene.camera
        cam_name = cam_ob.name_full if cam_ob is not None else ""
        cam_data = cam_ob.data.name_full if cam_ob is not None and cam_ob.data is not None else ""
        frame_setup = (width, height, render_region(scene, width, height), cam_name)
        kept = pd.camera_only(updates, settings, frame_setup, cam_name, cam_data) if persistent else None
        reused = []  # what this frame took from the one before, for the stats line
        if kept is not None:  # only the camera changed: export it alone
            self._status("Exporting camera (persistent data)")
            t_cam = time.perf_counter()
            cam_warn = Warnings()
            camera = export_camera(depsgraph, width=width, height=height, camera=self.camera_override, warn=cam_warn,
                                   frame_set=self.frame_set, objects_checked=True)
            old = kept.exported
            exported = ExportResult(
                replace(old.scene, camera=camera),
                [w for w in old.warnings if w not in kept.camera_warnings] + cam_warn.items,
                dict(old.stats, export_s=time.perf_counter() - t_cam))
            camera_warnings = tuple(cam_warn.items)
            reused.append("export")
        else:
            self._status("Exporting scene")
            if persistent:
                pd.invalidate_meshes(updates)
            exported = export_scene(
                depsgraph, width=width, height=height, camera=self.camera_override,
                test_break=self._should_stop, progress=lambda msg: self._status(msg.capitalize()),
                mesh_cache=pd.mesh_cache if persistent else None,
                frame_set=self.frame_set,  # motion blur: the camera and objects at sub-frames (export/)
            )
            cam_warn = Warnings()
            if persistent:  # which of its warnings the camera made (a camera-only frame replaces them)
                export_camera(depsgraph, width=width, height=height, camera=self.camera_override, warn=cam_warn,
                              frame_set=self.frame_set, objects_checked=True)
            camera_warnings = tuple(cam_warn.items)
        warnings = [w for w in (opal.wavelength_warning(),) if w] + list(exported.warnings)
        last_render["export"] = dict(exported.stats)
        if npz_path:
            validate(exported.scene)  # do not write a file the command line cannot render
            try:
                os.makedirs(os.path.dirname(npz_path), exist_ok=True)
                save_scene(exported.scene, npz_path)
            except OSError as e:
                warnings.append(f"could not write the scene file '{npz_path}': {e}")

        # border render: Blender counts rows from the bottom, the core from the top
        region_b = render_region(scene, width, height)
        if region_b is not None:
            x0, y0, x1, y1 = region_b
            region = (x0, height - y1, x1, height - y0)
        else:
            x0, y0, x1, y1 = 0, 0, width, height
            region = None
        rw, rh = x1 - x0, y1 - y0

        to_working = rec709_to_working_space()
        result = self.begin_result(0, 0, rw, rh, layer=depsgraph.view_layer.name)
        if result is None:
            raise SceneError(f"Blender refused a {rw}x{rh} render result")
        state = {"round": 0}

        def progress(fraction, message):
            self._progress(fraction)
            self._status(f"{message} | {time.perf_counter() - t0:.1f} s")

        def on_round(partial):
            state["round"] += 1
            self._fill(result, partial, to_working, settings.film_transparent)
            self.update_result(result)

        previous = pd.kept
        keep = {"prepared": None, "light": None, "ran": False, "resplat": None}
        # the camera splat's light-path vertices kept with the light pass, for the next frame's camera
        cap = int(_persistent.SPLAT_VERTEX_CAP) if persistent else 0

        def on_light(lp):  # the light pass this frame ran, or the kept one splatted into this view
            if lp.resplatted:
                keep.update(light=lp, resplat=dict(lp.resplat))
            else:
                keep.update(light=lp, ran=True)

        try:
            if kept is not None:  # the kept preparation through the new camera: nothing rebuilt
                prepared = kept.prepared.with_view(camera, spectral_exr=settings.spectral_exr)
                light = reusable_light(prepared, kept.light)
                keep.update(prepared=prepared, light=light)
                reused.append("preparation")
                rr = render_prepared(prepared, light, progress=progress, should_cancel=self._should_stop,
                                     on_round=on_round, region=region, on_light=on_light, keep_splat=cap)
            else:
                with connect(opal.scheduler) if opal.scheduler.strip() else nullcontext() as client:
                    rr = core_render(exported.scene, settings, progress=progress, should_cancel=self._should_stop,
                                     on_round=on_round, region=region, client=client,
                                     reuse=previous.prepared if persistent and previous is not None else None,
                                     light=previous.light if persistent and previous is not None else None,
                                     on_prepared=(lambda p: keep.update(prepared=p)) if persistent else None,
                                     on_light=on_light if persistent else None, keep_splat=cap)
                prepared = keep["prepared"]
                if persistent and previous is not None and prepared is not None:
                    if prepared.accel is previous.prepared.accel:
                        reused.append("ray caster")
                    if not keep["ran"] and keep["resplat"] is None:  # the core reused the kept light pass, or the plan has none
                        keep["light"] = reusable_light(prepared, previous.light)
        except BaseException:
            pd.kept = None  # a failed or interrupted frame keeps nothing
            self.end_result(result, cancel=True)
            raise
        denoise_warning = ""
        if opal.use_denoising and rr.samples > 0:
            if _denoise.available():
                self._status("Denoising")
                try:
                    rr = _denoise.denoise_result(rr)
                except SceneError:
                    self.end_result(result, cancel=True)
                    raise
            else:  # the image stays noisy; the Noisy Image pass holds it all the same
                denoise_warning = DENOISER_MISSING
                rr = replace(rr, passes={**rr.passes, NOISY_PASS: rr.rgb})
        self._fill(result, rr, to_working, settings.film_transparent)
        self.end_result(result)

        light_ran = bool(keep["ran"]) if persistent else "light_pass_s" in rr.stats
        if persistent and not light_ran and keep["light"] is not None and previous is not None \
                and (keep["light"] is previous.light or keep["resplat"] is not None) and "light_pass_s" in rr.stats:
            reused.append("light pass")
        # why the kept light pass could not serve this frame (its scene unchanged), for the stats line
        rerun_note = ""
        if persistent and light_ran and previous is not None and keep["prepared"] is not None:
            rerun_note = light_reuse(keep["prepared"], previous.light)[1]
        kept_vertices = getattr(keep["light"], "vertices", None) if persistent else None
        if persistent and keep["prepared"] is not None and not rr.cancelled:
            pd.kept = Kept(settings_key(settings), frame_setup, exported, camera_warnings, keep["prepared"],
                           keep["light"])
        else:
            pd.kept = None
        pd.renders += 1

        core_warnings = list(rr.warnings) + ([denoise_warning] if denoise_warning else [])
        message = ""
        if rr.cancelled:  # the core says where it stopped: the render's message, not a warning
            notes = [w for w in core_warnings if w.startswith("cancelled")]
            core_warnings = [w for w in core_warnings if w not in notes]
            message = notes[0] if notes else "cancelled"
        warnings += core_warnings
        stats = dict(rr.stats, **{"export_" + k: v for k, v in exported.stats.items()})
        stats["total_s"] = time.perf_counter() - t0
        if "preparation" in reused:  # the kept preparation was seen through the new camera: none this frame
            stats["prepare_s"] = 0.0
        if spectral_path and rr.samples > 0:
            try:
                write_spectral_exr(spectral_path, rr.spectral, rr.wavelengths, rr.rgb)
                stats["spectral_exr"] = spectral_path
            except Exception as e:  # the image itself is fine: keep it, say what failed
                warnings.append(f"could not write the spectral EXR '{spectral_path}': {e}")
        warnings = list(dict.fromkeys(warnings))  # once each, in first-seen order
        for w in warnings:
            self.report({"WARNING"}, f"Opal Diffraction: {w}")
        summary = (f"{rr.samples} samples | {stats.get('rays', 0) / 1e6:.1f} M rays | "
                   f"{exported.stats['triangles']} triangles | {stats['total_s']:.1f} s | "
                   f"{stats.get('kernels', 'numpy')} kernels")
        if persistent:  # Persistent Data: what this frame took from the one before
            summary += " | persistent data: " + ("reused " + ", ".join(reused) if reused else "nothing reused")
            rs = keep["resplat"]
            if rs is not None:
                summary += (f"; camera splat re-splatted from {rs['resplat_vertices'] / 1e6:.2f} M light-path vertices "
                            f"({rs['resplat_bytes'] / 2**20:.0f} MB, {rs['resplat_s']:.2f} s), no light paths traced")
            if rerun_note:
                summary += f"; light pass ran again: {rerun_note}"
            if keep["ran"] and kept_vertices is not None and kept_vertices.over_cap:
                summary += (f"; camera-splat vertices not kept ({kept_vertices.nbytes / 2**20:.0f} MB over the "
                            f"{kept_vertices.cap / 2**20:.0f} MB cap): a camera move runs the light pass again")
        if rr.cancelled:
            summary = "Cancelled | " + summary
        summary += warning_summary(warnings)
        self._status(summary)
        last_render.update(
            status="CANCELLED" if rr.cancelled else "FINISHED", message=message, warnings=warnings, stats=stats,
            samples=rr.samples, rgb=rr.rgb, passes=rr.passes, plan=rr.plan.summary(), region=region,
            sample_counts=rr.sample_counts,
            spectral_exr=stats.get("spectral_exr", ""), partial_updates=state["round"],
            plan_gratings=bool(getattr(rr.plan, "gratings", False)),
            persistent={"on": persistent, "reused": tuple(reused), "exported_geometry": "export" not in reused,
                        "light_pass_ran": light_ran, "renders": pd.renders, "kept": pd.kept is not None,
                        "resplat": keep["resplat"], "light_pass_note": rerun_note,
                        "splat_vertices": None if kept_vertices is None else {
                            "vertices": kept_vertices.vertices, "bytes": kept_vertices.nbytes,
                            "over_cap": kept_vertices.over_cap, "cap": kept_vertices.cap}},
        )

    @staticmethod
    def _fill(result, rr, to_working, transparent: bool = False) -> None:
        """Copy a core RenderResult into Blender's result passes (bottom row first, float32);
        ``transparent``: Film > Transparent, Combined's alpha is the result's coverage."""
        layer = result.layers[0]
        last_render["result_passes"] = [p.name for p in layer.passes]
        h, w = rr.rgb.shape[:2]
        rgb = rr.rgb if to_working is None else rr.rgb @ to_working.T.astype(np.float32)
        combined = np.empty((h, w, 4), np.float32)
        combined[..., :3] = rgb[::-1]
        # Film > Transparent: alpha = coverage (the core left the world seen directly black, as Cycles)
        combined[..., 3] = rr.alpha[::-1] if transparent and rr.alpha is not None else 1.0
        layer.passes["Combined"].rect.foreach_set(combined.ravel())
        for name in AOV_PASSES + (NOISY_PASS, SAMPLE_COUNT_PASS):
            try:
                rp = layer.passes[name]
            except KeyError:
                continue
            img = rr.sample_counts[..., None] if name == SAMPLE_COUNT_PASS else rr.passes.get(name)
            if img is None:
                continue
            if to_working is not None and name not in VECTOR_PASSES and name != SAMPLE_COUNT_PASS:
                img = img @ to_working.T.astype(np.float32)
            if name == NOISY_PASS:  # RGBA, as Combined
                img = np.concatenate([img, np.ones((h, w, 1), np.float32)], axis=-1)
            rp.rect.foreach_set(np.ascontiguousarray(img[::-1], np.float32).ravel())


def register():
    bpy.utils.register_class(OpalRenderEngine)
    viewport.register()


def unregister():
    viewport.unregister()
    bpy.utils.unregister_class(OpalRenderEngine)
