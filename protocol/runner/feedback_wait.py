"""The score card between two blocks: shown when a block of one haptic mode ends, the next cue held while it shows.

Where the protocol allows feedback (:mod:`protocol.study.feedback`, off by default), before each cue the runner asks
:meth:`FeedbackWait.holds` whether a block ended at that schedule position with no card shown yet: its card -- the
block's primary measures against the participant's own earlier sessions with the same mode
(:func:`protocol.study.feedback.score_card`) -- is stored as a ``feedback`` event (an intervention, in the record),
told to the listeners as ``("score_card", card)`` (the participant screen shows it) and the next cue waits the
card's ``show_s``.  A simulated participant is shown it as a person is (the event, the wait); a resumed session
shows no block's card twice.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from protocol.runner.session_desk import SessionDesk, SessionPlan
from protocol.storage import StudyDatabase
from protocol.storage.annotations import event_details
from protocol.study.design import TrialSpec
from protocol.study.feedback import FEEDBACK_EVENT, score_card, shown_blocks
from protocol.study.records import Outcome, TrialRecord

__all__ = ["FeedbackWait", "cards_shown", "earlier_trials"]

#: One earlier trial: (its session id, its haptic mode, its metrics by name, its outcome).
Earlier = tuple[int, str, dict[str, Any], str]


def earlier_trials(db: StudyDatabase, code: str, session_id: int) -> tuple[Earlier, ...]:
    """The participant's finished trials in their sessions before ``session_id`` (any kind; aborted ones left out):
    what a score card compares a block with."""
    out: list[Earlier] = []
    for info in db.sessions_of(code):
        if info.session_id >= session_id:
            continue
        for row in db.trial_rows(info.session_id):
            r = TrialRecord.from_row(row)
            if r.outcome is not Outcome.ABORTED:
                out.append((info.session_id, str(r.haptic_mode), dict(r.metrics), str(r.outcome)))
    return tuple(out)


def cards_shown(db: StudyDatabase, session_id: int) -> tuple[str, ...]:
    """The blocks (haptic modes) a session has shown its score card for (a resume shows none twice)."""
    return tuple(sorted(shown_blocks(event_details(db.conn, session_id, FEEDBACK_EVENT))))


class FeedbackWait:
    """Which blocks' cards a session has shown, and until when the next cue waits for one."""

    def __init__(self, desk: SessionDesk, plan: SessionPlan) -> None:
        self.desk = desk
        self.on = plan.score_cards
        self.show_ns = int(round(plan.protocol.feedback.show_s * 1e9))
        self.metrics = plan.protocol.task.metrics
        self.earlier = plan.earlier
        self.shown: set[str] = set(plan.cards_shown)
        self._until_ns: int | None = None

    def holds(self, t_ns: int, position: int, schedule: Sequence[TrialSpec], finished: Sequence[TrialRecord]) -> bool:
        """Whether the next cue (or the session's end) waits for a score card: shown here when a block ended before
        ``position`` and has none yet, then held for its ``show_s``."""
        if not self.on or position <= 0:
            return False
        if self._until_ns is not None:
            if t_ns < self._until_ns:
                return True
            self._until_ns = None
            self.desk.state.waiting = ""
            return False
        mode = str(schedule[position - 1].haptic_mode)
        block_ends = position == len(schedule) or str(schedule[position].haptic_mode) != mode
        if not block_ends or mode in self.shown:
            return False
        start = position - 1
        while start > 0 and str(schedule[start - 1].haptic_mode) == mode:
            start -= 1
        indices = {s.index for s in schedule[start:position]}
        mine = [(dict(r.metrics), str(r.outcome)) for r in finished
                if r.trial_index in indices and r.outcome is not Outcome.ABORTED]
        card = score_card(self.metrics, mode, mine, [(sid, m, o) for sid, md, m, o in self.earlier if md == mode])
        self.shown.add(mode)
        self.desk.event(t_ns, FEEDBACK_EVENT, card.detail())
        self.desk.emit(("score_card", card))
        self.desk.state.waiting = f"score card after the haptics {mode.upper()} block"
        self._until_ns = t_ns + self.show_ns
        return True
