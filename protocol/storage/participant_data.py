"""Every stored row about one participant, table by table: what a subject-access request is answered from.

:func:`participant_rows` reads, for one participant code, their ``participants`` row and every row that refers to
them -- their covariates, sessions, trials, events, the experimenter's notes, the questionnaires' answers, recorded
runs (``recordings``), the recorded blocks' descriptions (the
blocks' bytes are decoded by :mod:`protocol.recording`), the ``samples`` rows of older versions and the leases of
their sessions -- as plain column names and value tuples.  ``haptic-study export participant`` writes them out
(:mod:`analysis.export.participant_export`); ``withdraw`` removes the same rows (:mod:`protocol.storage.withdrawal`).
"""

from __future__ import annotations

import sqlite3
from dataclasses import dataclass
from typing import Any

from protocol.storage.common import has_table
from protocol.storage.leases import session_scope
from protocol.storage.lsl_streams import ALIGNED_COLUMNS, aligned_samples
from protocol.study.records import trial_id_of

__all__ = ["ParticipantRows", "Table", "participant_rows"]


@dataclass(frozen=True, slots=True)
class Table:
    """Rows of one table: column names and value tuples."""

    columns: tuple[str, ...]
    rows: tuple[tuple[Any, ...], ...]


@dataclass(frozen=True, slots=True)
class ParticipantRows:
    """Every row stored about one participant, by table name (``participants``, ``sessions``, ``trials``, ...)."""

    code: str
    session_ids: tuple[int, ...]
    tables: dict[str, Table]


def _table(conn: sqlite3.Connection, sql: str, args: tuple[Any, ...]) -> Table:
    cur = conn.execute(sql, args)
    return Table(tuple(d[0] for d in cur.description), tuple(tuple(r) for r in cur.fetchall()))


def _per_session(conn: sqlite3.Connection, sql: str, args: list[tuple[Any, ...]]) -> Table:
    """One query run for each session's arguments, the rows joined (the columns even when there is no session)."""
    parts = [_table(conn, sql, a) for a in args] or [_table(conn, sql, (None,) * sql.count("?"))]
    return Table(parts[0].columns, tuple(r for p in parts for r in p.rows))


def participant_rows(conn: sqlite3.Connection, code: str) -> ParticipantRows | None:
    """Every stored row about participant ``code`` (None: no such participant), sessions and trials in order.

    ``session_blocks`` and ``session_chunks`` are described without their ``data`` (the blocks' bytes); tables a
    file of an older schema version lacks are empty.
    """
    person = _table(conn, "SELECT * FROM participants WHERE code = ?", (code,))
    if not person.rows:
        return None
    pid = person.rows[0][person.columns.index("participant_id")]
    sessions = _table(conn, "SELECT * FROM sessions WHERE participant_id = ? ORDER BY session_id", (pid,))
    sids = tuple(int(r[sessions.columns.index("session_id")]) for r in sessions.rows)
    blocks_cols = ("session_id, segment, block, first_tick, last_tick, n_records, t_first_s, t_last_s"
                   + (", crc32" if any(r[1] == "crc32" for r in conn.execute("PRAGMA table_info(session_blocks)"))
                      else ""))
    queries: dict[str, tuple[str, bool]] = {
        "trials": ("SELECT * FROM trials WHERE session_id = ? ORDER BY trial_index", True),
        "events": ("SELECT * FROM events WHERE session_id = ? ORDER BY t_s, rowid", True),
        "notes": ("SELECT * FROM notes WHERE session_id = ? ORDER BY rowid", has_table(conn, "notes")),
        "questionnaire_answers": ("SELECT * FROM questionnaire_answers WHERE session_id = ? ORDER BY rowid",
                                  has_table(conn, "questionnaire_answers")),
        "trial_answers": ("SELECT * FROM trial_answers WHERE session_id = ? ORDER BY trial_index",
                          has_table(conn, "trial_answers")),
        "recordings": ("SELECT * FROM recordings WHERE session_id = ? ORDER BY segment", has_table(conn, "recordings")),
        "session_blocks": (f"SELECT {blocks_cols} FROM session_blocks WHERE session_id = ? ORDER BY segment, block",
                           has_table(conn, "session_blocks")),
        "session_chunks": ("SELECT session_id, segment, block, chunk, first_tick, last_tick, n_records, t_first_s, "
                           "t_last_s, crc32 FROM session_chunks WHERE session_id = ? ORDER BY segment, block, chunk",
                           has_table(conn, "session_chunks")),
        # a rig of several arms: the other arms' recordings, described like the task arm's
        "arm_recordings": ("SELECT * FROM arm_recordings WHERE session_id = ? ORDER BY arm, segment",
                           has_table(conn, "arm_recordings")),
        "arm_blocks": ("SELECT session_id, arm, segment, block, first_tick, last_tick, n_records, t_first_s, t_last_s, "
                       "crc32 FROM arm_blocks WHERE session_id = ? ORDER BY arm, segment, block",
                       has_table(conn, "arm_blocks")),
        "arm_chunks": ("SELECT session_id, arm, segment, block, chunk, first_tick, last_tick, n_records, t_first_s, "
                       "t_last_s, crc32 FROM arm_chunks WHERE session_id = ? ORDER BY arm, segment, block, chunk",
                       has_table(conn, "arm_chunks")),
        # the Lab Streaming Layer: each run's clock link and outlets, the external streams recorded with it
        "lsl_runs": ("SELECT * FROM lsl_runs WHERE session_id = ? ORDER BY segment", has_table(conn, "lsl_runs")),
        "lsl_streams": ("SELECT * FROM lsl_streams WHERE session_id = ? ORDER BY segment, stream",
                        has_table(conn, "lsl_streams")),
    }
    tables = {"participants": person}
    if has_table(conn, "covariates"):
        tables["covariates"] = _table(conn, "SELECT * FROM covariates WHERE participant_id = ? ORDER BY rowid", (pid,))
    tables["sessions"] = sessions
    for name, (sql, present) in queries.items():
        if present:
            tables[name] = _per_session(conn, sql, [(sid,) for sid in sids])
    tables["samples"] = _per_session(conn, "SELECT * FROM samples WHERE trial_id >= ? AND trial_id < ? "
                                     "ORDER BY trial_id, t_s",
                                     [(trial_id_of(sid, 0), trial_id_of(sid + 1, 0)) for sid in sids])
    if has_table(conn, "lsl_chunks"):  # their samples, each on the session clock beside its LSL timestamp
        tables["lsl_samples"] = Table(ALIGNED_COLUMNS, tuple(r for sid in sids for r in aligned_samples(conn, sid)))
    if has_table(conn, "leases"):
        tables["leases"] = _per_session(conn, "SELECT * FROM leases WHERE scope = ?",
                                        [(session_scope(sid),) for sid in sids])
    return ParticipantRows(code, sids, tables)
