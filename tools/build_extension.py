"""Build the Blender extension zip, with the Python wheels Blender does not ship, and validate it.

    .venv/bin/python tools/build_extension.py [--platforms current|all|linux-x64,windows-x64,...]
                                              [--pythons current|all|3.11,3.13] [--no-wheels]
                                              [--output-dir build] [--wheel-cache DIR] [--offline]

Steps:
1. Stage ``build/stage/``: ``blender_manifest.toml`` beside the contents of ``opal_diffraction/``,
   so the package's own ``__init__.py`` (register/unregister) is the extension's root and every
   import inside it is relative (the extension CLI wants ``__init__.py`` next to the manifest).
2. Download the wheels of the runtime dependencies Blender does not bundle (``pip download``,
   cached outside the repository in ``~/.cache/opal_wheels/cp<XY>-<platform>/``, or ``--wheel-cache``
   / ``$OPAL_WHEEL_CACHE``) for each Python Blender runs (3.11: Blender 4.2 LTS-5.0; 3.13: Blender
   5.1 and later) and list them in that Python's staged manifest with its ``platforms`` and the
   Blender range of that Python (``blender_version_min``/``blender_version_max``). Blender ships numpy; it does not ship colour-science (spectra, CIE observer,
   blackbody) or the scipy and typing-extensions it imports, OpenEXR's Python binding (spectral
   EXR output), embreex (Embree ray casting, x86-64 only; without it the core falls back to its
   NumPy BVH) or threadpoolctl (one BLAS thread while a render runs: core/util/blas_threads.py), nor
   numba and its LLVM binding llvmlite (the compiled kernels, core/util/jit.py; numba 0.68 has no
   macOS x86-64 wheels, so that zip goes without them and renders with the NumPy reference). Their
   versions are the ``==`` pins of ``requirements.txt`` for that Python (its environment markers
   pick the pin): the zip ships exactly what the test venv of that Python runs. Each wheel is the
   oldest platform tag that has one (PLATFORM_TAGS, tried in order: e.g. scipy's macosx_12_0 arm64
   wheel rather than its macosx_14_0 one, which macOS 12/13 cannot load).
3. ``blender_ext.py build`` (the extension CLI inside the bpy wheel), ``--split-platforms`` when
   wheels are bundled (one zip per platform), then ``blender_ext.py validate`` on every zip.

The zips land in ``build/`` (gitignored): ``opal_diffraction-<version>-py<XY>-<platform>.zip``
(py311 for Blender 4.2-5.0, py313 for Blender 5.1+), or ``opal_diffraction-<version>.zip`` for
``--no-wheels``, a platform-independent zip for machines that already have the dependencies in
Blender's Python. Exit code 0 when every zip validates.
"""

from __future__ import annotations

import argparse
import glob
import os
import platform
import re
import shutil
import subprocess
import sys
import tomllib

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
PACKAGE = os.path.join(ROOT, "opal_diffraction")
MANIFEST = os.path.join(ROOT, "blender_manifest.toml")
REQUIREMENTS = os.path.join(ROOT, "requirements.txt")
#: Where downloaded wheels are kept between builds (outside the repository, shared by checkouts)
WHEEL_CACHE = os.environ.get("OPAL_WHEEL_CACHE") or os.path.join(os.path.expanduser("~"), ".cache", "opal_wheels")

#: Runtime dependencies Blender does not ship, bundled as wheels; (distribution, optional: the core
#: falls back to NumPy code where it has no wheel: embreex's BVH, numba's reference path). Each is
#: pinned (``==``) in requirements.txt, the one source of their versions (see wheel_requirements).
#: The scipy pin must support every numpy Blender bundles from blender_version_min on (Blender
#: 4.2 LTS: numpy 1.24.3; 5.0: 1.26.4).
BUNDLED = [
    ("colour-science", False),
    ("typing-extensions", False),
    ("scipy", False),
    ("OpenEXR", False),
    ("embreex", True),
    ("threadpoolctl", False),
    ("numba", True),
    ("llvmlite", True),
]
#: numpy bundled with Blender releases (the oldest is blender_version_min's): every bundled wheel
#: of that Blender's Python that depends on numpy must accept it (tests/system/test_packaging_meta.py,
#: tests/blender/test_packaging.py). 4.2 LTS: numpy 1.24.3 (Blender's build_files/build_environment/
#: cmake/versions.cmake of that series; also what SciPy's version warning reports inside Blender
#: 4.2); 5.0: 1.26.4 (versions.cmake, and the bpy 5.0.1 wheel requires numpy>=1.26,<2). 4.3-4.5
#: bundle a numpy between the two. 5.1: the lowest numpy the bpy wheels on Python 3.13 admit (bpy
#: 5.2.3 requires numpy>=2.2,<3; Blender's own bundled 2.x version was not checked here).
BLENDER_NUMPY = {"4.2": "1.24.3", "5.0": "1.26.4", "5.1": "2.2"}
#: The Python of each Blender series of BLENDER_NUMPY (Blender 5.1 moved from 3.11 to 3.13)
BLENDER_PYTHON = {"4.2": "3.11", "5.0": "3.11", "5.1": "3.13"}
#: Python -> the Blender range (manifest blender_version_min, blender_version_max; max exclusive, None:
#: open) whose Python it is: the staged manifest of that Python's zips gets these.
PYTHON_BLENDER = {"3.11": ("4.2.0", "5.1.0"), "3.13": ("5.1.0", None)}
#: The Pythons the zips are built for (--pythons all)
PYTHONS = list(PYTHON_BLENDER)
#: Blender platform -> pip --platform tags, OLDEST first: a wheel is taken from the first tag that has
#: one (pip also accepts older tags of the same family for a tag: macosx_12_0 takes macosx_11_0 wheels),
#: so each wheel runs on the oldest system its project supports. Blender 4.2+ needs glibc 2.28 on Linux
#: and macOS 11.2 on both Macs.
PLATFORM_TAGS = {
    "linux-x64": ["manylinux2014_x86_64", "manylinux_2_28_x86_64"],
    "windows-x64": ["win_amd64"],
    "macos-arm64": ["macosx_11_0_arm64", "macosx_12_0_arm64", "macosx_13_0_arm64", "macosx_14_0_arm64"],
    "macos-x64": ["macosx_10_15_x86_64", "macosx_11_0_x86_64", "macosx_12_0_x86_64", "macosx_13_0_x86_64",
                  "macosx_14_0_x86_64"],
}
EXCLUDE = ("__pycache__", ".pyc", ".pyo", ".DS_Store")
#: What the stage leaves out of the package (shutil.ignore_patterns patterns)
DEV_ONLY = ("__pycache__", "*.pyc", "*.pyo", "_scripts.py")


def canonical_name(name: str) -> str:
    """A distribution name as PEP 503 normalises it (``OpenEXR`` -> ``openexr``, ``typing_extensions``
    -> ``typing-extensions``)."""
    return re.sub(r"[-_.]+", "-", name).lower()


def current_python() -> str:
    """``"3.11"``: the major.minor of this interpreter."""
    return f"{sys.version_info.major}.{sys.version_info.minor}"


def _marker_applies(marker: str, python: str) -> bool:
    """Whether a requirement's environment marker holds for ``python`` (``"3.13"``). Only the Python
    decides: a platform marker (embreex's x86-64 one) says where a wheel exists, and the pin is the
    same on every platform (the download skips optional wheels a platform lacks)."""
    try:
        from packaging.markers import Marker
    except ImportError:  # pip's vendored copy, present wherever pip is
        from pip._vendor.packaging.markers import Marker
    env = {"python_version": python, "python_full_version": python + ".0", "platform_machine": "x86_64",
           "implementation_name": "cpython", "platform_python_implementation": "CPython", "extra": ""}
    return Marker(marker).evaluate(env)


def pinned_versions(path: str = REQUIREMENTS, python: str | None = None) -> dict[str, str]:
    """``{canonical name: version}`` of the ``name==version`` lines of a requirements file whose
    environment marker holds for ``python`` (default: this interpreter's; see _marker_applies), comments
    ignored; ranges and wildcards are not pins and are left out."""
    python = python or current_python()
    pins = {}
    with open(path, encoding="utf-8") as f:
        for line in f:
            line, _, marker = line.split("#", 1)[0].partition(";")
            m = re.fullmatch(r"([A-Za-z0-9][A-Za-z0-9._-]*)(?:\[[^\]]*\])?\s*==\s*([A-Za-z0-9._+!-]+)", line.strip())
            if m and (not marker.strip() or _marker_applies(marker.strip(), python)):
                name = canonical_name(m.group(1))
                if name in pins:
                    raise SystemExit(f"error: {os.path.relpath(path, ROOT)} pins {name} twice for Python {python}")
                pins[name] = m.group(2)
    return pins


def wheel_requirements(path: str = REQUIREMENTS, python: str | None = None) -> list[tuple[str, bool]]:
    """The bundled wheels as pip requirements, ``[("scipy==1.15.3", False), ...]``, at the pins of
    requirements.txt for ``python`` (default: this interpreter's); exits with an error when one of
    BUNDLED is not pinned there."""
    pins = pinned_versions(path, python)
    missing = [name for name, _ in BUNDLED if canonical_name(name) not in pins]
    if missing:
        raise SystemExit(f"error: {os.path.relpath(path, ROOT)} pins no exact version (==) of {missing}; "
                         "the extension bundles these wheels at the venv's pins")
    return [(f"{name}=={pins[canonical_name(name)]}", optional) for name, optional in BUNDLED]


def wheel_name_version(filename: str) -> tuple[str, str]:
    """``(canonical name, version)`` of a wheel file name (``scipy-1.15.3-cp311-...whl``)."""
    name, version = os.path.basename(filename).split("-")[:2]
    return canonical_name(name), version


def blender_ext_cli() -> str:
    """Path of the extension CLI shipped inside the bpy wheel."""
    import importlib.util

    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        raise SystemExit("error: the bpy module is not installed (run ./setup.sh)")
    hits = sorted(glob.glob(os.path.join(os.path.dirname(spec.origin), "*", "scripts", "addons_core", "bl_pkg",
                                         "cli", "blender_ext.py")))
    if not hits:
        raise SystemExit("error: blender_ext.py not found inside the bpy module")
    return hits[-1]


def current_platform() -> str:
    machine = platform.machine().lower()
    machine = {"x86_64": "x64", "amd64": "x64", "aarch64": "arm64"}.get(machine, machine)
    system = {"darwin": "macos", "windows": "windows", "linux": "linux"}.get(platform.system().lower())
    return f"{system}-{machine}"


def stage(stage_dir: str, wheels: dict[str, list[str]], python: str | None = None) -> None:
    """Copy the package and write the manifest (with its wheels and platforms, and with a ``python``
    the Blender range of that Python) into stage_dir."""
    if os.path.exists(stage_dir):
        shutil.rmtree(stage_dir)
    # _scripts.py loads the repository's example and tool scripts for tests and benchmarks: not part of the add-on
    shutil.copytree(PACKAGE, stage_dir, ignore=shutil.ignore_patterns(*DEV_ONLY))
    with open(MANIFEST, "rb") as f:
        tomllib.load(f)  # fail early on a broken manifest
    with open(MANIFEST, encoding="utf-8") as f:
        text = f.read().rstrip() + "\n"
    if wheels:
        os.makedirs(os.path.join(stage_dir, "wheels"), exist_ok=True)
        names = []
        for plat, files in wheels.items():
            for path in files:
                name = os.path.basename(path)
                if name not in names:
                    shutil.copy2(path, os.path.join(stage_dir, "wheels", name))
                    names.append(name)
        extra = "\n# Added by tools/build_extension.py\n"
        extra += "platforms = [" + ", ".join(f'"{p}"' for p in wheels) + "]\n"
        extra += "wheels = [\n" + "".join(f'  "./wheels/{n}",\n' for n in sorted(names)) + "]\n"
        if python:
            low, high = PYTHON_BLENDER[python]
            text = re.sub(r'(?m)^blender_version_min\s*=.*\n', "", text)
            extra += f'# Python {python}\nblender_version_min = "{low}"\n'
            extra += f'blender_version_max = "{high}"\n' if high else ""
        # top-level keys must come before the first [table] of the TOML file
        head, sep, tail = text.partition("\n[")
        text = head.rstrip() + "\n" + extra + (sep + tail if sep else "")
    with open(os.path.join(stage_dir, "blender_manifest.toml"), "w", encoding="utf-8") as f:
        f.write(text)


def _cached_wheels(folder: str, key: tuple[str, str]) -> list[str]:
    return [p for p in glob.glob(os.path.join(folder, "*.whl")) if wheel_name_version(p) == key]


def download_wheels(plat: str, cache: str, offline: bool, python: str | None = None) -> list[str]:
    """Wheels for one Blender platform and Python (cached in ``<cache>/cp<XY>-<plat>``); optional ones
    are skipped when unavailable."""
    python = python or current_python()
    folder = os.path.join(cache, f"cp{python.replace('.', '')}-{plat}")
    os.makedirs(folder, exist_ok=True)
    out = []
    for req, optional in wheel_requirements(python=python):
        name, version = req.split("==")
        key = (canonical_name(name), version)
        have = _cached_wheels(folder, key)  # only the pinned version: a wheel cached for an older pin is not reused
        if have:
            out.append(sorted(have)[-1])
            continue
        if offline:
            if optional:
                continue
            raise SystemExit(f"error: no cached wheel for {req} ({plat}) in {folder} and --offline given")
        for tag in PLATFORM_TAGS[plat]:  # oldest first: the first tag with a wheel wins
            cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--only-binary=:all:",
                   "--python-version", python, "--implementation", "cp", "--platform", tag, "-d", folder, req]
            res = subprocess.run(cmd, capture_output=True, text=True)
            if res.returncode == 0:
                break
        if res.returncode != 0:
            if optional:
                fallback = "the NumPy BVH" if name == "embreex" else "the NumPy reference of the kernels"
                print(f"note: {req} has no wheel for {plat}: skipped ({fallback} is used there)")
                continue
            raise SystemExit(f"error: pip could not download {req} for {plat}:\n{res.stderr.strip()}")
        have = _cached_wheels(folder, key)
        if not have:
            raise SystemExit(f"error: pip downloaded no wheel named {key[0]}-{version}-*.whl for {req} ({plat})")
        out.append(sorted(have)[-1])
    return out


def run_cli(cli: str, args: list[str]) -> subprocess.CompletedProcess:
    res = subprocess.run([sys.executable, cli, *args], capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(f"error: blender_ext {args[0]} failed:\n{res.stdout}{res.stderr}")
    return res


def build(platforms: list[str], with_wheels: bool, output_dir: str, offline: bool = False,
          pythons: list[str] | None = None, wheel_cache: str | None = None) -> list[str]:
    """Build and validate one zip per Python (default: this interpreter's) and platform; return the
    zip paths (``<id>-<version>-py<XY>-<platform>.zip``; one ``<id>-<version>.zip`` without wheels)."""
    output_dir = os.path.abspath(output_dir)
    os.makedirs(output_dir, exist_ok=True)
    with open(MANIFEST, "rb") as f:
        manifest = tomllib.load(f)
    cli = blender_ext_cli()
    prefix = f"{manifest['id']}-{manifest['version']}"
    if not with_wheels:
        target = os.path.join(output_dir, f"{prefix}.zip")
        if os.path.exists(target):
            os.remove(target)
        stage_dir = os.path.join(output_dir, "stage")
        stage(stage_dir, {})
        run_cli(cli, ["build", "--source-dir", stage_dir, "--output-dir", output_dir])
        if not os.path.exists(target):
            raise SystemExit(f"error: the build produced no {target}")
        run_cli(cli, ["validate", target])
        return [target]
    cache = os.path.abspath(wheel_cache or WHEEL_CACHE)
    zips = []
    for python in pythons or [current_python()]:
        if python not in PYTHON_BLENDER:
            raise SystemExit(f"error: no Blender runs Python {python}; known: {PYTHONS}")
        tag = "py" + python.replace(".", "")
        wheels = {p: download_wheels(p, cache, offline, python) for p in platforms}
        stage_dir = os.path.join(output_dir, f"stage-{tag}")
        stage(stage_dir, wheels, python)
        raw_dir = os.path.join(output_dir, f"raw-{tag}")  # the CLI's names, before the Python is added
        if os.path.exists(raw_dir):
            shutil.rmtree(raw_dir)
        os.makedirs(raw_dir)
        # one zip per platform, named <id>-<version>-<platform>.zip
        run_cli(cli, ["build", "--source-dir", stage_dir, "--output-dir", raw_dir, "--split-platforms"])
        built = sorted(glob.glob(os.path.join(raw_dir, f"{prefix}-*.zip")))
        if len(built) != len(platforms):
            raise SystemExit(f"error: the build produced {built} in {raw_dir} for {platforms}")
        for z in built:
            target = os.path.join(output_dir, f"{prefix}-{tag}-{os.path.basename(z)[len(prefix) + 1:]}")
            os.replace(z, target)
            run_cli(cli, ["validate", target])
            zips.append(target)
        os.rmdir(raw_dir)
    return zips


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--platforms", default="current",
                    help="'current' (default), 'all', or a comma-separated list of " + ", ".join(PLATFORM_TAGS))
    ap.add_argument("--pythons", default="current",
                    help="'current' (default: this interpreter's), 'all', or a comma-separated list of " + ", ".join(PYTHONS))
    ap.add_argument("--no-wheels", action="store_true",
                    help="bundle no wheels (for a Blender whose Python already has the dependencies)")
    ap.add_argument("--output-dir", default=os.path.join(ROOT, "build"))
    ap.add_argument("--wheel-cache", default=WHEEL_CACHE, help=f"where wheels are cached (default {WHEEL_CACHE})")
    ap.add_argument("--offline", action="store_true", help="use only wheels already cached in the wheel cache")
    args = ap.parse_args(argv)
    if args.platforms == "current":
        platforms = [current_platform()]
    elif args.platforms == "all":
        platforms = list(PLATFORM_TAGS)
    else:
        platforms = [p.strip() for p in args.platforms.split(",") if p.strip()]
    unknown = [p for p in platforms if p not in PLATFORM_TAGS]
    if unknown and not args.no_wheels:
        raise SystemExit(f"error: unknown platform(s) {unknown}; known: {sorted(PLATFORM_TAGS)}")
    if args.pythons == "current":
        pythons = [current_python()]
    elif args.pythons == "all":
        pythons = list(PYTHONS)
    else:
        pythons = [p.strip() for p in args.pythons.split(",") if p.strip()]
    zips = build(platforms, not args.no_wheels, args.output_dir, args.offline, pythons, args.wheel_cache)
    for z in zips:
        print(f"built and validated {z} ({os.path.getsize(z) / 1e6:.1f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
