"""The engine's rendered viewport: progressive previews drawn through the ``gpu`` module.

``view_update`` (Blender calls it when the scene changes: an edit, a new frame, a material)
exports the evaluated depsgraph and prepares it again, reusing what did not change
(``core.prepare(..., reuse=...)``: the acceleration structure when the geometry is the same, the
light pass's result when nothing it reads changed), and restarts the preview only when the
scene really changed; ``view_draw`` (every redraw) builds the core camera from the 3D view's
matrices, restarts the preview when the view moved or the region was resized, and draws the
newest image as a float texture through the scene's display transform
(``bind_display_space_shader``), as Cycles does. Never ``bgl``.

The session keeps its PreparedScene and LightPassResult between redraws, so a camera move
re-renders only the eye pass. The preview renders in a background thread with the core's
``render_levels`` (core/render/progressive.py, through the core's scheduler): first at 1/8 of
the region's resolution with one sample (the first image comes quickly), then 1/4, 1/2, and the
full resolution refined round after round up to the scene's preview samples. Every restart bumps
a generation number; the old render stops at its next tile (the scheduler polls
``should_cancel`` between tiles) and its images are dropped. Leaving
Rendered mode frees the engine, which cancels the thread. A main-thread timer tags the 3D views
for redraw while new images arrive (the thread never touches bpy).

This module never imports the engine: the engine passes itself to ``update`` and ``draw``.

The logic is plain Python for tests without a display: :func:`viewport_camera` (view and window matrices to a core Camera), :func:`prepare_pixels`
(the texture buffer) and :class:`ProgressiveRenderer` (the thread).
"""

from __future__ import annotations

import threading
import time
import weakref
from dataclasses import dataclass, replace

import numpy as np

from ..core.render.frame import LightPassResult
from ..core.render.prepare import PreparedScene, prepare
from ..core.render.progressive import preview_levels, render_levels
from ..core.scene.checks import SceneError
from ..core.scene.model import Camera
from .settings import render_settings

__all__ = ["viewport_camera", "prepare_pixels", "Frame", "ProgressiveRenderer", "ViewportSession",
           "REDRAW_INTERVAL"]

#: Seconds between redraw checks while a preview is rendering.
REDRAW_INTERVAL = 0.1


def viewport_camera(view_matrix, window_matrix, is_perspective: bool, width: int, height: int,
                    ortho_back: float = 1000.0) -> Camera:
    """A core Camera that sees what the 3D view shows.

    ``view_matrix``: world to view (4x4, the view looks down -Z, +Y up); ``window_matrix``: the
    view's projection (OpenGL convention). Perspective: the horizontal field of view and the
    off-centre shift come from P[0][0], P[0][2], P[1][1], P[1][2] (sensor fit HORIZONTAL, 36 mm
    sensor); orthographic: the scale and shift from P[0][0], P[0][3], P[1][1], P[1][3]. An
    orthographic eye is moved ``ortho_back`` metres back so nothing in front of the view's clip
    range is cut off.
    """
    v = np.asarray(view_matrix, np.float64).reshape(4, 4)
    p = np.asarray(window_matrix, np.float64).reshape(4, 4)
    m = np.linalg.inv(v)
    # drop any scale so the frame is orthonormal
    m[:3, :3] /= np.linalg.norm(m[:3, :3], axis=0, keepdims=True)
    w, h = max(int(width), 1), max(int(height), 1)
    if is_perspective:
        lens = 18.0 * p[0, 0]  # tan(half fov x) = 1 / P00 = (36 / 2) / lens
        shift_x = p[0, 2] / 2.0
        shift_y = p[1, 2] * p[0, 0] / (2.0 * p[1, 1])
        return Camera(matrix=m, kind="PERSP", lens=float(lens), sensor_width=36.0, sensor_height=36.0 * h / w,
                      sensor_fit="HORIZONTAL", shift_x=float(shift_x), shift_y=float(shift_y), width=w, height=h)
    scale = 2.0 / p[0, 0]
    m[:3, 3] += m[:3, 2] * ortho_back  # back along the view's +Z
    return Camera(matrix=m, kind="ORTHO", ortho_scale=float(scale), sensor_fit="HORIZONTAL",
                  shift_x=float(-p[0, 3] / 2.0), shift_y=float(-p[1, 3] * p[0, 0] / (2.0 * p[1, 1])), width=w, height=h)


def prepare_pixels(rgb: np.ndarray, to_working: np.ndarray | None = None, alpha: np.ndarray | None = None) -> np.ndarray:
    """A float32 RGBA buffer (H * W * 4) for a texture: rows bottom first (OpenGL's origin),
    colours in the blend file's working space, alpha 1 (or ``alpha`` (H, W): Film > Transparent's
    coverage, drawn premultiplied over the viewport's background as Cycles' preview), NaN and
    negative values cleared."""
    img = np.asarray(rgb, np.float32)
    h, w = img.shape[:2]
    if to_working is not None:
        img = img @ np.asarray(to_working, np.float32).T
    out = np.empty((h, w, 4), np.float32)
    out[..., :3] = np.nan_to_num(img[::-1], nan=0.0, posinf=0.0, neginf=0.0)
    np.maximum(out[..., :3], 0.0, out=out[..., :3])
    out[..., 3] = 1.0 if alpha is None else np.clip(np.nan_to_num(np.asarray(alpha, np.float32)[::-1]), 0.0, 1.0)
    return out.ravel()


@dataclass
class Frame:
    """One preview image: its generation, level, size, samples and the texture buffer."""

    generation: int
    level: int
    width: int
    height: int
    samples: int
    pixels: np.ndarray
    serial: int = 0


class ProgressiveRenderer:
    """Renders a prepared scene progressively in a background thread.

    ``start(prepared, levels, light)`` cancels any render under way and starts a new
    generation; ``frame()`` returns the newest image (or None); ``cancel()`` stops the thread.
    ``on_image()`` (optional) is called from the thread after every new image; ``on_light(result)``
    (optional) receives the light pass's result when the thread had to run it, for reuse.
    """

    def __init__(self, on_image=None, to_working: np.ndarray | None = None, on_light=None):
        self.on_image = on_image
        self.on_light = on_light
        self.to_working = to_working
        self._lock = threading.Lock()
        self._generation = 0
        self._frame: Frame | None = None
        self._thread: threading.Thread | None = None
        self._serial = 0
        self.error = ""
        self.warnings: list[str] = []
        self.started_at = 0.0
        self.first_image_s: float | None = None
        self.done = False

    @property
    def generation(self) -> int:
        return self._generation

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def frame(self) -> Frame | None:
        with self._lock:
            return self._frame

    def start(self, prepared: PreparedScene, levels: list[tuple[int, int]],
              light: LightPassResult | None = None) -> int:
        """Render ``prepared`` (its camera sets the full size) level by level; ``light``: its
        finished light pass, if one is at hand (else the thread runs it when the plan asks)."""
        with self._lock:
            self._generation += 1
            gen = self._generation
            self.error, self.warnings, self.done = "", [], False
            self.started_at = time.perf_counter()
            self.first_image_s = None
            self._transparent = bool(getattr(prepared.settings, "film_transparent", False))
        thread = threading.Thread(target=self._run, args=(gen, prepared, light, list(levels)),
                                  name=f"opal-viewport-{gen}", daemon=True)
        self._thread = thread
        thread.start()
        return gen

    def cancel(self, wait: float = 0.0) -> None:
        """Stop the render under way (it stops at its next tile); wait up to ``wait`` seconds."""
        with self._lock:
            self._generation += 1
        t = self._thread
        if wait > 0 and t is not None and t is not threading.current_thread():
            t.join(wait)

    def wait(self, timeout: float = 10.0) -> bool:
        """Wait for the thread to finish (tests, scripts); True when it did."""
        t = self._thread
        if t is not None:
            t.join(timeout)
        return not self.running

    def _stale(self, gen: int) -> bool:
        return gen != self._generation

    def _publish(self, gen: int, level: int, rr) -> None:
        if self._stale(gen) or rr.samples <= 0:
            return
        pixels = prepare_pixels(rr.rgb, self.to_working, rr.alpha if getattr(self, "_transparent", False) else None)
        h, w = rr.rgb.shape[:2]
        with self._lock:
            if gen != self._generation:
                return
            self._serial += 1
            self._frame = Frame(gen, level, w, h, int(rr.samples), pixels, self._serial)
            if self.first_image_s is None:
                self.first_image_s = time.perf_counter() - self.started_at
        if self.on_image is not None:
            try:
                self.on_image()
            except Exception:  # a redraw request must never kill the render
                pass

    def _run(self, gen: int, prepared: PreparedScene, light: LightPassResult | None, levels) -> None:
        try:
            last = render_levels(prepared, levels, light, should_cancel=lambda: self._stale(gen),
                                 on_round=lambda li, r: self._publish(gen, li, r), on_light=self.on_light)
            if last is not None and not self._stale(gen):
                self.warnings = list(last.warnings)
                self.done = True
        except SceneError as e:
            if not self._stale(gen):
                self.error = str(e)
        except Exception as e:  # keep the UI alive; say what happened
            if not self._stale(gen):
                self.error = f"internal error ({type(e).__name__}: {e})"
        finally:
            if not self._stale(gen) and self.on_image is not None:
                try:
                    self.on_image()
                except Exception:
                    pass


# ============================================================================ the Blender side
def _region_matrices(context):
    rv3d = context.region_data
    region = context.region
    return (np.array(rv3d.view_matrix, np.float64), np.array(rv3d.window_matrix, np.float64),
            bool(rv3d.is_perspective), int(region.width), int(region.height))


class ViewportSession:
    """The viewport state of one engine instance: the exported scene, the view, the renderer."""

    def __init__(self):
        self.prepared: PreparedScene | None = None
        self.light: LightPassResult | None = None  # the light pass of ``prepared`` once it ran
        self.levels: list[tuple[int, int]] = []
        self.view_key = None
        self.renderer = ProgressiveRenderer(on_image=self._on_image, on_light=self._on_light)
        from .export import MeshCache  # noqa: PLC0415 - export needs bpy; this module's logic does not

        self.mesh_cache = MeshCache()  # meshes read from Blender, kept until their geometry changes
        _SESSIONS.add(self)
        self.texture = None
        self._texture_key = None
        self.export_warnings: list[str] = []
        self.error = ""
        self.restarts = 0

    # ---------------------------------------------------------------- update (scene changed)
    @property
    def scene(self):
        """The exported core Scene the preview renders (None before the first export)."""
        return None if self.prepared is None else self.prepared.scene

    def update(self, engine, context, depsgraph) -> None:
        """Export the scene, prepare what changed, and restart the preview if anything did
        (``view_update``)."""
        from .export import ExportCancelled, export_scene, rec709_to_working_space

        view, window, persp, w, h = _region_matrices(context)
        scene = depsgraph.scene
        opal = scene.opal
        old = self.prepared
        try:
            self.mesh_cache.invalidate(depsgraph.updates)
            exported = export_scene(depsgraph, width=w, height=h, mesh_cache=self.mesh_cache)
            settings = replace(render_settings(opal, scene), spectral_exr="", time_limit=0.0)
            prepared = prepare(exported.scene, settings, reuse=old)
        except (SceneError, ExportCancelled) as e:
            self.error = str(e) or "cancelled"
            self.prepared = self.light = None
            self.renderer.cancel()
            _status(engine, f"Error: {self.error}")
            return
        self.error = ""
        self.export_warnings = list(exported.warnings)
        self.renderer.to_working = rec709_to_working_space()
        levels = preview_levels(getattr(opal, "preview_samples", 16), getattr(opal, "preview_start_scale", 8))
        if old is not None and self.light is not None and self.light.key != prepared.key:
            self.light = None  # something the light pass reads changed
        unchanged = (old is not None and prepared.key == old.key and levels == self.levels
                     and prepared.settings == old.settings
                     and np.array_equal(prepared.world_spectrum, old.world_spectrum))
        self.prepared, self.levels = prepared, levels
        if unchanged and not self.renderer.error:
            return  # nothing the preview shows changed (a selection, a redo of the same values)
        self.view_key = None  # force a restart with the current view
        if self.sync_view(view, window, persp, w, h):
            _status(engine, "Rendering preview")

    def _on_light(self, light: LightPassResult) -> None:  # from the render thread
        if self.prepared is not None and light.key == self.prepared.key:
            self.light = light

    # ---------------------------------------------------------------- the view
    def sync_view(self, view, window, persp, width, height) -> bool:
        """Restart when the view (matrices or region size) changed; True when it restarted."""
        if self.prepared is None:
            return False
        key = (np.round(np.asarray(view, np.float64), 9).tobytes(), np.round(np.asarray(window, np.float64), 9).tobytes(),
               bool(persp), int(width), int(height))
        if key == self.view_key:
            return False
        self.view_key = key
        cam = viewport_camera(view, window, persp, width, height)
        self.renderer.start(self.prepared.with_view(cam), self.levels, self.light)
        self.restarts += 1
        return True

    # ---------------------------------------------------------------- draw
    def draw(self, engine, context, depsgraph) -> None:
        """Draw the newest preview image (``view_draw``); restart if the view moved."""
        view, window, persp, w, h = _region_matrices(context)
        self.sync_view(view, window, persp, w, h)
        frame = self.renderer.frame()
        if frame is not None and frame.generation == self.renderer.generation:
            self._draw_frame(engine, depsgraph.scene, frame, w, h)
        r = self.renderer
        if r.error:
            _status(engine, f"Error: {r.error}")
        elif frame is not None and frame.generation == r.generation:
            state = "Done" if r.done else "Rendering"
            _status(engine, f"{state} | {frame.width}x{frame.height}, {frame.samples} sample(s)")
        if r.running:
            _RedrawTimer.ensure(r)

    def _draw_frame(self, engine, scene, frame: Frame, region_w: int, region_h: int) -> None:
        import bpy  # noqa: PLC0415

        if bpy.app.background:  # no GPU drawing without a window
            return
        key = (frame.generation, frame.serial)
        import gpu  # noqa: PLC0415 - not available in background mode
        from gpu_extras.presets import draw_texture_2d  # noqa: PLC0415

        if key != self._texture_key or self.texture is None:
            buf = gpu.types.Buffer("FLOAT", frame.width * frame.height * 4, frame.pixels)
            self.texture = gpu.types.GPUTexture((frame.width, frame.height), format="RGBA16F", data=buf)
            self._texture_key = key
        gpu.state.blend_set("ALPHA_PREMULT")
        engine.bind_display_space_shader(scene)
        draw_texture_2d(self.texture, (0, 0), region_w, region_h)
        engine.unbind_display_space_shader()
        gpu.state.blend_set("NONE")

    # ---------------------------------------------------------------- housekeeping
    def _on_image(self) -> None:  # called from the render thread: only set a flag
        _RedrawTimer.pending.set()

    def free(self) -> None:
        """Stop the render thread (the engine is being freed: Rendered mode was left)."""
        self.renderer.cancel()
        self.texture = None
        self.prepared = self.light = None


#: Every live session, so undo and file loads can drop their mesh caches.
_SESSIONS: "weakref.WeakSet[ViewportSession]" = weakref.WeakSet()


def _drop_mesh_caches(*_args) -> None:
    """Undo, redo and loading a file replace mesh data without geometry updates a cache can
    trust: start every viewport's cache afresh."""
    for session in list(_SESSIONS):
        session.mesh_cache.invalidate_all()


_HANDLERS = ("undo_post", "redo_post", "load_post")


def register() -> None:
    import bpy  # noqa: PLC0415

    for name in _HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if _drop_mesh_caches not in handlers:
            handlers.append(_drop_mesh_caches)


def _status(engine, message: str) -> None:
    if engine is not None:
        try:
            engine.update_stats("", message)
        except (ReferenceError, AttributeError, RuntimeError):
            pass


class _RedrawTimer:
    """A main-thread timer that tags 3D views in Rendered mode for redraw while previews arrive."""

    pending = threading.Event()
    registered = False
    renderers: "weakref.WeakSet" = weakref.WeakSet()  # previews that may still produce images

    @classmethod
    def ensure(cls, renderer=None) -> None:
        if renderer is not None:
            cls.renderers.add(renderer)
        try:
            import bpy  # noqa: PLC0415
        except ImportError:  # pragma: no cover
            return
        if not cls.registered:
            bpy.app.timers.register(_redraw_tick, first_interval=REDRAW_INTERVAL)
            cls.registered = True


def _redraw_tick():
    """Timer callback: redraw Rendered 3D views when a new image is ready; stops when no preview
    is rendering any more (the last image has been drawn)."""
    import bpy  # noqa: PLC0415

    t = _RedrawTimer
    if t.pending.is_set():
        t.pending.clear()
        wm = getattr(bpy.context, "window_manager", None)
        for window in getattr(wm, "windows", []):
            for area in window.screen.areas:
                if area.type == "VIEW_3D" and any(s.type == "VIEW_3D" and s.shading.type == "RENDERED"
                                                  for s in area.spaces):
                    area.tag_redraw()
        return REDRAW_INTERVAL
    if any(r.running for r in list(t.renderers)):
        return REDRAW_INTERVAL
    t.registered = False
    return None


def unregister() -> None:
    import bpy  # noqa: PLC0415

    for name in _HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if _drop_mesh_caches in handlers:
            handlers.remove(_drop_mesh_caches)
    unregister_timer()


def unregister_timer() -> None:
    try:
        import bpy  # noqa: PLC0415

        if bpy.app.timers.is_registered(_redraw_tick):
            bpy.app.timers.unregister(_redraw_tick)
    except Exception:
        pass
    _RedrawTimer.registered = False
