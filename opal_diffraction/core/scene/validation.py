"""Scene validation with readable errors: ``validate(scene) -> ValidatedScene``.

Every table column is checked for its dtype, shape, finite values, float32 range and the rules
of its quantity (checks.py holds the limits and the shared checks); a scene that cannot be
rendered raises a one-line SceneError naming the column, the row and the rule. The result is a
clean copy of the scene (canonical dtypes, unit shading normals, degenerate triangles dropped),
the warnings, and the products of validation that prepare reads instead of computing them again
(the triangles' cross products).
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from ..util.geometry import triangle_cross, triangle_normals
from ..spectral.optics import DISPERSION_MODELS, ior_spectrum
from .checks import (COHERENCE_MAX, COORD_LIMIT, DTYPE_WORDS, EMISSION_LIMIT, FLOAT32_MAX, FOV_TAN_MAX, IOR_MAX,
                     MAX_PIXELS, MAX_SIDE, MIN_TRIANGLE_AREA, PERIOD_MAX, SHIFT_MAX, SLIT_COUNT_MAX, TEMPERATURE_MAX,
                     TEMPERATURE_MIN, SceneError, as_column, as_number, check_range, first_row, number_text, one_line,
                     within)
from .shader_programs import program_problems
from .model import (CONDUCTOR_FRESNELS, GLASS_TINTS, LAYER_FACS, GRATING_DIRECTIONS, GRATING_TYPES, LATTICES, LIGHT_COLUMNS, LIGHT_KINDS,
                    MATERIAL_COLUMNS, MATERIAL_KINDS, TEXTURE_COLUMNS, TEXTURE_ENCODINGS, TEXTURE_EXTENSIONS,
                    TEXTURE_INTERPOLATIONS, Camera, Lights, Materials, Scene)

__all__ = ["ValidatedScene", "validate", "BRAGG_RANGES"]

#: Valid ranges of the BRAGG lattice's columns (checked on grating rows with lattice BRAGG).
BRAGG_RANGES = {"sphere_diameter": (100.0, 500.0, " nm"), "sphere_ior": (1.0, 3.0, ""), "void_ior": (1.0, 3.0, ""),
                "layers": (1, 10000, ""), "mosaic_spread": (0.0, 45.0, " degrees")}

#: Unit-interval material columns (validated to [0, 1]).
_UNIT_COLUMNS = ("roughness", "metallic", "transmission", "diffuse_roughness", "holdout", "coat_weight",
                 "coat_roughness", "sheen_weight", "sheen_roughness")

_OBSERVER_NM = (360.0, 830.0)  # the wavelengths any grid may hold (spectrum.py)


@dataclass(frozen=True, eq=False)  # arrays: compared by identity
class ValidatedScene:
    """What ``validate`` returns: the clean scene, the warnings, and validation's products.

    ``triangle_cross`` (T, 3) float64: the clean triangles' edge cross products
    (util.geometry.triangle_cross of the clean vertices and triangles) and ``triangle_cross_norm``
    (T,) float64 their norms (twice the areas), None for a scene without triangles; prepare
    divides them into its normals (in place: it is their only reader) instead of computing them
    a second time.
    """

    scene: Scene
    warnings: list[str]
    triangle_cross: np.ndarray | None = None
    triangle_cross_norm: np.ndarray | None = None


def validate(scene: Scene) -> ValidatedScene:
    """The clean copy of ``scene``, its warnings and validation's products; raise SceneError
    naming what makes it unrenderable.

    Every table column is checked for its dtype (numbers, or integers for indices and
    codes: strings, complex numbers, booleans and objects are errors), its shape (row count
    and per-row shape), finite values, float32 range (the tracer computes in float32) and
    the rules of its quantity; the message names the column, the row and the rule. Dropped
    with a warning: zero-area triangles and triangles too small for float32 ray casting.
    Warned: nothing to render, no light.
    """
    try:
        return _validate(scene)
    except SceneError:
        raise
    except MemoryError:
        raise SceneError("the scene is too large to validate in this machine's memory") from None
    except Exception as e:  # a gap in the checks: still one readable line, never a traceback
        raise SceneError(f"the scene cannot be validated ({type(e).__name__}: {one_line(e)})") from None


def _validate(scene: Scene) -> ValidatedScene:
    warns: list[str] = []
    if scene.camera is None:
        raise SceneError("the scene has no camera: add one and make it the active camera")
    if not isinstance(scene.camera, Camera):
        raise SceneError(f"the scene's camera must be a Camera, got {type(scene.camera).__name__}")
    camera = _validate_camera(scene.camera)
    v = as_column(scene.vertices, "vertices", (3,), allow_empty=True)
    t = as_column(scene.triangles, "triangles", (3,), kind="int", allow_empty=True)
    if not within(v, COORD_LIMIT):  # the full checks only when something is wrong
        v64 = v.astype(np.float64, copy=False)
        bad = ~np.isfinite(v64).all(axis=1)
        if bad.any():
            raise SceneError(
                f"{int(bad.sum())} vertex coordinate(s) are NaN or infinite (first: vertex {int(np.argmax(bad))})"
            )
        check_range(v64, lambda i: f"vertex {i}", "coordinate", " m", limit=COORD_LIMIT)
    v = v if v.dtype == np.float32 else v.astype(np.float32)
    if len(t):
        if t.min() < 0 or t.max() >= len(v):
            i = int(np.argmax((t < 0).any(1) | (t >= len(v)).any(1)))
            raise SceneError(
                f"triangle {i} uses vertex index {t[i].tolist()} but the scene has {len(v)} vertices"
            )
    tm = as_column(scene.tri_material, "tri_material", (), kind="int", allow_empty=len(t) == 0)
    if tm.shape != (len(t),):
        raise SceneError(f"tri_material must have one entry per triangle ({len(t)}), got shape {tm.shape}")
    if not isinstance(scene.materials, Materials):
        raise SceneError(f"the scene's materials must be a Materials table, got {type(scene.materials).__name__}")
    if not isinstance(scene.lights, Lights):
        raise SceneError(f"the scene's lights must be a Lights table, got {type(scene.lights).__name__}")
    materials = _validate_materials(scene.materials)
    nm = len(materials)
    if len(tm) and (tm.min() < 0 or tm.max() >= nm):
        i = int(np.argmax((tm < 0) | (tm >= nm)))
        raise SceneError(f"triangle {i} uses material {int(tm[i])} but the scene has {nm} materials")
    lights = _validate_lights(scene.lights)
    wc = as_column(scene.world_color, "world colour", (), rows=3)
    check_range(wc[None, :], lambda i: "world colour", "value", "", limit=EMISSION_LIMIT, finite_text="world colour is NaN or infinite")
    world_image, world_rotation = _validate_world_image(scene.world_image, scene.world_rotation, wc)

    tt = as_column(scene.tri_tangent, "tri_tangent", (3,), allow_empty=True)
    tp = as_column(scene.tri_period, "tri_period", (), allow_empty=True)
    if len(tt) not in (0, len(t)) or len(tp) not in (0, len(t)):
        raise SceneError(f"tri_tangent / tri_period must have one entry per triangle ({len(t)}) or none")
    if not np.isfinite(tt).all() or not np.isfinite(tp).all() or (tp < 0).any():
        raise SceneError("a per-triangle grating direction or period is NaN, infinite or negative")
    check_range(tt, lambda i: f"triangle {i}", "grating direction", "")
    check_range(tp, lambda i: f"triangle {i}", "grating period", " nm", limit=PERIOD_MAX)
    tt = tt if tt.dtype == np.float32 else tt.astype(np.float32)
    tp = tp if tp.dtype == np.float32 else tp.astype(np.float32)
    tex = _validate_textures(scene, len(t), materials, tm, warns)
    dom = _validate_domains(scene, len(t))
    t = t.astype(np.int32)
    cn = _validate_corner_normals(scene.corner_normals, v, t, warns)
    cross = None
    if len(t):
        cross, area2 = triangle_cross(v, t, with_norm=True)  # area2: np.linalg.norm(cross, axis=1)
        degenerate = area2 <= 0.0
        tiny = ~degenerate & (area2 < 2 * MIN_TRIANGLE_AREA)
        if degenerate.any():
            warns.append(f"dropped {int(degenerate.sum())} degenerate (zero-area) triangle(s)")
        if tiny.any():
            warns.append(f"dropped {int(tiny.sum())} triangle(s) too small for float32 ray casting "
                         f"(area below {MIN_TRIANGLE_AREA:g} m^2)")
        if degenerate.any() or tiny.any():
            keep = ~(degenerate | tiny)
            t, tm, cross, area2 = t[keep], tm[keep], cross[keep], area2[keep]
            tt = tt[keep] if len(tt) else tt
            tp = tp[keep] if len(tp) else tp
            cn = cn[keep] if len(cn) else cn
            dom["tri_domain_group"] = dom["tri_domain_group"][keep] if len(dom["tri_domain_group"]) else \
                dom["tri_domain_group"]
            for name in ("corner_uvs", "corner_tangents", "corner_generated", "corner_object"):  # one row per triangle
                tex[name] = tex[name][keep] if len(tex[name]) else tex[name]
            tex["corner_attributes"] = {k: a[keep] for k, a in tex["corner_attributes"].items()}
    if len(t) == 0:
        warns.append("the scene has no geometry: the image shows only the background")
    # a coloured or mapped world lights the scene, and so does a mesh whose material emits
    emitting = len(t) > 0 and bool(np.any(np.asarray(materials.emission)[np.bincount(tm, minlength=nm) > 0] > 0))
    world_lit = bool(np.any(np.asarray(wc) > 0)) and (world_image.size == 0 or bool(np.any(world_image > 0)))
    if len(lights) == 0 and not world_lit and not emitting:
        warns.append("the scene has no lights: only the background is lit")
    wv = scene.world_volume
    if not isinstance(wv, (int, np.integer)) or isinstance(wv, bool) or not -1 <= int(wv) < nm:
        raise SceneError(f"world_volume must be -1 (none) or a material index below {nm}, got {wv!r}")
    mv = _validate_motion_vertices(scene, len(v))
    clean = replace(scene, world_volume=int(wv), motion_vertices=mv, vertices=v, triangles=t, tri_material=tm.astype(np.int32), tri_tangent=tt, tri_period=tp,
                    materials=materials, lights=lights, camera=camera, world_color=wc, corner_normals=cn,
                    world_image=world_image, world_rotation=world_rotation, **tex, **dom)
    # prepare's normals are these products normalised
    return ValidatedScene(clean, warns, cross, area2 if cross is not None else None)


def _check_volume(f64: dict, label) -> None:
    """The interior medium's columns (docs/physics.md section 15): densities and emission >= 0,
    colours in [0, 1], the anisotropy in [-1, 1]."""
    for name, lo, hi in (("volume_scatter_density", 0.0, np.inf), ("volume_absorption_density", 0.0, np.inf),
                         ("volume_scatter_color", 0.0, 1.0), ("volume_absorption_color", 0.0, 1.0),
                         ("volume_emission", 0.0, np.inf), ("volume_anisotropy", -1.0, 1.0)):
        v = f64[name].reshape(len(f64[name]), -1)
        bad = ((v < lo) | (v > hi)).any(axis=1)
        if bad.any():
            i = int(np.argmax(bad))
            words = f">= {lo:g}" if hi == np.inf else f"between {lo:g} and {hi:g}"
            raise SceneError(f"{label(i)}: {name.replace('_', ' ')} must be {words}, got "
                             f"{', '.join(number_text(x) for x in v[i])}")


def _check_bragg(f64: dict, layers, label) -> None:
    """The BRAGG lattice's columns (docs/physics.md section 5.2): D_s > 0 nm, indices >= 1,
    at least one layer, a mosaic spread of 0-90 degrees."""
    for name, ok, rule in (("sphere_diameter", lambda x: (x > 0) & (x <= PERIOD_MAX), "must be > 0 nm"),
                           ("sphere_ior", lambda x: x >= 1.0, "must be at least 1"),
                           ("void_ior", lambda x: x >= 1.0, "must be at least 1"),
                           ("mosaic_spread", lambda x: (x >= 0.0) & (x <= 90.0), "must be 0-90 degrees")):
        bad = ~ok(f64[name])
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"{label(i)}: {name.replace('_', ' ')} {number_text(f64[name][i])} {rule}")
    lay = np.asarray(layers, np.int64)
    if (lay < 1).any():
        i = int(np.argmax(lay < 1))
        raise SceneError(f"{label(i)}: layers must be at least 1, got {int(lay[i])}")


def _validate_domains(sc, n_tri: int) -> dict:
    """The domain columns checked (shapes, finite, unit axes, positive diameters, groups in range)."""
    s = as_column(sc.domain_seeds, "domain_seeds", (3,), allow_empty=True).astype(np.float64)
    k = len(s)
    w = as_column(sc.domain_weight, "domain_weight", (), rows=k, allow_empty=k == 0).astype(np.float64)
    a = as_column(sc.domain_axis, "domain_axis", (3,), rows=k, allow_empty=k == 0).astype(np.float64)
    d = as_column(sc.domain_diameter, "domain_diameter", (), rows=k, allow_empty=k == 0).astype(np.float64)
    g = as_column(sc.domain_group, "domain_group", (), rows=k, kind="int", allow_empty=k == 0).astype(np.int32)
    tg = as_column(sc.tri_domain_group, "tri_domain_group", (), kind="int", allow_empty=True).astype(np.int32)
    if not np.isfinite(s).all() or not np.isfinite(w).all():
        raise SceneError("an opal domain seed or weight is NaN or infinite")
    check_range(s, lambda i: f"opal domain {i}", "seed", " m", limit=COORD_LIMIT)
    length = np.linalg.norm(a, axis=1)
    bad = ~(np.isfinite(length) & (length > 1e-12))
    if bad.any():
        raise SceneError(f"opal domain {int(np.argmax(bad))}: its (111) axis is zero, NaN or infinite")
    bad = ~(np.isfinite(d) & (d > 0) & (d < PERIOD_MAX))
    if bad.any():
        raise SceneError(f"opal domain {int(np.argmax(bad))}: sphere diameter {d[bad][0]:g} nm must be > 0")
    n_groups = int(g.max()) + 1 if k else 0
    if k and g.min() < 0:
        raise SceneError("opal domain groups must be >= 0")
    if k and len(tg) < n_tri:  # triangles added after the last add_domains have none
        tg = np.concatenate([tg, np.full(n_tri - len(tg), -1, np.int32)])
    if len(tg) not in (0, n_tri) or (len(tg) and (tg.min() < -1 or tg.max() >= n_groups)):
        raise SceneError(f"tri_domain_group must have one entry per triangle ({n_tri}), each -1 or one of the "
                         f"{n_groups} domain groups")
    return {"domain_seeds": s, "domain_weight": w, "domain_axis": (a / np.where(bad, 1.0, length)[:, None]).astype(
        np.float32), "domain_diameter": d.astype(np.float32), "domain_group": g, "tri_domain_group": tg}


def _validate_world_image(image, rotation, world_color) -> tuple[np.ndarray, np.ndarray]:
    """The world map (H, W, 3) float32 (empty: (0, 0, 3)) and its rotation (3, 3) float64, or a
    SceneError: finite, non-negative, within the image size limits, its product with the world
    colour within EMISSION_LIMIT, the rotation orthogonal."""
    try:
        img = np.asarray(image)
    except Exception:
        raise SceneError("world image is not a regular array of numbers") from None
    if img.dtype.kind not in "iuf":
        raise SceneError(f"world image must hold numbers, got {DTYPE_WORDS.get(img.dtype.kind, img.dtype)}")
    if img.size == 0:
        img = np.zeros((0, 0, 3), np.float32)
    else:
        if img.ndim != 3 or img.shape[2] != 3:
            raise SceneError(f"world image must have shape (H, W, 3), got {img.shape}")
        h, w = img.shape[:2]
        if h > MAX_SIDE or w > MAX_SIDE:
            raise SceneError(f"world image {w}x{h}: each side must be at most {MAX_SIDE} pixels")
        if h * w > MAX_PIXELS:
            raise SceneError(f"world image {w}x{h} is {w * h / 1e6:.0f} M pixels, more than the "
                             f"{MAX_PIXELS / 1e6:.0f} M allowed")
        if img.dtype != np.float32:
            with np.errstate(over="ignore", invalid="ignore"):
                if not np.isfinite(img.astype(np.float64)).all() or np.abs(img.astype(np.float64)).max() > FLOAT32_MAX:
                    raise SceneError("world image holds NaN, infinite or float32-overflowing values")
            img = img.astype(np.float32)
        if not np.isfinite(img).all():
            raise SceneError("world image holds NaN or infinite values")
        if (img < 0).any():
            raise SceneError(f"world image holds negative radiance (min {number_text(img.min())})")
        peak = float(img.max()) * float(np.max(world_color))
        if peak > EMISSION_LIMIT:
            raise SceneError(f"world image times the world colour reaches {number_text(peak)}, beyond the renderable "
                             f"limit {EMISSION_LIMIT:g}")
        img = np.ascontiguousarray(img)
    try:
        rot = np.asarray(rotation)
    except Exception:
        raise SceneError("world rotation must be a 3x3 rotation matrix") from None
    if rot.dtype.kind not in "iuf" or rot.shape != (3, 3):
        raise SceneError(f"world rotation must be a 3x3 matrix of numbers, got {rot.dtype} of shape {rot.shape}")
    rot = rot.astype(np.float64)
    if not np.isfinite(rot).all():
        raise SceneError("world rotation is NaN or infinite")
    err = float(np.abs(rot @ rot.T - np.eye(3)).max())
    if err > 1e-4:
        raise SceneError(f"world rotation is not orthonormal (|R R^T - I| = {number_text(err)}): a rotation, "
                         "optionally with a mirror, is expected")
    return img, rot


def _validate_camera(c: Camera) -> Camera:
    try:
        m = np.asarray(c.matrix)
    except Exception:
        raise SceneError("camera matrix must be a finite 4x4 matrix") from None
    if m.dtype.kind not in "iuf":
        raise SceneError(f"camera matrix must hold numbers, got {DTYPE_WORDS.get(m.dtype.kind, m.dtype)}")
    m = m.astype(np.float64)
    if m.shape != (4, 4) or not np.isfinite(m).all():
        raise SceneError("camera matrix must be a finite 4x4 matrix")
    if np.abs(m[3] - (0.0, 0.0, 0.0, 1.0)).max() > 1e-6:
        raise SceneError(f"camera matrix: the bottom row must be (0, 0, 0, 1) (an affine transform), got "
                         f"{[float(x) for x in m[3]]}")
    if np.abs(m[:3, 3]).max() > COORD_LIMIT:
        raise SceneError(f"camera position {number_text(np.abs(m[:3, 3]).max())} m is beyond the renderable limit "
                         f"{COORD_LIMIT:g} m")
    if np.abs(m[:3, :3]).max() > COORD_LIMIT:
        raise SceneError("camera matrix: its scale is beyond the renderable limit")
    if abs(np.linalg.det(m[:3, :3])) < 1e-12:
        raise SceneError("camera matrix is singular (zero scale?)")
    for name, allowed in (("kind", ("PERSP", "ORTHO", "PANO")), ("sensor_fit", ("AUTO", "HORIZONTAL", "VERTICAL")),
                          ("panorama_type", PANORAMA_TYPES)):
        val = getattr(c, name)
        if not isinstance(val, str) or val not in allowed:
            what = {"kind": "camera type", "sensor_fit": "camera sensor fit"}.get(name, "camera panorama type")
            raise SceneError(f"{what} {val!r} is not supported ({' or '.join(allowed)})")
    w = as_number(c.width, "image width", integer=True)
    h = as_number(c.height, "image height", integer=True)
    if w < 1 or h < 1:
        raise SceneError(f"image resolution must be at least 1x1, got {c.width}x{c.height}")
    if w > MAX_SIDE or h > MAX_SIDE:
        raise SceneError(f"image resolution {w}x{h}: each side must be at most {MAX_SIDE} pixels")
    if w * h > MAX_PIXELS:
        raise SceneError(f"image resolution {w}x{h} is {w * h / 1e6:.0f} M pixels, more than the "
                         f"{MAX_PIXELS / 1e6:.0f} M a render allows")
    vals = {}
    for name in ("lens", "sensor_width", "sensor_height", "ortho_scale"):
        val = as_number(getattr(c, name), f"camera {name}")
        if not val > 0:
            raise SceneError(f"camera {name} must be > 0, got {val}")
        if val > FLOAT32_MAX:
            raise SceneError(f"camera {name} {number_text(val)} overflows float32 (max 3.4e38)")
        vals[name] = val
    for name in ("shift_x", "shift_y"):
        val = as_number(getattr(c, name), f"camera {name}")
        if abs(val) > SHIFT_MAX:
            raise SceneError(f"camera {name} {number_text(val)} is beyond +-{SHIFT_MAX:g} (a fraction of the image)")
        vals[name] = val
    if c.kind == "PERSP":
        for sensor in ("sensor_width", "sensor_height"):
            tan_half = vals[sensor] / vals["lens"] / 2
            if tan_half > FOV_TAN_MAX:
                raise SceneError(f"camera field of view too wide: {sensor} / lens = {number_text(2 * tan_half)} "
                                 f"(at most {2 * FOV_TAN_MAX:g})")
    elif vals["ortho_scale"] > COORD_LIMIT:
        raise SceneError(f"camera ortho_scale {number_text(vals['ortho_scale'])} m is beyond the renderable limit "
                         f"{COORD_LIMIT:g} m")
    lens = _validate_lens(c)
    _validate_motion(c)
    same = (w == c.width and type(c.width) is int and h == c.height and type(c.height) is int
            and type(c.kind) is str and type(c.sensor_fit) is str
            and all(type(getattr(c, k)) is type(v) and getattr(c, k) == v for k, v in lens.items()))
    return c if same else replace(c, width=w, height=h, kind=str(c.kind), sensor_fit=str(c.sensor_fit), **lens)


PANORAMA_TYPES = ("EQUIRECTANGULAR", "FISHEYE_EQUIDISTANT", "FISHEYE_EQUISOLID")


#: time bins of object motion a scene may hold
MAX_MOTION_BINS = 64


def _validate_motion_vertices(scene, n_vertices: int) -> np.ndarray:
    """The object-motion vertices (K, V, 3) float32 (docs/physics.md section 6.13): empty, or 2 to
    MAX_MOTION_BINS bins of as many finite vertices as the scene has."""
    mv = np.asarray(getattr(scene, "motion_vertices", np.zeros((0, 0, 3))))
    if mv.size == 0:
        return np.zeros((0, 0, 3), np.float32)
    if mv.dtype.kind not in "iuf":
        raise SceneError(f"motion_vertices must hold real numbers, got {mv.dtype}")
    if mv.ndim != 3 or mv.shape[1:] != (n_vertices, 3) or not 2 <= mv.shape[0] <= MAX_MOTION_BINS:
        raise SceneError(f"motion_vertices must be (2 to {MAX_MOTION_BINS} bins, {n_vertices} vertices, 3), "
                         f"got shape {mv.shape}")
    mv = mv.astype(np.float32)
    if not np.isfinite(mv).all():
        raise SceneError("motion_vertices: a vertex is NaN or infinite (or beyond float32)")
    return mv


def _validate_motion(c: Camera) -> None:
    """The camera's motion blur (docs/physics.md section 6.13): no steps or at least two finite,
    invertible 4x4 matrices; the shutter table empty or finite, non-decreasing, within [0, 1]."""
    m = np.asarray(getattr(c, "motion", np.zeros((0, 4, 4))))
    t = np.asarray(getattr(c, "shutter_table", np.zeros(0)))
    for name, a in (("motion", m), ("shutter_table", t)):
        if a.size and a.dtype.kind not in "iuf":
            raise SceneError(f"camera {name} must hold real numbers, got {a.dtype}")
    m = m.astype(np.float64)
    if m.size:
        if m.ndim != 3 or m.shape[1:] != (4, 4) or m.shape[0] < 2 or m.shape[0] > 1024:
            raise SceneError(f"camera motion must be 2 to 1024 4x4 matrices, got shape {m.shape}")
        if not np.isfinite(m).all():
            raise SceneError("camera motion: a step's matrix is NaN or infinite")
        if (np.abs(np.linalg.det(m[:, :3, :3].astype(np.float64))) < 1e-12).any():
            raise SceneError("camera motion: a step's matrix is singular (zero scale?)")
    t = t.astype(np.float64)
    if t.size:
        if t.ndim != 1 or t.size < 2 or not np.isfinite(t).all() or (t < 0).any() or (t > 1).any() \
                or (np.diff(t) < 0).any():
            raise SceneError("camera shutter_table must be a non-decreasing list of at least 2 times in [0, 1]")


def _validate_lens(c: Camera) -> dict:
    """The thin lens, clipping and panorama fields of a camera (docs/physics.md sections 6.7-6.9), as
    clean Python numbers; SceneError naming the first bad one."""
    out = {}
    for name in ("aperture_radius", "focus_distance", "aperture_rotation", "aperture_ratio", "clip_start",
                 "fisheye_fov", "fisheye_lens", "latitude_min", "latitude_max", "longitude_min", "longitude_max"):
        val = as_number(getattr(c, name), f"camera {name}")
        if not np.isfinite(val) or abs(val) > FLOAT32_MAX:
            raise SceneError(f"camera {name} must be a finite number (within float32), got {number_text(val)}")
        out[name] = float(val)
    end = c.clip_end
    if isinstance(end, np.ndarray) and end.ndim == 0:
        end = end.item()
    # clip_end may be +inf (no far clipping, the core's default); any other value a finite number
    out["clip_end"] = np.inf if isinstance(end, (float, np.floating)) and end == np.inf else \
        float(as_number(end, "camera clip_end"))
    if np.isfinite(out["clip_end"]) and out["clip_end"] > FLOAT32_MAX:
        raise SceneError(f"camera clip_end {number_text(out['clip_end'])} m overflows float32 (max 3.4e38; inf: no far clip)")
    out["aperture_blades"] = int(as_number(c.aperture_blades, "camera aperture_blades", integer=True))
    if out["aperture_radius"] < 0 or out["aperture_radius"] > COORD_LIMIT:
        raise SceneError(f"camera aperture_radius {number_text(out['aperture_radius'])} m must be in [0, {COORD_LIMIT:g}]")
    if out["aperture_radius"] > 0 and not 0 < out["focus_distance"] <= COORD_LIMIT:
        raise SceneError(f"camera focus_distance {number_text(out['focus_distance'])} m must be > 0 (and at most "
                         f"{COORD_LIMIT:g}) with depth of field")
    if not 0 < out["aperture_ratio"] <= 1e6:
        raise SceneError(f"camera aperture_ratio {number_text(out['aperture_ratio'])} must be > 0")
    if not 0 <= out["aperture_blades"] <= 1024:
        raise SceneError(f"camera aperture_blades {out['aperture_blades']} must be in [0, 1024]")
    if out["clip_start"] < 0:
        raise SceneError(f"camera clip_start {number_text(out['clip_start'])} m must be >= 0")
    if not out["clip_end"] > out["clip_start"]:
        raise SceneError(f"camera clip_end {number_text(out['clip_end'])} m must be beyond clip_start "
                         f"{number_text(out['clip_start'])} m")
    if c.kind == "PANO":
        if not 0 < out["fisheye_fov"] <= 2 * np.pi:
            raise SceneError(f"camera fisheye_fov {number_text(out['fisheye_fov'])} rad must be in (0, 2 pi]")
        if not out["fisheye_lens"] > 0:
            raise SceneError(f"camera fisheye_lens {number_text(out['fisheye_lens'])} mm must be > 0")
        for lo, hi in (("latitude_min", "latitude_max"), ("longitude_min", "longitude_max")):
            if not out[lo] < out[hi]:
                raise SceneError(f"camera {lo} {number_text(out[lo])} must be below {hi} {number_text(out[hi])}")
    return out


def _clean_float(a: np.ndarray, canonical) -> np.ndarray:
    """Float columns keep their float32/float64 dtype (the values the caller gave); others
    (integers, float16, longdouble) become the canonical dtype."""
    return a if a.dtype in (np.float32, np.float64) else a.astype(canonical)


def _enum_check(col: np.ndarray, enum: dict, label, what: str) -> None:
    bad = ~np.isin(col, list(enum.values()))
    if bad.any():
        i = int(np.argmax(bad))
        names = ", ".join(f"{v}={k}" for k, v in enum.items())
        raise SceneError(f"{label(i)}: {what} code {int(col[i])} is not one of {names}")


def _material_label(names):
    def label(i):
        try:
            return f"material {i} {str(names[i])!r}"
        except Exception:
            return f"material {i}"
    return label


def _check_row_counts(table, what: str, n: int) -> None:
    """Every column of a material or light table has ``n`` rows (SceneError naming the column)."""
    for f in fields(table):
        try:
            rows = len(getattr(table, f.name))
        except TypeError:
            rows = None
        if rows != n:
            raise SceneError(f"{what} table column {f.name!r} has {rows if rows is not None else 'no'} rows, "
                             f"expected {n}")


_ROWS_PER_CHUNK = 1 << 14  # rows of per-corner data normalised at a time (a few MB: in cache)


def _validate_corner_normals(value, v: np.ndarray, t: np.ndarray, warns: list) -> np.ndarray:
    """Scene.corner_normals: (T, 3, 3) finite, or empty (flat). Returned unit length in float32;
    a zero normal falls back to its triangle's face normal (one warning for all of them)."""
    cn = as_column(value, "corner_normals", (3, 3), allow_empty=True)
    if len(cn) == 0:
        return np.zeros((0, 3, 3), np.float32)
    if len(cn) != len(t):
        raise SceneError(f"corner_normals must have one (3, 3) entry per triangle ({len(t)}) or none, got {len(cn)}")
    check_range(cn.reshape(len(cn), 9), lambda i: f"triangle {i}", "shading normal", "")
    # normalised in float64 in chunks of rows (the same values as over the whole array at once,
    # without (T, 3, 3) float64 temporaries), chunks small enough to stay in cache; the length is sqrt((x^2 + y^2) + z^2), the order
    # np.linalg.norm's reduction adds in (the same values, tests/test_prepare_scale.py)
    out = np.empty(cn.shape, np.float32)
    n_zero = 0
    for s in range(0, len(cn), _ROWS_PER_CHUNK):
        c64 = cn[s:s + _ROWS_PER_CHUNK].astype(np.float64)
        sq = c64 * c64
        length = sq[..., 0] + sq[..., 1]
        length += sq[..., 2]
        del sq
        length = np.sqrt(length, out=length)[..., None]
        zero = ~(length > 1e-30)
        if zero.any():
            tc = t[s:s + _ROWS_PER_CHUNK]  # the chunk's corners only (not all V vertices in float64)
            face = triangle_normals(v[tc.reshape(-1)], np.arange(tc.size).reshape(-1, 3))
            # degenerate triangles (zero face normal) are dropped later: no warning for them
            n_zero += int((zero[:, :, 0] & (np.abs(face).max(axis=1) > 0)[:, None]).sum())
            c64 = np.where(zero, face[:, None, :], c64)
            length = np.where(zero, 1.0, length)
        np.divide(c64, length, out=c64)
        out[s:s + _ROWS_PER_CHUNK] = c64
    if n_zero:
        warns.append(f"{n_zero} zero shading normal(s): their triangles' face normals are used there")
    return out


def _validate_materials(m: Materials) -> Materials:
    # the row count comes from the kind column; every column must have that many rows and its per-row shape
    kind = as_column(m.kind, "material table column 'kind'", (), kind="int", allow_empty=True)
    n = len(kind)
    _check_row_counts(m, "material", n)
    try:
        names = np.asarray(m.name)
    except Exception:
        names = None
    if names is None or names.shape != (n,) or not (names.dtype.kind in "US" or
                                                     (names.dtype.kind == "O" and all(isinstance(x, str) for x in names))):
        raise SceneError(f"material table column 'name' must hold {n} strings, got "
                         f"{'shape ' + str(names.shape) + ' of ' + str(names.dtype) if names is not None else 'no array'}")
    label = _material_label(names)
    out = {"name": m.name, "kind": kind}
    for name, (dtype, tail, _default, enum) in MATERIAL_COLUMNS.items():
        if name in ("name", "kind"):
            continue
        is_int = np.dtype(dtype).kind == "i"
        col = as_column(getattr(m, name), f"material table column {name!r}", tail, rows=n,
                      kind=("flag" if name == "grating" else "int") if is_int else "float", allow_empty=n == 0)
        out[name] = col
    if n == 0:
        return m if all(out[k] is getattr(m, k) for k in out) else Materials(**out)
    _enum_check(kind, MATERIAL_KINDS, label, "kind")
    _enum_check(out["dispersion"], DISPERSION_MODELS, label, "dispersion")
    for name, enum in (("grating_type", GRATING_TYPES), ("lattice", LATTICES), ("grating_direction", GRATING_DIRECTIONS),
                       ("conductor_fresnel", CONDUCTOR_FRESNELS), ("glass_tint", GLASS_TINTS),
                       ("layer_fac", LAYER_FACS)):
        _enum_check(out[name], enum, label, name.replace("_", " "))
    g = out["grating"].astype(np.int64)
    bad = (g != 0) & (g != 1)
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"{label(i)}: grating flag must be 0 or 1, got {int(g[i])}")
    f64 = {name: out[name].astype(np.float64) for name in out
           if name != "name" and np.dtype(MATERIAL_COLUMNS[name][0]).kind == "f"}
    # every float column: finite and within float32
    for name in ("color", "emission", "ior", "abbe", "period", "slit_width", "coherence_length", "rotation",
                 "normal_strength", "emission_strength", "roughness", "metallic", "transmission",
                 "specular_ior_level", "specular_tint", "sphere_diameter", "sphere_ior", "void_ior", "mosaic_spread",
                 "thin_film_thickness", "thin_film_ior", "metal_color", "glass_color", "layer_fac_value",
                 "diffuse_roughness", "holdout", "volume_scatter_density", "volume_scatter_color",
                 "volume_absorption_density", "volume_absorption_color", "volume_anisotropy", "volume_emission",
                 "coat_weight", "coat_roughness", "coat_ior", "coat_tint", "sheen_weight", "sheen_roughness",
                 "sheen_tint"):
        check_range(f64[name], label, name.replace("_", " "), "")
    _check_volume(f64, label)
    for name in ("layer_fac_from", "layer_fac_to"):
        code = out[name].astype(np.int64)
        bad = (code < 0) | (code > 2)
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"{label(i)}: {name.replace('_', ' ')} {int(code[i])} is not a layer (0 base, 1 metal, "
                             f"2 glass)")
    bad = (out["layer_fac"] != LAYER_FACS["CONSTANT"]) & (out["layer_fac_from"] == out["layer_fac_to"])
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"{label(i)}: a per-hit layer mix needs two different layers")
    film_d, film_n = f64["thin_film_thickness"], f64["thin_film_ior"]
    bad = film_d < 0
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"{label(i)}: thin film thickness must be >= 0 nm, got {number_text(film_d[i])}")
    bad = (film_d > 0) & ~((film_n >= 1.0) & (film_n <= IOR_MAX))
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"{label(i)}: thin film IOR must be between 1 and {IOR_MAX:g}, got {number_text(film_n[i])}")
    for name in TEXTURE_COLUMNS:
        bad = out[name].astype(np.int64) < -1
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"{label(i)}: {name.replace('_', ' ')} {int(out[name][i])} is not a texture index "
                             f"(-1: none)")
    bad = out["shader_program"].astype(np.int64) < -1
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"{label(i)}: shader program {int(out['shader_program'][i])} is not a program index (-1: none)")
    for name in ("roughness_channel", "metallic_channel"):
        ch = out[name].astype(np.int64)
        bad = (ch < -1) | (ch > 3)
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"{label(i)}: {name.replace('_', ' ')} {int(ch[i])} is not -1 (luminance) or 0-3 "
                             f"(R, G, B, alpha)")
    es = f64["emission_strength"]
    if (es < 0).any():
        i = int(np.argmax(es < 0))
        raise SceneError(f"{label(i)}: emission strength {number_text(es[i])} is negative")
    check_range(es, label, "emission strength", "", limit=EMISSION_LIMIT)
    for name in _UNIT_COLUMNS:
        bad = ~((f64[name] >= 0.0) & (f64[name] <= 1.0))
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"{label(i)}: {name} must be between 0 and 1, got {number_text(f64[name][i])}")
    for name in ("specular_ior_level", "specular_tint", "coat_tint", "sheen_tint"):
        check_range(f64[name], label, name.replace("_", " "), "", nonneg=True)
    coat_ior = f64["coat_ior"]
    bad = (f64["coat_weight"] > 0) & ~((coat_ior >= 1.0) & (coat_ior <= IOR_MAX))
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"{label(i)}: coat IOR must be between 1 and {IOR_MAX:g}, got {number_text(coat_ior[i])}")
    em = f64["emission"]
    if (em < 0).any():
        i = first_row(em < 0)
        raise SceneError(f"{label(i)}: emission {em[i].tolist()} is negative")
    check_range(em, label, "emission", "", limit=EMISSION_LIMIT)
    k = kind
    # the IOR is read by glass and by a specular layer
    diel = k == MATERIAL_KINDS["DIELECTRIC"]
    uses_ior = diel | (f64["transmission"] > 0) | (f64["specular_ior_level"] > 0)
    ior = f64["ior"]
    bad_ior = uses_ior & ~((ior >= 1.0) & (ior <= IOR_MAX))
    if bad_ior.any():
        i = int(np.argmax(bad_ior))
        if ior[i] < 1.0:
            raise SceneError(f"{label(i)}: IOR must be >= 1, got {float(ior[i])}")
        raise SceneError(f"{label(i)}: IOR {number_text(ior[i])} is above {IOR_MAX:g}")
    abbe_rows = diel & (out["dispersion"] == DISPERSION_MODELS["ABBE"])
    abbe = f64["abbe"]
    bad = abbe_rows & ~(abbe > 0)
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"{label(i)}: Abbe dispersion needs an Abbe number > 0")
    for i in np.flatnonzero(abbe_rows):  # loop over Abbe glasses (a few): the index must stay in [1, IOR_MAX]
        n_ends = ior_spectrum(np.array(_OBSERVER_NM), "ABBE", float(ior[i]), float(abbe[i]))
        if not (np.isfinite(n_ends).all() and n_ends.min() >= 1.0 and n_ends.max() <= IOR_MAX):
            raise SceneError(f"{label(i)}: Abbe number {number_text(abbe[i])} with IOR {number_text(ior[i])} gives an index of "
                             f"{number_text(n_ends[1])} at {_OBSERVER_NM[1]:g} nm and {number_text(n_ends[0])} at "
                             f"{_OBSERVER_NM[0]:g} nm, outside 1-{IOR_MAX:g} (use a larger Abbe number)")
    bragg = (g != 0) & (out["lattice"] == LATTICES["BRAGG"])
    for col, (lo, hi, unit) in BRAGG_RANGES.items():
        val = out[col].astype(np.float64)
        bad = bragg & ~((val >= lo) & (val <= hi))
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"{label(i)}: opal {col.replace('_', ' ')} must be between {lo:g} and {hi:g}{unit}, "
                             f"got {number_text(val[i])}")
    _check_bragg(f64, out["layers"], label)  # every row (a BRAGG row has been held to its ranges above)
    on = (g != 0) & ~bragg  # the surface-grating columns (a BRAGG layer does not read them)
    for col, what, unit, limit in (("period", "period", " nm", PERIOD_MAX), ("slit_width", "slit width", " nm", PERIOD_MAX),
                                   ("coherence_length", "coherence length", " um", COHERENCE_MAX)):
        val = f64[col]
        bad = on & ~(val > 0)
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"{label(i)}: grating {what} must be > 0, got {float(val[i])}")
        bad = on & (val > limit)
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"{label(i)}: grating {what} {number_text(val[i])}{unit} is above {limit:g}{unit}")
    bad = on & (f64["slit_width"] > f64["period"])
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"{label(i)}: grating slit width {float(out['slit_width'][i])} nm is larger "
                         f"than the period {float(out['period'][i])} nm")
    sc = out["slit_count"].astype(np.int64)
    bad = on & ((sc < 1) | (sc > SLIT_COUNT_MAX))
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"{label(i)}: grating slit count must be >= 1 and <= {SLIT_COUNT_MAX}, got {int(sc[i])}")
    clean = {}
    for name, col in out.items():
        dtype = MATERIAL_COLUMNS[name][0]
        if name == "name":
            clean[name] = col
        elif np.dtype(dtype).kind == "f":
            clean[name] = _clean_float(col, dtype)
        else:
            clean[name] = col if col.dtype == dtype else col.astype(dtype)
    if all(clean[f.name] is getattr(m, f.name) for f in fields(Materials)):
        return m
    return Materials(**clean)


def _validate_textures(scene: Scene, n_tri: int, materials: Materials, tri_material: np.ndarray,
                       warns: list) -> dict:
    """The texture fields of ``scene`` checked (docs/physics.md section 13): every image (H, W, 4)
    of finite numbers within float32 and MAX_SIDE / MAX_PIXELS, the codes, per-corner UVs and
    tangents (T, 3, 2) / (T, 3, 4) or none, and the materials' texture indices within the list.
    Returns the clean fields (the given arrays where nothing needed converting); warns where a
    used texture has no UVs or a normal map no tangents."""
    raw = scene.textures
    if raw is None:
        raw = []
    if isinstance(raw, np.ndarray) and raw.ndim == 4:  # one stacked array: a list of its images
        raw = list(raw)
    if not isinstance(raw, (list, tuple)):
        raise SceneError(f"the scene's textures must be a list of (H, W, 4) images, got {type(raw).__name__}")
    images, same = [], isinstance(raw, list)
    for i, px in enumerate(raw):
        try:
            a = np.asarray(px)
        except Exception:
            raise SceneError(f"texture {i} is not a regular array of numbers") from None
        if a.dtype.kind not in "iuf":
            raise SceneError(f"texture {i} must hold numbers, got {DTYPE_WORDS.get(a.dtype.kind, str(a.dtype))} "
                             f"({a.dtype})")
        if a.ndim != 3 or a.shape[2] != 4:
            raise SceneError(f"texture {i} must have shape (height, width, 4) (RGBA), got {a.shape}")
        h, w = a.shape[:2]
        if h < 1 or w < 1:
            raise SceneError(f"texture {i} is empty ({w}x{h} pixels)")
        if h > MAX_SIDE or w > MAX_SIDE or h * w > MAX_PIXELS:
            raise SceneError(f"texture {i} is {w}x{h} pixels: each side must be at most {MAX_SIDE} and the "
                             f"image at most {MAX_PIXELS / 1e6:.0f} M pixels")
        a32 = a if a.dtype == np.float32 else a.astype(np.float32)
        finite = np.isfinite(a32)
        if not finite.all():
            j = int(np.argmax(~finite.reshape(-1))) // 4
            what = "overflows float32 (max 3.4e38)" if np.isfinite(a).all() else "is NaN or infinite"
            raise SceneError(f"texture {i}: pixel ({j % w}, {j // w}) {what}")
        same = same and a32 is px
        images.append(a32)
    k = len(images)
    out = {"textures": raw if same else images}
    for name, table, default in (("interpolation", TEXTURE_INTERPOLATIONS, "LINEAR"),
                                 ("extension", TEXTURE_EXTENSIONS, "REPEAT"), ("encoding", TEXTURE_ENCODINGS, "LINEAR")):
        what = f"texture_{name}"
        col = as_column(getattr(scene, what), what, (), kind="int", allow_empty=True)
        if len(col) == 0 and k:
            col = np.full(k, table[default], np.int32)
        if len(col) != k:
            raise SceneError(f"{what} must have one code per texture ({k}), got {len(col)}")
        _enum_check(col, table, lambda i: f"texture {i}", name)
        out[what] = col if col.dtype == np.int32 else col.astype(np.int32)
    for name, width in (("corner_uvs", 2), ("corner_tangents", 4), ("corner_generated", 3), ("corner_object", 3)):
        a = as_column(getattr(scene, name), name, (3, width), allow_empty=True)
        if len(a) not in (0, n_tri):
            raise SceneError(f"{name} must have one row of 3 corners per triangle ({n_tri}) or none, got {len(a)}")
        if a.size and not within(a):
            bad = ~np.isfinite(a.astype(np.float64))
            if bad.any():
                raise SceneError(f"{name}: triangle {first_row(bad)} has a NaN or infinite value")
            check_range(a.astype(np.float64), lambda i: f"triangle {i}", name.replace("_", " ")[:-1], "")
        out[name] = a if a.dtype == np.float32 else a.astype(np.float32)
    attrs = getattr(scene, "corner_attributes", None) or {}
    if not isinstance(attrs, dict):
        raise SceneError(f"corner_attributes must be a dict of name -> (T, 3, 4) arrays, got {type(attrs).__name__}")
    out["corner_attributes"] = {}
    for key, arr in attrs.items():
        what = f"corner attribute {key!r}"
        a = as_column(arr, what, (3, 4), allow_empty=True)
        if len(a) != n_tri:
            raise SceneError(f"{what} must have one row of 3 corners per triangle ({n_tri}), got {len(a)}")
        if a.size and not np.isfinite(a.astype(np.float64)).all():
            bad = ~np.isfinite(a.astype(np.float64))
            raise SceneError(f"{what}: triangle {first_row(bad)} has a NaN or infinite value")
        out["corner_attributes"][str(key)] = a if a.dtype == np.float32 else a.astype(np.float32)
    label = _material_label(materials.name)
    used = np.zeros(len(materials), bool)
    if len(tri_material):  # validated: 0 <= tri_material < len(materials)
        used |= np.bincount(tri_material, minlength=len(materials))[:len(materials)] > 0
    for col in TEXTURE_COLUMNS:
        idx = np.asarray(getattr(materials, col)).astype(np.int64)
        bad = idx >= k
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"{label(i)}: {col.replace('_', ' ')} {int(idx[i])} but the scene has {k} texture(s)")
        rows = np.flatnonzero(used & (idx >= 0))
        if rows.size and not len(out["corner_uvs"]):
            warns.append(f"{label(int(rows[0]))} has image textures but the scene has no UVs: they are read at "
                         "UV (0, 0), as Cycles reads them without a UV map")
        if col == "normal_texture" and rows.size and not len(out["corner_tangents"]):
            warns.append(f"{label(int(rows[0]))} has a normal map but the scene has no tangents: the normal map is "
                         "ignored, as Cycles does without tangents")
    out["shader_programs"] = _validate_programs(scene, materials, used, out, label, warns)
    return out


def _validate_programs(scene: Scene, materials: Materials, used: np.ndarray, corners: dict, label,
                       warns: list) -> list:
    """The shader programs (docs/physics.md section 13.6): a list of ShaderProgram, each passing
    ``program_problems``, bound by materials within the list; a used program reading
    coordinates the scene lacks reads (0, 0, 0) (a warning)."""
    raw = scene.shader_programs
    raw = [] if raw is None else raw
    if not isinstance(raw, (list, tuple)):
        raise SceneError(f"the scene's shader programs must be a list, got {type(raw).__name__}")
    idx = np.asarray(materials.shader_program).astype(np.int64)
    for i, prog in enumerate(raw):
        problem = program_problems(prog)
        if problem is not None:
            users = np.flatnonzero(idx == i)
            who = label(int(users[0])) + ": its shader program" if users.size else f"shader program {i}"
            raise SceneError(f"{who}{f' ({prog.name!r})' if getattr(prog, 'name', '') else ''}: {problem}")
    bad = idx >= len(raw)
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"{label(i)}: shader program {int(idx[i])} but the scene has {len(raw)} program(s)")
    k = len(corners["textures"])
    for i, prog in enumerate(raw):
        if prog.images() and max(prog.images()) >= k:
            raise SceneError(f"shader program {i}: it samples texture {max(prog.images())} but the scene has {k} "
                             "texture(s)")
    have = {"generated": len(corners["corner_generated"]), "object": len(corners["corner_object"]),
            "uv": len(corners["corner_uvs"])}
    for m in np.flatnonzero(used & (idx >= 0)):
        missing = sorted(k for k in raw[idx[m]].reads() if not have[k])
        if missing:
            warns.append(f"{label(int(m))}: its shader program reads {', '.join(missing)} coordinates the scene does "
                         "not have: they read (0, 0, 0)")
        absent = sorted(a for a in raw[idx[m]].attributes() if a not in corners["corner_attributes"])
        if absent:
            warns.append(f"{label(int(m))}: its shader program reads the attribute(s) {', '.join(map(repr, absent))} "
                         "the scene does not have: they read (0, 0, 0), as in Cycles")
    return list(raw)


#: The light table's 0/1 columns.
_FLAG_COLUMNS = ("soft_falloff", "camera_visible")


def _validate_lights(lt: Lights) -> Lights:
    kind = as_column(lt.kind, "light table column 'kind'", (), kind="int", allow_empty=True)
    n = len(kind)
    _check_row_counts(lt, "light", n)
    out = {"kind": kind}
    for name, (tail, _dtype) in LIGHT_COLUMNS.items():
        if name != "kind":
            out[name] = as_column(getattr(lt, name), f"light table column {name!r}", tail, rows=n, allow_empty=n == 0,
                                **({"kind": "int"} if name in _FLAG_COLUMNS else {}))
    if n == 0:
        return lt if all(out[k] is getattr(lt, k) for k in out) else Lights(**{
            k: v if v.dtype == LIGHT_COLUMNS[k][1] else v.astype(LIGHT_COLUMNS[k][1]) for k, v in out.items()})

    def label(i):
        return f"light {i}"

    _enum_check(kind, LIGHT_KINDS, label, "kind")
    f64 = {name: out[name].astype(np.float64) for name in out if name != "kind" and name not in _FLAG_COLUMNS}
    units = {"position": " m", "power": " W", "size_u": " m", "size_v": " m", "temperature": " K", "radius": " m",
             "angle": " rad"}
    for name in ("position", "direction", "axis_u", "color", "power", "temperature", "spot_size", "spot_blend",
                 "size_u", "size_v", "radius", "angle"):
        a = f64[name]
        if not np.isfinite(a).all():
            i = first_row(~np.isfinite(a))
            raise SceneError(f"light {i}: {name.replace('_', ' ')} is NaN or infinite")
        limit = COORD_LIMIT if name in ("position", "size_u", "size_v", "radius") else None
        check_range(a, label, name.replace("_", " "), units.get(name, ""), limit=limit)
    power = f64["power"]
    if (power < 0).any():
        raise SceneError(f"light {int(np.argmax(power < 0))}: power must be >= 0, got {number_text(power[power < 0][0])}")
    dn = np.linalg.norm(f64["direction"], axis=1)
    if (dn < 1e-12).any():
        i = int(np.argmax(dn < 1e-12))
        raise SceneError(f"light {i}: direction {f64['direction'][i].tolist()} is a zero vector")
    temp = f64["temperature"]
    bad = (temp != 0) & ~((temp >= TEMPERATURE_MIN) & (temp <= TEMPERATURE_MAX))
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"light {i}: temperature {number_text(temp[i])} K is outside {TEMPERATURE_MIN:g}-{TEMPERATURE_MAX:g} K "
                         f"(0: use the light's colour)")
    spot = kind == LIGHT_KINDS["SPOT"]
    bad = spot & ~((f64["spot_size"] >= 0) & (f64["spot_size"] <= np.pi + 1e-6))
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"light {i}: spot size {number_text(f64['spot_size'][i])} rad is outside 0-pi")
    bad = spot & ~((f64["spot_blend"] >= 0) & (f64["spot_blend"] <= 1 + 1e-6))
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"light {i}: spot blend {number_text(f64['spot_blend'][i])} is outside 0-1")
    point = np.isin(kind, [LIGHT_KINDS["POINT"], LIGHT_KINDS["SPOT"]])
    bad = point & (f64["radius"] < 0)
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"light {i}: radius {number_text(f64['radius'][i])} m is negative")
    sun = kind == LIGHT_KINDS["SUN"]
    bad = sun & ~((f64["angle"] >= 0) & (f64["angle"] <= np.pi + 1e-6))
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"light {i}: sun angle {number_text(f64['angle'][i])} rad is outside 0-pi")
    for name in _FLAG_COLUMNS:
        sf = out[name].astype(np.int64)
        bad = (sf != 0) & (sf != 1)
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"light {i}: {name.replace('_', ' ')} must be 0 or 1, got {int(sf[i])}")
    su, sv = f64["size_u"], f64["size_v"]
    rect, disk = kind == LIGHT_KINDS["AREA_RECT"], kind == LIGHT_KINDS["AREA_DISK"]
    area_rows = rect | disk
    bad = area_rows & ((su <= 0) | (sv <= 0))
    if bad.any():
        i = int(np.argmax(bad))
        raise SceneError(f"light {i}: an area light has a zero or negative size ({number_text(su[i])} x {number_text(sv[i])} m)")
    area = np.where(rect, su * sv, np.where(disk, np.pi * su * sv / 4, 0.0))
    tiny = area_rows & (area < float(np.finfo(np.float32).tiny))
    if tiny.any():
        i = int(np.argmax(tiny))
        raise SceneError(f"light {i}: area {number_text(area[i])} m^2 underflows float32 (min 1.2e-38)")
    # what the light emits, before its spectrum's shape: W/sr, W/m^2 or W/m^2/sr
    scale = np.where(temp > 0, 1.0, np.maximum(f64["color"], 0.0).max(axis=1))
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        point = np.isin(kind, [LIGHT_KINDS["POINT"], LIGHT_KINDS["SPOT"]])
        emitted = np.where(point, power / (4 * np.pi), np.where(area_rows, power / (np.pi * np.where(area_rows, area, 1.0)),
                                                                  power)) * scale
    over = ~(emitted <= EMISSION_LIMIT)
    if over.any():
        i = int(np.argmax(over))
        if point[i]:
            what, unit, how = "intensity", "W/sr", "power / (4 pi)"
        elif area_rows[i]:
            what, unit, how = "radiance", "W/m^2/sr", "power / (pi * area)"
        else:
            what, unit, how = "irradiance", "W/m^2", "strength"
        why = "overflows float32" if emitted[i] > FLOAT32_MAX else "is beyond the renderable limit"
        raise SceneError(f"light {i}: {what} {number_text(emitted[i])} {unit} ({how}, times the colour) {why} "
                         f"(max {EMISSION_LIMIT:g} {unit})")
    clean = {}
    for name, (tail, dtype) in LIGHT_COLUMNS.items():
        col = out[name]
        if np.dtype(dtype).kind == "f":
            clean[name] = _clean_float(col, dtype)
        else:
            clean[name] = col if col.dtype == dtype else col.astype(dtype)
    if all(clean[f.name] is getattr(lt, f.name) for f in fields(Lights)):
        return lt
    return Lights(**clean)
