"""``check`` finds what was changed (issue 42, classes 1-2): in a 3-participant, two-arm study, every edit a
person or a faulty tool could make to one part of the record -- and that leaves the other parts as they were --
is a problem named in one line (exit 1); the healthy study is clean (exit 0); check changes no byte.
"""

from __future__ import annotations

import shutil
import sqlite3
import tomllib
from collections.abc import Callable
from pathlib import Path

import pytest
from cli_subprocess import tiny_protocol

from protocol.study.config import protocol_from_dict
from study_app.cli.main import main
from study_app.headless import run_study

Edit = Callable[[sqlite3.Connection], None]


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    db = tmp_path_factory.mktemp("edits") / "study.db"
    protocol = protocol_from_dict(tomllib.loads(tiny_protocol("edits")))
    run_study(str(db), participants=3, seed=2, protocol=protocol, jobs=1, sim_arms=("right", "left"))
    c = sqlite3.connect(db)
    try:
        c.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    finally:
        c.close()
    return db


def _sql(*statements: str) -> Edit:
    def edit(c: sqlite3.Connection) -> None:
        for s in statements:
            assert c.execute(s).rowcount != 0, s  # a case that changes nothing proves nothing
    return edit


#: (what was changed, the edit, a words of the line check must print)
EDITS: list[tuple[str, Edit, str]] = [
    ("an event moved to a session that does not exist",
     _sql("UPDATE events SET session_id = 999 WHERE rowid = (SELECT MIN(rowid) FROM events WHERE kind = 'phase')"),
     "refers to a row of sessions that does not exist"),
    ("a trial's cue event moved to a session that does not exist",
     _sql("UPDATE events SET session_id = 999 WHERE rowid = (SELECT MIN(rowid) FROM events WHERE kind = 'cue')"),
     "no cue event within 0.1 s of its start"),
    ("a cue event's target rewritten",
     _sql("UPDATE events SET detail = replace(detail, '0.6 N', '1.2 N') "
          "WHERE rowid = (SELECT MIN(rowid) FROM events WHERE kind = 'cue')"),
     "its cue event says 'GENTLE 1.2 N"),
    ("a trial's target rewritten",
     _sql("UPDATE trials SET target_force_n = 0.7 WHERE trial_id = (SELECT MIN(trial_id) FROM trials)"),
     "the trial row 'GENTLE 0.7 N"),
    ("a trial's mode rewritten",
     _sql("UPDATE trials SET haptic_mode = CASE haptic_mode WHEN 'on' THEN 'off' ELSE 'on' END "
          "WHERE trial_id = (SELECT MAX(trial_id) FROM trials)"),
     "its cue event says"),
    ("a trial's tick window shifted by 1.5 s",
     _sql("UPDATE trials SET first_tick = first_tick + 1500, last_tick = last_tick + 1500 "
          "WHERE trial_id = (SELECT MIN(trial_id) FROM trials)"),
     "its window is not where the trial ran"),
    ("a trial's start moved by 1.5 s",
     _sql("UPDATE trials SET started_at_s = started_at_s + 1.5 WHERE trial_id = (SELECT MAX(trial_id) FROM trials)"),
     "its window is not where the trial ran"),
    ("a trial moved to a session that does not exist",
     _sql("UPDATE trials SET session_id = 999 WHERE trial_id = (SELECT MIN(trial_id) FROM trials)"),
     "trials row"),
    ("a recorded block moved to a run that does not exist",
     _sql("UPDATE session_blocks SET segment = 7 WHERE session_id = 1 AND block = 0"),
     "refers to a row of recordings that does not exist"),
]


def _swap_blocks(c: sqlite3.Connection) -> None:
    """Session 1's block 2 and session 2's (the same ticks, the same tiny protocol): each intact, in the other's
    place, with its own checksum."""
    get = "SELECT data, crc32 FROM session_blocks WHERE session_id = ? AND segment = 0 AND block = 2"
    one, two = c.execute(get, (1,)).fetchone(), c.execute(get, (2,)).fetchone()
    put = "UPDATE session_blocks SET data = ?, crc32 = ? WHERE session_id = ? AND segment = 0 AND block = 2"
    c.execute(put, (*two, 1))
    c.execute(put, (*one, 2))


def _task_block_over_the_arms(c: sqlite3.Connection) -> None:
    """The task arm's block 3 of session 1 copied, checksum and all, over the other arm's (the same ticks)."""
    data, crc = c.execute("SELECT data, crc32 FROM session_blocks WHERE session_id = 1 AND segment = 0 AND block = 3"
                          ).fetchone()
    assert c.execute("UPDATE arm_blocks SET data = ?, crc32 = ? WHERE session_id = 1 AND segment = 0 AND block = 3 "
                     "AND arm = 'left'", (data, crc)).rowcount == 1


BLOCK_EDITS: list[tuple[str, Edit, str]] = [
    ("blocks swapped between two sessions with the same tick range", _swap_blocks,
     "session 2, recorded run 0, 2.000–2.999 s (block 2): checksum mismatch (the block's bytes, or the place"),
    ("one arm's block copied over the other's", _task_block_over_the_arms,
     "arm left, session 1, recorded run 0, block 3 (ticks 3000–3999): checksum mismatch"),
    ("a session's last block deleted",
     _sql("DELETE FROM session_blocks WHERE session_id = 3 AND segment = 0 "
          "AND block = (SELECT MAX(block) FROM session_blocks WHERE session_id = 3)"),
     "blocks were written, block"),
    ("an arm's last block deleted",
     _sql("DELETE FROM arm_blocks WHERE session_id = 2 AND segment = 0 "
          "AND block = (SELECT MAX(block) FROM arm_blocks WHERE session_id = 2)"),
     "arm left, session 2, recorded run 0:"),
    ("a session's last two blocks deleted",
     _sql("DELETE FROM session_blocks WHERE session_id = 1 AND segment = 0 "
          "AND block >= (SELECT MAX(block) - 1 FROM session_blocks WHERE session_id = 1)"),
     "missing from the recording"),
    ("a block renumbered",
     _sql("UPDATE session_blocks SET block = block + 1000 WHERE session_id = 2 AND segment = 0 AND block = 1"),
     "(block 1001): checksum mismatch (the block's bytes, or the place"),
]
EDITS += BLOCK_EDITS


def _plain_crc(c: sqlite3.Connection) -> None:
    """A tool that 'repairs' a block by giving it the CRC-32 of its bytes alone (the pre-binding checksum)."""
    import zlib

    data = c.execute("SELECT data FROM session_blocks WHERE session_id = 3 AND segment = 0 AND block = 4").fetchone()[0]
    c.execute("UPDATE session_blocks SET crc32 = ? WHERE session_id = 3 AND segment = 0 AND block = 4",
              (zlib.crc32(data),))


def _swap_arm_blocks(c: sqlite3.Connection) -> None:
    get = "SELECT data, crc32 FROM arm_blocks WHERE session_id = ? AND segment = 0 AND block = 1 AND arm = 'left'"
    one, two = c.execute(get, (1,)).fetchone(), c.execute(get, (3,)).fetchone()
    put = ("UPDATE arm_blocks SET data = ?, crc32 = ? "
           "WHERE session_id = ? AND segment = 0 AND block = 1 AND arm = 'left'")
    c.execute(put, (*two, 1))
    c.execute(put, (*one, 3))


MORE_EDITS: list[tuple[str, Edit, str]] = [
    ("a block given the checksum of its bytes alone", _plain_crc, "(block 4): checksum mismatch"),
    ("the other arm's blocks swapped between two sessions", _swap_arm_blocks,
     "arm left, session 1, recorded run 0, block 1"),
    ("every block of a session deleted",
     _sql("DELETE FROM session_blocks WHERE session_id = 2"), "blocks 0–"),
    ("a block's record count changed", _sql(
        "UPDATE session_blocks SET n_records = n_records - 1 WHERE session_id = 1 AND segment = 0 AND block = 5"),
     "(block 5): checksum mismatch"),
    ("a block's ticks changed", _sql(
        "UPDATE session_blocks SET first_tick = first_tick + 1 WHERE session_id = 2 AND segment = 0 AND block = 3"),
     "(block 3): checksum mismatch"),
    ("a recorded run's row deleted", _sql("DELETE FROM recordings WHERE session_id = 3"),
     "refers to a row of recordings that does not exist"),
    ("the other arm's run row deleted", _sql("DELETE FROM arm_recordings WHERE session_id = 1"),
     "refers to a row of arm_recordings that does not exist"),
    ("a session moved to a participant who does not exist",
     _sql("UPDATE sessions SET participant_id = 99 WHERE session_id = 2"),
     "sessions row 2 refers to a row of participants that does not exist"),
    ("a trial moved to a run that does not exist",
     _sql("UPDATE trials SET segment = 5 WHERE trial_id = (SELECT MAX(trial_id) FROM trials)"),
     "are not all in readable blocks"),
    ("a trial's label rewritten",
     _sql("UPDATE trials SET target_label = 'FIRM' WHERE trial_id = (SELECT MIN(trial_id) FROM trials)"),
     "the trial row 'FIRM 0.6 N"),
    ("two trials' modes swapped",
     _sql("UPDATE trials SET haptic_mode = CASE haptic_mode WHEN 'on' THEN 'off' ELSE 'on' END "
          "WHERE session_id = 2 AND trial_index IN (SELECT trial_index FROM trials t WHERE t.session_id = 2 "
          "AND t.haptic_mode = 'on' LIMIT 1) OR session_id = 2 AND trial_index IN (SELECT trial_index FROM trials t "
          "WHERE t.session_id = 2 AND t.haptic_mode = 'off' LIMIT 1)"),
     "its cue event says"),
    ("a trial's window and start moved together by 1.5 s (its cue event left)",
     _sql("UPDATE trials SET first_tick = first_tick + 1500, last_tick = last_tick + 1500, "
          "started_at_s = started_at_s + 1.5 WHERE trial_id = (SELECT MIN(trial_id) FROM trials WHERE session_id = 3)"),
     "no cue event within 0.1 s of its start"),
    ("a cue event's words garbled",
     _sql("UPDATE events SET detail = 'GENTLE' WHERE rowid = (SELECT MAX(rowid) FROM events WHERE kind = 'cue')"),
     "does not name a trial as the runner does"),
    ("a withdrawal's rewrite marked unfinished",
     _sql("INSERT INTO withdrawals (code, withdrawn_at, reason, removed_sessions, removed_trials, removed_events, "
          "removed_blocks, removed_records, removed_samples, rewritten) "
          "VALUES ('P09', '2026-01-01T00:00:00+00:00', 'consent withdrawn', 1, 4, 20, 8, 8000, 0, 0)"),
     "withdrawal of P09 incomplete"),
]
EDITS += MORE_EDITS

_A_TRIAL = "trial_id = (SELECT MIN(trial_id) FROM trials WHERE outcome != 'aborted' AND session_id = 2)"
METRIC_EDITS: list[tuple[str, Edit, str]] = [
    ("a trial's stored RMSE edited by 1 %", _sql(f"UPDATE trials SET rmse_n = rmse_n * 1.01 WHERE {_A_TRIAL}"),
     "its rmse_n recomputed from the recording is"),
    ("a trial's stored Max AE edited", _sql(f"UPDATE trials SET max_ae_n = max_ae_n + 0.05 WHERE {_A_TRIAL}"),
     "its max_ae_n recomputed from the recording is"),
    ("a trial's stored error impulse edited",
     _sql(f"UPDATE trials SET abs_impulse_n_s = abs_impulse_n_s * 0.9 WHERE {_A_TRIAL}"),
     "its abs_impulse_n_s recomputed from the recording is"),
    ("a timeout stored as a success",
     _sql("UPDATE trials SET outcome = 'success', tct_s = 1.0 WHERE trial_id = "
          "(SELECT MIN(trial_id) FROM trials WHERE outcome = 'timeout')"),
     "its outcome recomputed from the recording is no success, stored success"),
]
EDITS += METRIC_EDITS


def _check(db: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    before = db.read_bytes()
    status = main(["check", "--db", str(db)])
    assert db.read_bytes() == before  # read only
    return status, capsys.readouterr().out


def test_the_healthy_study_is_clean(study: Path, capsys: pytest.CaptureFixture[str]) -> None:
    status, said = _check(study, capsys)
    assert status == 0, said


@pytest.mark.parametrize(("what", "edit", "words"), EDITS, ids=[e[0] for e in EDITS])
def test_an_edit_is_found_and_named(study: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], what: str,
                                    edit: Edit, words: str) -> None:
    db = tmp_path / "edited.db"
    shutil.copyfile(study, db)
    c = sqlite3.connect(db)
    try:
        edit(c)
        c.commit()
        c.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    finally:
        c.close()
    status, said = _check(db, capsys)
    assert status == 1 and words in said, f"{what}:\n{said}"
