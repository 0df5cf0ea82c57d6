"""What protects a study database: integrity check, owner-only files, schema upgrade with backup, leases.

Every database lives in ``tmp_path``.  Leases held by "other processes" are real processes
(a child that takes a lease and waits, or exits) or rows written as another host would.
"""

from __future__ import annotations

import datetime as dt
import multiprocessing as mp
import os
import socket
import sqlite3
import stat
import zlib
from pathlib import Path

import pytest

from protocol.storage import (
    LEASE_STALE_S,
    SCHEMA_VERSION,
    LeaseHeld,
    StorageError,
    StudyDatabase,
    connect_readonly,
    new_owner_token,
    process_identity,
    session_scope,
)
from protocol.study.config import default_protocol
from protocol.study.design import build_schedule, schedule_to_json

V1_SCHEMA = Path(__file__).parent / "data" / "schema_v1.sql"
V3_SCHEMA = Path(__file__).parent / "data" / "schema_v3.sql"


def _session_args(code: str = "P01", kind: str = "experiment") -> dict:
    p = default_protocol()
    return dict(
        code=code, kind=kind, seed=7, participant_number=1, protocol_json=p.to_json(),
        schedule_json=schedule_to_json(build_schedule(p, seed=7, participant_number=1)),
        software_version="0.1.0+test", rig="sim", config={}, calibration=None,
    )


def _v1_database(path: Path) -> None:
    """A version-1 study database with one session, one trial and two samples (as 0.1 wrote them)."""
    c = sqlite3.connect(path)
    c.executescript(V1_SCHEMA.read_text() + "\nPRAGMA user_version = 1;")
    c.execute("PRAGMA journal_mode = WAL")
    c.execute("INSERT INTO participants VALUES (1, 'P01', '2026-01-01T00:00:00Z')")
    c.execute("INSERT INTO sessions (session_id, participant_id, kind, seed, participant_number, protocol_json, "
              "schedule_json, status, started_at, software_version, rig, config_json) VALUES "
              "(1, 1, 'experiment', 0, 1, '{}', '[]', 'running', 'x', '0.1.0', 'sim', '{}')")
    c.execute("INSERT INTO trials (trial_id, session_id, trial_index, target_label, target_force_n, haptic_mode, "
              "outcome, started_at_s, ended_at_s) VALUES (1000000, 1, 0, 'GENTLE', 0.6, 'on', 'timeout', 1.0, 13.0)")
    c.executemany("INSERT INTO samples (trial_id, t_s, force_n) VALUES (?, ?, ?)",
                  [(1000000, 0.0, 0.1), (1000000, 0.001, 0.2)])
    c.commit()
    c.close()


def _damage(path: Path) -> None:
    """Overwrite a page in the middle of a database with fixed junk (a disk error, a bad copy)."""
    data = bytearray(path.read_bytes())
    mid = (len(data) // 4096 // 2) * 4096
    for i in range(4096):
        data[mid + i] = (i * 151 + 7) % 256
    path.write_bytes(bytes(data))


def _big_database(path: Path) -> None:
    d = StudyDatabase(path)
    sid = d.create_session(**_session_args())
    with d.transaction():
        d.insert_samples([(sid * 1_000_000, k / 1000, 0.5) + (1.0,) * 12 for k in range(20_000)])
    d.conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    d.close()


# -- integrity ------------------------------------------------------------------------------------
def test_a_damaged_database_is_refused_before_anything_is_written(tmp_path):
    path = tmp_path / "study.db"
    _big_database(path)
    _damage(path)
    before = path.read_bytes()
    with pytest.raises(StorageError) as info:
        StudyDatabase(path)
    msg = str(info.value)
    assert msg.startswith(f"{path}: the database is damaged") and "\n" not in msg
    assert path.read_bytes() == before
    with pytest.raises(StorageError, match="damaged"):
        StudyDatabase(path, readonly=True, check=True)
    assert path.read_bytes() == before


def test_a_healthy_database_passes_the_check(tmp_path):
    path = tmp_path / "study.db"
    _big_database(path)
    StudyDatabase(path).close()
    StudyDatabase(path, readonly=True, check=True).close()


def test_a_file_that_is_not_sqlite_is_named_so(tmp_path):
    path = tmp_path / "notes.db"
    path.write_text("participant list\n")
    for readonly in (False, True):
        with pytest.raises(StorageError, match=r"not a haptic-study database \(not an SQLite file\)"):
            StudyDatabase(path, readonly=readonly)
    assert path.read_text() == "participant list\n"


# -- permissions ----------------------------------------------------------------------------------
def test_new_databases_and_their_journal_files_are_owner_only(tmp_path):
    old = os.umask(0o022)
    try:
        path = tmp_path / "study.db"
        d = StudyDatabase(path)
        d.create_session(**_session_args())
        files = [path, Path(f"{path}-wal"), Path(f"{path}-shm")]
        modes = {f.name: stat.S_IMODE(f.stat().st_mode) for f in files}
        d.close()
    finally:
        os.umask(old)
    assert modes == {"study.db": 0o600, "study.db-wal": 0o600, "study.db-shm": 0o600}


# -- reading archives -----------------------------------------------------------------------------
def test_connect_readonly_quotes_awkward_paths(tmp_path):
    folder = tmp_path / "pilot #2 ?x=1 %20"
    folder.mkdir()
    path = folder / "study.db"
    StudyDatabase(path).close()
    c = connect_readonly(path)
    assert c.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
    c.close()


# -- version 1 ------------------------------------------------------------------------------------
def test_a_v1_database_is_read_as_it_is(tmp_path):
    path = tmp_path / "old.db"
    _v1_database(path)
    before = path.read_bytes()
    d = StudyDatabase(path, readonly=True, check=True)
    assert d.schema_version == 1 and [s.code for s in d.open_sessions()] == ["P01"]
    d.close()
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.endswith(("-wal", "-shm"))) == ["old.db"]


def test_a_writer_upgrades_a_v1_database_after_writing_a_backup(tmp_path):
    path = tmp_path / "old.db"
    _v1_database(path)
    d = StudyDatabase(path)
    assert d.upgraded_from == 1 and d.schema_version == SCHEMA_VERSION
    backup = d.backup_path
    assert backup is not None and backup.parent == tmp_path and backup.name.startswith("old.v1-backup-")
    assert backup.suffix == ".db" and stat.S_IMODE(backup.stat().st_mode) == 0o600
    d.close()
    # the backup is the v1 database as it was
    b = sqlite3.connect(backup)
    assert b.execute("PRAGMA user_version").fetchone()[0] == 1
    assert b.execute("SELECT COUNT(*) FROM samples").fetchone()[0] == 2
    b.close()
    # the upgraded file has exactly the tables, columns and indexes of a new one
    fresh = tmp_path / "new.db"
    StudyDatabase(fresh).close()

    def shape(p: Path) -> dict:
        c = sqlite3.connect(p)
        tables = [r[0] for r in c.execute("SELECT name FROM sqlite_master WHERE type = 'table' ORDER BY name")]
        out = {t: c.execute(f"PRAGMA table_info({t})").fetchall() for t in tables}
        out["indexes"] = sorted(
            (r[1], r[2]) for t in tables for r in c.execute(f"PRAGMA index_list({t})") if not r[1].startswith("sqlite_")
        )
        c.close()
        return out

    assert shape(path) == shape(fresh)
    # and it keeps its data; reopening does not upgrade again
    d = StudyDatabase(path)
    assert d.upgraded_from is None and d.trial_rows(1)[0]["outcome"] == "timeout"
    d.close()
    assert len(list(tmp_path.glob("old.v1-backup-*"))) == 1


def test_a_v1_database_with_duplicate_samples_is_upgraded_keeping_its_index(tmp_path):
    path = tmp_path / "old.db"
    _v1_database(path)
    c = sqlite3.connect(path)
    c.execute("INSERT INTO samples (trial_id, t_s, force_n) VALUES (1000000, 0.001, 0.2)")  # the double-writer bug
    c.commit()
    c.close()
    d = StudyDatabase(path)
    assert d.schema_version == SCHEMA_VERSION
    assert d.conn.execute("SELECT COUNT(*) FROM samples").fetchone()[0] == 3
    d.close()


def test_a_v3_database_is_upgraded_to_checksummed_blocks_and_keeps_its_old_blocks_unverifiable(tmp_path):
    path = tmp_path / "v3.db"
    c = sqlite3.connect(path)
    c.executescript(V3_SCHEMA.read_text() + "\nPRAGMA user_version = 3;")
    c.execute("INSERT INTO participants VALUES (1, 'P01', '2026-01-01T00:00:00Z')")
    c.execute("INSERT INTO sessions (session_id, participant_id, kind, seed, participant_number, protocol_json, "
              "schedule_json, status, started_at, software_version, rig, config_json) VALUES "
              "(1, 1, 'experiment', 0, 1, '{}', '[]', 'running', 'x', '0.1.0', 'sim', '{}')")
    c.execute("INSERT INTO recordings VALUES (1, 0, 0.0, 0, '{}', '{}')")
    c.execute("INSERT INTO session_blocks VALUES (1, 0, 0, 0, 9, 10, 0.0, 0.009, x'0102')")
    c.commit()
    c.close()
    d = StudyDatabase(path)
    assert d.upgraded_from == 3 and d.schema_version == SCHEMA_VERSION == 4
    assert d.backup_path is not None and d.backup_path.name.startswith("v3.v3-backup-")
    # the block written before version 4 carries no checksum (NULL: not verifiable), a new one does
    d.write_block(1, 0, 1, 10, 19, 10, 0.01, 0.019, b"\x03\x04")
    d.commit()
    rows = d.conn.execute("SELECT block, crc32 FROM session_blocks ORDER BY block").fetchall()
    assert rows == [(0, None), (1, zlib.crc32(b"\x03\x04"))]
    assert d.conn.execute("SELECT software_commit, software_dirty FROM sessions").fetchone() == (None, None)
    d.close()


def test_upgrade_can_be_refused_and_then_nothing_changes(tmp_path):
    path = tmp_path / "old.db"
    _v1_database(path)
    before = path.read_bytes()
    with pytest.raises(StorageError, match="must be upgraded to 4 before it is written to; nothing was changed"):
        StudyDatabase(path, upgrade=False)
    assert path.read_bytes() == before


def test_an_upgrade_whose_backup_cannot_be_written_changes_nothing(tmp_path, monkeypatch):
    path = tmp_path / "old.db"
    _v1_database(path)
    before = path.read_bytes()

    def no_space(self, target, *a, **k):  # sqlite3.Connection.backup's signature
        raise sqlite3.OperationalError("database or disk is full")

    monkeypatch.setattr(StudyDatabase, "_backup_to", no_space, raising=True)
    with pytest.raises(StorageError) as info:
        StudyDatabase(path)
    assert "could not be written (database or disk is full); nothing was changed" in str(info.value)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.endswith(("-wal", "-shm"))) == ["old.db"]


# -- leases ---------------------------------------------------------------------------------------
def _hold_lease(path: str, scope: str, ready, release) -> None:  # mp events
    d = StudyDatabase(path, check=False)
    d.acquire_lease(scope, new_owner_token(), command="haptic-study run --resume P01")
    ready.set()
    release.wait(30)
    d.close()


@pytest.fixture
def other_process_holding():
    """Start a real process that takes a lease and holds it until the test ends."""
    ctx = mp.get_context("spawn")
    started = []

    def start(path: Path, scope: str) -> int:
        ready, release = ctx.Event(), ctx.Event()
        p = ctx.Process(target=_hold_lease, args=(str(path), scope, ready, release))
        p.start()
        assert ready.wait(60)
        started.append((p, release))
        return p.pid

    yield start
    for p, release in started:
        release.set()
        p.join(30)


def test_a_session_held_by_a_live_process_is_refused_with_its_name(tmp_path, other_process_holding):
    path = tmp_path / "study.db"
    d = StudyDatabase(path)
    sid = d.create_session(**_session_args())
    pid = other_process_holding(path, session_scope(sid))
    with pytest.raises(LeaseHeld) as info:
        d.acquire_lease(session_scope(sid), new_owner_token())
    msg = str(info.value)
    assert f"session {sid} of this database is being written by process {pid}" in msg
    assert "haptic-study run --resume P01" in msg and "\n" not in msg
    # nor can a whole study start over it
    with pytest.raises(LeaseHeld, match=f"session {sid} of this database"):
        d.acquire_lease("study", new_owner_token())
    d.close()


def test_a_study_held_by_a_live_process_refuses_sessions_but_not_its_own_workers(tmp_path, other_process_holding):
    path = tmp_path / "study.db"
    StudyDatabase(path).close()
    other_process_holding(path, "study")
    d = StudyDatabase(path)
    with pytest.raises(LeaseHeld, match="the study in this database is being written by process"):
        d.create_session(**_session_args(), lease_owner=new_owner_token())
    assert d.sessions_of("P01") == []  # refused before it wrote
    with pytest.raises(LeaseHeld):
        d.acquire_lease("study", new_owner_token())
    d.close()


def test_a_study_lease_is_shared_by_its_workers(tmp_path):
    path = tmp_path / "study.db"
    d = StudyDatabase(path)
    token = new_owner_token()
    assert d.acquire_lease("study", token) == ""
    worker = StudyDatabase(path)
    sid = worker.create_session(**_session_args(), lease_owner=new_owner_token(), study_owner=token)
    assert [r["scope"] for r in worker.lease_holders()] == ["study", session_scope(sid)]
    worker.close()
    d.close()


def _take_and_exit(path: str, scope: str) -> None:
    d = StudyDatabase(path, check=False)
    d.acquire_lease(scope, new_owner_token(), command="haptic-study run --participants 2")
    d.close()
    os._exit(0)  # killed: nothing released


def test_a_lease_left_by_a_dead_process_is_taken_over_and_said_so(tmp_path):
    path = tmp_path / "study.db"
    d = StudyDatabase(path)
    sid = d.create_session(**_session_args())
    p = mp.get_context("spawn").Process(target=_take_and_exit, args=(str(path), session_scope(sid)))
    p.start()
    p.join(60)
    (held,) = d.lease_holders()
    assert held["pid"] == p.pid and held["alive"] is False
    note = d.acquire_lease(session_scope(sid), new_owner_token())
    assert note.startswith(f"took over the lease on session {sid} left by process {p.pid}")
    assert [r["pid"] for r in d.lease_holders()] == [os.getpid()]
    d.close()


def test_a_reused_pid_does_not_keep_a_lease_alive(tmp_path):
    path = tmp_path / "study.db"
    d = StudyDatabase(path)
    # the lease names a running pid (this very process) but another process start: the pid was reused
    d.conn.execute("INSERT INTO leases VALUES ('study', 'x', ?, ?, 'old-boot:1', 'haptic-study run', 'a', 'a')",
                   (os.getpid(), socket.gethostname()))
    assert process_identity(os.getpid()) not in ("", "old-boot:1")
    assert d.acquire_lease("study", new_owner_token()).startswith("took over the lease on study")
    d.close()


def test_a_lease_from_another_host_lives_by_its_heartbeat(tmp_path):
    path = tmp_path / "study.db"
    d = StudyDatabase(path)
    now = dt.datetime.now(dt.UTC)
    fresh = (now - dt.timedelta(seconds=LEASE_STALE_S / 3)).isoformat()
    d.conn.execute("INSERT INTO leases VALUES ('session 9', 'x', 1, 'lab-pc-2', '', 'haptic-study gui', ?, ?)",
                   (fresh, fresh))
    with pytest.raises(LeaseHeld, match="process 1 on lab-pc-2"):
        d.acquire_lease("session 9", new_owner_token())
    stale = (now - dt.timedelta(seconds=2 * LEASE_STALE_S)).isoformat()
    d.conn.execute("UPDATE leases SET heartbeat_at = ?", (stale,))
    assert d.acquire_lease("session 9", new_owner_token()) != ""
    d.close()


def test_release_gives_back_only_ones_own_lease(tmp_path):
    path = tmp_path / "study.db"
    d = StudyDatabase(path)
    mine, theirs = new_owner_token(), new_owner_token()
    d.acquire_lease("session 1", mine)
    d.release_lease("session 1", theirs)
    assert len(d.lease_holders()) == 1
    d.release_lease("session 1", mine)
    assert d.lease_holders() == []
    d.close()


def test_heartbeat_refreshes_this_processs_leases(tmp_path):
    path = tmp_path / "study.db"
    d = StudyDatabase(path)
    d.acquire_lease("study", new_owner_token())
    d.conn.execute("UPDATE leases SET heartbeat_at = '2000-01-01T00:00:00+00:00'")
    d.heartbeat(force=True)
    (row,) = d.lease_holders()
    assert row["heartbeat_at"] > "2026"
    d.close()
