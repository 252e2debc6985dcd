"""The rooms of ``opal_diffraction/core`` and what each may import (docs/architecture.md, "Rooms").

A room is a subpackage of core/ (integrators/light and integrators/eye count as rooms of their
own). Every import counts, deferred ones inside functions too, so a lazy import cannot dodge the
table. A room not in the table fails the test: a new room states its rule here first.
"""

from __future__ import annotations

import ast
import os

import pytest

PACKAGE = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", "opal_diffraction"))
CORE = "opal_diffraction.core"

# room -> the rooms it may import (besides itself); the order is the layer order, low to high
_BELOW_TRANSPORT = {"util", "spectral", "accel", "opal", "scene", "sampling", "materials"}
MAY_IMPORT = {
    "util": set(),
    "spectral": {"util"},
    "accel": {"util"},
    "opal": {"util", "spectral", "accel"},
    "scene": {"util", "spectral", "accel", "opal"},
    "sampling": {"util", "spectral", "scene"},
    "materials": {"util", "spectral", "scene", "opal"},
    "lights": {"util", "spectral", "accel", "scene", "sampling", "materials"},
    "transport": _BELOW_TRANSPORT,
    "gratings": _BELOW_TRANSPORT | {"transport"},
    "volumes": {"util", "spectral", "scene"},
    "integrators": _BELOW_TRANSPORT | {"lights", "transport", "gratings"},
    "integrators.light": _BELOW_TRANSPORT | {"lights", "transport", "gratings", "integrators"},
    "integrators.eye": _BELOW_TRANSPORT | {"lights", "transport", "gratings", "integrators", "integrators.light",
                                           "volumes"},
    "render": _BELOW_TRANSPORT | {"lights", "transport", "gratings", "integrators", "integrators.light",
                                  "integrators.eye", "volumes"},
}


def modules() -> dict[str, str]:
    """Dotted module name -> file path, for every module of the package."""
    out = {}
    root = os.path.dirname(PACKAGE)
    for folder, _, files in os.walk(PACKAGE):
        for f in files:
            if f.endswith(".py"):
                path = os.path.join(folder, f)
                rel = os.path.relpath(path, root)[:-3].replace(os.sep, ".")
                out[rel[: -len(".__init__")] if rel.endswith(".__init__") else rel] = path
    return out


def imported_modules(path: str, module: str, known: dict) -> set[str]:
    """The package's modules that ``module`` (file ``path``) imports anywhere in the file."""
    tree = ast.parse(open(path, encoding="utf-8").read())
    pkg = module if path.endswith("__init__.py") else module.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.split(".")
                base = base[: len(base) - (node.level - 1)] if node.level > 1 else base
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            out.update(t for t in [target] + [f"{target}.{a.name}" for a in node.names] if t in known)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name in known)
    return out


def room_of(module: str) -> str | None:
    """'opal_diffraction.core.integrators.eye.eye_pass' -> 'integrators.eye'; None outside a room."""
    if not module.startswith(CORE + "."):
        return None
    parts = module[len(CORE) + 1:].split(".")
    if parts[0] == "integrators" and len(parts) > 2:
        return "integrators." + parts[1]
    return parts[0]


def violations(graph: dict[str, set[str]]) -> list[str]:
    bad = []
    for m, targets in sorted(graph.items()):
        r = room_of(m)
        if r is None:
            continue
        if r not in MAY_IMPORT:
            bad.append(f"{m}: room {r!r} is not in the layer table")
            continue
        for t in sorted(targets):
            if t == CORE or not t.startswith(CORE + "."):
                if t.startswith("opal_diffraction") and t != CORE:
                    bad.append(f"{m} imports {t}: the core never imports the add-on or the CLI")
                continue
            rt = room_of(t)
            if rt != r and rt not in MAY_IMPORT[r]:
                bad.append(f"{m} imports {t}: {r}/ may not import {rt}/")
    return bad


def import_graph() -> dict[str, set[str]]:
    known = modules()
    return {m: imported_modules(p, m, known) - {m} for m, p in known.items()}


def test_the_package_has_no_import_cycle():
    """Depth-first search for a back edge over the whole package (the add-on too); a submodule
    importing from its own package's __init__ (``from . import x``) is not a cycle between concepts."""
    graph = import_graph()
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for t in sorted(graph[m]):
            if state.get(t) == 1 and not m.startswith(t + "."):
                raise AssertionError("import cycle: " + " -> ".join(stack[stack.index(t):] + [t]))
            if t not in state:
                visit(t)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)


def test_every_room_imports_only_the_rooms_below_it():
    assert violations(import_graph()) == []


def test_a_back_import_is_caught():
    """The table is not vacuous: a planted import of render/ from util/ (and of the eye pass from
    the light pass) is reported."""
    graph = import_graph()
    graph[f"{CORE}.util.enums"] = graph[f"{CORE}.util.enums"] | {f"{CORE}.render.plan"}
    graph[f"{CORE}.integrators.light.light_pass"] = (graph[f"{CORE}.integrators.light.light_pass"]
                                                     | {f"{CORE}.integrators.eye.eye_pass"})
    found = violations(graph)
    assert any("util.enums imports" in v and "render" in v for v in found)
    assert any("light_pass imports" in v and "integrators.eye" in v for v in found)


def test_core_holds_rooms_not_modules():
    """At most a dozen modules directly in core/ (today: only its __init__)."""
    direct = [f for f in os.listdir(os.path.join(PACKAGE, "core")) if f.endswith(".py")]
    assert len(direct) <= 12, direct
    rooms = {d for d in os.listdir(os.path.join(PACKAGE, "core"))
             if os.path.isfile(os.path.join(PACKAGE, "core", d, "__init__.py"))}
    assert rooms - {"integrators"} <= set(MAY_IMPORT), rooms - set(MAY_IMPORT)


@pytest.mark.parametrize("room", sorted(MAY_IMPORT))
def test_every_room_states_its_rule(room):
    """Each room's __init__ docstring says what the room holds (docs/architecture.md repeats it)."""
    init = os.path.join(PACKAGE, "core", *room.split("."), "__init__.py")
    doc = ast.get_docstring(ast.parse(open(init, encoding="utf-8").read()))
    assert doc and len(doc) > 40, room


def test_nothing_edits_sys_path():
    root = os.path.dirname(PACKAGE)
    found = []
    for folder in ("opal_diffraction", "tests", "benchmarks", "tools", "examples"):
        for d, dirs, files in os.walk(os.path.join(root, folder)):
            dirs[:] = [x for x in dirs if x != "__pycache__"]
            for f in files:
                if f.endswith(".py") and f != "test_layers.py":
                    text = open(os.path.join(d, f), encoding="utf-8").read()
                    if "sys.path.insert" in text or "sys.path.append" in text:
                        found.append(os.path.join(d, f))
    assert found == []


def test_tests_mirror_the_rooms():
    """tests/ holds the shared helpers only; every test file sits in the folder of the room (or
    tests/system/, tests/blender/) it tests, and each room has its folder."""
    tests = os.path.join(os.path.dirname(PACKAGE), "tests")
    assert sorted(f for f in os.listdir(tests) if f.startswith("test_") and f.endswith(".py")) == []
    for room in MAY_IMPORT:
        assert os.path.isdir(os.path.join(tests, *room.split("."))), room
