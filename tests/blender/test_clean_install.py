"""The extension zip in a clean Blender of this Python: a virtualenv holding only the bpy wheel of that
Blender (requirements.txt's pin for this interpreter's Python: bpy 5.0.1 on 3.11, 5.2.3 on 3.13, with
nothing but bpy's own dependencies, which Blender bundles too), a fresh user-resource folder
(BLENDER_USER_RESOURCES) and a fresh user cache, the zip built for this platform and Python installed
the way Blender installs an extension (bpy.ops.extensions.package_install_files, as Install from Disk
does), a scene rendered with OPAL_DIFFRACTION, and each bundled dependency (scipy, colour-science,
OpenEXR, threadpoolctl, numba, llvmlite, embreex where it has a wheel) imported from the extension's
own site-packages (``<user resources>/extensions/.local/lib/python3.X/site-packages``), not from a
venv: the venv does not have them (checked first).

The clean venv is kept between runs in the user cache (``~/.cache/opal_diffraction/clean-bpy-<pin>-
py<XY>``; it takes a ~400 MB wheel) and re-made when it holds anything more than bpy's closure.
Run it with ``OPAL_CLEAN_INSTALL_REPORT=path.json`` to keep the subprocess's report (versions, where
each module came from, the render's pixel mean)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest

from opal_diffraction._scripts import REPO_ROOT as ROOT
from opal_diffraction._scripts import load_script

pytestmark = pytest.mark.slow

#: import name -> distribution, for what the zip bundles (optional ones may lack a wheel on a platform)
BUNDLED_MODULES = {"scipy": "scipy", "colour": "colour-science", "OpenEXR": "OpenEXR", "numba": "numba",
                   "llvmlite": "llvmlite", "threadpoolctl": "threadpoolctl", "typing_extensions": "typing-extensions",
                   "embreex": "embreex"}
#: what a clean venv may hold besides bpy: bpy's own dependencies (Blender bundles numpy, requests,
#: zstandard and cython in its Python too) and the venv's pip
ALLOWED = {"bpy", "numpy", "requests", "zstandard", "cython", "cattrs", "attrs", "typing-extensions",
           "charset-normalizer", "idna", "urllib3", "certifi", "pip", "setuptools", "exceptiongroup"}


def _tool():
    return load_script("tools/build_extension.py")


def _clean_venv(tool) -> str:
    """Path of the python of a venv holding only this Python's pinned bpy (made once, then reused)."""
    pin = tool.pinned_versions()["bpy"]
    tag = tool.current_python().replace(".", "")
    folder = os.path.join(os.path.expanduser("~"), ".cache", "opal_diffraction", f"clean-bpy-{pin}-py{tag}")
    python = os.path.join(folder, "Scripts" if sys.platform == "win32" else "bin", "python")
    if os.path.exists(python) and _distributions(python) - ALLOWED:
        shutil.rmtree(folder)  # someone installed more into it: not clean any more
    if not os.path.exists(python):
        base = getattr(sys, "_base_executable", sys.executable)
        subprocess.run([base, "-m", "venv", folder], check=True)
        # cwd: not the checkout, whose opal_diffraction.egg-info python -c / pip would see on sys.path
        subprocess.run([python, "-m", "pip", "install", "-q", "--disable-pip-version-check", f"bpy=={pin}"], check=True,
                       cwd=folder, env=_env_without_project())
    return python


def _distributions(python: str) -> set[str]:
    out = subprocess.run([python, "-c", "import importlib.metadata as m, json; "
                          "print(json.dumps(sorted({d.metadata['Name'] for d in m.distributions()})))"],
                         capture_output=True, text=True, check=True, env=_env_without_project(),
                         cwd=os.path.dirname(os.path.dirname(python))).stdout
    return {_tool().canonical_name(n) for n in json.loads(out)}


def _env_without_project(**extra) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "NUMBA", "OPAL_", "VIRTUAL_ENV"))}
    env.update(PYTHONNOUSERSITE="1", **extra)  # nor ~/.local's site-packages
    return env


SCRIPT = r"""
import importlib, json, os, sys
import bpy, addon_utils
zip_path, out = sys.argv[sys.argv.index("--") + 1:]
info = {"python": sys.version.split()[0], "bpy": bpy.app.version_string, "sys_path": sys.path}
before = set(sys.modules)
res = bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
mod = "bl_ext.user_default.opal_diffraction"
info["install"] = sorted(res)
info["enabled"] = list(addon_utils.check(mod))
sc = bpy.context.scene
sc.render.engine = "OPAL_DIFFRACTION"
sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = 48, 32, 100
sc.opal.samples = 4
sc.render.image_settings.file_format = "OPEN_EXR"
sc.render.filepath = os.path.join(out, "clean.exr")
bpy.ops.render.render(write_still=True)
img = bpy.data.images.load(sc.render.filepath)
px = list(img.pixels)
rgb = [v for i, v in enumerate(px) if i % 4 != 3]
info["pixel_mean"] = sum(rgb) / len(rgb)
info["pixels"] = len(px) // 4
# what the render imported (before this script imports anything itself), then the rest of the bundle
info["imported_by_render"] = sorted(n for n in set(sys.modules) - before if "." not in n)
info["origins"] = {n: getattr(sys.modules[n], "__file__", None) for n in info["imported_by_render"]}
jit = sys.modules[mod + ".core.util.jit"]
info["kernels"] = {"available": jit.AVAILABLE, "reason": jit.UNAVAILABLE_REASON, "path": jit.kernels_path("auto")}
modules = {}
for name in NAMES:
    try:
        m = importlib.import_module(name)
    except ImportError as e:
        modules[name] = {"error": str(e)}
        continue
    modules[name] = {"file": m.__file__, "version": getattr(m, "__version__", None)}
modules["numpy"] = {"file": sys.modules["numpy"].__file__, "version": sys.modules["numpy"].__version__}
info["modules"] = modules
json.dump(info, open(os.path.join(out, "info.json"), "w"), indent=1)
"""


@pytest.fixture(scope="module")
def zip_for_this_python():
    tool = _tool()
    zips = tool.build([tool.current_platform()], with_wheels=True, output_dir=os.path.join(ROOT, "build"))
    assert len(zips) == 1
    return zips[0]


def test_zip_installs_and_renders_in_a_clean_blender(zip_for_this_python, tmp_path):
    tool = _tool()
    python = _clean_venv(tool)
    pins = tool.pinned_versions()
    have = _distributions(python)
    assert "bpy" in have and not have - ALLOWED, f"the clean venv holds {sorted(have - ALLOWED)}"
    assert not have & {tool.canonical_name(d) for d in BUNDLED_MODULES.values() if d != "typing-extensions"}
    user, cache = tmp_path / "user", tmp_path / "cache"
    script = tmp_path / "clean_install.py"
    script.write_text(SCRIPT.replace("NAMES", repr(sorted(BUNDLED_MODULES))))
    # a fresh user-resource folder and user cache (numba's compiled kernels, jit.cache_dir())
    env = _env_without_project(BLENDER_USER_RESOURCES=str(user), XDG_CACHE_HOME=str(cache),
                               LOCALAPPDATA=str(cache), HOME=str(tmp_path / "home"))
    res = subprocess.run([python, str(script), "--", zip_for_this_python, str(tmp_path)], capture_output=True,
                         text=True, env=env, cwd=str(tmp_path), timeout=1800)
    assert res.returncode == 0, res.stdout[-4000:] + res.stderr[-4000:]
    info = json.loads((tmp_path / "info.json").read_text())
    if os.environ.get("OPAL_CLEAN_INSTALL_REPORT"):
        report = dict(info, zip=os.path.basename(zip_for_this_python), zip_mb=os.path.getsize(zip_for_this_python) / 1e6)
        report.pop("sys_path")
        with open(os.environ["OPAL_CLEAN_INSTALL_REPORT"], "w") as f:
            json.dump(report, f, indent=1)
    assert info["python"].startswith(tool.current_python() + ".") and info["bpy"].startswith(pins["bpy"])
    assert info["install"] == ["FINISHED"] and info["enabled"] == [True, True]
    site = os.path.join(str(user), "extensions", ".local", "lib", f"python{tool.current_python()}", "site-packages")
    assert os.path.isdir(site), f"no extension site-packages at {site}"
    optional = {n for n, opt in tool.BUNDLED if opt}
    for name, dist in BUNDLED_MODULES.items():
        got = info["modules"][name]
        if "error" in got:
            assert dist in optional, f"{name} did not import in the clean Blender: {got['error']}"
            continue
        if tool.canonical_name(dist) in have:
            continue  # bpy's closure has it too (typing-extensions, through cattrs): Blender's copy may win
        assert os.path.realpath(got["file"]).startswith(os.path.realpath(site) + os.sep), \
            f"{name} came from {got['file']}, not from the extension's site-packages {site}"
    for name in ("scipy", "colour", "OpenEXR", "numba"):
        assert "file" in info["modules"][name] or tool.current_platform() == "macos-x64", name
    # Blender's own numpy (here: bpy's), not a bundled one
    assert not os.path.realpath(info["modules"]["numpy"]["file"]).startswith(os.path.realpath(site))
    assert info["modules"]["scipy"]["version"] == pins["scipy"]
    # the render imported the bundle itself (the core needs colour and scipy; the JIT where numba loads)
    assert {"colour", "scipy"} <= set(info["imported_by_render"])
    if "file" in info["modules"]["numba"]:
        assert info["kernels"]["available"] and "numba" in info["imported_by_render"], info["kernels"]
    # nothing came from the checkout or from the project's venv
    for name, path in info["origins"].items():
        real = os.path.realpath(path) if path else ""
        assert not real.startswith((os.path.realpath(ROOT) + os.sep, os.path.realpath(sys.prefix) + os.sep)), (name, path)
    assert info["pixels"] == 48 * 32 and 0 < info["pixel_mean"] < 100, info["pixel_mean"]
    assert "Traceback" not in res.stderr, res.stderr[-4000:]
