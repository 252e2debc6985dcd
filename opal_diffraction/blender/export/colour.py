"""Colours: the blend file's linear working space <-> the core's linear Rec.709, and blackbody
colours (an image's average colour is ``images.image_mean``).

Blender 5.0 gives each file a working space (``bpy.data.colorspace.working_space``: Linear
Rec.709, Linear Rec.2020 or ACEScg); the core works in linear Rec.709. The 3x3 conversions come
from colour-science's ``matrix_RGB_to_RGB`` with Bradford chromatic adaptation; None stands for
the identity (a Rec.709 file). A blackbody colour is the core's own spectrum -> RGB conversion
of Planck's law at luminance 1, Blender's Blackbody node convention.
"""

from __future__ import annotations

import bpy
import numpy as np

__all__ = [
    "working_space_to_rec709",
    "rec709_to_working_space",
    "rgb",
    "in_rec709",
    "blackbody_rgb",
    "BLACKBODY_MIN_K",
]

_COLOUR_SPACE_NAMES = {
    "Linear Rec.2020": "ITU-R BT.2020",
    "ACEScg": "ACEScg",
}


def _working_space() -> str:
    cs = getattr(bpy.data, "colorspace", None)  # Blender 5.0+: a per-file working space
    return getattr(cs, "working_space", "Linear Rec.709") if cs is not None else "Linear Rec.709"


def _matrix_to_rec709(space: str) -> np.ndarray | None:
    name = _COLOUR_SPACE_NAMES.get(space)
    if name is None:
        return None
    from ...core.spectral.spectrum import _colour

    colour = _colour()
    return np.asarray(colour.matrix_RGB_to_RGB(colour.RGB_COLOURSPACES[name], colour.RGB_COLOURSPACES["sRGB"],
                                               chromatic_adaptation_transform="Bradford"), np.float64)


def working_space_to_rec709() -> np.ndarray | None:
    """3x3 matrix from the blend file's linear working space to linear Rec.709 (None: identity)."""
    return _matrix_to_rec709(_working_space())


def rec709_to_working_space() -> np.ndarray | None:
    """3x3 matrix from linear Rec.709 to the blend file's working space (None: identity)."""
    m = _matrix_to_rec709(_working_space())
    return None if m is None else np.linalg.inv(m)


def rgb(v) -> np.ndarray:
    """The first three components of a Blender colour, as float64."""
    return np.array(tuple(v)[:3], np.float64)


def in_rec709(col: np.ndarray, to709: np.ndarray | None) -> np.ndarray:
    """A working-space colour in linear Rec.709 (``to709`` from :func:`working_space_to_rec709`)."""
    return col if to709 is None else to709 @ col


#: Temperatures below this (K) take its colour, as Cycles' Blackbody node clamps low temperatures
#: (and Planck's law at a few kelvin underflows to 0/0 over the visible range).
BLACKBODY_MIN_K = 800.0


def blackbody_rgb(temperature: float) -> np.ndarray:
    """Linear Rec.709 colour of a blackbody with luminance 1 (Blender's Blackbody node convention);
    below ``BLACKBODY_MIN_K`` that temperature's colour, NaN, infinite or not positive: 6500 K."""
    from ...core.spectral.spectrum import SpectralConverter

    conv = blackbody_rgb.conv = getattr(blackbody_rgb, "conv", None) or SpectralConverter()
    t = float(temperature)
    t = max(t, BLACKBODY_MIN_K) if 0.0 < t < float("inf") else 6500.0
    return conv.to_rgb(conv.blackbody(t)).astype(np.float64)
