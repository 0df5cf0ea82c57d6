"""The sessions of a study database, as people ask about them (``haptic-study sessions``, the GUI's setup form).

Read-only: the database is opened with ``mode=ro`` and nothing is written.
Trials are counted for people: ``trials_done`` finished (success or timeout),
``trials_aborted`` aborted (each re-run later in its session) and
``trials_planned`` the schedule as drawn, re-runs not counted.
"""

from __future__ import annotations

import json
import os
from typing import Any

from pipeline.force.pipeline_settings import describe, non_default_settings, stored_settings
from protocol.storage import StorageError, StudyDatabase, StudyReader
from protocol.storage.annotations import covariates_by_code
from protocol.storage.withdrawal import withdrawals
from protocol.study.labels import plural

__all__ = ["format_sessions", "list_covariates", "list_sessions", "list_withdrawn", "next_participant_number"]

def list_covariates(db_path: str | os.PathLike[str]) -> dict[str, dict[str, Any]]:
    """Each registered participant's covariates by code (read-only; {} when the file does not exist yet)."""
    if not os.path.exists(db_path):
        return {}
    db = StudyDatabase(db_path, readonly=True, check=False)
    try:
        return {code: dict(v) for code, v in covariates_by_code(db.conn).items()}
    finally:
        db.close()


def list_sessions(db_path: str | os.PathLike[str], *, check: bool = True) -> list[dict[str, Any]]:
    """Every session of a study database, oldest first; empty when the file does not exist yet.

    Returns
    -------
    list of dict
        ``session_id, code, participant_number, kind, status, rig, seed, started_at, ended_at, end_reason,
        trials_planned, trials_done, trials_aborted, successes``, ``first_trial``, ``last_trial``: the
        stored trials' numbers, from 1 (None when none is stored), and ``writer``: the live process running
        a session right now ("" when none: a ``running`` session without one was interrupted),
        ``pipeline``: the pipeline settings it ran with that are not the paper's (``run --set``; {} for the
        paper's), ``part``: the study part it is ("" in a study of one task; :mod:`protocol.study.parts`), and
        ``visit``: the visit of a schedule it belongs to ("" without ``[[visits]]``; :mod:`protocol.study.visits`).

    ``check``: run the integrity check first (the command line does; the GUI's engine, listing between
    sessions, checks when it opens the database to write).

    Raises
    ------
    StorageError
        Not a study database, or a damaged one (the message says why).
    """
    if not os.path.exists(db_path):
        return []
    db = StudyDatabase(db_path, readonly=True, check=check)
    try:
        reader = StudyReader.over(db)
        rows = reader.session_overview()
        infos = reader.sessions()
        pipeline = {int(s.session_id): _pipeline_settings(s.config_json) for s in infos}
        parts = {int(s.session_id): s.part for s in infos}
        visits = {int(s.session_id): s.visit for s in infos}
        writers = db.sessions_being_written()
    finally:
        db.close()
    out = []
    for (sid, code, number, kind, status, rig, seed, started, ended, reason, schedule, done, aborted, successes,
         first, last) in rows:
        try:
            planned = sum(1 for t in json.loads(schedule) if t.get("repeat_of") is None)
        except (ValueError, TypeError, AttributeError):
            raise StorageError(f"{db_path}: session {sid} has an unreadable schedule") from None
        out.append({
            "session_id": int(sid), "code": code, "participant_number": int(number), "kind": kind,
            "status": status, "rig": rig, "seed": int(seed), "started_at": started, "ended_at": ended,
            "end_reason": reason or "", "trials_planned": planned, "trials_done": int(done),
            "trials_aborted": int(aborted), "successes": int(successes),
            "first_trial": None if first is None else int(first) + 1,
            "last_trial": None if last is None else int(last) + 1,
            "writer": writers.get(int(sid), "") if status == "running" else "",
            "pipeline": pipeline.get(int(sid), {}),
            "part": parts.get(int(sid), ""),
            "visit": visits.get(int(sid), ""),
        })
    return out


def list_withdrawn(db_path: str | os.PathLike[str]) -> list[dict[str, str]]:
    """The participants who withdrew from a study (``code``, ``withdrawn_at``), oldest first; their codes are not
    used again.  Empty when the file does not exist yet."""
    if not os.path.exists(db_path):
        return []
    db = StudyDatabase(db_path, readonly=True, check=False)
    try:
        return [{"code": w.code, "withdrawn_at": w.withdrawn_at} for w in withdrawals(db.conn)]
    finally:
        db.close()


def _pipeline_settings(config_json: str | None) -> dict[str, float]:
    """The settings a session's ``config_json`` records that are not the paper's."""
    try:
        record = json.loads(config_json or "{}").get("framework")
    except (ValueError, TypeError, AttributeError):
        return {}
    return non_default_settings(stored_settings(record))


def _part(s: dict[str, Any]) -> str:
    """A session's part as the listing shows it: ``VISIT/PART`` in a study with visits."""
    part, visit = str(s.get("part", "")), str(s.get("visit", ""))
    return f"{visit}/{part}" if visit else part


def next_participant_number(sessions: list[dict[str, Any]]) -> int:
    """One more than the largest participant number in use (1 for an empty database)."""
    return max((int(s["participant_number"]) for s in sessions), default=0) + 1


def _status(s: dict[str, Any]) -> str:
    if s["status"] != "running":
        return str(s["status"])
    return f"in progress ({s['writer'].split(' (')[0]})" if s.get("writer") else "interrupted"


def format_sessions(db_path: str, sessions: list[dict[str, Any]]) -> str:
    """A table of the sessions for the terminal, with how to plot one of their trials."""
    if not sessions:
        return f"{db_path}: no sessions yet"
    parts = any(s.get("part") for s in sessions)  # a study of several parts: which part each session is
    head = ("session", "participant", "number", "kind", *(("part",) if parts else ()), "status", "rig", "trials",
            "aborted", "started (UTC)")
    rows = [head]
    for s in sessions:
        rows.append((
            str(s["session_id"]), s["code"], str(s["participant_number"]), s["kind"],
            *((_part(s),) if parts else ()), _status(s), s["rig"],
            f"{s['trials_done']}/{s['trials_planned']}", str(s["trials_aborted"]),
            str(s["started_at"])[:16].replace("T", " "),
        ))
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    left = (1, 3, 4, 5, 6) if parts else (1, 3, 4, 5)
    lines = ["  ".join(c.ljust(w) if i in left else c.rjust(w)
                       for i, (c, w) in enumerate(zip(r, widths, strict=True)))
             for r in rows]
    n_participants = len({s["code"] for s in sessions})
    lines.insert(0, f"{db_path}: {plural(len(sessions), 'session')}, {plural(n_participants, 'participant')}")
    lines.append("")
    by_settings: dict[str, list[str]] = {}
    for s in sessions:
        if s.get("pipeline"):
            by_settings.setdefault(describe(s["pipeline"]), []).append(str(s["session_id"]))
    for text, ids in by_settings.items():
        lines.append(f"pipeline settings not the paper's (run --set): {text} (session{'s' if len(ids) > 1 else ''} "
                     f"{', '.join(ids)})")
    lines.append("trials: finished / planned (aborted trials are re-run and not counted as finished)")
    if any(_status(s) == "interrupted" for s in sessions):
        lines.append("an interrupted session can be resumed: haptic-study run --resume CODE, or the GUI")
    lines.append("plot a trial: haptic-study plot-trial --db PATH --session SESSION --trial N --out FILE.png "
                 "(trials are numbered from 1)")
    return "\n".join(lines)
