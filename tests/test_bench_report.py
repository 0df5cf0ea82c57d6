"""bench report --reference: the other version's report really runs the other version's code."""

from __future__ import annotations

from pathlib import Path

from bench.analysis_bench import _report_wall
from bench.source_trees import imported_from

ROOT = Path(__file__).resolve().parents[1]


def test_the_reference_runs_its_own_tree_even_when_the_bench_starts_in_our_checkout(tmp_path, monkeypatch) -> None:
    tree = tmp_path / "ref"
    (tree / "study_app").mkdir(parents=True)
    (tree / "study_app" / "__init__.py").write_text("")
    # a stand-in for the other version's CLI: it leaves its name where the report would go
    (tree / "study_app" / "cli.py").write_text(
        "import sys\nout = sys.argv[sys.argv.index('--out') + 1]\nopen(out, 'w').write(__file__)\n")
    monkeypatch.chdir(ROOT)  # python -m puts the working directory first: our study_app would win from here
    out = tmp_path / "report-ref0"
    _report_wall(str(ROOT / "pyproject.toml"), str(out), str(tree))
    assert out.read_text() == str(tree / "study_app" / "cli.py")
    assert imported_from(str(tree), str(tmp_path)) == str(tree / "study_app" / "__init__.py")
    assert Path(imported_from(None, str(tmp_path))).resolve() == ROOT / "study_app" / "__init__.py"
