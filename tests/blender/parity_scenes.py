"""The Cycles comparison scenes of the [scenes] issue's "Must show" (issue 10): ordinary scenes a
user builds with ordinary nodes, each rendered by Cycles and by OPAL_DIFFRACTION from the same
.blend in one bpy session (tools/cycles_parity.py renders and compares them,
tests/blender/test_cycles_parity.py asserts the agreement, benchmarks/bench_cycles_parity.py
times it).

Every builder starts from an empty file (``blender_scenes.empty_scene``) and makes the complete
scene: camera, world, lights, materials (Diffuse / Principled / Glass / Glossy / Emission
nodes, Image Texture, Environment Texture and Normal Map nodes), meshes. Images (checker,
bumps, sky) are generated with NumPy and saved to files in ``image_dir`` so both engines read
the same pixels. Resolution is small (64 x 64).

What both engines are told alike (:func:`match_engines`):

- the pixel filter: Blackman-Harris of width ``scene.opal.filter_width`` (1.5 px) in both;
- the view transform 'Standard', look 'None', exposure 0, gamma 1, Cycles' film exposure 1,
  opaque film;
- bounces: Cycles' defaults written explicitly (max 12, diffuse 4, glossy 4, transmission 12,
  transparent 8, volume 0), and ``scene.opal``'s ``max_bounces`` / ``diffuse_bounces`` /
  ``glossy_bounces`` / ``transmission_bounces`` the same;
- Cycles' biasing shortcuts off, so the reference converges to the unbiased image: no sample
  clamping (``sample_clamp_direct`` / ``sample_clamp_indirect`` = 0; Cycles' default clamps
  indirect light at 10, which would dim the light seen in the mirror sphere) and no Filter
  Glossy (``blur_glossy`` = 0). Caustic options keep Cycles' defaults (reflective and
  refractive caustics on).
"""

from __future__ import annotations

import math
import os

import bpy
import numpy as np

try:  # pytest puts tests/blender on sys.path
    import blender_scenes as bs
except ImportError:  # loaded by file path from tools/ or benchmarks/
    from opal_diffraction._scripts import load_script

    bs = load_script(os.path.join("tests", "blender", "blender_scenes.py"))

__all__ = ["SCENES", "build", "match_engines", "CYCLES_BOUNCES"]

WIDTH = HEIGHT = 64

#: Cycles' default light path bounces (Blender 5.0), written explicitly so both engines get them.
CYCLES_BOUNCES = dict(max_bounces=12, diffuse_bounces=4, glossy_bounces=4, transmission_bounces=12,
                      transparent_max_bounces=8, volume_bounces=0)


# ---------------------------------------------------------------------------- shared settings
def match_engines(sc) -> None:
    """Set what both engines must agree on (filter, view transform, bounces, no clamping)."""
    vs = sc.view_settings
    vs.view_transform = "Standard"
    vs.look = "None"
    vs.exposure = 0.0
    vs.gamma = 1.0
    sc.render.film_transparent = False
    sc.render.use_border = False
    sc.opal.filter_width = 1.5
    cy = sc.cycles
    cy.pixel_filter_type = "BLACKMAN_HARRIS"
    cy.filter_width = sc.opal.filter_width
    cy.film_exposure = 1.0
    cy.device = "CPU"
    cy.use_denoising = False
    cy.use_adaptive_sampling = False
    cy.sample_clamp_direct = 0.0
    cy.sample_clamp_indirect = 0.0
    cy.blur_glossy = 0.0
    for k, v in CYCLES_BOUNCES.items():
        setattr(cy, k, v)
    for k in ("max_bounces", "diffuse_bounces", "glossy_bounces", "transmission_bounces"):
        setattr(sc.opal, k, CYCLES_BOUNCES[k])


def _scene():
    sc = bs.empty_scene(WIDTH, HEIGHT)
    match_engines(sc)
    return sc


def look_at(location, target, lens=50.0):
    """A perspective camera at ``location`` looking at ``target`` (+Z up)."""
    from mathutils import Vector

    ob = bs.camera(location=location, lens=lens)
    d = Vector(target) - Vector(location)
    ob.rotation_euler = d.to_track_quat("-Z", "Y").to_euler()
    return ob


def _uv_plane(name, half, z, mat, uv_repeat=1.0):
    """A square at height ``z`` with a UV map covering [0, uv_repeat]^2."""
    ob = bs.plane(name, half=half, z=z, mat=mat)
    uv = ob.data.uv_layers.new(name="UVMap")
    corners = np.array([(0, 0), (1, 0), (1, 1), (0, 1)], np.float32) * uv_repeat
    uv.data.foreach_set("uv", corners.ravel())
    return ob


def _smooth_sphere(name, radius, location, mat, segments=32, rings=16):
    """Blender's default UV sphere (32 segments, 16 rings), shaded smooth."""
    bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=rings, radius=radius, location=location)
    ob = bpy.context.active_object
    ob.name = name
    ob.data.shade_smooth()
    ob.data.materials.append(mat)
    return ob


def _cube(name, size, location, mat):
    bpy.ops.mesh.primitive_cube_add(size=size, location=location)
    ob = bpy.context.active_object
    ob.name = name
    ob.data.materials.append(mat)
    return ob


def _save_image(name, rgb, path, colorspace):
    """Write (H, W, 3) values (row 0 at the top) to ``path`` (.exr: float, linear; .png: 8-bit, the
    values as stored) with OpenEXR / Pillow, and load it as a Blender image in ``colorspace``: a
    file a user would have. (Blender's own Image.save() writes a generated float image through
    its colour space, not as the values were set.)"""
    if path.endswith(".exr"):
        from opal_diffraction.core.render.output import write_rgb_exr

        write_rgb_exr(path, np.ascontiguousarray(rgb, np.float32))
    else:
        from PIL import Image

        Image.fromarray((np.clip(rgb, 0, 1) * 255 + 0.5).astype(np.uint8), "RGB").save(path)
    img = bpy.data.images.load(path, check_existing=False)
    img.name = name
    img.colorspace_settings.name = colorspace
    return img


def _image_material(name, img, shader="DIFFUSE", strength=None, interpolation="Linear"):
    mat = bs.material(name, shader, (0.8, 0.8, 0.8))
    nt = mat.node_tree
    bsdf = next(n for n in nt.nodes if n.bl_idname != "ShaderNodeOutputMaterial")
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.interpolation = interpolation
    nt.links.new(tex.outputs["Color"], bsdf.inputs["Color"])
    if strength is not None:
        bsdf.inputs["Strength"].default_value = strength
    return mat


def _world_colour(sc, colour, strength=1.0):
    world = bpy.data.worlds.new("world")
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (*colour, 1.0)
    bg.inputs["Strength"].default_value = strength
    sc.world = world
    return world


def _floor_and_cube():
    bs.plane("floor", half=6.0, mat=bs.material("floor", "DIFFUSE", (0.5, 0.5, 0.5)))
    _cube("cube", 1.0, (0.3, 0.4, 0.5), bs.material("cube", "DIFFUSE", (0.8, 0.8, 0.8)))
    look_at((2.5, -4.5, 2.6), (0.0, 0.2, 0.4))


# ---------------------------------------------------------------------------- images
def checker_rgb(n=64, squares=8, light=(0.85, 0.75, 0.55), dark=(0.10, 0.15, 0.30)) -> np.ndarray:
    """An n x n checker of ``squares`` x ``squares`` cells, values as stored in an sRGB file."""
    i = (np.arange(n) * squares // n)
    cell = (i[:, None] + i[None, :]) % 2 == 0
    return np.where(cell[..., None], np.array(light, np.float32), np.array(dark, np.float32))


def bumps_normal_rgb(n=128, bumps=4, height=0.1) -> np.ndarray:
    """A tangent-space normal map (values in [0, 1], Non-Color) of a ``bumps`` x ``bumps`` grid of
    round bumps, height field h = height * cos^2 of the distance to the cell centre; row 0 is the
    top of the image, i.e. v = 1 (n = normalize(-dh/du, -dh/dv, 1) in texture units)."""
    c = (np.arange(n) + 0.5) / n
    u, v = np.meshgrid(c, c[::-1])  # row 0 at v = 1
    fu, fv = (u * bumps) % 1.0 - 0.5, (v * bumps) % 1.0 - 0.5
    r = np.sqrt(fu * fu + fv * fv)
    inside = r < 0.5
    # h = height * cos^2(pi r): dh/dr = -height * pi * sin(2 pi r); chain rule to u, v (cells of 1/bumps)
    dhdr = np.where(inside, -height * math.pi * np.sin(2 * math.pi * r), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        dru, drv = np.where(r > 0, fu / r, 0.0), np.where(r > 0, fv / r, 0.0)
    dhdu, dhdv = dhdr * dru * bumps, dhdr * drv * bumps
    nrm = np.stack([-dhdu, -dhdv, np.ones_like(u)], axis=-1)
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    return (nrm * 0.5 + 0.5).astype(np.float32)


def sky_rgb(width=256, height=128, sun_elevation=35.0, sun_azimuth=150.0, sun_radius=6.0,
            sun_radiance=60.0) -> np.ndarray:
    """An equirectangular sky (linear Rec.709 radiance): a blue-to-white gradient above the
    horizon, a dim brown ground below it and a bright round sun patch of ``sun_radius`` degrees.

    Blender's equirectangular layout (Cycles' direction_to_equirectangular): u = 0.5 -
    atan2(d.y, d.x) / (2 pi), v = 0.5 + elevation / pi; row 0 of the returned array is v = 1
    (the zenith)."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    uu, vv = np.meshgrid(u, v[::-1])
    phi = -(uu - 0.5) * 2 * math.pi
    theta = (vv - 0.5) * math.pi  # elevation
    d = np.stack([np.cos(theta) * np.cos(phi), np.cos(theta) * np.sin(phi), np.sin(theta)], axis=-1)
    t = np.clip(np.sin(theta), 0.0, 1.0)[..., None]
    zenith, horizon = np.array([0.25, 0.45, 1.0]), np.array([1.0, 1.0, 1.0])
    sky = (1 - t) * horizon + t * zenith
    ground = np.array([0.25, 0.2, 0.15])
    rgb = np.where((theta > 0)[..., None], sky, ground)
    se, sa = math.radians(sun_elevation), math.radians(sun_azimuth)
    sun = np.array([math.cos(se) * math.cos(sa), math.cos(se) * math.sin(sa), math.sin(se)])
    in_sun = d @ sun > math.cos(math.radians(sun_radius))
    rgb = np.where(in_sun[..., None], np.array([1.0, 0.95, 0.85]) * sun_radiance, rgb)
    return rgb.astype(np.float32)


# ---------------------------------------------------------------------------- the scenes
def world_only(image_dir):
    """A grey floor and a white cube lit only by a uniform world colour."""
    sc = _scene()
    _world_colour(sc, (0.8, 0.9, 1.0), 1.0)
    _floor_and_cube()
    return sc


def world_env(image_dir):
    """The same floor and cube lit only by an Environment Texture (a sky with a sun patch, EXR)."""
    sc = _scene()
    img = _save_image("sky", sky_rgb(), os.path.join(image_dir, "parity_sky.exr"), "Linear Rec.709")
    world = bpy.data.worlds.new("sky")
    nt = world.node_tree
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = img
    nt.links.new(env.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    sc.world = world
    _floor_and_cube()
    return sc


def textured_floor(image_dir):
    """An image-textured (checker PNG, sRGB) diffuse floor and a small cube under an area light."""
    sc = _scene()
    img = _save_image("checker", checker_rgb(), os.path.join(image_dir, "parity_checker.png"), "sRGB")
    _uv_plane("floor", 3.0, 0.0, _image_material("checker", img), uv_repeat=2.0)
    _cube("cube", 0.6, (0.4, 0.3, 0.3), bs.material("cube", "DIFFUSE", (0.7, 0.7, 0.7)))
    bs.light("AREA", (0.5, -0.5, 2.5), 300.0, shape="SQUARE", size=1.0)
    look_at((0.0, -3.6, 3.0), (0.0, 0.0, 0.0))
    return sc


def emissive_room(image_dir):
    """A closed white diffuse room seen from inside, lit only by an emissive ceiling panel (the
    middle cell of a 3 x 3 ceiling has an Emission shader; its back faces the black outside)."""
    sc = _scene()
    white = bs.material("white", "DIFFUSE", (0.8, 0.8, 0.8))
    glow = bs.material("panel", "EMISSION", (1.0, 0.95, 0.9), Strength=12.0)
    hx, hy, hz = 2.0, 2.0, 2.6
    verts = [(-hx, -hy, 0), (hx, -hy, 0), (hx, hy, 0), (-hx, hy, 0)]  # floor corners 0..3
    xs, ys = (-hx, -0.5, 0.5, hx), (-hy, -0.5, 0.5, hy)
    ceil = {}
    for j, y in enumerate(ys):  # a 4 x 4 grid of ceiling vertices
        for i, x in enumerate(xs):
            ceil[i, j] = len(verts)
            verts.append((x, y, hz))
    faces, mats = [(0, 1, 2, 3)], [0]  # floor, normal up (into the room)
    for j in range(3):
        for i in range(3):  # ceiling cells, normals down
            faces.append((ceil[i, j], ceil[i, j + 1], ceil[i + 1, j + 1], ceil[i + 1, j]))
            mats.append(1 if (i, j) == (1, 1) else 0)
    c = {(0, 0): ceil[0, 0], (1, 0): ceil[3, 0], (1, 1): ceil[3, 3], (0, 1): ceil[0, 3]}
    f = {(0, 0): 0, (1, 0): 1, (1, 1): 2, (0, 1): 3}
    for a, b in (((0, 0), (1, 0)), ((1, 0), (1, 1)), ((1, 1), (0, 1)), ((0, 1), (0, 0))):  # walls, inward
        faces.append((f[a], c[a], c[b], f[b]))
        mats.append(0)
    ob = bs.mesh_object("room", verts, faces)
    ob.data.materials.append(white)
    ob.data.materials.append(glow)
    ob.data.polygons.foreach_set("material_index", mats)
    ob.data.update()
    _cube("block", 0.8, (0.6, 0.5, 0.4), bs.material("block", "DIFFUSE", (0.6, 0.6, 0.6)))
    look_at((-1.5, -1.8, 1.4), (0.4, 0.6, 0.9), lens=24.0)
    return sc


def rough_metal(image_dir):
    """A smooth-shaded rough gold-coloured metal sphere (Principled, metallic 1, roughness 0.3) on
    a grey floor under an area light."""
    sc = _scene()
    bs.plane("floor", half=4.0, mat=bs.material("floor", "DIFFUSE", (0.5, 0.5, 0.5)))
    metal = bs.material("metal", "PRINCIPLED", (0.95, 0.7, 0.4), Metallic=1.0, Roughness=0.3)
    _smooth_sphere("sphere", 0.8, (0.0, 0.0, 0.8), metal)
    bs.light("AREA", (-1.0, -1.5, 3.0), 400.0, shape="SQUARE", size=2.0,
             rotation=(math.radians(20), math.radians(-15), 0))
    look_at((0.0, -4.0, 1.8), (0.0, 0.0, 0.7))
    return sc


def emissive_checker(bright, dim, n: int, half: float = 2.5, y0: float = 1.5):
    """An n x n grid of faces at y = y0 (x in [-half, half], z in [-half, half] + 0.8) alternating
    between the materials ``bright`` and ``dim``: a pattern made of geometry, no image needed."""
    xs = np.linspace(-half, half, n + 1)
    zs = np.linspace(-half + 0.8, half + 0.8, n + 1)
    verts = [(x, y0, z) for z in zs for x in xs]
    faces, mats = [], []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            faces.append((a, a + 1, a + n + 2, a + n + 1))
            mats.append((i + j) % 2)
    ob = bs.mesh_object("pattern", verts, faces)
    ob.data.materials.append(bright)
    ob.data.materials.append(dim)
    ob.data.polygons.foreach_set("material_index", mats)
    ob.data.update()
    return ob


def glass_sphere(image_dir):
    """A smooth-shaded clear glass sphere (Glass BSDF, IOR 1.45, roughness 0) in front of a bright
    emissive checker (a 10 x 10 grid of faces alternating between two Emission materials: the
    pattern is geometry, so this scene needs no image textures)."""
    sc = _scene()
    emissive_checker(bs.material("bright", "EMISSION", (1.0, 0.9, 0.7), Strength=3.0),
                     bs.material("dim", "EMISSION", (0.2, 0.4, 1.0), Strength=0.6), 10)
    glass = bs.material("glass", "GLASS", (1.0, 1.0, 1.0), IOR=1.45, Roughness=0.0)
    _smooth_sphere("sphere", 0.7, (0.0, 0.0, 0.8), glass)
    look_at((0.0, -2.6, 0.9), (0.0, 0.0, 0.8))
    return sc


def tinted_glass_spheres(image_dir):
    """Two smooth-shaded tinted glass spheres before an emissive wall of white and dim white stripes
    (docs/physics.md section 2.7): a default Principled glass (Base Color 0.8, Transmission 1,
    IOR 1.5, roughness 0) and a ruby Glass BSDF (Color (0.8, 0.1, 0.1), IOR 1.5)."""
    sc = _scene()
    bright = bs.material("bright", "EMISSION", (1.0, 1.0, 1.0), Strength=2.0)
    dim = bs.material("dim", "EMISSION", (1.0, 1.0, 1.0), Strength=0.5)
    n, half, y0 = 16, 2.5, 1.5
    xs = np.linspace(-half, half, n + 1)
    verts = [(x, y0, z) for z in (-half + 0.8, half + 0.8) for x in xs]
    faces = [(i, i + 1, n + 2 + i, n + 1 + i) for i in range(n)]
    ob = bs.mesh_object("stripes", verts, faces)
    ob.data.materials.append(bright)
    ob.data.materials.append(dim)
    ob.data.polygons.foreach_set("material_index", [i % 2 for i in range(n)])
    ob.data.update()
    principled = bs.material("principled_glass", "PRINCIPLED", (0.8, 0.8, 0.8),
                             **{"Transmission Weight": 1.0, "IOR": 1.5, "Roughness": 0.0})
    ruby = bs.material("ruby_glass", "GLASS", (0.8, 0.1, 0.1), IOR=1.5, Roughness=0.0)
    _smooth_sphere("principled", 0.7, (-0.72, 0.0, 0.8), principled)
    _smooth_sphere("ruby", 0.7, (0.72, 0.0, 0.8), ruby)
    look_at((0.0, -2.9, 0.9), (0.0, 0.0, 0.8), lens=35.0)
    return sc


def mirror_area(image_dir):
    """An area light seen in a smooth mirror sphere (Glossy BSDF, roughness 0) over a dark floor."""
    sc = _scene()
    bs.plane("floor", half=4.0, mat=bs.material("floor", "DIFFUSE", (0.1, 0.1, 0.1)))
    mirror = bs.material("mirror", "GLOSSY", (0.9, 0.9, 0.9), Roughness=0.0)
    _smooth_sphere("sphere", 0.8, (0.0, 0.0, 0.8), mirror)
    bs.light("AREA", (-1.2, -2.0, 2.6), 300.0, shape="SQUARE", size=1.2,
             rotation=(math.radians(40), math.radians(-20), 0))
    look_at((0.0, -3.5, 1.4), (0.0, 0.0, 0.8))
    return sc


def normal_mapped(image_dir):
    """A diffuse plane with a tangent-space normal map (a grid of bumps, Non-Color PNG) under a
    low, grazing area light."""
    sc = _scene()
    img = _save_image("bumps", bumps_normal_rgb(), os.path.join(image_dir, "parity_bumps.png"), "Non-Color")
    mat = bs.material("bumpy", "DIFFUSE", (0.7, 0.7, 0.7))
    nt = mat.node_tree
    bsdf = nt.nodes["Diffuse BSDF"]
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    nmap = nt.nodes.new("ShaderNodeNormalMap")
    nmap.space = "TANGENT"
    nmap.uv_map = "UVMap"
    nt.links.new(tex.outputs["Color"], nmap.inputs["Color"])
    nt.links.new(nmap.outputs["Normal"], bsdf.inputs["Normal"])
    _uv_plane("plane", 2.0, 0.0, mat, uv_repeat=1.0)
    bs.light("AREA", (-3.0, 0.0, 0.6), 200.0, shape="RECTANGLE", size=0.3, size_y=2.0,
             rotation=(0, math.radians(-78), 0))
    look_at((0.0, -2.2, 3.2), (0.0, 0.0, 0.0))
    return sc


SCENES = {f.__name__: f for f in (world_only, world_env, textured_floor, emissive_room, rough_metal,
                                  glass_sphere, tinted_glass_spheres, mirror_area, normal_mapped)}


def build(name: str, image_dir: str):
    """Build scene ``name`` (a key of SCENES) in the current bpy session; images go to ``image_dir``."""
    os.makedirs(image_dir, exist_ok=True)
    return SCENES[name](image_dir)
