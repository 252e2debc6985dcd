"""Volume scenes against Cycles (issue 31's "Must show"): homogeneous fog lit by a spot, and an
absorbing medium inside glass, built with ordinary nodes (a World Output's Volume: Volume Scatter
plus Volume Absorption; a Glass BSDF with a Volume Absorption on the Material Output's Volume),
rendered by Cycles and by OPAL_DIFFRACTION in one bpy session (tests/blender/test_volume_parity.py).
Both engines are matched as tests/blender/parity_scenes.py's ``match_engines`` matches them
(Volume bounces 0: Cycles' default, single scattering, and the core's)."""

from __future__ import annotations

import math

import bpy

import blender_scenes as bs
import parity_scenes as ps

__all__ = ["SCENES", "build"]


def _volume_world(sc, scatter=(0.9, 0.8, 0.6), density=0.25, anisotropy=0.3, absorb=(0.6, 0.8, 0.9),
                  absorb_density=0.05):
    world = bpy.data.worlds.new("fog")
    nt = world.node_tree
    nt.nodes["Background"].inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    out = nt.nodes["World Output"]
    sc_node = nt.nodes.new("ShaderNodeVolumeScatter")
    sc_node.inputs["Color"].default_value = (*scatter, 1.0)
    sc_node.inputs["Density"].default_value = density
    sc_node.inputs["Anisotropy"].default_value = anisotropy
    ab = nt.nodes.new("ShaderNodeVolumeAbsorption")
    ab.inputs["Color"].default_value = (*absorb, 1.0)
    ab.inputs["Density"].default_value = absorb_density
    add = nt.nodes.new("ShaderNodeAddShader")
    nt.links.new(sc_node.outputs[0], add.inputs[0])
    nt.links.new(ab.outputs[0], add.inputs[1])
    nt.links.new(add.outputs[0], out.inputs["Volume"])
    sc.world = world
    return world


def fog_spot(image_dir):
    """A grey floor and a white cube in the world's fog (Volume Scatter (0.9, 0.8, 0.6), density
    0.25, anisotropy 0.3, plus a bluish Volume Absorption of density 0.05), lit by a spot from
    above: the cone of light in the air, the cube's shadow in it, the lit floor."""
    sc = ps._scene()
    bs.plane("floor", half=6.0, mat=bs.material("floor", "DIFFUSE", (0.5, 0.5, 0.5)))
    ps._cube("cube", 0.8, (0.4, 0.3, 0.4), bs.material("cube", "DIFFUSE", (0.8, 0.8, 0.8)))
    bs.light("SPOT", (0.0, 0.0, 3.5), 800.0, spot_size=math.radians(50), spot_blend=0.2)
    _volume_world(sc)
    ps.look_at((0.0, -5.5, 2.0), (0.0, 0.0, 1.2))
    return sc


def glass_absorption(image_dir):
    """A smooth glass sphere (Glass BSDF, white, IOR 1.45) holding a Volume Absorption (colour
    (0.2, 0.5, 0.9), density 1.5) before a white-and-grey emissive checker: Beer-Lambert deepens
    with the path length through the sphere."""
    sc = ps._scene()
    ps.emissive_checker(bs.material("bright", "EMISSION", (1.0, 1.0, 1.0), Strength=2.0),
                        bs.material("dim", "EMISSION", (0.5, 0.5, 0.5), Strength=1.0), 8)
    glass = bs.material("glass", "GLASS", (1.0, 1.0, 1.0), IOR=1.45, Roughness=0.0)
    nt = glass.node_tree
    ab = nt.nodes.new("ShaderNodeVolumeAbsorption")
    ab.inputs["Color"].default_value = (0.2, 0.5, 0.9, 1.0)
    ab.inputs["Density"].default_value = 1.5
    nt.links.new(ab.outputs[0], nt.nodes["Material Output"].inputs["Volume"])
    ps._smooth_sphere("sphere", 0.7, (0.0, 0.0, 0.8), glass)
    ps.look_at((0.0, -2.6, 0.9), (0.0, 0.0, 0.8))
    return sc


SCENES = {f.__name__: f for f in (fog_spot, glass_absorption)}


def build(name: str, image_dir: str):
    sc = SCENES[name](image_dir)
    ps.match_engines(sc)
    return sc
