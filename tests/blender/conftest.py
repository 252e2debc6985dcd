"""Blender-layer tests: they need the bpy module (a pinned requirement), so a missing bpy fails
the run rather than skipping it. The add-on is registered once for the session from the source
tree; the packaging test installs the built zip into a separate Blender in a subprocess."""

from __future__ import annotations

import os
import sys

import bpy  # noqa: F401  - a hard requirement: ImportError here fails the suite
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
for p in (ROOT, HERE):
    if p not in sys.path:
        sys.path.insert(0, p)


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
