"""What the wheel ships: every package of the product and the data files it reads at run time.

The wheel itself is built, installed into a fresh environment and run outside the checkout by
``scripts/wheel_check.sh`` (``.ci/run``); this test catches the usual cause of a broken wheel -- a folder added
without being listed in ``pyproject.toml`` -- in a second, and checks the runtime data files are declared.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from protocol.storage import schema_path

ROOT = Path(__file__).resolve().parents[1]
FLOORS = ("pipeline", "protocol", "analysis", "bench", "study_app")


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
    assert "*.toml" in cfg["package-data"]["protocol"] and (ROOT / "protocol" / "default.toml").is_file()
    # a checkout reads data/schema.sql (an installed wheel its copy in protocol/storage/sql/)
    assert schema_path() == ROOT / "data" / "schema.sql" and schema_path().is_file()
