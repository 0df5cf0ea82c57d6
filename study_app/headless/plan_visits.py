"""What a ``run`` does in a study with a schedule of visits (:mod:`protocol.study.visits`): the whole schedule on the
virtual clock, or one visit at a time (``run --visit NAME``), as a lab's participants come back.

A step ``("visit", VisitStep)`` is a new session of a part in a visit, with the events stored with it at session
time 0 (:data:`protocol.runner.visit_schedule.VISIT_EVENT`: the study day it is held on; a deviation).

**The day a visit is held on.**  A whole-schedule ``run`` simulates every visit on its planned day (the simulated
participant keeps the schedule): each session's visit event says so.  The sessions' ``started_at`` stay the wall
clock of the run -- the record says when it was made, not when a simulated person came -- so the planned day, not
the wall clock, is the simulated visit's date.  ``run --visit NAME`` holds the visit on the study day of today's
date (:func:`protocol.runner.visit_schedule.held_day`), or on ``--day N`` (a simulated participant coming on day N).
A visit out of order (an earlier one not done) or outside its window is refused in one line, nothing stored,
unless the experimenter gives the reason (``--deviation``): it is then stored as a ``deviation`` event of the
visit's first new session, and the report lists it among the deviations.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Sequence
from dataclasses import dataclass

from protocol.runner.study_rules import DEVIATION_EVENT, StoredSession, StudyRuleError
from protocol.runner.visit_schedule import VISIT_EVENT, first_visit_date, held_day, visit_refusal, visit_schedule
from protocol.storage import SessionInfo
from protocol.study.config import ProtocolConfig
from protocol.study.visits import VisitPlace

__all__ = ["VisitRequest", "VisitStep", "check_visit_request", "visit_step"]


@dataclass(frozen=True, slots=True)
class VisitStep:
    """A new session of ``part`` in ``visit``, and the events stored with it."""

    visit: str
    part: str
    events: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True, slots=True)
class VisitRequest:
    """What ``run --visit`` asks: the visit, the study day it is held on (None: today's), the deviation's reason."""

    visit: str
    day: int | None = None
    deviation: str = ""


def check_visit_request(protocol: ProtocolConfig, request: VisitRequest | None) -> None:
    """Refuse (one ``ValueError`` line) a request the protocol cannot have: a visit it does not declare."""
    if request is None:
        return
    if not protocol.visits:
        raise ValueError(f"--visit = {request.visit!r}: the protocol has no [[visits]] (a study done in one visit)")
    if request.visit not in protocol.visit_names:
        raise ValueError(f"--visit = {request.visit!r}: no such visit; the visits are "
                         f"{', '.join(protocol.visit_names)}")
    if request.day is not None and request.day < 0:
        raise ValueError(f"--day = {request.day}: must be a study day ≥ 0 (days after the participant's first visit)")


def visit_step(part: ProtocolConfig, request: VisitRequest | None, day: int, deviation: str = "",
               how: str = "") -> VisitStep:
    """The step of a new session of ``part`` (a part of a visit) held on study ``day``; ``how`` it was started, in
    the visit event's last words (default: ``run --visit`` for a request, else the simulated schedule)."""
    assert part.part is not None and part.part.visit is not None
    v: VisitPlace = part.part.visit
    how = how or ("run --visit" if request is not None else "the simulated participant keeps the schedule")
    held = (f"{v.name} (visit {v.number}): held on study day {day}, planned day {v.day} ± {v.window_days} "
            f"({how})")
    events = ((VISIT_EVENT, held),) + (((DEVIATION_EVENT, deviation),) if deviation else ())
    return VisitStep(v.name, part.part.name, events)


def request_day(request: VisitRequest | None, part: ProtocolConfig, stored: Sequence[SessionInfo | StoredSession],
                code: str, today: _dt.date) -> int:
    """The study day a new session of ``part`` is held on: the planned day in a whole-schedule run, else
    ``--day`` or today's study day."""
    assert part.part is not None and part.part.visit is not None
    if request is None:
        return part.part.visit.day
    if request.day is not None:
        return request.day
    return held_day(first_visit_date(stored, code), today)


def visit_deviation(protocol: ProtocolConfig, number: int, seed: int, rules: list[StoredSession], code: str,
                    stored: Sequence[SessionInfo | StoredSession], request: VisitRequest, day: int,
                    db_path: str) -> str:
    """The deviation detail to store with the requested visit's first new session ("" when none is needed); a
    :class:`StudyRuleError` line (nothing written) when one is needed and no reason was given."""
    sched = visit_schedule(protocol, number, seed, rules, code, first_visit_date(stored, code), _dt.date.today())
    why = visit_refusal(sched, request.visit, day)
    if not why or sched.visit(request.visit).state == "done":
        return ""
    if not request.deviation.strip():
        raise StudyRuleError(f"cannot run {code}'s {why}; nothing was changed ({db_path}); give the reason with "
                             "--deviation to run it anyway (stored as a deviation)")
    return f"{why}: {request.deviation.strip()}"
