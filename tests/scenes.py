"""Small scenes built in code for the tests (no files, no Blender)."""

import numpy as np

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene


def top_down_camera(size_m: float, pixels: int, height: float = 10.0, centre=(0.0, 0.0)) -> Camera:
    """Orthographic camera looking straight down at z = 0; image x = world +x, image y = world -y."""
    m = np.eye(4)
    m[:3, 3] = (centre[0], centre[1], height)
    return Camera(matrix=m, kind="ORTHO", ortho_scale=size_m, width=pixels, height=pixels)


def plane_under_light(light: dict, albedo=(0.5, 0.5, 0.5), size_m=4.0, pixels=64, plane_size=40.0) -> Scene:
    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE", "color": albedo}]))
    s.add_mesh(*primitives.quad((0, 0, 0), (plane_size, 0, 0), (0, plane_size, 0)), material=0)
    s.lights = Lights.from_list([light])
    s.camera = top_down_camera(size_m, pixels)
    return s


def pixel_centres_world(cam: Camera) -> tuple[np.ndarray, np.ndarray]:
    """World (x, y) of each pixel centre for top_down_camera."""
    n = cam.width
    c = (np.arange(n) + 0.5) / n - 0.5
    x = c[None, :] * cam.ortho_scale + cam.matrix[0, 3]
    y = -c[:, None] * cam.ortho_scale + cam.matrix[1, 3]
    return np.broadcast_to(x, (n, n)), np.broadcast_to(y, (n, n))


def glass_in_uniform_world(material: dict, world=(1.0, 1.0, 1.0), pixels=32) -> Scene:
    """A glass slab filling most of the view, in a uniformly bright world, no lights."""
    s = Scene(materials=Materials.from_list([material]))
    s.add_mesh(*primitives.box((0, 0, 0), (3.0, 3.0, 0.5)), material=0)
    s.camera = Camera.look_at((0.4, -0.6, 4.0), (0, 0, 0), lens=50, width=pixels, height=pixels)
    s.world_color = np.array(world, np.float32)
    return s
