"""The extension zip: builds with tools/build_extension.py, passes Blender's own validation, installs
and enables through bpy.ops.extensions.package_install_files in a fresh Blender (a subprocess with
its own user folder), renders from the installed copy, and writes nothing into its own folder."""

from __future__ import annotations

import importlib.metadata as md
import io
import json
import os
import subprocess
import sys
import tomllib
import zipfile
from email.parser import Parser

import pytest
from packaging.requirements import Requirement
from packaging.version import Version

from opal_diffraction._scripts import REPO_ROOT as ROOT
from opal_diffraction._scripts import load_script


def _build_tool():
    return load_script("tools/build_extension.py")


@pytest.fixture(scope="module")
def built_zip():
    tool = _build_tool()
    # build/ is gitignored; its wheel cache makes rebuilds offline and fast
    zips = tool.build([tool.current_platform()], with_wheels=True, output_dir=os.path.join(ROOT, "build"))
    assert len(zips) == 1
    return zips[0]


def test_manifest_is_valid_and_complete():
    with open(os.path.join(ROOT, "blender_manifest.toml"), "rb") as f:
        m = tomllib.load(f)
    assert m["schema_version"] == "1.0.0" and m["id"] == "opal_diffraction" and m["type"] == "add-on"
    assert m["blender_version_min"] >= "4.2.0" and m["license"] == ["SPDX:GPL-3.0-or-later"]
    assert "files" in m["permissions"]
    # the Scheduler setting (Dask cluster rendering) opens network connections
    assert "Dask" in m["permissions"].get("network", "")
    assert "example.invalid" not in m.get("website", ""), "a placeholder website"


# the tests of the built zip are slow: the build (its wheels downloaded on a fresh clone) and a second Blender
@pytest.mark.slow
def test_zip_builds_and_validates(built_zip):
    tool = _build_tool()
    res = subprocess.run([sys.executable, tool.blender_ext_cli(), "validate", built_zip], capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr
    with zipfile.ZipFile(built_zip) as z:
        names = z.namelist()
        manifest = tomllib.loads(z.read("blender_manifest.toml").decode())
    assert "__init__.py" in names and "blender/engine.py" in names and "core/render/frame.py" in names
    assert not any("__pycache__" in n or n.endswith(".pyc") for n in names)
    wheels = " ".join(manifest["wheels"])
    for dep in ("colour_science", "scipy", "openexr"):
        assert dep in wheels.lower(), dep
    assert manifest["platforms"] == [tool.current_platform()]
    # the Blender range of this Python's wheels (Blender's repository hides a zip of another Python)
    low, high = tool.PYTHON_BLENDER[tool.current_python()]
    assert manifest["blender_version_min"] == low and manifest.get("blender_version_max") == high
    tag = "cp" + tool.current_python().replace(".", "")
    assert all(f"-{tag}-" in w or "-py3-none-" in w for w in manifest["wheels"]), manifest["wheels"]
    assert not any(n.endswith("_scripts.py") for n in names), "the development-only loader is in the zip"


@pytest.mark.slow
def test_zip_wheels_are_the_venvs_pins(built_zip):
    """The shipped extension and the test venv use the same pinned versions: each wheel in the zip is
    requirements.txt's pin, which is what this venv has installed; and every wheel that depends on
    numpy accepts the numpy of each Blender from blender_version_min on."""
    tool = _build_tool()
    pins = tool.pinned_versions()
    with zipfile.ZipFile(built_zip) as z:
        manifest = tomllib.loads(z.read("blender_manifest.toml").decode())
        shipped = {}
        for w in manifest["wheels"]:
            name, version = tool.wheel_name_version(w)
            shipped[name] = version
            with zipfile.ZipFile(io.BytesIO(z.read(w.removeprefix("./")))) as wheel:
                meta_path = next(n for n in wheel.namelist() if n.endswith(".dist-info/METADATA"))
                meta = Parser().parsestr(wheel.read(meta_path).decode())
            for r in map(Requirement, meta.get_all("Requires-Dist") or []):
                if tool.canonical_name(r.name) == "numpy" and (r.marker is None or r.marker.evaluate({"extra": ""})):
                    for blender, numpy in tool.BLENDER_NUMPY.items():
                        if tool.BLENDER_PYTHON[blender] != tool.current_python():
                            continue  # another Python's zip
                        assert r.specifier.contains(numpy), f"{w} needs {r}; Blender {blender} has numpy {numpy}"
    expected = {tool.canonical_name(n) for n, optional in tool.BUNDLED if not optional}
    assert expected <= set(shipped) <= {tool.canonical_name(n) for n, _ in tool.BUNDLED}
    for name, version in shipped.items():
        assert version == pins[name], f"the zip ships {name} {version}, requirements.txt pins {pins[name]}"
        assert Version(md.version(name)) == Version(version), f"the venv has {name} {md.version(name)}, the zip {version}"


INSTALL_SCRIPT = r"""
import json, os, sys, time
import bpy, addon_utils
zip_path, out = sys.argv[1], sys.argv[2]
t0 = time.time()
res = bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
mod = "bl_ext.user_default.opal_diffraction"
info = {"install": sorted(res), "enabled": list(addon_utils.check(mod)), "install_s": time.time() - t0}
pkg = sys.modules[mod]
folder = os.path.dirname(pkg.__file__)
info["folder"] = folder
def files():
    return sorted(os.path.relpath(os.path.join(d, f), folder) for d, _, fs in os.walk(folder) for f in fs
                  if "__pycache__" not in d)
before = files()
sc = bpy.context.scene
sc.render.engine = "OPAL_DIFFRACTION"
sc.render.resolution_x, sc.render.resolution_y = 24, 16
sc.opal.samples = 2
sc.render.filepath = os.path.join(out, "installed.png")
bpy.ops.render.render(write_still=True)
info["rendered"] = os.path.exists(sc.render.filepath)
info["engine_module"] = type(bpy.context.scene.opal).__module__
info["new_files"] = sorted(set(files()) - set(before))
json.dump(info, open(os.path.join(out, "info.json"), "w"))
"""


@pytest.mark.slow
def test_zip_installs_enables_and_renders(built_zip, tmp_path):
    script = tmp_path / "install.py"
    script.write_text(INSTALL_SCRIPT)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    env.pop("PYTHONPATH", None)
    res = subprocess.run([sys.executable, str(script), built_zip, str(tmp_path)], capture_output=True, text=True,
                         env=env, cwd=str(tmp_path), timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    info = json.loads((tmp_path / "info.json").read_text())
    assert info["install"] == ["FINISHED"] and info["enabled"] == [True, True]
    assert info["folder"].startswith(str(tmp_path / "user"))  # the installed copy, not the source tree
    assert info["engine_module"].startswith("bl_ext.user_default.opal_diffraction")
    assert info["rendered"]
    assert info["new_files"] == [], "the add-on wrote into its own folder"
    assert "Traceback" not in res.stderr
