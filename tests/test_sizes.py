"""Sizes (house style): no file over 600 lines, no function over 80 lines.

There is no exception any more: the 1 kHz step of the force path, once fused by hand into one long Python function
because each call it made cost the loop per tick, is a compiled kernel that calls its stages' kernels (a call between
kernels costs nothing once compiled).  Pure AST, no imports of the code it reads: a fraction of a second.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: The product's packages, and the project's other code (benchmarks, scripts) that lives by the same rule.
SCANNED = ("foundation", "pipeline", "protocol", "analysis", "study_app", "bench", "scripts")
MAX_FILE_LINES = 600
MAX_FUNCTION_LINES = 80


def oversized(relpath: str, text: str) -> list[str]:
    """What in one source file breaks the limits, one line each (empty: nothing)."""
    found = []
    n_lines = len(text.splitlines())
    if n_lines > MAX_FILE_LINES:
        found.append(f"{relpath}: {n_lines} lines (at most {MAX_FILE_LINES})")

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = f"{prefix}{child.name}"
                if not isinstance(child, ast.ClassDef):
                    length = (child.end_lineno or child.lineno) - child.lineno + 1
                    if length > MAX_FUNCTION_LINES:
                        found.append(f"{relpath}:{child.lineno}: {name} is {length} lines (at most "
                                     f"{MAX_FUNCTION_LINES})")
                visit(child, f"{name}.")
            else:
                visit(child, prefix)

    visit(ast.parse(text, relpath), "")
    return found


def test_no_file_or_function_over_the_limits() -> None:
    files = sorted(p for pkg in SCANNED for p in (ROOT / pkg).rglob("*.py"))
    assert len(files) > 100  # the packages were found
    found = [line for p in files for line in oversized(p.relative_to(ROOT).as_posix(), p.read_text("utf-8"))]
    assert not found, "split by job:\n" + "\n".join(found)


def _function(name: str, lines: int, indent: str = "") -> str:
    body = "".join(f"{indent}    x = {i}\n" for i in range(lines - 1))
    return f"{indent}def {name}():\n{body}"


def test_the_check_reports_what_breaks_the_limits() -> None:
    assert oversized("a.py", _function("f", 80)) == []
    assert oversized("a.py", _function("f", 81)) == ["a.py:1: f is 81 lines (at most 80)"]
    method = "class C:\n" + _function("g", 81, "    ")
    assert oversized("a.py", method) == ["a.py:2: C.g is 81 lines (at most 80)"]
    nested = _function("outer", 3) + "    " + _function("inner", 81, "    ").lstrip()
    assert any("outer.inner is 81 lines" in line for line in oversized("a.py", nested))
    # the old exception is gone: the framework's step is held to the limit as any function
    step = "class HapticFramework:\n" + _function("step", 81, "    ")
    assert oversized("pipeline/force/framework.py", step) != []
    assert oversized("a.py", "x = 1\n" * 601) == ["a.py: 601 lines (at most 600)"]
    assert oversized("a.py", "x = 1\n" * 600) == []
