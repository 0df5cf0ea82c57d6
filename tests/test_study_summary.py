"""The summary `haptic-study run` prints: whose figures they are when the command ran only some sessions."""

from __future__ import annotations

import tomllib
from pathlib import Path

from cli_subprocess import tiny_protocol

from protocol.storage import StudyReader
from protocol.study.config import protocol_from_dict
from study_app.cli.study_summary import format_study_summary
from study_app.headless import run_study


def test_a_summary_of_some_sessions_says_so(tmp_path: Path) -> None:
    """After `run --resume P01` the summary read "Study database …: 1 participant, … 0 training trials excluded", as
    if it were the study's: it is the sessions this command ran."""
    db = tmp_path / "study.db"
    run_study(str(db), participants=2, seed=1, protocol=protocol_from_dict(tomllib.loads(tiny_protocol("s"))), jobs=1)
    with StudyReader(db) as reader:
        ids = [s.session_id for s in reader.sessions()]
    whole = format_study_summary(str(db), ids, 1.0).splitlines()[0]
    assert whole.startswith(f"Study database {db}: 2 participants, ") and "this command ran" not in whole
    part = format_study_summary(str(db), ids[-1:], 1.0).splitlines()[0]
    assert part.startswith(f"Study database {db} (the 1 session this command ran, of 2 stored; haptic-study report "
                           "analyses them all): 1 participant, "), part


def test_the_summary_says_over_how_many_participants_tct_is_averaged(tmp_path: Path) -> None:
    """A participant without a success in a mode has no TCT there: the TCT row's mean ± SD was over fewer people
    than the other rows (2 OFF against 6 ON in a 6-participant study), and the summary did not say so."""
    db = tmp_path / "study.db"
    run_study(str(db), participants=2, seed=1, protocol=protocol_from_dict(tomllib.loads(tiny_protocol("s"))), jobs=1)
    with StudyReader(db) as reader:
        sessions = {s.session_id: s.code for s in reader.sessions()}
        records = reader.trial_records(list(sessions))
    succeeded = {m: {sessions[t.session_id] for t in records
                     if t.haptic_mode.value == m and t.metric("tct_s") is not None and t.outcome.value == "success"}
                 for m in ("off", "on")}
    assert min(len(succeeded["off"]), len(succeeded["on"])) < 2  # the case this test is about
    text = format_study_summary(str(db), list(sessions), 1.0)
    assert (f"  (TCT: over {len(succeeded['off'])} (OFF) / {len(succeeded['on'])} (ON) of 2 participants: one with "
            "no success in a mode has no TCT there)") in text, text
