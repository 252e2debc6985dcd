"""Filling an embreex scene with triangles through Embree's C API (ctypes), without embreex's copy loop.

embreex 4.4's ``TriangleMesh`` (embreex/mesh_construction.pyx, ``_build_from_indices``) copies
the mesh into Embree's buffers element by element through untyped ``np.ndarray`` indexing
(``tri_indices[i][0]``: a Python view and a NumPy scalar per index), ~1-1.5 us per triangle
with the GIL held: at 10 M triangles that alone took 15-45 s of the preparation. Here the same
Embree calls it makes (Embree 4 API, include/embree4/rtcore_geometry.h: ``rtcNewGeometry``
TRIANGLE, ``rtcSetNewGeometryBuffer`` VERTEX FLOAT3 stride 16 and INDEX UINT3 stride 12,
``rtcCommitGeometry``, ``rtcAttachGeometry``, ``rtcReleaseGeometry``) are made through ctypes on
the very library embreex loaded, and the buffers are filled with one NumPy copy each; the
scene is committed with ``rtcCommitScene`` through ctypes, which releases the GIL while Embree
builds the BVH (so a cancel poll keeps running). The buffers hold the same bytes as embreex's,
so Embree builds the same BVH and every hit is the same (tests/render/test_prepare_scale.py).

embreex keeps the ``RTCScene`` handle in a C field of ``EmbreeScene`` that Python cannot read;
its place in the object (after the object header: ``scene_i``, then ``is_committed``, then
``device``) is Cython's layout of the class's fields in declaration order (embreex/rtcore_scene.pxd).
Before using it, :func:`_layout_ok` checks that layout on a scene whose device is known: the
public ``is_committed`` is read back at its offset, the device object at its offset, and
Embree itself confirms the handle (``rtcGetSceneDevice`` returns the device, ``rtcGetSceneFlags``
the ROBUST flag embreex set). If any check fails (another embreex build), ``available()`` is
False and the caller keeps embreex's own ``TriangleMesh``.
"""

from __future__ import annotations

import ctypes
import glob
import os
import threading

import numpy as np

__all__ = ["available", "new_scene", "add_triangles", "commit"]

_RTC_GEOMETRY_TYPE_TRIANGLE = 0
_RTC_BUFFER_TYPE_INDEX = 0
_RTC_BUFFER_TYPE_VERTEX = 1
_RTC_FORMAT_UINT3 = 0x5003
_RTC_FORMAT_FLOAT3 = 0x9003
_RTC_SCENE_FLAG_ROBUST = 1 << 2
_P = ctypes.sizeof(ctypes.c_void_p)
_HEAD = 2 * _P  # PyObject_HEAD: ob_refcnt, ob_type (CPython, non-debug build)
# EmbreeScene's C fields, in declaration order (embreex/rtcore_scene.pxd)
_OFF_SCENE = _HEAD
_OFF_COMMITTED = _HEAD + _P
_OFF_DEVICE = _HEAD + 2 * _P  # after the int, padded to the pointer's alignment
_OFF_DEVICE_HANDLE = _HEAD    # EmbreeDevice's only field (embreex/rtcore.pxd)

_lock = threading.Lock()
_state: dict = {}


def _library():
    """The libembree4 embreex links to (its wheel's embreex.libs/), or None."""
    import embreex

    here = os.path.dirname(os.path.abspath(embreex.__file__))
    paths = sorted(glob.glob(os.path.join(here, "..", "embreex.libs", "libembree4*.so*"))
                   + glob.glob(os.path.join(here, "libembree4*.so*")))
    if len(paths) != 1:
        return None
    lib = ctypes.CDLL(paths[0])  # already loaded by embreex: dlopen returns the same handle
    vp, ui, sz = ctypes.c_void_p, ctypes.c_uint, ctypes.c_size_t
    for name, res, args in (
        ("rtcNewGeometry", vp, [vp, ctypes.c_int]),
        ("rtcSetNewGeometryBuffer", vp, [vp, ctypes.c_int, ui, ctypes.c_int, sz, sz]),
        ("rtcCommitGeometry", None, [vp]),
        ("rtcAttachGeometry", ui, [vp, vp]),
        ("rtcReleaseGeometry", None, [vp]),
        ("rtcCommitScene", None, [vp]),
        ("rtcGetSceneDevice", vp, [vp]),
        ("rtcReleaseDevice", None, [vp]),
        ("rtcGetSceneFlags", ctypes.c_int, [vp]),
        ("rtcGetDeviceError", ctypes.c_int, [vp]),
    ):
        f = getattr(lib, name)
        f.restype, f.argtypes = res, args
    return lib


def _read(obj_id: int, offset: int, ctype):
    return ctype.from_address(obj_id + offset).value


def _layout_ok(lib) -> bool:
    from embreex import rtcore, rtcore_scene

    dev = rtcore.EmbreeDevice()
    s = rtcore_scene.EmbreeScene(dev)
    for probe in (12345, 0):  # the public int field, seen at its offset
        s.is_committed = probe
        if _read(id(s), _OFF_COMMITTED, ctypes.c_int) != probe:
            return False
    if _read(id(s), _OFF_DEVICE, ctypes.c_void_p) != id(dev):
        return False
    handle = _read(id(dev), _OFF_DEVICE_HANDLE, ctypes.c_void_p)
    scene = _read(id(s), _OFF_SCENE, ctypes.c_void_p)
    if not handle or not scene:
        return False
    got = lib.rtcGetSceneDevice(scene)  # retains the device: release it again
    lib.rtcReleaseDevice(got)
    return got == handle and lib.rtcGetSceneFlags(scene) & _RTC_SCENE_FLAG_ROBUST != 0


def available() -> bool:
    """Whether the direct path works with this embreex (checked once per process)."""
    with _lock:
        if "ok" not in _state:
            try:
                lib = _library()
                _state["lib"] = lib
                _state["ok"] = lib is not None and _layout_ok(lib)
            except Exception:  # no library, another layout, no ctypes: embreex's own path
                _state["ok"] = False
        return _state["ok"]


def new_scene():
    """An embreex EmbreeScene (robust, as embreex's default) and its device, for add_triangles."""
    from embreex import rtcore, rtcore_scene

    dev = rtcore.EmbreeDevice()
    return rtcore_scene.EmbreeScene(dev)


def _handles(scene):
    return (_read(id(scene), _OFF_SCENE, ctypes.c_void_p),
            _read(_read(id(scene), _OFF_DEVICE, ctypes.c_void_p), _OFF_DEVICE_HANDLE, ctypes.c_void_p))


def add_triangles(scene, vertices: np.ndarray, triangles: np.ndarray) -> int:
    """Attach one triangle geometry (``vertices`` (V, 3) float32, ``triangles`` (T, 3) indices
    into them) to the embreex ``scene``, exactly as embreex's TriangleMesh does; returns its
    geomID."""
    lib = _state["lib"]
    sc, dev = _handles(scene)
    v = np.asarray(vertices, np.float32)
    t = np.asarray(triangles)
    geom = lib.rtcNewGeometry(dev, _RTC_GEOMETRY_TYPE_TRIANGLE)
    if not geom:
        raise RuntimeError(f"Embree: rtcNewGeometry failed (error {lib.rtcGetDeviceError(dev)})")
    try:
        vb = lib.rtcSetNewGeometryBuffer(geom, _RTC_BUFFER_TYPE_VERTEX, 0, _RTC_FORMAT_FLOAT3, 16, len(v))
        ib = lib.rtcSetNewGeometryBuffer(geom, _RTC_BUFFER_TYPE_INDEX, 0, _RTC_FORMAT_UINT3, 12, len(t))
        if not vb or not ib:
            raise RuntimeError(f"Embree: no geometry buffer (error {lib.rtcGetDeviceError(dev)}): out of memory?")
        # embreex writes x, y, z and leaves the 4th float of each vertex as allocated; we zero it
        vdst = np.ctypeslib.as_array((ctypes.c_float * (4 * len(v))).from_address(vb)).reshape(-1, 4)
        vdst[:, :3] = v
        vdst[:, 3] = 0
        idst = np.ctypeslib.as_array((ctypes.c_uint32 * (3 * len(t))).from_address(ib)).reshape(-1, 3)
        idst[:] = t
        lib.rtcCommitGeometry(geom)
        gid = lib.rtcAttachGeometry(sc, geom)
    finally:
        lib.rtcReleaseGeometry(geom)
    err = lib.rtcGetDeviceError(dev)
    if err:
        raise RuntimeError(f"Embree error {err} while adding {len(t)} triangles")
    return int(gid)


def commit(scene) -> None:
    """Build the scene's BVH (``rtcCommitScene``, GIL released by ctypes) and tell embreex it is
    committed, so its ``run`` does not commit again."""
    lib = _state["lib"]
    sc, dev = _handles(scene)
    lib.rtcCommitScene(sc)
    err = lib.rtcGetDeviceError(dev)
    if err:
        raise RuntimeError(f"Embree error {err} while building the BVH")
    scene.is_committed = 1
