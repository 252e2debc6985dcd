"""An independent thin-film reference for the tests: the characteristic (transfer) matrix of a
stack of layers (Born & Wolf, *Principles of Optics*, section 1.6; Macleod, *Thin-Film Optical
Filters*, ch. 2), in scalar complex arithmetic, written apart from core/spectral/thin_film.py's
Airy sum (tests/spectral/test_thin_film.py, tests/system/test_thin_film_render.py)."""

import cmath
import math

__all__ = ["matrix_rt", "matrix_unpolarised"]


def matrix_rt(n0, layers, n_sub, theta0, wl, pol):
    """(R, T) of a stack by characteristic matrices, one wavelength and polarisation, scalar complex
    arithmetic in Macleod's convention (an absorbing index is n - ik: ``n_sub`` n + ik is
    conjugated): M_j = [[cos d_j, i sin d_j / y_j], [i y_j sin d_j, cos d_j]], d_j = 2 pi n_j d_j cos t_j / wl,
    tilted admittances y = n cos t (s) or n / cos t (p); [B, C] = prod M_j [1, y_sub];
    r = (y0 B - C) / (y0 B + C), T = 4 Re(y0) Re(y_sub) / |y0 B + C|^2."""
    s = n0 * math.sin(theta0)

    def cos_t(n):
        c = cmath.sqrt(1 - (s / n) ** 2)
        # the root for a wave going on (decaying) into the medium: Im(n cos t) <= 0 in this convention
        if (n * c).imag > 0 or ((n * c).imag == 0 and (n * c).real < 0):
            c = -c
        return c

    def adm(n):
        c = cos_t(n)
        return n * c if pol == "s" else n / c

    n_sub = complex(n_sub).conjugate()
    b, cc = 1.0 + 0j, adm(n_sub)
    for n, d in reversed(layers):
        delta = 2 * math.pi * n * d * cos_t(n) / wl
        y = adm(n)
        b, cc = (cmath.cos(delta) * b + 1j * cmath.sin(delta) / y * cc,
                 1j * y * cmath.sin(delta) * b + cmath.cos(delta) * cc)
    y0 = adm(n0)
    r = (y0 * b - cc) / (y0 * b + cc)
    t_power = 4 * y0.real * adm(n_sub).real / abs(y0 * b + cc) ** 2
    return abs(r) ** 2, t_power


def matrix_unpolarised(n0, n_film, d, n_sub, theta0, wl):
    rs, ts = matrix_rt(n0, [(n_film, d)], n_sub, theta0, wl, "s")
    rp, tp = matrix_rt(n0, [(n_film, d)], n_sub, theta0, wl, "p")
    return 0.5 * (rs + rp), 0.5 * (ts + tp)
