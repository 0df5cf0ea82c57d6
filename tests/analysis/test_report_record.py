"""What the report says about the record: an incomplete session, deviations, and which code ran each session.

One small study, reported twice (by default and with --include-incomplete): six complete participants, each
with an aborted trial re-run later, and P07, whose session the experimenter ended after 3 of its 6 trials (one
of them aborted and never re-run).  The sessions ran two different commits, one with uncommitted changes.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pandas as pd
import pytest
from studybuilder import SessionDef, TrialDef, build, success_trial, timeout_trial

from study_app.cli.main import main

COMMIT_A, COMMIT_B = "a" * 8 + "1" * 32, "b" * 8 + "2" * 32


def _aborted(label: str, mode: str) -> TrialDef:
    t = success_trial(label, mode, 0)
    t.outcome_override = "aborted"
    return t


def _complete(code: str, i: int, commit: str, dirty: bool) -> SessionDef:
    rerun = success_trial("FIRM", "on", 120 * i)
    rerun.repeat_of = 2
    trials = [success_trial("GENTLE", "on", 100 * i), timeout_trial("GENTLE", "off", 0.2 + 0.05 * i),
              _aborted("FIRM", "on"), success_trial("FIRM", "off", 300 + 80 * i),
              timeout_trial("FIRM", "off", 2.0 + 0.1 * i), success_trial("GENTLE", "off", 500 + 60 * i), rerun]
    override = "experiment started without a completed training session (override)"
    events = [(3.0, "deviation", override)] if i == 2 else []
    return SessionDef(code, trials, max_trial_s=4.0, software_commit=commit, software_dirty=dirty, events=events)


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    sessions = [_complete(f"P0{i}", i, COMMIT_A if i <= 3 else COMMIT_B, i == 5) for i in range(1, 7)]
    half = SessionDef("P07", [success_trial("GENTLE", "on", 200), _aborted("FIRM", "off"),
                              timeout_trial("FIRM", "on", 0.5), success_trial("GENTLE", "off", 700)],
                      max_trial_s=4.0, status="aborted", end_reason="participant felt unwell", designed=7,
                      software_commit=COMMIT_B, software_dirty=False)
    return build(tmp_path_factory.mktemp("record") / "record.db", [*sessions, half])


@pytest.fixture(scope="module")
def reports(study, tmp_path_factory) -> dict[str, Path]:
    out = {}
    for name, extra in (("default", []), ("included", ["--include-incomplete"])):
        folder = tmp_path_factory.mktemp(name) / "rep"
        assert main(["report", "--db", str(study), "--out", str(folder), *extra]) == 0
        out[name] = folder
    return out


def _methods(folder: Path) -> str:
    page = (folder / "report.html").read_text()
    return page[page.index("<h2>Methods</h2>"):page.index("<h2>Sessions</h2>")]


def test_an_incomplete_session_is_left_out_by_default_and_listed_with_its_reason(reports):
    folder = reports["default"]
    trials = pd.read_csv(folder / "trials.csv")
    assert "P07" not in set(trials["participant_code"]) and trials["participant_code"].nunique() == 6
    listed = pd.read_csv(folder / "incomplete_sessions.csv")
    assert len(listed) == 1
    row = listed.iloc[0]
    assert (row["participant_code"], row["n_finished"], row["n_designed"], bool(row["analysed"])) == \
        ("P07", 3, 7, False)
    reason = "P07, session 7: aborted by the experimenter after 3 of 7 trials (participant felt unwell)"
    assert row["reason"] == reason
    page = (folder / "report.html").read_text()
    assert reason in page and "left out of every analysis" in page
    methods = _methods(folder)
    assert "1 experiment session did not complete and is left out with its 3 finished trials" in methods
    assert reason in methods
    # the aborted trials of the analysed sessions were all re-run: the methods may say so
    assert "6 aborted trials (each re-run later in its session)" in methods
    assert "6 participants in 6 analysed experiment sessions of 7" in methods


def test_with_the_flag_its_finished_trials_are_analysed_and_the_methods_say_so(reports):
    folder = reports["included"]
    trials = pd.read_csv(folder / "trials.csv")
    assert (trials["participant_code"] == "P07").sum() == 3
    assert bool(pd.read_csv(folder / "incomplete_sessions.csv").iloc[0]["analysed"])
    methods = _methods(folder)
    assert "did not complete and is analysed with its finished trials (report --include-incomplete)" in methods
    # P07's aborted trial was never re-run: "each re-run" would be false now
    assert "each re-run" not in methods
    assert "7 aborted trials (6 of them re-run later in their session; the other 1 not" in methods
    assert "7 participants in 7 analysed experiment sessions of 7" in methods
    assert "incomplete sessions included" in (folder / "report.html").read_text()


def test_the_report_lists_each_sessions_code_and_warns_when_they_differ(reports):
    page = (reports["default"] / "report.html").read_text()
    assert COMMIT_A[:12] in page and COMMIT_B[:12] in page
    assert "The sessions of this study ran different code" in page
    assert "1 session ran from a checkout with uncommitted changes" in page
    sessions = pd.read_csv(reports["default"] / "sessions.csv")
    assert set(sessions["software_commit"]) == {COMMIT_A, COMMIT_B}
    assert sessions.set_index("participant_code").at["P05", "software_dirty"]


def test_recorded_deviations_are_listed(reports):
    dev = pd.read_csv(reports["default"] / "deviations.csv")
    assert list(dev[["participant_code", "kind"]].itertuples(index=False, name=None)) == [("P02", "deviation")]
    assert "without a completed training session" in (reports["default"] / "report.html").read_text()
    for folder in reports.values():  # the methods name it too, with or without the incomplete session
        assert ("1 deviation from the protocol was recorded (listed under Deviations from the protocol, "
                "deviations.csv; the trials they concern are analysed as recorded): P02: experiment started "
                "without a completed training session (override).") in _methods(folder)


def test_a_session_run_from_a_checkout_stores_its_commit(tmp_path):
    from foundation.version import checkout_provenance, software_provenance
    from protocol.runner.session_setup import open_new_session
    from protocol.storage import StudyDatabase
    from protocol.study.config import default_protocol
    from study_app.cli.main import version_text

    root = Path(__file__).resolve().parents[2]
    head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                          check=True).stdout.strip()
    dirty = bool(subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                                capture_output=True, text=True, check=True).stdout.strip())
    db = StudyDatabase(tmp_path / "s.db")
    opened = open_new_session(db, code="P01", number=1, kind="training", protocol=default_protocol(), seed=0,
                              rig="sim", config={}, calibration=None, lease_owner="test")
    row = db.conn.execute("SELECT software_version, software_commit, software_dirty FROM sessions "
                          "WHERE session_id = ?", (opened.session_id,)).fetchone()
    db.close()
    assert row == (software_provenance().version, head, int(dirty))
    # --version says the same, from the same function; a folder that is no checkout knows no commit
    assert version_text() == software_provenance().describe() and head[:8] in version_text()
    assert checkout_provenance(tmp_path) == (None, None)
