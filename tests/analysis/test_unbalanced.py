"""``report --include-incomplete`` (issue 41, 5): a session stopped part-way leaves a participant × mode with more
trials of one target than of the other; its mean over trials would weigh the targets unequally.  The report says so
beside the tests and takes each such mode's value as the mean of its per-target values (every target the same
weight), as participants_by_target.csv lets anyone recompute."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from studybuilder import SessionDef, build, success_trial, timeout_trial

from study_app.cli.main import main


def test_an_unbalanced_cell_is_said_and_weighs_the_targets_equally(tmp_path: Path) -> None:
    def full(code: str, i: int) -> SessionDef:
        return SessionDef(code, [success_trial("GENTLE", "on", 100 * i), timeout_trial("FIRM", "off", 2.0),
                                 success_trial("FIRM", "on", 200 + 50 * i), success_trial("GENTLE", "off", 700)],
                          max_trial_s=4.0)

    # P03 stopped after 3 of 4 planned ON trials: FIRM twice (a success and a failure), GENTLE once
    stopped = SessionDef("P03", [success_trial("FIRM", "on", 300), timeout_trial("FIRM", "on", 2.0),
                                 success_trial("GENTLE", "on", 100), timeout_trial("GENTLE", "off", 0.2)],
                         max_trial_s=4.0, status="aborted", designed=6)
    db = build(tmp_path / "u.db", [full("P01", 1), full("P02", 2), stopped])
    out = tmp_path / "rep"
    assert main(["report", "--db", str(db), "--out", str(out), "--include-incomplete"]) == 0
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "P03 ON: GENTLE 1, FIRM 2" in page and "every target weighing the same" in page
    per = pd.read_csv(out / "participants.csv").set_index(["participant_code", "haptic_mode"])
    by_t = pd.read_csv(out / "participants_by_target.csv")
    cell = by_t[(by_t["participant_code"] == "P03") & (by_t["haptic_mode"] == "on")]
    assert per.at[("P03", "on"), "success_rate"] == pytest.approx(cell["success_rate"].mean(), abs=0.5e-4)
    assert per.at[("P03", "on"), "success_rate"] == pytest.approx(0.75, abs=1e-9)  # (1/1 + 1/2)/2, not 2/3
    assert per.at[("P03", "on"), "rmse_N"] == pytest.approx(cell["rmse_N"].mean(), abs=0.5e-4)
