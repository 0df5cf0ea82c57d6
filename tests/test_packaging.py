"""What the wheel ships: every package of the product and the data files it reads at run time.

The wheel itself is built, installed into a fresh environment and run outside the checkout by
``scripts/wheel_check.sh`` (``.ci/run``); this test catches the usual cause of a broken wheel -- a folder added
without being listed in ``pyproject.toml`` -- in a second, and checks the runtime data files are declared and
every library the product imports is a declared dependency.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from protocol.storage import schema_path

ROOT = Path(__file__).resolve().parents[1]
FLOORS = ("foundation", "pipeline", "protocol", "analysis", "bench", "study_app")


def _setuptools() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]


def test_every_folder_of_the_product_is_a_listed_package() -> None:
    on_disk = {".".join(p.parent.relative_to(ROOT).parts) for floor in FLOORS for p in (ROOT / floor).rglob("*.py")
               if "__pycache__" not in p.parts}
    listed = set(_setuptools()["packages"])
    assert on_disk - listed == set(), "folders with modules missing from [tool.setuptools] packages"
    for pkg in listed:
        folder = ROOT / _setuptools().get("package-dir", {}).get(pkg, pkg.replace(".", "/"))
        assert folder.is_dir(), pkg


def test_the_data_files_read_at_run_time_are_shipped() -> None:
    cfg = _setuptools()
    assert cfg["package-dir"]["protocol.storage.sql"] == "data"
    assert "schema.sql" in cfg["package-data"]["protocol.storage.sql"]
    assert "*.toml" in cfg["package-data"]["protocol.study"]
    assert (ROOT / "protocol" / "study" / "default.toml").is_file()
    # a checkout reads data/schema.sql (an installed wheel its copy in protocol/storage/sql/)
    assert schema_path() == ROOT / "data" / "schema.sql" and schema_path().is_file()


#: The distribution that provides each third-party module the product imports, where the names differ.
_DISTRIBUTION_OF = {"PySide6": "PySide6-Essentials", "serial": "pyserial", "pyOpenHaptics": "pyopenhaptics",
                    "rtde_receive": "ur-rtde", "rtde_control": "ur-rtde",
                    "distributed": "dask"}  # the cluster extra's dask[distributed]


def _third_party_imports() -> dict[str, str]:
    """Each top-level module outside the standard library and the product that the product imports: where first."""
    import ast
    import sys

    found: dict[str, str] = {}
    for floor in FLOORS:
        for path in sorted((ROOT / floor).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                         [node.module] if isinstance(node, ast.ImportFrom) and node.module and not node.level else [])
                for name in names:
                    top = name.split(".")[0]
                    if top not in sys.stdlib_module_names and top not in FLOORS:
                        found.setdefault(top, str(path.relative_to(ROOT)))
    return found


def test_every_library_the_product_imports_is_a_declared_dependency() -> None:
    """The wheel check borrows the checkout's environment, which holds the test extra too (pytest, hypothesis, ...):
    a library imported by the product but declared nowhere passes there and fails in a lab's own install."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    from packaging.requirements import Requirement

    declared = {Requirement(r).name.lower() for r in project["dependencies"]}
    optional = {Requirement(r).name.lower() for extra in ("touch", "cluster", "lsl")
                for r in project["optional-dependencies"][extra]}
    imports = _third_party_imports()
    assert {"numpy", "PySide6", "scipy"} <= set(imports), imports  # the scan sees the product's imports
    missing = {m: where for m, where in imports.items()
               if _DISTRIBUTION_OF.get(m, m).lower() not in declared | optional}
    assert missing == {}, f"imported by the product, not in [project] dependencies: {missing}"
