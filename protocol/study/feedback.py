"""Feedback to the trainee: a score card after a block, where the protocol allows it (off by default; issue 44).

Declared in the protocol file's ``[feedback]`` table::

    [feedback]
    score_card = true                     # a score card after each block of one haptic mode (default false)
    show_s = 6.0                          # how long it stays on the participant screen before the next cue
    sessions = ["training", "experiment"] # in which sessions (default: both)

After the last trial of each block of one haptic mode (an ordering by mode is needed, as for a questionnaire after a
block: ``blocked_by_mode`` or ``counterbalanced``) the participant screen shows the block's primary measures -- for
the paper's task its success rate, TCT, RMSE and Max AE -- each against the same measure in the participant's own
earlier sessions with the same haptic mode, and whether it is better (:func:`score_card`).  The next cue waits
``show_s``.  Feedback is an intervention: each card shown is stored as a ``feedback`` event (:data:`FEEDBACK_EVENT`,
its detail the card), the protocol with the session, and the report's methods say it was given.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from pipeline.settings.tomlfields import Fields
from protocol.metrics import Metric, primary

__all__ = ["FEEDBACK_EVENT", "FeedbackConfig", "ScoreCard", "feedback_from_table", "score_card", "shown_blocks"]

#: The ``events.kind`` of a score card shown (its detail begins ``BLOCK:``, the block's haptic mode).
FEEDBACK_EVENT = "feedback"
_KINDS = ("training", "experiment")
_BY_MODE = ("blocked_by_mode", "counterbalanced")


@dataclass(frozen=True, slots=True)
class FeedbackConfig:
    """What feedback the protocol allows: none by default."""

    score_card: bool = False
    show_s: float = 6.0
    sessions: tuple[str, ...] = _KINDS

    def in_session(self, kind: str) -> bool:
        """Whether a session of ``kind`` shows score cards."""
        return self.score_card and kind in self.sessions

    def to_dict(self) -> dict[str, Any] | None:
        """As stored with the protocol (None when off: a protocol without feedback stores what it stored before)."""
        return None if not self.score_card else {"score_card": True, "show_s": self.show_s,
                                                 "sessions": list(self.sessions)}


def feedback_from_table(f: Fields, top: Mapping[str, Any], ordering: str) -> FeedbackConfig:
    """The protocol file's ``[feedback]`` (absent: off), checked (one line naming the field)."""
    t = f.section(dict(top), "feedback", {"score_card", "show_s", "sessions"})
    card = f.boolean("feedback.score_card", t.get("score_card", False))
    show_s = f.number("feedback.show_s", t.get("show_s", 6.0), lo=1.0, hi=60.0, lo_open=False)
    kinds = t.get("sessions", list(_KINDS))
    if not isinstance(kinds, list) or not kinds or any(k not in _KINDS for k in kinds) or len(set(kinds)) != len(kinds):
        raise f.fail("feedback.sessions", kinds, "must be a non-empty list of distinct values from 'training', "
                                                 "'experiment'")
    if card and ordering not in _BY_MODE:
        raise f.fail("feedback.score_card", card, f"a card after each block of one haptic mode needs "
                                                  f"design.ordering = 'blocked_by_mode' or 'counterbalanced' (it is "
                                                  f"{ordering!r})")
    return FeedbackConfig(card, show_s, tuple(kinds))


@dataclass(frozen=True, slots=True)
class ScoreCard:
    """One block's card: per measure (its label, the block's value, the earlier sessions' value -- None: no earlier
    session, NaN: none with a value --, whether the block's is better, None: not comparable), with the block's mode
    and the earlier sessions counted."""

    block: str
    rows: tuple[tuple[str, float, float | None, bool | None], ...]
    n_trials: int
    n_earlier: int

    def lines(self) -> tuple[str, ...]:
        """The card in words, a line per measure (the participant screen's)."""
        out = []
        for label, now, before, better in self.rows:
            was = "no earlier session" if before is None else f"your earlier sessions {_fmt(label, before)}"
            mark = "" if better is None else ("  ▲ better" if better else "  ▼ not better")
            out.append(f"{label}: {_fmt(label, now)}   ({was}){mark}")
        return tuple(out)

    def detail(self) -> str:
        """The stored event's detail: ``BLOCK:`` (read back by :func:`shown_blocks`), then the card."""
        earlier = f"{self.n_earlier} earlier session{'' if self.n_earlier == 1 else 's'}"
        return (f"{self.block}: score card after the haptics {self.block.upper()} block ({self.n_trials} trials; "
                f"{earlier}): " + "; ".join(self.lines()))


def _fmt(label: str, v: float) -> str:
    if not math.isfinite(v):
        return "–"
    return f"{v:.0%}" if "rate" in label else f"{v:.3g}"


def _value(m: Metric, row: Mapping[str, Any], outcome: str) -> float:
    """One trial's value of ``m`` (a yes/no outcome from the trial's outcome; a failure's TCT: NaN)."""
    if m.boolean:
        return 1.0 if outcome == "success" else 0.0
    v = row.get(m.name)
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan


def _mean(values: Sequence[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return sum(finite) / len(finite) if finite else math.nan


def score_card(metrics: Sequence[Metric], block: str, trials: Sequence[tuple[Mapping[str, Any], str]],
               earlier: Sequence[tuple[int, Mapping[str, Any], str]]) -> ScoreCard:
    """The card of a block's finished ``trials`` ((metrics by name, outcome) each) against the participant's
    ``earlier`` trials with the same mode ((session id, metrics, outcome) each): per primary measure of the task,
    the block's mean (a yes/no outcome: its rate) and the earlier trials' (None: none), and whether the block's is
    better by the measure's own direction (:attr:`protocol.metrics.Metric.better`)."""
    rows = []
    for m in primary(metrics):
        now = _mean([_value(m, r, o) for r, o in trials])
        before = _mean([_value(m, r, o) for _, r, o in earlier]) if earlier else None
        better: bool | None = None
        if before is not None and math.isfinite(now) and math.isfinite(before) and now != before:
            better = {"higher": now > before, "lower": now < before}.get(m.better, abs(now - 1) < abs(before - 1))
        rows.append((m.label, now, before, better))
    return ScoreCard(block, tuple(rows), len(trials), len({sid for sid, _, _ in earlier}))


def shown_blocks(details: Iterable[str]) -> set[str]:
    """The blocks a session has shown its card for, from its ``feedback`` events' details (a resume shows none
    twice)."""
    return {d.split(":", 1)[0] for d in details if ":" in d}
