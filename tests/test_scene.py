"""The scene model: .npz round trip and validation that names the problem."""

import numpy as np
import pytest

from opal_diffraction.core import primitives
from opal_diffraction.core.render import render
from opal_diffraction.core.scene import Camera, Lights, Materials, Scene, SceneError
from opal_diffraction.core.settings import RenderSettings

from scenes import plane_under_light


def small_scene():
    s = plane_under_light({"kind": "SPOT", "position": (0, 0, 2), "power": 10.0}, pixels=8)
    s.materials = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
                                       {"kind": "DIELECTRIC", "ior": 1.6, "dispersion": "ABBE", "abbe": 40.0, "name": "glass"}])
    s.add_mesh(*primitives.icosphere((0, 0, 0.5), 0.4, 1), material=1)
    return s


def test_npz_round_trip(tmp_path):
    s = small_scene()
    s.world_color = np.array([0.1, 0.2, 0.3], np.float32)
    s.save(tmp_path / "s.npz")
    t = Scene.load(tmp_path / "s.npz")
    np.testing.assert_array_equal(t.vertices, s.vertices)
    np.testing.assert_array_equal(t.triangles, s.triangles)
    np.testing.assert_array_equal(t.tri_material, s.tri_material)
    np.testing.assert_array_equal(t.materials.dispersion, s.materials.dispersion)
    assert list(t.materials.name) == ["material_0", "glass"]
    np.testing.assert_array_equal(t.lights.spot_size, s.lights.spot_size)
    np.testing.assert_array_equal(t.camera.matrix, s.camera.matrix)
    assert t.camera.kind == "ORTHO" and t.camera.width == 8
    np.testing.assert_array_equal(t.world_color, s.world_color)
    a = render(s, RenderSettings(samples=1, threads=1)).rgb
    b = render(t, RenderSettings(samples=1, threads=1)).rgb
    np.testing.assert_array_equal(a, b)


def test_nan_coordinates_are_an_error_naming_the_vertex():
    s = small_scene()
    s.vertices[5, 1] = np.nan
    with pytest.raises(SceneError, match=r"NaN or infinite.*vertex 5"):
        s.validated()


def test_index_out_of_range_is_an_error():
    s = small_scene()
    s.triangles[3, 2] = len(s.vertices) + 10
    with pytest.raises(SceneError, match="triangle 3 uses vertex index"):
        s.validated()
    s = small_scene()
    s.tri_material[1] = 7
    with pytest.raises(SceneError, match="triangle 1 uses material 7"):
        s.validated()


def test_missing_camera_is_an_error():
    s = small_scene()
    s.camera = None
    with pytest.raises(SceneError, match="no camera"):
        render(s)


def test_degenerate_triangles_are_dropped_and_counted():
    s = small_scene()
    n = len(s.triangles)
    s.add_mesh([[0, 0, 0], [1, 1, 1], [2, 2, 2]], [[0, 1, 2]], material=0)  # collinear
    s.add_mesh([[0, 0, 0], [1, 0, 0]], [[0, 0, 1]], material=0)  # repeated vertex
    clean, warns = s.validated()
    assert len(clean.triangles) == n
    assert any("dropped 2 degenerate" in w for w in warns)


def test_empty_scene_renders_black_with_a_warning():
    s = Scene(camera=Camera(width=16, height=8))
    res = render(s, RenderSettings(samples=2))
    assert res.rgb.shape == (8, 16, 3) and not res.rgb.any()
    assert any("no geometry" in w for w in res.warnings)
    assert any("no lights" in w for w in res.warnings)


def test_bad_material_and_light_values_are_errors():
    s = small_scene()
    s.materials.ior[1] = 0.5
    with pytest.raises(SceneError, match="IOR must be >= 1"):
        s.validated()
    s = small_scene()
    s.lights.power[0] = -1
    with pytest.raises(SceneError, match="power must be >= 0"):
        s.validated()
    with pytest.raises(SceneError, match="unknown kind"):
        Materials.from_list([{"kind": "VELVET"}])
    with pytest.raises(SceneError, match="unknown kind"):
        Lights.from_list([{"kind": "LASER"}])


def test_bad_settings_are_errors():
    s = small_scene()
    for bad in (RenderSettings(samples=0), RenderSettings(wavelength_step=0), RenderSettings(dispersion_sampling="X")):
        with pytest.raises(SceneError):
            render(s, bad)


def test_loading_a_non_scene_file_is_a_clear_error(tmp_path):
    p = tmp_path / "x.npz"
    np.savez(p, a=np.zeros(3))
    with pytest.raises(SceneError, match="not an opal_diffraction scene"):
        Scene.load(p)
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(SceneError, match="cannot read"):
        Scene.load(tmp_path / "junk.npz")
    with pytest.raises(SceneError, match="not found"):
        Scene.load(tmp_path / "missing.npz")
