"""Participants recorded in another database merged into a study database, each block's checksum bound anew.

A study run on a Dask cluster (``haptic-study run --scheduler``) runs each participant on a worker, into a database
in the worker's scratch folder; the file comes back to the machine that asked and is merged here into the study's
database.  A merge copies every row of the participant -- the participant and their covariates, their sessions, and
each session's trials, events, notes, questionnaire answers, recorded runs, blocks and chunks -- in one
transaction: all of it or nothing.  The copy gets the session ids the study database gives it (they are
allocated in the order sessions arrive, as a parallel run's are), so each recorded block's checksum, which binds
the block to its session (:func:`protocol.recording.integrity.place_crc32`), is verified against the place it was
written under and bound to its new one.  A block that matches neither its old place nor (a run recorded before
checksums bound their place) its bytes is damage: the merge is refused and nothing is stored.
"""

from __future__ import annotations

import sqlite3
import zlib
from collections.abc import Sequence
from typing import Any

from protocol.metrics import get as metric
from protocol.recording.integrity import WHOLE_BLOCK, place_crc32
from protocol.storage.common import StorageError, has_table
from protocol.storage.database import StudyDatabase
from protocol.storage.schema import add_later_columns, add_metric_columns
from protocol.study.records import trial_id_of

__all__ = ["database_bytes", "merge_database_bytes", "merge_participants"]

#: The tables keyed by a session, in the order a merge fills them (a run before its blocks and chunks).
SESSION_TABLES = ("trials", "events", "notes", "questionnaire_answers", "recordings", "session_blocks",
                  "session_chunks", "arm_recordings", "arm_blocks", "arm_chunks")
#: The block tables, and whether a row is a chunk (its number in its place) or a whole block.
BLOCK_TABLES = {"session_blocks": False, "session_chunks": True, "arm_blocks": False, "arm_chunks": True}


def merge_participants(db: StudyDatabase, src: sqlite3.Connection, source: str) -> dict[int, int]:
    """Copy every participant of the database open in ``src`` (``source`` names it in messages) into ``db``, in one
    transaction.

    Returns the new session id of each copied session (old id -> new).  Raises :class:`StorageError` (nothing
    stored) when a participant's code is already in ``db`` (or was withdrawn from it), ``src`` has a table
    or column ``db`` cannot hold, or a block's checksum matches neither its place nor its bytes.
    """
    codes = [r[0] for r in src.execute("SELECT code FROM participants ORDER BY participant_id")]
    _check_codes(db, source, codes)
    _give_columns(db, src, source)
    db.begin()
    try:
        mapping: dict[int, int] = {}
        for pid, code, created_at in src.execute(
                "SELECT participant_id, code, created_at FROM participants ORDER BY participant_id").fetchall():
            mapping.update(_copy_participant(db.conn, src, source, pid, code, created_at))
    except BaseException:
        db.conn.execute("ROLLBACK")
        raise
    db.commit()
    return mapping


def _check_codes(db: StudyDatabase, source: str, codes: Sequence[str]) -> None:
    """Refuse a participant the study already has, or had and was withdrawn (their code is not given again)."""
    for code in codes:
        if db.conn.execute("SELECT 1 FROM participants WHERE code = ?", (code,)).fetchone():
            raise StorageError(f"{source}: participant {code} is already in {db.path}; nothing was merged")
        if has_table(db.conn, "withdrawals") and db.conn.execute(
                "SELECT 1 FROM withdrawals WHERE code = ?", (code,)).fetchone():
            raise StorageError(f"{source}: participant {code} was withdrawn from {db.path}; nothing was merged")


def _give_columns(db: StudyDatabase, src: sqlite3.Connection, source: str) -> None:
    """Give ``db`` the metric and later columns ``src`` has (as a writer of a new session would); refuse any other
    column or table it lacks."""
    if has_table(src, "samples") and src.execute("SELECT 1 FROM samples LIMIT 1").fetchone():
        raise StorageError(f"{source}: trials recorded as sample rows (versions 1-2) are not merged; nothing was")
    add_later_columns(db.conn)
    extra = [c for c in _columns(src, "trials") if c not in _columns(db.conn, "trials")]
    stored = []
    for name in extra:
        try:
            if metric(name).stored:
                stored.append(name)
        except KeyError:
            pass
    if stored:
        add_metric_columns(db.conn, stored)
    for table in ("participants", "covariates", "sessions", *SESSION_TABLES):
        if not has_table(src, table):
            continue
        if not has_table(db.conn, table):
            raise StorageError(f"{source}: table {table} is not in {db.path} (another version of haptic-study); "
                               "nothing was merged")
        lacking = [c for c in _columns(src, table) if c not in _columns(db.conn, table)]
        if lacking:
            raise StorageError(f"{source}: {table}.{lacking[0]} is not in {db.path} (another version of "
                               "haptic-study); nothing was merged")


def _copy_participant(conn: sqlite3.Connection, src: sqlite3.Connection, source: str, pid: int, code: str,
                      created_at: str) -> dict[int, int]:
    new_pid = int(conn.execute("INSERT INTO participants (code, created_at) VALUES (?, ?)",
                               (code, created_at)).lastrowid or 0)
    if has_table(src, "covariates"):
        _copy_rows(conn, src, "covariates", "participant_id", pid, new_pid)
    mapping = {}
    cols = [c for c in _columns(src, "sessions") if c != "session_id"]
    for row in src.execute(f"SELECT session_id, {', '.join(cols)} FROM sessions WHERE participant_id = ? "
                           "ORDER BY session_id", (pid,)).fetchall():
        values = [new_pid if c == "participant_id" else v for c, v in zip(cols, row[1:], strict=True)]
        cur = conn.execute(f"INSERT INTO sessions ({', '.join(cols)}) VALUES ({', '.join('?' * len(cols))})",
                           values)
        mapping[int(row[0])] = int(cur.lastrowid or 0)
    for old, new in mapping.items():
        for table in SESSION_TABLES:
            if has_table(src, table):
                _copy_rows(conn, src, table, "session_id", old, new, source=source)
    return mapping


def _copy_rows(conn: sqlite3.Connection, src: sqlite3.Connection, table: str, key: str, old: int, new: int,
               source: str = "") -> None:
    """Copy ``table``'s rows whose ``key`` is ``old`` with ``new`` in its place (a block's checksum bound anew)."""
    cols = _columns(src, table)
    at = cols.index(key)
    rows = src.execute(f"SELECT {', '.join(cols)} FROM {table} WHERE {key} = ? ORDER BY rowid", (old,)).fetchall()
    if table == "trials":  # a trial's id is its session's and its index (trial_id_of)
        tid, index = cols.index("trial_id"), cols.index("trial_index")
        rows = [tuple(new if i == at else trial_id_of(new, r[index]) if i == tid else v for i, v in enumerate(r))
                for r in rows]
    elif table in BLOCK_TABLES:
        rows = [_rebound(dict(zip(cols, r, strict=True)), table, new, source) for r in rows]
        rows = [tuple(r[c] for c in cols) for r in rows]
    else:
        rows = [(*r[:at], new, *r[at + 1:]) for r in rows]
    conn.executemany(f"INSERT INTO {table} ({', '.join(cols)}) VALUES ({', '.join('?' * len(cols))})", rows)


def _rebound(row: dict[str, Any], table: str, new_session: int, source: str) -> dict[str, Any]:
    """A block (or chunk) row moved to session ``new_session``: its checksum verified where it was, then bound."""
    def place(session_id: int) -> int:
        return place_crc32(row["data"], arm=row.get("arm", ""), session_id=session_id, segment=row["segment"],
                           block=row["block"], chunk=row["chunk"] if BLOCK_TABLES[table] else WHOLE_BLOCK,
                           first_tick=row["first_tick"], last_tick=row["last_tick"], n_records=row["n_records"])

    crc = row["crc32"]
    old = row["session_id"]
    if crc is not None and crc == place(old):
        row["crc32"] = place(new_session)
    elif crc is not None and crc != zlib.crc32(row["data"]):
        raise StorageError(f"{source}: {table} block {row['block']} of session {old} (segment {row['segment']}) "
                           "does not match its checksum: damaged; nothing was merged")
    row["session_id"] = new_session
    return row


def _columns(conn: sqlite3.Connection, table: str) -> list[str]:
    return [r[1] for r in conn.execute(f"PRAGMA table_info({table})")]


def database_bytes(db: StudyDatabase) -> bytes:
    """The whole database as one file's bytes, to send to another machine: taken out of WAL mode first (its log
    checkpointed into the file), since a WAL database's bytes open nowhere but beside their log, and deserialized
    in memory not at all.  For a database this process made and is done with (a worker's scratch database)."""
    db.conn.execute("PRAGMA journal_mode=DELETE")
    return db.conn.serialize()


def merge_database_bytes(db: StudyDatabase, data: bytes, source: str) -> dict[int, int]:
    """:func:`merge_participants` from a database's bytes (:func:`database_bytes`), opened in memory."""
    src = sqlite3.connect(":memory:")
    try:
        src.deserialize(data)
        return merge_participants(db, src, source)
    finally:
        src.close()
