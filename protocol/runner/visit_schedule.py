"""Where a participant is in a schedule of visits (:mod:`protocol.study.visits`): each visit's state and date, the
next (visit, part) to run, and the rules a visit run out of order or outside its window breaks.

The API the GUI's schedule view and ``haptic-study run --visit`` share::

    sched = visit_schedule(protocol, number, seed, stored_sessions(db), code, first_visit_date(infos, code), today)
    for v in sched.visits:            # VisitState: name, number, day, window_days, role, state, earliest, latest,
        ...                           #   parts ((part, state) in the participant's order)
    sched.next                        # (visit name, part name) to run next, or None when the schedule is done
    why = visit_refusal(sched, "post", held_day)   # "" when the visit may start on that study day

**Dates.**  A visit's days count from the participant's first visit: its date is the *local* calendar date of the
participant's first stored session (``started_at``, UTC, in the machine's time zone) plus the visit's day, and it
may be held from ``day − window_days`` to ``day + window_days``.  Before the first visit, the first visit is due
today and the others' dates are not known yet.

**States.**  ``done``: every part of the visit completed or ended by the experimenter; otherwise ``due`` (today is in
its window), ``overdue`` (the window has passed) or ``not yet`` (the window has not begun, or the first visit is
not made yet).  A visit partly made keeps its date's state; its parts' states say which are done.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Sequence
from dataclasses import dataclass

from protocol.runner.study_rules import StoredSession, part_states
from protocol.storage import SessionInfo
from protocol.study.config import ProtocolConfig

__all__ = ["VISIT_EVENT", "Schedule", "VisitState", "first_visit_date", "held_day", "visit_refusal",
           "visit_schedule"]

#: The ``events.kind`` storing, at session time 0 of each session of a visit, the study day it was held on.
VISIT_EVENT = "visit"
#: What a visit may be.
VISIT_STATES = ("done", "due", "overdue", "not yet")


@dataclass(frozen=True, slots=True)
class VisitState:
    """One visit of a participant's schedule and where they are in it."""

    name: str
    number: int
    day: int
    window_days: int
    role: str
    state: str  # one of VISIT_STATES
    earliest: _dt.date | None  # the window's first date (None before the first visit)
    latest: _dt.date | None
    parts: tuple[tuple[str, str], ...]  # (part, its state: completed / interrupted / ended / to do)


@dataclass(frozen=True, slots=True)
class Schedule:
    """A participant's schedule: the date of their first visit (None before it), the visits, what runs next."""

    first: _dt.date | None
    visits: tuple[VisitState, ...]
    next: tuple[str, str] | None

    def visit(self, name: str) -> VisitState:
        """The visit ``name`` (:class:`KeyError` naming the visits)."""
        for v in self.visits:
            if v.name == name:
                return v
        raise KeyError(f"no visit {name!r}: the visits are {', '.join(v.name for v in self.visits)}")


def first_visit_date(sessions: Sequence[SessionInfo | StoredSession], code: str) -> _dt.date | None:
    """The local date of ``code``'s first stored session (None when they have none)."""
    starts = [s.started_at for s in sessions if s.code == code and s.started_at]
    if not starts:
        return None
    return _dt.datetime.fromisoformat(min(starts)).astimezone().date()


def held_day(first: _dt.date | None, today: _dt.date) -> int:
    """The study day ``today`` is for a participant whose first visit was on ``first`` (0 before it)."""
    return 0 if first is None else (today - first).days


def visit_schedule(protocol: ProtocolConfig, number: int, seed: int, sessions: Sequence[StoredSession], code: str,
                   first: _dt.date | None, today: _dt.date) -> Schedule:
    """Participant ``code`` (number ``number``)'s schedule on ``today`` (module docstring); ``first``: the date of
    their first visit (:func:`first_visit_date`)."""
    if not protocol.visits:
        raise ValueError(f"protocol {protocol.name!r} has no [[visits]]: a study done in one visit has no schedule")
    states = part_states(sessions, code, protocol.plan_for(number, seed))
    out: list[VisitState] = []
    following: tuple[str, str] | None = None
    for i, v in enumerate(protocol.visits, start=1):
        mine = [(p.part.name, state) for p, state, _ in states
                if p.part is not None and p.part.visit is not None and p.part.visit.name == v.name]
        left = [name for name, state in mine if state in ("interrupted", "to do")]
        if left and following is None:
            following = (v.name, left[0])
        lo = None if first is None else first + _dt.timedelta(days=v.day - v.window_days)
        hi = None if first is None else first + _dt.timedelta(days=v.day + v.window_days)
        if not left:
            state = "done"
        elif lo is None or hi is None:
            state = "due" if i == 1 else "not yet"
        else:
            state = "not yet" if today < lo else ("overdue" if today > hi else "due")
        out.append(VisitState(v.name, i, v.day, v.window_days, v.role, state, lo, hi, tuple(mine)))
    return Schedule(first, tuple(out), following)


def visit_refusal(schedule: Schedule, name: str, day: int) -> str:
    """Why the visit ``name`` may not be held on study day ``day`` without a recorded deviation ("" when it may):
    done already, an earlier visit not done (out of order), or ``day`` outside its window."""
    v = schedule.visit(name)
    if v.state == "done":
        return f"visit {name!r} is done (every part of it completed or ended): it is not run again"
    earlier = [e.name for e in schedule.visits if e.number < v.number and e.state != "done"]
    if earlier:
        return f"visit {name!r} is out of order: the earlier visit {earlier[0]!r} is not done"
    if abs(day - v.day) > v.window_days:
        return (f"visit {name!r} is outside its window: held on study day {day}, planned for day {v.day} "
                f"± {v.window_days}")
    return ""
