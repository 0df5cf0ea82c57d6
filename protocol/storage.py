"""The study database: SQLite in WAL mode, created from ``data/schema.sql``.

One writer owns the connection (:class:`StudyDatabase`); in a live session it
runs in a :class:`Recorder` thread fed through a queue, so neither the 1 kHz
loop nor the GUI ever waits on the disk.  Sample batches are committed at least
every 100 ms, each trial summary atomically when the trial ends, and nothing is
ever overwritten: a participant code with an experiment session already
stored is refused unless the caller resumes it.  WAL mode lets analysis read
while a session writes.

What protects the record:

* **one writer per session** -- a writer takes a lease (:meth:`StudyDatabase.acquire_lease`,
  the ``leases`` table) on the session, or on the whole study for a headless
  ``run``; a second process is refused with a message naming the holder, and a
  lease left by a killed process is taken over only once that process is gone;
* **no writing into a damaged file** -- ``PRAGMA quick_check`` runs before a
  writer touches the file (and when analysis asks for it); a damaged file is
  refused and left byte-identical;
* **archives stay readable** -- readers open read-only, and a database in a
  folder they cannot write opens immutable (:func:`connect_readonly`);
* **older files** -- a version-1 database is read as it is; a writer upgrades
  it in place only after writing a backup copy beside it;
* **privacy** -- new databases (and so their ``-wal``/``-shm`` files, which
  SQLite creates with the database's permissions) are readable by their owner only.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import queue
import re
import secrets
import socket
import sqlite3
import sys
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from protocol.recording import BlockBuilder

__all__ = [
    "ABORT_CAUSES",
    "CODE_PATTERN",
    "EmptyDatabase",
    "HEALTH_COLUMNS",
    "LeaseHeld",
    "SCHEMA_VERSION",
    "SessionInfo",
    "StorageError",
    "StudyDatabase",
    "Recorder",
    "connect_readonly",
    "new_owner_token",
    "schema_path",
    "session_scope",
    "trial_id_of",
    "validate_code",
]

SCHEMA_VERSION = 3
#: Why an aborted trial was aborted (``trials.abort_cause``, schema version 2).
ABORT_CAUSES = ("experimenter", "fault", "feedback", "gap", "interrupted")
#: Per-trial loop health columns (schema version 2), in table order.
HEALTH_COLUMNS = (
    "period_p50_ms", "period_p99_ms", "period_max_ms", "periods_over_2ms",
    "sensor_age_max_ms", "pose_age_max_ms", "latency_p50_ms", "latency_max_ms",
)
#: What upgrades a version-1 database to version 2 (the same tables as a new one; tested).
_UPGRADE_1_TO_2 = (
    "ALTER TABLE trials ADD COLUMN abort_cause TEXT CHECK (abort_cause IS NULL OR abort_cause IN "
    "('experimenter', 'fault', 'feedback', 'gap', 'interrupted'))",
    *(f"ALTER TABLE trials ADD COLUMN {c} {'INTEGER' if c == 'periods_over_2ms' else 'REAL'}" for c in HEALTH_COLUMNS),
    "CREATE TABLE leases (scope TEXT PRIMARY KEY, owner TEXT NOT NULL, pid INTEGER NOT NULL, host TEXT NOT NULL, "
    "process_start TEXT NOT NULL, command TEXT NOT NULL, acquired_at TEXT NOT NULL, heartbeat_at TEXT NOT NULL)",
)
#: What upgrades a version-2 database to version 3: whole sessions recorded in blocks.
_UPGRADE_2_TO_3 = (
    "ALTER TABLE trials ADD COLUMN segment INTEGER",
    "ALTER TABLE trials ADD COLUMN first_tick INTEGER",
    "ALTER TABLE trials ADD COLUMN last_tick INTEGER",
    "CREATE TABLE recordings (session_id INTEGER NOT NULL REFERENCES sessions(session_id), segment INTEGER NOT NULL, "
    "started_at_s REAL NOT NULL, t0_ns INTEGER NOT NULL, snapshot_json TEXT NOT NULL, scales_json TEXT NOT NULL, "
    "PRIMARY KEY (session_id, segment))",
    "CREATE TABLE session_blocks (session_id INTEGER NOT NULL, segment INTEGER NOT NULL, block INTEGER NOT NULL, "
    "first_tick INTEGER NOT NULL, last_tick INTEGER NOT NULL, n_records INTEGER NOT NULL, t_first_s REAL NOT NULL, "
    "t_last_s REAL NOT NULL, data BLOB NOT NULL, PRIMARY KEY (session_id, segment, block), "
    "FOREIGN KEY (session_id, segment) REFERENCES recordings (session_id, segment))",
)
#: A lease held from another host is stale after this long without a heartbeat.
LEASE_STALE_S = 30.0
#: Writers refresh their leases' heartbeat this often (with a commit).
LEASE_HEARTBEAT_S = 5.0
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


class LeaseHeld(StorageError):
    """Another live process writes to the study or session; the message names it."""


class EmptyDatabase(StorageError):
    """Opened for reading, the file holds no study yet (an empty or brand-new SQLite file)."""


def session_scope(session_id: int) -> str:
    """The lease scope of one session."""
    return f"session {int(session_id)}"


def new_owner_token() -> str:
    """A fresh lease owner token (one per writing command; a study's workers share their command's)."""
    return secrets.token_hex(8)


def _boot_id() -> str:
    try:
        with open("/proc/sys/kernel/random/boot_id", encoding="ascii") as fh:
            return fh.read().strip()
    except OSError:
        return ""


def _proc_stat(pid: int) -> list[str] | None:
    """The fields of ``/proc/<pid>/stat`` after the command name (field 3 first), or None."""
    try:
        with open(f"/proc/{int(pid)}/stat", encoding="ascii", errors="replace") as fh:
            stat = fh.read()
    except (OSError, ValueError, OverflowError):
        return None
    # the command name (field 2) may hold spaces and parentheses: count fields after the last ')'
    return stat[stat.rindex(")") + 2 :].split()


def process_identity(pid: int) -> str:
    """Boot id and start time of a process: equal for the same process, different for a reused pid.

    Empty where ``/proc`` cannot tell (not Linux); the caller then falls back on heartbeats.
    """
    fields = _proc_stat(pid)
    return "" if fields is None else f"{_boot_id()}:{fields[19]}"


def _pid_alive(pid: int) -> bool:
    fields = _proc_stat(pid)
    if fields is not None:
        # a zombie (killed, not yet reaped -- an orphan whose reaper is slow) writes nothing any more
        return fields[0] not in ("Z", "X")
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # it exists, owned by someone else
        return True
    except (OverflowError, ValueError):
        return False
    return True


_SQLITE_MAGIC = b"SQLite format 3\x00"


def _check_sqlite_header(p: Path) -> None:
    """Refuse a non-empty file that is not SQLite at all (before SQLite touches it)."""
    try:
        with open(p, "rb") as fh:
            head = fh.read(len(_SQLITE_MAGIC))
    except OSError as exc:
        raise StorageError(f"{p}: cannot read the database ({exc.strerror})") from None
    if head and head != _SQLITE_MAGIC:
        raise StorageError(f"{p}: not a haptic-study database (not an SQLite file)")


def connect_readonly(path: str | os.PathLike[str], *, timeout_s: float = 5.0) -> sqlite3.Connection:
    """A read-only connection that never creates, migrates or locks the database for writing.

    An archived database -- a read-only file in a folder this user cannot
    write -- cannot be opened read-only in WAL mode (SQLite needs to create the
    ``-shm`` index beside it); it is opened *immutable* instead, which is
    exact as long as nobody writes to it, and nobody can.

    Raises
    ------
    StorageError
        No such file, or it cannot be opened.
    """
    p = Path(path)
    if not p.exists():
        raise StorageError(f"{p}: no such database")
    if p.is_dir():
        raise StorageError(f"{p}: is a directory, not a database file")
    uri = p.resolve().as_uri()
    try:
        conn = sqlite3.connect(f"{uri}?mode=ro", uri=True, check_same_thread=False, timeout=timeout_s)
        try:
            conn.execute("PRAGMA user_version").fetchone()
            return conn
        except sqlite3.OperationalError:
            conn.close()
            folder = p.resolve().parent
            wal = p.with_name(p.name + "-wal")
            if os.access(folder, os.W_OK):
                raise
            if wal.exists() and wal.stat().st_size > 0:
                raise StorageError(
                    f"{p}: cannot be read where it is: its last changes are still in {wal.name}, which SQLite can "
                    f"read only with a writable folder and {folder} is read-only; copy the database and its "
                    f"{wal.name} into a writable folder and read the copy") from None
        except sqlite3.DatabaseError:
            conn.close()
            raise
        # an archive (nobody can write here): immutable needs no -shm and takes no lock
        conn = sqlite3.connect(f"{uri}?immutable=1", uri=True, check_same_thread=False, timeout=timeout_s)
        try:
            conn.execute("PRAGMA user_version").fetchone()
        except sqlite3.DatabaseError:
            conn.close()
            raise
        return conn
    except sqlite3.OperationalError as exc:
        raise StorageError(f"{p}: cannot open the database ({exc})") from None
    except sqlite3.DatabaseError as exc:
        raise StorageError(f"{p}: not a haptic-study database ({exc})") from None


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


def _command_line() -> str:
    """This process's command, shortened (``haptic-study run --resume P01 ...``)."""
    args = [os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else "python", *sys.argv[1:]]
    text = " ".join(args)
    return text if len(text) <= 120 else text[:117] + "..."


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
        Database file; created (with the schema, readable by its owner only) if it does not exist.
    readonly
        Open for reading only (analysis); never creates, upgrades or locks for writing.
    busy_timeout_s
        How long a statement waits for another connection's write lock before
        failing with "database is locked".  Several writers share one database
        when a study runs participants in parallel processes
        (:func:`study_app.headless.run_study` with ``jobs > 1``); each holds the
        lock only for one short commit, but a commit that also checkpoints a
        large WAL on a slow disk can take seconds, so writers wait up to 30 s
        (sqlite3's default, 5 s, could turn a slow disk into a failed study).
    check
        Run ``PRAGMA quick_check`` before anything else (default: for writers;
        readers ask for it where a whole study is read).  A damaged file is
        refused with one line and left byte-identical.
    upgrade
        A writer that opens a version-1 database upgrades it to the current
        schema after writing a backup copy beside it (``<name>.v1-backup-<time><suffix>``);
        False refuses instead.  Readers never upgrade.

    Attributes
    ----------
    upgraded_from
        The schema version the file had before this writer upgraded it (None if it did not).
    backup_path
        The backup written before the upgrade.
    """

    #: Writers' default busy timeout (see ``busy_timeout_s``).
    WRITER_BUSY_TIMEOUT_S = 30.0

    def __init__(
        self, path: str | os.PathLike[str], *, readonly: bool = False, busy_timeout_s: float | None = None,
        check: bool | None = None, upgrade: bool = True,
    ) -> None:
        self.path = Path(path)
        self.readonly = readonly
        self.upgraded_from: int | None = None
        self.backup_path: Path | None = None
        self._last_heartbeat = 0.0
        self._owners: set[str] = set()
        created = self._check_path(readonly)
        if readonly:
            self.conn = connect_readonly(self.path, timeout_s=5.0 if busy_timeout_s is None else busy_timeout_s)
        else:
            try:
                self.conn = sqlite3.connect(
                    str(self.path), check_same_thread=False, isolation_level=None,
                    timeout=self.WRITER_BUSY_TIMEOUT_S if busy_timeout_s is None else busy_timeout_s,
                )
            except sqlite3.Error as exc:
                raise StorageError(f"{self.path}: cannot open the database ({exc})") from None
        try:
            if (not readonly if check is None else check) and not created:
                self._quick_check()
            self._prepare(readonly, upgrade)
        except sqlite3.DatabaseError as exc:
            self.conn.close()
            raise StorageError(f"{self.path}: not a haptic-study database ({exc})") from None
        except StorageError:
            self.conn.close()
            raise

    # -- opening ------------------------------------------------------------------------------------
    def _check_path(self, readonly: bool) -> bool:
        """Refuse what cannot be opened as asked; create a new file owner-only.  True if it was created."""
        p = self.path
        if p.exists() and p.is_dir():
            raise StorageError(f"{p}: is a directory, not a database file")
        if readonly:
            if not p.exists():
                raise StorageError(f"{p}: no such database")
            _check_sqlite_header(p)
            return False
        parent = p.parent if str(p.parent) else Path(".")
        if not parent.exists():
            raise StorageError(f"{p}: the folder {parent} does not exist")
        if p.exists():
            _check_sqlite_header(p)
            if not os.access(p, os.W_OK):
                raise StorageError(f"{p}: the database is not writable (open it read-only, e.g. with report)")
            if not os.access(parent, os.W_OK):
                raise StorageError(f"{p}: the folder {parent} is not writable (SQLite writes its journal beside the database)")
            return False
        if not os.access(parent, os.W_OK):
            raise StorageError(f"{p}: cannot create the database here (folder {parent} is not writable)")
        try:
            # owner-only from the first byte: SQLite gives the -wal and -shm files the database's permissions
            os.close(os.open(p, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        except FileExistsError:  # another process created it meanwhile: open it as it is
            return False
        except OSError as exc:
            raise StorageError(f"{p}: cannot create the database ({exc.strerror})") from None
        return True

    def _quick_check(self) -> None:
        try:
            rows = self.conn.execute("PRAGMA quick_check(5)").fetchall()
        except sqlite3.DatabaseError as exc:
            raise StorageError(f"{self.path}: the database is damaged ({exc}); nothing was written to it "
                               "(restore it from a backup)") from None
        problems = [" ".join(str(r[0]).split()) for r in rows if r[0] != "ok"]  # SQLite's report spans lines
        if problems:
            raise StorageError(f"{self.path}: the database is damaged (integrity check: {problems[0]}); "
                               "nothing was written to it (restore it from a backup)")

    def quick_check(self) -> None:
        """``PRAGMA quick_check``; raises :class:`StorageError` with the first problem found."""
        self._quick_check()

    def _prepare(self, readonly: bool, upgrade: bool) -> None:
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
                raise EmptyDatabase(f"{self.path}: empty database (no study data)")
            script = schema_path().read_text(encoding="utf-8")
            c.execute("PRAGMA journal_mode = WAL")
            c.executescript("BEGIN IMMEDIATE;\n" + script + f"\nPRAGMA user_version = {SCHEMA_VERSION};\nCOMMIT;")
            self._owner_only()
        elif not {"participants", "sessions", "trials", "samples", "events"} <= tables:
            raise StorageError(f"{self.path}: not a haptic-study database (tables missing)")
        elif version < SCHEMA_VERSION and not readonly:
            if not upgrade:
                raise StorageError(f"{self.path}: database schema version {version} must be upgraded to "
                                   f"{SCHEMA_VERSION} before it is written to; nothing was changed")
            self._upgrade(version)
        if not readonly:
            c.execute("PRAGMA journal_mode = WAL")
            # NORMAL in WAL mode: a committed transaction survives a process
            # crash (SIGKILL); only a power cut can lose the last commits.
            c.execute("PRAGMA synchronous = NORMAL")
            c.execute("PRAGMA foreign_keys = ON")

    def _owner_only(self) -> None:
        """A study was just created in this file (new, or empty before): readable by its owner only."""
        try:
            if self.path.stat().st_uid == os.getuid():
                os.chmod(self.path, 0o600)
        except OSError:  # (not ours to change: leave it)
            pass

    @property
    def schema_version(self) -> int:
        """The file's ``PRAGMA user_version``."""
        return int(self.conn.execute("PRAGMA user_version").fetchone()[0])

    def _backup_to(self, target: Path) -> None:
        """A consistent copy of the whole database in ``target`` (SQLite's online backup)."""
        dst = sqlite3.connect(str(target))
        try:
            self.conn.backup(dst)
        finally:
            dst.close()

    def _upgrade(self, version: int) -> None:
        """Write a backup copy beside the file, then upgrade the schema in one transaction."""
        assert version in (1, 2), version
        stamp = _dt.datetime.now().strftime("%Y%m%dT%H%M%S")
        backup = self.path.with_name(f"{self.path.stem}.v{version}-backup-{stamp}{self.path.suffix or '.db'}")
        n = 1
        while backup.exists():
            n += 1
            backup = self.path.with_name(f"{self.path.stem}.v{version}-backup-{stamp}-{n}{self.path.suffix or '.db'}")
        try:
            os.close(os.open(backup, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
            self._backup_to(backup)
        except (OSError, sqlite3.Error) as exc:
            try:
                backup.unlink()
            except OSError:
                pass
            raise StorageError(f"{self.path}: schema version {version} must be upgraded to {SCHEMA_VERSION}, and the "
                               f"backup copy {backup.name} could not be written ({exc}); nothing was changed") from None
        c = self.conn
        c.execute("BEGIN IMMEDIATE")
        try:
            if c.execute("PRAGMA user_version").fetchone()[0] == version:  # not upgraded by another writer meanwhile
                if version == 1:
                    for stmt in _UPGRADE_1_TO_2:
                        c.execute(stmt)
                    try:
                        # v2 keeps one sample per time and trial; a v1 file that already holds duplicates keeps its index
                        c.execute("SAVEPOINT unique_samples")
                        c.execute("DROP INDEX IF EXISTS samples_by_trial")
                        c.execute("CREATE UNIQUE INDEX samples_by_trial ON samples (trial_id, t_s)")
                        c.execute("RELEASE unique_samples")
                    except sqlite3.IntegrityError:
                        c.execute("ROLLBACK TO unique_samples")
                        c.execute("RELEASE unique_samples")
                for stmt in _UPGRADE_2_TO_3:
                    c.execute(stmt)
                c.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
            c.execute("COMMIT")
        except BaseException:
            c.execute("ROLLBACK")
            raise
        self.upgraded_from, self.backup_path = version, backup

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
        lease_owner: str | None = None, command: str = "", study_owner: str | None = None,
    ) -> int:
        """Insert a session with its whole schedule and provenance, committed before trial 1.

        With ``lease_owner`` the session's lease is taken in the same
        transaction (see :meth:`acquire_lease`), so no other process can write
        to it from its first moment.

        Raises
        ------
        StorageError
            If the participant already has a session of this kind (nothing is overwritten).
        LeaseHeld
            If another live process runs the whole study (a headless ``run``).
        """
        with self.transaction():
            existing = self.sessions_of(code, kind)
            if existing:
                s = existing[-1]
                hint = "resume it with --resume " + code if s.status == "running" else "use a new participant code"
                raise StorageError(
                    f"participant {code} already has a{'n' if kind == 'experiment' else ''} {kind} session "
                    f"(session {s.session_id}, status {s.status}) in {self.path}; {hint}"
                )
            if lease_owner is not None:
                self._refuse_if_study_held(study_owner or lease_owner)
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
            session_id = int(cur.lastrowid)  # type: ignore[arg-type]
            if lease_owner is not None:
                self._write_lease(session_scope(session_id), lease_owner, command)
        return session_id

    # -- leases: one writer per session -------------------------------------------------------------
    def acquire_lease(self, scope: str, owner: str, *, command: str = "", study_owner: str | None = None) -> str:
        """Take the lease on ``scope`` (``"study"`` or :func:`session_scope`) for this process.

        Parameters
        ----------
        scope
            What to own.
        owner
            The caller's token (:func:`new_owner_token`).  A lease already held
            under this token by a live process of this command is shared, not refused.
        command
            What the caller is, for other processes' refusal messages.
        study_owner
            The token of the study lease the caller works under (a parallel
            ``run``'s workers), if any: a study lease under it is not a conflict.

        Returns
        -------
        str
            "" or, when a lease left by a process that is gone was taken over, a
            sentence saying so (worth storing as an event).

        Raises
        ------
        LeaseHeld
            Another live process holds the scope (or, for a session, the whole
            study; for the study, any session); the message names it.
        """
        with self.transaction():
            note = ""
            if scope == "study":
                for row in self._leases():
                    if row["owner"] != owner and self._alive(row):
                        what = "the study in" if row["scope"] == "study" else f"{row['scope']} of"
                        raise LeaseHeld(self._held_message(row, what))
            else:
                self._refuse_if_study_held(study_owner or owner)
            row = self._lease(scope)
            if row is not None and row["owner"] != owner:
                if self._alive(row):
                    raise LeaseHeld(self._held_message(row, f"{scope} of"))
                note = (f"took over the lease on {scope} left by process {row['pid']} on {row['host']} "
                        f"({row['command'] or 'unknown command'}), which is no longer running")
            for other in self._leases():  # leases of processes that are gone protect nothing: clear them
                if other["scope"] != scope and not self._alive(other):
                    self.conn.execute("DELETE FROM leases WHERE scope = ? AND owner = ?", (other["scope"], other["owner"]))
            self._write_lease(scope, owner, command)
        return note

    def release_lease(self, scope: str, owner: str) -> None:
        """Give a lease back (only the owner's own; a lease taken over meanwhile is left alone)."""
        with self.transaction():
            self.conn.execute("DELETE FROM leases WHERE scope = ? AND owner = ? AND pid = ?", (scope, owner, os.getpid()))

    def heartbeat(self, *, force: bool = False) -> None:
        """Refresh this process's leases (at most every ``LEASE_HEARTBEAT_S``) in the open transaction, if any."""
        now = time.monotonic()
        if not self._owners or (not force and now - self._last_heartbeat < LEASE_HEARTBEAT_S):
            return
        self._last_heartbeat = now
        self.conn.execute("UPDATE leases SET heartbeat_at = ? WHERE pid = ? AND host = ?",
                          (_now_iso(), os.getpid(), socket.gethostname()))

    def lease_holders(self) -> list[dict[str, Any]]:
        """Every stored lease with ``alive`` (for displays and tests)."""
        return [{**row, "alive": self._alive(row)} for row in self._leases()]

    def sessions_being_written(self) -> dict[int, str]:
        """Sessions a live process writes to right now: session id -> "process N (command)" ({} before version 2)."""
        if self.schema_version < 2:
            return {}
        out = {}
        for row in self.lease_holders():
            if row["alive"] and str(row["scope"]).startswith("session "):
                out[int(str(row["scope"]).split()[1])] = f"process {row['pid']} ({row['command']})"
        return out

    def _leases(self) -> list[dict[str, Any]]:
        cur = self.conn.execute("SELECT scope, owner, pid, host, process_start, command, acquired_at, heartbeat_at FROM leases")
        names = [d[0] for d in cur.description]
        return [dict(zip(names, r)) for r in cur]

    def _lease(self, scope: str) -> dict[str, Any] | None:
        return next((r for r in self._leases() if r["scope"] == scope), None)

    def _refuse_if_study_held(self, my_study_owner: str) -> None:
        row = self._lease("study")
        if row is not None and row["owner"] != my_study_owner and self._alive(row):
            raise LeaseHeld(self._held_message(row, "the study in"))

    def _write_lease(self, scope: str, owner: str, command: str) -> None:
        now = _now_iso()
        pid = os.getpid()
        self.conn.execute(
            "INSERT OR REPLACE INTO leases (scope, owner, pid, host, process_start, command, acquired_at, heartbeat_at) "
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
            (scope, owner, pid, socket.gethostname(), process_identity(pid), command or _command_line(), now, now),
        )
        self._owners.add(owner)

    @staticmethod
    def _alive(row: dict[str, Any]) -> bool:
        """Is the lease's process still running? Same host: the pid runs the very process; else a fresh heartbeat."""
        if row["host"] == socket.gethostname():
            if not _pid_alive(row["pid"]):
                return False
            ident = process_identity(row["pid"])
            return not (ident and row["process_start"] and ident != row["process_start"])
        try:
            beat = _dt.datetime.fromisoformat(row["heartbeat_at"])
        except (TypeError, ValueError):
            return False
        return (_dt.datetime.now(_dt.timezone.utc) - beat).total_seconds() < LEASE_STALE_S

    def _held_message(self, row: dict[str, Any], what: str) -> str:
        where = "" if row["host"] == socket.gethostname() else f" on {row['host']}"
        return (f"{self.path}: {what} this database is being written by process {row['pid']}{where} "
                f"({row['command']}, since {str(row['acquired_at'])[:19].replace('T', ' ')} UTC); nothing was changed "
                "(wait for it to finish, or stop it)")

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

    def insert_recording(self, session_id: int, segment: int, started_at_s: float, t0_ns: int,
                         snapshot: dict[str, Any], scales: dict[str, float]) -> None:
        """Open a segment of a session's recording (version 3): where it starts, and the framework's state then."""
        self.conn.execute(
            "INSERT INTO recordings (session_id, segment, started_at_s, t0_ns, snapshot_json, scales_json) "
            "VALUES (?, ?, ?, ?, ?, ?)",
            (session_id, segment, started_at_s, int(t0_ns), json.dumps(snapshot), json.dumps(scales)),
        )

    def write_block(self, session_id: int, segment: int, block: int, first_tick: int, last_tick: int,
                    n_records: int, t_first_s: float, t_last_s: float, data: bytes) -> None:
        """Write a recorded block, or rewrite the segment's open block as it grew (the recorder's own row)."""
        self.conn.execute(
            "INSERT OR REPLACE INTO session_blocks (session_id, segment, block, first_tick, last_tick, n_records, "
            "t_first_s, t_last_s, data) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (session_id, segment, block, int(first_tick), int(last_tick), int(n_records), t_first_s, t_last_s, data),
        )

    def next_segment(self, session_id: int) -> int:
        """The number the next run of a session records under (0 for its first)."""
        r = self.conn.execute("SELECT MAX(segment) FROM recordings WHERE session_id = ?", (session_id,)).fetchone()
        return 0 if r is None or r[0] is None else int(r[0]) + 1

    def insert_event(self, session_id: int, t_s: float, kind: str, detail: str = "") -> None:
        """Record a phase change or an experimenter action."""
        self.conn.execute("INSERT INTO events (session_id, t_s, kind, detail) VALUES (?, ?, ?, ?)", (session_id, t_s, kind, detail))

    def trial_rows(self, session_id: int) -> list[dict[str, Any]]:
        """The trials of a session as dicts, in index order."""
        cur = self.conn.execute("SELECT * FROM trials WHERE session_id = ? ORDER BY trial_index", (session_id,))
        names = [d[0] for d in cur.description]
        return [dict(zip(names, r)) for r in cur]

    def last_session_time_s(self, session_id: int) -> float:
        """Latest session-clock time recorded (events, trials, recorded records), for resuming the clock."""
        blocks = ("UNION ALL SELECT MAX(t_last_s) FROM session_blocks WHERE session_id = ?"
                  if self.schema_version >= 3 else "")
        args = (session_id,) * (3 if blocks else 2)
        r = self.conn.execute(
            "SELECT MAX(t) FROM (SELECT MAX(t_s) AS t FROM events WHERE session_id = ? "
            f"UNION ALL SELECT MAX(ended_at_s) FROM trials WHERE session_id = ? {blocks})", args,
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
        #: The open block of every segment being recorded: (session, segment) -> (builder, started_at_s, t0_ns).
        self._blocks: dict[tuple[int, int], tuple[BlockBuilder, float, int]] = {}
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

    def segment(self, session_id: int, segment: int, started_at_s: float, t0_ns: int, snapshot: dict[str, Any],
                scales: dict[str, float]) -> None:
        """Open a segment of the session's recording (committed at once, before any of its blocks)."""
        self._put(("segment", (session_id, segment, started_at_s, t0_ns, snapshot, scales)))

    def records(self, session_id: int, segment: int, columns: dict[str, np.ndarray],
                log: Sequence[tuple[int, str, Any]] = ()) -> None:
        """Queue records of a segment (:func:`protocol.recording.rows_to_columns`) and the replay log of their ticks.

        They are cut into blocks as they fill; the open block is written as it stands at every commit.
        """
        self._put(("records", (session_id, segment, columns, list(log))))

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
        elif kind == "records":
            sid, seg, columns, log = payload
            builder, _, _ = self._blocks[(sid, seg)]
            builder.add(columns, log)
            for block in builder.take_full():
                self._write_block(sid, seg, block)
        elif kind == "segment":
            sid, seg, started_at_s, t0_ns, snapshot, scales = payload
            db.insert_recording(sid, seg, started_at_s, t0_ns, snapshot, scales)
            self._blocks[(sid, seg)] = (BlockBuilder(scales=scales), started_at_s, t0_ns)
            self._commit()
        elif kind == "trial":
            db.insert_trial(payload)
            self._commit()
        elif kind == "call":
            payload(db)
            self._commit()

    def _write_block(self, session_id: int, segment: int, block: tuple[int, int, dict[str, np.ndarray], bytes]) -> None:
        _, started_at_s, t0_ns = self._blocks[(session_id, segment)]
        number, _, cols, data = block
        ticks, t_ns = cols["tick"], cols["t_ns"]
        self.db.write_block(session_id, segment, number, int(ticks[0]), int(ticks[-1]), len(ticks),
                            started_at_s + (int(t_ns[0]) - t0_ns) / 1e9, started_at_s + (int(t_ns[-1]) - t0_ns) / 1e9,
                            data)

    def _commit(self, final: bool = False) -> None:
        if self._held:
            held, self._held = self._held, []
            try:
                for item in held:
                    self._apply(item)  # a trial or call item commits everything before it, itself included
            except BaseException:
                if self.db.conn.in_transaction:
                    self.db.conn.execute("ROLLBACK")
                raise
        for (sid, seg), (builder, _, _) in self._blocks.items():
            # the records since the last commit reach the disk with it; at the end, the open block whole
            open_block = builder.final() if final else builder.partial()
            if open_block is not None:
                self.db.begin()
                self._write_block(sid, seg, open_block)
        if self.db.conn.in_transaction:
            self.db.heartbeat()  # with data anyway: a live writer's leases stay fresh for other hosts
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
            self._commit(final=True)
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
            self._commit(final=True)
        if self.error is not None:
            raise StorageError(f"the recorder failed: {self.error}")
