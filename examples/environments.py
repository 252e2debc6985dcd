"""Procedural equirectangular environment maps for the examples (no image files to ship).

Each function returns an (H, W, 3) float32 linear Rec.709 radiance map in Cycles'
equirectangular convention (row 0 at the bottom; core/lights/environment.py), for ``Scene.world_image``
with ``Scene.world_color`` as its multiplier, or for an Environment Texture in Blender.
"""

from __future__ import annotations

import numpy as np

from opal_diffraction.core.lights.environment import uv_to_direction

__all__ = ["texel_directions", "sky", "studio", "blender_world"]


def texel_directions(width: int, height: int) -> np.ndarray:
    """(H, W, 3) unit directions of the texel centres, row 0 at the bottom."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    uu, vv = np.meshgrid(u, v)
    return uv_to_direction(uu, vv)


def _disk(d: np.ndarray, towards: np.ndarray, half_angle_deg: float) -> np.ndarray:
    """1 inside the cone of ``half_angle_deg`` about the unit direction ``towards``, else 0."""
    return (d @ towards >= np.cos(np.radians(half_angle_deg))).astype(np.float32)


def _direction(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    e, a = np.radians(elevation_deg), np.radians(azimuth_deg)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def sky(width: int = 512, height: int = 256, sun_elevation: float = 35.0, sun_azimuth: float = -60.0,
        sun_radiance: float = 2.0e4, sun_half_angle: float = 1.5) -> np.ndarray:
    """A clear daytime sky: blue overhead fading to a pale horizon, a brown-grey ground below, and
    a small bright sun (radiance ``sun_radiance`` in a disk of ``sun_half_angle`` degrees; with
    the defaults its irradiance is about 43 W/m^2 facing it, the sky's about 1.5)."""
    d = texel_directions(width, height)
    z = d[..., 2:3]
    zenith, horizon, ground = np.array([0.18, 0.32, 0.75]), np.array([0.75, 0.82, 0.95]), np.array([0.12, 0.10, 0.08])
    t = np.clip(z, 0, 1) ** 0.5
    up = horizon * (1 - t) + zenith * t
    rgb = np.where(z >= 0, up, ground * (1 - 0.5 * np.clip(-z, 0, 1)))
    rgb = rgb + sun_radiance * _disk(d, _direction(sun_elevation, sun_azimuth), sun_half_angle)[..., None] * \
        np.array([1.0, 0.95, 0.88])
    return rgb.astype(np.float32)


def studio(width: int = 512, height: int = 256) -> np.ndarray:
    """A dark photo studio: a black room lit by four soft boxes (a key to the front left, a small
    one to the right, a large dim top light, a small bright one behind) - bright patches a gem
    breaks into sparks of fire."""
    d = texel_directions(width, height)
    rgb = np.full(d.shape, 0.01, np.float64)
    for elevation, azimuth, half_angle, radiance in ((35.0, -130.0, 12.0, 40.0), (20.0, -20.0, 5.0, 120.0),
                                                     (70.0, 100.0, 20.0, 12.0), (10.0, 60.0, 3.0, 200.0)):
        rgb += radiance * _disk(d, _direction(elevation, azimuth), half_angle)[..., None]
    return rgb.astype(np.float32)


def blender_world(bpy, rgb: np.ndarray, strength: float, name: str = "World"):
    """A Blender world whose Background shows ``rgb`` (an (H, W, 3) map of this module) through
    an Environment Texture node, at ``strength``: the image is a packed float image, so the
    .blend needs no file beside it. Returns the world (assign it to ``scene.world``)."""
    image = bpy.data.images.new(name + " map", rgb.shape[1], rgb.shape[0], float_buffer=True)
    rgba = np.concatenate([rgb, np.ones(rgb.shape[:2] + (1,), np.float32)], axis=2)
    image.pixels.foreach_set(rgba.astype(np.float32).ravel())
    image.pack()
    world = bpy.data.worlds.new(name)
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    nt = world.node_tree
    bg = nt.nodes.get("Background")
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = image
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = float(strength)
    world.color = tuple(float(c) for c in rgb.reshape(-1, 3).mean(axis=0) * strength)
    return world
