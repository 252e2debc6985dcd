"""Compiled twins of the procedural textures' hot loops: Cycles' 2-D and 3-D Perlin noise and
Voronoi cell scans (F1, F2, distance to edge; core/materials/shader_textures.py ``perlin``,
``_voronoi_octave``, ``_distance_to_edge``; docs/physics.md section 13.6), one pass per point
instead of NumPy's chain of temporaries over the lattice corners or the 9 / 27 cells.

Each kernel does the reference's operations in its order and precision: lookup3 on 32-bit
words (kept in 64-bit integers, masked to 32 bits after every add, subtract and rotation), the
gradient selection by the hash's low bits, the fade with fused multiply-adds emulated in float64
and rounded once to float32 (as the reference does), and the corner blends x, y, z as
``a + t (b - a)`` in float32; numba compiles without fastmath, so nothing is reordered or
contracted and the kernels equal the reference bit for bit (tests/materials/test_shader_kernels.py).
The Voronoi kernels hash cells with the PCG hashes in 64-bit integers masked to 32 bits, the
signed shift emulated, and sum squared components in the reference's order.
``shader_textures`` chooses them through core/util/jit.py. ``curve_lookup_kernel`` is the RGB /
Float Curves' table lookup with Cycles' extrapolation (shader_eval.py ``curve_lookup_reference``,
tests/materials/test_shader_curves.py), chosen by ``shader_eval.curve_lookup``.
"""

from __future__ import annotations

import numpy as np

from ..util.jit import njit

__all__ = ["perlin2_kernel", "perlin3_kernel", "voronoi_octave_kernel", "voronoi_edge_kernel", "curve_lookup_kernel"]

_M = np.uint64(0xFFFFFFFF)
_F0, _F1, _F2 = np.float32(0.0), np.float32(1.0), np.float32(2.0)
_F6, _F15, _F10 = np.float64(6.0), np.float64(-15.0), np.float64(10.0)


@njit
def _rot(x, k):
    return ((x << np.uint64(k)) | (x >> np.uint64(32 - k))) & _M


@njit
def _final(a, b, c):
    c = ((c ^ b) - _rot(b, 14)) & _M
    a = ((a ^ c) - _rot(c, 11)) & _M
    b = ((b ^ a) - _rot(a, 25)) & _M
    c = ((c ^ b) - _rot(b, 16)) & _M
    a = ((a ^ c) - _rot(c, 4)) & _M
    b = ((b ^ a) - _rot(a, 14)) & _M
    c = ((c ^ b) - _rot(b, 24)) & _M
    return c


@njit
def _hash2(kx, ky):
    init = np.uint64((0xDEADBEEF + (2 << 2) + 13) & 0xFFFFFFFF)
    a = (init + kx) & _M
    b = (init + ky) & _M
    return _final(a, b, init)


@njit
def _hash3(kx, ky, kz):
    init = np.uint64((0xDEADBEEF + (3 << 2) + 13) & 0xFFFFFFFF)
    a = (init + kx) & _M
    b = (init + ky) & _M
    c = (init + kz) & _M
    return _final(a, b, c)


@njit
def _fade(t):
    a = np.float32(np.float64(t) * _F6 + _F15)
    b = np.float32(np.float64(t) * np.float64(a) + _F10)
    return np.float32(np.float32(t * t) * np.float32(t * b))


@njit
def _cell(x):
    """(the cell's index as a 32-bit word, the fraction) of float32 x (floorfrac)."""
    f = np.float32(np.floor(x))
    return np.uint64(np.int64(f) & 0xFFFFFFFF), np.float32(x - f)


@njit
def _lerp(a, b, t):
    return np.float32(a + np.float32(t * np.float32(b - a)))


@njit
def _grad2(h, x, y):
    h = h & np.uint64(7)
    u = x if h < 4 else y
    v = np.float32(_F2 * (y if h < 4 else x))
    if h & np.uint64(1):
        u = -u
    if h & np.uint64(2):
        v = -v
    return np.float32(u + v)


@njit
def _grad3(h, x, y, z):
    h = h & np.uint64(15)
    u = x if h < 8 else y
    vt = x if (h == 12 or h == 14) else z
    v = y if h < 4 else vt
    if h & np.uint64(1):
        u = -u
    if h & np.uint64(2):
        v = -v
    return np.float32(u + v)


@njit
def perlin2_kernel(px, py, out):
    """Cycles' perlin_2d at (px[i], py[i]) (float32 arrays) into out (float32)."""
    one = np.uint64(1)
    for i in range(px.shape[0]):
        X, fx = _cell(px[i])
        Y, fy = _cell(py[i])
        u, v = _fade(fx), _fade(fy)
        X1, Y1 = (X + one) & _M, (Y + one) & _M
        fx1, fy1 = np.float32(fx - _F1), np.float32(fy - _F1)
        g00 = _grad2(_hash2(X, Y), fx, fy)
        g10 = _grad2(_hash2(X1, Y), fx1, fy)
        g01 = _grad2(_hash2(X, Y1), fx, fy1)
        g11 = _grad2(_hash2(X1, Y1), fx1, fy1)
        out[i] = _lerp(_lerp(g00, g10, u), _lerp(g01, g11, u), v)


@njit
def perlin3_kernel(px, py, pz, out):
    """Cycles' perlin_3d at (px[i], py[i], pz[i]) (float32 arrays) into out (float32)."""
    one = np.uint64(1)
    for i in range(px.shape[0]):
        X, fx = _cell(px[i])
        Y, fy = _cell(py[i])
        Z, fz = _cell(pz[i])
        u, v, w = _fade(fx), _fade(fy), _fade(fz)
        X1, Y1, Z1 = (X + one) & _M, (Y + one) & _M, (Z + one) & _M
        fx1, fy1, fz1 = np.float32(fx - _F1), np.float32(fy - _F1), np.float32(fz - _F1)
        g000 = _grad3(_hash3(X, Y, Z), fx, fy, fz)
        g100 = _grad3(_hash3(X1, Y, Z), fx1, fy, fz)
        g010 = _grad3(_hash3(X, Y1, Z), fx, fy1, fz)
        g110 = _grad3(_hash3(X1, Y1, Z), fx1, fy1, fz)
        g001 = _grad3(_hash3(X, Y, Z1), fx, fy, fz1)
        g101 = _grad3(_hash3(X1, Y, Z1), fx1, fy, fz1)
        g011 = _grad3(_hash3(X, Y1, Z1), fx, fy1, fz1)
        g111 = _grad3(_hash3(X1, Y1, Z1), fx1, fy1, fz1)
        m00 = _lerp(g000, g100, u)
        m10 = _lerp(g010, g110, u)
        m01 = _lerp(g001, g101, u)
        m11 = _lerp(g011, g111, u)
        out[i] = _lerp(_lerp(m00, m10, v), _lerp(m01, m11, v), w)


# ------------------------------------------------------------------------------------ Voronoi
_M31 = np.uint64(0x7FFFFFFF)
_PCG_MUL, _PCG_ADD = np.uint64(1664525), np.uint64(1013904223)
_PCG_NORM = np.float32(np.float32(1.0) / np.float32(2147483647.0))
_HI16 = np.uint64(0xFFFF0000)
_SIGN = np.uint64(0x80000000)


@njit
def _sra16(v):
    """v ^ (v >> 16) with a signed 32-bit v's arithmetic shift."""
    s = v >> np.uint64(16)
    if v & _SIGN:
        s = s | _HI16
    return (v ^ s) & _M


@njit
def _pcg3(x, y, z):
    vx = (x * _PCG_MUL + _PCG_ADD) & _M
    vy = (y * _PCG_MUL + _PCG_ADD) & _M
    vz = (z * _PCG_MUL + _PCG_ADD) & _M
    vx = (vx + vy * vz) & _M
    vy = (vy + vz * vx) & _M
    vz = (vz + vx * vy) & _M
    vx, vy, vz = _sra16(vx), _sra16(vy), _sra16(vz)
    vx = (vx + vy * vz) & _M
    vy = (vy + vz * vx) & _M
    vz = (vz + vx * vy) & _M
    return (np.float32(np.float32(vx & _M31) * _PCG_NORM), np.float32(np.float32(vy & _M31) * _PCG_NORM),
            np.float32(np.float32(vz & _M31) * _PCG_NORM))


@njit
def _pcg2(x, y):
    vx = (x * _PCG_MUL + _PCG_ADD) & _M
    vy = (y * _PCG_MUL + _PCG_ADD) & _M
    vx = (vx + vy * _PCG_MUL) & _M
    vy = (vy + vx * _PCG_MUL) & _M
    vx, vy = _sra16(vx), _sra16(vy)
    vx = (vx + vy * _PCG_MUL) & _M
    vy = (vy + vx * _PCG_MUL) & _M
    return np.float32(np.float32(vx & _M31) * _PCG_NORM), np.float32(np.float32(vy & _M31) * _PCG_NORM)


@njit
def _word(i):
    return np.uint64(np.int64(i) & 0xFFFFFFFF)


@njit
def _point(d, cx, cy, cz, i, j, k, rnd):
    """The feature point of cell (cx + i, cy + j, cz + k) (d = 2: no z) relative to the cell
    (cx, cy, cz), and its colour hash."""
    if d == 3:
        hx, hy, hz = _pcg3(_word(cx + i), _word(cy + j), _word(cz + k))
        return (np.float32(np.float32(i) + np.float32(hx * rnd)), np.float32(np.float32(j) + np.float32(hy * rnd)),
                np.float32(np.float32(k) + np.float32(hz * rnd)))
    hx, hy = _pcg2(_word(cx + i), _word(cy + j))
    return np.float32(np.float32(i) + np.float32(hx * rnd)), np.float32(np.float32(j) + np.float32(hy * rnd)), _F0


@njit
def _dist(metric, d, ax, ay, az):
    if metric == 0:  # Euclidean: sqrt of the sum in order
        s = np.float32(np.float32(ax * ax) + np.float32(ay * ay))
        if d == 3:
            s = np.float32(s + np.float32(az * az))
        return np.float32(np.sqrt(s))
    if metric == 1:  # Manhattan
        s = np.float32(abs(ax) + abs(ay))
        if d == 3:
            s = np.float32(s + abs(az))
        return s
    m = max(abs(ax), abs(ay))  # Chebychev
    if d == 3:
        m = max(m, abs(az))
    return np.float32(m)


@njit
def voronoi_octave_kernel(coord, randomness, metric, f2, dist_out, colour_out, pos_out):
    """One Voronoi octave (F1, or F2 with ``f2``) of points ``coord`` (n, d) float32, d = 2 or 3,
    metric 0 Euclidean / 1 Manhattan / 2 Chebychev: the distance, the cell colour (PCG hash) and
    the feature point's position, as shader_textures._voronoi_octave."""
    n, d = coord.shape
    for r in range(n):
        fx, fy = np.float32(np.floor(coord[r, 0])), np.float32(np.floor(coord[r, 1]))
        fz = np.float32(np.floor(coord[r, 2])) if d == 3 else _F0
        lx, ly = np.float32(coord[r, 0] - fx), np.float32(coord[r, 1] - fy)
        lz = np.float32(coord[r, 2] - fz) if d == 3 else _F0
        cx, cy, cz = np.int64(np.int32(fx)), np.int64(np.int32(fy)), np.int64(np.int32(fz))
        rnd = randomness[r]
        d1 = d2 = np.float32(3.4028234663852886e38)
        o1 = o2 = (0, 0, 0)
        p1 = p2 = (_F0, _F0, _F0)
        krange = 3 if d == 3 else 1
        for kk in range(krange):
            k = kk - 1 if d == 3 else 0
            for jj in range(3):
                j = jj - 1
                for ii in range(3):
                    i = ii - 1
                    px, py, pz = _point(d, cx, cy, cz, i, j, k, rnd)
                    dist = _dist(metric, d, np.float32(px - lx), np.float32(py - ly), np.float32(pz - lz))
                    if dist < d1:
                        d2, o2, p2 = d1, o1, p1
                        d1, o1, p1 = dist, (i, j, k), (px, py, pz)
                    elif dist < d2:
                        d2, o2, p2 = dist, (i, j, k), (px, py, pz)
        if f2:
            d1, o1, p1 = d2, o2, p2
        dist_out[r] = d1
        if d == 3:
            h = _pcg3(_word(cx + o1[0]), _word(cy + o1[1]), _word(cz + o1[2]))
        else:
            h = _pcg3(_word(cx + o1[0]), _word(cy + o1[1]), np.uint64(0))
        colour_out[r, 0], colour_out[r, 1], colour_out[r, 2] = h[0], h[1], h[2]
        pos_out[r, 0] = np.float32(p1[0] + fx)
        pos_out[r, 1] = np.float32(p1[1] + fy)
        if d == 3:
            pos_out[r, 2] = np.float32(p1[2] + fz)


@njit
def voronoi_edge_kernel(coord, randomness, out):
    """Voronoi distance to edge (Euclidean) of points ``coord`` (n, d) float32, d = 2 or 3, as
    shader_textures._distance_to_edge."""
    n, d = coord.shape
    vx = np.empty(27, np.float32)
    vy = np.empty(27, np.float32)
    vz = np.empty(27, np.float32)
    for r in range(n):
        fx, fy = np.float32(np.floor(coord[r, 0])), np.float32(np.floor(coord[r, 1]))
        fz = np.float32(np.floor(coord[r, 2])) if d == 3 else _F0
        lx, ly = np.float32(coord[r, 0] - fx), np.float32(coord[r, 1] - fy)
        lz = np.float32(coord[r, 2] - fz) if d == 3 else _F0
        cx, cy, cz = np.int64(np.int32(fx)), np.int64(np.int32(fy)), np.int64(np.int32(fz))
        rnd = randomness[r]
        best = np.float32(3.4028234663852886e38)
        bx = by = bz = _F0
        m = 0
        krange = 3 if d == 3 else 1
        for kk in range(krange):
            k = kk - 1 if d == 3 else 0
            for jj in range(3):
                for ii in range(3):
                    px, py, pz = _point(d, cx, cy, cz, ii - 1, jj - 1, k, rnd)
                    ax, ay, az = np.float32(px - lx), np.float32(py - ly), np.float32(pz - lz)
                    vx[m], vy[m], vz[m] = ax, ay, az
                    m += 1
                    dd = np.float32(np.float32(ax * ax) + np.float32(ay * ay))
                    if d == 3:
                        dd = np.float32(dd + np.float32(az * az))
                    if dd < best:
                        best, bx, by, bz = dd, ax, ay, az
        res = np.float32(3.4028234663852886e38)
        for q in range(m):
            qx, qy, qz = np.float32(vx[q] - bx), np.float32(vy[q] - by), np.float32(vz[q] - bz)
            pp = np.float32(np.float32(qx * qx) + np.float32(qy * qy))
            if d == 3:
                pp = np.float32(pp + np.float32(qz * qz))
            if pp > np.float32(0.0001):
                ln = np.float32(np.sqrt(pp))
                nx, ny, nz = np.float32(qx / ln), np.float32(qy / ln), np.float32(qz / ln)
                e = np.float32(np.float32(np.float32(np.float32(bx + vx[q]) / _F2) * nx)
                               + np.float32(np.float32(np.float32(by + vy[q]) / _F2) * ny))
                if d == 3:
                    e = np.float32(e + np.float32(np.float32(np.float32(bz + vz[q]) / _F2) * nz))
                res = min(res, e)
        out[r] = res


# ------------------------------------------------------------------------------------ curves
@njit
def curve_lookup_kernel(table, rel, extrapolate, out):
    """RGB / Float Curves' table lookup (Cycles svm/ramp.h ``rgb_ramp_lookup`` /
    ``float_ramp_lookup`` with interpolation, as shader_eval.curve_lookup_reference): column c
    of ``table`` (n, C) float32 read at ``rel[i, c]`` (the input relative to the table's x
    range, float32) into ``out[i, c]``; past [0, 1] with ``extrapolate`` the end segment's
    slope continues, else the end value holds."""
    n = table.shape[0]
    scale = np.float32(n - 1)
    for r in range(rel.shape[0]):
        for c in range(rel.shape[1]):
            f = rel[r, c]
            if extrapolate and (f < _F0 or f > _F1):
                if f < _F0:
                    t0 = table[0, c]
                    dy = np.float32(t0 - table[1, c])
                    f = np.float32(-f)
                else:
                    t0 = table[n - 1, c]
                    dy = np.float32(t0 - table[n - 2, c])
                    f = np.float32(f - _F1)
                out[r, c] = np.float32(t0 + np.float32(np.float32(dy * f) * scale))
                continue
            if f != f:
                f = _F0
            f = np.float32(min(max(f, _F0), _F1) * scale)
            i = min(max(int(f), 0), n - 1)
            t = np.float32(f - np.float32(i))
            a = table[i, c]
            if t > _F0:
                a = np.float32(np.float32((_F1 - t) * a) + np.float32(t * table[i + 1, c]))
            out[r, c] = a
