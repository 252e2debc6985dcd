"""The eye pass: the spectral path tracer over tiles, reading the light pass's caustics and records."""
