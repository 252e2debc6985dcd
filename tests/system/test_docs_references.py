"""Every reference to docs/physics.md resolves to one of its numbered headings.

Scans the .py and .md files of the repository's own folders (opal_diffraction, tests, docs,
examples, benchmarks, tools) and README.md for citations of docs/physics.md in every form found
so far: "section 3.2", "sections 3.6 and 3.8", "§3", "sections 5.2-5.5", and the old short
forms "s2" and a bare "5" after the file's name. It checks that:

- each cited section number is a numbered heading of the document (``## 3.`` / ``### 3.2``);
- each citation names the file by its path, docs/ included (inside docs/ a relative Markdown
  link target is fine too);
- no file cites design notes that are not in the repository (the architecture notes, unless a
  docs/ copy exists, or the shared design folder: the module docstrings, the README,
  docs/physics.md and docs/blender.md say what they meant).

Pure text processing: no Blender, no rendering, well under a second.
"""

from __future__ import annotations

import os
import re

import pytest

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
FOLDERS = ("opal_diffraction", "tests", "docs", "examples", "benchmarks", "tools")
TOP_FILES = ("README.md",)
SKIP_DIRS = {".venv", "__pycache__", ".git", "build", "out", "node_modules"}

# Built from pieces so this file does not cite what it forbids.
DOC_NAME = "physics" + ".md"
ARCHITECTURE = "architecture" + ".md"
FORBIDDEN = (ARCHITECTURE, ".." + "/shared", "shared" + "/design")

_NUM = r"\d+(?:\.\d+)*"
# a list of section numbers: "3", "3.2", "3.6 and 3.8", "1.5, 2.4 and 7", "5.2-5.5", "§3 and §4"
_NUM_LIST = rf"§?\s*{_NUM}(?:\s*(?:,|and|or|&|to|-|–)\s*§?\s*{_NUM})*"
# what may follow the file name: "section 3", "sections 3 and 4", "§3", "§§3-4", "s2", or a bare "5"
_CITATION = re.compile(
    r"physics\.md(?:'s)?(?:"
    rf"[\s#:]*(?:,\s*)?(?:sections?|§§?)\s*(?P<nums>{_NUM_LIST})"
    rf"|[ \t]+s(?P<short>{_NUM})\b"
    rf"|[ \t]+(?P<bare>{_NUM})\b(?!\s*%)"
    r")",
    re.IGNORECASE,
)
# a section number mentioned later in the same clause ("the document's table (section 2)")
_CLAUSE_SECTION = re.compile(rf"(?:sections?|§§?)\s*(?P<nums>{_NUM_LIST})", re.IGNORECASE)
_CLAUSE_END = re.compile(r"[;)\]]|\.(?:\s|$)|\n\s*\n")
_HEADING = re.compile(r"^#{2,6}\s+(?P<num>\d+(?:\.\d+)*)\.?\s+\S", re.MULTILINE)


def section_numbers(text: str) -> list[str]:
    """Section numbers of a number list: '3.6 and 3.8' -> ['3.6', '3.8'], '5.2-5.5' -> both ends."""
    return re.findall(_NUM, text)


def headings(doc_text: str) -> set[str]:
    """The numbered headings of the physics document: {'1', '1.1', ..., '12'}."""
    return {m.group("num") for m in _HEADING.finditer(doc_text)}


def citations(text: str) -> list[tuple[int, str, str]]:
    """(line, cited text, section number) for every section cited after a mention of the document.

    A mention without a section number (the document as a whole) yields nothing.
    """
    out = []
    for m in re.finditer(re.escape(DOC_NAME), text):
        line = text.count("\n", 0, m.start()) + 1
        tail = text[m.start():m.start() + 200]
        found = []
        c = _CITATION.match(tail)
        if c:
            nums = c.group("nums") or c.group("short") or c.group("bare")
            found += [(c.group(0), n) for n in section_numbers(nums)]
        # anything else of the form "section N" in the rest of the clause
        rest_start = c.end() if c else len(DOC_NAME)
        end = _CLAUSE_END.search(tail, rest_start)
        clause = tail[rest_start:end.start() if end else len(tail)]
        for s in _CLAUSE_SECTION.finditer(clause):
            found += [(s.group(0), n) for n in section_numbers(s.group("nums"))]
        out += [(line, cited.strip(), n) for cited, n in found]
    return out


def unprefixed_mentions(text: str, in_docs: bool) -> list[int]:
    """Lines where the document is named without its path docs/ (Markdown link targets in docs/
    may be relative)."""
    bad = []
    for m in re.finditer(re.escape(DOC_NAME), text):
        before = text[max(0, m.start() - 5):m.start()]
        if before.endswith("docs/"):
            continue
        if in_docs and before.endswith(("(", "(./")):
            continue
        if m.start() > 0 and (text[m.start() - 1].isalnum() or text[m.start() - 1] in "_-"):
            continue  # another name that merely ends the same way
        bad.append(text.count("\n", 0, m.start()) + 1)
    return bad


def repository_files() -> list[str]:
    files = [os.path.join(ROOT, f) for f in TOP_FILES if os.path.exists(os.path.join(ROOT, f))]
    for folder in FOLDERS:
        for dirpath, dirnames, filenames in os.walk(os.path.join(ROOT, folder)):
            dirnames[:] = sorted(d for d in dirnames if d not in SKIP_DIRS and not d.startswith("."))
            files += [os.path.join(dirpath, f) for f in sorted(filenames) if f.endswith((".py", ".md"))]
    return files


def _read(path: str) -> str:
    with open(path, encoding="utf-8") as f:
        return f.read()


@pytest.fixture(scope="module")
def physics_headings() -> set[str]:
    return headings(_read(os.path.join(ROOT, "docs", DOC_NAME)))


@pytest.fixture(scope="module")
def files() -> list[tuple[str, str]]:
    return [(os.path.relpath(p, ROOT), _read(p)) for p in repository_files()]


# ------------------------------------------------------------------------- the repository
def test_the_physics_document_names_the_source_paper_and_keeps_the_top_level_sections(physics_headings):
    text = _read(os.path.join(ROOT, "docs", DOC_NAME))
    top = " ".join(text[:1500].split())
    assert "Kobayashi & Kawai" in top
    assert "An implementation of bidirectional ray tracing taking account of spectrum and diffraction" in top
    assert "Osaka Electro-Communication University" in top
    # the specification's top-level numbering, which older citations rely on
    titles = {m.group(1): m.group(2) for m in re.finditer(r"^## (\d+)\. (.+)$", text, re.MULTILINE)}
    for num, word in (("1", "Spectra"), ("2", "Dispersion"), ("3", "Diffraction"), ("4", "Bidirectional"),
                      ("5", "Opal")):
        assert word in titles.get(num, ""), (num, titles.get(num))
    # a sub-section is numbered inside its section: "### 3.2" lives under "## 3."
    current = None
    for m in re.finditer(r"^(#{2,6})\s+(\d+(?:\.\d+)*)\.?\s", text, re.MULTILINE):
        level, num = len(m.group(1)), m.group(2)
        if level == 2:
            current = num
        else:
            assert current is not None and num.split(".")[0] == current, (num, current)
    assert len(physics_headings) == len(re.findall(r"^#{2,6}\s+\d", text, re.MULTILINE)), "duplicate numbers"


def test_every_cited_section_exists(files, physics_headings):
    unresolved = [f"{path}:{line}: '{cited}' -> section {num}"
                  for path, text in files for line, cited, num in citations(text) if num not in physics_headings]
    assert not unresolved, "citations of sections that docs/physics.md does not have:\n" + "\n".join(unresolved)


def test_citations_name_the_document_by_its_path(files):
    bad = [f"{path}:{line}" for path, text in files
           if not path.endswith(os.path.join("docs", DOC_NAME))
           for line in unprefixed_mentions(text, in_docs=path.startswith("docs" + os.sep))]
    assert not bad, "write 'docs/physics.md' (the file is not beside these):\n" + "\n".join(bad)


def test_no_file_cites_design_notes_outside_the_repository(files):
    words = [w for w in FORBIDDEN if not (w == ARCHITECTURE and os.path.exists(os.path.join(ROOT, "docs", w)))]
    bad = [f"{path}:{text.count(chr(10), 0, text.index(word)) + 1}: {word}"
           for path, text in files for word in words if word in text]
    assert not bad, "references to files that are not in the repository:\n" + "\n".join(bad)


def test_the_scan_covers_the_code_the_tests_and_the_docs(files):
    paths = {p for p, _ in files}
    for must in ("README.md", os.path.join("docs", DOC_NAME), os.path.join("opal_diffraction", "core", "gratings", "radiance.py"),
                 os.path.join("tests", "gratings", "test_diffraction.py"), os.path.join("tests", "blender", "test_cycles_units.py")):
        assert must in paths, must
    assert sum(len(citations(t)) for _, t in files) > 30  # the citations themselves are found


# ------------------------------------------------------------------------- the scanner itself
D = "docs/" + DOC_NAME


@pytest.mark.parametrize("text,expected", [
    (f"see {D} section 3.2.", ["3.2"]),
    (f"({D} section 4)", ["4"]),
    (f"{D} sections 3.6 and 3.8, \"each", ["3.6", "3.8"]),
    (f"{D} sections 1.5, 2.4 and 7)", ["1.5", "2.4", "7"]),
    (f"{D} sections 5.2-5.5.", ["5.2", "5.5"]),
    (f"{D} §3 and §4", ["3", "4"]),
    (f"{D}\n    section 1.5.", ["1.5"]),
    (f"from {D}\n    # section 3.2; this", ["3.2"]),
    (f"{DOC_NAME} s2).", ["2"]),
    (f"between them ({DOC_NAME} 5).", ["5"]),
    (f"closed forms and {DOC_NAME}'s table (section 2).", ["2"]),
    (f"the whole of [{D}]({DOC_NAME}) says", []),
    (f"{D}: 12 % of it", []),
    (f"{D}:12 is a line", []),
])
def test_the_scanner_finds_every_form(text, expected):
    assert [n for _, _, n in citations(text)] == expected


def test_a_bogus_section_is_reported(physics_headings):
    bogus = f"Known deviation ({D} section 9.99)."
    assert [n for _, _, n in citations(bogus) if n not in physics_headings] == ["9.99"]
    assert "9.99" not in physics_headings and "3.2" in physics_headings


def test_headings_are_parsed_with_and_without_a_trailing_dot():
    doc = "# Title\n\n## 1. Spectra\n### 1.2 Colour\n#### 1.2.3. Detail\n## Sources\ntext ## 9 no\n"
    assert headings(doc) == {"1", "1.2", "1.2.3"}


def test_mentions_without_the_path_are_reported():
    assert unprefixed_mentions(f"see {DOC_NAME} section 2", in_docs=False) == [1]
    assert unprefixed_mentions(f"see {D} section 2", in_docs=False) == []
    assert unprefixed_mentions(f"[{D}]({DOC_NAME}#3-gratings)", in_docs=True) == []
    assert unprefixed_mentions("test_truncation_loss_matches_physics_md", in_docs=False) == []
