"""What a ``run`` of a study of several parts will do (:mod:`protocol.study.parts`): each participant's parts in their
order, one session each; when continuing, every interrupted part resumed and the first unfinished one on.

A step ``("part", NAME)`` is a new session of the participant's part ``NAME`` (:meth:`ProtocolConfig.part_of`:
the part's protocol with its place in their order); ``("resume", SESSION_ID)`` continues an interrupted one, as in
a study of one task.  Every refusal is decided on a read-only look first (:mod:`study_app.headless.plan`).
"""

from __future__ import annotations

import datetime as _dt
import json
from typing import Any

from protocol.runner.session_setup import (
    participant_code,
    refuse_damaged_recording,
    training_protocol,
    training_schedule,
)
from protocol.runner.study_rules import StoredSession, StudyRuleError, part_states, requires_training
from protocol.storage import SessionInfo, StorageError, StudyDatabase
from protocol.study.config import ProtocolConfig, protocol_from_dict
from study_app.headless.plan_visits import VisitRequest, request_day, visit_deviation, visit_step

__all__ = ["part_steps", "part_trials", "parts_left"]


def part_trials(part: ProtocolConfig) -> int:
    """The trials a new session of ``part`` runs (a training part: its training schedule's)."""
    assert part.part is not None
    return len(training_schedule(part)) if part.part.session == "training" else part.trials_per_participant


def part_steps(protocol: ProtocolConfig, number: int, seed: int,
               request: VisitRequest | None = None) -> tuple[list[tuple[str, Any]], int]:
    """A new participant's steps (every part in their order; with visits, every visit's, or the ``request``ed
    visit's) and the trials they run."""
    if protocol.visits:
        steps, trials, _ = parts_left(None, "", protocol, number, seed, [], None, request)
        return steps, trials
    parts = protocol.plan_for(number, seed)
    return [("part", p.part.name) for p in parts if p.part is not None], sum(part_trials(p) for p in parts)


def parts_left(
    db: StudyDatabase | None, db_path: str, protocol: ProtocolConfig, number: int, seed: int,
    stored: list[SessionInfo], remaining: Any, request: VisitRequest | None = None,
) -> tuple[list[tuple[str, Any]], int, list[int]]:
    """What is left of participant ``number``'s plan: steps, trials, and their finished sessions (kept).

    ``remaining(db, info)`` counts an interrupted session's trials left.  Raises :class:`StorageError` (nothing
    written) when a stored part ran another protocol than this file's part, and :class:`StudyRuleError` when a new
    experiment part would start without a training part before it completed or run first by this command, or the
    ``request``ed visit is out of order or outside its window without a deviation's reason
    (:mod:`study_app.headless.plan_visits`); with a request, only that visit's parts are run.
    """
    code = participant_code(number)
    parts = protocol.plan_for(number, seed)
    rules = [StoredSession(s.session_id, s.code, s.kind, s.status, s.seed, s.part, s.visit) for s in stored]
    steps: list[tuple[str, Any]] = []
    kept: list[int] = []
    trials = 0
    runs_before: set[str] = set()  # parts this command runs or resumes before the next
    today = _dt.date.today()
    day = 0 if request is None else request_day(request, parts[0], stored, code, today)
    deviation = "" if request is None else visit_deviation(protocol, number, seed, rules, code, stored, request,
                                                            day, db_path)
    for part, state, session in part_states(rules, code, parts):
        assert part.part is not None
        name, visit = part.part.name, part.part.visit.name if part.part.visit is not None else ""
        if session is not None:
            info = next(s for s in stored if s.session_id == session.session_id)
            _check_same(info, part, db_path)
        if state in ("completed", "ended"):
            kept.extend(s.session_id for s in stored
                        if s.part == name and s.visit == visit and s.status != "running")
            continue
        if request is not None and visit != request.visit:
            continue
        if session is not None:
            assert db is not None
            refuse_damaged_recording(db, session.session_id)
            steps.append(("resume", session.session_id))
            trials += remaining(db, info)
        else:
            _check_trained(part, rules, code, runs_before, db_path)
            if part.part.visit is not None:
                held = day if request is not None else part.part.visit.day
                steps.append(("visit", visit_step(part, request, held, deviation)))
                deviation = ""  # stored once, with the visit's first new session
            else:
                steps.append(("part", name))
            trials += part_trials(part)
        runs_before.add(name)
    return steps, trials, kept


def _check_same(info: SessionInfo, part: ProtocolConfig, db_path: str) -> None:
    """A stored part's protocol must be this file's part for this participant (its place in their order too)."""
    try:
        have = json.loads(protocol_from_dict(json.loads(info.protocol_json), "stored protocol").to_json())
    except ValueError:
        have = json.loads(info.protocol_json)
    run = training_protocol(part) if info.kind == "training" else part
    if have != json.loads(run.to_json()):
        raise StorageError(
            f"cannot continue: {info.code}'s part {info.part!r} (session {info.session_id}) in {db_path} was run with "
            "another protocol; nothing was changed (give the --protocol the study was started with)")


def _check_trained(part: ProtocolConfig, rules: list[StoredSession], code: str, runs_before: set[str],
                   db_path: str) -> None:
    """Refuse a new experiment part whose training parts are neither completed nor run first by this command."""
    if part.part is None or part.part.session != "experiment" or not requires_training(part):
        return
    done = {s.part for s in rules if s.code == code and s.kind == "training" and s.status == "completed"}
    missing = [t for t in part.part.trained_by if t not in done and t not in runs_before]
    if missing:
        raise StudyRuleError(
            f"cannot continue: {code}'s part {part.part.name!r} requires the training part {missing[0]!r} completed "
            f"before it (training.required), and it ended without completing; nothing was changed ({db_path})")
