"""The single writer of a study database: participants, sessions, trials, events and recorded blocks.

One writer owns the connection (:class:`StudyDatabase`); in a live session it
runs in a :class:`protocol.storage.Recorder` thread.  Nothing is ever
overwritten: a participant code with an experiment session already stored is
refused unless the caller resumes it.
"""

from __future__ import annotations

import json
import os
import sqlite3
import zlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.devices.rig import SINGLE_ARM_NAME
from protocol.metrics import METRICS
from protocol.recording.integrity import WHOLE_BLOCK, place_crc32
from protocol.storage import crashpoint
from protocol.storage.annotations import insert_covariates
from protocol.storage.codes import CODE_PATTERN, stored_clash, validate_code
from protocol.storage.common import StorageError, has_table, now_iso, recording_tables
from protocol.storage.leases import LeaseHolder, session_scope
from protocol.storage.schema import SAMPLE_COLUMNS, SchemaFile, add_metric_columns, connect_readonly
from protocol.storage.withdrawal import withdrawal_of
from protocol.study.covariates import Covariate, CovariateValue

__all__ = ["CODE_PATTERN", "SessionInfo", "StudyDatabase", "validate_code"]

#: The ``trials`` columns that are metrics' (the registry's with a column of their own): a writer adds one a file
#: lacks when a session's trial has it.
_METRIC_COLUMNS = frozenset(m.name for m in METRICS if m.stored)

_INSERT_SAMPLES = f"INSERT INTO samples ({', '.join(SAMPLE_COLUMNS)}) VALUES ({', '.join('?' * len(SAMPLE_COLUMNS))})"


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

    @property
    def arms(self) -> tuple[str, ...]:
        """The rig's arms the session ran on, its task arm (whose records are the session's) first: those a
        session of several arms stores in ``config_json``, else the one arm (:data:`SINGLE_ARM_NAME`)."""
        try:
            config = json.loads(self.config_json)
        except (TypeError, ValueError):
            config = {}
        names = (config.get("arms", {}).get("names")
                 or [a["name"] for a in config.get("hardware", {}).get("arms", [])])
        return tuple(names) if names else (SINGLE_ARM_NAME,)

    @property
    def part(self) -> str:
        """The study part (task block) the session is (:mod:`protocol.study.parts`), "" for a single-task study's."""
        return part_of_protocol(self.protocol_json)

    @property
    def visit(self) -> str:
        """The visit of a schedule the session belongs to (:mod:`protocol.study.visits`), "" in a study without."""
        return part_of_protocol(self.protocol_json, "visit")


def part_of_protocol(protocol_json: str, what: str = "part") -> str:
    """The part name a stored protocol names (its ``part`` table, :mod:`protocol.study.parts`); "" when none.
    ``what = "visit"``: the name of the visit it stores beside the part (``part.visit``)."""
    try:
        part = json.loads(protocol_json).get("part")
    except (TypeError, ValueError, AttributeError):
        return ""
    if what == "visit":
        part = part.get("visit") if isinstance(part, dict) else None
    name = part.get("name") if isinstance(part, dict) else None
    return name if isinstance(name, str) else ""


def part_key(protocol_json: str) -> str:
    """The stored session's part as its report names it: ``VISIT-PART`` in a study with a schedule of visits (a part
    recurs across visits), else the part's name ("" for a single-task study's session)."""
    part, visit = part_of_protocol(protocol_json), part_of_protocol(protocol_json, "visit")
    return f"{visit}-{part}" if visit else part


class StudyDatabase(SchemaFile, LeaseHolder):
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
        self._trial_columns: set[str] = set()  # the trials table's columns, as far as insert_trial has seen them
        # a planned crash (tests): nothing unless HAPTIC_STUDY_CRASH_AT
        crash = None if readonly else crashpoint.planned()
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
            crashpoint.install(self.conn, crash)
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

    def close(self) -> None:
        """Close the connection."""
        self.conn.close()

    def seal(self) -> None:
        """Make the file whole on its own: the WAL checkpointed into it and WAL mode left.

        For a finished file nobody will write again (a power analysis's simulated pool): a reader of a
        file in WAL mode makes ``-wal`` and ``-shm`` files beside it, which stay after it closes; in
        rollback-journal mode a reader leaves nothing.  A writer that opens it later returns it to WAL.
        """
        if self.readonly:
            raise StorageError(f"{self.path}: opened read-only; it cannot be sealed")
        self.conn.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchone()
        self.conn.execute("PRAGMA journal_mode = DELETE").fetchone()

    # -- participants and sessions ------------------------------------------------------------------
    def participant_id(self, code: str, *, create: bool) -> int | None:
        """The id of a participant code, optionally creating it.  A code that reads as another participant's
        without being it (``p01`` beside ``P01``, :mod:`protocol.storage.codes`) is refused naming that one."""
        if code != validate_code(code):
            raise StorageError(f"participant code = {code!r}: give it without surrounding spaces or look-alike "
                               f"characters ({validate_code(code)!r})")
        stored_clash(self.conn, code, str(self.path))
        row = self.conn.execute("SELECT participant_id FROM participants WHERE code = ?", (code,)).fetchone()
        if row is not None:
            return int(row[0])
        if not create:
            return None
        cur = self.conn.execute("INSERT INTO participants (code, created_at) VALUES (?, ?)", (code, now_iso()))
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
            "FROM sessions s JOIN participants p USING (participant_id) WHERE s.status = 'running' "
            "ORDER BY s.session_id"
        )
        return [SessionInfo(*r) for r in self.conn.execute(sql)]

    def create_session(
        self, *, code: str, kind: str, seed: int, participant_number: int, protocol_json: str, schedule_json: str,
        software_version: str, rig: str, config: dict[str, Any], calibration: dict[str, Any] | None,
        lease_owner: str | None = None, command: str = "", study_owner: str | None = None, start_event: str = "",
        rules: Callable[[StudyDatabase], Sequence[tuple[str, str]]] | None = None,
        software_commit: str | None = None, software_dirty: bool | None = None, metric_columns: Sequence[str] = (),
        covariates: Mapping[str, CovariateValue] | None = None, declared: Sequence[Covariate] = (),
    ) -> int:
        """Insert a session with its whole schedule and provenance, committed before trial 1.

        ``metric_columns`` are the stored metrics of its task (:func:`protocol.metrics.stored` of the task's
        metrics): the ``trials`` table gets a column for each it lacks, in the same transaction
        (:func:`protocol.storage.schema.add_metric_columns`).

        ``covariates`` (checked against the protocol's ``declared`` ones) are stored with a participant this
        session registers, in the same transaction; a participant registered before keeps those of their first
        session (:func:`protocol.storage.annotations.insert_covariates`).

        ``software_commit`` and ``software_dirty`` say which code ran it (the git commit of the checkout and
        whether it had uncommitted changes; None when not known, e.g. installed from a wheel).

        With ``lease_owner`` the session's lease is taken in the same
        transaction (see :meth:`acquire_lease`), so no other process can write
        to it from its first moment; with ``start_event`` its ``session_start``
        event (at session time 0) is stored in it too.  ``rules`` (the study's
        rules, :mod:`protocol.runner.study_rules`) is called inside the same
        transaction, before the insert, so no other writer can change what it
        checked: it raises to refuse the session, or returns the events
        ``(kind, detail)`` (a deviation) to store with it at session time 0.

        Raises
        ------
        StorageError
            If the participant already has a session of this kind (nothing is overwritten), or withdrew.
        LeaseHeld
            If another live process runs the whole study (a headless ``run``).
        """
        with self.transaction():
            self._refuse_new_session(code, kind, part_of_protocol(protocol_json),
                                     part_of_protocol(protocol_json, "visit"))
            if lease_owner is not None:
                self._refuse_if_study_held(study_owner or lease_owner)
            extra_events = rules(self) if rules is not None else ()
            add_metric_columns(self.conn, metric_columns)
            known = self.participant_id(code, create=False)
            pid = known if known is not None else self.participant_id(code, create=True)
            assert pid is not None
            insert_covariates(self.conn, pid, code, declared, covariates or {}, new=known is None)
            cur = self.conn.execute(
                "INSERT INTO sessions (participant_id, kind, seed, participant_number, protocol_json, schedule_json, "
                "status, started_at, software_version, rig, config_json, calibration_json, software_commit, "
                "software_dirty) VALUES (?, ?, ?, ?, ?, ?, 'running', ?, ?, ?, ?, ?, ?, ?)",
                (
                    pid, kind, seed, participant_number, protocol_json, schedule_json, now_iso(), software_version,
                    rig, json.dumps(config, sort_keys=True), None if calibration is None else json.dumps(calibration),
                    software_commit, None if software_dirty is None else int(bool(software_dirty)),
                ),
            )
            session_id = int(cur.lastrowid)  # type: ignore[arg-type]
            if lease_owner is not None:
                self._write_lease(session_scope(session_id), lease_owner, command)
            if start_event:
                self.insert_event(session_id, 0.0, "session_start", start_event)
            for event_kind, detail in extra_events:
                self.insert_event(session_id, 0.0, event_kind, detail)
        return session_id

    def _refuse_new_session(self, code: str, kind: str, part: str = "", visit: str = "") -> None:
        """Refuse (one :class:`StorageError` line) a new session of ``kind`` for ``code``: a code that reads as
        another's, a participant who withdrew, or one who has a session of this kind (running, interrupted or ended)
        -- of this ``part`` of a study of several (:attr:`SessionInfo.part`: one session per part), in this
        ``visit`` of a schedule (:attr:`SessionInfo.visit`: one session per visit and part)."""
        stored_clash(self.conn, validate_code(code), str(self.path))  # p01 beside P01 is refused, named
        gone = withdrawal_of(self.conn, code)
        if gone is not None:
            raise StorageError(f"participant {code} withdrew from the study in {self.path} "
                               f"({gone.withdrawn_at[:16].replace('T', ' ')} UTC) and their data were erased; "
                               "a withdrawn code is not used again (give a new participant code)")
        existing = [s for s in self.sessions_of(code, kind) if s.part == part and s.visit == visit]
        if existing:
            s = existing[-1]
            writer = self.sessions_being_written().get(s.session_id) if s.status == "running" else None
            if writer is not None:  # live in another window or process: one writer per session
                hint = f"it is being run right now by {writer}; wait for it to end there"
            elif s.status == "running":
                hint = (f"it was interrupted: resume it (haptic-study run --resume {code}, or Resume selected in "
                        "the GUI)")
            else:
                hint = "use a new participant code"
            raise StorageError(
                f"participant {code} already has a{'n' if kind == 'experiment' else ''} {kind} session "
                f"{f'of part {part!r} ' if part else ''}"
                f"{f'in visit {visit!r} ' if visit else ''}(session {s.session_id}, status {s.status}) in {self.path}; "
                f"{hint}"
            )

    def update_schedule(self, session_id: int, schedule_json: str) -> None:
        """Store the schedule after an aborted trial was re-queued (the only schedule change)."""
        self.conn.execute("UPDATE sessions SET schedule_json = ? WHERE session_id = ?", (schedule_json, session_id))

    def end_session(self, session_id: int, status: str, reason: str = "") -> None:
        """Fill the end columns, once."""
        cur = self.conn.execute(
            "UPDATE sessions SET status = ?, ended_at = ?, end_reason = ? WHERE session_id = ? AND status = 'running'",
            (status, now_iso(), reason, session_id),
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

    def insert_trial(self, row: Mapping[str, Any]) -> None:
        """Insert one ``trials`` row (:meth:`protocol.study.records.TrialRecord.to_row`; atomic: its own statement).

        A metric of the row the file has no column for (a session started before its task's column was added, by an
        older haptic-study) gets its column first (:func:`protocol.storage.schema.add_metric_columns`).
        """
        if any(c not in self._trial_columns for c in row):
            add_metric_columns(self.conn, [c for c in row if c in _METRIC_COLUMNS])
            self._trial_columns = {r[1] for r in self.conn.execute("PRAGMA table_info(trials)")}
        cols = ", ".join(row)
        self.conn.execute(f"INSERT INTO trials ({cols}) VALUES ({', '.join('?' * len(row))})", tuple(row.values()))

    def insert_recording(self, session_id: int, segment: int, started_at_s: float, t0_ns: int,
                         snapshot: dict[str, Any], scales: dict[str, float], arm: str = "") -> None:
        """Open a segment of a session's recording (version 3): where it starts, and the framework's state then
        (``arm``: another arm's than the task arm's, :func:`protocol.storage.common.recording_tables`)."""
        # n_blocks 0: this run counts its blocks and binds each to its place (place_crc32)
        self._insert(recording_tables(arm)[0], arm, "session_id, segment, started_at_s, t0_ns, snapshot_json, "
                     "scales_json, n_blocks", (session_id, segment, started_at_s, int(t0_ns), json.dumps(snapshot),
                                               json.dumps(scales), 0))

    def write_block(self, session_id: int, segment: int, block: int, first_tick: int, last_tick: int,
                    n_records: int, t_first_s: float, t_last_s: float, data: bytes, arm: str = "") -> None:
        """Write a recorded block with its checksum, in place of the chunks it was written in so far (the recorder's
        own rows; :meth:`write_chunk`)."""
        runs, blocks, chunks = recording_tables(arm)
        crc = (place_crc32(data, arm=arm, session_id=session_id, segment=segment, block=block, chunk=WHOLE_BLOCK,
                           first_tick=int(first_tick), last_tick=int(last_tick), n_records=int(n_records))
               if self._binds(session_id, segment, arm) else zlib.crc32(data))
        self._insert(blocks, arm, "session_id, segment, block, first_tick, last_tick, n_records, t_first_s, t_last_s, "
                     "data, crc32", (session_id, segment, block, int(first_tick), int(last_tick), int(n_records),
                                     t_first_s, t_last_s, data, crc), replace=True)
        same = " AND arm = ?" if arm else ""
        place = (session_id, segment, block, *((arm,) if arm else ()))
        self.conn.execute(f"DELETE FROM {chunks} WHERE session_id = ? AND segment = ? AND block = ?{same}", place)
        # the run's count, in the block's transaction: a block deleted later (the last one too) is missing
        self.conn.execute(f"UPDATE {runs} SET n_blocks = MAX(n_blocks, ? + 1) WHERE session_id = ? AND segment = ?"
                          f"{same}", (block, session_id, segment, *((arm,) if arm else ())))

    def write_chunk(self, session_id: int, segment: int, block: int, chunk: int, first_tick: int, last_tick: int,
                    n_records: int, t_first_s: float, t_last_s: float, data: bytes, arm: str = "") -> None:
        """Append what a segment's open block gained since the last commit, with its checksum (until
        :meth:`write_block` replaces the block's chunks)."""
        self._insert(recording_tables(arm)[2], arm, "session_id, segment, block, chunk, first_tick, last_tick, "
                     "n_records, t_first_s, t_last_s, data, crc32",
                     (session_id, segment, block, chunk, int(first_tick), int(last_tick), int(n_records), t_first_s,
                      t_last_s, data, place_crc32(data, arm=arm, session_id=session_id, segment=segment, block=block,
                                                  chunk=chunk, first_tick=int(first_tick), last_tick=int(last_tick),
                                                  n_records=int(n_records))
                      if self._binds(session_id, segment, arm) else zlib.crc32(data)))

    def _binds(self, session_id: int, segment: int, arm: str) -> bool:
        """Whether a run binds its blocks' checksums to their place: it counts its blocks (``n_blocks`` not NULL),
        as every run this writer opens does; a run recorded before keeps checksums of the bytes alone."""
        row = self.conn.execute(f"SELECT n_blocks IS NOT NULL FROM {recording_tables(arm)[0]} WHERE session_id = ? "
                                f"AND segment = ?{' AND arm = ?' if arm else ''}",
                                (session_id, segment, *((arm,) if arm else ()))).fetchone()
        return bool(row and row[0])

    def _insert(self, table: str, arm: str, columns: str, values: tuple[Any, ...], replace: bool = False) -> None:
        """One row of a recording's table (with ``arm`` in another arm's)."""
        if arm:
            columns, values = f"arm, {columns}", (arm, *values)
        verb = "INSERT OR REPLACE" if replace else "INSERT"
        self.conn.execute(f"{verb} INTO {table} ({columns}) VALUES ({', '.join('?' * len(values))})", values)

    def next_segment(self, session_id: int) -> int:
        """The number the next run of a session records under (0 for its first)."""
        r = self.conn.execute("SELECT MAX(segment) FROM recordings WHERE session_id = ?", (session_id,)).fetchone()
        return 0 if r is None or r[0] is None else int(r[0]) + 1

    def insert_event(self, session_id: int, t_s: float, kind: str, detail: str = "") -> None:
        """Record a phase change or an experimenter action."""
        self.conn.execute("INSERT INTO events (session_id, t_s, kind, detail) VALUES (?, ?, ?, ?)",
                          (session_id, t_s, kind, detail))

    def trial_rows(self, session_id: int) -> list[dict[str, Any]]:
        """The trials of a session as dicts, in index order."""
        cur = self.conn.execute("SELECT * FROM trials WHERE session_id = ? ORDER BY trial_index", (session_id,))
        names = [d[0] for d in cur.description]
        return [dict(zip(names, r, strict=True)) for r in cur]

    def last_session_time_s(self, session_id: int) -> float:
        """Latest session-clock time recorded (events, trials, recorded records), for resuming the clock."""
        blocks = "".join(f" UNION ALL SELECT MAX(t_last_s) FROM {t} WHERE session_id = ?"
                         for t in ("session_blocks", "session_chunks") if has_table(self.conn, t))
        args = (session_id,) * (2 + blocks.count("?"))
        r = self.conn.execute(
            "SELECT MAX(t) FROM (SELECT MAX(t_s) AS t FROM events WHERE session_id = ? "
            f"UNION ALL SELECT MAX(ended_at_s) FROM trials WHERE session_id = ?{blocks})", args,
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
