"""Persistent data: what a final render keeps for the next frame (Render > Performance > Final
Render > Persistent Data, ``scene.render.use_persistent_data``).

With Persistent Data on, Blender keeps the render engine instance between the frames of an
animation (and between F12s) and calls its ``update`` with the depsgraph's updates before each
``render``, as for Cycles. The engine then keeps here the exported core Scene, the
PreparedScene (ray caster, triangle frames, spectra, light-pass targets, ...) and the light
pass's result, and takes from them what nothing it depends on changed
(docs/blender.md, "Persistent data"):

- **camera only**: when every update since the last frame is of the render camera (its object's
  transform, its camera data) or of an animation action, and the render settings, resolution,
  border and camera override are the same, only the camera is exported again
  (``export_camera``); the prepared scene is the kept one seen through it
  (``PreparedScene.with_view``: nothing rebuilt) and the light pass's caustic map and grating
  records are kept. Its camera splat (light paths joined to the camera, docs/physics.md section
  4.9) is made for one view, so the light pass keeps the splat's light-path vertices (up to
  ``SPLAT_VERTEX_CAP`` bytes) and the new view's splat is made from them: shadow rays to the new
  camera, no light paths traced (core/integrators/light/splat_vertices.py ``resplat``,
  core/render/frame.py ``light_reuse``), the image the one a fresh render makes, bit for bit.
  Where none were kept (over the cap, or the kept frame did not splat: its camera moved
  during the motion-blur shutter) the light pass runs again, and the stats line says why;
- **anything else** (an object moved, a material, light, world or setting changed, or no
  updates were seen): the scene is exported again, reading only the meshes whose geometry an
  update changed (``MeshCache``), and prepared with the kept preparation as ``reuse``
  (core/render/prepare.py): the ray caster is kept when the exported vertices and triangles are
  equal, the light pass when the whole scene but the camera and every light-pass setting are
  equal (a comparison of the exported arrays, not a guess from the updates);
- **Persistent Data off**: nothing is kept; what an earlier frame kept is freed.

Each view layer has its own depsgraph, so the engine keeps one ``PersistentData`` per view layer.
``PersistentData`` is plain Python (no bpy) so its decisions are testable without Blender; the
engine feeds it ``depsgraph.updates`` (``note_updates``) and reads and stores its ``Kept``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from types import SimpleNamespace

__all__ = ["Kept", "PersistentData", "Update", "camera_only_updates", "settings_key", "SPLAT_VERTEX_CAP"]

#: Bytes of camera-splat vertices a final render's light pass keeps for the next frame's camera
#: (core/integrators/light/splat_vertices.py): 256 MB, the most the caustic map's two lanes may
#: take (light_pass.element_layout). The prism example keeps 0.56 M vertices, 35 MB, at its 1 M
#: light paths (65 bytes each: 44 for a path split by the prism, 32 + 4 x 61 for a white one;
#: docs/benchmarks.md, "Persistent data"), so the cap holds about 7 M of its paths; past it the
#: light pass keeps none and a camera-only frame runs it again (said in the stats line).
SPLAT_VERTEX_CAP = 256 * 2**20

#: ID types whose updates alone change nothing the render reads besides what is checked
#: elsewhere: an action's own update (the IDs it animates report their own updates).
_NEUTRAL_TYPES = frozenset({"ACTION"})


@dataclass(frozen=True)
class Update:
    """One of ``depsgraph.updates``, copied while it is valid (``update`` runs before ``render``)."""

    id_type: str
    name: str
    geometry: bool
    transform: bool
    shading: bool

    @classmethod
    def of(cls, update) -> "Update":
        return cls(str(update.id.id_type), str(update.id.name_full), bool(update.is_updated_geometry),
                   bool(update.is_updated_transform), bool(update.is_updated_shading))

    def as_depsgraph_update(self):
        """The attributes MeshCache.invalidate reads of a depsgraph update."""
        return SimpleNamespace(id=SimpleNamespace(id_type=self.id_type, name_full=self.name),
                               is_updated_geometry=self.geometry)


def camera_only_updates(updates, camera_object: str, camera_data: str) -> bool:
    """Whether ``updates`` (Updates) change nothing but the camera: each is the camera object
    (without a geometry update), its camera data, or an action. An empty list (a re-render of
    the same frame) counts as camera only."""
    for u in updates:
        if u.id_type in _NEUTRAL_TYPES:
            continue
        if u.id_type == "OBJECT" and u.name == camera_object and not u.geometry:
            continue
        if u.id_type == "CAMERA" and u.name == camera_data:
            continue
        return False
    return True


def settings_key(settings):
    """The render settings a kept frame must share with the next for the camera-only path: all
    of them but the spectral EXR's path (it holds the frame number)."""
    return replace(settings, spectral_exr="")


@dataclass
class Kept:
    """One final render's reusable state."""

    settings: object            # RenderSettings as the engine made them (settings_key)
    frame_setup: tuple          # (width, height, border region, camera object name)
    exported: object            # export.ExportResult
    camera_warnings: tuple      # the warnings of its camera's export (replaced on a camera-only frame)
    prepared: object            # core PreparedScene
    light: object = None        # core LightPassResult of ``prepared``, or None


class PersistentData:
    """The engine's kept state between final renders, and the counts of what was reused."""

    def __init__(self):
        self.kept: Kept | None = None
        self.updates: list[Update] | None = None  # since the last render; None: not seen
        self._mesh_cache = None
        self.renders = 0

    @property
    def mesh_cache(self):
        if self._mesh_cache is None:
            from .export import MeshCache  # noqa: PLC0415 - export needs bpy; this module's logic does not

            self._mesh_cache = MeshCache()
        return self._mesh_cache

    def note_updates(self, updates) -> None:
        """``depsgraph.updates`` (RenderEngine.update, before each render)."""
        self.updates = [Update.of(u) for u in updates]

    def take_updates(self) -> list[Update] | None:
        """The updates noted since the last render (None: none were seen), once."""
        out, self.updates = self.updates, None
        return out

    def camera_only(self, updates, settings, frame_setup, camera_object: str, camera_data: str) -> Kept | None:
        """The kept frame, if the next frame differs from it in the camera alone (see the module)."""
        k = self.kept
        if k is None or updates is None or k.frame_setup != frame_setup:
            return None
        if settings_key(settings) != k.settings:
            return None
        return k if camera_only_updates(updates, camera_object, camera_data) else None

    def invalidate_meshes(self, updates) -> None:
        """Drop the kept meshes the updates changed (all of them when no updates were seen)."""
        if updates is None:
            self.mesh_cache.invalidate_all()
        else:
            self.mesh_cache.invalidate([u.as_depsgraph_update() for u in updates])

    def free(self) -> None:
        """Forget everything (Persistent Data off)."""
        self.kept = None
        self.updates = None
        self._mesh_cache = None
