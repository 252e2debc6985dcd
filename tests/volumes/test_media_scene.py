"""The media's scene data: the volume columns and Scene.world_volume through validation (one
readable line for a bad value) and the .npz file, and their spectra (core/volumes/media.py)."""

import numpy as np
import pytest

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.model import Materials, Scene
from opal_diffraction.core.scene.npz import load_scene, save_scene
from opal_diffraction.core.scene.validation import validate
from opal_diffraction.core.spectral.spectrum import SpectralConverter
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.volumes.media import has_media, prepare_media
from scenes import top_down_camera


def _scene(**fog):
    row = {"kind": "DIFFUSE", "volume_scatter_density": 0.3, "volume_scatter_color": (0.9, 0.5, 0.2),
           "volume_anisotropy": 0.4, "volume_emission": (0.1, 0.0, 0.0)}
    row.update(fog)
    s = Scene(materials=Materials.from_list([{"kind": "DIFFUSE"}, row]))
    s.add_mesh(*primitives.quad((0, 0, 0), (4, 0, 0), (0, 4, 0)), material=0)
    s.camera = top_down_camera(2.0, 4)
    s.world_volume = 1
    return s


def test_npz_round_trip_keeps_the_media(tmp_path):
    s = _scene()
    save_scene(s, tmp_path / "fog.npz")
    back = validate(load_scene(tmp_path / "fog.npz")).scene
    assert back.world_volume == 1
    np.testing.assert_allclose(back.materials.volume_scatter_color[1], (0.9, 0.5, 0.2))
    assert back.materials.volume_anisotropy[1] == pytest.approx(0.4)
    assert has_media(back) and not has_media(Scene(materials=Materials.from_list([{"kind": "DIFFUSE"}])))


@pytest.mark.parametrize("bad, words", [
    ({"volume_scatter_density": -1.0}, "volume scatter density must be >= 0"),
    ({"volume_absorption_color": (0.5, 1.5, 0.0)}, "volume absorption color must be between 0 and 1"),
    ({"volume_anisotropy": 1.5}, "volume anisotropy must be between -1 and 1"),
])
def test_bad_values_are_one_line_errors(bad, words):
    with pytest.raises(SceneError, match=words):
        validate(_scene(**bad))


def test_world_volume_must_name_a_material():
    s = _scene()
    s.world_volume = 5
    with pytest.raises(SceneError, match="world_volume must be -1"):
        validate(s)


def test_media_spectra_are_the_uplifted_colours_times_the_densities():
    conv = SpectralConverter(RenderSettings().grid())
    media = prepare_media(validate(_scene()).scene, conv)
    assert media.world == 1 and media.has.tolist() == [False, True]
    np.testing.assert_allclose(media.sigma_s[1], 0.3 * conv.reflectance_from_rgb(np.array([0.9, 0.5, 0.2])))
    assert (media.sigma_a[1] == 0).all() and media.scatters.tolist() == [False, True]
    np.testing.assert_allclose(media.emission[1], conv.illuminant_from_rgb(np.array([0.1, 0.0, 0.0])).clip(0))
    # where a segment runs: behind a back face of a medium's material, else the world's
    s = _scene()
    s.materials = Materials.from_list([{"kind": "DIFFUSE"}, {"kind": "DIFFUSE", "volume_scatter_density": 0.3},
                                       {"kind": "DIELECTRIC", "volume_absorption_density": 2.0}])
    media = prepare_media(validate(s).scene, conv)
    got = media.segment_medium(np.array([2, 2, 0, 2]), np.array([False, True, False, False]),
                               np.array([False, False, False, True]))
    assert got.tolist() == [2, 1, 1, 1]  # inside the glass; its front, a plain back face, a miss: the world
