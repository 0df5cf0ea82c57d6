"""One rig per study, as one seed (issue 42, class 5): ``run --continue`` on other arms is refused, nothing touched."""

from __future__ import annotations

from pathlib import Path

import pytest

from study_app.cli.main import main
from tests.cli_subprocess import tiny_protocol


@pytest.fixture
def two_arm_study(tmp_path: Path) -> tuple[list[str], Path]:
    (tmp_path / "tiny.toml").write_text(tiny_protocol("rig"), encoding="utf-8")
    db = tmp_path / "s.db"
    base = ["run", "--protocol", str(tmp_path / "tiny.toml"), "--db", str(db), "--jobs", "1"]
    assert main([*base, "--participants", "1", "--sim-arms", "right,left"]) == 0
    return base, db


@pytest.mark.parametrize("arms", [(), ("--sim-arms", "right"), ("--sim-arms", "right,middle")])
def test_continuing_a_two_arm_study_on_other_arms_is_refused(two_arm_study: tuple[list[str], Path],
                                                             arms: tuple[str, ...], capsys) -> None:
    base, db = two_arm_study
    before = db.read_bytes()
    capsys.readouterr()
    assert main([*base, "--participants", "2", "--continue", *arms]) == 2
    said = capsys.readouterr().err
    assert "P01's experiment session 1 ran on the arms right,left" in said and "one study runs on one rig" in said
    assert db.read_bytes() == before  # refused on a read-only look: nothing stored touched


def test_the_same_arms_in_another_order_are_the_same_rig(two_arm_study: tuple[list[str], Path], capsys) -> None:
    base, db = two_arm_study
    assert main([*base, "--participants", "2", "--continue", "--sim-arms", "left,right"]) == 0  # task arm first
    assert main(["sessions", "--db", str(db)]) == 0
    assert "P02" in capsys.readouterr().out


def test_a_one_arm_study_is_not_continued_on_two(tmp_path: Path, capsys) -> None:
    (tmp_path / "tiny.toml").write_text(tiny_protocol("rig"), encoding="utf-8")
    base = ["run", "--protocol", str(tmp_path / "tiny.toml"), "--db", str(tmp_path / "s.db"), "--jobs", "1"]
    assert main([*base, "--participants", "1"]) == 0
    capsys.readouterr()
    assert main([*base, "--participants", "2", "--continue", "--sim-arms", "right,left"]) == 2
    assert "ran on the arms right (the task arm first); this command's: right,left" in capsys.readouterr().err
