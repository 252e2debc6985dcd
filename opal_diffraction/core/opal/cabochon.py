"""The opal cabochon: an oval dome with a flat base, as a triangle mesh of even-sized triangles."""

from __future__ import annotations

import numpy as np

from ..util.geometry import triangle_cross

__all__ = [
    "cabochon",
]


def cabochon(size_x: float = 0.02, size_y: float = 0.015, height: float = 0.007, rings: int = 24,
             base: bool = True, profile: float = 1.0):
    """An oval dome (half ellipsoid) with a flat base, as (vertices (V, 3), triangles (T, 3)).

    ``size_x`` / ``size_y``: the base's diameters; ``height``: the dome's height (m); ``rings``:
    resolution (the dome has 1 + 3 rings (rings + 1) vertices and 6 rings^2 triangles of
    similar size: ring i has 6 i vertices). ``profile`` shapes the dome: 1 is a half ellipsoid,
    above 1 fuller shoulders, below 1 more pointed. The base (a fan to its centre, facing -Z)
    closes the solid. Triangles wind counter-clockwise seen from outside (normals point out).
    """
    rings = max(int(rings), 1)
    a, b, h = float(size_x) / 2, float(size_y) / 2, float(height)
    verts = [(0.0, 0.0, h)]
    starts = [0]
    for i in range(1, rings + 1):
        theta = 0.5 * np.pi * i / rings  # polar angle: even arc steps over the dome
        r = np.sin(theta)
        z = h * np.cos(theta) ** (1.0 / profile) if i < rings else 0.0
        n = 6 * i
        phi = 2 * np.pi * np.arange(n) / n
        starts.append(len(verts))
        verts.extend(zip(a * r * np.cos(phi), b * r * np.sin(phi), np.full(n, z)))
    tris = []
    for i in range(rings):  # strip between ring i (inner) and ring i + 1 (outer)
        n_in, n_out = max(6 * i, 1), 6 * (i + 1)
        s_in, s_out = starts[i], starts[i + 1]
        j_in = j_out = 0
        while j_in < n_in or j_out < n_out:
            # advance along whichever ring's next vertex comes first in angle
            a_in = (j_in + 1) / n_in if n_in > 1 else 2.0
            a_out = (j_out + 1) / n_out
            if i == 0 or (j_out < n_out and a_out <= a_in):
                tris.append((s_in + j_in % n_in, s_out + j_out % n_out, s_out + (j_out + 1) % n_out))
                j_out += 1
            else:
                tris.append((s_in + j_in % n_in, s_out + j_out % n_out, s_in + (j_in + 1) % n_in))
                j_in += 1
            if i == 0 and j_out >= n_out:
                break
    v = np.asarray(verts, np.float64)
    t = np.asarray(tris, np.int64)
    if base:
        centre = len(v)
        v = np.vstack([v, [[0.0, 0.0, 0.0]]])
        s, n = starts[rings], 6 * rings
        j = np.arange(n)
        t = np.vstack([t, np.stack([np.full(n, centre), s + (j + 1) % n, s + j], axis=1)])
    # outward winding: the dome's triangles face away from the axis / up, the base's down
    p = v[t]
    nrm = triangle_cross(v, t)
    out = p.mean(axis=1) - np.array([0.0, 0.0, h * 0.25])
    flip = np.sum(nrm * out, axis=1) < 0
    t[flip] = t[flip][:, [0, 2, 1]]
    return v, t.astype(np.int32)
