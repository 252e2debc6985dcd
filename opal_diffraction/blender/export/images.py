"""Blender images -> linear Rec.709 float32 arrays, read once per export.

``Image.pixels`` hands back an image's own encoding: byte images (PNG, JPEG) as their stored
values / 255 in the image's colour space (sRGB-encoded for a colour photo), float images (EXR,
HDR) in Blender's scene-linear working space. The tracer wants linear Rec.709 (its RGB ->
spectrum upsampling is for Rec.709 primaries), so byte images are decoded by their colour space
(sRGB's piecewise curve, or nothing for linear and data spaces), float images converted from the
working space, and data images (Non-Color: roughness, normal maps) kept as they are. (A byte
image in a linear space other than Rec.709 is taken as Rec.709: a rare case, not converted.)
"""

from __future__ import annotations

import numpy as np

from .colour import working_space_to_rec709

__all__ = ["read_image", "srgb_to_linear", "is_data"]

#: Colour spaces whose byte values are linear already (decoded as they are).
_LINEAR_SPACES = {"Linear Rec.709", "Linear Rec.2020", "Linear CIE-XYZ D65", "Linear CIE-XYZ E",
                  "Linear DCI-P3 D65", "Linear FilmLight E-Gamut", "ACEScg", "ACES2065-1", "Working Space"}
_DATA_SPACES = {"Non-Color", "Raw", "Generic Data"}


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """The sRGB transfer function's inverse (IEC 61966-2-1), elementwise."""
    x = np.asarray(x, np.float32)
    return np.where(x <= 0.04045, x / np.float32(12.92), ((x + np.float32(0.055)) / np.float32(1.055)) ** np.float32(2.4))


def is_data(image) -> bool:
    """The image holds data (normals, roughness), not colour: no colour transform applies."""
    cs = image.colorspace_settings
    return bool(getattr(cs, "is_data", False)) or cs.name in _DATA_SPACES


def read_image(image, warn=None, owner: str = "") -> np.ndarray | None:
    """``image``'s pixels as (H, W, 4) float32, row 0 at the bottom (Blender's order), colour
    channels linear Rec.709 (data images untouched); None (with a warning) when the image has no
    pixels (a missing file, an empty image). ``warn(message)`` collects warnings."""
    w, h = (int(s) for s in image.size)
    channels = int(image.channels)
    if w * h == 0 or channels == 0:
        if warn is not None:
            warn(f"{owner + ': ' if owner else ''}image '{image.name}' has no pixels "
                 f"(missing file '{image.filepath}'?): it is left out")
        return None
    px = np.empty(w * h * channels, np.float32)
    image.pixels.foreach_get(px)
    px = px.reshape(h, w, channels)
    if channels < 4:  # grey (1), grey + alpha (2) or RGB (3) -> RGBA
        rgb = px[..., :1].repeat(3, axis=2) if channels <= 2 else px[..., :3]
        alpha = px[..., 1:2] if channels == 2 else np.ones((h, w, 1), np.float32)
        px = np.concatenate([rgb, alpha], axis=2)
    if is_data(image):
        return np.ascontiguousarray(px)
    rgb = px[..., :3]
    if image.is_float:  # scene linear (the working space) -> Rec.709
        to709 = working_space_to_rec709()
        if to709 is not None:
            rgb = (rgb.reshape(-1, 3) @ to709.T.astype(np.float32)).reshape(h, w, 3)
    else:
        name = image.colorspace_settings.name
        if name not in _LINEAR_SPACES:  # sRGB-encoded Rec.709 primaries
            if name != "sRGB" and warn is not None:
                warn(f"{owner + ': ' if owner else ''}image '{image.name}' is in colour space '{name}': "
                     "decoded as sRGB")
            rgb = srgb_to_linear(rgb)
    px[..., :3] = rgb
    return np.ascontiguousarray(px, np.float32)
