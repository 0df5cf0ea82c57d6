"""A session interrupted (the run killed mid-trial) and resumed: the report says so, where delivery is stated.

P01's session runs in one go; P02's run is killed during its 3rd trial and ``run --continue`` resumes it, through
the real command line.  The report names the resume (participant, session, when the run stopped, the trial it
cut, when it went on, whether the real-time break is known), the methods say it, and ``sessions.csv`` counts
each session's runs.
"""

from __future__ import annotations

import csv
import tomllib
from pathlib import Path

import pytest
from cli_subprocess import cli as _cli
from cli_subprocess import tiny_protocol

from protocol.study.config import protocol_from_dict
from study_app.headless import run_study

PROTOCOL = tiny_protocol("resume")



@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("resumed")
    (d / "p.toml").write_text(PROTOCOL, encoding="utf-8")
    db = d / "study.db"
    run_study(str(db), participants=1, seed=4, protocol=protocol_from_dict(tomllib.loads(PROTOCOL)), jobs=1)
    common = ["run", "--participants", "2", "--seed", "4", "--db", str(db), "--protocol", str(d / "p.toml"),
              "--continue"]
    killed = _cli([*common, "--inject-fault", "kill@P02:3+0.4"], d)
    assert killed.returncode == -9, killed.stderr
    resumed = _cli(common, d)
    assert resumed.returncode == 0, resumed.stderr
    r = _cli(["report", "--db", str(db), "--out", str(d / "rep")], d)
    assert r.returncode == 0, r.stderr
    return d / "rep"


def test_the_report_names_the_resumed_session_where_it_states_delivery(report: Path) -> None:
    page = (report / "report.html").read_text(encoding="utf-8")
    delivered = page.split("<h2>What was delivered</h2>")[1].split("<h3>Deviations")[0]
    assert "Every experiment session completed (1 of them after an interruption" in delivered
    assert "1 session was interrupted and resumed (1 resume;" in delivered
    item = delivered.split("<li>")[1].split("</li>")[0]
    assert item.startswith("P02, experiment session 2: run 1 was interrupted after ")
    assert "s of session time; it cut trial 3 (cue at " in item
    assert "stored as aborted (interrupted) and re-run later in the session" in item
    assert "the session was resumed as run 2 of 2 at " in item
    assert "the real-time break between the runs is not derivable" in item  # the simulated rig: a virtual clock
    methods = page.split("<b>Data.</b>")[1].split("</p>")[0]
    assert "1 session was interrupted and resumed, analysed as one session each" in methods
    # the interruption was a rehearsed kill: the methods say so, counted by plan (not by its events)
    assert "No deviation from the protocol was recorded" in methods
    assert "Faults were rehearsed on the simulated rig: 1 planned fault (" in methods
    assert "P02, session 2, run 2 from " in methods and "(cut trial 3)" in methods


def test_sessions_csv_counts_each_sessions_runs(report: Path) -> None:
    with open(report / "sessions.csv", newline="", encoding="utf-8") as f:
        runs = {row["participant_code"]: int(row["n_runs"]) for row in csv.DictReader(f)}
    assert runs == {"P01": 1, "P02": 2}
    with open(report / "codebook.csv", newline="", encoding="utf-8") as f:
        assert any(r["file"] == "sessions.csv" and r["column"] == "n_runs" for r in csv.DictReader(f))


def test_a_session_on_the_real_clock_is_not_said_to_run_on_a_virtual_one(report: Path, tmp_path: Path) -> None:
    """Issue 40, item 6: the GUI runs the simulated rig on the real clock; its periods are measured in real time and
    its session clock steps over a break like the real rig's, so the report says neither "exactly 1 ms" nor "the
    session clock is virtual" of it."""
    import json
    import shutil
    import sqlite3

    from analysis.report.report import build_report

    db = tmp_path / "gui.db"
    shutil.copy(report.parent / "study.db", db)
    c = sqlite3.connect(db)  # P02's session as the GUI's engine stores it: the simulated rig on the real clock
    (cfg,), = c.execute("SELECT config_json FROM sessions WHERE session_id = 2").fetchall()
    c.execute("UPDATE sessions SET config_json = ? WHERE session_id = 2", (json.dumps({**json.loads(cfg),
                                                                                       "clock": "real"}),))
    c.commit()
    c.close()
    build_report([db], tmp_path / "rep")
    page = (tmp_path / "rep" / "report.html").read_text(encoding="utf-8")
    assert "On the virtual clock (1 session of the simulated rig run headless) computing takes no time" in page
    item = page.split("<h2>What was delivered</h2>")[1].split("<li>")[1].split("</li>")[0]
    assert item.startswith("P02, experiment session 2") and "the real-time break between the runs was " in item
    assert "virtual" not in item
