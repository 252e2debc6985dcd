"""Denoising the finished image with Intel Open Image Denoise, through the optional ``pyoidn`` wheel.

OpenImageDenoise's "RT" filter (Áfra, Intel Open Image Denoise, https://www.openimagedenoise.org/;
the denoiser Cycles and Blender's compositor Denoise node run) with the auxiliary feature images
Cycles gives it (intern/cycles/integrator/denoiser_oidn.cpp): the colour as HDR linear RGB, the
Denoising Albedo and the Denoising Normal passes (film.py), at "high" quality. The feature images
are noisy too (antialiased edges, glass): they go in with ``clean_aux`` off, so OIDN does not
trust them as noise-free (Cycles' "Fast" prefilter; its default "Accurate" first denoises each
feature image on its own, which pyoidn's one-call API does not offer). The denoised image replaces Combined; the
noisy one is kept as the "Noisy Image" pass (Cycles' name), and the spectral film is untouched:
the denoiser works on RGB only. Negative RGB values (colours outside the Rec.709 gamut) are
clipped to 0 for the denoiser, which takes non-negative HDR input.

``pyoidn`` is optional (requirements-denoise.txt): ``available()`` says whether it imports, and
``denoise_rgb`` raises DenoiserUnavailable, a SceneError with the install line, when it does not
(docs/physics.md section 10.6).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..scene.checks import SceneError

__all__ = ["DenoiserUnavailable", "available", "denoise_rgb", "denoise_result", "NOISY_PASS", "INSTALL_HINT"]

NOISY_PASS = "Noisy Image"
INSTALL_HINT = "pip install -r requirements-denoise.txt (the pyoidn wheel of Intel Open Image Denoise)"


class DenoiserUnavailable(SceneError):
    """pyoidn (Open Image Denoise) cannot be imported."""


def _pyoidn():
    try:
        import pyoidn
    except (ImportError, OSError) as e:  # OSError: the wheel's shared library failed to load
        raise DenoiserUnavailable(f"denoising needs Open Image Denoise's Python binding pyoidn, which cannot be "
                                  f"imported ({type(e).__name__}: {e}): {INSTALL_HINT}") from None
    return pyoidn


def available() -> bool:
    """Whether pyoidn imports here."""
    try:
        _pyoidn()
    except DenoiserUnavailable:
        return False
    return True


def denoise_rgb(rgb: np.ndarray, albedo: np.ndarray | None = None, normal: np.ndarray | None = None) -> np.ndarray:
    """(H, W, 3) linear HDR RGB denoised by OIDN's RT filter, guided by the albedo and normal
    feature images when given (a normal needs the albedo too: OIDN's rule)."""
    oidn = _pyoidn()
    color = np.ascontiguousarray(np.maximum(np.nan_to_num(rgb, nan=0.0, posinf=0.0), 0.0), np.float32)
    if normal is not None and albedo is None:
        raise ValueError("OIDN takes a normal image only together with an albedo image")
    aux = {}
    if albedo is not None:
        aux["albedo"] = np.ascontiguousarray(np.clip(albedo, 0.0, 1.0), np.float32)
    if normal is not None:
        aux["normal"] = np.ascontiguousarray(np.clip(normal, -1.0, 1.0), np.float32)
    try:
        return oidn.denoise(color, hdr=True, quality="high", **aux)
    except RuntimeError as e:
        raise SceneError(f"Open Image Denoise failed: {e}") from None


def denoise_result(result):
    """A film.RenderResult with its RGB denoised (guided by its Denoising Albedo and Normal
    passes) and the noisy RGB as the "Noisy Image" pass; the spectral film is unchanged."""
    if result.rgb.size == 0 or result.samples == 0:
        return result
    albedo = result.passes.get("Denoising Albedo")
    normal = result.passes.get("Denoising Normal") if albedo is not None else None
    clean = denoise_rgb(result.rgb, albedo, normal)
    return replace(result, rgb=clean, passes={**result.passes, NOISY_PASS: result.rgb})
