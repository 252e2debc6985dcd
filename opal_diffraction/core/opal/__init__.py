"""The opal model: a cabochon mesh and grating domains over a surface, as NumPy on mesh arrays.

Sources. The source paper's model (Kobayashi & Kawai; docs/physics.md section 5.1) puts one
diffraction grating on every triangle of the opal mesh, all oriented consistently. Real precious opal shows patches
("domains") of differently oriented and spaced silica-sphere lattices, the "harlequin" look; a
domain model gives it: Voronoi cells over the surface, each with its own grating direction and
period. The periods come from the silica sphere diameter through the Bragg law of the FCC
(111) planes (Sanders, "Colour of precious opal", Nature 204, 1964, doi:10.1038/2041151a0):

    d111 = sqrt(2/3) D_s,   lambda_B(theta) = 2 d111 sqrt(n_eff^2 - sin^2 theta),
    n_eff^2 = 0.74 n_s^2 + 0.26 n_void^2

(silica n_s = 1.45, air voids: n_eff = 1.3475; D_s = 250 nm gives 550 nm at normal incidence
and 468 nm at 45 degrees). The renderer's gratings are surface gratings, so a domain's period
is the *equivalent* grating period ``period_from_sphere_diameter``: the Bragg wavelength at
normal incidence, which the grating's first order sends where |u| = |(w_o + w_i) . t| = 1
(light and viewer about 30 degrees either side of the normal, across the slits). Spheres of
150-350 nm give periods of 330-770 nm: colour from violet to red, one order at a time.
(That relation is the LINES grating's; a HEXAGONAL lattice's first orders sit at
|q| = 2 lambda / (sqrt 3 D): a known deviation, docs/physics.md section 5.5.)

Everything here is a pure function on arrays (no bpy), so the Blender operators are thin
wrappers and the tests call the logic directly. A surface is given as vertices (V, 3) and
triangles (T, 3), with an optional ``tri_face`` (T,) mapping triangles to polygons (Blender's
loop triangles); per-face data is then per polygon. Per-face grating data is a
:class:`DomainField`: ``domain`` (F,) int32, ``direction`` (F, 3) float32 unit vectors in each
face's plane (object space), ``period`` (F,) float32 nm. A grating's direction is an axis
(t and -t diffract alike), which the preview colours respect.

    bragg      the Bragg law of the silica-sphere lattice, the equivalent grating period
    cabochon   the cabochon mesh
    surface    face geometry, tangent bases, projection and transport of tangents
    domains    DomainField, Voronoi domains with their directions and periods
    editing    assigning, rotating, jittering, splitting and merging on selected faces
    preview    the preview colours (surface gratings, and the Bragg colour of volume domains)
    volume     volume domains: additively weighted 3-D Voronoi cells with (111) normals
               (imported as ``core.opal.volume``)
"""

from __future__ import annotations

from .bragg import (
    N_SILICA,
    N_VOID,
    SPHERE_DIAMETER_RANGE,
    bragg_wavelength,
    d111_spacing,
    effective_index,
    period_from_sphere_diameter,
)
from .cabochon import cabochon
from .domains import (
    DomainField,
    aligned_directions,
    domain_directions,
    domain_periods,
    generate_domains,
    nearest_seed,
    sample_surface_points,
    voronoi_domains,
)
from .editing import (
    assign_grating,
    direction_angle,
    direction_from_angle,
    direction_from_vector,
    jitter_period,
    merge_domains,
    rotate_directions,
    set_period,
    split_domains,
)
from .preview import bragg_band_width, bragg_colors, preview_colors
from .surface import FaceGeometry, face_geometry, project_to_planes, tangent_basis, transport_tangents

__all__ = [
    "N_SILICA",
    "N_VOID",
    "SPHERE_DIAMETER_RANGE",
    "effective_index",
    "d111_spacing",
    "bragg_wavelength",
    "period_from_sphere_diameter",
    "cabochon",
    "FaceGeometry",
    "face_geometry",
    "DomainField",
    "sample_surface_points",
    "nearest_seed",
    "voronoi_domains",
    "tangent_basis",
    "project_to_planes",
    "transport_tangents",
    "domain_directions",
    "aligned_directions",
    "domain_periods",
    "generate_domains",
    "direction_from_vector",
    "direction_from_angle",
    "direction_angle",
    "rotate_directions",
    "assign_grating",
    "set_period",
    "jitter_period",
    "split_domains",
    "merge_domains",
    "preview_colors",
    "bragg_band_width",
    "bragg_colors",
]
