"""Triangle meshes of simple shapes for examples, tests and benchmarks (outward normals).

Each function returns (vertices (V, 3) float64, triangles (T, 3) int32) with counter-clockwise
winding seen from outside, so the geometric normal points out of closed solids, which the
dielectric code relies on to tell entering from leaving.
"""

from __future__ import annotations

import numpy as np

from ..util.geometry import triangle_cross

__all__ = ["quad", "box", "prism", "uv_sphere", "icosphere", "round_brilliant"]


def quad(center, u, v):
    """A parallelogram center +- u/2 +- v/2, normal along u x v."""
    c, u, v = (np.asarray(a, np.float64) for a in (center, u, v))
    verts = np.array([c - u / 2 - v / 2, c + u / 2 - v / 2, c + u / 2 + v / 2, c - u / 2 + v / 2])
    return verts, np.array([[0, 1, 2], [0, 2, 3]], np.int32)


def box(center, size):
    """An axis-aligned box."""
    c = np.asarray(center, np.float64)
    s = np.broadcast_to(np.asarray(size, np.float64), (3,)) / 2
    corners = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], np.float64) * s + c
    # faces as quads (outward, counter-clockwise): -z, +z, -y, +y, -x, +x
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    tris = [[a, b, c_] for a, b, c_, d in faces] + [[a, c_, d] for a, b, c_, d in faces]
    return corners, np.array(tris, np.int32)


def prism(center, side, length, apex_angle_deg=60.0, axis="Y", rotation_deg=0.0):
    """A triangular prism: an isosceles triangle (two sides of length ``side`` meeting at
    ``apex_angle_deg``) extruded ``length`` along ``axis`` ('X' or 'Y'), apex up (+Z), centroid at
    ``center``, optionally rotated about the extrusion axis by ``rotation_deg``."""
    half = np.radians(apex_angle_deg) / 2
    h = side * np.cos(half)
    b = side * np.sin(half)
    # triangle in the (a, z) plane, centroid at 0: base corners and apex
    tri2 = np.array([[-b, -h / 3], [b, -h / 3], [0.0, 2 * h / 3]])
    r = np.radians(rotation_deg)
    rot = np.array([[np.cos(r), -np.sin(r)], [np.sin(r), np.cos(r)]])
    tri2 = tri2 @ rot.T
    verts = []
    for s in (-length / 2, length / 2):
        for a, z in tri2:
            verts.append([a, s, z] if axis == "Y" else [s, -a, z])
    verts = np.array(verts) + np.asarray(center, np.float64)
    tris = np.array([
        [0, 2, 1], [3, 4, 5],            # end caps
        [0, 1, 4], [0, 4, 3],            # base
        [1, 2, 5], [1, 5, 4],            # right face
        [2, 0, 3], [2, 3, 5],            # left face
    ], np.int32)
    # make the winding outward whatever the axis/rotation: flip triangles whose normal points inward
    p = verts[tris]
    nrm = triangle_cross(verts, tris)
    outward = np.sum(nrm * (p.mean(axis=1) - verts.mean(axis=0)), axis=1) > 0
    tris[~outward] = tris[~outward][:, [0, 2, 1]]
    return verts, tris


def uv_sphere(center, radius, segments=32, rings=16):
    """A UV sphere (poles on Z)."""
    th = np.linspace(0, np.pi, rings + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    t, p = np.meshgrid(th, ph, indexing="ij")
    ring = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    verts = np.concatenate([[[0, 0, 1]], ring, [[0, 0, -1]]]) * radius + np.asarray(center, np.float64)
    tris = []
    s = segments
    j = np.arange(s)
    tris.append(np.stack([np.zeros(s, int), 1 + j, 1 + (j + 1) % s], 1))
    for i in range(rings - 2):
        a, b = 1 + i * s + j, 1 + i * s + (j + 1) % s
        c, d = a + s, b + s
        tris.append(np.stack([a, c, d], 1))
        tris.append(np.stack([a, d, b], 1))
    last = len(verts) - 1
    base = 1 + (rings - 2) * s
    tris.append(np.stack([np.full(s, last), base + (j + 1) % s, base + j], 1))
    return verts, np.concatenate(tris).astype(np.int32)


def icosphere(center, radius, subdivisions=3):
    """An icosphere: 20 * 4**subdivisions triangles, nearly uniform."""
    g = (1 + 5**0.5) / 2
    v = np.array([[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0], [0, -1, g], [0, 1, g], [0, -1, -g], [0, 1, -g],
                  [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]], np.float64)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
                  [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
                  [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]], np.int64)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    for _ in range(subdivisions):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(edges, axis=0, return_inverse=True)
        mid = v[uniq[:, 0]] + v[uniq[:, 1]]
        mid /= np.linalg.norm(mid, axis=1, keepdims=True)
        m = inv.reshape(3, -1) + len(v)
        a, b, c = f[:, 0], f[:, 1], f[:, 2]
        ab, bc, ca = m[0], m[1], m[2]
        f = np.concatenate([np.stack([a, ab, ca], 1), np.stack([b, bc, ab], 1),
                            np.stack([c, ca, bc], 1), np.stack([ab, bc, ca], 1)])
        v = np.concatenate([v, mid])
    return v * radius + np.asarray(center, np.float64), f.astype(np.int32)


def round_brilliant(center, diameter, table=0.57, crown_deg=34.5, pavilion_deg=40.75, girdle=0.02):
    """A round brilliant gem (58-facet style, simplified to 8-fold symmetry), table up (+Z), its
    girdle centred at ``center``: Tolkowsky's proportions by default (table 57 % of the
    diameter, crown angle 34.5 deg, pavilion angle 40.75 deg, girdle 2 %). The crown joins an
    octagonal table to a 16-sided girdle with star and bezel triangles; the pavilion runs from
    the girdle's 16 corners through 8 main facets to a pointed culet. Flat facets: no shading
    normals wanted."""
    c = np.asarray(center, np.float64)
    r = 0.5 * float(diameter)
    rt = table * r
    hc = (r - rt) * np.tan(np.radians(crown_deg))      # crown height above the girdle's top
    hp = r * np.tan(np.radians(pavilion_deg))          # pavilion depth below the girdle's bottom
    hg = 0.5 * girdle * float(diameter)                # half the girdle's thickness
    a8 = np.arange(8) * (2 * np.pi / 8)
    a16 = np.arange(16) * (2 * np.pi / 16)
    ring = lambda rad, ang, z: np.stack([rad * np.cos(ang), rad * np.sin(ang), np.full(len(ang), z)], 1)  # noqa: E731
    verts = np.concatenate([
        ring(rt, a8, hg + hc),            # 0..7 table corners
        ring(r, a16, hg),                 # 8..23 girdle top
        ring(r, a16, -hg),                # 24..39 girdle bottom
        [[0.0, 0.0, hg + hc]],            # 40 table centre
        [[0.0, 0.0, -hg - hp]],           # 41 culet
    ]) + c
    t8, g_top, g_bot, tc, cul = 0, 8, 24, 40, 41
    tris = []
    for i in range(8):
        j = (i + 1) % 8
        tris.append((tc, t8 + i, t8 + j))                              # table
        gi, gm, gj = g_top + 2 * i, g_top + (2 * i + 1) % 16, g_top + (2 * j) % 16
        tris.append((t8 + i, gi, gm))                                   # crown: bezel halves
        tris.append((t8 + i, gm, t8 + j))                               # star facet
        tris.append((t8 + j, gm, gj))
    for k in range(16):
        m = (k + 1) % 16
        tris.append((g_top + k, g_bot + k, g_bot + m))                  # girdle band
        tris.append((g_top + k, g_bot + m, g_top + m))
        tris.append((g_bot + k, cul, g_bot + m))                        # pavilion
    verts, tris = verts, np.array(tris, np.int64)
    nrm = triangle_cross(verts, tris)
    cen = verts[tris].mean(axis=1) - c
    outward = np.sum(nrm * cen, axis=1) > 0
    tris[~outward] = tris[~outward][:, [0, 2, 1]]
    return verts, tris.astype(np.int32)
