"""Import contracts: the folder layout is the architecture (docs/architecture.md, "Five floors").

The project is a house of floors, ``study_app`` → ``bench`` → ``analysis`` → ``protocol`` → ``pipeline``, but
``bench`` stands beside the product rather than inside it: the benchmarks import the product, the product never
imports them (``haptic-study bench`` reaches them through an entry point, by name).

Every contract is checked on one import graph (:func:`import_graph`), built with ``ast`` from every ``import``
statement of every module -- the ones at the top of a file *and* the ones inside functions (lazy imports), and
``importlib.import_module("...")`` / ``__import__("...")`` with a literal name.  Lazy imports count because
they hide a dependency from the interpreter at load time, not from the reader or from the install: a lazy
``from study_app.cli.main import CliError`` inside ``report_cmds`` was a circle all the same, and a lazy
``import bench`` makes the product need the benchmarks all the same.  Imports under ``if TYPE_CHECKING:``
count too: a type named across floors is a dependency of the code that names it.

Each contract is shown to fail (the ``test_*_reports_*`` tests): a deliberately bad module is written into a
temporary copy of the tree and the same checking function must report it.
"""

from __future__ import annotations

import ast
import functools
import shutil
import subprocess
import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
QT = {"PySide6", "pyqtgraph", "PyQt5", "PyQt6", "shiboken6"}
#: The product's packages; ``bench`` is the project's but not the product's.
PRODUCT = ("pipeline", "protocol", "analysis", "study_app")
PACKAGES = (*PRODUCT, "bench")

# module (or package: the rule covers what is inside it) -> top-level names it must never import
FORBIDDEN = {
    "pipeline": QT | {"protocol", "analysis", "study_app", "bench"},
    "protocol": QT | {"analysis", "study_app", "bench"},
    "analysis": QT | {"study_app", "pipeline", "bench"},
    # the benchmarks import the product, never the reverse -- not even lazily (haptic-study bench is an entry point)
    "study_app": {"bench"},
    # windows hold layout and wiring; the models they show hold behaviour, testable without Qt
    "study_app.models": QT,
}

#: The one module every floor may import: the operating system's calls and their fallbacks (it imports nothing of
#: the product: its own rule in FORBIDDEN); analysis imports nothing else of pipeline.
EVERY_FLOOR = {"pipeline.runtime.platform_support"}
FORBIDDEN["pipeline.runtime.platform_support"] = {"pipeline", "protocol", "analysis", "study_app", "bench"}

#: The benchmarks import the product, never the reverse (also within FORBIDDEN; named here on its own).
NO_BENCH = {package: {"bench"} for package in PRODUCT}

#: The simulated rig and participant: imported only where the program is wired together (which rig a run uses
#: is decided there), by the simulators themselves, and by the benchmarks.
SIM = "pipeline.sim"
SIM_IMPORTERS = (
    "pipeline.sim",
    "pipeline.runtime.engine",
    "study_app.engine.setup",
    "study_app.engine.sessions",
    "study_app.engine.commissioning",
    "study_app.cli.calibrate_cmds",
    "study_app.cli.sim_summary",
    "study_app.headless",
    "bench",
)


# -- the import graph ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Import:
    """One import: ``source`` (a module of the tree) needs ``target`` (a module of the tree, or an outside name)."""

    source: str
    target: str
    line: int
    lazy: bool  # inside a function: run when it is called, not when the module is loaded

    def __str__(self) -> str:
        return f"{self.source} imports {self.target} (line {self.line}{', inside a function' if self.lazy else ''})"


def module_names(root: Path, packages: Iterable[str]) -> dict[str, Path]:
    """Every module of ``packages`` under ``root``, by dotted name (a package by its ``__init__.py``)."""
    out: dict[str, Path] = {}
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = path
    return out


def _resolve(name: str, known: Mapping[str, Path]) -> str:
    """The longest prefix of ``name`` that is a module of the tree, else ``name`` itself (an outside module)."""
    parts = name.split(".")
    for n in range(len(parts), 0, -1):
        if ".".join(parts[:n]) in known:
            return ".".join(parts[:n])
    return name


def _is_within(node: ast.AST, parents: Mapping[ast.AST, ast.AST]) -> bool:
    while node in parents:
        node = parents[node]
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            return True
    return False


def imports_of(module: str, path: Path, known: Mapping[str, Path]) -> list[Import]:
    """The imports of one module, wherever they stand in it (see the module docstring)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out: list[Import] = []

    def add(node: ast.AST, target: str) -> None:
        out.append(Import(module, _resolve(target, known), node.lineno, _is_within(node, parents)))

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                add(node, alias.name)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join([*up, base] if base else up)
            for alias in node.names:  # ``from study_app import messages`` imports the module study_app.engine.messages
                sub = f"{base}.{alias.name}"
                add(node, sub if sub in known else base)
        elif (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
              and isinstance(node.args[0].value, str)
              and ((isinstance(node.func, ast.Name) and node.func.id == "__import__")
                   or (isinstance(node.func, ast.Attribute) and node.func.attr == "import_module"))):
            add(node, node.args[0].value)
    return out


def import_graph(root: Path, packages: Iterable[str] = PACKAGES) -> list[Import]:
    """Every import of every module of ``packages`` under ``root``."""
    known = module_names(root, packages)
    return [imp for module, path in known.items() for imp in imports_of(module, path, known)]


def _within(module: str, prefix: str) -> bool:
    return module == prefix or module.startswith(prefix + ".")


# -- the contracts: each returns what breaks it, one line each ------------------------------------------------
def import_cycles(graph: Iterable[Import]) -> list[str]:
    """Circles among the tree's modules: every strongly connected set of modules, with the imports that join it.

    An import of a package's own submodule from its ``__init__`` (or back) is a circle too: Python's
    partially initialised package makes it work, and makes it fragile.
    """
    graph = list(graph)
    nodes = {i.source for i in graph}
    edges: dict[str, set[str]] = {n: set() for n in nodes}
    for i in graph:
        if i.target in nodes:
            edges[i.source].add(i.target)
    # Tarjan's strongly connected components, iteratively (no recursion limit on a long chain)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []
    for start in sorted(nodes):
        if start in index:
            continue
        work = [(start, iter(sorted(edges[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1 or node in edges[node]:
                    components.append(sorted(component))
    out = []
    for component in sorted(components):
        members = set(component)
        joins = sorted({str(i) for i in graph if (i.source in members and i.target in members and i.source != i.target)
                        or (i.source == i.target and i.source in members)})
        out.append(f"circle {' <-> '.join(component)}: " + "; ".join(joins))
    return out


def forbidden_imports(graph: Iterable[Import], rules: Mapping[str, set[str]] = FORBIDDEN) -> list[str]:
    """Imports of a name a module's floor must never import (``rules``: module or package -> top-level names)."""
    out = []
    for i in graph:
        top = i.target.split(".")[0]
        if i.target in EVERY_FLOOR:
            continue
        for where, names in rules.items():
            if _within(i.source, where) and top in names:
                out.append(f"{i} -- {where} must not import {top}")
    return sorted(out)


def sim_importers(graph: Iterable[Import], allowed: Iterable[str] = SIM_IMPORTERS) -> list[str]:
    """Imports of the simulators (:data:`SIM`) from anywhere but the wiring modules."""
    allowed = tuple(allowed)
    return sorted(str(i) for i in graph
                  if _within(i.target, SIM) and not any(_within(i.source, a) for a in allowed))


# -- the contracts on the tree as it is ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def graph() -> list[Import]:
    return import_graph(ROOT)


def test_the_graph_sees_lazy_and_relative_imports(graph: list[Import]) -> None:
    # the checks below are only as good as the graph: it must hold the imports the contracts are about
    assert any(i.lazy for i in graph)
    assert any(i.source == "study_app.cli.main" and i.target == "study_app.cli.run_cmds" for i in graph)
    assert len({i.source for i in graph}) > 100  # every module of the five packages, not a few


def test_no_import_cycles(graph: list[Import]) -> None:
    assert import_cycles(graph) == []


@pytest.mark.parametrize("where", sorted(FORBIDDEN))
def test_layering(graph: list[Import], where: str) -> None:
    assert forbidden_imports(graph, {where: FORBIDDEN[where]}) == []


def test_bench_is_imported_by_nothing_in_the_product(graph: list[Import]) -> None:
    assert forbidden_imports(graph, NO_BENCH) == []


def test_only_the_wiring_modules_import_the_simulators(graph: list[Import]) -> None:
    assert sim_importers(graph) == []


# -- each contract fails on a deliberately bad module ---------------------------------------------------------
@functools.cache
def _cycles_of_the_tree() -> tuple[str, ...]:
    return tuple(import_cycles(import_graph(ROOT)))


def _new_cycles(graph: list[Import]) -> list[str]:
    """The circles of ``graph`` that the tree as it is does not have."""
    return [c for c in import_cycles(graph) if c not in _cycles_of_the_tree()]


def _tree_with(tmp_path: Path, files: Mapping[str, str], *, append: bool = False) -> list[Import]:
    """The import graph of a copy of the tree with ``files`` written (or appended to) in it."""
    for package in PACKAGES:
        shutil.copytree(ROOT / package, tmp_path / package, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    for rel, text in files.items():
        path = tmp_path / rel
        path.write_text((path.read_text(encoding="utf-8") if append else "") + text, encoding="utf-8")
    return import_graph(tmp_path)


def test_a_lazy_import_circle_is_reported(tmp_path: Path) -> None:
    # the circle this project had: a command module importing the CLI's error from the CLI that imports it
    graph = _tree_with(tmp_path,
                       {"study_app/cli/report_cmds.py":
                            "\n\ndef _bad():\n    from study_app.cli.main import CliError\n"},
                       append=True)
    cycles = _new_cycles(graph)
    assert len(cycles) == 1
    # power_cmds is in it too: it imports report_cmds (the analysis options) and is imported by the CLI
    assert cycles[0].startswith(
        "circle study_app.cli.main <-> study_app.cli.power_cmds <-> study_app.cli.report_cmds: ")
    line = len((ROOT / "study_app/cli/report_cmds.py").read_text(encoding="utf-8").splitlines()) + 4
    assert cycles[0].endswith(
        f"; study_app.cli.report_cmds imports study_app.cli.main (line {line}, inside a function)")


def test_a_circle_through_relative_imports_is_reported(tmp_path: Path) -> None:
    graph = _tree_with(tmp_path, {"protocol/_bad_a.py": "from . import _bad_b\n",
                                  "protocol/_bad_b.py": "def f():\n    from ._bad_a import x\n"})
    assert _new_cycles(graph) == [
        "circle protocol._bad_a <-> protocol._bad_b: protocol._bad_a imports protocol._bad_b (line 1); "
        "protocol._bad_b imports protocol._bad_a (line 2, inside a function)"
    ]


@pytest.mark.parametrize("code", ["def _bad():\n    import bench.pipeline_bench\n",
                                  "def _bad():\n    from bench import commands\n",
                                  "import importlib\n\n\ndef _bad():\n    importlib.import_module('bench.commands')\n"],
                         ids=["lazy-import", "lazy-from", "import_module"])
def test_the_product_importing_bench_is_reported(tmp_path: Path, code: str) -> None:
    graph = _tree_with(tmp_path, {"study_app/cli/main.py": "\n\n" + code}, append=True)
    assert forbidden_imports(graph, NO_BENCH) == forbidden_imports(graph)
    bad = forbidden_imports(graph, NO_BENCH)
    assert len(bad) == 1 and bad[0].startswith("study_app.cli.main imports bench")
    assert bad[0].endswith("inside a function) -- study_app must not import bench")


def test_qt_in_a_model_is_reported(tmp_path: Path) -> None:
    graph = _tree_with(tmp_path, {"study_app/models/_bad.py": "from PySide6.QtCore import QObject\n"})
    assert forbidden_imports(graph) == [
        "study_app.models._bad imports PySide6.QtCore (line 1) -- study_app.models must not import PySide6"
    ]


@pytest.mark.parametrize("floor, above", [("pipeline", "protocol.trial"), ("pipeline", "study_app.cli.main"),
                                          ("protocol", "analysis.stats"), ("protocol", "study_app.engine.messages")])
def test_an_upward_import_is_reported(tmp_path: Path, floor: str, above: str) -> None:
    graph = _tree_with(tmp_path, {f"{floor}/_bad.py": f"def f():\n    import {above}\n"})
    assert forbidden_imports(graph) == [
        f"{floor}._bad imports {above} (line 2, inside a function) -- {floor} must not import {above.split('.')[0]}"
    ]


def test_the_simulators_imported_outside_the_wiring_is_reported(tmp_path: Path) -> None:
    graph = _tree_with(tmp_path, {"study_app/gui/_bad.py": "from pipeline.sim import rig\n"})
    assert sim_importers(graph) == ["study_app.gui._bad imports pipeline.sim.rig (line 1)"]


def test_the_real_rigs_engine_loads_no_simulator() -> None:
    # what a real rig's engine process imports before it builds anything: the simulators stay unloaded
    code = ("import sys, study_app.engine.host, study_app.engine.client, pipeline.settings.hardware; "
            "print(sorted(m for m in sys.modules if m == 'pipeline.sim' or m.startswith('pipeline.sim.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"
