"""Scenes for tests/gratings/test_grating_records.py: gratings lit only through plane mirrors, and the same
gratings lit by point lights at the mirror images of the light (docs/physics.md section 3.5).

A plane mirror of reflectance R turns a point light at P into a virtual point light at P's mirror
image with R times its intensity, seen through the mirror's outline; so a grating lit through
mirrors (and nothing else) must render like the grating lit by the virtual lights with the mirrors
removed. A small black occluder next to the real light keeps its direct light off the grating (it
blocks the same rays in both scenes: none of the virtual lights' rays pass it).
"""

import numpy as np

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene

D_NM, A_NM, N_SLITS, L_UM = 1600.0, 800.0, 10, 1.5
POWER = 200.0
GRATING_HALF = 0.1  # the grating is a 0.2 m square at the origin, normal +z, slits along y


def _mirror_plane(light, image):
    """The plane that mirrors ``light`` onto ``image``: its point and unit normal."""
    light, image = np.asarray(light, float), np.asarray(image, float)
    n = image - light
    return 0.5 * (light + image), n / np.linalg.norm(n)


def _mirror_quad(light, image, half_u, half_v):
    """A mirror quad on the bisecting plane of ``light`` and ``image``, centred where the line
    from ``image`` to the grating's centre crosses it, with half extents along y (``half_u``) and
    along the plane's direction in the xz plane (``half_v``)."""
    p0, n = _mirror_plane(light, image)
    image = np.asarray(image, float)
    s = np.dot(p0 - image, n) / np.dot(-image, n)  # image + s (0 - image) on the plane
    c = image * (1 - s)
    ey = np.array([0.0, 1.0, 0.0])
    ev = np.cross(ey, n)
    return primitives.quad(c, 2 * half_u * ey, 2 * half_v * ev)


def grating_scene(lights_at, powers, transmission=False, mirrors=(), occluder_at=None, camera_z=0.3, pixels=40):
    """The grating, point lights at ``lights_at`` with ``powers`` (W), optional mirror meshes
    ((vertices, triangles) pairs) and a small black occluder quad centred at ``occluder_at``."""
    mats = Materials.from_list([
        {"kind": "DIFFUSE", "color": (0, 0, 0), "grating": 1,
         "grating_type": "TRANSMISSION" if transmission else "REFLECTION", "lattice": "LINES",
         "period": D_NM, "slit_width": A_NM, "slit_count": N_SLITS, "coherence_length": L_UM},
        {"kind": "MIRROR", "color": (1, 1, 1)},
        {"kind": "DIFFUSE", "color": (0, 0, 0)},
    ])
    s = Scene(materials=mats)
    g = 2 * GRATING_HALF
    s.add_mesh(*primitives.quad((0, 0, 0), (g, 0, 0), (0, g, 0)), material=0, tangent=(1, 0, 0))
    for v, t in mirrors:
        s.add_mesh(v, t, material=1)
    if occluder_at is not None:
        s.add_mesh(*primitives.quad(occluder_at, (0.024, 0, 0), (0, 0.024, 0)), material=2)
    s.lights = Lights.from_list([{"kind": "POINT", "position": tuple(map(float, p)), "power": float(w)}
                                 for p, w in zip(lights_at, powers)])
    m = np.eye(4)
    m[2, 3] = camera_z
    s.camera = Camera(matrix=m, lens=40.0, sensor_width=36.0, width=pixels, height=pixels)
    return s


LIGHT_TWO = np.array([0.0, 0.0, 1.0])
IMAGES_TWO = (np.array([1.0, 0.0, 1.0]), np.array([-0.6, 0.0, 1.4]))


def two_mirror_scene(pixels=40):
    """A reflection grating lit by one point light through two plane mirrors only: the light's
    images sit at 45 degrees on the +x side and 23 degrees on the -x side of the grating."""
    mirrors = [_mirror_quad(LIGHT_TWO, IMAGES_TWO[0], 0.15, 0.2), _mirror_quad(LIGHT_TWO, IMAGES_TWO[1], 0.15, 0.15)]
    return grating_scene([LIGHT_TWO], [POWER], mirrors=mirrors, occluder_at=LIGHT_TWO - [0, 0, 0.05], pixels=pixels)


def two_virtual_lights_scene(pixels=40, reflectance=1.0):
    """The same grating lit by point lights at the two mirror images (power x mirror reflectance)."""
    return grating_scene(IMAGES_TWO, [POWER * reflectance] * 2, occluder_at=LIGHT_TWO - [0, 0, 0.05], pixels=pixels)


LIGHT_TRANS = np.array([0.0, 0.0, -1.0])
IMAGE_TRANS = np.array([0.5, 0.0, -1.0])


def mirror_transmission_scene(pixels=40):
    """A transmission grating lit from below by one point light through one vertical mirror."""
    mirrors = [_mirror_quad(LIGHT_TRANS, IMAGE_TRANS, 0.15, 0.25)]
    return grating_scene([LIGHT_TRANS], [POWER], transmission=True, mirrors=mirrors,
                         occluder_at=LIGHT_TRANS + [0, 0, 0.05], pixels=pixels)


def virtual_transmission_scene(pixels=40, reflectance=1.0):
    return grating_scene([IMAGE_TRANS], [POWER * reflectance], transmission=True,
                         occluder_at=LIGHT_TRANS + [0, 0, 0.05], pixels=pixels)


WEDGE_ALPHA = np.radians(20.0)


def wedge(w=0.2, z_top=0.6, alpha=WEDGE_ALPHA):
    """A glass wedge along y: a horizontal top face at ``z_top`` over x, y in [-w, w], a vertical
    face at x = -w and a bottom face tilted by ``alpha`` (outward normal (sin a, 0, -cos a)).
    Triangles wound with outward normals."""
    a = np.array([-w, z_top])
    b = np.array([w, z_top])
    c = np.array([-w, z_top - 2 * w * np.tan(alpha)])
    v = np.array([[p[0], y, p[1]] for y in (-w, w) for p in (a, b, c)], float)  # 0 1 2 at -w, 3 4 5 at +w
    tris = np.array([[0, 2, 1], [3, 4, 5],                # ends
                     [0, 1, 4], [0, 4, 3],                # top
                     [1, 2, 5], [1, 5, 4],                # tilted bottom
                     [2, 0, 3], [2, 3, 5]], np.int64)     # vertical side
    centre = v.mean(axis=0)
    n = np.cross(v[tris[:, 1]] - v[tris[:, 0]], v[tris[:, 2]] - v[tris[:, 0]])
    out = np.einsum("ij,ij->i", n, v[tris].mean(axis=1) - centre) > 0
    tris[~out] = tris[~out][:, [0, 2, 1]]  # make every normal point outwards
    return v, tris


def sun_through_wedge_scene():
    """A sun straight down through a BK7 wedge onto a large reflection grating at z = 0: the
    light enters the top face at normal incidence and leaves the tilted face refracted by
    Snell's law, a parallel beam per wavelength."""
    mats = Materials.from_list([
        {"kind": "DIFFUSE", "color": (0, 0, 0), "grating": 1, "grating_type": "REFLECTION", "lattice": "LINES",
         "period": D_NM, "slit_width": A_NM, "slit_count": N_SLITS, "coherence_length": L_UM},
        {"kind": "DIELECTRIC", "ior": 1.5168, "dispersion": "BK7", "color": (1, 1, 1)},
    ])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (1.6, 0, 0), (0, 1.6, 0)), material=0, tangent=(1, 0, 0))
    s.add_mesh(*wedge(), material=1)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": (0.0, 0.0, -1.0), "power": 1.0}])
    m = np.eye(4)
    m[2, 3] = 2.0
    s.camera = Camera(matrix=m, lens=40.0, sensor_width=36.0, width=8, height=8)
    return s
