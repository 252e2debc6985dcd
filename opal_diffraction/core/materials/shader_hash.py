"""Cycles' hash functions, vectorised: Bob Jenkins' lookup3 ``final``/``mix`` on uint32 arrays and
the float hashes built on them (docs/physics.md section 13.6).

Ported from Blender's ``intern/cycles/util/hash.h`` (Apache-2.0; itself from
http://burtleburtle.net/bob/c/lookup3.c): ``hash_uint``..``hash_uint4`` start from
``0xdeadbeef + (n << 2) + 13``, add the keys and run ``final`` (``hash_uint4`` runs ``mix`` on the
first three keys first); ``hash_floatN_to_float`` hashes the keys' IEEE-754 bit patterns and maps
the result to [0, 1] as ``uint_to_float_incl`` (``(float)h * (1 / (float)0xFFFFFFFF)`` in float32).
Everything is uint32 / float32, so the values are Cycles' bit for bit (tests/materials/
test_shader_hash.py checks them against an independent big-integer lookup3 and against Cycles'
White Noise texture rendered in the same bpy session).
"""

from __future__ import annotations

import numpy as np

__all__ = ["hash_uint", "hash_uint2", "hash_uint3", "hash_uint4", "float_bits", "uint_to_float_incl",
           "hash_float_to_float", "hash_float2_to_float", "hash_float3_to_float", "hash_float4_to_float",
           "hash_float_to_float3", "hash_float2_to_float2", "hash_float2_to_float3", "hash_float3_to_float3",
           "hash_float4_to_float3", "hash_float4_to_float4"]

_U = np.uint32


def _rot(x, k: int):
    return (x << _U(k)) | (x >> _U(32 - k))


def _final(a, b, c):
    c = (c ^ b) - _rot(b, 14)
    a = (a ^ c) - _rot(c, 11)
    b = (b ^ a) - _rot(a, 25)
    c = (c ^ b) - _rot(b, 16)
    a = (a ^ c) - _rot(c, 4)
    b = (b ^ a) - _rot(a, 14)
    c = (c ^ b) - _rot(b, 24)
    return a, b, c


def _mix(a, b, c):
    a = (a - c) ^ _rot(c, 4)
    c = c + b
    b = (b - a) ^ _rot(a, 6)
    a = a + c
    c = (c - b) ^ _rot(b, 8)
    b = b + a
    a = (a - c) ^ _rot(c, 16)
    c = c + b
    b = (b - a) ^ _rot(a, 19)
    a = a + c
    c = (c - b) ^ _rot(b, 4)
    b = b + a
    return a, b, c


def _u(x):
    """uint32 view of int keys (Cycles passes ints as uint: two's complement)."""
    x = np.asarray(x)
    if x.dtype == np.uint32:
        return x
    return x.astype(np.int64).astype(np.uint32)


def _init(n: int, shape):
    v = np.full(shape, (0xDEADBEEF + (n << 2) + 13) & 0xFFFFFFFF, np.uint32)
    return v, v.copy(), v.copy()


def hash_uint(kx):
    kx = _u(kx)
    with np.errstate(over="ignore"):
        a, b, c = _init(1, kx.shape)
        a = a + kx
        return _final(a, b, c)[2]


def hash_uint2(kx, ky):
    kx, ky = np.broadcast_arrays(_u(kx), _u(ky))
    with np.errstate(over="ignore"):
        a, b, c = _init(2, kx.shape)
        b = b + ky
        a = a + kx
        return _final(a, b, c)[2]


def hash_uint3(kx, ky, kz):
    kx, ky, kz = np.broadcast_arrays(_u(kx), _u(ky), _u(kz))
    with np.errstate(over="ignore"):
        a, b, c = _init(3, kx.shape)
        c = c + kz
        b = b + ky
        a = a + kx
        return _final(a, b, c)[2]


def hash_uint4(kx, ky, kz, kw):
    kx, ky, kz, kw = np.broadcast_arrays(_u(kx), _u(ky), _u(kz), _u(kw))
    with np.errstate(over="ignore"):
        a, b, c = _init(4, kx.shape)
        a = a + kx
        b = b + ky
        c = c + kz
        a, b, c = _mix(a, b, c)
        a = a + kw
        return _final(a, b, c)[2]


def float_bits(x) -> np.ndarray:
    """The float32 values' bit patterns as uint32 (Cycles' ``__float_as_uint``)."""
    x = np.asarray(x, np.float32)
    return np.ascontiguousarray(x).view(np.uint32).reshape(x.shape)


_INCL = np.float32(1.0) / np.float32(4294967295.0)  # 1.0f / (float)0xFFFFFFFFu


def uint_to_float_incl(h) -> np.ndarray:
    """[0, 2^32 - 1] -> [0, 1] as Cycles: (float)h * (1.0f / (float)0xFFFFFFFF), in float32."""
    return np.asarray(h).astype(np.float32) * _INCL


def _f(x):
    return float_bits(x)


def hash_float_to_float(k):
    return uint_to_float_incl(hash_uint(_f(k)))


def hash_float2_to_float(kx, ky):
    return uint_to_float_incl(hash_uint2(_f(kx), _f(ky)))


def hash_float3_to_float(kx, ky, kz):
    return uint_to_float_incl(hash_uint3(_f(kx), _f(ky), _f(kz)))


def hash_float4_to_float(kx, ky, kz, kw):
    return uint_to_float_incl(hash_uint4(_f(kx), _f(ky), _f(kz), _f(kw)))


def _const(v, like):
    return np.full(np.shape(like), v, np.float32)


def hash_float_to_float3(k):
    """(..., 3): hash(k), hash(k, 1), hash(k, 2)."""
    return np.stack([hash_float_to_float(k), hash_float2_to_float(k, _const(1.0, k)),
                     hash_float2_to_float(k, _const(2.0, k))], axis=-1)


def hash_float2_to_float2(x, y):
    return np.stack([hash_float2_to_float(x, y), hash_float3_to_float(x, y, _const(1.0, x))], axis=-1)


def hash_float2_to_float3(x, y):
    return np.stack([hash_float2_to_float(x, y), hash_float3_to_float(x, y, _const(1.0, x)),
                     hash_float3_to_float(x, y, _const(2.0, x))], axis=-1)


def hash_float3_to_float3(x, y, z):
    return np.stack([hash_float3_to_float(x, y, z), hash_float4_to_float(x, y, z, _const(1.0, x)),
                     hash_float4_to_float(x, y, z, _const(2.0, x))], axis=-1)


def hash_float4_to_float3(x, y, z, w):
    return np.stack([hash_float4_to_float(x, y, z, w), hash_float4_to_float(z, x, w, y),
                     hash_float4_to_float(w, z, y, x)], axis=-1)


def hash_float4_to_float4(x, y, z, w):
    return np.stack([hash_float4_to_float(x, y, z, w), hash_float4_to_float(w, x, y, z),
                     hash_float4_to_float(z, w, x, y), hash_float4_to_float(y, z, w, x)], axis=-1)


# ------------------------------------------------------------------------------------ PCG (Voronoi)
# Cycles' Voronoi hashes integer cells with the signed-integer PCG hashes of util/hash.h
# (Jarzynski & Olano, "Hash Functions for GPU Rendering", JCGT 2020, modified by Blender to
# signed ints so OSL can run them): wrapping int32 products, an arithmetic shift, and the result
# masked to 31 bits, mapped to [0, 1] as (float)h * (1.0f / (float)0x7FFFFFFF).

_PCG_MUL, _PCG_ADD = np.uint32(1664525), np.uint32(1013904223)
_PCG_NORM = np.float32(1.0) / np.float32(2147483647.0)


def _sra16(v):
    """v ^ (v >> 16) with the arithmetic (sign-extending) shift of a signed int."""
    return v ^ (v.view(np.int32) >> np.int32(16)).view(np.uint32)


def _pcg_start(parts):
    arrs = np.broadcast_arrays(*[np.asarray(p).astype(np.int64).astype(np.uint32) for p in parts])
    return [a * _PCG_MUL + _PCG_ADD for a in (np.array(x, copy=True) for x in arrs)]


def hash_pcg2d_i(x, y):
    with np.errstate(over="ignore"):
        vx, vy = _pcg_start((x, y))
        vx = vx + vy * _PCG_MUL
        vy = vy + vx * _PCG_MUL
        vx, vy = _sra16(vx), _sra16(vy)
        vx = vx + vy * _PCG_MUL
        vy = vy + vx * _PCG_MUL
    return vx & np.uint32(0x7FFFFFFF), vy & np.uint32(0x7FFFFFFF)


def hash_pcg3d_i(x, y, z):
    with np.errstate(over="ignore"):
        vx, vy, vz = _pcg_start((x, y, z))
        vx = vx + vy * vz
        vy = vy + vz * vx
        vz = vz + vx * vy
        vx, vy, vz = _sra16(vx), _sra16(vy), _sra16(vz)
        vx = vx + vy * vz
        vy = vy + vz * vx
        vz = vz + vx * vy
    m = np.uint32(0x7FFFFFFF)
    return vx & m, vy & m, vz & m


def hash_pcg4d_i(x, y, z, w):
    with np.errstate(over="ignore"):
        vx, vy, vz, vw = _pcg_start((x, y, z, w))
        vx = vx + vy * vw
        vy = vy + vz * vx
        vz = vz + vx * vy
        vw = vw + vy * vz
        vx, vy, vz, vw = _sra16(vx), _sra16(vy), _sra16(vz), _sra16(vw)
        vx = vx + vy * vw
        vy = vy + vz * vx
        vz = vz + vx * vy
        vw = vw + vy * vz
    m = np.uint32(0x7FFFFFFF)
    return vx & m, vy & m, vz & m, vw & m


def _pcg_float(hs):
    return np.stack([h.astype(np.float32) * _PCG_NORM for h in hs], axis=-1)


def hash_int2_to_float2(x, y):
    return _pcg_float(hash_pcg2d_i(x, y))


def hash_int3_to_float3(x, y, z):
    return _pcg_float(hash_pcg3d_i(x, y, z))


def hash_int2_to_float3(x, y):
    return hash_int3_to_float3(x, y, np.zeros_like(np.asarray(x)))


def hash_int4_to_float4(x, y, z, w):
    return _pcg_float(hash_pcg4d_i(x, y, z, w))


def hash_int4_to_float3(x, y, z, w):
    return hash_int4_to_float4(x, y, z, w)[..., :3]


__all__ += ["hash_pcg2d_i", "hash_pcg3d_i", "hash_pcg4d_i", "hash_int2_to_float2", "hash_int3_to_float3",
            "hash_int2_to_float3", "hash_int4_to_float4", "hash_int4_to_float3"]
