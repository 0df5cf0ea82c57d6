"""A participant's withdrawal: every row of theirs removed, the file rewritten, a record of it kept.

An ethics approval lets a participant withdraw and have their data erased.  :func:`erase_participant` removes,
in one transaction, the participant row and everything that refers to it -- their covariates, sessions, trials,
events, notes, questionnaires' answers, recorded runs and blocks, the samples rows of older versions and the leases
of their sessions -- with SQLite's
``secure_delete`` on, so the freed bytes are overwritten with zeros rather than left in free pages (and every page
that was already free, which a writer's ``secure_delete = FAST`` may have left with old bytes, zeroed too), and stores a
:class:`Withdrawal` record that keeps only the pseudonymous code, the time, the reason and how many rows of each kind
were removed (no measurement).  :func:`rewrite_file` then checkpoints the write-ahead log into the file (so the
zeroed pages land on the file's own blocks), rewrites the whole file (``VACUUM``) and empties the log, so nothing of
theirs can be read back from the database or its ``-wal`` file.

The caller holds the study's one-writer lease (:meth:`protocol.storage.StudyDatabase.acquire_lease` on
``"study"``) while it does so: no session is written meanwhile, and none of theirs is running.  A withdrawn code
is never given a session again (:meth:`protocol.storage.StudyDatabase.create_session` refuses it).
"""

from __future__ import annotations

import os
import sqlite3
from contextlib import AbstractContextManager
from dataclasses import astuple, dataclass, fields
from pathlib import Path
from typing import Protocol

from protocol.storage.common import StorageError, has_table, now_iso, recording_tables
from protocol.storage.leases import session_scope
from protocol.storage.lsl_streams import erase_lsl_rows
from protocol.study.labels import plural
from protocol.study.records import trial_id_of

__all__ = ["Footprint", "Withdrawal", "erase_participant", "footprint", "lsl_words", "mark_rewritten",
           "nobody_reading", "rewrite_file", "rewrite_pending", "withdrawal_of", "withdrawals"]


class StudyDatabase(Protocol):
    """What this module uses of :class:`protocol.storage.StudyDatabase` (which imports this module)."""

    path: Path
    conn: sqlite3.Connection

    def transaction(self) -> AbstractContextManager[None]: ...
    def sessions_being_written(self) -> dict[int, str]: ...
    def quick_check(self) -> None: ...


@dataclass(frozen=True, slots=True)
class Footprint:
    """What is stored about one participant: what a withdrawal removes.

    ``sessions`` holds ``(session_id, kind, status)`` per session, oldest first.
    """

    code: str
    participant_id: int
    sessions: tuple[tuple[int, str, str], ...]
    trials: int
    events: int
    segments: int
    blocks: int
    records: int
    samples: int
    #: The external LSL streams recorded with their sessions (``lsl_streams`` rows) and their samples' chunks
    #: (``lsl_chunks`` rows): what the LSL recorder kept of other instruments while they took part
    lsl_streams: int = 0
    lsl_chunks: int = 0

    def describe(self) -> str:
        """One sentence naming what is stored (what a withdrawal will remove)."""
        kinds = ", ".join(f"{k} session {sid} ({'interrupted' if st == 'running' else st})"
                          for sid, k, st in self.sessions)
        recorded = (f"{plural(self.segments, 'recorded run')} in {plural(self.blocks, 'block')} "
                    f"({self.records:,} records at 1 kHz)")
        older = f", {plural(self.samples, 'samples row')} (an older version's)" if self.samples else ""
        return (f"participant {self.code}: {plural(len(self.sessions), 'session')}{': ' + kinds if kinds else ''}; "
                f"{plural(self.trials, 'trial')}, {plural(self.events, 'event')}, {recorded}{older}"
                f"{lsl_words(self.lsl_streams, self.lsl_chunks)}")


def lsl_words(streams: int | None, chunks: int | None) -> str:
    """The LSL rows of a footprint or a withdrawal, in words (nothing when there are none, or none were counted)."""
    if not streams and not chunks:
        return ""
    return (f", {plural(streams or 0, 'external LSL stream')} ({plural(chunks or 0, 'chunk')} of their samples: "
            f"lsl_streams, lsl_chunks)")


@dataclass(frozen=True, slots=True)
class Withdrawal:
    """The record a withdrawal leaves (table ``withdrawals``): no measurement, only what the ethics board asks."""

    code: str
    withdrawn_at: str
    reason: str
    removed_sessions: int
    removed_trials: int
    removed_events: int
    removed_blocks: int
    removed_records: int
    removed_samples: int
    #: 1 once the file's rewrite after the removal finished; 0 until then (a reader held it up, or the command was
    #: stopped between the removal and the rewrite); None in a record made before this mark
    rewritten: int | None = None
    #: The ``lsl_streams`` and ``lsl_chunks`` rows removed (external streams recorded with their sessions); None in
    #: a record made before these columns
    removed_lsl_streams: int | None = None
    removed_lsl_chunks: int | None = None

    def counts(self) -> str:
        """What was removed, in words."""
        return (f"{plural(self.removed_sessions, 'session')}, {plural(self.removed_trials, 'trial')}, "
                f"{plural(self.removed_events, 'event')}, {plural(self.removed_blocks, 'recorded block')} "
                f"({self.removed_records:,} records)"
                + (f", {plural(self.removed_samples, 'samples row')}" if self.removed_samples else "")
                + lsl_words(self.removed_lsl_streams, self.removed_lsl_chunks))


_COLUMNS = ", ".join(f.name for f in fields(Withdrawal))


def _read_columns(conn: sqlite3.Connection) -> str:
    """The record's columns as a file holds them (``rewritten`` NULL in a file from before the mark)."""
    have = {r[1] for r in conn.execute("PRAGMA table_info(withdrawals)")}
    return ", ".join(f.name if f.name in have else "NULL" for f in fields(Withdrawal))


def withdrawals(conn: sqlite3.Connection) -> list[Withdrawal]:
    """Every withdrawal recorded in a database, oldest first (none in a file from before withdrawals)."""
    if not has_table(conn, "withdrawals"):
        return []
    return [Withdrawal(*r) for r in conn.execute(
        f"SELECT {_read_columns(conn)} FROM withdrawals ORDER BY withdrawn_at, code")]


def withdrawal_of(conn: sqlite3.Connection, code: str) -> Withdrawal | None:
    """The withdrawal of one participant code, or None."""
    if not has_table(conn, "withdrawals"):
        return None
    row = conn.execute(f"SELECT {_read_columns(conn)} FROM withdrawals WHERE code = ?", (code,)).fetchone()
    return None if row is None else Withdrawal(*row)


def mark_rewritten(db: StudyDatabase, code: str) -> None:
    """Record that the file's rewrite after ``code``'s removal finished (what :func:`rewrite_pending` reads)."""
    with db.transaction():
        db.conn.execute("UPDATE withdrawals SET rewritten = 1 WHERE code = ?", (code,))


def footprint(conn: sqlite3.Connection, code: str) -> Footprint | None:
    """Everything stored about participant ``code``, counted; None when there is no such participant."""
    row = conn.execute("SELECT participant_id FROM participants WHERE code = ?", (code,)).fetchone()
    if row is None:
        return None
    pid = int(row[0])
    sessions = tuple((int(s), str(k), str(st)) for s, k, st in conn.execute(
        "SELECT session_id, kind, status FROM sessions WHERE participant_id = ? ORDER BY session_id", (pid,)))
    trials = events = segments = blocks = records = samples = 0
    recorded = has_table(conn, "session_blocks")
    open_blocks = has_table(conn, "session_chunks")  # (a killed run's last block, in the chunks it was written in)
    for sid, _, _ in sessions:
        trials += conn.execute("SELECT COUNT(*) FROM trials WHERE session_id = ?", (sid,)).fetchone()[0]
        events += conn.execute("SELECT COUNT(*) FROM events WHERE session_id = ?", (sid,)).fetchone()[0]
        samples += conn.execute("SELECT COUNT(*) FROM samples WHERE trial_id >= ? AND trial_id < ?",
                                (trial_id_of(sid, 0), trial_id_of(sid + 1, 0))).fetchone()[0]
        for arm in ("", "arm") if recorded else ():  # the task arm's recording, then the other arms' (if any)
            recs, blocks_table, chunks = recording_tables(arm)
            if not has_table(conn, recs):
                continue
            if not arm:  # (a run records every arm: counted once)
                segments += conn.execute(f"SELECT COUNT(*) FROM {recs} WHERE session_id = ?", (sid,)).fetchone()[0]
            b, r = conn.execute(f"SELECT COUNT(*), COALESCE(SUM(n_records), 0) FROM {blocks_table} "
                                "WHERE session_id = ?", (sid,)).fetchone()
            blocks, records = blocks + int(b), records + int(r)
            if open_blocks and has_table(conn, chunks):
                b, r = conn.execute(f"SELECT COUNT(*), COALESCE(SUM(n), 0) FROM (SELECT SUM(n_records) AS n FROM "
                                    f"{chunks} WHERE session_id = ? GROUP BY {'arm, ' if arm else ''}segment, block)",
                                    (sid,)).fetchone()
                blocks, records = blocks + int(b), records + int(r)
    lsl_streams, lsl_chunks = _lsl_counts(conn, [sid for sid, _, _ in sessions])
    return Footprint(code, pid, sessions, int(trials), int(events), int(segments), blocks, records, int(samples),
                     lsl_streams, lsl_chunks)


def _lsl_counts(conn: sqlite3.Connection, session_ids: list[int]) -> tuple[int, int]:
    """The ``lsl_streams`` and ``lsl_chunks`` rows of these sessions (0 in a file no LSL session wrote to)."""
    counts = []
    for table in ("lsl_streams", "lsl_chunks"):
        n = 0
        if has_table(conn, table):
            for sid in session_ids:
                n += int(conn.execute(f"SELECT COUNT(*) FROM {table} WHERE session_id = ?", (sid,)).fetchone()[0])
        counts.append(n)
    return counts[0], counts[1]


def erase_participant(db: StudyDatabase, code: str, reason: str) -> Withdrawal:
    """Remove every row of participant ``code`` in one transaction, its bytes overwritten, and record the withdrawal.

    The caller holds the study's lease.  Nothing is removed when anything is refused.

    Raises
    ------
    StorageError
        No such participant, the participant already withdrew, or a live process writes one of their sessions.
    """
    c = db.conn
    c.execute("PRAGMA secure_delete = ON")  # deleted cells and freed pages are overwritten with zeros
    with db.transaction():
        done = withdrawal_of(c, code)
        if done is not None:
            raise StorageError(f"participant {code} already withdrew from {db.path} ({done.withdrawn_at[:16]} UTC); "
                               "nothing to remove")
        fp = footprint(c, code)
        if fp is None:
            raise StorageError(f"participant {code}: no such participant in {db.path}; nothing was changed")
        writing = db.sessions_being_written()
        for sid, _, _ in fp.sessions:
            if sid in writing:
                raise StorageError(f"participant {code}'s session {sid} is running (being written by "
                                   f"{writing[sid]}); withdraw once it has ended; nothing was changed")
        for sid, _, _ in fp.sessions:
            c.execute("DELETE FROM samples WHERE trial_id >= ? AND trial_id < ?",
                      (trial_id_of(sid, 0), trial_id_of(sid + 1, 0)))
            for arm in ("", "arm"):  # the task arm's recording, then the other arms'; chunks and blocks first
                for table in reversed(recording_tables(arm)):
                    if has_table(c, table):
                        c.execute(f"DELETE FROM {table} WHERE session_id = ?", (sid,))
            erase_lsl_rows(c, sid)  # the external streams recorded with it, and its runs' clock links
            for table in ("notes", "questionnaire_answers", "trial_answers"):  # (a file made before them has none)
                if has_table(c, table):
                    c.execute(f"DELETE FROM {table} WHERE session_id = ?", (sid,))
            c.execute("DELETE FROM trials WHERE session_id = ?", (sid,))
            c.execute("DELETE FROM events WHERE session_id = ?", (sid,))
            c.execute("DELETE FROM leases WHERE scope = ?", (session_scope(sid),))
            c.execute("DELETE FROM sessions WHERE session_id = ?", (sid,))
        if has_table(c, "covariates"):  # who they are goes with them
            c.execute("DELETE FROM covariates WHERE participant_id = ?", (fp.participant_id,))
        c.execute("DELETE FROM participants WHERE participant_id = ?", (fp.participant_id,))
        record = Withdrawal(code, now_iso(), reason, len(fp.sessions), fp.trials, fp.events, fp.blocks, fp.records,
                            fp.samples, rewritten=0, removed_lsl_streams=fp.lsl_streams,
                            removed_lsl_chunks=fp.lsl_chunks)
        c.execute(f"INSERT INTO withdrawals ({_COLUMNS}) VALUES ({', '.join('?' * len(fields(Withdrawal)))})",
                  astuple(record))
        _scrub_free_pages(c)
    return record


def _scrub_free_pages(c: sqlite3.Connection) -> None:
    """Overwrite every free page of the file with zeros, in the open transaction.

    A writer deletes its own chunks with ``secure_delete = FAST`` (:mod:`protocol.storage.schema`), which leaves
    the freed pages' old bytes -- copies of recorded blocks, possibly this participant's -- until a page is used
    again.  SQLite hands out free pages first, so one zero-filled blob as large as the free list takes every one of
    them and writes zeros over it; dropping it (``secure_delete`` on) frees them again, zeroed, for ``VACUUM`` to
    drop.
    """
    free = int(c.execute("PRAGMA freelist_count").fetchone()[0])
    if free == 0:
        return
    page = int(c.execute("PRAGMA page_size").fetchone()[0])
    c.execute("CREATE TABLE withdrawal_scrub (zeros BLOB)")
    # in blobs of at most _SCRUB_BLOB_BYTES: SQLite refuses a value over 1e9 bytes (its SQLITE_MAX_LENGTH)
    for start in range(0, free * page, _SCRUB_BLOB_BYTES):
        c.execute("INSERT INTO withdrawal_scrub VALUES (zeroblob(?))", (min(_SCRUB_BLOB_BYTES, free * page - start),))
    c.execute("DROP TABLE withdrawal_scrub")


_SCRUB_BLOB_BYTES = 1 << 26  # 64 MiB a row of zeros


#: How long emptying the write-ahead log waits for programs reading the study to finish their read.
CHECKPOINT_WAIT_S = 5.0


def _checkpoint(conn: sqlite3.Connection) -> bool:
    """Copy the whole write-ahead log into the file and empty it; False if a reader kept it from finishing."""
    conn.execute(f"PRAGMA busy_timeout = {int(CHECKPOINT_WAIT_S * 1000)}")  # a reader's snapshot: wait this long
    busy, _, _ = conn.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchone()
    return int(busy) == 0


def _log_holds_pages(path: str) -> bool:
    """The database's write-ahead log is not empty (after a withdrawal: its rewrite was held up by a reader)."""
    try:
        return os.path.getsize(f"{path}-wal") > 0
    except OSError:
        return False


def rewrite_pending(db: StudyDatabase, done: Withdrawal) -> bool:
    """The file still needs the rewrite of the withdrawal ``done``: its record says the rewrite did not finish (a
    reader held it up, or the command was stopped -- killed, a power cut -- between the removal and the rewrite),
    or its write-ahead log holds pages.  Decided by what is in the file, never by clock order.

    A record made before the mark (``rewritten`` None) is judged as then: pending when the file has free pages and
    no session began after the withdrawal (a later session's writes leave free pages of their own).
    """
    if _log_holds_pages(str(db.path)):
        return True
    if done.rewritten is not None:
        return not done.rewritten
    later = db.conn.execute("SELECT COUNT(*) FROM sessions WHERE started_at > ?", (done.withdrawn_at,)).fetchone()[0]
    return int(later) == 0 and int(db.conn.execute("PRAGMA freelist_count").fetchone()[0]) > 0


def nobody_reading(db: StudyDatabase) -> bool:
    """Empty the write-ahead log now: True when it could be (no other program holds a read of the study open).

    Run before :func:`erase_participant`, after something was written (the lease), so that a program reading
    the study (a report, a window) is found before anything is removed rather than after, when it would keep the
    old pages in the file until it closes.  (With an empty log a reader holds nothing up, and is not seen.)
    """
    return _checkpoint(db.conn)


def rewrite_file(db: StudyDatabase) -> bool:
    """After :func:`erase_participant`: the zeroed pages written over the file's own, the file rewritten, the log
    emptied.

    Returns
    -------
    bool
        True when the write-ahead log is empty at the end.  False when another program reading the study kept
        the log from being emptied (it waited the connection's busy timeout): the log may still hold pages
        of what was removed until that reader closes.
    """
    c = db.conn
    first = _checkpoint(c)  # the zeroed pages onto the file's blocks, before VACUUM shrinks the file
    c.execute("VACUUM")  # every page written anew, free pages gone
    last = _checkpoint(c)
    db.quick_check()
    wal = Path(f"{db.path}-wal")
    try:
        empty = not wal.exists() or os.path.getsize(wal) == 0
    except OSError:
        empty = False
    return first and last and empty
