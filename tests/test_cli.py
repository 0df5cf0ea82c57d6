"""The ``haptic-study`` command line: the sim main job and bad input."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import pytest

from study_app.cli.main import main

#: What a --seconds option allows (one tick at least: issue 42)
SIM_SECONDS = "must be a number from 0.001 to 86400 (one tick of the 1 kHz loop at least)"
LOOP_SECONDS = "must be 0 (skips the loop) or a number from 0.001 to 3600 (one tick of the 1 kHz loop at least)"


@pytest.mark.parametrize("seconds", ["0.001", "0.05"])
def test_a_sim_shorter_than_the_rest_window_is_summarised_in_strict_json(capsys: pytest.CaptureFixture[str],
                                                                         seconds: str) -> None:
    """Issue 42: under 0.2 s (the rest window) the summary's convolution was longer than the run: a traceback."""
    assert main(["sim", "--seconds", seconds, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out, parse_constant=lambda c: pytest.fail(f"not strict JSON: {c}"))
    assert summary["contacts"] == 0 and summary["contact_rms_error_n"] is None  # nothing to measure: null, not NaN
    assert summary["ticks"] >= 2


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
        (["sim", "--seconds", "-1"], "--seconds = '-1': " + SIM_SECONDS),
        (["sim", "--seconds", "abc"], "--seconds = 'abc': " + SIM_SECONDS),
        (["sim", "--seed", "-3"],
         "--seed = '-3': must be a whole number from 0 to 9223372036854775807 (the largest integer SQLite stores)"),
        (["sim", "--clock", "wall"], "invalid choice: 'wall'"),
        (["bench", "nothing"], "invalid choice: 'nothing'"),
        (["bench", "pipeline", "--loop-seconds", "-1"],
         "--loop-seconds = '-1': " + LOOP_SECONDS),
        (["report", "--db", "/nonexistent/study.db", "--out", "/nonexistent/out"],
         "the folder /nonexistent does not exist"),
        (["bench", "pipeline", "--loop-seconds", "nan"],
         "--loop-seconds = 'nan': " + LOOP_SECONDS),
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


# -- commands from outside the product: the benchmarks, found by entry point ----------------------------------
def test_bench_is_registered_by_entry_point_not_imported() -> None:
    from importlib.metadata import entry_points

    from study_app.cli.main import COMMANDS_GROUP, build_parser

    eps = {ep.name: ep.value for ep in entry_points(group=COMMANDS_GROUP)}
    assert eps.get("bench") == "bench.commands:register"  # pip install -e . (scripts/setup.sh) wrote it
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    bench = next(a for a in sub.choices["bench"]._actions if isinstance(a, argparse._SubParsersAction))
    assert list(bench.choices) == ["pipeline", "loop", "lsl", "study", "report", "power", "stats", "gui"]


def _entry_points_of(monkeypatch: pytest.MonkeyPatch, *values: str) -> None:
    import importlib.metadata as md

    from study_app.cli.main import COMMANDS_GROUP

    eps = tuple(md.EntryPoint(name="bench", value=v, group=COMMANDS_GROUP) for v in values)
    monkeypatch.setattr(md, "entry_points", lambda group: eps if group == COMMANDS_GROUP else ())


@pytest.mark.parametrize("values", [(), ("no_such_bench_package.commands:register",)],
                         ids=["unregistered", "package-left-out"])
@pytest.mark.parametrize("argv", [["bench"], ["bench", "pipeline", "--ticks", "5"]])
def test_bench_absent_is_one_line(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                                  values: tuple[str, ...], argv: list[str]) -> None:
    _entry_points_of(monkeypatch, *values)
    assert main(argv) == 2
    out = capsys.readouterr()
    assert out.out == ""
    assert out.err == ("haptic-study: error: bench: the benchmarks are not part of this install (the 'bench' package "
                       "and its entry point in 'haptic_study.commands'); install haptic-study from its source tree: "
                       "pip install -e .\n")
    assert main(["sessions", "--db", "/no/such.db"]) == 2  # the rest of the command line unaffected


def test_bench_with_a_missing_dependency_is_not_masked(monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:
    # the registered module exists but imports something absent: a broken install, shown as it is
    (tmp_path / "broken_bench_commands.py").write_text("import no_such_dependency_of_bench\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    _entry_points_of(monkeypatch, "broken_bench_commands:register")
    with pytest.raises(ModuleNotFoundError, match="no_such_dependency_of_bench"):
        main(["bench"])


@pytest.mark.parametrize("value", ["0", "-2", "two", "1.5"])
def test_a_bad_worker_count_in_the_environment_is_one_line_and_nothing_runs(
        value: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path) -> None:
    monkeypatch.setenv("HAPTIC_STUDY_WORKERS", value)
    assert main(["report", "--db", str(tmp_path / "absent.db"), "--out", str(tmp_path / "rep")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [f"haptic-study: error: HAPTIC_STUDY_WORKERS = {value!r}: must be a whole number of worker "
                   "processes, at least 1"]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("value", ["banana", "off", "2", "yes"])
def test_a_bad_realtime_switch_in_the_environment_is_one_line_and_nothing_runs(
        value: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """HAPTIC_STUDY_REALTIME=banana ran `sim` with exit 0 (anything but "0" silently meant real-time on)."""
    monkeypatch.setenv("HAPTIC_STUDY_REALTIME", value)
    assert main(["sim", "--seconds", "1"]) == 2
    out = capsys.readouterr()
    assert out.out == ""
    assert out.err.splitlines() == [f"haptic-study: error: HAPTIC_STUDY_REALTIME = {value!r}: must be 0 (the loop at "
                                    "normal priority) or 1 (SCHED_FIFO, the default; also when unset)"]


@pytest.mark.parametrize("value", ["0", "1", " 0 ", ""])
def test_a_good_realtime_switch_is_taken(value: str, monkeypatch: pytest.MonkeyPatch) -> None:
    from pipeline.core.clock import _set_fifo, realtime_env_problem

    monkeypatch.setenv("HAPTIC_STUDY_REALTIME", value)
    assert realtime_env_problem() is None
    if value.strip() == "0":
        assert _set_fifo(1) == "normal (HAPTIC_STUDY_REALTIME=0)"


def test_the_worker_count_in_the_environment_is_used(monkeypatch: pytest.MonkeyPatch) -> None:
    from foundation.parallel import default_workers

    monkeypatch.setenv("HAPTIC_STUDY_WORKERS", "3")
    assert default_workers() == 3
    monkeypatch.delenv("HAPTIC_STUDY_WORKERS")
    assert 1 <= default_workers() <= 4
