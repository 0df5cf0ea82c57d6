"""Every document the code and the docs cite exists in the project, and so does every section they cite.

A citation is ``docs/NAME.md`` (or a bare ``science.md`` / ``hardware.md``, as many docstrings write it), optionally
followed by sections: ``§1.2``, ``§3a``, ``§1.1–§1.3``, ``§2, §3``.  A section ``§X`` exists when the document has a
Markdown heading that starts with ``X.`` or ``X `` (``### 1.2 How many poses``, ``### 3a. ATI Net F/T``).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: Where citations are looked for: the product, its tests, scripts, docs and the project's own files.
SCANNED = ("foundation", "pipeline", "protocol", "analysis", "study_app", "bench", "tests", "scripts", "docs", "data",
           "firmware")
TOP_FILES = ("README.md", "pyproject.toml", "hardware.example.toml")
SUFFIXES = {".py", ".md", ".toml", ".sh", ".sql", ".ino"}

_CITE = re.compile(r"(?:docs/)?(?P<doc>science|hardware)\.md(?P<tail>(?:[ ,]*(?:and )?§ ?[0-9]+[a-z]?(?:\.[0-9]+)?"
                   r"(?:[–-]§? ?[0-9]+[a-z]?(?:\.[0-9]+)?)?)*)")
_DOC = re.compile(r"\bdocs/(?P<name>[A-Za-z0-9_-]+\.md)")
_SECTION = re.compile(r"§ ?(?P<sec>[0-9]+[a-z]?(?:\.[0-9]+)?)")


def _files() -> list[Path]:
    out = [ROOT / f for f in TOP_FILES if (ROOT / f).exists()]
    for folder in SCANNED:
        out += [p for p in (ROOT / folder).rglob("*") if p.suffix in SUFFIXES and "__pycache__" not in p.parts]
    return [p for p in out if p.name != Path(__file__).name]


def _headings(doc: Path) -> set[str]:
    """The section numbers a document's headings carry (``0``, ``1``, ``1.2``, ``3a``, …)."""
    secs = set()
    for line in doc.read_text(encoding="utf-8").splitlines():
        m = re.match(r"#{2,4} +(?P<sec>[0-9]+[a-z]?(?:\.[0-9]+)?)[. ]", line)
        if m:
            secs.add(m["sec"])
    return secs


def _citations() -> list[tuple[str, str, str]]:
    """(file:line, document, section or '') for every citation in the scanned files."""
    found = []
    for path in _files():
        rel = path.relative_to(ROOT)
        for n, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            where = f"{rel}:{n}"
            for m in _DOC.finditer(line):
                found.append((where, m["name"], ""))
            for m in _CITE.finditer(line):
                for s in _SECTION.finditer(m["tail"]):
                    found.append((where, f"{m['doc']}.md", s["sec"]))
    return found


def test_the_scan_finds_the_citations_it_should() -> None:
    """The scanner is not blind: the code cites science.md and hardware.md sections in many places."""
    cites = _citations()
    assert sum(1 for _, d, s in cites if d == "science.md" and s) >= 40
    assert {("hardware.md", "3a"), ("science.md", "1.2"), ("science.md", "7")} <= {(d, s) for _, d, s in cites}


@pytest.mark.parametrize("where,doc,section", _citations(), ids=lambda v: str(v))
def test_every_cited_document_and_section_exists(where: str, doc: str, section: str) -> None:
    path = ROOT / "docs" / doc
    assert path.is_file(), f"{where} cites docs/{doc}, which is not in the project"
    if section:
        assert section in _headings(path), f"{where} cites docs/{doc} §{section}, which has no such heading"
