"""The report's methods name the rig's qualification (``haptic-study qualify``) a session stored, and say nothing of
one when no session stored it (a simulated study's report is unchanged)."""

from __future__ import annotations

import json
import sqlite3

from studybuilder import SessionDef, build, success_trial

from analysis.reading.load import load_study
from analysis.report.latency_methods import qualification_paragraph

RECORD = {"software_version": "0.1.0", "date": "2026-12-06T13:53:56+00:00", "verdict": "PARTIAL",
          "checks": [{"name": "process-death", "verdict": "PASS", "measured": "0.440 N held; 0.0000 N at 50.4 ms",
                      "bound": "", "why": ""},
                     {"name": "latency", "verdict": "NOT CHECKED", "measured": "", "bound": "", "why": "not measured"}]}


def test_the_stored_qualification_is_named_and_none_is_nothing(tmp_path) -> None:
    sessions = [SessionDef(code, [success_trial("GENTLE", "on", 200)], max_trial_s=4.0) for code in ("P01", "P02")]
    db = build(tmp_path / "q.db", sessions)
    assert qualification_paragraph(load_study([db])) == ""
    con = sqlite3.connect(db)
    with con:
        con.execute("UPDATE sessions SET config_json = ? WHERE participant_id = (SELECT MIN(participant_id) "
                    "FROM sessions)", (json.dumps({"qualification": {"right": RECORD}}),))
    con.close()
    said = qualification_paragraph(load_study([db]))
    assert said.startswith("<p><b>Rig qualification</b> (haptic-study qualify, docs/qualify.md): the record stored "
                           "with 1 session when it started: arm right: PARTIAL on 2026-12-06T13:53:56+00:00 "
                           "(software 0.1.0): process-death PASS (0.440 N held; 0.0000 N at 50.4 ms); latency NOT "
                           "CHECKED (not measured).")
    assert said.endswith(" 1 session stored no qualification.</p>")
