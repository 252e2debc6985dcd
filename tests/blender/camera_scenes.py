"""The camera and film scenes of the [camera-world] issue's "Must show" (issue 29): depth of
field, clip start / end, Film > Transparent, panoramic cameras and motion blur, each built in the bpy
session and rendered by Cycles and by OPAL_DIFFRACTION from the same scene
(tests/blender/test_camera_parity.py compares them).

Every builder starts from an empty file (parity_scenes' ``_scene``: the engines' shared
settings, :func:`parity_scenes.match_engines`) and makes camera, world, sun, materials and
meshes. Images are 64 x 64 (the panorama 64 x 32, its natural 2:1).
"""

from __future__ import annotations

import math

import bpy

try:  # pytest puts tests/blender on sys.path
    import blender_scenes as bs
    import parity_scenes as ps
except ImportError:  # loaded by file path from tools/
    import os

    from opal_diffraction._scripts import load_script

    bs = load_script(os.path.join("tests", "blender", "blender_scenes.py"))
    ps = load_script(os.path.join("tests", "blender", "parity_scenes.py"))

__all__ = ["SCENES", "MOTION_SCENES", "build"]


def _sun_and_world(sc, world=(0.25, 0.3, 0.4)):
    ps._world_colour(sc, world, 1.0)
    bs.light("SUN", (0, 0, 5), 3.0, rotation=(math.radians(35), 0, math.radians(30)))


def _sphere(name, radius, location, colour):
    return ps._smooth_sphere(name, radius, location, bs.material(name, "DIFFUSE", colour))


def dof():
    """Three spheres at about 1.6, 3 and 8 m in front of an f/0.1, 50 mm lens (aperture radius
    0.25 m) focused on the middle one (a Focus Object), six blades turned 0.3 rad, anamorphic
    ratio 1.3, under a sun and a dark world: the near sphere blurs over ~15 px, the far one
    over ~9 px (a pinhole camera misses Cycles by 0.2 in the filtered RMSE), the middle one
    is sharp."""
    sc = ps._scene()
    _sun_and_world(sc, world=(0.03, 0.04, 0.06))
    bs.plane("floor", half=14.0, z=-0.6, mat=bs.material("floor", "DIFFUSE", (0.3, 0.3, 0.3)))
    _sphere("near", 0.25, (-0.35, -3.4, -0.05), (0.9, 0.3, 0.15))
    mid = _sphere("mid", 0.3, (0.1, -2.0, -0.1), (0.2, 0.8, 0.25))
    _sphere("far", 0.8, (1.2, 3.0, 0.2), (0.25, 0.4, 0.9))
    cam = ps.look_at((0.0, -5.0, 0.1), (0.0, 0.0, -0.1), lens=50.0)
    d = cam.data.dof
    d.use_dof = True
    d.focus_object = mid
    d.aperture_fstop = 0.1
    d.aperture_blades = 6
    d.aperture_rotation = 0.3
    d.aperture_ratio = 1.3
    return sc


def bokeh():
    """An emissive sphere (radius 0.4 m) 6 m away, far out of focus (focus distance 1 m, f/0.1,
    50 mm), 32 x 32 pixels: its image (6 px) is spread over the aperture's (~20 px), a pentagon
    turned 0.5 rad and squeezed by the anamorphic ratio 1.5."""
    sc = ps._scene()
    sc.render.resolution_x = sc.render.resolution_y = 32
    ps._smooth_sphere("lamp", 0.4, (0.0, 0.0, 0.0), bs.material("lamp", "EMISSION", (1.0, 0.9, 0.7), Strength=20.0))
    cam = ps.look_at((0.0, -6.0, 0.0), (0.0, 0.0, 0.0), lens=50.0)
    d = cam.data.dof
    d.use_dof = True
    d.focus_distance = 1.0
    d.aperture_fstop = 0.1
    d.aperture_blades = 5
    d.aperture_rotation = 0.5
    d.aperture_ratio = 1.5
    return sc


def _floor_cube_sphere(floor_half=6.0):
    bs.plane("floor", half=floor_half, mat=bs.material("floor", "DIFFUSE", (0.5, 0.5, 0.5)))
    ps._cube("cube", 1.0, (0.3, 0.4, 0.5), bs.material("cube", "DIFFUSE", (0.8, 0.8, 0.8)))
    _sphere("ball", 0.45, (-0.9, -0.6, 0.45), (0.8, 0.5, 0.2))


def clip():
    """The cube, a ball and the floor seen from 5.8 m with clip start 5.4 m (the cube's near
    corner is cut away, its inside shows) and clip end 8.0 m (the floor's far part and its
    shadows are cut: the world shows there)."""
    sc = ps._scene()
    _sun_and_world(sc)
    _floor_cube_sphere(floor_half=8.0)
    cam = ps.look_at((2.5, -4.5, 2.6), (0.0, 0.2, 0.4))
    cam.data.clip_start = 5.4
    cam.data.clip_end = 8.0
    return sc


def transparent():
    """A small floor, the cube and a ball under a sun and a bright world, Film > Transparent:
    the world seen directly is alpha 0 and black, the objects alpha 1, their edges partial."""
    sc = ps._scene()
    _sun_and_world(sc, world=(0.6, 0.7, 0.9))
    _floor_cube_sphere(floor_half=1.6)
    ps.look_at((2.5, -4.5, 2.6), (0.0, 0.2, 0.4))
    sc.render.film_transparent = True
    return sc


def transparent_glass():
    """``transparent`` with a smooth glass sphere (IOR 1.45) floating above the floor's far
    corner, the world behind it, and Cycles' Transparent Glass on: the world seen through the
    glass lowers alpha by the light that gets through (alpha about 0.1 in its middle, rising at
    its rim where reflections are opaque). Its sun shadow falls off the floor (ours renders the
    sun's caustic through the glass, which Cycles cannot find from a point-like sun)."""
    sc = transparent()
    ps._smooth_sphere("glass", 0.5, (-1.0, 0.9, 2.0), bs.material("glass", "GLASS", (1.0, 1.0, 1.0), IOR=1.45,
                                                                  Roughness=0.0))
    sc.cycles.film_transparent_glass = True
    return sc


def holdout():
    """``transparent`` with the cube a Holdout (a hole: alpha 0, black, where it is seen; it still
    shadows the floor) and the ball a Mix(Holdout, Diffuse, 0.5) (alpha 0.5, half its colour)."""
    sc = transparent()
    cube = bpy.data.materials.new("holdout")
    nt = cube.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(nt.nodes.new("ShaderNodeHoldout").outputs[0], out.inputs["Surface"])
    bpy.data.objects["cube"].data.materials.clear()
    bpy.data.objects["cube"].data.materials.append(cube)
    ball = bpy.data.objects["ball"].active_material
    nt = ball.node_tree
    out = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    diffuse = out.inputs["Surface"].links[0].from_node
    mix = nt.nodes.new("ShaderNodeMixShader")
    mix.inputs["Fac"].default_value = 0.5
    nt.links.new(nt.nodes.new("ShaderNodeHoldout").outputs[0], mix.inputs[1])
    nt.links.new(diffuse.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])
    return sc


def equirect():
    """An equirectangular panorama (full sphere, 64 x 32) from 1 m above a floor, with a cube
    ahead, a ball to the left, a tall box behind and a sun: every direction of Cycles' mapping
    (forward at the centre, left to the left, up at the top) is somewhere in the image."""
    sc = ps._scene()
    sc.render.resolution_x, sc.render.resolution_y = 64, 32
    _sun_and_world(sc)
    bs.plane("floor", half=10.0, mat=bs.material("floor", "DIFFUSE", (0.5, 0.5, 0.5)))
    ps._cube("cube", 1.2, (0.0, 2.0, 0.6), bs.material("cube", "DIFFUSE", (0.8, 0.8, 0.8)))
    _sphere("ball", 0.6, (-1.8, 0.3, 0.6), (0.8, 0.3, 0.1))
    tall = ps._cube("tall", 1.0, (0.8, -2.2, 1.0), bs.material("tall", "DIFFUSE", (0.2, 0.4, 0.8)))
    tall.scale = (1.0, 1.0, 2.0)
    cam = bs.camera(location=(0.0, 0.0, 1.0), rotation=(math.radians(90), 0.0, 0.0))  # looking along +Y
    cam.data.type = "PANO"
    cam.data.panorama_type = "EQUIRECTANGULAR"
    return sc


def fisheye():
    """An equisolid fisheye (10.5 mm on a 36 mm sensor, 180 degrees) looking down at the scene
    of ``equirect``: the corners outside its circle are black in both engines."""
    sc = equirect()
    sc.render.resolution_x, sc.render.resolution_y = 64, 64
    cam = sc.camera
    cam.location = (0.0, -1.0, 3.0)
    cam.rotation_euler = (math.radians(40), 0.0, 0.0)
    cam.data.panorama_type = "FISHEYE_EQUISOLID"
    cam.data.fisheye_lens = 10.5
    cam.data.fisheye_fov = math.pi
    return sc


def _linear_keys(ob, path, values, frames=(0, 2)):
    """Keyframes of ``ob``'s ``path`` (one value per frame), linear between them."""
    for f, v in zip(frames, values):
        setattr(ob, path, v)
        ob.keyframe_insert(data_path=path, frame=f)
    ad = ob.animation_data
    fcurves = ad.action.fcurves if hasattr(ad.action, "fcurves") else [
        fc for layer in ad.action.layers for strip in layer.strips for bag in strip.channelbags for fc in bag.fcurves]
    for fc in fcurves:
        for k in fc.keyframe_points:
            k.interpolation = "LINEAR"


def _motion_blur(sc, shutter=1.0, position="CENTER"):
    sc.render.use_motion_blur = True
    sc.render.motion_blur_shutter = shutter
    sc.render.motion_blur_position = position
    sc.frame_set(1)


def motion_camera():
    """The floor, cube and ball under a sun, seen by a camera that slides 1.8 m to its right and
    turns 24 degrees to the right while the shutter is open (frames 0.5-1.5 of a move keyed linearly from
    frame 0 to 2, shutter 1 frame centred on frame 1): everything smears sideways, the near
    ball most."""
    sc = ps._scene()
    _sun_and_world(sc)
    _floor_cube_sphere(floor_half=8.0)
    cam = ps.look_at((2.5, -4.5, 2.6), (0.0, 0.2, 0.4))
    rx, ry, rz = cam.rotation_euler
    _linear_keys(cam, "location", [(0.9, -5.3, 2.6), (4.1, -3.7, 2.6)])
    # sliding right and turning right (z rotation falling): both move the image left
    _linear_keys(cam, "rotation_euler", [(rx, ry, rz + math.radians(24)), (rx, ry, rz - math.radians(24))])
    _motion_blur(sc)
    return sc


def motion_cube():
    """A 1.4 m cube flying 1.6 m across the view during the shutter (keyed linearly from frame 0 to
    2, shutter 1 frame starting on frame 1) over the floor, a still ball beside it, under a
    sun: the cube and its shadow smear, the ball stays sharp."""
    sc = ps._scene()
    _sun_and_world(sc)
    bs.plane("floor", half=8.0, mat=bs.material("floor", "DIFFUSE", (0.5, 0.5, 0.5)))
    cube = ps._cube("cube", 1.4, (0.0, 0.6, 0.7), bs.material("cube", "DIFFUSE", (0.8, 0.8, 0.8)))
    _sphere("ball", 0.45, (-0.9, -0.9, 0.45), (0.8, 0.5, 0.2))
    _linear_keys(cube, "location", [(-1.6, 0.6, 0.7), (1.6, 0.6, 0.7)])
    ps.look_at((2.5, -4.5, 2.6), (0.0, 0.2, 0.4))
    _motion_blur(sc, position="START")
    return sc


SCENES = {"dof": dof, "bokeh": bokeh, "clip": clip, "transparent": transparent, "transparent_glass": transparent_glass, "holdout": holdout, "equirect": equirect, "fisheye": fisheye}
#: motion blur (tests/blender/test_motion_parity.py)
MOTION_SCENES = {"motion_camera": motion_camera, "motion_cube": motion_cube}


def build(name: str):
    """Build scene ``name`` (a key of SCENES) in the current bpy session."""
    return {**SCENES, **MOTION_SCENES}[name]()
