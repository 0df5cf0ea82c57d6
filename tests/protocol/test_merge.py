"""A participant recorded in another database merged into a study's (``run --scheduler``): all of it or nothing,
every block's checksum verified where it was written and bound to its new session."""

from __future__ import annotations

import sqlite3
import tomllib
from pathlib import Path

import pytest
from cli_subprocess import tiny_protocol

from protocol.storage import StorageError, StudyDatabase
from protocol.storage.audit import audit_database
from protocol.storage.merge import merge_participants
from protocol.study.config import protocol_from_dict
from study_app.headless import run_study

PROTOCOL = protocol_from_dict(tomllib.loads(tiny_protocol("merge")), "merge protocol")


@pytest.fixture(scope="module")
def one(tmp_path_factory) -> Path:
    """A study database of one simulated participant, P01."""
    path = tmp_path_factory.mktemp("merge") / "p01.db"
    run_study(str(path), participants=1, seed=3, protocol=PROTOCOL, jobs=1)
    return path


def _merge(dst: Path, src: Path) -> dict[int, int]:
    db = StudyDatabase(str(dst))
    conn = sqlite3.connect(src)
    try:
        return merge_participants(db, conn, src.name)
    finally:
        conn.close()
        db.close()


def test_a_participant_merged_into_a_study_keeps_every_row_and_a_bound_checksum_per_block(tmp_path: Path,
                                                                                           one: Path) -> None:
    dst = tmp_path / "study.db"
    run_study(str(dst), participants=1, seed=9, protocol=PROTOCOL, jobs=1)  # P01 of another seed: a session 1
    src = tmp_path / "p02.db"
    c = sqlite3.connect(one)
    c.execute("VACUUM INTO ?", (str(src),))
    c.close()
    c = sqlite3.connect(src)
    c.execute("UPDATE participants SET code = 'P02'")  # as a worker's P02 would be
    c.commit()
    c.close()
    assert _merge(dst, src) == {1: 2}
    c = sqlite3.connect(dst)
    try:
        report = audit_database(c, str(dst))
        assert not report.problems and not report.damage, report.problems  # every block verifies in its new place
        assert report.blocks_verified > 0 and report.blocks_unverifiable == 0
        assert c.execute("SELECT COUNT(*) FROM trials WHERE session_id = 2").fetchone() == (4,)
        assert c.execute("SELECT MIN(trial_id) FROM trials WHERE session_id = 2").fetchone() == (2_000_000,)
    finally:
        c.close()


def test_a_participant_the_study_has_is_refused_and_nothing_is_stored(tmp_path: Path, one: Path) -> None:
    dst = tmp_path / "study.db"
    run_study(str(dst), participants=1, seed=9, protocol=PROTOCOL, jobs=1)
    before = dst.read_bytes()
    with pytest.raises(StorageError, match="participant P01 is already in"):
        _merge(dst, one)
    assert dst.read_bytes() == before


def test_a_damaged_block_is_refused_and_nothing_is_stored(tmp_path: Path, one: Path) -> None:
    src = tmp_path / "damaged.db"
    c = sqlite3.connect(one)
    c.execute("VACUUM INTO ?", (str(src),))
    c.close()
    c = sqlite3.connect(src)
    data = bytearray(c.execute("SELECT data FROM session_blocks WHERE block = 1").fetchone()[0])
    data[len(data) // 2] ^= 0x01  # one flipped bit
    c.execute("UPDATE session_blocks SET data = ? WHERE block = 1", (bytes(data),))
    c.commit()
    c.close()
    dst = tmp_path / "study.db"
    StudyDatabase(str(dst)).close()
    with pytest.raises(StorageError, match=r"block 1 of session 1 .* does not match its checksum"):
        _merge(dst, src)
    c = sqlite3.connect(dst)
    try:
        assert c.execute("SELECT (SELECT COUNT(*) FROM participants) + (SELECT COUNT(*) FROM sessions) "
                         "+ (SELECT COUNT(*) FROM session_blocks)").fetchone() == (0,)
    finally:
        c.close()
