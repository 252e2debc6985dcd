"""Blender-layer tests: they need the bpy module (a pinned requirement), so a missing bpy fails
the run rather than skipping it. The add-on is registered once for the session from the source
tree; the packaging test installs the built zip into a separate Blender in a subprocess.

Every test collected under this folder gets the ``blender`` marker (``pytest -m "not blender"``
leaves them out; bpy must still be importable, as this file imports it). opal_diffraction is
importable through the editable install, and ``blender_scenes`` because pytest puts this folder
(no ``__init__.py``) on sys.path itself."""

from __future__ import annotations

from pathlib import Path

import bpy  # noqa: F401  - a hard requirement: ImportError here fails the suite
import pytest

HERE = Path(__file__).resolve().parent


def pytest_collection_modifyitems(config, items):
    # a conftest's hook sees the whole session's items: mark only the ones in this folder
    for item in items:
        if Path(item.path).resolve().is_relative_to(HERE):
            item.add_marker(pytest.mark.blender)


@pytest.fixture(scope="session", autouse=True)
def addon():
    import opal_diffraction

    opal_diffraction.register()
    yield
    opal_diffraction.unregister()


@pytest.fixture
def last_render():
    from opal_diffraction.blender import engine

    return engine.last_render
