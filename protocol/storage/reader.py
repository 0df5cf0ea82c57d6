"""The one reader of a study database: sessions, participants, trials, events and the recording, read-only.

Every query that reads a study outside the writer's own bookkeeping is here, named for what it returns;
analysis, power, the run summary, replay and the recording's readers (:mod:`protocol.recording`) read
through :class:`StudyReader`, and no module outside ``protocol/storage/`` holds SQL
(``tests/protocol/test_sql_only_in_storage.py``).

A reader opened on a path is read-only as :class:`StudyDatabase` ``(path, readonly=True, check=True)`` is:
the file is checked first (a damaged, foreign or newer file is refused in one line) and left byte-identical.
:meth:`StudyReader.over` reads through a connection already open -- a writer's, inside its transaction (a
resume reads what it continues), or one a caller of :mod:`protocol.recording` holds.
"""

from __future__ import annotations

import heapq
import itertools
import math
import os
import sqlite3
import zlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

from pipeline.devices.rig import SINGLE_ARM_NAME
from protocol.metrics import get
from protocol.recording.codec import BlockRow, join_chunks
from protocol.recording.integrity import block_crc32, place_crc32
from protocol.storage.codes import stored_clash
from protocol.storage.common import has_table, recording_tables
from protocol.storage.database import SessionInfo, StudyDatabase
from protocol.storage.participant_data import ParticipantRows, participant_rows
from protocol.storage.withdrawal import Withdrawal, withdrawal_of, withdrawals
from protocol.study.records import TrialRecord

__all__ = ["Rows", "StudyReader"]

#: Columns of a ``sessions`` row as :class:`SessionInfo` has them.
_SESSION_INFO = (
    "SELECT s.session_id, s.participant_id, p.code, s.kind, s.seed, s.participant_number, s.protocol_json, "
    "s.schedule_json, s.status, s.started_at, s.calibration_json, s.config_json "
    "FROM sessions s JOIN participants p USING (participant_id)"
)


@dataclass(frozen=True, slots=True)
class Rows:
    """A query's result as a table: its column names and its rows, in order.

    What a tidy table is built from (``pandas.DataFrame.from_records(rows.rows, columns=rows.columns)``);
    the protocol floor does not depend on pandas.
    """

    columns: tuple[str, ...]
    rows: list[tuple[Any, ...]]


def _still_open(arm: str) -> str:
    """Chunks whose block has not replaced them (it does so in the same transaction, so never both: a guard)."""
    blocks = recording_tables(arm)[1]
    same_arm = " AND b.arm = c.arm" if arm else ""
    return (f"NOT EXISTS (SELECT 1 FROM {blocks} b WHERE b.session_id = c.session_id AND b.segment = c.segment "
            f"AND b.block = c.block{same_arm})")


def _block_filter(session_id: int | None, segment: int | None, ticks: tuple[int, int] | None,
                  prefix: str = "", arm: str = "") -> tuple[str, list[Any]]:
    """The ``WHERE`` clause (or "") and its arguments that pick blocks or chunks of a session, a segment, a tick
    range (of another arm than the task arm: ``arm``)."""
    where: list[str] = []
    args: list[Any] = []
    if arm:
        where.append(f"{prefix}arm = ?")
        args.append(arm)
    for cond, value in ((f"{prefix}session_id = ?", session_id), (f"{prefix}segment = ?", segment)):
        if value is not None:
            where.append(cond)
            args.append(int(value))
    if ticks is not None:
        where.append(f"{prefix}last_tick >= ? AND {prefix}first_tick <= ?")
        args.extend((int(ticks[0]), int(ticks[1])))
    return ("WHERE " + " AND ".join(where) if where else ""), args


def _in(n: int) -> str:
    """Placeholders of an ``IN (…)`` list of ``n`` values (``NULL`` when there are none: matches nothing)."""
    return ",".join("?" * n) or "NULL"


class StudyReader:
    """Read-only access to a study database; every method returns what its name says.

    Parameters
    ----------
    path
        The study database.  Opened as :class:`StudyDatabase` ``(path, readonly=True, check=check)``: never
        created, upgraded or locked for writing; an archive in a read-only folder opens immutable.
    check
        Run ``PRAGMA quick_check`` first (default): a damaged file is refused with one line.
    busy_timeout_s
        How long a read waits for a writer's lock (default 5 s).

    Raises
    ------
    StorageError
        Not a study database (damaged, foreign, newer schema, empty: :class:`EmptyDatabase`), or no such file.
    """

    def __init__(self, path: str | os.PathLike[str], *, check: bool = True, busy_timeout_s: float | None = None,
                 ) -> None:
        db = StudyDatabase(path, readonly=True, check=check, busy_timeout_s=busy_timeout_s)
        self.path: Path = db.path
        self.conn: sqlite3.Connection = db.conn
        self._db: StudyDatabase | None = db
        self._owned = True

    @classmethod
    def over(cls, source: StudyDatabase | sqlite3.Connection | StudyReader) -> StudyReader:
        """A reader through a connection already open (not closed by :meth:`close`): a writer's, or a caller's."""
        if isinstance(source, StudyReader):
            return source
        reader = cls.__new__(cls)
        if isinstance(source, StudyDatabase):
            reader.path, reader.conn, reader._db = source.path, source.conn, source
        else:
            reader.path, reader.conn, reader._db = Path(""), source, None
        reader._owned = False
        return reader

    def close(self) -> None:
        """Close the connection, if this reader opened it."""
        if self._owned:
            self.conn.close()

    def __enter__(self) -> StudyReader:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def _rows(self, sql: str, args: Sequence[Any] = ()) -> Rows:
        cur = self.conn.execute(sql, tuple(args))
        return Rows(tuple(d[0] for d in cur.description), [tuple(r) for r in cur.fetchall()])

    def _has_columns(self, table: str) -> set[str]:
        return {str(r[1]) for r in self.conn.execute(f"PRAGMA table_info({table})")}

    # -- the file ---------------------------------------------------------------------------------------------
    @property
    def schema_version(self) -> int:
        """The file's schema version (``PRAGMA user_version``)."""
        if self._db is not None:
            return self._db.schema_version
        return int(self.conn.execute("PRAGMA user_version").fetchone()[0])

    def has_recordings(self) -> bool:
        """Whether the file has the recording's tables (schema version 3 and later)."""
        return has_table(self.conn, "session_blocks")

    # -- participants and sessions ------------------------------------------------------------------------------
    def participant_codes(self, limit: int | None = None) -> list[str]:
        """Participant codes stored, in code order (the first ``limit`` of them)."""
        sql = "SELECT code FROM participants ORDER BY code" + ("" if limit is None else " LIMIT ?")
        return [str(r[0]) for r in self.conn.execute(sql, () if limit is None else (int(limit),))]

    def session_ids(self) -> list[int]:
        """Every session's id, in order."""
        return [int(r[0]) for r in self.conn.execute("SELECT session_id FROM sessions ORDER BY session_id")]

    def session_codes(self) -> dict[int, str]:
        """Each session's participant code, by session id."""
        return {int(s): str(c) for s, c in self.conn.execute(
            "SELECT s.session_id, p.code FROM sessions s JOIN participants p USING (participant_id)")}

    def participant_data(self, code: str) -> ParticipantRows | None:
        """Everything stored of one participant, table by table (None when the code is not stored; a code that reads
        as a stored one without being it, ``p01`` for ``P01``, is refused naming it: :mod:`protocol.storage.codes`)."""
        stored_clash(self.conn, code, str(self.path))
        return participant_rows(self.conn, code)

    def withdrawals(self) -> list[Withdrawal]:
        """Every withdrawal recorded in the study, oldest first."""
        return withdrawals(self.conn)

    def withdrawal(self, code: str) -> Withdrawal | None:
        """A participant's withdrawal, or None when they did not withdraw."""
        return withdrawal_of(self.conn, code)

    def sessions(self) -> list[SessionInfo]:
        """Every stored session, oldest first."""
        return [SessionInfo(*r) for r in self.conn.execute(_SESSION_INFO + " ORDER BY s.session_id")]

    def session(self, session_id: int) -> SessionInfo | None:
        """One stored session, or None when there is no such session."""
        row = self.conn.execute(_SESSION_INFO + " WHERE s.session_id = ?", (int(session_id),)).fetchone()
        return None if row is None else SessionInfo(*row)

    def arm_key(self, session_id: int, arm: str | None) -> str:
        """Which recording ``arm`` names in a session: "" for the task arm's (``None``, or its name), else the name
        of another arm whose records are stored (:meth:`arms`).

        Raises
        ------
        KeyError
            One line naming the session's arms, the task arm first.
        """
        info = self.session(session_id)
        task = info.arms[0] if info is not None else SINGLE_ARM_NAME
        if arm is None or arm == task:
            return ""
        others = self.arms(session_id)
        if arm in others:
            return arm
        raise KeyError(f"--arm {arm}: session {session_id} has no recorded arm of that name (its arms: {task}, the "
                       f"task arm{''.join(', ' + a for a in others)})")

    def session_overview(self) -> list[tuple[Any, ...]]:
        """Every session as people ask about it (``haptic-study sessions``), in order: ``session_id, code,
        participant_number, kind, status, rig, seed, started_at, ended_at, end_reason, schedule_json``, then its
        trials counted -- not aborted, aborted, successful -- and its first and last trial index (None: none)."""
        return [tuple(r) for r in self.conn.execute(
            "SELECT s.session_id, p.code, s.participant_number, s.kind, s.status, s.rig, s.seed, s.started_at, "
            "s.ended_at, s.end_reason, s.schedule_json, "
            "(SELECT COUNT(*) FROM trials t WHERE t.session_id = s.session_id AND t.outcome != 'aborted'), "
            "(SELECT COUNT(*) FROM trials t WHERE t.session_id = s.session_id AND t.outcome = 'aborted'), "
            "(SELECT COUNT(*) FROM trials t WHERE t.session_id = s.session_id AND t.outcome = 'success'), "
            "(SELECT MIN(trial_index) FROM trials t WHERE t.session_id = s.session_id), "
            "(SELECT MAX(trial_index) FROM trials t WHERE t.session_id = s.session_id) "
            "FROM sessions s JOIN participants p USING (participant_id) ORDER BY s.session_id")]

    def session_table(self) -> Rows:
        """Every session with its participant code, for the tidy sessions table, in order.

        Columns ``session_id, participant_code, participant_number, kind, status, seed, started_at, ended_at,
        end_reason, software_version, software_commit, software_dirty, rig, protocol_json, config_json,
        schedule_json`` (which code ran it is NULL before schema version 4).
        """
        has = self._has_columns("sessions")
        v4 = ", ".join(f"s.{c}" if c in has else f"NULL AS {c}" for c in ("software_commit", "software_dirty"))
        return self._rows(
            "SELECT s.session_id, p.code AS participant_code, s.participant_number, s.kind, s.status, s.seed, "
            f"s.started_at, s.ended_at, s.end_reason, s.software_version, {v4}, s.rig, s.protocol_json, "
            "s.config_json, s.schedule_json FROM sessions s JOIN participants p USING (participant_id) "
            "ORDER BY s.session_id")

    # -- trials -------------------------------------------------------------------------------------------------
    def trial_table(self, later_columns: Sequence[str], metrics: Sequence[str]) -> Rows:
        """Every stored trial, by session and index, the stored metrics ``metrics`` (the study's:
        :func:`protocol.metrics.stored` of its tasks' metrics) prefixed ``stored_``.

        ``later_columns`` (added by later schema versions: the abort cause, the loop's health, where the
        trial is in the recording) read as NULL where the file lacks them, and so does a metric (defined after the
        file was written).
        """
        has = self._has_columns("trials")
        later = ", ".join(c if c in has else f"NULL AS {c}" for c in later_columns)
        for name in metrics:  # a name goes into SQL text: only the registry's stored metrics
            if not get(name).stored:
                raise ValueError(f"{name}: not a metric with a trials column")
        stored_metrics = "".join(f"{m} AS stored_{m}, " if m in has else f"NULL AS stored_{m}, " for m in metrics)
        return self._rows(
            "SELECT trial_id, session_id, trial_index, target_label, target_force_n, haptic_mode, outcome, "
            f"started_at_s, ended_at_s, {stored_metrics}n_samples, abort_reason, repeat_of, {later} "
            "FROM trials ORDER BY session_id, trial_index")

    def trial_records(self, session_ids: Sequence[int] | None = None) -> list[TrialRecord]:
        """The stored trials (of some sessions, or all) as :class:`TrialRecord` s, by session and index."""
        where = "" if session_ids is None else f" WHERE session_id IN ({_in(len(session_ids))})"
        rows = self._rows(f"SELECT * FROM trials{where} ORDER BY session_id, trial_index",
                          [int(s) for s in session_ids or ()])
        return [TrialRecord.from_row(dict(zip(rows.columns, r, strict=True))) for r in rows.rows]

    def recorded_trial_table(self, session_id: int) -> Rows:
        """A session's recorded trials (those with a place in its recording), by index, for replay's marks."""
        return self._rows(
            "SELECT trial_index, target_label, target_force_n, haptic_mode, outcome, segment, first_tick, last_tick, "
            "started_at_s, ended_at_s, abort_reason FROM trials WHERE session_id = ? AND first_tick IS NOT NULL "
            "ORDER BY trial_index", (int(session_id),))

    def trial_window(self, trial_id: int) -> tuple[Any, Any, Any] | None:
        """Where a trial is in its session's recording: ``(segment, first_tick, last_tick)`` (NULLs when it is not
        recorded), or None when there is no such trial.  Schema version 3 and later."""
        row = self.conn.execute("SELECT segment, first_tick, last_tick FROM trials WHERE trial_id = ?",
                                (int(trial_id),)).fetchone()
        return None if row is None else (row[0], row[1], row[2])

    def trial_cues(self, session_id: int) -> dict[int, tuple[int, float]]:
        """Each recorded trial's cue: ``{trial_index: (first_tick, started_at_s)}``."""
        return {int(i): (int(f), float(c)) for i, f, c in self.conn.execute(
            "SELECT trial_index, first_tick, started_at_s FROM trials WHERE session_id = ? AND first_tick IS NOT NULL",
            (int(session_id),))}

    def trial_ends(self, session_id: int) -> dict[int, tuple[int, int]]:
        """Each recorded trial's end: ``{trial_index: (segment, last_tick)}`` (its last record, the one its metrics
        end on)."""
        if "last_tick" not in self._has_columns("trials"):
            return {}  # a file of schema version 1 or 2: no recording, no ticks
        return {int(i): (int(s), int(t)) for i, s, t in self.conn.execute(
            "SELECT trial_index, segment, last_tick FROM trials WHERE session_id = ? AND last_tick IS NOT NULL",
            (int(session_id),))}

    def trials_touching(self, session_id: int, segment: int, first_tick: int, last_tick: int) -> tuple[int, ...]:
        """Indices of the trials whose records overlap ticks ``first_tick`` … ``last_tick`` of a segment, in order."""
        if "first_tick" not in self._has_columns("trials"):
            return ()
        return tuple(int(i) for (i,) in self.conn.execute(
            "SELECT trial_index FROM trials WHERE session_id = ? AND segment = ? AND first_tick <= ? "
            "AND last_tick >= ? ORDER BY trial_index", (session_id, segment, last_tick, first_tick)))

    def trial_samples(self, trial_id: int, columns: Sequence[str] = ("t_s", "force_n")) -> Rows:
        """A trial's rows of the ``samples`` table (schema versions 1 and 2), in time order."""
        return self._rows(f"SELECT {', '.join(columns)} FROM samples WHERE trial_id = ? ORDER BY t_s",
                          (int(trial_id),))

    def session_samples(self, session_id: int) -> Rows:
        """A session's rows of the ``samples`` table with their trial's index and start, by trial and time."""
        return self._rows(
            "SELECT t.trial_index, t.started_at_s, s.* FROM samples s JOIN trials t USING (trial_id) "
            "WHERE t.session_id = ? ORDER BY t.trial_index, s.t_s", (int(session_id),))

    # -- events -------------------------------------------------------------------------------------------------
    def events(self, kinds: Sequence[str]) -> Rows:
        """Events of some kinds, every session's: ``session_id, t_s, kind, detail``, by session and time."""
        return self._rows(f"SELECT session_id, t_s, kind, detail FROM events WHERE kind IN ({_in(len(kinds))}) "
                          "ORDER BY session_id, t_s", list(kinds))

    def session_events(self, session_id: int, kind: str, details: Sequence[str]) -> list[tuple[float, str]]:
        """A session's events of one kind with one of some details: ``(t_s, detail)``, in time order."""
        return [(float(t), str(d)) for t, d in self.conn.execute(
            f"SELECT t_s, detail FROM events WHERE session_id = ? AND kind = ? AND detail IN ({_in(len(details))}) "
            "ORDER BY t_s", (int(session_id), kind, *details))]

    def trial_start_events(self, session_id: int, names: Sequence[str]) -> list[tuple[str, float]]:
        """When a trial (named any of ``names``) began: its ``phase`` events ``"<name>: cued -> active"`` and its
        ``cue`` events ``"<name>: …"``, as ``(kind, t_s)``, latest first."""
        phases = [f"{n}: cued -> active" for n in names]
        cues = [f"{n}: %" for n in names]
        likes = " OR ".join("detail LIKE ?" for _ in cues) or "0"
        return [(str(k), float(t)) for k, t in self.conn.execute(
            f"SELECT kind, t_s FROM events WHERE session_id = ? AND ((kind = 'phase' AND detail IN "
            f"({_in(len(phases))})) OR (kind = 'cue' AND ({likes}))) ORDER BY t_s DESC",
            (int(session_id), *phases, *cues))]

    # -- the recording ------------------------------------------------------------------------------------------
    def arms(self, session_id: int | None = None) -> list[str]:
        """The arms other than the task arm whose records are stored (of a session), by name; [] for a one-arm rig
        or a file from before the arms."""
        if not has_table(self.conn, "arm_recordings"):
            return []
        where, args = ("WHERE session_id = ?", [int(session_id)]) if session_id is not None else ("", [])
        return [str(r[0]) for r in self.conn.execute(
            f"SELECT DISTINCT arm FROM arm_recordings {where} ORDER BY arm", args)]

    def recordings(self, session_id: int, arm: str = "") -> list[tuple[int, float, int]]:
        """A session's recorded segments: ``(segment, started_at_s, t0_ns)``, in order (none before version 3);
        ``arm``: another arm's than the task arm's (:meth:`arms`)."""
        if arm and not has_table(self.conn, "arm_recordings"):
            return []
        where, args = _block_filter(session_id, None, None, arm=arm)
        return [(int(a), float(b), int(c)) for a, b, c in self.conn.execute(
            f"SELECT segment, started_at_s, t0_ns FROM {recording_tables(arm)[0]} {where} ORDER BY segment", args)]

    def sessions_being_written(self) -> dict[int, str]:
        """Sessions a live process writes to right now (their leases): session id -> "process N (command)"; {}
        through a bare connection."""
        return self._db.sessions_being_written() if self._db is not None else {}

    def recorded_runs(self) -> Rows:
        """Every recorded run of every session -- a session resumed after an interruption has one per run -- by
        session and run: ``session_id, segment, started_at_s`` (session clock of its first record) and
        ``last_record_s`` (of its last block's last record; NULL when it has no block).  None before version 3."""
        cols = ("session_id", "segment", "started_at_s", "last_record_s")
        if not self.has_recordings():
            return Rows(cols, [])
        return self._rows(
            "SELECT r.session_id, r.segment, r.started_at_s, (SELECT MAX(b.t_last_s) FROM session_blocks b WHERE "
            "b.session_id = r.session_id AND b.segment = r.segment) AS last_record_s FROM recordings r "
            "ORDER BY r.session_id, r.segment")

    def recording(self, session_id: int, segment: int, arm: str = "") -> tuple[float, int, str] | None:
        """One segment's start: ``(started_at_s, t0_ns, snapshot_json)``, or None when there is no such segment."""
        if arm and not has_table(self.conn, "arm_recordings"):
            return None
        where, args = _block_filter(session_id, segment, None, arm=arm)
        row = self.conn.execute(
            f"SELECT started_at_s, t0_ns, snapshot_json FROM {recording_tables(arm)[0]} {where}", args).fetchone()
        return None if row is None else (float(row[0]), int(row[1]), str(row[2]))

    def blocks(self, session_id: int | None = None, segment: int | None = None,
               ticks: tuple[int, int] | None = None, arm: str = "") -> Iterator[BlockRow]:
        """Recorded blocks (of a session, a segment, those overlapping ticks ``(first, last)``), in order.

        A column the file lacks reads as missing (``crc32`` before version 4: None, the block not verifiable;
        the times: NaN).  A block a killed run left open is read from its chunks (``session_chunks``), joined
        into one (:func:`protocol.recording.join_chunks`).  ``arm``: another arm's blocks than the task arm's
        (:meth:`arms`).
        """
        if arm and not has_table(self.conn, "arm_blocks"):
            return
        table = recording_tables(arm)[1]
        have = {d[0] for d in self.conn.execute(f"SELECT * FROM {table} LIMIT 0").description}
        cols = ", ".join(f"b.{c}" if c in have else "NULL" for c in ("t_first_s", "t_last_s", "crc32"))
        where, args = _block_filter(session_id, segment, ticks, "b.", arm)
        rows = self.conn.execute(
            # CAST: a block whose value was changed to TEXT is bytes to check, not a UTF-8 error for every reader
            f"SELECT b.session_id, b.segment, b.block, b.first_tick, b.last_tick, b.n_records, CAST(b.data AS BLOB), "
            f"{cols}, {self._bound(arm)} "
            f"FROM {table} b "
            f"{where} ORDER BY b.session_id, b.segment, b.block", args)
        open_blocks = self._open_blocks(session_id, segment, ticks, arm)
        for r in heapq.merge(rows, open_blocks, key=lambda r: (r[0], r[1], r[2])) if open_blocks else rows:
            yield BlockRow(int(r[0]), int(r[1]), int(r[2]), int(r[3]), int(r[4]), int(r[5]),
                           math.nan if r[7] is None else float(r[7]), math.nan if r[8] is None else float(r[8]),
                           bytes(r[6]), None if r[9] is None else int(r[9]), arm, bool(r[10]))

    def _bound(self, arm: str, alias: str = "b") -> str:
        """The SQL of whether a block's (or chunk's) run binds its checksums to their place: its run counts its
        blocks (``n_blocks`` not NULL; a file without the column: none does)."""
        runs = recording_tables(arm)[0]
        if not has_table(self.conn, runs) or "n_blocks" not in {
                d[0] for d in self.conn.execute(f"SELECT * FROM {runs} LIMIT 0").description}:
            return "0"
        same_arm = f" AND r.arm = {alias}.arm" if arm else ""
        return (f"(SELECT r.n_blocks IS NOT NULL FROM {runs} r WHERE r.session_id = {alias}.session_id "
                f"AND r.segment = {alias}.segment{same_arm})")

    def _open_blocks(self, session_id: int | None, segment: int | None,
                     ticks: tuple[int, int] | None, arm: str = "") -> list[tuple[Any, ...]]:
        """Blocks left open by a killed run, each joined from its chunks as :meth:`blocks` returns a block.

        The joined block's checksum is that of its bytes when every chunk's own checksum holds, else one that
        cannot match: a damaged chunk is reported as its block's damage.
        """
        table = recording_tables(arm)[2]
        if not has_table(self.conn, table):
            return []
        where, args = _block_filter(session_id, segment, ticks, "c.", arm)
        where = f"{where} AND {_still_open(arm)}" if where else f"WHERE {_still_open(arm)}"
        chunks = self.conn.execute(
            "SELECT c.session_id, c.segment, c.block, c.first_tick, c.last_tick, c.n_records, CAST(c.data AS BLOB), "
            "c.t_first_s, "
            f"c.t_last_s, c.crc32, c.chunk, {self._bound(arm, 'c')} FROM {table} c {where} "
            "ORDER BY c.session_id, c.segment, c.block, c.chunk", args)
        out = []
        for key, group in itertools.groupby(chunks, key=lambda r: (r[0], r[1], r[2])):
            parts = list(group)
            data = join_chunks(bytes(r[6]) for r in parts)
            bound = bool(parts[0][11])
            intact = all(r[9] == (place_crc32(bytes(r[6]), arm=arm, session_id=r[0], segment=r[1], block=r[2],
                                              chunk=r[10], first_tick=r[3], last_tick=r[4], n_records=r[5])
                                  if bound else zlib.crc32(r[6])) for r in parts)
            joined = BlockRow(*key, min(r[3] for r in parts), max(r[4] for r in parts), sum(r[5] for r in parts),
                              min(r[7] for r in parts), max(r[8] for r in parts), data, None, arm, bound)
            crc = block_crc32(joined) ^ (0 if intact else 1)  # a damaged chunk: a checksum that cannot match
            out.append((*key, joined.first_tick, joined.last_tick, joined.n_records, data, joined.t_first_s,
                        joined.t_last_s, crc, bound))
        return out

    def block_counts(self, arm: str = "") -> list[tuple[int, int, int]]:
        """``(session_id, segment, n_blocks)`` of every run that counts its blocks (an arm's: ``arm``); none in a
        file from before the count."""
        runs = recording_tables(arm)[0]
        if not has_table(self.conn, runs) or "n_blocks" not in {
                d[0] for d in self.conn.execute(f"SELECT * FROM {runs} LIMIT 0").description}:
            return []
        where, args = _block_filter(None, None, None, arm=arm)
        cond = f"{where} AND n_blocks IS NOT NULL" if where else "WHERE n_blocks IS NOT NULL"
        return [(int(a), int(b), int(c)) for a, b, c in self.conn.execute(
            f"SELECT session_id, segment, n_blocks FROM {runs} {cond} ORDER BY session_id, segment", args)]

    def block_count(self) -> int:
        """How many recorded blocks the file holds (a block left open by a killed run counts once)."""
        n = int(self.conn.execute("SELECT COUNT(*) FROM session_blocks").fetchone()[0])
        if has_table(self.conn, "session_chunks"):
            n += int(self.conn.execute("SELECT COUNT(*) FROM (SELECT DISTINCT c.session_id, c.segment, c.block "
                                       f"FROM session_chunks c WHERE {_still_open('')})").fetchone()[0])
        return n

    # -- the audit (haptic-study check) ----------------------------------------------------------------------------
    def integrity_check(self, max_errors: int = 20) -> list[str]:
        """SQLite's own ``PRAGMA integrity_check``: ``["ok"]``, or up to ``max_errors`` lines of what is wrong."""
        return [" ".join(str(r[0]).split()) for r in self.conn.execute(f"PRAGMA integrity_check({int(max_errors)})")]

    def session_count(self) -> int:
        """How many sessions are stored."""
        return int(self.conn.execute("SELECT COUNT(*) FROM sessions").fetchone()[0])

    def trial_count(self) -> int:
        """How many trials are stored."""
        return int(self.conn.execute("SELECT COUNT(*) FROM trials").fetchone()[0])

    def trial_places(self) -> list[tuple[int, int, int, int, int]]:
        """Every recorded trial's place: ``(session_id, trial_index, segment, first_tick, last_tick)``, in order."""
        return [tuple(r) for r in self.conn.execute(
            "SELECT session_id, trial_index, segment, first_tick, last_tick FROM trials "
            "WHERE segment IS NOT NULL AND first_tick IS NOT NULL ORDER BY session_id, trial_index")]

    def experiment_designs(self) -> list[tuple[int, str, str, str, str]]:
        """Every experiment session's design: ``(session_id, code, status, protocol_json, schedule_json)``."""
        return [tuple(r) for r in self.conn.execute(
            "SELECT s.session_id, p.code, s.status, s.protocol_json, s.schedule_json FROM sessions s "
            "JOIN participants p USING (participant_id) WHERE s.kind = 'experiment' ORDER BY s.session_id")]

    def trial_cells(self, session_id: int) -> list[tuple[int, str, str, str]]:
        """A session's trials' cells: ``(trial_index, target_label, haptic_mode, outcome)``."""
        return [tuple(r) for r in self.conn.execute(
            "SELECT trial_index, target_label, haptic_mode, outcome FROM trials WHERE session_id = ?",
            (int(session_id),))]

    # -- counts (the run summary) -------------------------------------------------------------------------------
    def sample_count(self, session_ids: Sequence[int]) -> int:
        """How many ``samples`` rows (schema versions 1 and 2) some sessions' trials have."""
        return int(self.conn.execute(
            f"SELECT COUNT(*) FROM samples WHERE trial_id / 1000000 IN ({_in(len(session_ids))})",
            [int(s) for s in session_ids]).fetchone()[0])

    def record_count(self, session_ids: Sequence[int]) -> int:
        """How many 1 kHz records some sessions' recordings hold (0 without a recording)."""
        if not self.has_recordings():
            return 0
        ids = [int(s) for s in session_ids]
        tables = ("session_blocks", "session_chunks") if has_table(self.conn, "session_chunks") else ("session_blocks",)
        return sum(int(self.conn.execute(
            f"SELECT COALESCE(SUM(n_records), 0) FROM {t} WHERE session_id IN ({_in(len(ids))})", ids).fetchone()[0])
            for t in tables)
