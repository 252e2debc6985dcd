"""Cycles' hashes (core/materials/shader_hash.py) against independent computations: Bob Jenkins'
lookup3 ``hashlittle`` written here byte by byte on Python integers (itself checked against the
values lookup3.c publishes), of which Cycles' ``hash_uint*`` are the 4-, 8-, 12- and 16-byte keys
with initval 13; and the PCG hashes Voronoi uses, on Python integers with a signed shift."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from opal_diffraction.core.materials import shader_hash as H

M = 0xFFFFFFFF


def _rot(x, k):
    return ((x << k) | (x >> (32 - k))) & M


def _mix(a, b, c):
    a = (a - c) & M; a ^= _rot(c, 4); c = (c + b) & M
    b = (b - a) & M; b ^= _rot(a, 6); a = (a + c) & M
    c = (c - b) & M; c ^= _rot(b, 8); b = (b + a) & M
    a = (a - c) & M; a ^= _rot(c, 16); c = (c + b) & M
    b = (b - a) & M; b ^= _rot(a, 19); a = (a + c) & M
    c = (c - b) & M; c ^= _rot(b, 4); b = (b + a) & M
    return a, b, c


def _final(a, b, c):
    c ^= b; c = (c - _rot(b, 14)) & M
    a ^= c; a = (a - _rot(c, 11)) & M
    b ^= a; b = (b - _rot(a, 25)) & M
    c ^= b; c = (c - _rot(b, 16)) & M
    a ^= c; a = (a - _rot(c, 4)) & M
    b ^= a; b = (b - _rot(a, 14)) & M
    c ^= b; c = (c - _rot(b, 24)) & M
    return a, b, c


def hashlittle(key: bytes, initval: int = 0) -> int:
    """lookup3.c's hashlittle, on bytes (little-endian words, the tail zero-padded)."""
    length = len(key)
    a = b = c = (0xDEADBEEF + length + initval) & M
    k = key
    while length > 12:
        a = (a + int.from_bytes(k[0:4], "little")) & M
        b = (b + int.from_bytes(k[4:8], "little")) & M
        c = (c + int.from_bytes(k[8:12], "little")) & M
        a, b, c = _mix(a, b, c)
        k, length = k[12:], length - 12
    if length == 0:
        return c
    tail = k + bytes(12 - length)
    a = (a + int.from_bytes(tail[0:4], "little")) & M
    b = (b + int.from_bytes(tail[4:8], "little")) & M
    c = (c + int.from_bytes(tail[8:12], "little")) & M
    return _final(a, b, c)[2]


def test_the_reference_hashlittle_gives_lookup3_published_values():
    # lookup3.c's driver5 (Bob Jenkins, 2006): the hashes of "Four score and seven years ago"
    assert hashlittle(b"Four score and seven years ago", 0) == 0x17770551
    assert hashlittle(b"Four score and seven years ago", 1) == 0xCD628161
    assert hashlittle(b"", 0) == 0xDEADBEEF


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_hash_uint_n_is_lookup3_of_the_keys_with_initval_13(n):
    rng = np.random.default_rng(n)
    keys = rng.integers(0, 2**32, (200, n), dtype=np.uint64).astype(np.uint32)
    keys[:4] = [[0] * n, [M] * n, [1] * n, list(range(n))]
    fn = {1: H.hash_uint, 2: H.hash_uint2, 3: H.hash_uint3, 4: H.hash_uint4}[n]
    got = fn(*[keys[:, i] for i in range(n)])
    want = [hashlittle(struct.pack(f"<{n}I", *map(int, row)), 13) for row in keys]
    assert got.dtype == np.uint32
    assert got.tolist() == want


def test_float_hashes_hash_the_bit_patterns_and_map_to_the_closed_unit_interval():
    x = np.array([0.0, -0.0, 1.0, 0.5, -3.25, 1e30], np.float32)
    y = np.array([2.0, 2.0, -1.0, 7.5, 0.125, -1e-30], np.float32)
    bits = [struct.unpack("<I", struct.pack("<f", float(v)))[0] for v in x]
    ybits = [struct.unpack("<I", struct.pack("<f", float(v)))[0] for v in y]
    want1 = np.float32([hashlittle(struct.pack("<I", b), 13) for b in bits]) * (np.float32(1) / np.float32(M))
    want2 = np.float32([hashlittle(struct.pack("<2I", b, c), 13) for b, c in zip(bits, ybits)]) * (
        np.float32(1) / np.float32(M))
    assert H.hash_float_to_float(x).tolist() == want1.tolist()
    assert H.hash_float2_to_float(x, y).tolist() == want2.tolist()
    assert H.hash_float_to_float(x)[0] != H.hash_float_to_float(x)[1]  # +0 and -0 differ, as in Cycles
    assert (H.hash_float3_to_float3(x, y, x) >= 0).all() and (H.hash_float3_to_float3(x, y, x) <= 1).all()
    assert H.uint_to_float_incl(np.uint32(M)) == np.float32(1.0)


def _pcg3d(x, y, z):
    """Cycles' hash_pcg3d_i on Python ints (int32 wrap-around, arithmetic >> 16)."""
    def wrap(v):
        v &= M
        return v - (1 << 32) if v >= 1 << 31 else v

    v = [wrap(k * 1664525 + 1013904223) for k in (x, y, z)]
    for rnd in range(2):
        v[0] = wrap(v[0] + v[1] * v[2])
        v[1] = wrap(v[1] + v[2] * v[0])
        v[2] = wrap(v[2] + v[0] * v[1])
        if rnd == 0:
            v = [wrap(e ^ (e >> 16)) for e in v]  # Python's >> on a negative int is arithmetic
    return [e & 0x7FFFFFFF for e in v]


def test_pcg3d_matches_signed_integer_arithmetic():
    rng = np.random.default_rng(5)
    cells = rng.integers(-(2**20), 2**20, (300, 3)).astype(np.int32)
    got = np.stack(H.hash_pcg3d_i(cells[:, 0], cells[:, 1], cells[:, 2]), axis=1)
    want = [_pcg3d(*map(int, c)) for c in cells]
    assert got.tolist() == want
    f = H.hash_int3_to_float3(cells[:, 0], cells[:, 1], cells[:, 2])
    assert (f >= 0).all() and (f <= 1).all()
