"""Surfaces on the wavelength grid: material spectra, BSDFs (GGX, Lambert), surface parameters and image textures, the opal's Bragg lobe. Imports util/, spectral/, scene/, opal/."""
