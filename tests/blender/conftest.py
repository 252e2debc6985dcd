"""Blender-layer tests: they need the bpy module (a pinned requirement). The add-on is registered
once for the session from the source tree; the packaging test installs the built zip into a
separate Blender in a subprocess.

Every test collected under this folder gets the ``blender`` marker, so ``pytest -m "not blender"``
leaves them out. Without bpy (a venv for the quick loop) this folder's test files cannot be
imported, so none is collected; one stand-in item marked ``blender`` is collected in their place
and fails, so a run that asks for the Blender tests without bpy fails rather than skipping them,
and ``pytest -m "not blender"`` deselects it and runs. opal_diffraction is importable through the
editable install, and ``blender_scenes`` because pytest puts this folder (no ``__init__.py``) on
sys.path itself."""

from __future__ import annotations

from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent

try:
    import bpy  # noqa: F401
except ModuleNotFoundError as error:
    BPY_MISSING: ModuleNotFoundError | None = error
    collect_ignore_glob = ["test_*.py"]  # the test modules import bpy
else:
    BPY_MISSING = None


class BpyMissing(pytest.Item):
    """Stands for this folder's tests when bpy cannot be imported: fails with the import error."""

    def runtest(self):
        raise BPY_MISSING

    def repr_failure(self, excinfo):
        return f"bpy is not importable ({BPY_MISSING}): install requirements.txt, or leave these out with -m \"not blender\""

    def reportinfo(self):
        return HERE, None, self.name


@pytest.hookimpl(tryfirst=True)  # before the -m deselection, so the marker counts
def pytest_collection_modifyitems(session, config, items):
    if BPY_MISSING is not None:
        folder = HERE.relative_to(config.rootpath).as_posix()
        items.append(BpyMissing.from_parent(session, name="bpy_is_importable", path=HERE,
                                            nodeid=f"{folder}::bpy_is_importable"))
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
