"""A participant's plan in a study of several parts (:mod:`protocol.study.parts`), as the setup form shows it.

The experimenter sees each part in the participant's order -- done, interrupted, ended early, to do -- and which
comes next; the form proposes that part (its kind follows: a training part is a training session) until the
experimenter picks another.  The rules are :mod:`protocol.runner.study_rules`' (:func:`part_states`,
:func:`next_part`), the ones ``run`` and the engine apply.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from protocol.runner.study_rules import StoredSession, next_part, part_states
from protocol.study.config import ProtocolConfig

__all__ = ["PlanRow", "next_part_name", "plan_rows", "plan_words"]

#: How each state reads in the plan view.
_STATE_WORDS = {"completed": "done", "interrupted": "interrupted: resume it", "ended": "ended early",
                "to do": "to do"}


@dataclass(frozen=True, slots=True)
class PlanRow:
    """One part of a participant's plan as the view lists it."""

    position: int
    name: str
    kind: str
    task: str
    state: str
    session_id: int | None
    next: bool

    def text(self) -> str:
        """The row in words: ``2. tracking — force tracking, experiment: done (session 5)``."""
        where = f" (session {self.session_id})" if self.session_id is not None else ""
        mark = "▶ " if self.next else ""
        return f"{mark}{self.position}. {self.name} — {self.task}, {self.kind}: {_STATE_WORDS[self.state]}{where}"


def _plan(protocol: ProtocolConfig, number: int, seed: int) -> tuple[ProtocolConfig, ...]:
    return protocol.plan_for(max(number, 1), max(seed, 0))


def plan_rows(protocol: ProtocolConfig | None, sessions: Sequence[StoredSession], code: str, number: int,
              seed: int) -> list[PlanRow]:
    """Participant ``code`` (number ``number``)'s parts in their order with their state; [] for a study of one task
    (or no protocol)."""
    if protocol is None or not protocol.parts:
        return []
    parts = _plan(protocol, number, seed)
    coming = next_part(sessions, code, parts) if code else None
    following = None if coming is None else coming[0].part
    rows = []
    for part, state, session in part_states(sessions, code, parts):
        assert part.part is not None
        rows.append(PlanRow(part.part.position, part.part.name, part.part.session, part.task.title.lower(), state,
                            None if session is None else session.session_id,
                            following is not None and following.name == part.part.name))
    return rows


def next_part_name(protocol: ProtocolConfig | None, sessions: Sequence[StoredSession], code: str, number: int,
                   seed: int) -> str:
    """The part participant ``code`` does next ("" for a study of one task, or when their plan is done)."""
    if protocol is None or not protocol.parts:
        return ""
    coming = next_part(sessions, code, _plan(protocol, number, seed))
    return "" if coming is None or coming[0].part is None else coming[0].part.name


def plan_words(rows: Sequence[PlanRow], code: str) -> str:
    """A line above the plan: how far ``code`` is (``P03: 2 of 4 parts done; next: tracking``)."""
    if not rows or not code:
        return ""
    done = sum(r.state in ("completed", "ended") for r in rows)
    coming = next((r for r in rows if r.next), None)
    tail = f"next: {coming.name}" if coming is not None else "the plan is done"
    return f"{code}'s plan: {done} of {len(rows)} parts done; {tail}"
