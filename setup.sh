#!/usr/bin/env bash
# Sets up everything the project needs on a brand-new machine (idempotent):
# the X11/GL shared libraries the bpy module loads, and a virtualenv in .venv
# with the pinned Python packages and this project installed editable. Re-running it is cheap.
set -euo pipefail
cd "$(dirname "$0")"

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

PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null || PY=python3
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
# pip runs again only when a requirements file or pyproject.toml changed since the last install
stamp=.venv/.requirements.sha
want=$(sha256sum requirements.txt requirements-dask.txt requirements-denoise.txt pyproject.toml | sha256sum | cut -d" " -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  .venv/bin/python -m pip install -q --upgrade pip
  # the optional Dask cluster rendering and Open Image Denoise too, so their tests
  # (tests/render/test_distributed.py, tests/render/test_denoise.py) run here
  .venv/bin/python -m pip install -q -r requirements.txt -r requirements-dask.txt -r requirements-denoise.txt
  # the project itself, editable (its dependencies are the pins above): tests, examples,
  # benchmarks and tools import opal_diffraction from this checkout without touching sys.path
  .venv/bin/python -m pip install -q --no-deps -e .
  echo "$want" > "$stamp"
fi
