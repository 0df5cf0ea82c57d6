"""A visit's part started from the GUI (:mod:`protocol.study.visits`): the schedule's rule, applied by the engine to
what is stored before the session is, as ``run --visit`` applies it.

The setup form (:mod:`study_app.models.schedule`) proposes the participant's next (visit, part) and builds the events
a new session of it stores -- the study day it is held on and, for a visit out of order or outside its window, the
deviation with the experimenter's reason -- with the functions ``run --visit`` uses.  The engine, the one writer,
checks the command against the database as it is now (another window may have run the visit since the form was
filled): a visit the rule refuses (:func:`protocol.runner.visit_schedule.visit_refusal`) does not start without that
deviation, and a visit's session always says the day it was held on.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Sequence

from protocol.runner.study_rules import DEVIATION_EVENT, StoredSession, StudyRuleError
from protocol.runner.visit_schedule import VISIT_EVENT, first_visit_date, held_day, visit_refusal, visit_schedule
from protocol.storage import SessionInfo
from protocol.study.config import ProtocolConfig
from study_app.engine import messages as m

__all__ = ["check_visit_start"]


def check_visit_start(cmd: m.StartSession, study: ProtocolConfig, sessions: Sequence[StoredSession],
                      infos: Sequence[SessionInfo], today: _dt.date | None = None) -> None:
    """Refuse (one line, nothing stored) a start of ``cmd.visit``'s part that the schedule of ``study`` (the whole
    protocol, not the part's) refuses without a deviation, or a visit's start without its events; ``sessions`` and
    ``infos``: the database's sessions (none for a new file)."""
    kinds = [kind for kind, _ in cmd.events]
    if not study.visits:
        if cmd.visit or cmd.events:
            raise ValueError(f"visit = {cmd.visit!r}: the protocol has no [[visits]] (a study done in one visit)")
        return
    unknown = [k for k in kinds if k not in (VISIT_EVENT, DEVIATION_EVENT)]
    if unknown or VISIT_EVENT not in kinds:
        raise ValueError(f"visit = {cmd.visit!r}: a visit's session stores the study day it is held on (a "
                         f"{VISIT_EVENT!r} event) and at most a deviation; given {kinds}")
    day = _dt.date.today() if today is None else today
    first = first_visit_date(infos, cmd.code)
    sched = visit_schedule(study, cmd.participant_number, cmd.seed, sessions, cmd.code, first, day)
    if sched.visit(cmd.visit).state == "done":
        return  # a part of it run again: the database refuses that itself, naming the session
    why = visit_refusal(sched, cmd.visit, held_day(first, day))
    if why and DEVIATION_EVENT not in kinds:
        raise StudyRuleError(f"cannot run {cmd.code}'s {why}; nothing was stored: start it with the reason, which is "
                             "stored as a deviation")
