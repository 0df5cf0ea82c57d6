"""What the study record holds beside the trials: who the participants are, the experimenter's notes, and the
questionnaires' answers -- written and read here (the tables ``covariates``, ``notes`` and
``questionnaire_answers`` of ``data/schema.sql``).

* **Covariates** are stored once, with a participant's first session, in the transaction that stores it
  (:meth:`protocol.storage.StudyDatabase.create_session`); never changed afterwards.
* **Notes** are appended (during a session through the recorder, in one transaction with nothing else; after it
  by ``haptic-study note``): a note never alters another row.
* **Answers** of one questionnaire are stored together, in one transaction.

Withdrawal removes all three with the participant (:mod:`protocol.storage.withdrawal`), and ``export
participant`` writes them (:mod:`protocol.storage.participant_data`).
"""

from __future__ import annotations

import sqlite3
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from protocol.storage.common import StorageError, has_table, now_iso
from protocol.study.covariates import Covariate, CovariateValue
from protocol.study.questionnaires import QUESTIONNAIRE_SKIPPED_EVENT, skipped_key

__all__ = [
    "Answer", "Note", "answered_blocks", "answers", "covariate_rows", "covariates_by_code", "event_details",
    "insert_answers", "insert_covariates", "insert_note", "notes",
]


@dataclass(frozen=True, slots=True)
class Note:
    """One of the experimenter's notes (``t_s`` None: added after the session; ``trial_index`` None: the session)."""

    session_id: int
    t_s: float | None
    trial_index: int | None
    text: str
    deviation: bool
    written_at: str


@dataclass(frozen=True, slots=True)
class Answer:
    """One answered question: a rating or a pair's choice, with its questionnaire, block and time."""

    session_id: int
    questionnaire: str
    block: str
    item: str
    rating: float | None
    choice: str | None
    answered_at_s: float


def _text(kind: str, value: CovariateValue) -> str:
    return repr(float(value)) if kind == "float" else str(int(value)) if kind == "integer" else str(value)


def _typed(kind: str, text: str) -> CovariateValue:
    return float(text) if kind == "float" else int(text) if kind == "integer" else text


def covariate_rows(conn: sqlite3.Connection, participant_id: int) -> dict[str, CovariateValue]:
    """A participant's stored covariates by name (none: {})."""
    if not has_table(conn, "covariates"):
        return {}
    return {str(n): _typed(str(k), str(v)) for n, k, v in conn.execute(
        "SELECT name, kind, value FROM covariates WHERE participant_id = ? ORDER BY rowid", (participant_id,))}


def insert_covariates(conn: sqlite3.Connection, participant_id: int, code: str, declared: Sequence[Covariate],
                      values: Mapping[str, CovariateValue], *, new: bool) -> None:
    """Store a participant's covariates (``values``, checked against ``declared``) when they are ``new``; for a
    participant registered before, values are only compared: they were given at the first session and are
    never changed (a different value is refused, naming the stored one).  Inside the caller's transaction."""
    if not values:
        return
    if not new:
        stored = covariate_rows(conn, participant_id)
        for name, v in values.items():
            if name in stored and stored[name] != v:
                raise StorageError(f"covariate {name} = {v!r}: participant {code}'s {name} was recorded as "
                                   f"{stored[name]!r} when they were registered, and is not changed")
        return
    kinds = {c.name: c.kind for c in declared}
    conn.executemany("INSERT INTO covariates (participant_id, name, kind, value) VALUES (?, ?, ?, ?)",
                     [(participant_id, n, kinds[n], _text(kinds[n], v)) for n, v in values.items()])


def covariates_by_code(conn: sqlite3.Connection) -> dict[str, dict[str, CovariateValue]]:
    """Every participant's covariates, by code (participants without any are left out)."""
    if not has_table(conn, "covariates"):
        return {}
    out: dict[str, dict[str, CovariateValue]] = {}
    for code, name, kind, value in conn.execute(
            "SELECT p.code, c.name, c.kind, c.value FROM covariates c JOIN participants p USING (participant_id) "
            "ORDER BY p.code, c.rowid"):
        out.setdefault(str(code), {})[str(name)] = _typed(str(kind), str(value))
    return out


def insert_note(conn: sqlite3.Connection, note: Note) -> None:
    """Append one note (the session must exist; its trial, when named, is not required to have ended)."""
    if not note.text.strip():
        raise StorageError("note = '': a note needs its text")
    if conn.execute("SELECT 1 FROM sessions WHERE session_id = ?", (note.session_id,)).fetchone() is None:
        raise StorageError(f"note: session {note.session_id}: no such session")
    conn.execute("INSERT INTO notes (session_id, t_s, trial_index, text, deviation, written_at) VALUES "
                 "(?, ?, ?, ?, ?, ?)", (note.session_id, note.t_s, note.trial_index, note.text.strip(),
                                        int(note.deviation), note.written_at or now_iso()))


def notes(conn: sqlite3.Connection, session_ids: Sequence[int] | None = None) -> list[Note]:
    """The notes (of ``session_ids``, or all), in the order they were written."""
    if not has_table(conn, "notes"):
        return []
    rows = conn.execute("SELECT session_id, t_s, trial_index, text, deviation, written_at FROM notes ORDER BY rowid")
    wanted = None if session_ids is None else set(session_ids)
    return [Note(int(s), t, None if i is None else int(i), str(x), bool(d), str(w)) for s, t, i, x, d, w in rows
            if wanted is None or s in wanted]


def insert_answers(conn: sqlite3.Connection, session_id: int, questionnaire: str, block: str,
                   answered: Mapping[str, float | str], t_s: float) -> None:
    """Store one questionnaire's answers (checked by :func:`protocol.study.questionnaires.checked_answers`)."""
    conn.executemany(
        "INSERT INTO questionnaire_answers (session_id, questionnaire, block, item, rating, choice, answered_at_s) "
        "VALUES (?, ?, ?, ?, ?, ?, ?)",
        [(session_id, questionnaire, block, item, None if isinstance(v, str) else float(v),
          v if isinstance(v, str) else None, t_s) for item, v in answered.items()])


def answers(conn: sqlite3.Connection, session_ids: Sequence[int] | None = None) -> list[Answer]:
    """The stored answers (of ``session_ids``, or all), in the order they were stored."""
    if not has_table(conn, "questionnaire_answers"):
        return []
    rows = conn.execute("SELECT session_id, questionnaire, block, item, rating, choice, answered_at_s "
                        "FROM questionnaire_answers ORDER BY rowid")
    wanted = None if session_ids is None else set(session_ids)
    return [Answer(int(s), str(q), str(b), str(i), r, c, float(t)) for s, q, b, i, r, c, t in rows
            if wanted is None or s in wanted]


def event_details(conn: sqlite3.Connection, session_id: int, kind: str) -> list[str]:
    """The details of a session's events of ``kind``, in the order stored."""
    return [str(d or "") for (d,) in conn.execute(
        "SELECT detail FROM events WHERE session_id = ? AND kind = ? ORDER BY rowid", (session_id, kind))]


def answered_blocks(conn: sqlite3.Connection, session_id: int) -> list[tuple[str, str]]:
    """The (questionnaire, block) a session has answers of, or skipped by the experimenter (a resume asks no
    questionnaire twice)."""
    skipped = [k for d in event_details(conn, session_id, QUESTIONNAIRE_SKIPPED_EVENT)
               if (k := skipped_key(d)) is not None]
    if not has_table(conn, "questionnaire_answers"):
        return skipped
    return [(str(q), str(b)) for q, b in conn.execute(
        "SELECT DISTINCT questionnaire, block FROM questionnaire_answers WHERE session_id = ?", (session_id,))
            ] + skipped
