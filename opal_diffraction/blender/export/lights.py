"""Blender lights -> the core's light table, in Cycles' units.

Point, spot and area lights keep their power in watts, the sun its strength in W/m^2; exposure
multiplies by 2^exposure, an unnormalised area light emits per m^2 (times its area here), and
the emission node of a light's node tree scales the strength and tints the colour. A white
light with "Temperature" on is a blackbody spectrum (``temperature`` > 0), a tinted one an RGB
product. A point or spot light's radius (``shadow_soft_size``) and "Soft Falloff" and a sun's
angle are kept (soft shadows, lights seen in mirrors: docs/physics.md section 7.5); with
*Normalize* off the power is multiplied by the light's area as Cycles' scene/light.cpp does
(a sphere's 4 pi r^2, 4 for a point; a sun's pi sin^2(angle / 2), 1 without an angle; an area
light's area). What the core cannot render is named in the warnings: square and non-uniformly
scaled spot cones, area spread below 180 degrees.
A NaN power, colour, temperature or size is an error naming the light; a negative power is 0 and
one beyond ``MAX_INTENSITY`` (Blender accepts up to FLT_MAX) is clamped, with a warning.
"""

from __future__ import annotations

import math

import numpy as np

from ...core.scene.model import Lights
from ...core.scene.checks import SceneError
from .colour import BLACKBODY_MIN_K, blackbody_rgb, in_rec709, rgb, working_space_to_rec709
from .messages import Warnings
from .nodes import MAX_INTENSITY, NodeReader, missing_output, surface_socket

__all__ = ["light_color", "light_row", "LightRows", "export_lights"]


def light_color(light, warn, to709, owner: str | None = None) -> tuple[np.ndarray, float, float]:
    """(Rec.709 colour, temperature K or 0, strength factor from the light's nodes). ``owner``
    names the light in messages (default: its data's name). A NaN colour or temperature is an
    error; a colour above ``MAX_INTENSITY`` is clamped with a warning."""
    owner = owner or f"light '{light.name}'"
    col = in_rec709(rgb(light.color), to709)
    if np.isnan(col).any():
        raise SceneError(f"{owner}: its colour is NaN")
    temperature = 0.0
    if getattr(light, "use_temperature", False):
        if np.allclose(col, 1.0, atol=1e-4):
            temperature = float(light.temperature)
            if not 0.0 < temperature < float("inf"):
                raise SceneError(f"{owner}: its temperature must be a positive number of kelvin "
                                 f"(got {temperature:g})")
            temperature = max(temperature, BLACKBODY_MIN_K)
        else:  # tinted blackbody: an RGB product (the spectrum is approximated)
            col = col * in_rec709(rgb(light.temperature_color), to709)
    strength = 1.0
    nt = light.node_tree if getattr(light, "use_nodes", False) else None
    if nt is not None:
        reader = NodeReader(owner, warn, to709)
        sock = surface_socket(nt)
        src = reader.source(sock) if sock else None
        if reader.cycle is not None:
            warn(f"{owner}: its node tree has a cycle (through the link {reader.cycle}): using the light's colour")
            return _finite(col, owner, warn), temperature, strength
        if src is None:
            why = missing_output(nt, "Light Output") if sock is None else "nothing is connected to its Surface"
            warn(f"{owner}: {why}: the light is off, as in Cycles")
            return _finite(col, owner, warn), temperature, 0.0
        node = src[0]
        if node.bl_idname != "ShaderNodeEmission":
            warn(f"{owner}: light node '{node.name}' is not supported: using the light's colour")
            return _finite(col, owner, warn), temperature, strength
        strength = reader.strength(node, "Strength", 1.0)
        csrc = reader.source(node.inputs["Color"])
        if csrc is not None and csrc[0].bl_idname == "ShaderNodeBlackbody":
            t_node = max(reader.temperature(csrc[0]), BLACKBODY_MIN_K)
            if temperature == 0.0 and np.allclose(col, 1.0, atol=1e-4):
                temperature = t_node
            else:
                col = col * blackbody_rgb(t_node)
        else:
            col = col * reader.color(node, "Color", (1, 1, 1))
    return _finite(col, owner, warn), temperature, strength


def _finite(col: np.ndarray, owner: str, warn) -> np.ndarray:
    if (col > MAX_INTENSITY).any():
        warn(f"{owner}: its colour ({col.max():.3g}) is above {MAX_INTENSITY:.0e}: clamped")
        col = np.minimum(col, MAX_INTENSITY)
    return col


def _power(ob, light, strength: float, col: np.ndarray, warn) -> float:
    """The light's power in the core's units (W, or W/m^2 for a sun): energy x 2^exposure x node
    strength. NaN is an error; a negative power is 0 and one whose product with the colour is
    above ``MAX_INTENSITY`` is lowered to it, each with a warning naming the light."""
    energy = float(light.energy)
    exposure = float(getattr(light, "exposure", 0.0))
    if energy != energy or exposure != exposure:
        raise SceneError(f"light '{ob.name}': its {'power' if energy != energy else 'exposure'} is NaN")
    if energy == 0.0 or strength == 0.0:
        return 0.0
    power = energy * 2.0 ** min(exposure, 1024.0) * strength
    if power < 0.0:
        warn(f"light '{ob.name}': negative power ({power:g}) is rendered as 0 (the light is off)")
        return 0.0
    peak = power * max(float(col.max()), 1.0)
    if not peak <= MAX_INTENSITY:
        warn(f"light '{ob.name}': its power ({power:.3g}) is above {MAX_INTENSITY:.0e}: clamped")
        power = MAX_INTENSITY / max(float(col.max()), 1.0)
    return power


def _finite_size(ob, what: str, value: float) -> float:
    value = float(value)
    if not np.isfinite(value):
        raise SceneError(f"light '{ob.name}': its {what} is NaN or infinite")
    return value


def light_row(ob, m: np.ndarray, warn, to709) -> dict | None:
    """The core's row for light object ``ob`` with world matrix ``m``, or None when it is skipped."""
    light = ob.data
    x, y, z = m[:3, 0], m[:3, 1], m[:3, 2]
    nz = np.linalg.norm(z)
    if not np.isfinite(m).all() or nz < 1e-12:
        raise SceneError(f"light '{ob.name}': its transform is NaN, infinite or has zero scale")
    col, temperature, strength = light_color(light, warn, to709, f"light '{ob.name}'")
    col = np.clip(col, 0.0, None)
    power = _power(ob, light, strength, col, warn)
    row = {
        "position": tuple(m[:3, 3]), "direction": tuple(-z / nz), "axis_u": tuple(x / max(np.linalg.norm(x), 1e-30)),
        "color": tuple(float(c) for c in col), "power": power, "temperature": temperature,
    }
    t = light.type
    normalize = bool(getattr(light, "normalize", True))
    if t in ("POINT", "SPOT"):
        radius = max(_finite_size(ob, "radius", getattr(light, "shadow_soft_size", 0.0)), 0.0)
        row["radius"] = radius
        row["soft_falloff"] = int(bool(getattr(light, "use_soft_falloff", True)))
        if not normalize:  # Cycles: eval_fac = 1 / pi instead of 1 / (pi * area), area 4 pi r^2 (4 at r = 0)
            row["power"] = min(row["power"] * (4 * math.pi * radius**2 if radius > 0 else 4.0), MAX_INTENSITY)
        row["kind"] = t
        if t == "SPOT":
            row["spot_size"] = _finite_size(ob, "spot size", light.spot_size)
            row["spot_blend"] = _finite_size(ob, "spot blend", light.spot_blend)
            if getattr(light, "use_square", False):
                warn(f"light '{ob.name}': square spot cones are rendered round")
            sx, sy = np.linalg.norm(x), np.linalg.norm(y)
            if abs(sx - sy) > 1e-3 * max(sx, sy):
                warn(f"light '{ob.name}': a non-uniformly scaled spot cone is rendered round")
    elif t == "SUN":
        row["kind"] = "SUN"
        row["camera_visible"] = int(bool(getattr(ob, "visible_camera", False)))  # Cycles shows the disc then
        angle = min(max(_finite_size(ob, "angle", getattr(light, "angle", 0.0)), 0.0), math.pi)
        row["angle"] = angle
        if not normalize and angle > 0:  # Cycles: the sun's area pi sin^2(angle / 2)
            row["power"] = row["power"] * math.pi * math.sin(0.5 * angle) ** 2
    elif t == "AREA":
        shape = light.shape
        su = _finite_size(ob, "size", light.size) * float(np.linalg.norm(x))
        sv = _finite_size(ob, "size", light.size_y if shape in ("RECTANGLE", "ELLIPSE") else light.size) * float(
            np.linalg.norm(y))
        row["kind"] = "AREA_RECT" if shape in ("SQUARE", "RECTANGLE") else "AREA_DISK"
        row["size_u"], row["size_v"] = su, sv
        if su <= 0 or sv <= 0:
            warn(f"light '{ob.name}': area light of zero size skipped")
            return None
        if not normalize:  # Cycles: an unnormalised light emits power per m^2
            area = su * sv * (1.0 if row["kind"] == "AREA_RECT" else math.pi / 4)
            row["power"] = min(row["power"] * area, MAX_INTENSITY)
        if getattr(light, "spread", math.pi) < math.pi - 1e-4:
            warn(f"light '{ob.name}': area light spread below 180 degrees is rendered as a full 180")
    else:
        warn(f"light '{ob.name}': light type {t} is not supported: skipped")
        return None
    return row


class LightRows:
    """The light rows of one export, in instance order."""

    def __init__(self, warn: Warnings, to709: np.ndarray | None):
        self.rows: list[dict] = []
        self.warn, self.to709 = warn, to709

    def add(self, ob, matrix_world) -> None:
        """Add a light object instance with its world matrix (skipped when it cannot render)."""
        row = light_row(ob, np.array(matrix_world, np.float64), self.warn, self.to709)
        if row is not None:
            self.rows.append(row)


def export_lights(depsgraph, warn: Warnings | None = None) -> Lights:
    """The core's light table alone, as :func:`export_scene` makes it. ``warn``: collects the
    warnings (default: dropped)."""
    lights = LightRows(warn if warn is not None else Warnings(), working_space_to_rec709())
    for inst in depsgraph.object_instances:
        if inst.object.type == "LIGHT":
            lights.add(inst.object, inst.matrix_world)
    return Lights.from_list(lights.rows)
