"""Packaging metadata, without bpy: pyproject.toml agrees with blender_manifest.toml and requirements.txt,
the wheels tools/build_extension.py bundles into the extension are requirements.txt's pins, this venv
runs exactly those pins, and they work with the numpy of every Blender the manifest allows.
(tests/blender/test_packaging.py checks the built zip itself.)"""

from __future__ import annotations

import importlib.metadata as md
import os
import tomllib

import pytest
from packaging.requirements import Requirement
from packaging.version import Version

from opal_diffraction._scripts import REPO_ROOT, load_script

tool = load_script("tools/build_extension.py")


def _toml(name):
    with open(os.path.join(REPO_ROOT, name), "rb") as f:
        return tomllib.load(f)


def test_pyproject_version_is_the_manifests():
    project, manifest = _toml("pyproject.toml")["project"], _toml("blender_manifest.toml")
    assert project["name"] == manifest["id"] == "opal_diffraction"
    assert project["version"] == manifest["version"]
    assert project["requires-python"] == ">=3.11"


def test_pyproject_dependencies_admit_the_pins():
    """The ranges of pyproject.toml hold the exact versions requirements.txt pins (and the tests use)."""
    pins = tool.pinned_versions()
    deps = [Requirement(d) for d in _toml("pyproject.toml")["project"]["dependencies"]]
    names = {tool.canonical_name(r.name) for r in deps}
    assert {"numpy", "colour-science", "scipy", "openexr", "embreex"} <= names
    for r in deps:
        pin = pins.get(tool.canonical_name(r.name))
        assert pin is not None, f"{r.name} is a dependency but requirements.txt pins no version of it"
        assert r.specifier.contains(pin, prereleases=True), f"{r.name}=={pin} is outside pyproject's {r}"


def test_bundled_wheels_are_the_requirements_pins():
    pins = tool.pinned_versions()
    reqs = tool.wheel_requirements()
    assert [r.split("==")[0] for r, _ in reqs] == [name for name, _ in tool.BUNDLED]
    for req, _ in reqs:
        name, version = req.split("==")
        assert pins[tool.canonical_name(name)] == version


def test_the_venv_runs_the_pins_the_zip_bundles():
    """A stale venv (requirements.txt changed, ./setup.sh not rerun) fails here rather than testing
    other versions than the extension ships."""
    pins = tool.pinned_versions()
    for name in ["numpy", *(n for n, _ in tool.BUNDLED)]:
        try:
            installed = md.version(name)
        except md.PackageNotFoundError:
            if name == "embreex":  # x86-64 only (requirements.txt's marker)
                continue
            raise
        pin = pins[tool.canonical_name(name)]
        assert Version(installed) == Version(pin), f"the venv has {name} {installed}, requirements.txt pins {pin}"


@pytest.mark.parametrize("blender", sorted(tool.BLENDER_NUMPY))
def test_bundled_pins_support_the_numpy_blender_ships(blender):
    """Every bundled distribution that depends on numpy accepts the numpy of each Blender from
    blender_version_min on (the venv's metadata is the pins', see the test above)."""
    numpy = tool.BLENDER_NUMPY[blender]
    if tool.BLENDER_PYTHON[blender] != tool.current_python():
        pytest.skip(f"Blender {blender} runs Python {tool.BLENDER_PYTHON[blender]}: its pins are checked in that venv")
    for name, _ in tool.BUNDLED:
        try:
            requires = md.requires(name) or []
        except md.PackageNotFoundError:
            continue
        for r in map(Requirement, requires):
            if tool.canonical_name(r.name) == "numpy" and (r.marker is None or r.marker.evaluate({"extra": ""})):
                assert r.specifier.contains(numpy), f"{name} {md.version(name)} needs {r}; Blender {blender} has numpy {numpy}"


@pytest.mark.parametrize("python", tool.PYTHONS)
def test_each_python_has_its_pins(python):
    """requirements.txt's markers give each Python Blender runs one pin of every bundled wheel and of
    bpy and numpy, and the bpy wheel of that Python; the Blender ranges of the Pythons meet."""
    pins = tool.pinned_versions(python=python)
    assert {"bpy", "numpy"} | {tool.canonical_name(n) for n, _ in tool.BUNDLED} <= set(pins)
    assert [r.split("==")[0] for r, _ in tool.wheel_requirements(python=python)] == [n for n, _ in tool.BUNDLED]
    bpy_series = ".".join(pins["bpy"].split(".")[:2])
    low, high = tool.PYTHON_BLENDER[python]
    assert Version(low) <= Version(bpy_series) and (high is None or Version(bpy_series) < Version(high))
    assert [b for b, p in tool.BLENDER_PYTHON.items() if p == python], f"no Blender of BLENDER_NUMPY runs {python}"
    ranges = sorted(tool.PYTHON_BLENDER.values(), key=lambda r: Version(r[0]))
    assert all(a[1] == b[0] for a, b in zip(ranges, ranges[1:])) and ranges[-1][1] is None


def test_pins_differ_by_python_only_where_they_must():
    """One pin serves both Pythons unless it cannot (NumPy 1 vs 2, the bpy of each Blender, scipy)."""
    a, b = (tool.pinned_versions(python=p) for p in tool.PYTHONS)
    assert {n for n in a if a[n] != b.get(n)} == {"bpy", "numpy", "scipy"}


def test_blender_numpy_covers_the_manifests_minimum():
    minimum = _toml("blender_manifest.toml")["blender_version_min"]
    assert min(tool.BLENDER_NUMPY, key=Version) == ".".join(minimum.split(".")[:2])
