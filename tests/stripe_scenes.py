"""A test scene shared by several test files: stripes seen through a dispersive prism."""

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene

GREY_STRIPES = ((0.9, 0.9, 0.9), (0.05, 0.05, 0.05))


def prism_and_stripes(width: int = 32, height: int | None = None, colors=GREY_STRIPES) -> Scene:
    """Eight horizontal stripes, alternating ``colors`` (two diffuse base colours), under a sun,
    seen through a dense-flint prism (n_d 1.72, V_d 29) that bends the view up; ``height``
    defaults to ``width``."""
    mats = Materials.from_list([
        {"kind": "DIFFUSE", "color": tuple(colors[0])}, {"kind": "DIFFUSE", "color": tuple(colors[1])},
        {"kind": "DIELECTRIC", "ior": 1.72, "dispersion": "ABBE", "abbe": 29.0},
    ])
    s = Scene(materials=mats)
    for i in range(8):
        s.add_mesh(*primitives.quad((0, 3.0, i + 0.5), (10, 0, 0), (0, 0, 1.0)), material=i % 2)
    s.add_mesh(*primitives.prism((0, 0, 0.75), side=1.2, length=2.4, axis="X", rotation_deg=180), material=2)
    s.lights = Lights.from_list([{"kind": "SUN", "direction": (0, 1, -0.3), "power": 3.0}])
    s.camera = Camera.look_at((0, -5.5, 3.6), (0, 0.2, 0.8), lens=120, width=width,
                              height=width if height is None else height)
    return s
