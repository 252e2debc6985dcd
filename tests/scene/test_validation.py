"""Validation at the boundary: every column's dtype, shape and range, in the dtype the tracer
computes in (float32), with one-line messages naming the column, the row and the rule."""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.checks import SceneError
from opal_diffraction.core.scene.validation import validate
from opal_diffraction.core.scene.settings import RenderSettings


def scene() -> Scene:
    s = Scene(materials=Materials.from_list([
        {"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
        {"kind": "DIELECTRIC", "ior": 1.5, "dispersion": "ABBE", "abbe": 40.0, "name": "glass"},
        {"kind": "DIFFUSE", "grating": 1, "period": 1000.0, "slit_width": 500.0, "name": "cd"},
    ]))
    s.add_mesh(*primitives.quad((0, 0, 0), (6, 0, 0), (0, 6, 0)), material=0)
    s.add_mesh(*primitives.box((0, 0, 0.5), (1, 1, 1)), material=1)
    s.add_mesh(*primitives.quad((2, 0, 0.01), (1, 0, 0), (0, 1, 0)), material=2)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (0, 0, 3), "power": 50.0},
                                 {"kind": "SUN", "direction": (0, 0, -1), "power": 1.0},
                                 {"kind": "AREA_RECT", "position": (1, 0, 3), "power": 50.0, "size_u": 0.5}])
    s.camera = Camera.look_at((0, -4, 3), (0, 0, 0), width=4, height=4)
    return s


def error_of(mutate) -> str:
    s = scene()
    mutate(s)
    with pytest.raises(SceneError) as e:
        validate(s)
    msg = str(e.value)
    assert "\n" not in msg and msg
    return msg


def setattr_(obj_name, name, value):
    def f(s):
        setattr(s if obj_name is None else getattr(s, obj_name), name, value)
    return f


def test_a_clean_scene_validates_to_the_same_arrays():
    s = scene()
    checked = validate(s)
    clean, warns = checked.scene, checked.warnings
    assert warns == []
    assert clean.materials is s.materials and clean.lights is s.lights and clean.camera is s.camera
    assert clean.vertices is s.vertices and clean.tri_tangent is s.tri_tangent


@pytest.mark.parametrize("shape", [(3, 2), (3,), (3, 3, 1), (2, 3), ()])
def test_per_row_shape_of_a_material_colour(shape):
    msg = error_of(setattr_("materials", "color", np.zeros(shape, np.float32)))
    assert "material table column 'color'" in msg


@pytest.mark.parametrize("dtype, word", [(str, "strings"), (complex, "complex"), (bool, "booleans"), (object, "objects")])
def test_strings_complex_bool_and_objects_are_not_numbers(dtype, word):
    msg = error_of(lambda s: setattr(s, "vertices", s.vertices.astype(dtype)))
    assert msg.startswith("vertices must hold numbers") and word in msg
    msg = error_of(lambda s: setattr(s.lights, "power", s.lights.power.astype(dtype)))
    assert "'power'" in msg
    if dtype is not bool:  # a 0/1 grating flag may be a bool
        msg = error_of(lambda s: setattr(s.materials, "grating", s.materials.grating.astype(dtype)))
        assert "'grating'" in msg


def test_ragged_lists_are_an_error():
    assert "not a regular array" in error_of(setattr_(None, "vertices", [[0, 0, 0], [1, 1]]))


def test_float32_overflow_names_row_and_rule():
    def big_vertices(s):
        v = s.vertices.astype(np.float64)
        v[7, 2] = 1e39
        s.vertices = v
    assert error_of(big_vertices) == "vertex 7: coordinate 1e+39 m overflows float32 (max 3.4e38)"
    assert "beyond the renderable limit" in error_of(lambda s: setattr(s, "vertices", s.vertices.astype(np.float64) * 1e15))

    def power(s):
        s.lights.power = np.array([50.0, 1.0, 1e41])
    assert error_of(power) == "light 2: power 1e+41 W overflows float32 (max 3.4e38)"

    def radiance(s):  # finite power, tiny area: power / (pi * area) overflows
        s.lights.size_u = np.array([1.0, 1.0, 1e-15])
        s.lights.size_v = np.array([1.0, 1.0, 1e-15])
    msg = error_of(radiance)
    assert msg.startswith("light 2: radiance") and "power / (pi * area)" in msg

    def area_underflow(s):
        s.lights.size_u = np.array([1.0, 1.0, 1e-30])
        s.lights.size_v = np.array([1.0, 1.0, 1e-30])
        s.lights.power = np.array([50.0, 1.0, 1e-60])
    assert "underflows float32" in error_of(area_underflow)

    def intensity(s):
        s.lights.power = np.array([1e30, 1.0, 1.0])
    assert error_of(intensity).startswith("light 0: intensity")


def test_light_temperature():
    for bad in (1.0, 0.5, -10.0, np.nan, np.inf, 1e12):
        msg = error_of(lambda s, t=bad: setattr(s.lights, "temperature", np.array([0.0, t, 0.0])))
        assert msg.startswith("light 1: temperature")
    s = scene()
    s.lights.temperature = np.array([0.0, 5000.0, 0.0])  # 0: no temperature, the colour
    validate(s)


def test_light_kind_and_spot_ranges():
    assert "kind code 7" in error_of(lambda s: setattr(s.lights, "kind", np.array([0, 7, 3], np.int32)))
    assert "must hold integers" in error_of(lambda s: setattr(s.lights, "kind", np.array([0.0, 2.0, 3.0])))

    def spot(s):
        s.lights = Lights.from_list([{"kind": "SPOT", "spot_size": 4.0}])
    assert "spot size" in error_of(spot)


def test_grating_rules():
    def mat(**kw):
        def f(s):
            for k, v in kw.items():
                col = getattr(s.materials, k).copy()
                col[2] = v
                setattr(s.materials, k, col)
        return f
    assert "rotation is NaN or infinite" in error_of(mat(rotation=np.nan))
    assert "rotation is NaN or infinite" in error_of(mat(rotation=np.inf))
    for col, what in (("period", "period"), ("slit_width", "slit width"), ("coherence_length", "coherence length")):
        assert f"'cd': grating {what} must be > 0" in error_of(mat(**{col: 0.0}))
        assert f"'cd': grating {what} must be > 0" in error_of(mat(**{col: -1.0}))
    assert "larger than the period" in error_of(mat(slit_width=2000.0))
    assert "slit count must be >= 1" in error_of(mat(slit_count=0))
    assert "slit count must be >= 1" in error_of(mat(slit_count=2**31 - 1))
    assert "grating flag must be 0 or 1" in error_of(mat(grating=5))


def test_material_rules():
    def mat(**kw):
        def f(s):
            for k, v in kw.items():
                col = getattr(s.materials, k).copy()
                col[1] = v
                setattr(s.materials, k, col)
        return f
    assert "IOR must be >= 1" in error_of(mat(ior=0.5))
    assert "IOR 1e+05 is above" in error_of(mat(ior=1e5))
    assert "Abbe number > 0" in error_of(mat(abbe=0.0))
    assert "index of" in error_of(mat(abbe=0.1))  # a Cauchy fit that goes below 1
    assert "kind code 9" in error_of(mat(kind=9))
    assert "emission" in error_of(mat(emission=(1e30, 0, 0)))
    assert "emission" in error_of(mat(emission=(-1, 0, 0)))
    assert "column 'name'" in error_of(setattr_("materials", "name", np.zeros(3)))
    assert "column 'ior' has 2 rows, expected 3" in error_of(setattr_("materials", "ior", np.ones(2, np.float32)))


def test_indices():
    assert "must hold integers" in error_of(lambda s: setattr(s, "triangles", s.triangles.astype(np.float64)))
    assert "32-bit integer range" in error_of(lambda s: setattr(s, "triangles", s.triangles.astype(np.int64) + 2**40))
    assert "tri_material must hold integers" in error_of(lambda s: setattr(s, "tri_material", s.tri_material * 1.0))


def test_camera_limits_before_any_allocation():
    for w, h, what in ((10**9, 1, "at most 65536"), (40000, 40000, "M pixels"), (0, 4, "at least 1x1")):
        assert what in error_of(lambda s, w=w, h=h: setattr(s, "camera", Camera(width=w, height=h)))
    assert "whole number" in error_of(lambda s: setattr(s, "camera", Camera(width=4.5, height=4)))
    assert "must be a number" in error_of(lambda s: setattr(s, "camera", Camera(width="4", height=4)))
    assert "must be a number" in error_of(lambda s: setattr(s, "camera", Camera(lens=True)))
    assert "bottom row" in error_of(lambda s: setattr(s, "camera", Camera(matrix=np.ones((4, 4)))))
    assert "field of view" in error_of(lambda s: setattr(s, "camera", Camera(lens=1e-9)))
    assert "camera type" in error_of(lambda s: setattr(s, "camera", Camera(kind=np.array(["PERSP", "ORTHO"]))))
    # a 1e9-pixel render fails at once with the error, not after allocating the film
    s = scene()
    s.camera = Camera(width=65536, height=65536)
    with pytest.raises(SceneError, match="M pixels"):
        render(s, RenderSettings(samples=1))


def test_world_colour_and_grating_data():
    assert "world colour" in error_of(setattr_(None, "world_color", np.array([np.nan, 0, 0])))
    assert "world colour must have shape (3,)" in error_of(setattr_(None, "world_color", np.zeros((1, 3))))
    assert "world colour" in error_of(setattr_(None, "world_color", np.array([1e30, 0, 0])))
    assert "per triangle" in error_of(lambda s: setattr(s, "tri_period", np.zeros(3, np.float32)))


def test_tiny_triangles_are_dropped_with_a_warning():
    s = scene()
    s.add_mesh([[0, 0, 0], [1e-16, 0, 0], [0, 1e-16, 0]], [[0, 1, 2]], material=0)
    checked = validate(s)
    clean, warns = checked.scene, checked.warnings
    assert len(clean.triangles) == len(s.triangles) - 1
    assert any("too small for float32" in w for w in warns)


def test_from_list_errors_are_scene_errors():
    with pytest.raises(SceneError, match="light 0: position must be 3 numbers"):
        Lights.from_list([{"position": (1, 2)}])
    with pytest.raises(SceneError, match="light 0: unknown setting"):
        Lights.from_list([{"positon": (1, 2, 3)}])
    with pytest.raises(SceneError, match="material 0: color must be 3 numbers"):
        Materials.from_list([{"color": "red"}])
    with pytest.raises(SceneError, match="expected a dict"):
        Materials.from_list(["DIFFUSE"])


# ---------------------------------------------------------------------------------- settings
@pytest.mark.parametrize("kw, match", [
    (dict(seed=-1), "seed must be >= 0"),
    (dict(threads=-1), "threads must be >= 0"),
    (dict(backend="cuda"), "unknown ray-casting backend 'cuda'"),
    (dict(backend=None), "unknown ray-casting backend"),
    (dict(samples=2.5), "samples must be a whole number"),
    (dict(samples="4"), "samples must be a number"),
    (dict(samples=True), "samples must be a number"),
    (dict(samples=0), "samples must be at least 1"),
    (dict(light_paths=1.5), "light paths must be a whole number"),
    (dict(light_paths=10**12), "above the maximum"),
    (dict(max_bounces=-1), "max bounces must be >= 0"),
    (dict(tile_size=0), "tile size must be at least 1"),
    (dict(round_samples=complex(1, 1)), "round samples must be a number"),
    (dict(time_limit=float("nan")), "time limit must be a finite number"),
    (dict(time_limit=-1.0), "time limit must be >= 0"),
    (dict(filter_width=-1.0), "filter width"),
    (dict(element_size=float("inf")), "element size must be a finite number"),
    (dict(dispersion_sampling="split"), "dispersion sampling must be SPLIT or SAMPLE"),
    (dict(dispersion_branches=0), "dispersion branches must be at least 1"),
    (dict(dispersion_branches=2.5), "dispersion branches must be a whole number"),
    (dict(dispersion_importance=1), "dispersion importance must be True or False"),
    (dict(dispersion_white_reflection="yes"), "dispersion white reflection must be True or False"),
    (dict(fresnel_split=None), "fresnel split must be True or False"),
    (dict(splat_bounce=0), "splat bounce must be True or False"),
    (dict(wavelength_step=0.001), "gives 300001 samples"),
    (dict(wavelength_step=1e-300), "more than the 4001 allowed"),
    (dict(wavelength_min=500.0, wavelength_max=503.0), "at least 2 are needed"),
    (dict(wavelength_step=0.0), "step must be > 0"),
    (dict(wavelength_step=float("nan")), "wavelength step must be a finite number"),
    (dict(wavelength_min=300.0), "outside the observer"),
    (dict(wavelength_min=700.0, wavelength_max=400.0), "must be below maximum"),
])
def test_bad_settings(kw, match):
    with pytest.raises(SceneError, match=match):
        RenderSettings(**kw).validate()


def test_settings_number_types_are_normalised():
    s = RenderSettings(samples=np.int64(4), seed=np.uint32(3), wavelength_step=np.float32(10), round_samples=2.0)
    s.validate()
    assert type(s.samples) is int and type(s.seed) is int and type(s.round_samples) is int
    assert type(s.wavelength_step) is float and s == RenderSettings(samples=4, seed=3, wavelength_step=10.0,
                                                                    round_samples=2)


def test_few_wavelengths_are_a_warning():
    assert RenderSettings().warnings() == []
    (w,) = RenderSettings(wavelength_step=30.0).warnings()
    assert "only 11 samples" in w and "16" in w
    with pytest.raises(SceneError, match="fewer than 16 make colours coarse"):
        RenderSettings(wavelength_min=400.0, wavelength_max=402.0).validate()


def test_single_wavelength_grid_with_a_blackbody_is_an_error_not_a_crash():
    s = scene()
    s.lights.temperature = np.array([3000.0, 0.0, 0.0])
    with pytest.raises(SceneError, match="at least 2"):
        render(s, RenderSettings(samples=1, wavelength_min=550.0, wavelength_max=552.0))


def test_blackbody_on_odd_grids():
    s = scene()
    s.lights.temperature = np.array([3000.0, 100.0, 1e9])
    res = render(s, RenderSettings(samples=1, light_paths=0, wavelength_min=475.55, wavelength_max=731.72,
                                   wavelength_step=25.617, threads=1), spectral_film=True)
    assert np.isfinite(res.spectral).all() and res.spectral.shape[-1] == 11


@pytest.mark.parametrize("lo, hi, step", [(360, 830, 0.1174), (360, 830, 0.117), (400, 700, 0.07), (380, 780, 0.0999)])
def test_the_suggested_smallest_wavelength_step_is_accepted_and_above_the_refused_one(lo, hi, step):
    """"use a step of at least X" must name an X the check accepts (and so above the step refused)."""
    import re
    with pytest.raises(SceneError) as e:
        RenderSettings(wavelength_min=lo, wavelength_max=hi, wavelength_step=step).validate()
    msg = str(e.value)
    assert f"wavelength step {step:g} nm" in msg, msg  # the step as given, not rounded to a neighbour
    bound = float(re.search(r"at least ([0-9.e+-]+) nm", msg).group(1))
    assert bound > step, msg
    # the grid the check counts: lo + i * step <= hi, at most 4001 samples
    assert int(np.floor((hi - lo) / bound + 1e-9)) + 1 <= 4001, msg
    RenderSettings(wavelength_min=lo, wavelength_max=hi, wavelength_step=bound).validate()


def test_the_suggested_largest_wavelength_step_gives_enough_samples():
    import re
    with pytest.raises(SceneError) as e:
        RenderSettings(wavelength_min=360, wavelength_max=830, wavelength_step=500).validate()
    bound = float(re.search(r"at most ([0-9.e+-]+) nm", str(e.value)).group(1))
    assert int(np.floor(470 / bound + 1e-9)) + 1 >= 16, str(e.value)
    assert not any("only" in w for w in RenderSettings(wavelength_min=360, wavelength_max=830,
                                                        wavelength_step=bound).warnings())
