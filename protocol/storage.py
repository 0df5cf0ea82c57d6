"""The study database: SQLite in WAL mode, created from ``data/schema.sql``.

One writer owns the connection (:class:`StudyDatabase`); in a live session it
runs in a :class:`Recorder` thread fed through a queue, so neither the 1 kHz
loop nor the GUI ever waits on the disk.  Sample batches are committed at least
every 100 ms, each trial summary atomically when the trial ends, and nothing is
ever overwritten: a participant code with an experiment session already
stored is refused unless the caller resumes it.  WAL mode lets analysis read
while a session writes.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import queue
import re
import sqlite3
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "CODE_PATTERN",
    "SCHEMA_VERSION",
    "SessionInfo",
    "StorageError",
    "StudyDatabase",
    "Recorder",
    "schema_path",
    "trial_id_of",
    "validate_code",
]

SCHEMA_VERSION = 1
CODE_PATTERN = re.compile(r"^[A-Za-z0-9_-]{1,32}\Z")  # \Z, not $: "$" also matches before a final newline
SAMPLE_COLUMNS = (
    "trial_id", "t_s", "force_n",
    "raw_fx", "raw_fy", "raw_fz", "raw_tx", "raw_ty", "raw_tz",
    "comp_fx", "comp_fy", "comp_fz",
    "render_fx", "render_fy", "render_fz",
)
_INSERT_SAMPLES = f"INSERT INTO samples ({', '.join(SAMPLE_COLUMNS)}) VALUES ({', '.join('?' * len(SAMPLE_COLUMNS))})"


class StorageError(Exception):
    """The database cannot be used as asked; the message says why and what to do."""


def schema_path() -> Path:
    """Location of ``data/schema.sql`` in the source tree."""
    return Path(__file__).resolve().parent.parent / "data" / "schema.sql"


def trial_id_of(session_id: int, trial_index: int) -> int:
    """The trial key used by ``trials`` and ``samples`` (allocated at trial start)."""
    return session_id * 1_000_000 + trial_index


def validate_code(code: str) -> str:
    """Check a participant code: 1–32 of ``A–Z a–z 0–9 _ -`` (pseudonymous, no personal data)."""
    if not isinstance(code, str) or not CODE_PATTERN.match(code):
        raise StorageError(f"participant code = {code!r}: must be 1–32 characters from A–Z, a–z, 0–9, '_' and '-'")
    return code


def _now_iso() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds")


@dataclass(frozen=True, slots=True)
class SessionInfo:
    """A stored session (what a resume needs)."""

    session_id: int
    participant_id: int
    code: str
    kind: str
    seed: int
    participant_number: int
    protocol_json: str
    schedule_json: str
    status: str
    started_at: str
    calibration_json: str | None
    config_json: str


class StudyDatabase:
    """The single writer of a study database.

    Parameters
    ----------
    path
        Database file; created (with the schema) if it does not exist.
    readonly
        Open for reading only (analysis); never creates or migrates.
    busy_timeout_s
        How long a statement waits for another connection's write lock before
        failing with "database is locked".  Several writers share one database
        when a study runs participants in parallel processes
        (:func:`protocol.study.run_study` with ``jobs > 1``); each holds the
        lock only for one short commit, but a commit that also checkpoints a
        large WAL on a slow disk can take seconds, so writers wait up to 30 s
        (sqlite3's default, 5 s, could turn a slow disk into a failed study).
    """

    #: Writers' default busy timeout (see ``busy_timeout_s``).
    WRITER_BUSY_TIMEOUT_S = 30.0

    def __init__(
        self, path: str | os.PathLike[str], *, readonly: bool = False, busy_timeout_s: float | None = None,
    ) -> None:
        self.path = Path(path)
        self._check_path(readonly)
        try:
            if readonly:
                self.conn = sqlite3.connect(f"file:{self.path}?mode=ro", uri=True, check_same_thread=False,
                                            timeout=5.0 if busy_timeout_s is None else busy_timeout_s)
            else:
                self.conn = sqlite3.connect(
                    str(self.path), check_same_thread=False, isolation_level=None,
                    timeout=self.WRITER_BUSY_TIMEOUT_S if busy_timeout_s is None else busy_timeout_s,
                )
        except sqlite3.Error as exc:
            raise StorageError(f"{self.path}: cannot open the database ({exc})") from None
        try:
            self._prepare(readonly)
        except sqlite3.DatabaseError as exc:
            self.conn.close()
            raise StorageError(f"{self.path}: not a haptic-study database ({exc})") from None
        except StorageError:
            self.conn.close()
            raise

    # -- opening ------------------------------------------------------------------------------------
    def _check_path(self, readonly: bool) -> None:
        p = self.path
        if p.exists() and p.is_dir():
            raise StorageError(f"{p}: is a directory, not a database file")
        if readonly:
            if not p.exists():
                raise StorageError(f"{p}: no such database")
            return
        parent = p.parent if str(p.parent) else Path(".")
        if not parent.exists():
            raise StorageError(f"{p}: the folder {parent} does not exist")
        if p.exists():
            if not os.access(p, os.W_OK):
                raise StorageError(f"{p}: the database is not writable")
        elif not os.access(parent, os.W_OK):
            raise StorageError(f"{p}: cannot create the database here (folder {parent} is not writable)")

    def _prepare(self, readonly: bool) -> None:
        c = self.conn
        version = c.execute("PRAGMA user_version").fetchone()[0]
        tables = {r[0] for r in c.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        if version > SCHEMA_VERSION:
            raise StorageError(
                f"{self.path}: database schema version {version} is newer than this software supports "
                f"({SCHEMA_VERSION}); update haptic-study to open it"
            )
        if version == 0:
            if tables:
                raise StorageError(f"{self.path}: not a haptic-study database (it has other tables: {', '.join(sorted(tables))})")
            if readonly:
                raise StorageError(f"{self.path}: empty database (no study data)")
            script = schema_path().read_text(encoding="utf-8")
            c.execute("PRAGMA journal_mode = WAL")
            c.executescript("BEGIN;\n" + script + f"\nPRAGMA user_version = {SCHEMA_VERSION};\nCOMMIT;")
        elif not {"participants", "sessions", "trials", "samples", "events"} <= tables:
            raise StorageError(f"{self.path}: not a haptic-study database (tables missing)")
        if not readonly:
            c.execute("PRAGMA journal_mode = WAL")
            # NORMAL in WAL mode: a committed transaction survives a process
            # crash (SIGKILL); only a power cut can lose the last commits.
            c.execute("PRAGMA synchronous = NORMAL")
            c.execute("PRAGMA foreign_keys = ON")

    def close(self) -> None:
        """Close the connection."""
        self.conn.close()

    # -- participants and sessions ------------------------------------------------------------------
    def participant_id(self, code: str, *, create: bool) -> int | None:
        """The id of a participant code, optionally creating it."""
        validate_code(code)
        row = self.conn.execute("SELECT participant_id FROM participants WHERE code = ?", (code,)).fetchone()
        if row is not None:
            return int(row[0])
        if not create:
            return None
        cur = self.conn.execute("INSERT INTO participants (code, created_at) VALUES (?, ?)", (code, _now_iso()))
        return int(cur.lastrowid)  # type: ignore[arg-type]

    def sessions_of(self, code: str, kind: str | None = None) -> list[SessionInfo]:
        """Stored sessions of a participant, oldest first."""
        sql = (
            "SELECT s.session_id, s.participant_id, p.code, s.kind, s.seed, s.participant_number, s.protocol_json, "
            "s.schedule_json, s.status, s.started_at, s.calibration_json, s.config_json "
            "FROM sessions s JOIN participants p USING (participant_id) WHERE p.code = ?"
        )
        args: list[Any] = [code]
        if kind is not None:
            sql += " AND s.kind = ?"
            args.append(kind)
        return [SessionInfo(*r) for r in self.conn.execute(sql + " ORDER BY s.session_id", args)]

    def open_sessions(self) -> list[SessionInfo]:
        """Sessions that never ended (interrupted): candidates for resume."""
        sql = (
            "SELECT s.session_id, s.participant_id, p.code, s.kind, s.seed, s.participant_number, s.protocol_json, "
            "s.schedule_json, s.status, s.started_at, s.calibration_json, s.config_json "
            "FROM sessions s JOIN participants p USING (participant_id) WHERE s.status = 'running' ORDER BY s.session_id"
        )
        return [SessionInfo(*r) for r in self.conn.execute(sql)]

    def create_session(
        self, *, code: str, kind: str, seed: int, participant_number: int, protocol_json: str, schedule_json: str,
        software_version: str, rig: str, config: dict[str, Any], calibration: dict[str, Any] | None,
    ) -> int:
        """Insert a session with its whole schedule and provenance, committed before trial 1.

        Raises
        ------
        StorageError
            If the participant already has a session of this kind (nothing is overwritten).
        """
        existing = [s for s in self.sessions_of(code, kind)]
        if existing:
            s = existing[-1]
            hint = "resume it with --resume " + code if s.status == "running" else "use a new participant code"
            raise StorageError(
                f"participant {code} already has a{'n' if kind == 'experiment' else ''} {kind} session "
                f"(session {s.session_id}, status {s.status}) in {self.path}; {hint}"
            )
        with self.transaction():
            pid = self.participant_id(code, create=True)
            cur = self.conn.execute(
                "INSERT INTO sessions (participant_id, kind, seed, participant_number, protocol_json, schedule_json, "
                "status, started_at, software_version, rig, config_json, calibration_json) "
                "VALUES (?, ?, ?, ?, ?, ?, 'running', ?, ?, ?, ?, ?)",
                (
                    pid, kind, seed, participant_number, protocol_json, schedule_json, _now_iso(), software_version,
                    rig, json.dumps(config, sort_keys=True), None if calibration is None else json.dumps(calibration),
                ),
            )
        return int(cur.lastrowid)  # type: ignore[arg-type]

    def update_schedule(self, session_id: int, schedule_json: str) -> None:
        """Store the schedule after an aborted trial was re-queued (the only schedule change)."""
        self.conn.execute("UPDATE sessions SET schedule_json = ? WHERE session_id = ?", (schedule_json, session_id))

    def end_session(self, session_id: int, status: str, reason: str = "") -> None:
        """Fill the end columns, once."""
        cur = self.conn.execute(
            "UPDATE sessions SET status = ?, ended_at = ?, end_reason = ? WHERE session_id = ? AND status = 'running'",
            (status, _now_iso(), reason, session_id),
        )
        if cur.rowcount != 1:
            raise StorageError(f"session {session_id} is not running; its end is already recorded")

    # -- trials, samples, events --------------------------------------------------------------------
    def insert_samples(self, rows: Sequence[Sequence[float]] | np.ndarray) -> None:
        """Append sample rows (columns :data:`SAMPLE_COLUMNS`): a sequence of rows or a 2-D float array."""
        if len(rows):
            # sqlite3 binds an array's rows element by element through NumPy scalars, ~4x slower
            # than plain floats; tolist() converts the whole block in C first
            self.conn.executemany(_INSERT_SAMPLES, rows.tolist() if isinstance(rows, np.ndarray) else rows)

    def insert_trial(self, row: dict[str, Any]) -> None:
        """Insert one trial summary (atomic: its own statement in the current transaction)."""
        cols = ", ".join(row)
        self.conn.execute(f"INSERT INTO trials ({cols}) VALUES ({', '.join('?' * len(row))})", tuple(row.values()))

    def insert_event(self, session_id: int, t_s: float, kind: str, detail: str = "") -> None:
        """Record a phase change or an experimenter action."""
        self.conn.execute("INSERT INTO events (session_id, t_s, kind, detail) VALUES (?, ?, ?, ?)", (session_id, t_s, kind, detail))

    def trial_rows(self, session_id: int) -> list[dict[str, Any]]:
        """The trials of a session as dicts, in index order."""
        cur = self.conn.execute("SELECT * FROM trials WHERE session_id = ? ORDER BY trial_index", (session_id,))
        names = [d[0] for d in cur.description]
        return [dict(zip(names, r)) for r in cur]

    def last_session_time_s(self, session_id: int) -> float:
        """Latest session-clock time recorded (events and trials), for resuming the clock."""
        r = self.conn.execute(
            "SELECT MAX(t) FROM (SELECT MAX(t_s) AS t FROM events WHERE session_id = ? "
            "UNION ALL SELECT MAX(ended_at_s) FROM trials WHERE session_id = ?)", (session_id, session_id),
        ).fetchone()
        return float(r[0]) if r and r[0] is not None else 0.0

    # -- transactions -------------------------------------------------------------------------------
    def begin(self) -> None:
        """Start a write transaction if none is open.

        IMMEDIATE takes the write lock at once: a deferred transaction that
        read before writing fails with SQLITE_BUSY, without waiting, if another
        connection committed in between (parallel participants share the file).
        """
        if not self.conn.in_transaction:
            self.conn.execute("BEGIN IMMEDIATE")

    def commit(self) -> None:
        """Commit the open transaction, if any."""
        if self.conn.in_transaction:
            self.conn.execute("COMMIT")

    def transaction(self) -> _Tx:
        """Context manager: commit on success, roll back on error."""
        return _Tx(self)


class _Tx:
    def __init__(self, db: StudyDatabase) -> None:
        self.db = db

    def __enter__(self) -> None:
        self.db.commit()
        self.db.conn.execute("BEGIN IMMEDIATE")  # see StudyDatabase.begin

    def __exit__(self, exc_type: object, *_: object) -> None:
        if exc_type is None:
            self.db.conn.execute("COMMIT")
        else:
            self.db.conn.execute("ROLLBACK")


class Recorder:
    """Queue-fed writer with a commit deadline: samples reach the disk within ``max_latency_s``.

    ``threaded=True`` runs the writer in its own thread (live sessions: the
    producers never wait on the disk); ``threaded=False`` executes each call
    inline (headless runs on the virtual clock, where nothing else is
    waiting) with the same commit rules.  Trial summaries are committed at
    once, together with every sample before them, in one transaction.

    Parameters
    ----------
    db
        The database (the recorder becomes its only writer).
    max_latency_s
        Longest time a queued sample may stay uncommitted (wall clock).
    clock
        Wall-clock source for the commit deadline (injectable for tests).
    short_transactions
        Keep queued writes in memory and execute them in one short
        transaction at each commit, instead of holding a transaction (and the
        database's write lock) open between commits.  For several writer
        processes on one database (parallel participants): a recorder holding
        the lock for ~100 ms at a time would starve the others.  The commit
        rules, and so the crash guarantees, are the same.
    """

    def __init__(
        self, db: StudyDatabase, *, threaded: bool = True, max_latency_s: float = 0.1,
        clock: Callable[[], float] = time.monotonic, short_transactions: bool = False,
    ) -> None:
        self.db = db
        self.short_transactions = short_transactions
        self._held: list[tuple[str, Any]] = []
        self.max_latency_s = max_latency_s
        self._clock = clock
        self._first_pending: float | None = None
        self._q: queue.SimpleQueue[tuple[str, Any] | None] = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None
        if threaded:
            self._thread = threading.Thread(target=self._run, name="recorder", daemon=True)
            self._thread.start()

    # producers ----------------------------------------------------------------------------------
    def samples(self, rows: Sequence[Sequence[float]] | np.ndarray) -> None:
        """Queue sample rows (a sequence of rows or a 2-D float array, not modified afterwards)."""
        self._put(("samples", rows))

    def trial(self, row: dict[str, Any]) -> None:
        """Queue a trial summary (committed at once with the samples before it)."""
        self._put(("trial", row))

    def event(self, session_id: int, t_s: float, kind: str, detail: str = "") -> None:
        """Queue an event."""
        self._put(("event", (session_id, t_s, kind, detail)))

    def call(self, fn: Callable[[StudyDatabase], Any]) -> None:
        """Run ``fn(db)`` in the writer, committed at once (session start/end, schedule updates)."""
        self._put(("call", fn))

    def _put(self, item: tuple[str, Any]) -> None:
        if self.error is not None:
            raise StorageError(f"the recorder stopped after an error: {self.error}")
        if self._thread is None:
            self._handle(item)
            self._maybe_commit()
        else:
            self._q.put(item)

    # writer -------------------------------------------------------------------------------------
    def _handle(self, item: tuple[str, Any]) -> None:
        if self._first_pending is None:
            self._first_pending = self._clock()
        if self.short_transactions:
            self._held.append(item)
            if item[0] in ("trial", "call"):
                self._commit()
            return
        self._apply(item)

    def _apply(self, item: tuple[str, Any]) -> None:
        kind, payload = item
        db = self.db
        db.begin()
        if kind == "samples":
            db.insert_samples(payload)
        elif kind == "event":
            db.insert_event(*payload)
        elif kind == "trial":
            db.insert_trial(payload)
            self._commit()
        elif kind == "call":
            payload(db)
            self._commit()

    def _commit(self) -> None:
        if self._held:
            held, self._held = self._held, []
            try:
                for item in held:
                    self._apply(item)  # a trial or call item commits everything before it, itself included
            except BaseException:
                if self.db.conn.in_transaction:
                    self.db.conn.execute("ROLLBACK")
                raise
        self.db.commit()
        self._first_pending = None

    def _maybe_commit(self) -> None:
        if self._first_pending is not None and self._clock() - self._first_pending >= self.max_latency_s:
            self._commit()

    def _run(self) -> None:
        try:
            while True:
                timeout = None
                if self._first_pending is not None:
                    timeout = max(0.0, self.max_latency_s - (self._clock() - self._first_pending))
                try:
                    item = self._q.get(timeout=timeout)
                except queue.Empty:
                    self._commit()
                    continue
                if item is None:
                    break
                self._handle(item)
                self._maybe_commit()
            self._commit()
        except BaseException as exc:  # noqa: BLE001 - reported to the producer on its next call
            self.error = exc
            try:
                self.db.conn.execute("ROLLBACK") if self.db.conn.in_transaction else None
            except sqlite3.Error:
                pass

    def flush(self) -> None:
        """Commit everything queued so far (blocks until the writer has)."""
        if self._thread is None:
            self._commit()
            return
        done = threading.Event()

        def committed(db: StudyDatabase) -> None:
            db.commit()  # before waking the caller, who may read what it wrote from another connection
            done.set()

        self.call(committed)
        while not done.wait(0.05):
            if self.error is not None or not self._thread.is_alive():
                raise StorageError(f"the recorder stopped: {self.error}")

    def close(self) -> None:
        """Commit what is pending and stop the writer thread."""
        if self._thread is not None:
            self._q.put(None)
            self._thread.join()
            self._thread = None
        else:
            self._commit()
        if self.error is not None:
            raise StorageError(f"the recorder failed: {self.error}")
