"""The surface-interaction stage of the eye pass: what a hit's shading needs, computed once.

Per hit of the tile tracer (core/integrators/eye/eye_pass.py): the shading normal bent by normal
maps (core/materials/surface.py, docs/physics.md section 4.6), Cycles' bump-terminator term for
normal-mapped diffuse lobes, the microfacet surfaces' BSDF parameters (core/materials/bsdf.py:
textures, side, one Principled layer drawn per hit for the bounce and every layer with its weight
for next events: core/materials/mixtures.py ``LobeMixture``), and the black-surface test. What the
emission / next-event stage computed for a hit and the BSDF-sampling stage reuses (the lobe's
parameters, the base colours) travels between them in a ``HitShading``, never as hidden state.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...materials import bsdf
from ...materials.mixtures import LobeMixture, per_hit_layers
from ...materials.surface import shading_normal, surface_mix_fac, surface_reflectance, surface_roughness
from ...transport.walker import Hit, Rays, shading_normals

__all__ = ["HitShading", "bend_normals", "bump", "bump_shadowing", "surface_params", "surface_lobes", "reflects"]


@dataclass
class HitShading:
    """What the eye pass's on_hit shaded at one batch of hits, handed to its scatter (the walker
    passes it on): the lobes for light and bounce, and the base colours computed once."""
    # (mask (B,) bool, bsdf.SurfaceParams of those hits, their LobeMixture or None): the microfacet hits, or None
    micro: tuple | None = None
    # (rows (K,) of the batch, base colours (K, n) or (K,)): the Lambertian hits, or None
    diffuse: tuple | None = None
    # (rows, BraggLobe, body share) of the opal hits (bragg_shading.BraggShading.shade), or None
    bragg: tuple | None = None

    def albedo_at(self, sel: np.ndarray):
        """The base colours of the hits ``sel`` (B,) bool, or None when they were not all shaded
        as diffuse."""
        if self.diffuse is None:
            return None
        rows, albedo = self.diffuse
        want = np.flatnonzero(sel)
        if len(want) == len(rows) and np.array_equal(rows, want):  # the usual case: the same hits
            return albedo
        pos = np.searchsorted(rows, want)
        if pos.size and (pos.max() >= len(rows) or not np.array_equal(rows[pos], want)):
            return None  # a hit on_hit did not shade as diffuse
        return albedo[pos]


def bend_normals(prepared, hit: Hit, bend: np.ndarray) -> None:
    """Bend the shading normal of the hits ``bend`` (B,) bool by their normal maps
    (core/materials/surface.py), in place: hit.ns becomes a new array."""
    ns = hit.ns.copy()
    ns[bend] = shading_normal(prepared, hit.take(bend))
    hit.ns = ns


def bump(prepared, normal_maps: bool, hit: Hit, wi: np.ndarray) -> np.ndarray | float:
    """bump_shadowing for the hits whose material has a normal map (1 elsewhere): light
    (next events) and sampled directions (the bounce's weight) alike, as Cycles applies it
    to diffuse closures; measured against Cycles in tests/blender/test_cycles_parity.py."""
    if not normal_maps:
        return np.float32(1.0)
    bent = prepared.textures.bound("normal")[hit.mat]
    if not bent.any():
        return np.float32(1.0)
    ni = hit.ng if prepared.corner_normals is None else shading_normals(
        prepared.corner_normals, hit.prim, hit.bu, hit.bv, hit.ng)  # the normal before the map bent it
    return np.where(bent, bump_shadowing(ni, hit.ns, wi), np.float32(1.0))


def bump_shadowing(ni: np.ndarray, ns: np.ndarray, wi: np.ndarray) -> np.ndarray:
    """The bump-terminator shadowing of a diffuse BSDF whose normal a normal map bent from the
    interpolated normal ``ni`` to ``ns``, for light from ``wi`` (Conty Estevez, Lecocq & Stein
    2019, "A Microfacet-Based Shadowing Function to Solve the Bump Terminator Problem", as
    Cycles' ``bump_shadowing_term`` has it): a GGX Smith G1 towards wi with alpha^2 =
    tan^2(angle(ni, ns)) / 8 (at most 1); 0 for light below the interpolated surface."""
    cos_i = np.einsum("ij,ij->i", ni, wi)
    cos_d = np.minimum(np.abs(np.einsum("ij,ij->i", ni, ns)), np.float32(1.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        tan2_d = (1 - cos_d * cos_d) / (cos_d * cos_d)
        alpha2 = np.clip(np.float32(0.125) * tan2_d, 0, 1)
        cos2_i = np.maximum(cos_i * cos_i, np.float32(1e-12))
        tan2_i = (1 - cos2_i) / cos2_i
        g = 2 / (1 + np.sqrt(1 + alpha2 * tan2_i))
    return np.where((cos_i < 0) | (cos_d <= 0), np.float32(0.0), g).astype(np.float32)


def surface_params(prepared, mixed_layers: np.ndarray, rays: Rays, hit: Hit, rng) -> "bsdf.SurfaceParams":
    """core/materials/bsdf.py's parameters of these hits (``surface_lobes`` without the mixture)."""
    return surface_lobes(prepared, mixed_layers, rays, hit, rng)[0]


def surface_lobes(prepared, mixed_layers: np.ndarray, rays: Rays, hit: Hit, rng):
    """(core/materials/bsdf.py's parameters of these hits, their LobeMixture or None): base colour
    and roughness per hit (textures), the side (entering or leaving glass), one Principled layer
    (or lobe of a shader mix, its weights per hit where a Fresnel / Layer Weight node gives them)
    drawn per hit where the material mixes layers (``mixed_layers`` (M,) bool; a pure metal,
    glass or base takes its one layer: no number) for the bounce, and every lobe of those hits
    with its weight for next events and MIS (core/materials/mixtures.py, docs/physics.md 14.8)."""
    base = surface_reflectance(prepared, hit, rays.lam)
    if rays.lam is not None:
        base = base[:, None]
    mixed = mixed_layers[hit.mat]
    u_layer = rng.random(len(rays)) if mixed.any() else None
    # a Fresnel / Layer Weight mix: its layer weights per hit from the view direction (section 14.8)
    weights = None if u_layer is None else per_hit_layers(
        prepared.materials, hit.mat, np.einsum("ij,ij->i", -rays.d, hit.ns), hit.front, surface_mix_fac(prepared, hit))
    rough = surface_roughness(prepared, hit)
    wo = -rays.d
    mixture, top = None, None
    if u_layer is not None:
        m = prepared.materials
        metallic, transmission = (m.metallic[hit.mat], m.transmission[hit.mat]) if weights is None else weights
        mixture = LobeMixture.of(m, hit.mat, hit.front, mixed, metallic, transmission, wo, hit.ns, lam=rays.lam,
                                 base=base, roughness=rough)
        if mixture is not None and mixture.layered:  # Principled's sheen and coat drawn first (section 14.10)
            u_layer, top = mixture.draw(u_layer)
    params = bsdf.params_from_materials(prepared.materials, hit.mat, hit.front, rays.lam, base=base,
                                        roughness=rough, u_layer=u_layer, weights=weights)
    if top is not None:
        params = mixture.put_top(params, top)
    return bsdf.with_outgoing(params, wo, hit.ns), mixture  # the next events and the bounce share wo


def reflects(n: int, probe: int | None, albedo: np.ndarray) -> np.ndarray:
    """(B,) bool: base colours (B, n) spectra or (B,) values that are not zero everywhere.
    One column decides where ``constants.probe_wavelength`` found one (``probe``; a (B, n)
    maximum costs about a tenth of a textured floor's eye pass)."""
    if albedo.ndim == 1:
        return albedo > 0
    if probe is not None and albedo.shape[1] == n:
        return albedo[:, probe] > 0
    return albedo.max(axis=1) > 0
