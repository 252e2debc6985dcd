"""Compiled twins of the procedural textures' hot loop: Cycles' 2-D and 3-D Perlin noise
(core/materials/shader_textures.py ``perlin``; docs/physics.md section 13.6), one pass per point
instead of NumPy's chain of temporaries over the 4 or 8 lattice corners.

Each kernel does the reference's operations in its order and precision: lookup3 on 32-bit
words (kept in 64-bit integers, masked to 32 bits after every add, subtract and rotation), the
gradient selection by the hash's low bits, the fade with fused multiply-adds emulated in float64
and rounded once to float32 (as the reference does), and the corner blends x, y, z as
``a + t (b - a)`` in float32; numba compiles without fastmath, so nothing is reordered or
contracted and the kernels equal the reference bit for bit (tests/materials/test_shader_kernels.py).
``shader_textures.perlin`` chooses them through core/util/jit.py.
"""

from __future__ import annotations

import numpy as np

from ..util.jit import njit

__all__ = ["perlin2_kernel", "perlin3_kernel"]

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
