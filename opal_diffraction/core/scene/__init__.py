"""The scene: its model and builders (model.py), readable errors and the renderable limits
(checks.py), validation returning the clean scene and its products (validation.py), the .npz file
(npz.py), the render settings (settings.py), and simple meshes (primitives.py). Imports util/,
spectral/, accel/ and opal/ (the volume domains)."""
