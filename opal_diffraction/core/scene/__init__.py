"""The scene model (flat NumPy arrays), its builders, validation and .npz file, the render settings, and simple meshes. Imports util/, spectral/, accel/ and opal/ (the volume domains)."""
