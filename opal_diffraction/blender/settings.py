"""``scene.opal`` to the core's RenderSettings: the one place the Blender settings are read.

Both the final render (engine.py) and the rendered viewport (viewport.py) use it, so neither
imports the other for it.
"""

from __future__ import annotations

from ..core.scene.settings import RenderSettings

__all__ = ["render_settings", "adaptive_threshold"]


def adaptive_threshold(opal) -> float:
    """The core's adaptive threshold from ``scene.opal``: 0 (off) unless Noise Threshold is
    checked; a threshold of 0 with the box checked is Cycles' automatic one,
    max(0.001, 1 / samples) (intern/cycles/scene/integrator.cpp)."""
    if not opal.use_adaptive_sampling:
        return 0.0
    t = float(opal.adaptive_threshold)
    return t if t > 0 else max(0.001, 1.0 / max(int(opal.samples), 1))


def render_settings(opal, scene, spectral_path: str = "") -> RenderSettings:
    """Core RenderSettings from ``scene.opal`` (names copied one to one) and Blender's threads."""
    seed = int(opal.seed) + (int(scene.frame_current) if opal.use_animated_seed else 0)
    return RenderSettings(
        samples=int(opal.samples), light_paths=None if opal.light_paths_auto else int(opal.light_paths), wavelength_min=float(opal.wavelength_min),
        wavelength_max=float(opal.wavelength_max), wavelength_step=float(opal.wavelength_step),
        max_bounces=int(opal.max_bounces), diffuse_bounces=int(opal.diffuse_bounces),
        glossy_bounces=int(opal.glossy_bounces), transmission_bounces=int(opal.transmission_bounces), seed=max(seed, 0), dispersion_sampling=opal.dispersion_sampling,
        spectral_exr=spectral_path, time_limit=float(opal.time_limit), threads=int(scene.render.threads),
        backend=opal.backend.lower(), tile_size=int(opal.tile_size), round_samples=int(opal.round_samples),
        filter_width=float(opal.filter_width), adaptive_threshold=adaptive_threshold(opal),
        adaptive_min_samples=int(opal.adaptive_min_samples), grating_footprint=bool(opal.grating_footprint),
        blue_noise=bool(opal.blue_noise),
        caustic_splat=bool(opal.caustic_splat),
        film_transparent=bool(getattr(scene.render, "film_transparent", False)),
        # Cycles' own Transparent Glass setting (scene.cycles exists where the Cycles add-on is on)
        film_transparent_glass=bool(getattr(getattr(scene, "cycles", None), "film_transparent_glass", False)),
    )
