"""docs/architecture.md matches the code: every module of the package listed once in its module
map (and no module that does not exist), and each hand-off's row names every field of its class."""

from __future__ import annotations

import dataclasses
import os
import re

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PACKAGE = os.path.join(ROOT, "opal_diffraction")
DOC = open(os.path.join(ROOT, "docs", "architecture.md"), encoding="utf-8").read()


def package_modules() -> set[str]:
    """Module paths relative to opal_diffraction/ (the preset scripts are data, not modules)."""
    out = set()
    for folder, dirs, files in os.walk(PACKAGE):
        dirs[:] = [d for d in dirs if d not in ("__pycache__", "presets")]
        out.update(os.path.relpath(os.path.join(folder, f), PACKAGE).replace(os.sep, "/")
                   for f in files if f.endswith(".py"))
    return out


def test_every_module_is_listed_once_in_the_module_map():
    rows = re.findall(r"^\| `([^`]+\.py)` \|", DOC.split("## Module map", 1)[1], flags=re.M)
    assert len(rows) == len(set(rows)), sorted(r for r in rows if rows.count(r) > 1)
    assert set(rows) == package_modules(), (sorted(package_modules() - set(rows)), sorted(set(rows) - package_modules()))


def _hand_offs():
    from opal_diffraction.core.integrators.eye.tile_output import TileResult
    from opal_diffraction.core.integrators.light.light_pass import LightPassResult
    from opal_diffraction.core.render.film import RenderResult
    from opal_diffraction.core.render.plan import RenderPlan
    from opal_diffraction.core.render.prepare import PreparedScene
    from opal_diffraction.core.render.scheduler import EyePassOutcome
    from opal_diffraction.core.render.tiles import EyeWork
    from opal_diffraction.core.scene.validation import ValidatedScene
    from opal_diffraction.core.transport.path_state import PathState

    return [ValidatedScene, PreparedScene, RenderPlan, LightPassResult, PathState, EyeWork, TileResult,
            EyePassOutcome, RenderResult]


@pytest.mark.parametrize("cls", _hand_offs(), ids=lambda c: c.__name__)
def test_each_hand_off_row_names_every_field(cls):
    row = re.search(rf"^\| `{cls.__name__}` \(([^)]+)\) \|(.*)$", DOC, flags=re.M)
    assert row, f"no hand-off row for {cls.__name__}"
    module_path = os.path.join(PACKAGE, *row.group(1).split("/"))
    assert os.path.exists(module_path), row.group(1)
    assert f"class {cls.__name__}" in open(module_path, encoding="utf-8").read(), row.group(1)
    missing = [f.name for f in dataclasses.fields(cls) if f"`{f.name}`" not in row.group(2)]
    assert missing == [], f"{cls.__name__}: {missing}"
