"""Bragg diffraction by the silica-sphere lattice of precious opal, and its equivalent grating period.

The colour of precious opal is first-order Bragg diffraction by the FCC (111) planes of its
close-packed silica spheres (Sanders, "Colour of precious opal", Nature 204, 1964,
doi:10.1038/2041151a0):

    d111 = sqrt(2/3) D_s,   lambda_B(theta) = 2 d111 sqrt(n_eff^2 - sin^2 theta),
    n_eff^2 = 0.74 n_s^2 + 0.26 n_void^2

The renderer's gratings are surface gratings, so a domain's period is the *equivalent* grating
period :func:`period_from_sphere_diameter`: the Bragg wavelength at normal incidence.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "N_SILICA",
    "N_VOID",
    "SPHERE_DIAMETER_RANGE",
    "effective_index",
    "d111_spacing",
    "bragg_wavelength",
    "period_from_sphere_diameter",
]

#: Refractive index of the silica spheres and of the voids (air) between them
#: (docs/physics.md section 5.3).
N_SILICA = 1.45
N_VOID = 1.0
#: Diameters of the silica spheres of precious opal, nm (docs/physics.md section 5.2).
SPHERE_DIAMETER_RANGE = (150.0, 350.0)
#: Volume fraction of the spheres in an FCC packing (0.74) and of the voids (0.26).
_FILL = 0.74


def effective_index(n_sphere: float = N_SILICA, n_void: float = N_VOID) -> float:
    """n_eff = sqrt(0.74 n_s^2 + 0.26 n_void^2): 1.3475 for silica in air."""
    return float(np.sqrt(_FILL * n_sphere**2 + (1.0 - _FILL) * n_void**2))


def d111_spacing(sphere_diameter):
    """Spacing of the FCC (111) planes, d111 = sqrt(2/3) D_s (same unit as D_s)."""
    return np.sqrt(2.0 / 3.0) * np.asarray(sphere_diameter, np.float64)


def bragg_wavelength(sphere_diameter, theta=0.0, n_sphere: float = N_SILICA, n_void: float = N_VOID):
    """First-order Bragg wavelength lambda = 2 d111 sqrt(n_eff^2 - sin^2 theta) (nm for D_s in nm).

    ``theta``: angle of incidence in air (radians) on the (111) planes.
    """
    n2 = effective_index(n_sphere, n_void) ** 2
    return 2.0 * d111_spacing(sphere_diameter) * np.sqrt(n2 - np.sin(np.asarray(theta, np.float64)) ** 2)


def period_from_sphere_diameter(sphere_diameter, n_sphere: float = N_SILICA, n_void: float = N_VOID):
    """The equivalent surface-grating period (nm): the Bragg wavelength at normal incidence.

    The first diffraction order of this grating has the Bragg colour where |u| = 1; smaller |u|
    (closer to the mirror direction) shifts it to the red, larger to the blue.
    """
    return bragg_wavelength(sphere_diameter, 0.0, n_sphere, n_void)
