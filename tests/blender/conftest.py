"""Blender-layer tests: they need the bpy module (a pinned requirement), so a missing bpy fails
the run rather than skipping it. The add-on is registered once for the session from the source
tree; the packaging test installs the built zip into a separate Blender in a subprocess.

opal_diffraction is importable through the editable install (./setup.sh), and ``blender_scenes``
because pytest puts this folder (no ``__init__.py``) on sys.path itself."""

from __future__ import annotations

import bpy  # noqa: F401  - a hard requirement: ImportError here fails the suite
import pytest


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
