"""The Blender world -> the core's uniform background colour (linear Rec.709, Cycles' units).

The colour of a Background or Emission shader times its strength (a texture on it is averaged),
or the world's viewport colour when it has no node tree; the core renders no environment map.
A NaN colour or strength is an error naming the world, a huge one is clamped with a warning.
"""

from __future__ import annotations

import numpy as np

from ...core.scene import SceneError
from .colour import in_rec709, rgb, working_space_to_rec709
from .messages import Warnings
from .nodes import MAX_INTENSITY, NodeReader, missing_output, node_tree, surface_socket

__all__ = ["world_color", "export_world"]


def world_color(world, warn, to709) -> np.ndarray:
    """The background colour (3,) of ``world`` (None: black), unclipped."""
    if world is None:
        return np.zeros(3)
    owner = f"world '{world.name}'"
    nt = node_tree(world)
    if nt is None:
        return _viewport_color(world, owner, to709)
    reader = NodeReader(owner, warn, to709)
    sock = surface_socket(nt)
    if sock is None:
        warn(f"{owner}: {missing_output(nt, 'World Output')}: the background is black, as in Cycles")
        return np.zeros(3)
    src = reader.source(sock)
    if reader.cycle is not None:
        warn(f"{owner}: its node tree has a cycle (through the link {reader.cycle}): using the world colour")
        return _viewport_color(world, owner, to709)
    if src is None:
        return np.zeros(3)
    node = src[0]
    if node.bl_idname in ("ShaderNodeBackground", "ShaderNodeEmission"):
        return reader.emission(reader.color(node, "Color", (0.05, 0.05, 0.05)), reader.strength(node), node)
    warn(f"{owner}: world shader '{node.name}' is not supported: using the world colour as a uniform background")
    return _viewport_color(world, owner, to709)


def _viewport_color(world, owner: str, to709) -> np.ndarray:
    col = in_rec709(rgb(world.color), to709)
    if np.isnan(col).any():
        raise SceneError(f"{owner}: its colour is NaN")
    return np.minimum(col, MAX_INTENSITY)


def export_world(depsgraph, warn: Warnings | None = None) -> np.ndarray:
    """The core's ``Scene.world_color`` alone, (3,) float32, as :func:`export_scene` makes it.
    ``warn``: collects the warnings (default: dropped)."""
    world = world_color(depsgraph.scene.world, warn if warn is not None else Warnings(), working_space_to_rec709())
    return np.clip(world, 0.0, None).astype(np.float32)
