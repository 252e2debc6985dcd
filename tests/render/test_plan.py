"""The render plan's pass decisions (core/render/plan.py): the camera splat, the light paths'
diffuse bounce, the Fresnel split, grey path weights and ray differentials follow the scene and
the settings, decided once per render (the passes read them from the plan)."""

from dataclasses import replace

from grating_record_scenes import two_mirror_scene

from opal_diffraction.core.render.plan import plan_render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings

SETTINGS = RenderSettings(samples=1, light_paths=1000, wavelength_step=50.0)


def _ball_scene() -> Scene:
    """A glass ball (IOR 1.5) on a grey floor under a point light, seen by the camera."""
    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE", "color": (0.5,) * 3},
                                             {"kind": "DIELECTRIC", "ior": 1.5, "color": (1, 1, 1)}]))
    s.add_mesh(*primitives.quad((-3, -3, 0), (6, 0, 0), (0, 6, 0)), material=0)
    s.add_mesh(*primitives.icosphere((0, 0, 1.0), 1.0, 1), material=1)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (-2.0, 3.0, 6.0), "power": 1500.0}])
    s.camera = Camera.look_at((0.0, -6.0, 4.0), (0.0, -0.4, 0.5), lens=50, width=8, height=8)
    return s


def _plan(scene, **settings):
    return plan_render(prepare(scene, replace(SETTINGS, **settings)))


def test_a_glass_ball_on_a_floor_splats_bounces_and_splits():
    plan = _plan(_ball_scene())
    assert plan.light_pass and plan.camera_splat and plan.splat_bounce and plan.fresnel_split
    assert plan.grey_paths and not plan.ray_differentials  # no gratings: no differentials, grey weights


def test_each_setting_switches_its_decision_alone():
    scene = _ball_scene()
    assert not _plan(scene, fresnel_split=False).fresnel_split
    bounce_off = _plan(scene, splat_bounce=False)
    assert bounce_off.camera_splat and not bounce_off.splat_bounce
    for off in (_plan(scene, caustic_splat=False), _plan(scene, filter_width=0.0)):
        assert not off.camera_splat and not off.splat_bounce  # the bounce needs the splat
        assert off.fresnel_split and off.grey_paths


def test_gratings_take_differentials_and_spectral_weights_and_no_split():
    plan = _plan(two_mirror_scene(8))
    assert plan.gratings and plan.ray_differentials and not plan.grey_paths
    assert not plan.fresnel_split and not plan.splat_bounce  # layered bases; light paths it cannot follow
    assert not _plan(two_mirror_scene(8), grating_footprint=False).ray_differentials
