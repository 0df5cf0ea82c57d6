"""The answers of a task that asks the participant a question (force discrimination's "which was stronger?"): one row
per answered trial in ``trial_answers``, beside its ``trials`` row and committed with it.

A row holds the trial's answer (the key; NULL: none given within the answer window), when it was given (session
clock), and the values its task's procedure defined and scored (:class:`protocol.tasks.base.Stimulus` and
:meth:`protocol.tasks.base.Procedure.answered`: force discrimination's reference, Δ, order, the force felt in each
interval, whether the answer was right) as JSON, so the table is the same for every task that asks.  A file gets
the table with its first such trial (a study of the paper's task has none: its file is as it always was).
Withdrawal removes the rows with the participant; ``export participant`` writes them.
"""

from __future__ import annotations

import json
import math
import sqlite3
from collections.abc import Mapping
from dataclasses import dataclass

from protocol.storage.common import has_table

__all__ = ["TABLE", "AnsweredSession", "TrialAnswer", "answered_sessions", "asks_questions", "insert_answer",
           "trial_answers"]

#: The table's name.
TABLE = "trial_answers"
_CREATE = (
    "CREATE TABLE IF NOT EXISTS trial_answers (session_id INTEGER NOT NULL REFERENCES sessions(session_id), "
    "trial_index INTEGER NOT NULL, answer TEXT, answered_at_s REAL, values_json TEXT NOT NULL, "
    "PRIMARY KEY (session_id, trial_index))"
)


@dataclass(frozen=True, slots=True)
class TrialAnswer:
    """One trial's answer and the values its task's procedure defined and scored (module docstring)."""

    session_id: int
    trial_index: int
    answer: str | None
    answered_at_s: float | None
    values: Mapping[str, float]


def insert_answer(conn: sqlite3.Connection, a: TrialAnswer) -> None:
    """Store one answer (inside the caller's transaction: the trial's row and its answer are one state change)."""
    conn.execute(_CREATE)
    values = {k: (None if not math.isfinite(float(v)) else float(v)) for k, v in a.values.items()}
    conn.execute("INSERT INTO trial_answers (session_id, trial_index, answer, answered_at_s, values_json) "
                 "VALUES (?, ?, ?, ?, ?)", (a.session_id, a.trial_index, a.answer, a.answered_at_s,
                                           json.dumps(values, sort_keys=True)))


def trial_answers(conn: sqlite3.Connection, session_id: int | None = None) -> list[TrialAnswer]:
    """The stored answers (of one session, or all), by session and trial; none: [] (a NULL value reads as NaN)."""
    if not has_table(conn, TABLE):
        return []
    where, args = ("WHERE session_id = ?", (session_id,)) if session_id is not None else ("", ())
    rows = conn.execute(f"SELECT session_id, trial_index, answer, answered_at_s, values_json FROM trial_answers "
                        f"{where} ORDER BY session_id, trial_index", args).fetchall()
    return [TrialAnswer(int(s), int(i), None if k is None else str(k), None if t is None else float(t),
                        {n: (math.nan if v is None else float(v)) for n, v in json.loads(j).items()})
            for s, i, k, t, j in rows]


@dataclass(frozen=True, slots=True)
class AnsweredSession:
    """An experiment session's answered trials, for analysis: its participant's number and each answer with its
    trial's target label (aborted trials left out)."""

    session_id: int
    participant_number: int
    answers: tuple[tuple[str, TrialAnswer], ...]


def asks_questions(conn: sqlite3.Connection, kind: str) -> bool:
    """Whether the file's experiment sessions are of the task ``kind`` and it has answers (a study of a task that
    asks: its report reads them)."""
    row = conn.execute("SELECT protocol_json FROM sessions WHERE kind = 'experiment' LIMIT 1").fetchone()
    return row is not None and f'"{kind}"' in str(row[0]) and has_table(conn, TABLE)


def answered_sessions(conn: sqlite3.Connection) -> list[AnsweredSession]:
    """Every experiment session with its answered trials, by participant number."""
    sessions = conn.execute("SELECT session_id, participant_number FROM sessions WHERE kind = 'experiment' "
                            "ORDER BY participant_number, session_id").fetchall()
    labels = {(int(a), int(b)): str(c) for a, b, c in conn.execute(
        "SELECT session_id, trial_index, target_label FROM trials WHERE outcome != 'aborted'")}
    answers = trial_answers(conn)
    return [AnsweredSession(int(sid), int(number), tuple(
        (labels[(a.session_id, a.trial_index)], a) for a in answers
        if a.session_id == sid and (a.session_id, a.trial_index) in labels))
        for sid, number in sessions]
