"""A participant's schedule of visits (:mod:`protocol.study.visits`) as the setup form shows it, and what a start of
one of its parts stores.

When the experimenter enters a participant (new or returning) in a study with ``[[visits]]``, the form shows each
visit -- its day and date window, its state (done / due today / overdue / not yet), its parts done and to do -- and
proposes the next (visit, part).  Nothing here decides a rule: the states and dates are
:func:`protocol.runner.visit_schedule.visit_schedule`'s (the dates count from the participant's first stored session,
in the machine's time zone), a visit the experimenter may not start without a reason is
:func:`~protocol.runner.visit_schedule.visit_refusal`'s, and the events a new session of a visit stores -- the study
day it is held on, the deviation with the reason -- are built by :mod:`study_app.headless.plan_visits`, as ``run
--visit`` builds them.  The engine applies the same rule again to the database before it stores the session
(:mod:`study_app.engine.visit_start`).
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from protocol.runner.study_rules import StoredSession
from protocol.runner.visit_schedule import (
    Schedule,
    VisitState,
    first_visit_date,
    held_day,
    visit_refusal,
    visit_schedule,
)
from protocol.study.config import ProtocolConfig
from study_app.headless.plan_visits import VisitRequest, request_day, visit_deviation, visit_step

__all__ = ["ScheduleForm", "VisitRow", "visit_events"]

#: How a visit's state reads in the schedule view.
STATE_WORDS = {"done": "done", "due": "due today", "overdue": "overdue", "not yet": "not yet"}
#: How a part's state reads in it.
_PART_WORDS = {"completed": "done", "interrupted": "interrupted (resume it)", "ended": "ended early", "to do": "to do"}


@dataclass(frozen=True, slots=True)
class VisitRow:
    """One visit of a participant's schedule as the view lists it; ``proposed``: the part the form proposes in it
    ("" when the next (visit, part) is in another visit)."""

    visit: VisitState
    proposed: str = ""

    def text(self, today: _dt.date | None = None) -> str:
        """The row in words, short enough for the form's column: ``▶ 2. post, day 7 ± 1 (4–6 Dec): due today — test
        to do`` (a date in another year than ``today``'s -- default: today -- with its year)."""
        v = self.visit
        mark = "▶" if self.proposed else ("✓" if v.state == "done" else "•")
        window = f" ± {v.window_days}" if v.window_days else ""
        parts = ", ".join(f"{p} {_PART_WORDS[s]}" for p, s in v.parts)
        dates = _dates(v, today or _dt.date.today())
        return f"{mark} {v.number}. {v.name}, day {v.day}{window}{dates}: {STATE_WORDS[v.state]} — {parts}"


_MONTHS = ("Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec")


def _date(d: _dt.date, today: _dt.date, month: bool = True) -> str:
    """``6 Dec`` (``6`` without the ``month``), ``6 Dec 2027`` in another year than ``today``'s."""
    if not month:
        return f"{d.day}"
    return f"{d.day} {_MONTHS[d.month - 1]}" + (f" {d.year}" if d.year != today.year else "")


def _dates(v: VisitState, today: _dt.date) -> str:
    """The visit's date, or its window's first and last (`` (4–6 Dec)``); "" before the participant's first visit
    (the dates count from it)."""
    lo, hi = v.earliest, v.latest
    if lo is None or hi is None:
        return ""
    if lo == hi:
        return f" ({_date(lo, today)})"
    same = (lo.year, lo.month) == (hi.year, hi.month)
    return f" ({_date(lo, today, month=not same)}–{_date(hi, today)})"


def visit_events(protocol: ProtocolConfig, known: Sequence[dict[str, Any]], code: str, number: int, seed: int,
                 visit: str, part: str, reason: str, db_path: str) -> tuple[tuple[str, str], ...]:
    """The events a new session of ``part`` in ``visit`` stores at session time 0, built as ``run --visit`` builds
    them (:func:`~study_app.headless.plan_visits.visit_step`, held today): the study day it is held on and, for a
    visit out of order or outside its window, the deviation ``"<rule's words>: <reason>"``.  Raises
    :class:`protocol.runner.study_rules.StudyRuleError` (one line) when the rule refuses it and ``reason`` is empty."""
    run_part = protocol.part_of(part, number, seed, visit)
    request = VisitRequest(visit, None, reason)
    rules = [StoredSession.of(s) for s in known]
    day = request_day(request, run_part, rules, code, _dt.date.today())
    deviation = visit_deviation(protocol, number, seed, rules, code, rules, request, day, db_path)
    return visit_step(run_part, request, day, deviation, how="started in the GUI").events


@dataclass
class ScheduleForm:
    """The form's participant's schedule (None: no schedule of visits, or no code) and why the form's visit may not
    start without the experimenter's reason (``refusal``, "" when it may)."""

    schedule: Schedule | None = None
    code: str = ""
    #: Today's study day for the participant (0 before their first visit).
    day: int = 0
    refusal: str = ""
    #: The visits' names and each visit's parts (the participant's order within it), for the form's fields.
    parts_of: dict[str, tuple[str, ...]] = field(default_factory=dict)

    def update(self, protocol: ProtocolConfig | None, known: Sequence[dict[str, Any]], code: str, number: int,
               seed: int, visit: str) -> None:
        """Recompute from the listed sessions; ``visit``: the one the form would start."""
        self.schedule, self.code, self.day, self.refusal, self.parts_of = None, code, 0, "", {}
        if protocol is None or not protocol.visits:
            return
        plan = protocol.plan_for(max(number, 1), max(seed, 0))
        for p in plan:
            if p.part is not None and p.part.visit is not None:
                self.parts_of[p.part.visit.name] = (*self.parts_of.get(p.part.visit.name, ()), p.part.name)
        if not code:
            return
        today = _dt.date.today()
        first = first_visit_date([StoredSession.of(s) for s in known], code)
        self.schedule = visit_schedule(protocol, max(number, 1), max(seed, 0), [StoredSession.of(s) for s in known],
                                       code, first, today)
        self.day = held_day(first, today)
        if visit in self.parts_of and self.schedule.visit(visit).state != "done":
            self.refusal = visit_refusal(self.schedule, visit, self.day)

    @property
    def next(self) -> tuple[str, str] | None:
        """The (visit, part) the participant does next (None: no schedule, or it is done)."""
        return None if self.schedule is None else self.schedule.next

    def first_left(self, visit: str) -> str:
        """The first part of ``visit`` not done yet in the participant's order (its first part when all are)."""
        parts = self.parts_of.get(visit, ())
        if self.schedule is not None and visit in self.parts_of:
            left = [p for p, s in self.schedule.visit(visit).parts if s in ("interrupted", "to do")]
            if left:
                return left[0]
        return parts[0] if parts else ""

    def rows(self) -> list[VisitRow]:
        """Each visit with its state, the proposed one marked."""
        if self.schedule is None:
            return []
        coming = self.next
        return [VisitRow(v, coming[1] if coming is not None and coming[0] == v.name else "")
                for v in self.schedule.visits]

    def words(self) -> str:
        """The line above the schedule: where the participant is (``P01: first visit 2026-11-28, today study day 8;
        1 of 4 visits done; next: post — test (due today)``)."""
        sched = self.schedule
        if sched is None:
            return ""
        first = ("no visit yet: the first is due today" if sched.first is None else
                 f"first visit {_date(sched.first, _dt.date.today())}, today study day {self.day}")
        done = sum(v.state == "done" for v in sched.visits)
        coming = self.next
        tail = ("the schedule is done" if coming is None else
                f"next: {coming[0]} — {coming[1]} ({STATE_WORDS[sched.visit(coming[0]).state]})")
        return f"{self.code}: {first}; {done} of {len(sched.visits)} visits done; {tail}"
