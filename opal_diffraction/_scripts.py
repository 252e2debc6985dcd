"""Load the repository's scripts (``examples/*.py``, ``tools/*.py``) as modules, for tests, benchmarks
and tools.

The examples and tools are scripts, not packages, so they are not importable by name. This finds
them beside the package in a source checkout (what ./setup.sh installs editable) and loads them by
file path, without touching ``sys.path``; library and scripts therefore always come from the same
tree.

    from opal_diffraction._scripts import load_example, load_script
    gratings = load_example("gratings")                  # examples/gratings.py
    build_tool = load_script("tools/build_extension.py")

Development only: no bpy, nothing in the library imports it, and tools/build_extension.py leaves it
out of the extension zip (which has no examples/ or tools/ folder).
"""

from __future__ import annotations

import importlib.util
import os
import re
import sys
from types import ModuleType

__all__ = ["REPO_ROOT", "load_example", "load_script"]

#: The checkout this package lives in (``<REPO_ROOT>/opal_diffraction/_scripts.py``).
REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def load_script(relpath: str) -> ModuleType:
    """The module of the script ``REPO_ROOT/relpath``, executed once per process (later calls return
    the same module).

    It is registered in ``sys.modules`` as ``_opal_script_<path>`` (``tools/build_extension.py`` ->
    ``_opal_script_tools_build_extension``), so dataclasses and the like work, and its
    ``if __name__ == "__main__":`` block does not run.
    """
    key = "_opal_script_" + re.sub(r"\W", "_", os.path.splitext(os.path.normpath(relpath))[0])
    module = sys.modules.get(key)
    if module is not None:
        return module
    path = os.path.join(REPO_ROOT, relpath)
    if not os.path.isfile(path):
        raise ModuleNotFoundError(f"no script {relpath!r}: {path} does not exist (scripts live in a source checkout)",
                                  name=key, path=path)
    spec = importlib.util.spec_from_file_location(key, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[key] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[key]
        raise
    return module


def load_example(name: str) -> ModuleType:
    """The example script ``examples/<name>.py`` as a module (see :func:`load_script`)."""
    return load_script(os.path.join("examples", f"{name}.py"))
