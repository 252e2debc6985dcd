"""The render plan: which passes a scene needs, and what was skipped and why.

A scene pays only for what it contains (product card): no light pass without a specular or
dielectric object for light to pass through, no grating work without gratings.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .materials import DIELECTRIC, MIRROR

__all__ = ["RenderPlan", "plan_render"]


@dataclass
class RenderPlan:
    eye_pass: bool = True
    light_pass: bool = False
    gratings: bool = False
    dispersion: bool = False
    notes: list[str] = field(default_factory=list)     # what runs and what is skipped, for the stats
    warnings: list[str] = field(default_factory=list)  # things the user should fix or know

    def summary(self) -> str:
        return "; ".join(self.notes)


def plan_render(ctx, light_pass=None) -> RenderPlan:
    """What this scene needs. ``light_pass``: a light_pass.LightPass, which knows whether any
    light reaches a mirror or glass object (and a diffuse surface to receive caustics)."""
    plan = RenderPlan()
    used = np.unique(ctx.tri_material) if len(ctx.tri_material) else np.zeros(0, np.int64)
    kinds = ctx.materials.kind[used] if len(used) else np.zeros(0, np.int32)
    specular = bool(np.isin(kinds, [MIRROR, DIELECTRIC]).any())
    plan.dispersion = bool(ctx.materials.dispersive[used].any()) if len(used) else False
    plan.notes.append(f"eye pass: {ctx.grid.n} wavelengths, {ctx.settings.samples} samples/pixel")
    if plan.dispersion:
        plan.notes.append(f"dispersion: {ctx.settings.dispersion_sampling}")
    if not specular:
        plan.notes.append("light pass skipped: no mirror or glass in the scene")
    elif len(ctx.lights) == 0:
        plan.notes.append("light pass skipped: no lights")
    elif light_pass is None or not light_pass.needed:
        plan.notes.append("light pass skipped: no light reaches a mirror or glass object")
    elif ctx.settings.light_paths <= 0:
        plan.notes.append("light pass skipped: light paths set to 0")
    else:
        plan.light_pass = True
        plan.notes.append(f"light pass: {ctx.settings.light_paths / 1e6:.2f} M paths aimed at "
                          f"{len(light_pass.objects)} mirror/glass object(s)")
    n_gratings = int(ctx.gratings.enabled[used].sum()) if len(used) else 0
    plan.gratings = n_gratings > 0
    if plan.gratings:
        plan.notes.append(f"gratings: {n_gratings} material(s), direct light diffracted in the eye pass")
    else:
        plan.notes.append("gratings: none in the scene, no grating work")
    return plan
