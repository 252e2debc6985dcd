"""Build the Blender extension zip, with the Python wheels Blender does not ship, and validate it.

    .venv/bin/python tools/build_extension.py [--platforms current|all|linux-x64,windows-x64,...]
                                              [--no-wheels] [--output-dir build] [--offline]

Steps:
1. Stage ``build/stage/``: ``blender_manifest.toml`` beside the contents of ``opal_diffraction/``,
   so the package's own ``__init__.py`` (register/unregister) is the extension's root and every
   import inside it is relative (the extension CLI wants ``__init__.py`` next to the manifest).
2. Download the wheels of the runtime dependencies Blender does not bundle (``pip download``,
   cached in ``build/wheels/<platform>/``) and list them in the staged manifest with its
   ``platforms``. Blender ships numpy; it does not ship colour-science (spectra, CIE observer,
   blackbody) or the scipy and typing-extensions it imports, OpenEXR's Python binding (spectral
   EXR output), embreex (Embree ray casting, x86-64 only; without it the core falls back to its
   NumPy BVH) or threadpoolctl (one BLAS thread while a render runs: core/util/blas_threads.py), nor
   numba and its LLVM binding llvmlite (the compiled kernels, core/util/jit.py; numba 0.68 has no
   macOS x86-64 wheels, so that zip goes without them and renders with the NumPy reference). Their
   versions are the ``==`` pins of ``requirements.txt``: the zip ships exactly what the test venv runs.
3. ``blender_ext.py build`` (the extension CLI inside the bpy wheel), ``--split-platforms`` when
   wheels are bundled (one zip per platform), then ``blender_ext.py validate`` on every zip.

The zips land in ``build/`` (gitignored): ``opal_diffraction-<version>-<platform>.zip`` (or
without the platform suffix for ``--no-wheels``, a platform-independent zip for machines that
already have the dependencies in Blender's Python). Exit code 0 when every zip validates.
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
#: that depends on numpy must accept each (tests/system/test_packaging_meta.py, tests/blender/test_packaging.py).
#: 4.2 LTS: numpy 1.24.3 (Blender's build_files/build_environment/cmake/versions.cmake of that
#: series; also what SciPy's version warning reports inside Blender 4.2); 5.0: 1.26.4 (versions.cmake,
#: and the bpy 5.0.1 wheel requires numpy>=1.26,<2). 4.3-4.5 bundle a numpy between the two.
BLENDER_NUMPY = {"4.2": "1.24.3", "5.0": "1.26.4"}
#: Blender platform -> pip --platform tags (newest first), for CPython 3.11 (Blender 4.2-5.x).
PLATFORM_TAGS = {
    "linux-x64": ["manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64"],
    "windows-x64": ["win_amd64"],
    "macos-arm64": ["macosx_14_0_arm64", "macosx_12_0_arm64", "macosx_11_0_arm64"],
    "macos-x64": ["macosx_10_15_x86_64", "macosx_10_9_x86_64", "macosx_10_9_universal2"],
}
PYTHON_VERSION = "3.11"
EXCLUDE = ("__pycache__", ".pyc", ".pyo", ".DS_Store")
#: What the stage leaves out of the package (shutil.ignore_patterns patterns)
DEV_ONLY = ("__pycache__", "*.pyc", "*.pyo", "_scripts.py")


def canonical_name(name: str) -> str:
    """A distribution name as PEP 503 normalises it (``OpenEXR`` -> ``openexr``, ``typing_extensions``
    -> ``typing-extensions``)."""
    return re.sub(r"[-_.]+", "-", name).lower()


def pinned_versions(path: str = REQUIREMENTS) -> dict[str, str]:
    """``{canonical name: version}`` of the ``name==version`` lines of a requirements file (environment
    markers and comments ignored; ranges and wildcards are not pins and are left out)."""
    pins = {}
    with open(path, encoding="utf-8") as f:
        for line in f:
            line = line.split("#", 1)[0].split(";", 1)[0].strip()
            m = re.fullmatch(r"([A-Za-z0-9][A-Za-z0-9._-]*)(?:\[[^\]]*\])?\s*==\s*([A-Za-z0-9._+!-]+)", line)
            if m:
                pins[canonical_name(m.group(1))] = m.group(2)
    return pins


def wheel_requirements(path: str = REQUIREMENTS) -> list[tuple[str, bool]]:
    """The bundled wheels as pip requirements, ``[("scipy==1.15.3", False), ...]``, at the pins of
    requirements.txt; exits with an error when one of BUNDLED is not pinned there."""
    pins = pinned_versions(path)
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


def stage(stage_dir: str, wheels: dict[str, list[str]]) -> None:
    """Copy the package and write the manifest (with its wheels and platforms) into stage_dir."""
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
        # top-level keys must come before the first [table] of the TOML file
        head, sep, tail = text.partition("\n[")
        text = head.rstrip() + "\n" + extra + (sep + tail if sep else "")
    with open(os.path.join(stage_dir, "blender_manifest.toml"), "w", encoding="utf-8") as f:
        f.write(text)


def _cached_wheels(folder: str, key: tuple[str, str]) -> list[str]:
    return [p for p in glob.glob(os.path.join(folder, "*.whl")) if wheel_name_version(p) == key]


def download_wheels(plat: str, cache: str, offline: bool) -> list[str]:
    """Wheels for one Blender platform (cached); optional ones are skipped when unavailable."""
    folder = os.path.join(cache, plat)
    os.makedirs(folder, exist_ok=True)
    out = []
    for req, optional in wheel_requirements():
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
        cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--only-binary=:all:",
               "--python-version", PYTHON_VERSION, "--implementation", "cp", "-d", folder, req]
        for tag in PLATFORM_TAGS[plat]:
            cmd += ["--platform", tag]
        res = subprocess.run(cmd, capture_output=True, text=True)
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


def build(platforms: list[str], with_wheels: bool, output_dir: str, offline: bool = False) -> list[str]:
    """Build and validate; return the zip paths."""
    output_dir = os.path.abspath(output_dir)
    os.makedirs(output_dir, exist_ok=True)
    wheels = {p: download_wheels(p, os.path.join(output_dir, "wheels"), offline) for p in platforms} if with_wheels else {}
    stage_dir = os.path.join(output_dir, "stage")
    stage(stage_dir, wheels)
    with open(MANIFEST, "rb") as f:
        manifest = tomllib.load(f)
    cli = blender_ext_cli()
    pattern = os.path.join(output_dir, f"{manifest['id']}-{manifest['version']}*.zip")
    for old in glob.glob(pattern):
        os.remove(old)
    args = ["build", "--source-dir", stage_dir, "--output-dir", output_dir]
    if wheels:
        args.append("--split-platforms")  # one zip per platform, named ..._<platform>.zip
    run_cli(cli, args)
    zips = sorted(glob.glob(pattern))
    if not zips:
        raise SystemExit(f"error: the build produced no zip in {output_dir}")
    for z in zips:
        run_cli(cli, ["validate", z])
    return zips


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--platforms", default="current",
                    help="'current' (default), 'all', or a comma-separated list of " + ", ".join(PLATFORM_TAGS))
    ap.add_argument("--no-wheels", action="store_true",
                    help="bundle no wheels (for a Blender whose Python already has the dependencies)")
    ap.add_argument("--output-dir", default=os.path.join(ROOT, "build"))
    ap.add_argument("--offline", action="store_true", help="use only wheels already cached in <output-dir>/wheels")
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
    zips = build(platforms, not args.no_wheels, args.output_dir, args.offline)
    for z in zips:
        print(f"built and validated {z} ({os.path.getsize(z) / 1e6:.1f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
