"""The ``haptic-study`` command line: the sim main job and bad input."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from study_app.cli import main


def test_sim_json_summary(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "--seconds", "6", "--seed", "3", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["seed"] == 3 and s["seconds"] == 6.0 and s["clock"] == "virtual"
    assert s["calibration"]["model"] == "affine"
    assert abs(s["calibration"]["mass_kg"] - 0.65) < 2e-3
    assert s["contacts"] >= 1 and s["faults"] == "none" and s["lost_records"] == 0
    assert s["contact_rms_error_n"] < 0.05
    assert 0 < s["max_render_n"] <= 3.0


def test_sim_text_summary_and_progress(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "--seconds", "2", "--haptics", "off"]) == 0
    out = capsys.readouterr()
    assert "haptic feedback off" in out.out
    assert "Rendered force: max 0.000 N" in out.out
    assert "100%" in out.err  # the progress bar goes to stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["sim", "--seconds", "-1"], "--seconds = '-1': must be a number > 0 and ≤ 86400"),
        (["sim", "--seconds", "abc"], "--seconds = 'abc': must be a number > 0 and ≤ 86400"),
        (["sim", "--seed", "-3"], "--seed = '-3': must be a whole number from 0 to 9223372036854775807 (the largest integer SQLite stores)"),
        (["sim", "--clock", "wall"], "invalid choice: 'wall'"),
        (["bench", "nothing"], "invalid choice: 'nothing'"),
        (["bench", "pipeline", "--loop-seconds", "-1"], "--loop-seconds = '-1': must be a number from 0 to 3600 (0 skips the loop)"),
        (["report", "--db", "/nonexistent/study.db", "--out", "/nonexistent/out"], "the folder /nonexistent does not exist"),
        (["bench", "pipeline", "--loop-seconds", "nan"], "--loop-seconds = 'nan': must be a number from 0 to 3600 (0 skips the loop)"),
    ],
)
def test_bad_input_is_one_clear_error(args: list[str], message: str) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "study_app.cli", *args], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 2
    assert message in proc.stderr
    assert "Traceback" not in proc.stderr
    assert len(proc.stderr.splitlines()) == 1, proc.stderr
