"""A questionnaire on the participant screen: one question a page, answered by mouse or keyboard, then sent.

When the engine says a questionnaire is due (:class:`study_app.engine.messages.QuestionnaireShown`), the
participant screen shows its questions one at a time: a NASA-TLX rating on its 21-mark scale (0–100, steps of 5),
one of its 15 pairs (which of two contributed more to the workload), or a Likert item on its own scale.  The keys:
Left/Right move a rating (or choose the left/right of a pair, 1/2 too), a digit picks a Likert point, Enter goes on
once the question is answered, Backspace goes back.  The last page sends the answers
(:class:`study_app.engine.messages.AnswerQuestionnaire`); the screen then waits for the engine to store them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from protocol.study import tlx
from protocol.study.questionnaires import SESSION, Item, Questionnaire
from study_app.engine import messages as m
from study_app.models import Emitter

__all__ = ["QuestionnaireModel"]


@dataclass
class QuestionnaireModel:
    """The questionnaire the participant answers now (None: none), its page and its answers."""

    session_id: int = 0
    questionnaire: Questionnaire | None = None
    block: str = ""
    page: int = 0
    answers: dict[str, float | str] = field(default_factory=dict)
    #: The answers were sent; the screen waits for the engine to store them.
    sent: bool = False
    #: Why the engine refused the answers ("" none): shown to the experimenter, the pages kept.
    refused: str = ""
    #: Sends a command to the engine (the app's :class:`study_app.models.notices.Commands`).
    send: Callable[[object], bool] | None = None
    changed: Emitter = field(default_factory=Emitter)

    # -- what is shown -------------------------------------------------------------------------------------
    @property
    def active(self) -> bool:
        """A questionnaire is on the participant screen."""
        return self.questionnaire is not None

    @property
    def questions(self) -> tuple[Item, ...]:
        return self.questionnaire.questions() if self.questionnaire is not None else ()

    @property
    def item(self) -> Item | None:
        """The question on the page (None: the last page, which sends the answers)."""
        qs = self.questions
        return qs[self.page] if self.page < len(qs) else None

    def heading(self) -> str:
        """What the questionnaire is about, for the participant."""
        if self.questionnaire is None:
            return ""
        about = "the whole session" if self.block == SESSION else "the block of trials you have just finished"
        kind = "Workload" if self.questionnaire.kind == "nasa_tlx" else "A few questions"
        return f"{kind}: about {about}"

    def position(self) -> str:
        """``Question 3 of 21`` (or the last page's words)."""
        n = len(self.questions)
        return f"Question {self.page + 1} of {n}" if self.page < n else f"All {n} questions answered"

    def instruction(self) -> str:
        """How to answer the page's question."""
        item = self.item
        if item is None:
            return "Press Enter or Submit to send your answers (Backspace goes back to change one)."
        if item.pair is not None:
            return ("Which of the two contributed more to the workload of the task? Click it, or press ← / → "
                    "(or 1 / 2).")
        return "Click on the scale, or move with ← / →; then Enter or Next."

    def value(self) -> float | str | None:
        """The page's answer so far (None: not answered)."""
        item = self.item
        return None if item is None else self.answers.get(item.id)

    def scale(self) -> tuple[int, int, int, str, str]:
        """The page's scale: (lowest, highest, step, low end's words, high end's words)."""
        item = self.item
        if item is None or item.pair is not None:
            return (0, 0, 1, "", "")
        if item.scale is not None:
            return (item.scale.lo, item.scale.hi, 1, item.scale.low, item.scale.high)
        sub = next(s for s in tlx.SUBSCALES if s.id == item.id)
        return (0, tlx.RATING_MAX, tlx.RATING_STEP, sub.low, sub.high)

    def title(self) -> str:
        """The page's question's title: a NASA-TLX subscale's name, else ""."""
        item = self.item
        if item is None or item.pair is not None or item.scale is not None:
            return ""
        return next(s.name for s in tlx.SUBSCALES if s.id == item.id)

    def pair_names(self) -> tuple[str, str]:
        """A pair page's two subscales, by name (("", "") on another page)."""
        item = self.item
        if item is None or item.pair is None:
            return ("", "")
        names = {s.id: s.name for s in tlx.SUBSCALES}
        return names[item.pair[0]], names[item.pair[1]]

    # -- what the participant does -----------------------------------------------------------------------
    def apply(self, ev: object) -> None:
        """Engine events: a questionnaire shown, its answers stored, a session's start or end."""
        if isinstance(ev, m.QuestionnaireShown):
            self.session_id, self.questionnaire, self.block = ev.session_id, ev.questionnaire, ev.block
            self.page, self.answers, self.sent, self.refused = 0, {}, False, ""
        elif isinstance(ev, (m.QuestionnaireAnswered, m.SessionStarted, m.SessionEnded)):
            if self.questionnaire is None:
                return
            self.questionnaire, self.sent, self.refused = None, False, ""
        elif isinstance(ev, m.CommandRefused) and ev.command == "AnswerQuestionnaire" and self.sent:
            self.sent, self.refused = False, ev.message
        else:
            return
        self.changed.emit()

    def set_value(self, v: float | str) -> None:
        """Answer the page's question (a rating, a Likert point, a pair's chosen subscale id)."""
        item = self.item
        if item is None or self.sent:
            return
        self.answers[item.id] = v
        self.changed.emit()

    def step(self, direction: int) -> None:
        """← / →: a rating one step down or up (from the middle when not answered yet); a pair: choose its left
        or right subscale and go on."""
        item = self.item
        if item is None or self.sent:
            return
        if item.pair is not None:
            self.set_value(item.pair[0 if direction < 0 else 1])
            self.next()
            return
        lo, hi, step, _, _ = self.scale()
        now = self.value()
        mid = lo + step * round((hi - lo) / 2 / step)
        v = float(mid) if not isinstance(now, float) else min(max(now + direction * step, lo), hi)
        self.set_value(float(v))

    def next(self) -> None:
        """Enter / Next: on to the next page once the question is answered."""
        if self.item is not None and self.value() is not None:
            self.page += 1
            self.changed.emit()

    def back(self) -> None:
        """Backspace / Back: the page before."""
        if self.page > 0 and not self.sent:
            self.page -= 1
            self.changed.emit()

    def skip(self, reason: str = "") -> bool:
        """The experimenter skips the questionnaire on the participant screen (stored as skipped, a deviation, with
        ``reason``); False when nothing was sent (none is waiting, or its answers are on their way)."""
        q = self.questionnaire
        if q is None or self.sent or self.send is None:
            return False
        return self.send(m.SkipQuestionnaire(self.session_id, q.name, self.block, reason.strip()))

    def submit(self) -> bool:
        """Send the answers (the last page only); False when they were not sent."""
        q = self.questionnaire
        if q is None or self.item is not None or self.sent or self.send is None:
            return False
        self.sent = self.send(m.AnswerQuestionnaire(self.session_id, q.name, self.block, dict(self.answers)))
        self.refused = ""
        self.changed.emit()
        return self.sent
