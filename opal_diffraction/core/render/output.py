"""Image output: float RGB EXR, spectral EXR (JCGT 2021 layout) and an 8-bit PNG preview.

The spectral layout is Fichet, Pacanowski & Wilkie (2021), "An OpenEXR Layout for Spectral
Images", JCGT 10(3): one channel per wavelength named ``S0.<nm with a comma>nm`` (emissive
Stokes component 0), the header attributes ``spectralLayoutVersion`` and ``emissiveUnits``, plus
R, G, B for ordinary viewers. Channels are passed contiguous: OpenEXR 3.5's binding silently
writes wrong pixels from strided views (checked with openexr 3.5.3: docs/physics.md section 10.3).
Every file is written to a temporary name in the same folder and renamed, so an interrupted
write never leaves a truncated image behind.
"""

from __future__ import annotations

import os
import signal
import tempfile

import numpy as np

__all__ = ["write_rgb_exr", "write_spectral_exr", "write_png", "read_exr", "spectral_channel_name"]


def spectral_channel_name(wavelength_nm: float) -> str:
    return "S0." + f"{wavelength_nm:.6f}".replace(".", ",") + "nm"


#: Prefix of the temporary files images are written to before the rename.
TMP_PREFIX = ".tmp_"


def _atomic_write(path, write):
    """``write(tmp)`` to a temporary file beside ``path``, then rename it to ``path``.

    The temporary file is removed on every way out (an exception, KeyboardInterrupt, or any
    exception a signal handler raises, e.g. the command line's SIGTERM handler) from the moment
    it exists; its removal cannot itself be interrupted by SIGINT / SIGTERM.
    """
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=TMP_PREFIX, suffix=os.path.splitext(path)[1], dir=folder)
        os.close(fd)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; an image should get the usual permissions
        write(tmp)
        os.replace(tmp, path)
        tmp = None
    finally:
        if tmp is not None:
            _remove_quietly(tmp)


def _remove_quietly(tmp: str) -> None:
    """Remove ``tmp`` with SIGINT and SIGTERM held back (they are delivered right after)."""
    held = {signal.SIGINT, signal.SIGTERM}
    try:
        old = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    except (AttributeError, OSError, ValueError):  # no pthread_sigmask (Windows)
        old = None
    try:
        if os.path.lexists(tmp):
            os.unlink(tmp)
    except OSError:
        pass
    finally:
        if old is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _exr(path, channels: dict, extra_header: dict | None = None):
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    header.update(extra_header or {})
    chans = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in channels.items()}
    _atomic_write(path, lambda tmp: OpenEXR.File(header, chans).write(tmp))


def write_rgb_exr(path, rgb: np.ndarray, alpha: np.ndarray | None = None) -> None:
    """(H, W, 3) linear RGB, row 0 at the top, as float32 R, G, B channels; with ``alpha``
    (H, W) an A channel too (premultiplied RGB, as a transparent film renders it)."""
    rgb = np.asarray(rgb, np.float32)
    chans = {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2]}
    if alpha is not None:
        chans["A"] = np.ascontiguousarray(alpha, np.float32)
    _exr(path, chans)


def write_spectral_exr(path, spectral: np.ndarray | None, wavelengths_nm: np.ndarray, rgb: np.ndarray) -> None:
    """(H, W, n) spectral radiance plus its RGB, in the JCGT 2021 spectral layout.

    ``spectral`` None (a RenderResult whose render kept no spectral film, core/render/film.py): a
    SceneError saying how to keep it, before anything is written. A film's spectral image is a
    view of (n, H, W) planes, so its channels are passed without a copy (another layout is
    copied one channel at a time into the contiguous arrays OpenEXR needs)."""
    if spectral is None:
        from .film import NO_SPECTRAL
        from ..scene.checks import SceneError

        raise SceneError(f"cannot write the spectral EXR {os.fspath(path)}: {NO_SPECTRAL}")
    spectral = np.asarray(spectral)
    if spectral.ndim != 3 or spectral.shape[-1] != len(wavelengths_nm):
        raise ValueError(f"spectral image of shape {spectral.shape} does not match {len(wavelengths_nm)} wavelengths")
    chans = {spectral_channel_name(wl): spectral[..., i] for i, wl in enumerate(wavelengths_nm)}
    chans.update({"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2]})
    _exr(path, chans, {"spectralLayoutVersion": "1.0", "emissiveUnits": "W.m^-2.sr^-1"})


def read_exr(path) -> dict[str, np.ndarray]:
    """All channels of an EXR file by name (for tests and tools)."""
    import OpenEXR

    with OpenEXR.File(os.fspath(path), separate_channels=True) as f:
        return {name: np.array(ch.pixels) for name, ch in f.channels().items()}


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer function (IEC 61966-2-1) on values clipped to [0, 1]."""
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


#: values (rows x width x 3) encoded at once by write_png (bounds its float64 temporaries)
PNG_CHUNK_VALUES = 1 << 20


def write_png(path, rgb: np.ndarray, exposure: float = 0.0) -> None:
    """An 8-bit sRGB preview of linear RGB (clipped; ``exposure`` in stops)."""
    from PIL import Image

    rgb = np.asarray(rgb)
    img = np.empty(rgb.shape, np.uint8)
    # in bands of rows: the float64 temporaries of a whole full-HD image were 240 MB (same bytes)
    rows = max(1, PNG_CHUNK_VALUES // max(1, rgb[:1].size))
    for y in range(0, rgb.shape[0], rows):
        band = np.asarray(rgb[y:y + rows], np.float64) * 2.0**exposure
        img[y:y + rows] = (srgb_encode(band) * 255 + 0.5).astype(np.uint8)
    _atomic_write(path, lambda tmp: Image.fromarray(img, "RGB").save(tmp, format="PNG"))
