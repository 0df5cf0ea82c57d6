"""The questionnaires between two trials: asked when due, the next cue held until they are answered.

Before each cue (and before the session's end) the runner asks :meth:`QuestionnaireWait.holds` whether a
questionnaire of the protocol is due there (:func:`protocol.study.questionnaires.due`: after a block of one haptic
mode, or after the last trial).  A simulated participant answers at once, by its documented rule
(:mod:`protocol.study.sim_answers`); a person answers on the participant screen, and the next cue waits: the runner
tells its listeners ``("questionnaire", prompt)`` once and stores a ``questionnaire`` event, and the answers come
back as a request (:meth:`protocol.runner.session.SessionRunner.answer`), checked, and stored together in one
transaction with their event (:meth:`QuestionnaireWait.answer`).  A resumed session asks nothing it has answers of.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from protocol.runner.session_desk import SessionDesk, SessionPlan
from protocol.storage.annotations import insert_answers
from protocol.study.design import TrialSpec
from protocol.study.questionnaires import (
    QUESTIONNAIRE_SKIPPED_EVENT,
    SESSION,
    Prompt,
    checked_answers,
    due,
    skip_detail,
)
from protocol.study.sim_answers import simulated_answers

__all__ = ["QuestionnaireWait", "prompt_words"]


def prompt_words(prompt: Prompt) -> str:
    """How the record and the displays name a prompt: *workload (NASA-TLX) after the haptics ON block*."""
    q = prompt.questionnaire
    after = "the session" if prompt.block == SESSION else f"the haptics {prompt.block.upper()} block"
    return f"{q.name} ({_KIND_WORDS.get(q.kind, q.kind)}) after {after}"


_KIND_WORDS = {"nasa_tlx": "NASA-TLX", "likert": "Likert items"}


class QuestionnaireWait:
    """Which questionnaires a session has asked and been answered, and the one it waits for.

    Parameters
    ----------
    desk
        The session's desk (its clock, events, listeners, the recorder).
    plan
        The run's plan: the protocol's questionnaires, those answered before (a resume) and who answers
        (``answers_seed``: the simulated participant's seed, or None for a person on the participant screen).
    """

    def __init__(self, desk: SessionDesk, plan: SessionPlan) -> None:
        self.desk = desk
        self.questionnaires = plan.protocol.questionnaires
        self.answered: set[tuple[str, str]] = set(plan.answered)
        self.answers_seed = plan.answers_seed
        #: The questionnaire shown on the participant screen and not yet answered (None: none).
        self.asked: Prompt | None = None

    def holds(self, t_ns: int, position: int, schedule: Sequence[TrialSpec]) -> bool:
        """Whether the next cue (or the session's end) waits for a questionnaire due before ``position``.

        A simulated participant's answers are stored here, at once; a person's prompt is shown (once) and held.
        """
        if not self.questionnaires:
            return False
        modes = [str(s.haptic_mode) for s in schedule]
        while (prompt := due(self.questionnaires, modes, position, self.answered)) is not None:
            if self.answers_seed is None:
                if self.asked != prompt:
                    self.asked = prompt
                    self.desk.state.waiting = f"questionnaire: {prompt_words(prompt)}"
                    self.desk.event(t_ns, "questionnaire", f"{prompt_words(prompt)}: shown on the participant screen")
                    self.desk.emit(("questionnaire", prompt))
                return True
            self._store(t_ns, prompt, simulated_answers(prompt, self.answers_seed), "the simulated participant")
        return False

    def answer(self, t_ns: int, name: str, block: str, answers: Mapping[str, float | str]) -> str:
        """Store the participant's answers to the questionnaire asked (in the caller's transaction); "" when stored,
        else why not (it was not the one asked; the answers do not fit its questions)."""
        asked = self.asked
        if asked is None or asked.key != (name, block):
            return f"answers to {name} ({block}) ignored: that questionnaire is not the one waiting for answers"
        try:
            checked = checked_answers(asked.questionnaire, answers)
        except ValueError as exc:
            return f"answers ignored: {exc}"
        self._store(t_ns, asked, checked, "the participant")
        self.asked = None
        self.desk.state.waiting = ""
        return ""

    def skip(self, t_ns: int, name: str, block: str, reason: str) -> str:
        """The experimenter skips the questionnaire waiting for the participant (in the caller's transaction): stored
        as skipped, a deviation (:data:`protocol.study.questionnaires.QUESTIONNAIRE_SKIPPED_EVENT`), and the next
        cue no longer waits; "" when skipped, else why not (it was not the one waiting)."""
        asked = self.asked
        if asked is None or asked.key != (name, block):
            return f"skip of {name} ({block}) ignored: that questionnaire is not the one waiting for answers"
        self.desk.event(t_ns, QUESTIONNAIRE_SKIPPED_EVENT, skip_detail(name, block, prompt_words(asked), reason))
        self.answered.add(asked.key)
        self.asked = None
        self.desk.state.waiting = ""
        self.desk.emit(("questionnaire_skipped", asked))
        return ""

    def _store(self, t_ns: int, prompt: Prompt, answers: Mapping[str, float | str], who: str) -> None:
        t_s = self.desk.time_s(t_ns)
        sid = self.desk.session_id
        name, block = prompt.key
        with self.desk.recorder.atomic():
            self.desk.recorder.call(lambda db: insert_answers(db.conn, sid, name, block, answers, t_s))
            self.desk.event(t_ns, "questionnaire", f"{prompt_words(prompt)}: answered by {who}")
        self.answered.add(prompt.key)
        self.desk.emit(("questionnaire_answered", prompt))
