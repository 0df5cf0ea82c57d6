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
