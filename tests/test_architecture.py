"""Import contracts: the folder layout is the architecture (docs/architecture.md, "Floors").

The project is a house of floors, ``study_app`` → ``analysis`` → ``protocol`` → ``pipeline`` → ``foundation``,
each package itself built of floors (its sub-folders, :data:`FLOORS`), and ``bench`` beside the product: the
benchmarks import the product, the product never imports them (``haptic-study bench`` reaches them through an
entry point, by name).  A module may import its own floor and the floors below it, never one above, and never a
sibling on its own level (``pipeline.sim`` and ``pipeline.settings`` know nothing of each other).

Every contract is checked on one import graph (:func:`import_graph`), built with ``ast`` from every ``import``
statement of every module -- the ones at the top of a file *and* the ones inside functions (lazy imports), and
``importlib.import_module("...")`` / ``__import__("...")`` with a literal name.  Lazy imports count because
they hide a dependency from the interpreter at load time, not from the reader or from the install: a lazy
``from study_app.cli.main import CliError`` inside ``report_cmds`` was a circle all the same, and a lazy
``import bench`` makes the product need the benchmarks all the same.  Imports under ``if TYPE_CHECKING:``
count too: a type named across floors is a dependency of the code that names it.  The same floors are also
import-linter's contracts (``[tool.importlinter]`` in pyproject.toml, :func:`test_import_linter_contracts_hold`),
the well-kept tool a reader may already know; this graph adds what it does not see (``import_module`` calls).

Each contract is shown to fail (the ``test_*_reports_*`` tests): a deliberately bad module is written into a
temporary copy of the tree and the same checking function must report it.
"""

from __future__ import annotations

import ast
import functools
import shutil
import subprocess
import sys
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
QT = {"PySide6", "pyqtgraph", "PyQt5", "PyQt6", "shiboken6"}
#: The product's packages; ``bench`` is the project's but not the product's.
PRODUCT = ("foundation", "pipeline", "protocol", "analysis", "study_app")
PACKAGES = (*PRODUCT, "bench")

# module (or package: the rule covers what is inside it) -> top-level names it must never import
FORBIDDEN = {
    "foundation": QT | {"pipeline", "protocol", "analysis", "study_app", "bench"},
    "pipeline": QT | {"protocol", "analysis", "study_app", "bench"},
    "protocol": QT | {"analysis", "study_app", "bench"},
    "analysis": QT | {"study_app", "pipeline", "bench"},
    # the benchmarks import the product, never the reverse -- not even lazily (haptic-study bench is an entry point)
    "study_app": {"bench"},
    # windows hold layout and wiring; the models they show hold behaviour, testable without Qt
    "study_app.models": QT,
}

#: The floors, from the bottom up: a module's floor is the longest entry that names its package (or it), and it may
#: import only modules of its own floor or of floors below; entries in one tuple are siblings on one level, which
#: import nothing of each other.  A package's root module sits where its entry stands (``analysis``, the notebook's
#: lazy front door, above every analysis floor; ``study_app``'s shared modules below its sub-floors).
FLOORS: tuple[tuple[str, ...], ...] = (
    ("foundation.platform_support",), ("foundation",),
    ("pipeline", "pipeline.core"), ("pipeline.force",), ("pipeline.devices",), ("pipeline.commissioning",),
    ("pipeline.backends",), ("pipeline.runtime",), ("pipeline.sim", "pipeline.settings"), ("pipeline.assembly",),
    ("protocol", "protocol.metrics"), ("protocol.tasks",), ("protocol.study",), ("protocol.recording",),
    ("protocol.storage",), ("protocol.lsl",), ("protocol.runner",),
    ("analysis.reading",), ("analysis.stats",), ("analysis.plots",), ("analysis.planning",), ("analysis.report",),
    ("analysis.export",), ("analysis",),
    ("study_app",), ("study_app.engine.messages",), ("study_app.engine",), ("study_app.headless",),
    ("study_app.models",), ("study_app.gui",),
    ("study_app.cli",),
    ("bench",),
)

#: The benchmarks import the product, never the reverse (also within FORBIDDEN; named here on its own).
NO_BENCH = {package: {"bench"} for package in PRODUCT}

#: The simulated rig and participant: imported only where the program is wired together (which rig a run uses
#: is decided there), by the simulators themselves, and by the benchmarks.
SIM = "pipeline.sim"
SIM_IMPORTERS = (
    "pipeline.sim",
    "pipeline.assembly.engine",
    "pipeline.assembly.loop_jobs",
    "pipeline.assembly.latency",  # the latency's twin of the simulated rig
    "pipeline.assembly.sim_config",
    "study_app.engine.setup",
    "study_app.engine.loop_process",
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
        for where, names in rules.items():
            if _within(i.source, where) and top in names:
                out.append(f"{i} -- {where} must not import {top}")
    return sorted(out)


def floor_of(module: str, floors: Sequence[Sequence[str]] = FLOORS) -> tuple[int, str] | None:
    """A module's floor (its index, and the entry that names it), or None for a module no floor names."""
    best: tuple[int, str] | None = None
    for level, entries in enumerate(floors):
        for entry in entries:
            if _within(module, entry) and (best is None or len(entry) > len(best[1])):
                best = (level, entry)
    return best


def floor_violations(graph: Iterable[Import], floors: Sequence[Sequence[str]] = FLOORS) -> list[str]:
    """Imports that go up a floor, or across to a sibling on the same level (and modules no floor names)."""
    out = []
    for i in graph:
        here, there = floor_of(i.source, floors), floor_of(i.target, floors)
        if here is None:
            out.append(f"{i.source} is on no floor (FLOORS)")
        elif there is not None and (there[0] > here[0] or (there[0] == here[0] and there[1] != here[1])):
            way = "up to" if there[0] > here[0] else "across to its sibling"
            out.append(f"{i} -- {here[1]} must not import {way} {there[1]}")
    return sorted(set(out))


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


def test_every_import_goes_down_a_floor(graph: list[Import]) -> None:
    assert floor_violations(graph) == []


def test_every_package_of_the_tree_has_its_floor() -> None:
    # a new sub-folder must be given its place: the floors are the architecture, not a list that lags behind it
    inits = [p for pkg in PACKAGES for p in (ROOT / pkg).rglob("__init__.py")]
    folders = {".".join(p.parent.relative_to(ROOT).parts) for p in inits}
    named = {entry for level in FLOORS for entry in level}
    assert sorted(f for f in folders if f not in named and floor_of(f) is None) == []
    assert sorted(f for f in folders if f not in named) == [], "give each folder its own entry in FLOORS"


def test_import_linter_contracts_hold() -> None:
    # the same floors as import-linter's layers contracts (pyproject.toml), checked by the tool itself
    out = subprocess.run([sys.executable, "-c", "from importlinter.cli import lint_imports_command; "
                          "lint_imports_command()"], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "0 broken" in out.stdout


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


@pytest.mark.parametrize("floor, above", [("pipeline/force", "pipeline.runtime.loop"),
                                          ("pipeline/core", "protocol.study.trial"),
                                          ("protocol/storage", "protocol.runner.session"),
                                          ("analysis/stats", "analysis.report.html_parts"),
                                          ("foundation", "analysis.reading.errors"),
                                          ("study_app/gui", "study_app.cli.main")])
def test_an_upward_import_is_reported(tmp_path: Path, floor: str, above: str) -> None:
    graph = _tree_with(tmp_path, {f"{floor}/_bad.py": f"def f():\n    import {above}\n"})
    here, there = floor_of(floor.replace("/", ".")), floor_of(above)
    assert here is not None and there is not None
    assert [v for v in floor_violations(graph) if "._bad " in v] == [
        f"{floor.replace('/', '.')}._bad imports {above} (line 2, inside a function) -- {here[1]} must not import "
        f"up to {there[1]}"
    ]


def test_a_sibling_import_is_reported(tmp_path: Path) -> None:
    graph = _tree_with(tmp_path, {"pipeline/sim/_bad.py": "from pipeline.settings import hardware\n"})
    assert [v for v in floor_violations(graph) if "._bad " in v] == [
        "pipeline.sim._bad imports pipeline.settings.hardware (line 1) -- pipeline.sim must not import across to "
        "its sibling pipeline.settings"
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
