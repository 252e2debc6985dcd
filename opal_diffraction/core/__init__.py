"""The spectral tracer, importable without Blender: its rooms are the subpackages (docs/architecture.md; tests/system/test_layers.py holds what each may import)."""
