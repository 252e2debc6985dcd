"""What the light pass aims at and who receives its light: the triangles that bend light (the
casters: mirrors, glass, line gratings, opal), those where caustics land (diffuse receivers) and
where grating records land, with the casters' bounding spheres and each emitter's power towards
them (part of the prepared scene).

Line gratings are casters: a light path that meets one is diffracted and its orders go on as
specular paths (docs/physics.md section 3.10). Rough and layered mirrors and glass are not: the
eye pass shades them. How paths are aimed at the casters is core/lights/aiming.py; each
emitter's power towards them, which shares out the path budget, core/lights/emission.py
(docs/physics.md sections 4.1, 7.7, 7.9).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...gratings.order_sampling import scattering_materials
from ...lights.aiming import CasterObjects, caster_objects
from ...lights.emission import light_budgets, mesh_light_budget, world_budget, world_luminance
from ...materials.spectra import DIELECTRIC, DIFFUSE, MIRROR

__all__ = ["LightTargets", "find_light_targets"]


@dataclass(frozen=True)
class LightTargets:
    """What the light pass aims at and who receives its light (part of the prepared scene)."""

    caster_mask: np.ndarray    # (T,) bool: mirror, glass and grating triangles (light bends or diffracts there)
    receiver_mask: np.ndarray  # (T,) bool: diffuse triangles (caustics land there)
    grating_mask: np.ndarray   # (T,) bool: grating triangles (records land there)
    objects: CasterObjects     # bounding spheres of the connected caster objects
    budget: np.ndarray         # (L,) estimated luminous power each light sends towards the casters
    mesh_budget: float = 0.0   # the same for all emissive triangles together (mesh_lights.MeshLights)
    world_budget: float = 0.0  # the same for the world (uniform or map)

    @property
    def needed(self) -> bool:
        """Some light reaches a caster, and something can receive what comes out of it."""
        return (bool(np.any(self.budget > 0)) or self.mesh_budget > 0 or self.world_budget > 0) and bool(
            self.receiver_mask.any() or self.grating_mask.any())

    @property
    def budgets(self) -> np.ndarray:
        """(L + 2,) the lights' budgets, then the emissive meshes' (light-pass index L) and the
        world's (index L + 1)."""
        return np.append(self.budget, [self.mesh_budget, self.world_budget])


def find_light_targets(vertices, triangles, tri_material, materials, gratings, lights, conv,
                       light_paths: int = 1, mesh_lights=None, world_spectrum=None, microfacet=None) -> LightTargets:
    """The light pass's targets for a scene (prepared materials, gratings, lights, emissive
    meshes, and ``world_spectrum`` (n,) the world's mean radiance, or None: a black world).
    Without light paths or any emitter there is nothing to aim, so the casters are not grouped
    at all. Rough and layered mirrors and glass (``microfacet`` (M,) bool, bsdf.microfacet_materials;
    None: none) are not casters: the eye pass shades them, and a light path ends there. Line
    gratings are casters: their orders go on (docs/physics.md section 3.10)."""
    mk = materials.kind[tri_material] if len(tri_material) else np.zeros(0, np.int32)
    grating = gratings.enabled[tri_material] if len(tri_material) else np.zeros(0, bool)
    caster = np.isin(mk, [MIRROR, DIELECTRIC])
    if microfacet is not None and len(tri_material):
        caster &= ~np.asarray(microfacet)[tri_material]
    if len(tri_material):
        caster |= scattering_materials(gratings, materials.kind, microfacet)[tri_material]
    if getattr(gratings, "bragg", None) is not None and len(tri_material):  # opal flashes light the table
        caster |= gratings.bragg[tri_material]
    world_lum = world_luminance(world_spectrum, conv)
    emitters = len(lights) > 0 or mesh_lights is not None or world_lum > 0
    aimed = caster if light_paths > 0 and emitters else np.zeros_like(caster)
    objects = caster_objects(vertices, triangles, aimed)
    # a black diffuse surface (an Emission-only material) reflects no caustic: not a receiver
    receiver = mk == DIFFUSE
    if len(tri_material):
        receiver &= (np.asarray(materials.reflectance).max(axis=1) > 0)[tri_material]
    return LightTargets(caster, receiver, grating, objects, light_budgets(lights, objects, conv),
                        mesh_light_budget(mesh_lights, objects), world_budget(world_lum, objects))

