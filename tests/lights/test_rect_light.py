"""core/lights/rect_light.py: rectangle lights sampled by solid angle (Urena et al. 2013; docs/physics.md
section 7.10). The solid angle against Van Oosterom & Strackee's formula for the rectangle's two
triangles (an independent closed form), the sampled directions against a uniform density over
the spherical rectangle (chi-square, Mitsuba's chi2.py scheme) and every sample on the
rectangle. (tests/lights/test_lights_sized.py checks the light's sampler against ``light_pdf`` and its
irradiance against Lambert's polygon formula.)"""

from __future__ import annotations

import numpy as np
import pytest
from chi2 import chi2_directions

from opal_diffraction.core.lights import rect_light


def _triangle_solid_angle(o, a, b, c):
    """Van Oosterom & Strackee 1983: tan(omega / 2) = |a.(b x c)| / (abc + (a.b)c + (a.c)b + (b.c)a)."""
    a, b, c = a - o, b - o, c - o
    la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
    num = np.abs(np.einsum("ij,ij->i", a, np.cross(b, c)))
    den = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", a, c) * lb \
        + np.einsum("ij,ij->i", b, c) * la
    return 2 * np.arctan2(num, den)


RECT = dict(c=(0.3, -0.2, 1.0), ex=(np.cos(0.4), np.sin(0.4), 0.0), ey=(-np.sin(0.4) * 0.8, np.cos(0.4) * 0.8, 0.6),
            lx=1.3, ly=0.5)


def _rect():
    ex = np.asarray(RECT["ex"]) / np.linalg.norm(RECT["ex"])
    ey = np.asarray(RECT["ey"]) - (np.asarray(RECT["ey"]) @ ex) * ex
    return rect_light.RectFrame(RECT["c"], ex, ey / np.linalg.norm(ey), RECT["lx"], RECT["ly"])


def test_solid_angle_is_van_oosterom_strackees():
    r = _rect()
    rng = np.random.default_rng(1)
    o = rng.uniform(-3, 3, (2000, 3))
    p00 = r.corner
    p10, p01 = p00 + r.lx * r.ex, p00 + r.ly * r.ey
    p11 = p10 + r.ly * r.ey
    b = len(o)
    rep = lambda x: np.broadcast_to(x, (b, 3))  # noqa: E731
    want = _triangle_solid_angle(o, rep(p00), rep(p10), rep(p11)) + _triangle_solid_angle(o, rep(p00), rep(p11),
                                                                                          rep(p01))
    np.testing.assert_allclose(rect_light.solid_angle(r, o), want, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("o", [(0.1, 0.0, 0.2), (2.5, -1.0, 1.3), (0.0, 0.4, 3.5)])
def test_samples_are_uniform_over_the_spherical_rectangle(o):
    r = _rect()
    n = 400_000
    rng = np.random.default_rng(7)
    oo = np.broadcast_to(np.asarray(o, np.float64), (n, 3))
    pts, s = rect_light.sample(r, oo, rng.random(n), rng.random(n))
    q = pts - r.corner  # on the rectangle
    assert np.abs(q @ r.ez).max() < 1e-9
    assert (q @ r.ex).min() >= -1e-9 and (q @ r.ex).max() <= r.lx + 1e-9
    assert (q @ r.ey).min() >= -1e-9 and (q @ r.ey).max() <= r.ly + 1e-9
    d = pts - oo
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    omega = float(s[0])

    def pdf(w):  # 1 / S inside the rectangle's cone, 0 outside (a ray-plane test)
        den = w @ r.ez
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((r.corner - np.asarray(o)) @ r.ez) / den
        hit = np.asarray(o) + t[:, None] * w - r.corner
        a, b = hit @ r.ex, hit @ r.ey
        inside = (t > 0) & (a >= 0) & (a <= r.lx) & (b >= 0) & (b <= r.ly)
        return np.where(inside, 1.0 / omega, 0.0)

    axis = r.corner + 0.5 * r.lx * r.ex + 0.5 * r.ly * r.ey - np.asarray(o)
    cos_max = (d @ (axis / np.linalg.norm(axis))).min()
    theta_max = min(np.pi, np.arccos(cos_max) * 1.05 + 1e-3)
    # a fine sub-grid: cells the spherical rectangle's edge only grazes still get their share
    pval, info, total = chi2_directions(d, pdf, axis, theta_max=theta_max, sub=64)
    assert abs(total - 1) < 0.01, total
    assert pval > 0.01 / 3, info
