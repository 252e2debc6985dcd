"""The scene file: one ``.npz`` archive of the scene's arrays (no pickles).

``save_scene(scene, path)`` writes a Scene; ``load_scene(path)`` reads one back, or raises a
one-line SceneError when the file is not one (missing, a directory, empty, not a .npz archive, a
corrupted, missing or non-.npy member, a newer format). Columns a file written before they existed lacks
load with the value that file rendered with (the loaded scene is checked by
validation.validate, as every render does).
"""

from __future__ import annotations

import os
from dataclasses import fields

import numpy as np

from .checks import SceneError, one_line
from .model import LIGHT_COLUMNS, Camera, Lights, Materials, Scene
from .shader_programs import ShaderProgram

__all__ = ["FORMAT_VERSION", "save_scene", "load_scene"]

FORMAT_VERSION = 1

#: The opal volume domain columns (Scene.add_domains), saved only when there are domains.
_DOMAIN_FIELDS = ("domain_seeds", "domain_weight", "domain_axis", "domain_diameter", "domain_group",
                  "tri_domain_group")

#: Light columns added after format 1: a file without them loads with 0 (what it rendered then).
_LIGHT_OPTIONAL = ("radius", "angle", "soft_falloff", "camera_visible")


def save_scene(scene: Scene, path) -> None:
    """Write ``scene`` to one ``.npz`` file (no pickles)."""
    d: dict[str, np.ndarray] = {
        "format_version": np.array(FORMAT_VERSION),
        "vertices": np.asarray(scene.vertices, np.float32),
        "triangles": np.asarray(scene.triangles, np.int32),
        "tri_material": np.asarray(scene.tri_material, np.int32),
        "world_color": np.asarray(scene.world_color, np.float32),
        "tri_tangent": np.asarray(scene.tri_tangent, np.float32).reshape(-1, 3),
        "tri_period": np.asarray(scene.tri_period, np.float32).reshape(-1),
        "corner_normals": np.asarray(scene.corner_normals, np.float32).reshape(-1, 3, 3),
        "world_image": np.asarray(scene.world_image, np.float32),
        "world_rotation": np.asarray(scene.world_rotation, np.float64),
    }
    if int(scene.world_volume) >= 0:
        d["world_volume"] = np.array(int(scene.world_volume), np.int32)
    if len(scene.domain_seeds):
        for name in _DOMAIN_FIELDS:
            d[name] = np.asarray(getattr(scene, name))
    if len(scene.corner_uvs):
        d["corner_uvs"] = np.asarray(scene.corner_uvs, np.float32)
    if len(scene.corner_tangents):
        d["corner_tangents"] = np.asarray(scene.corner_tangents, np.float32)
    if len(scene.textures):
        d["texture_count"] = np.array(len(scene.textures))
        for i, px in enumerate(scene.textures):
            d[f"texture_{i}"] = np.asarray(px, np.float32)
        for name in ("interpolation", "extension", "encoding"):
            d["texture_" + name] = np.asarray(getattr(scene, "texture_" + name), np.int32)
    if len(scene.shader_programs):
        # JSON text (no pickles): core/scene/shader_programs.ShaderProgram.to_json, one per program
        d["shader_programs"] = np.array([p.to_json() for p in scene.shader_programs])
    for name in ("corner_generated", "corner_object"):
        if len(getattr(scene, name)):
            d[name] = np.asarray(getattr(scene, name), np.float32)
    attrs = getattr(scene, "corner_attributes", None) or {}
    if attrs:  # names as a text list, arrays by position
        d["corner_attribute_names"] = np.array([str(k) for k in attrs])
        for i, a in enumerate(attrs.values()):
            d[f"corner_attribute_{i}"] = np.asarray(a, np.float32)
    for f in fields(Materials):
        d["material_" + f.name] = getattr(scene.materials, f.name)
    for f in fields(Lights):
        d["light_" + f.name] = getattr(scene.lights, f.name)
    mv = np.asarray(getattr(scene, "motion_vertices", np.zeros((0, 0, 3))), np.float32)
    if mv.size:  # object motion blur: the vertices of each time bin
        d["motion_vertices"] = mv
    if scene.camera is not None:
        for f in fields(Camera):
            val = np.asarray(getattr(scene.camera, f.name))
            if f.name in ("motion", "shutter_table") and val.size == 0:
                continue  # a still camera, a flat shutter: nothing to save (the defaults on load)
            d["camera_" + f.name] = val
    np.savez_compressed(path, **d)


def load_scene(path) -> Scene:
    """Read a scene written by ``save_scene``; a clear one-line SceneError if it is not one
    (missing, a directory, empty, not a .npz archive, a corrupted or missing member).
    The arrays are checked by validation.validate (every render does that)."""
    shown = os.fspath(path) if isinstance(path, (str, bytes, os.PathLike)) else path
    if isinstance(shown, (str, bytes)):
        if not os.path.exists(shown):
            raise SceneError(f"scene file not found: {shown}")
        if os.path.isdir(shown):
            raise SceneError(f"{shown} is a directory, not a scene file")
        if os.path.getsize(shown) == 0:
            raise SceneError(f"{shown} is empty, not a scene file")
    try:
        z = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise SceneError(f"scene file not found: {shown}") from None
    except Exception as e:  # not a zip, truncated, a pickle, unreadable, ...
        raise SceneError(f"cannot read scene file {shown}: {one_line(e)}") from None
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise SceneError(f"{shown} is a single array (.npy), not a scene archive (.npz)")
    with z:
        def read(name):
            try:
                val = z[name]
            except KeyError:
                raise SceneError(f"{shown} has no {name!r} array: not a complete scene file") from None
            except Exception as e:  # zipfile.BadZipFile, zlib.error, EOFError, ValueError, MemoryError, ...
                raise SceneError(f"{shown}: array {name!r} is corrupted or unreadable ({one_line(e)})") from None
            if not isinstance(val, np.ndarray):  # a member not stored as .npy: NpzFile hands back its raw bytes
                raise SceneError(f"{shown}: member {name!r} is not a NumPy array (.npy) but {len(val)} raw bytes")
            return val

        try:
            names = set(z.files)
        except Exception as e:
            raise SceneError(f"cannot read scene file {shown}: {one_line(e)}") from None
        if "format_version" not in names:
            raise SceneError(f"{shown} is not an opal_diffraction scene (no format_version)")
        fv = read("format_version")
        if fv.shape != () or fv.dtype.kind not in "iu":
            raise SceneError(f"{shown}: format_version must be one integer, got {fv.dtype} of shape {fv.shape}")
        ver = int(fv)
        if ver > FORMAT_VERSION:
            raise SceneError(f"{shown} was written by a newer version (format {ver} > {FORMAT_VERSION})")
        cols = {f.name: read("material_" + f.name) for f in fields(Materials) if "material_" + f.name in names}
        kind = cols.get("kind")
        rows = kind.shape[0] if kind is not None and kind.ndim >= 1 else 0
        mats = Materials.from_columns(cols, rows)
        lights = Lights(**{f.name: read("light_" + f.name) for f in fields(Lights) if "light_" + f.name in names})
        for name in _LIGHT_OPTIONAL:  # columns an older file lacks: 0 (delta lights, as they rendered)
            if "light_" + name not in names:
                setattr(lights, name, np.zeros(len(lights), LIGHT_COLUMNS[name][1]))
        cam = None
        if "camera_matrix" in names:
            kw = {}
            for f in fields(Camera):
                if "camera_" + f.name in names:
                    val = read("camera_" + f.name)
                    kw[f.name] = val.item() if val.ndim == 0 else val
            cam = Camera(**kw)
        return Scene(
            vertices=read("vertices"),
            triangles=read("triangles"),
            tri_material=read("tri_material"),
            materials=mats,
            lights=lights,
            camera=cam,
            world_color=read("world_color"),
            tri_tangent=read("tri_tangent") if "tri_tangent" in names else np.zeros((0, 3), np.float32),
            tri_period=read("tri_period") if "tri_period" in names else np.zeros(0, np.float32),
            # older files have no shading normals: flat shading
            corner_normals=read("corner_normals") if "corner_normals" in names else np.zeros((0, 3, 3), np.float32),
            # older files have no world map: a uniform world
            world_image=read("world_image") if "world_image" in names else np.zeros((0, 0, 3), np.float32),
            world_rotation=read("world_rotation") if "world_rotation" in names else np.eye(3),
            **_read_textures(read, names, shown),
            **{name: read(name) for name in _DOMAIN_FIELDS if name in names},
            **({"motion_vertices": read("motion_vertices")} if "motion_vertices" in names else {}),
            # older files have no world volume: none
            **({"world_volume": int(read("world_volume"))} if "world_volume" in names else {}),
        )


def _read_textures(read, names: set, shown) -> dict:
    """The texture fields of a scene file (none in files written before textures existed)."""
    out = {}
    for name in ("corner_uvs", "corner_tangents", "corner_generated", "corner_object"):
        if name in names:
            out[name] = read(name)
    if "corner_attribute_names" in names:
        keys = read("corner_attribute_names")
        if keys.ndim != 1 or keys.dtype.kind != "U":
            raise SceneError(f"{shown}: corner_attribute_names must be a list of names, got {keys.dtype}")
        out["corner_attributes"] = {str(k): read(f"corner_attribute_{i}") for i, k in enumerate(keys)}
    if "shader_programs" in names:
        text = read("shader_programs")
        if text.ndim != 1 or text.dtype.kind != "U":
            raise SceneError(f"{shown}: shader_programs must be a list of JSON texts, got {text.dtype} of shape "
                             f"{text.shape}")
        programs = []
        for i, t in enumerate(text):
            try:
                programs.append(ShaderProgram.from_json(str(t)))
            except (ValueError, TypeError, KeyError, IndexError) as e:
                raise SceneError(f"{shown}: shader program {i} is not a valid program ({one_line(e)})") from None
        out["shader_programs"] = programs
    if "texture_count" in names:
        count = read("texture_count")
        if count.shape != () or count.dtype.kind not in "iu" or not 0 <= int(count) <= 1_000_000:
            raise SceneError(f"{shown}: texture_count must be one integer, got {count.dtype} of shape {count.shape}")
        out["textures"] = [read(f"texture_{i}") for i in range(int(count))]
        for name in ("interpolation", "extension", "encoding"):
            if "texture_" + name in names:
                out["texture_" + name] = read("texture_" + name)
    return out
