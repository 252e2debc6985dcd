"""Wavelengths and colour (the grid, spectrum <-> XYZ <-> RGB) and geometric optics at a smooth interface (Fresnel, refraction, dispersion). Imports only util/."""
