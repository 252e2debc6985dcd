"""Blender images -> float32 RGBA arrays as Cycles reads them, once per image per export.

Cycles' Blender image loader (``intern/cycles/blender/image.cpp``, ``scene/image.cpp``) decides
how an image's pixels become shader values, and this module follows it (docs/physics.md
section 13.2):

- ``Image.pixels`` hands back an image's own encoding: byte images (PNG, JPEG) as their stored
  values / 255, float images (EXR, HDR) as Blender's scene-linear float buffer (working space,
  alpha premultiplied).
- Byte images in an sRGB colour space stay sRGB-encoded (Cycles' ``compress_as_srgb``) and are
  decoded after interpolation (``TextureEncoding.SRGB``; :func:`read_image` decodes them at once
  for callers that want linear texels); byte images in a linear space are taken as linear
  Rec.709 (a rare case with other primaries is not converted); other display spaces are
  decoded as sRGB with a warning.
- Data images (Non-Color: roughness, normal maps) keep their values, alpha untouched.
- Float images are converted from the working space to Rec.709 (Cycles renders in the working
  space; the core in Rec.709); channels as Cycles fills them (1: grey, 2 or 3: the missing
  channels 0 and alpha 1).
- Alpha: byte colour images are premultiplied in their 8-bit values, ``(c a) // 255``, as
  Cycles associates straight alpha (not for data images, nor for the alpha modes Channel Packed
  and None); alpha mode None sets alpha to 1. The colour is then what Cycles' Color output gives.
- An image without pixels (a missing file) renders magenta (1, 0, 1), as in Cycles, with a
  warning naming the image (and the material).

:class:`TextureTable` reads each image once per export (a dict by image name) and numbers the
(image, interpolation, extension) combinations the materials use: ``Scene.textures``.
"""

from __future__ import annotations

import numpy as np

from ...core.util.enums import TextureEncoding
from ...core.materials.textures import srgb_to_linear as _decode
from .colour import working_space_to_rec709

__all__ = ["read_image", "read_texture", "image_mean", "srgb_to_linear", "is_data", "MISSING_RGB", "TextureTable"]

#: Colour spaces whose byte values are linear already (decoded as they are).
_LINEAR_SPACES = {"Linear Rec.709", "Linear Rec.2020", "Linear CIE-XYZ D65", "Linear CIE-XYZ E",
                  "Linear DCI-P3 D65", "Linear FilmLight E-Gamut", "ACEScg", "ACES2065-1", "Working Space"}
_DATA_SPACES = {"Non-Color", "Raw", "Generic Data"}
_SRGB_SPACES = {"sRGB", "sRGB 2.1"}
#: Cycles' colour for an image it cannot load (TEX_IMAGE_MISSING_R/G/B).
MISSING_RGB = (1.0, 0.0, 1.0)


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """The sRGB transfer function's inverse (IEC 61966-2-1), elementwise, as Cycles applies it."""
    return _decode(x)


def is_data(image) -> bool:
    """The image holds data (normals, roughness), not colour: no colour transform applies."""
    cs = image.colorspace_settings
    return bool(getattr(cs, "is_data", False)) or cs.name in _DATA_SPACES


def _no_pixels(image, warn, owner: str) -> None:
    if warn is not None:
        path = getattr(image, "filepath", "")
        warn(f"{owner + ': ' if owner else ''}image '{image.name}' has no pixels"
             f"{f' (missing file {path!r}?)' if path else ''}: rendered magenta, as Cycles renders a missing image")


def read_texture(image, warn=None, owner: str = "") -> tuple[np.ndarray, int] | None:
    """``image``'s pixels as Cycles samples them: ((H, W, 4) float32, row 0 at the bottom,
    TextureEncoding code). Colour channels are linear Rec.709, or sRGB-encoded Rec.709 values
    (code SRGB) to decode after interpolation; data images untouched; alpha premultiplied as
    Cycles does (module docstring). None (with a warning naming the image and ``owner``) when
    the image has no pixels (a missing file, an empty image)."""
    try:
        w, h = (int(s) for s in image.size)
        channels = int(image.channels)
        n = len(image.pixels) if w * h else 0
    except Exception:  # an image Blender cannot load (unreadable file, unsupported format)
        w = h = channels = n = 0
    if w * h == 0 or channels == 0 or n != w * h * channels:
        _no_pixels(image, warn, owner)
        return None
    px = np.empty(n, np.float32)
    image.pixels.foreach_get(px)
    px = px.reshape(h, w, channels)
    is_float = bool(image.is_float)
    alpha_mode = getattr(image, "alpha_mode", "STRAIGHT")
    if channels < 4:
        if channels == 1 or not is_float:  # grey (1), grey + alpha (2), RGB (3) of a byte image
            rgb = px[..., :1].repeat(3, axis=2) if channels <= 2 else px[..., :3]
            alpha = px[..., 1:2] if channels == 2 else np.ones((h, w, 1), np.float32)
        else:  # float 2 or 3 channels: Cycles fills the missing channels with 0 and alpha 1
            rgb = np.concatenate([px, np.zeros((h, w, 3 - channels), np.float32)], axis=2)
            alpha = np.ones((h, w, 1), np.float32)
        px = np.concatenate([rgb, alpha], axis=2)
    px = np.ascontiguousarray(px, np.float32)
    if alpha_mode == "NONE":
        px[..., 3] = 1.0
    data = is_data(image)
    if data:
        return px, int(TextureEncoding.LINEAR)
    if is_float:  # scene linear (the working space) -> Rec.709; alpha is premultiplied already
        to709 = working_space_to_rec709()
        if to709 is not None:
            px[..., :3] = (px[..., :3].reshape(-1, 3) @ to709.T.astype(np.float32)).reshape(h, w, 3)
        return px, int(TextureEncoding.LINEAR)
    if alpha_mode not in ("CHANNEL_PACKED", "NONE"):
        # Cycles premultiplies straight 8-bit alpha in the stored values: (c * a) // 255
        c8 = np.rint(px * 255.0).astype(np.int32)
        px[..., :3] = ((c8[..., :3] * c8[..., 3:4]) // 255).astype(np.float32) / np.float32(255)
    name = image.colorspace_settings.name
    if name in _LINEAR_SPACES:
        return px, int(TextureEncoding.LINEAR)
    if name not in _SRGB_SPACES and warn is not None:
        warn(f"{owner + ': ' if owner else ''}image '{image.name}' is in colour space '{name}': decoded as sRGB")
    return px, int(TextureEncoding.SRGB)


def read_image(image, warn=None, owner: str = "") -> np.ndarray | None:
    """``image``'s pixels as (H, W, 4) float32, row 0 at the bottom (Blender's order), colour
    channels linear Rec.709 texel by texel (data images untouched; alpha as :func:`read_texture`);
    None (with a warning) when the image has no pixels. ``warn(message)`` collects warnings."""
    got = read_texture(image, warn, owner)
    if got is None:
        return None
    px, encoding = got
    if encoding == int(TextureEncoding.SRGB):
        px[..., :3] = srgb_to_linear(px[..., :3])
    return px


def image_mean(image) -> np.ndarray | None:
    """Average linear Rec.709 RGB of an image's pixels as Cycles reads them (:func:`read_image`:
    sRGB decoded, alpha premultiplied), or None for an image without pixels (no warning: the
    caller names what it falls back to)."""
    try:
        px = read_image(image)
    except Exception:  # unreadable: the caller falls back
        return None
    return None if px is None else px[..., :3].reshape(-1, 3).mean(axis=0, dtype=np.float64)


#: Blender's Image Texture node settings -> the core's names.
INTERPOLATIONS = {"Closest": "CLOSEST", "Linear": "LINEAR", "Cubic": "CUBIC", "Smart": "SMART"}


class TextureTable:
    """The textures of one export: each Blender image read once (by name), each (image,
    interpolation, extension) used numbered once, in first-use order (``Scene.textures``)."""

    def __init__(self, warn):
        self.warn = warn
        self._images: dict[str, tuple[np.ndarray, int] | None] = {}
        self._index: dict[tuple, int] = {}
        self.pixels: list[np.ndarray] = []
        self.interpolation: list[str] = []
        self.extension: list[str] = []
        self.encoding: list[int] = []
        self._means: list[np.ndarray] = []

    def __len__(self) -> int:
        return len(self.pixels)

    def read(self, image, owner: str) -> tuple[np.ndarray, int] | None:
        """The image's (pixels, encoding), read on first use; None for an image without pixels
        (warned, naming ``owner``, once per image and owner)."""
        key = image.name_full
        if key not in self._images:
            self._images[key] = read_texture(image, self.warn, owner)
        elif self._images[key] is None:
            _no_pixels(image, self.warn, owner)
        return self._images[key]

    def index(self, image, interpolation: str, extension: str, owner: str) -> int | None:
        """The texture number of ``image`` with these node settings (Blender's identifiers:
        'Linear', 'REPEAT', ...), or None when the image has no pixels."""
        got = self.read(image, owner)
        if got is None:
            return None
        interp = INTERPOLATIONS.get(interpolation, "LINEAR")
        ext = extension if extension in ("REPEAT", "EXTEND", "CLIP", "MIRROR") else "REPEAT"
        key = (image.name_full, interp, ext)
        if key not in self._index:
            px, encoding = got
            self._index[key] = len(self.pixels)
            self.pixels.append(px)  # the same array for every setting of one image
            self.interpolation.append(interp)
            self.extension.append(ext)
            self.encoding.append(encoding)
            lin = srgb_to_linear(px[..., :3]) if encoding == int(TextureEncoding.SRGB) else px[..., :3]
            self._means.append(np.concatenate([lin.reshape(-1, 3).mean(axis=0, dtype=np.float64),
                                               [px[..., 3].mean(dtype=np.float64)]]))
        return self._index[key]

    def mean_rgba(self, index: int) -> np.ndarray:
        """(4,) float64 average linear Rec.709 colour (each texel decoded) and alpha of texture
        ``index``."""
        return self._means[index]

    def mean_rgb(self, index: int) -> np.ndarray:
        """(3,) float64 average linear Rec.709 colour of texture ``index`` (each texel decoded)."""
        return self._means[index][:3]

    def scene_fields(self) -> dict:
        """The Scene fields: textures and their per-texture codes."""
        from ...core.scene.model import TEXTURE_EXTENSIONS, TEXTURE_INTERPOLATIONS

        return {
            "textures": list(self.pixels),
            "texture_interpolation": np.array([TEXTURE_INTERPOLATIONS[x] for x in self.interpolation], np.int32),
            "texture_extension": np.array([TEXTURE_EXTENSIONS[x] for x in self.extension], np.int32),
            "texture_encoding": np.array(self.encoding, np.int32),
        }
