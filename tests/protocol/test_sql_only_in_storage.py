"""No SQL outside ``protocol/storage/``: the study database is read through :class:`protocol.storage.StudyReader`
and written by :class:`protocol.storage.StudyDatabase` and its recorder, nowhere else.

The source of every module is scanned with ``ast`` for SQL: a string literal (or the first literal part of an
f-string) that starts with an SQL statement's keyword, and a call of ``.execute``/``.executemany``/
``.executescript`` or of pandas' ``read_sql``/``read_sql_query``.  The scan itself is shown to find SQL
(``test_the_scan_finds_sql``), so the contract cannot pass by finding nothing.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent.parent
SCANNED = ("foundation", "pipeline", "protocol", "analysis", "study_app", "bench")
STORAGE = ROOT / "protocol" / "storage"
_KEYWORD = re.compile(r"^\s*(SELECT|INSERT|UPDATE|DELETE|PRAGMA|CREATE|ALTER|DROP|VACUUM|BEGIN|COMMIT|ROLLBACK)\b")
_CALLS = {"execute", "executemany", "executescript", "read_sql", "read_sql_query"}

#: Modules that still hold SQL, each with why; the list may only shrink (a module listed without SQL fails too).
NOT_YET_MOVED: dict[str, str] = {
    "bench/analysis_bench.py": "counts the samples and recordings of the benchmark's own study (two reads)",
    "bench/row_format.py": "writes the old row format (schema version 2) by hand, for the storage benchmark",
    "bench/study_bench.py": "empties a copied study's recording and rewrites it, to time the recorder",
}


def sql_in(source: str) -> list[tuple[int, str]]:
    """Where a module's source holds SQL: (line, what), in order."""
    found: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(source)):
        text = None
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            text = node.value
        elif isinstance(node, ast.JoinedStr) and node.values and isinstance(node.values[0], ast.Constant):
            text = str(node.values[0].value)
        if text is not None and _KEYWORD.match(text):
            found.append((node.lineno, f"SQL literal {text.strip()[:40]!r}"))
        if isinstance(node, ast.Call):
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
            if name in _CALLS:
                found.append((node.lineno, f"call of {name}()"))
    return sorted(set(found))


def _modules() -> list[Path]:
    return sorted(p for pkg in SCANNED for p in (ROOT / pkg).rglob("*.py")
                  if STORAGE not in p.parents and ".venv" not in p.parts)


def test_the_scan_finds_sql() -> None:
    hits = sql_in('c.execute(f"SELECT a FROM t WHERE b = {x}")\nq = "  INSERT INTO t VALUES (1)"\n'
                  'pd.read_sql_query(q, c)\ns = "Select the file"\n')
    assert [line for line, _ in hits] == [1, 1, 2, 3]
    assert sql_in((STORAGE / "database.py").read_text())  # the writer's module does hold SQL


def test_no_sql_outside_storage() -> None:
    offenders, moved = [], []
    for path in _modules():
        rel = path.relative_to(ROOT).as_posix()
        hits = sql_in(path.read_text(encoding="utf-8"))
        if hits and rel not in NOT_YET_MOVED:
            offenders.extend(f"{rel}:{line}: {what}" for line, what in hits)
        if not hits and rel in NOT_YET_MOVED:
            moved.append(rel)
    assert not offenders, "SQL outside protocol/storage (read through StudyReader):\n" + "\n".join(offenders)
    assert not moved, f"no SQL left in {moved}: take them off NOT_YET_MOVED"
