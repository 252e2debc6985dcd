#!/usr/bin/env bash
# Sets up everything the project needs on a brand-new machine (idempotent):
# the X11/GL shared libraries the bpy module loads, and a virtualenv with the pinned Python packages
# (requirements.txt: its environment markers pick each Python's pins) and this project installed
# editable. Re-running it is cheap.
#
#   ./setup.sh                  # Python 3.11 + bpy 5.0.1 (Blender 4.2-5.0's Python) into .venv
#   ./setup.sh --python 3.13    # Python 3.13 + bpy 5.2.3 (Blender 5.1+'s Python) into .venv313
#
# The interpreter: $PYTHON if set, else python<version> on the PATH, else pyenv's newest
# <version>.* ($(pyenv root)/versions/, installed but not necessarily active).
set -euo pipefail
cd "$(dirname "$0")"

version=3.11
while [ $# -gt 0 ]; do
  case "$1" in
    --python) version=$2; shift 2 ;;
    --python=*) version=${1#--python=}; shift ;;
    -h|--help) sed -n '2,12p' "$0"; exit 0 ;;
    *) echo "setup: unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done
case "$version" in
  3.11) venv=${VENV:-.venv} ;;
  3.13) venv=${VENV:-.venv313} ;;
  *) echo "setup: Python $version is not one Blender runs (3.11: Blender 4.2-5.0, 3.13: Blender 5.1+)" >&2; exit 2 ;;
esac

need_libs=()
# (read the cache once: `ldconfig -p | grep -q` would fail under pipefail when grep exits early)
known_libs=$(ldconfig -p 2>/dev/null || true)
for lib in libX11.so.6 libXrender.so.1 libXfixes.so.3 libXi.so.6 libxkbcommon.so.0 libSM.so.6 libGL.so.1; do
  grep -q "$lib" <<<"$known_libs" || need_libs+=("$lib")
done
if [ ${#need_libs[@]} -gt 0 ]; then
  echo "setup: installing shared libraries for bpy (missing: ${need_libs[*]})"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq libx11-6 libxrender1 libxfixes3 libxi6 libxkbcommon0 libsm6 libgl1
fi

# a python<version> that really runs (a pyenv shim of a version not active exits non-zero)
is_python() { "$1" -c "import sys; sys.exit(sys.version_info[:2] != tuple(map(int, '$version'.split('.'))))" 2>/dev/null; }
PY=${PYTHON:-}
if [ -z "$PY" ]; then
  if is_python "python$version"; then
    PY=python$version
  elif command -v pyenv >/dev/null; then
    PY=$(ls -d "$(pyenv root)"/versions/"$version".*/bin/python"$version" 2>/dev/null | sort -V | tail -n 1)
  fi
  if [ -z "$PY" ] && [ "$version" = 3.11 ] && is_python python3; then PY=python3; fi
fi
if [ -z "$PY" ] || ! is_python "$PY"; then
  echo "setup: no Python $version found (set PYTHON=/path/to/python$version, or pyenv install $version)" >&2
  exit 1
fi
if [ ! -x "$venv/bin/python" ]; then
  "$PY" -m venv "$venv"
fi
# pip runs again only when a requirements file or pyproject.toml changed since the last install
stamp=$venv/.requirements.sha
want=$(sha256sum requirements.txt requirements-dask.txt requirements-denoise.txt pyproject.toml | sha256sum | cut -d" " -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  "$venv/bin/python" -m pip install -q --upgrade pip
  # the optional Dask cluster rendering and Open Image Denoise too, so their tests
  # (tests/render/test_distributed.py, tests/render/test_denoise.py) run here
  "$venv/bin/python" -m pip install -q -r requirements.txt -r requirements-dask.txt -r requirements-denoise.txt
  # the project itself, editable (its dependencies are the pins above): tests, examples,
  # benchmarks and tools import opal_diffraction from this checkout without touching sys.path
  "$venv/bin/python" -m pip install -q --no-deps -e .
  echo "$want" > "$stamp"
fi
