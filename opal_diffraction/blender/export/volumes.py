"""Volume shaders -> the core's homogeneous medium columns (``volume_*`` of a material row; the
world's volume; docs/physics.md section 15.1).

Read from what feeds a Volume socket, as Cycles' SVM evaluates the closures
(intern/cycles/kernel/svm/closure.h): Volume Scatter (sigma_s = sigma_t = Density x Color,
Henyey-Greenstein of its Anisotropy), Volume Absorption (sigma_a = Density x (1 - Color)),
Principled Volume (sigma_s = Density x Color, sigma_a = Density x max(1 - Color, 0) x
max(1 - sqrt(Absorption Color), 0), emission Emission Strength x Emission Color), Emission
(radiance per metre Strength x Color), summed through Add Shader and weighted through Mix Shader.
The coefficients are RGB sums; each becomes a density times a colour in [0, 1] (its largest
channel the density), which the core uplifts per wavelength. Inputs driven by other nodes take
their average or the socket's value (NodeReader's rules, with its warnings); what has no
homogeneous equivalent here (a density attribute's grid, blackbody emission, phase functions
other than Henyey-Greenstein) is named in a warning.
"""

from __future__ import annotations

import numpy as np

__all__ = ["read_volume"]


class _Sum:
    """The closures' coefficients summed over the tree (linear Rec.709 RGB, 1/m)."""

    def __init__(self):
        self.sigma_s = np.zeros(3)
        self.sigma_a = np.zeros(3)
        self.emission = np.zeros(3)
        self.g_weighted = 0.0  # sum of g x (the scattering's mean coefficient), for the mean g
        self.g_values = set()

    def columns(self) -> dict | None:
        if not ((self.sigma_s > 0).any() or (self.sigma_a > 0).any() or (self.emission > 0).any()):
            return None
        ds, da = float(self.sigma_s.max()), float(self.sigma_a.max())
        mean_s = float(self.sigma_s.mean())
        return {
            "volume_scatter_density": ds,
            "volume_scatter_color": tuple(float(c) for c in (self.sigma_s / ds if ds > 0 else np.ones(3))),
            "volume_absorption_density": da,
            "volume_absorption_color": tuple(float(c) for c in (self.sigma_a / da if da > 0 else np.ones(3))),
            "volume_anisotropy": float(np.clip(self.g_weighted / mean_s, -1.0, 1.0)) if mean_s > 0 else 0.0,
            "volume_emission": tuple(float(c) for c in self.emission),
        }


def read_volume(reader, socket) -> dict | None:
    """The medium columns of what feeds the Volume ``socket`` through ``reader`` (a
    nodes.NodeReader: its owner names the warnings), or None when nothing there absorbs,
    scatters or emits."""
    acc = _Sum()
    _walk(reader, socket, 1.0, acc, 0)
    if len(acc.g_values) > 1:
        reader.warn(f"{reader.owner}: its volume mixes scatterings of different anisotropy "
                    f"{sorted(acc.g_values)}: rendered with one Henyey-Greenstein of their weighted mean")
    return acc.columns()


def _walk(reader, socket, weight: float, acc: _Sum, depth: int) -> None:
    src = reader.source(socket)
    if src is None or weight <= 0 or depth > 64:
        return
    node, _ = src
    kind = node.bl_idname
    if kind == "ShaderNodeAddShader":
        for sock in node.inputs[:2]:
            _walk(reader, sock, weight, acc, depth + 1)
    elif kind == "ShaderNodeMixShader":
        fac = min(max(reader.value(node, "Fac", 0.5), 0.0), 1.0)
        _walk(reader, node.inputs[1], weight * (1.0 - fac), acc, depth + 1)
        _walk(reader, node.inputs[2], weight * fac, acc, depth + 1)
    elif kind == "ShaderNodeVolumeScatter":
        phase = getattr(node, "phase", "HENYEY_GREENSTEIN")
        if phase != "HENYEY_GREENSTEIN":
            reader.warn(f"{reader.owner}: the {phase.replace('_', '-').title()} phase function of '{node.name}' is "
                        "rendered as Henyey-Greenstein")
        d = max(reader.value(node, "Density", 1.0), 0.0)
        col = np.maximum(reader.color(node, "Color", (0.8, 0.8, 0.8)), 0.0)
        _scatter(acc, weight * d * col, reader.value(node, "Anisotropy", 0.0))
    elif kind == "ShaderNodeVolumeAbsorption":
        d = max(reader.value(node, "Density", 1.0), 0.0)
        col = reader.color(node, "Color", (0.8, 0.8, 0.8))
        acc.sigma_a += weight * d * np.maximum(1.0 - col, 0.0)
    elif kind == "ShaderNodeVolumePrincipled":
        d = max(reader.value(node, "Density", 1.0), 0.0)
        col = np.maximum(reader.color(node, "Color", (0.5, 0.5, 0.5)), 0.0)
        absorb = np.maximum(np.sqrt(np.maximum(reader.color(node, "Absorption Color", (0, 0, 0)), 0.0)), 0.0)
        _scatter(acc, weight * d * col, reader.value(node, "Anisotropy", 0.0))
        acc.sigma_a += weight * d * np.maximum(1.0 - col, 0.0) * np.maximum(1.0 - absorb, 0.0)
        strength = max(reader.value(node, "Emission Strength", 0.0), 0.0)
        if strength > 0:
            acc.emission += weight * strength * np.maximum(reader.color(node, "Emission Color", (1, 1, 1)), 0.0)
        if reader.value(node, "Blackbody Intensity", 0.0) > 0:
            reader.warn(f"{reader.owner}: the blackbody emission of '{node.name}' is not rendered (a temperature "
                        "grid's emission; the volume's other emission is)")
    elif kind == "ShaderNodeEmission":
        strength = max(reader.value(node, "Strength", 1.0), 0.0)
        acc.emission += weight * strength * np.maximum(reader.color(node, "Color", (1, 1, 1)), 0.0)
    else:
        reader.warn(f"{reader.owner}: '{node.name}' on a Volume input is not a volume shader the renderer "
                    "reads (Volume Scatter, Volume Absorption, Principled Volume, Emission, Add / Mix Shader): "
                    "left out of the volume")


def _scatter(acc: _Sum, sigma_s: np.ndarray, g: float) -> None:
    g = float(np.clip(g, -1.0, 1.0))
    acc.sigma_s += sigma_s
    acc.g_weighted += g * float(sigma_s.mean())
    if sigma_s.max() > 0:
        acc.g_values.add(round(g, 4))
