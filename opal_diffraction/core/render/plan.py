"""The render plan: which passes a scene needs, what was skipped and why, and how each pass runs.

A scene pays only for what it contains: no light pass without a specular or dielectric object
for light to pass through (and a light that reaches it, and a surface to receive what comes
out), no grating work without gratings. ``plan_render`` is a pure function of the prepared
scene: it runs nothing. It also makes every decision the passes would otherwise make per tile
or per batch (the camera splat, the light paths' diffuse bounce, the Fresnel split, grey path
weights, ray differentials): the passes read them from the plan.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..gratings import layering as grating_layering
from ..integrators.bragg_shading import bragg_materials
from ..integrators.light import camera_splat as camera_splat_rules
from ..integrators.light import splat_bounce as splat_bounce_rules
from ..materials.spectra import DIELECTRIC, MIRROR
from ..volumes.media import has_media

__all__ = ["RenderPlan", "plan_render"]


@dataclass(frozen=True)
class RenderPlan:
    eye_pass: bool = True
    light_pass: bool = False
    gratings: bool = False
    dispersion: bool = False
    # how the passes run (the light pass and the eye pass read these):
    # the light pass joins its landings on plain diffuse surfaces to the camera
    # (core/integrators/light/camera_splat.py, docs/physics.md section 4.9)
    camera_splat: bool = False
    # ... and continues them by one diffuse bounce (core/integrators/light/splat_bounce.py, section 4.11)
    splat_bounce: bool = False
    # camera rays take both branches at their first smooth glass (core/integrators/eye/fresnel_split.py)
    fresnel_split: bool = False
    # white eye paths through grey materials carry one number (core/integrators/eye/grey_paths.py)
    grey_paths: bool = False
    # camera rays carry ray differentials to integrate gratings over pixel footprints (core/sampling/footprint.py)
    ray_differentials: bool = False
    notes: tuple[str, ...] = ()     # what runs and what is skipped, for the stats
    warnings: tuple[str, ...] = ()  # things the user should fix or know

    def summary(self) -> str:
        return "; ".join(self.notes)


def plan_render(prepared) -> RenderPlan:
    """What the prepared scene (prepare.PreparedScene) needs."""
    settings = prepared.settings
    used = np.unique(prepared.tri_material) if len(prepared.tri_material) else np.zeros(0, np.int64)
    kinds = prepared.materials.kind[used] if len(used) else np.zeros(0, np.int32)
    specular = bool(np.isin(kinds, [MIRROR, DIELECTRIC]).any())
    bragg = getattr(prepared.gratings, "bragg", None)  # FCC opal planes send light paths on too
    specular |= bool(bragg is not None and len(used) and bragg[used].any())
    # line gratings scatter their orders in the light pass too (docs/physics.md section 3.10)
    scatters = specular or bool(prepared.light_targets.caster_mask.any())
    dispersion = bool(prepared.materials.dispersive[used].any()) if len(used) else False
    notes = [f"eye pass: {prepared.grid.n} wavelengths, {settings.samples} samples/pixel"]
    if dispersion:
        notes.append(f"dispersion: {settings.dispersion_sampling}")
    light_pass = False
    if not scatters:
        notes.append("light pass skipped: no mirror or glass in the scene")
    elif len(prepared.lights) == 0 and not (prepared.light_targets.world_budget > 0
                                            or prepared.light_targets.mesh_budget > 0):
        notes.append("light pass skipped: no lights")
    elif settings.light_paths <= 0:
        notes.append("light pass skipped: light paths set to 0")
    elif not prepared.light_targets.needed:
        notes.append("light pass skipped: no light reaches a mirror or glass object")
    else:
        light_pass = True
        notes.append(f"light pass: {settings.light_paths / 1e6:.2f} M paths aimed at "
                     f"{len(prepared.light_targets.objects)} mirror/glass/grating object(s)")
    n_gratings = int(prepared.gratings.enabled[used].sum()) if len(used) else 0
    if n_gratings:
        notes.append(f"gratings: {n_gratings} material(s), direct light diffracted in the eye pass")
    else:
        notes.append("gratings: none in the scene, no grating work")
    camera_splat = camera_splat_rules.applies(prepared)
    layered = grating_layering.active(prepared)  # gratings take their power from the base (section 3.3)
    m = prepared.scene.materials
    bragg = bool(len(m) and bragg_materials(m).any())  # FCC opal lobes
    warnings = []
    media = has_media(prepared.scene)  # [volumes] homogeneous media: the eye pass only (docs/physics.md section 15)
    if media:
        notes.append("volumes: homogeneous media in the eye pass")
        camera_splat = False  # the splat's light paths would cross the media unattenuated
        if light_pass:
            warnings.append("volumes: the light pass ignores media: caustics through mirrors and glass are "
                            "neither attenuated nor scattered by the media on their way to a surface")
    return RenderPlan(eye_pass=True, light_pass=light_pass, gratings=n_gratings > 0, dispersion=dispersion,
                      camera_splat=camera_splat, warnings=tuple(warnings),
                      splat_bounce=camera_splat and bool(settings.splat_bounce) and splat_bounce_rules.applies(prepared),
                      fresnel_split=bool(settings.fresnel_split) and not layered,
                      # gratings, their layers and the opal's lobes read spectral weights
                      grey_paths=not (prepared.gratings.any or layered or bragg or media),
                      ray_differentials=bool(prepared.gratings.any and settings.grating_footprint),
                      notes=tuple(notes))
