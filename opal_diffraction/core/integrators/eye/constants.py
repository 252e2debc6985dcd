"""What the eye pass knows about a render before it traces a tile: one frozen ``EyeConstants``.

Built once per render (``EyePass``) from the prepared scene and the light pass's result, and
read by every stage of the tile tracer (core/integrators/eye/eye_pass.py): which caustic paths
the light pass counted (docs/physics.md section 4.5), where its camera splat and splat bounce
already hold the light (sections 4.9, 4.11), which lights a ray can meet, the bounce limits,
black emission-only materials, grey-path weights (section 4.13), the grating layers and the
opal's Bragg lobes (section 5.8). Nothing here changes while tiles are traced, so tiles may run
in parallel threads over one object.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...gratings import layering as grating_layering
from ...gratings.order_sampling import scattering_materials
from ...gratings.lobe import lobe_materials
from ...lights.sources import AREA_DISK, AREA_RECT, POINT, SPOT, SUN, is_delta
from ...materials.spectra import DIFFUSE
from ..bragg_shading import BraggShading
from ..light import splat_bounce
from ..light.camera_splat import direct_materials, usable_splat
from ...volumes.media import prepare_media
from .grey_paths import GreyPaths
from .medium_interaction import MediumStage

__all__ = ["EyeConstants", "eye_constants"]


@dataclass(frozen=True)
class EyeConstants:
    """The per-render constants of the eye pass's stages."""
    prepared: object                  # prepare.PreparedScene
    n: int                            # wavelength samples
    caustic_map: object | None        # the light pass's IlluminationMap, or None (no light pass)
    caustic_lit: np.ndarray | None    # (T,) bool triangles the caustic map holds flux on
    record_map: object | None         # the light pass's GratingRecords, or None
    # (M,) bool: materials whose directly seen caustics the light pass splatted for this camera
    # (core/integrators/light/camera_splat.py, docs/physics.md section 4.9); None: the map everywhere
    direct_splat: np.ndarray | None
    # (M,) bool: where the light pass's paths also took a diffuse bounce to the camera
    # (core/integrators/light/splat_bounce.py, section 4.11); None: no such paths
    splat_bounce: np.ndarray | None
    # camera rays carry ray differentials (core/sampling/footprint.py): only to integrate gratings
    footprints: bool
    # (M,) bool Principled mixes whose layer is drawn per hit (metallic or transmission strictly
    # between 0 and 1); elsewhere the layer is fixed and no number is drawn for it
    mixed_layers: np.ndarray
    probe: int | None                 # the black-surface test's wavelength (``probe_wavelength``)
    lobe_gratings: np.ndarray         # (M,) bool gratings whose hits continue the path along an order (gratings/lobe.py)
    limits: tuple                     # (total, diffuse, glossy, transmission) bounce limits
    # the emitters' caustic paths (diffuse <- specular... <- emitter) the light pass has already
    # counted: the eye pass leaves those paths out (docs/physics.md section 4.5)
    caustics_cover_lights: bool
    delta: np.ndarray                 # (L,) bool delta lights (no MIS partner)
    hittable: np.ndarray              # (L,) bool lights a ray can meet (sized area, point, spot)
    soft_suns: np.ndarray             # indices of suns with an angle (met by escaping rays)
    mesh_lights: object | None        # lights.mesh_lights sampler of the emissive meshes, or None
    normal_maps: bool                 # a material has a normal map
    bragg: BraggShading | None        # FCC opal lobes (None: no BRAGG material)
    # (M,) black diffuse materials (emission-only surfaces: no base colour, no colour texture,
    # no grating, no microfacet layer): their paths end after the emission (and the first hit's
    # denoising features) without next events, caustic lookups or a bounce; None: none
    black: np.ndarray | None
    bent: bool                        # shading normals differ from geometric ones: both side tests
    albedo_rgb: np.ndarray            # (M, 3) linear RGB base colours (the denoising albedo)
    layers: bool                      # gratings take their power from the base (section 3.3)
    # gratings the light pass scatters (section 3.10): the caustic map holds their diffracted
    # light on diffuse surfaces, and at a diffuse base only the base's share already; None: none
    scattering: np.ndarray | None
    # camera rays take both Fresnel branches at their first smooth glass (fresnel_split.py)
    fresnel_split: bool
    # grey path weights (grey_paths.py) where the plan allows them (the plain path tracer: gratings,
    # their layers and the opal's lobes read spectral weights)
    greys: GreyPaths
    # [volumes] the media stage (medium_interaction.MediumStage; docs/physics.md section 15), None: no media
    media: MediumStage | None = None


def eye_constants(prepared, light, plan) -> EyeConstants:
    """The constants of a render of ``prepared`` with the light pass's result ``light`` (None:
    no light pass), as ``plan`` (render/plan.RenderPlan of ``prepared``) decided the passes."""
    caustic_map = None if light is None else light.caustics
    direct_splat = (None if caustic_map is None or not plan.camera_splat or usable_splat(prepared, light) is None
                    else direct_materials(prepared))
    s = prepared.settings
    pl = prepared.lights
    kinds = np.asarray(pl.kind)
    delta = np.array([is_delta(pl, i) for i in range(len(pl))], bool)
    normal_maps = prepared.textures.uses("normal")
    bragg = BraggShading.for_prepared(prepared)
    refl = prepared.materials.reflectance
    black = ((prepared.materials.kind == DIFFUSE) & ~prepared.microfacet & ~prepared.gratings.enabled
             & ~prepared.textures.bound("color") & ((refl.max(axis=1) <= 0) if refl.size else True))
    if bragg is not None or not black.any():
        black = None
    layers = grating_layering.active(prepared)
    mt, tr = np.asarray(prepared.materials.metallic), np.asarray(prepared.materials.transmission)
    return EyeConstants(
        prepared=prepared, n=prepared.grid.n, caustic_map=caustic_map,
        caustic_lit=None if caustic_map is None else caustic_map.lit_triangles(),
        record_map=None if light is None else light.grating_records,
        direct_splat=direct_splat,
        splat_bounce=(splat_bounce.receivers(prepared) if direct_splat is not None
                      and plan.splat_bounce else None),
        footprints=plan.ray_differentials,
        mixed_layers=((mt > 0) & (mt < 1)) | ((tr > 0) & (tr < 1)) | (
            np.asarray(prepared.materials.layer_fac) != 0 if prepared.materials.layer_fac is not None else False) | (
            prepared.materials.layered if prepared.materials.layered is not None else False),
        probe=probe_wavelength(prepared),
        lobe_gratings=lobe_materials(prepared),
        limits=(s.max_bounces, s.diffuse_bounces, s.glossy_bounces, s.transmission_bounces),
        caustics_cover_lights=caustic_map is not None,
        delta=delta,
        # lights a ray can meet: area lights, points and spots with a radius; suns with an angle
        hittable=~delta & np.isin(kinds, [POINT, SPOT, AREA_RECT, AREA_DISK]),
        soft_suns=np.flatnonzero(~delta & (kinds == SUN)),
        mesh_lights=prepared.mesh_lights, normal_maps=normal_maps, bragg=bragg, black=black,
        bent=prepared.corner_normals is not None or normal_maps,
        albedo_rgb=np.asarray(prepared.scene.materials.color, np.float32).reshape(-1, 3),
        layers=layers,
        scattering=(scattering_materials(prepared.gratings, prepared.materials.kind, prepared.microfacet)
                    if caustic_map is not None and prepared.gratings.any else None),
        fresnel_split=plan.fresnel_split,
        greys=GreyPaths(prepared, enabled=plan.grey_paths),
        media=_media_stage(prepared))


def _media_stage(prepared) -> MediumStage | None:
    """The eye pass's media stage, or None without media (core/volumes/media.py)."""
    media = prepare_media(prepared.scene, prepared.conv)
    if media is None:
        return None
    s = prepared.settings
    return MediumStage(prepared, media, (s.max_bounces, s.diffuse_bounces, s.glossy_bounces, s.transmission_bounces),
                       getattr(s, "volume_bounces", 0))


def probe_wavelength(prepared) -> int | None:
    """A wavelength index j at which every base colour the scene can produce is positive unless
    it is zero at every wavelength, or None. Textures' colours are rgb @ basis with rgb in
    [0, 1] (core/materials/surface.py), so j must have every basis row positive there; every material's
    own reflectance must be positive at j exactly when it is anywhere."""
    refl = np.asarray(prepared.materials.reflectance)
    if refl.ndim != 2 or refl.shape[1] == 0:
        return None
    tx = prepared.textures
    ok = np.ones(refl.shape[1], bool)
    if tx.uses("color"):
        ok &= (np.asarray(tx.reflectance_basis) > 0).all(axis=0)
    ok &= ((refl > 0) == (refl > 0).any(axis=1, keepdims=True)).all(axis=0)
    cols = np.flatnonzero(ok)
    return int(cols[len(cols) // 2]) if len(cols) else None
