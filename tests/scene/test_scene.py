"""The scene model: .npz round trip and validation that names the problem."""

import numpy as np
import pytest

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.npz import load_scene, save_scene
from opal_diffraction.core.scene.validation import validate
from opal_diffraction.core.scene.settings import RenderSettings

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
    save_scene(s, tmp_path / "s.npz")
    t = load_scene(tmp_path / "s.npz")
    np.testing.assert_array_equal(t.vertices, s.vertices)
    np.testing.assert_array_equal(t.triangles, s.triangles)
    np.testing.assert_array_equal(t.tri_material, s.tri_material)
    np.testing.assert_array_equal(t.materials.dispersion, s.materials.dispersion)
    assert list(t.materials.name) == ["material_0", "glass"]
    np.testing.assert_array_equal(t.lights.spot_size, s.lights.spot_size)
    np.testing.assert_array_equal(t.camera.matrix, s.camera.matrix)
    assert t.camera.kind == "ORTHO" and t.camera.width == 8
    np.testing.assert_array_equal(t.world_color, s.world_color)
    a = render(s, RenderSettings(samples=1, threads=1, light_paths=20000)).rgb
    b = render(t, RenderSettings(samples=1, threads=1, light_paths=20000)).rgb
    np.testing.assert_array_equal(a, b)


def test_nan_coordinates_are_an_error_naming_the_vertex():
    s = small_scene()
    s.vertices[5, 1] = np.nan
    with pytest.raises(SceneError, match=r"NaN or infinite.*vertex 5"):
        validate(s)


def test_index_out_of_range_is_an_error():
    s = small_scene()
    s.triangles[3, 2] = len(s.vertices) + 10
    with pytest.raises(SceneError, match="triangle 3 uses vertex index"):
        validate(s)
    s = small_scene()
    s.tri_material[1] = 7
    with pytest.raises(SceneError, match="triangle 1 uses material 7"):
        validate(s)


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
    checked = validate(s)
    clean, warns = checked.scene, checked.warnings
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
        validate(s)
    s = small_scene()
    s.lights.power[0] = -1
    with pytest.raises(SceneError, match="power must be >= 0"):
        validate(s)
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
        load_scene(p)
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(SceneError, match="cannot read"):
        load_scene(tmp_path / "junk.npz")
    with pytest.raises(SceneError, match="not found"):
        load_scene(tmp_path / "missing.npz")


def test_grating_settings_are_validated():
    s = small_scene()
    s.materials = Materials.from_list([{"kind": "DIFFUSE"}, {"kind": "DIFFUSE", "grating": 1, "period": 0.0, "name": "cd"}])
    with pytest.raises(SceneError, match="'cd': grating period must be > 0"):
        validate(s)
    s.materials = Materials.from_list([{"kind": "DIFFUSE"}, {"kind": "DIFFUSE", "grating": 1, "period": 500.0,
                                                              "slit_width": 800.0}])
    with pytest.raises(SceneError, match="slit width 800.0 nm is larger than the period"):
        validate(s)
    with pytest.raises(SceneError, match="unknown lattice"):
        Materials.from_list([{"grating": 1, "lattice": "CUBIC"}])
    with pytest.raises(SceneError, match="unknown setting"):
        Materials.from_list([{"colour": (1, 0, 0)}])


def test_grating_data_round_trips_and_follows_dropped_triangles(tmp_path):
    s = Scene(materials=Materials.from_list([{"grating": 1, "lattice": "HEXAGONAL", "period": 300.0, "slit_width": 200.0}]),
              camera=Camera(width=4, height=4))
    s.add_mesh(*primitives.quad((0, 0, 0), (1, 0, 0), (0, 1, 0)), material=0, tangent=(1, 0, 0), period=[250.0, 260.0])
    s.add_mesh([[0, 0, 0], [1, 1, 1], [2, 2, 2]], [[0, 1, 2]], material=0, tangent=(0, 1, 0), period=0.0)
    save_scene(s, tmp_path / "g.npz")
    t = load_scene(tmp_path / "g.npz")
    np.testing.assert_array_equal(t.tri_period, [250, 260, 0])
    assert int(t.materials.lattice[0]) == 1
    clean = validate(t).scene
    np.testing.assert_array_equal(clean.tri_period, [250, 260])
    assert clean.tri_tangent.shape == (2, 3)


def test_grating_tangents_lie_in_the_plane_and_agree_across_shared_edges():
    from opal_diffraction.core.gratings.radiance import triangle_tangents
    v, t = primitives.icosphere((0, 0, 0), 1.0, 2)
    p = v[t]
    nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    given = np.tile([0.3, 0.9, 0.1], (len(t), 1))  # e.g. an object axis
    tan = triangle_tangents(nrm, given)
    assert np.allclose(np.linalg.norm(tan, axis=1), 1, atol=1e-6)
    assert np.abs(np.sum(tan * nrm, axis=1)).max() < 1e-6
    # neighbours (sharing an edge) have nearly the same tangent: no flips between triangles
    edges = {}
    for i, tri in enumerate(t):
        for a, b in ((0, 1), (1, 2), (2, 0)):
            edges.setdefault(tuple(sorted((tri[a], tri[b]))), []).append(i)
    pairs = np.array([f for f in edges.values() if len(f) == 2])
    # (away from where the axis is along the normal: no tangent field is smooth there, hairy ball)
    axis = given[0] / np.linalg.norm(given[0])
    regular = np.all(np.abs(nrm[pairs] @ axis) < 0.9, axis=1)
    assert regular.mean() > 0.8
    assert np.min(np.sum(tan[pairs[regular, 0]] * tan[pairs[regular, 1]], axis=1)) > 0.8
    # a plane's two triangles: identical
    qv, qt = primitives.quad((0, 0, 0), (1, 0, 0), (0, 1, 0))
    qn = np.tile([0, 0, 1.0], (2, 1))
    np.testing.assert_allclose(triangle_tangents(qn, np.zeros((2, 3))), [[1, 0, 0], [1, 0, 0]])
