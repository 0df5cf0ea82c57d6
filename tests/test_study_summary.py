"""The summary `haptic-study run` prints: whose figures they are when the command ran only some sessions."""

from __future__ import annotations

import tomllib
from pathlib import Path

from cli_subprocess import tiny_protocol

from protocol.config import protocol_from_dict
from protocol.storage import StudyReader
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
