"""Thin films on the materials: the Fresnel reflectance of a filmed glass, mirror or metal at its hits.

Method: Airy's thin-film sum of core/spectral/thin_film.py (docs/physics.md section 2.8) with the
material table's film (``PreparedMaterials.film``, ``film_thickness``, ``film_ior``) at the rays'
wavelengths. A glass's film sits on its outer face: from the air the incident medium is 1 and the
substrate the glass's index, from inside the glass is the incident medium and the air the
substrate (the film's phase uses the absolute indices). A mirror or metal is a conductor whose
complex index comes from its colour (F0) and edge tint (F82: the F82-tint metal's, a constant
metal's own colour) by Gulbrandsen's mapping, as Cycles does under a film.

The walker and the BSDFs call these only for rows whose material has a film; ``rows`` says which.
"""

from __future__ import annotations

import numpy as np

from ..spectral.thin_film import conductor_ior_from_f0_f82, thin_film_conductor, thin_film_dielectric

__all__ = ["film_rows", "glass_fresnel", "conductor_reflectance"]


def film_rows(materials, mat) -> np.ndarray | None:
    """(B,) bool: the hits whose material has a thin film, or None when none has (the common case)."""
    film = getattr(materials, "film", None)
    if film is None or not film.any():
        return None
    rows = film[mat]
    return rows if rows.any() else None


def _per_hit(col, mat, like):
    v = col[mat]
    return v[:, None] if np.ndim(like) == 2 else v


def glass_fresnel(materials, wavelengths_nm, mat, front, cos, n, lam=None) -> np.ndarray:
    """(F) of the filmed glass ``mat`` (B,) hit on its ``front`` (B,) (from the air) or back, at
    the incident cosine ``cos`` (B,) and the glass's index ``n`` (B,) at the rays' wavelengths
    ``lam`` (B,) grid indices, or ``n`` (B, k) over the whole grid with ``lam`` None. F = 1 under
    total internal reflection; float32 out."""
    wl = np.asarray(wavelengths_nm, np.float64)
    n = np.asarray(n, np.float64)
    two_d = n.ndim == 2
    w = wl[None, :] if two_d else wl[np.asarray(lam)]
    fr = front[:, None] if two_d else front
    c = np.asarray(cos, np.float64)
    c = c[:, None] if two_d and c.ndim == 1 else c
    eta = np.where(fr, n, 1.0 / n)  # n_t / n_i
    n_i = np.where(fr, 1.0, n)
    f, _ = thin_film_dielectric(np.abs(c), eta, _per_hit(materials.film_ior, mat, n), _per_hit(materials.film_thickness, mat, n),
                                w, n_i)
    return np.asarray(f, np.float32)


def conductor_reflectance(materials, wavelengths_nm, mat, cos, lam=None) -> np.ndarray:
    """The reflectance of the filmed mirror / metal ``mat`` (B,) at cosine ``cos`` (B,): (B, n) over
    the grid with ``lam`` None, else (B,) at the rays' wavelengths; float32. F0 is the table's
    colour (a smooth mirror's colour texture is its average there too), the edge its F82
    reflectance (F82-tint metals) or F0."""
    from .bsdf import f82_b, fresnel_f82

    wl = np.asarray(wavelengths_nm, np.float64)
    # the complex index per material row (a handful), then gathered per hit
    rows, inv = np.unique(np.asarray(mat), return_inverse=True)
    base = materials.reflectance[rows].astype(np.float64)
    edge = base
    f82 = getattr(materials, "conductor_f82", None)
    if f82 is not None and materials.specular_tint is not None and f82[rows].any():
        b = f82_b(base, np.minimum(materials.specular_tint[rows].astype(np.float64), 1.0))
        edge = np.where(f82[rows][:, None], fresnel_f82(np.full(len(rows), 1.0 / 7.0), base, b), base)
    n, k = conductor_ior_from_f0_f82(base, edge)
    if lam is not None:
        lam = np.asarray(lam)
        n, k, w = n[inv, lam], k[inv, lam], wl[lam]
        c = np.asarray(cos, np.float64)
        d, nf = materials.film_thickness[mat], materials.film_ior[mat]
    else:
        n, k, w = n[inv], k[inv], wl[None, :]
        c = np.asarray(cos, np.float64)[:, None]
        d, nf = materials.film_thickness[mat][:, None], materials.film_ior[mat][:, None]
    return np.asarray(thin_film_conductor(np.abs(c), n, k, nf, d, w), np.float32)
