"""opal_diffraction: a Blender extension that renders dispersion and diffraction.

The spectral tracer lives in :mod:`opal_diffraction.core` (NumPy, no bpy) and runs without
Blender (``python -m opal_diffraction render scene.npz -o out.exr``). Blender is imported only
when the add-on is registered, so the core stays importable anywhere.
"""

__all__ = ["register", "unregister"]


def register():
    from .blender import register as _register  # noqa: PLC0415 - bpy only inside Blender

    _register()


def unregister():
    from .blender import unregister as _unregister  # noqa: PLC0415

    _unregister()
