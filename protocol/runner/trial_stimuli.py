"""The trials of a task that presents a force and asks about it (force discrimination): each trial's stimulus chosen
at its cue from the answers so far, rendered by the loop, and its answer stored with the trial.

At the cue the task's procedure (:meth:`protocol.tasks.base.Task.stimulus_procedure`, rebuilt from the session's stored
answers: a resumed block continues where it stopped) gives the trial's :class:`protocol.tasks.base.Stimulus`; its
force program goes to the loop with the trial's mark (:class:`pipeline.runtime.loop_messages.CommandForce`: the
same tick, so the program's time is the trial's), and back to the sensor's force when the trial ends.  While the
trial runs, the force the loop rendered (the records' ``render_*``) is kept; when the question is asked, a simulated
participant answers from it (:class:`pipeline.core.aim.AnsweringParticipant`), a person from the participant
screen.  The finished trial's answer and the procedure's values are one :class:`protocol.storage.trial_answers.
TrialAnswer`, stored in the trial's transaction.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from pipeline.core.aim import AnsweringParticipant, TrialParticipant, TrialQuestion
from pipeline.runtime.loop_messages import Command, CommandForce
from protocol.storage.trial_answers import TrialAnswer
from protocol.study.design import TrialSpec
from protocol.study.records import Outcome
from protocol.study.trial import TrialFinished
from protocol.tasks.base import Answered, Procedure, Stimulus, Task

__all__ = ["TrialStimuli"]


class TrialStimuli:
    """One session's stimuli and answers (module docstring); inert for a task that presents none."""

    def __init__(self, task: Task, seed: int, session_id: int, history: tuple[Answered, ...],
                 submit: Callable[[Command], None], participant: TrialParticipant | None) -> None:
        self.task, self.session_id, self.submit = task, session_id, submit
        self.procedure: Procedure | None = task.stimulus_procedure(seed, session_id, history)
        self.answerer = participant if isinstance(participant, AnsweringParticipant) else None
        self.stimulus: Stimulus | None = None
        self._t: list[np.ndarray] = []
        self._f: list[np.ndarray] = []

    def cue(self, spec: TrialSpec) -> None:
        """The trial's stimulus, chosen now; its force commanded from the trial's first tick."""
        if self.procedure is None:
            return
        self.stimulus = self.procedure.next(spec, spec.index)
        self._t, self._f = [], []
        self.submit(CommandForce(self.stimulus.program))

    def note(self, rows: np.ndarray, trial_index: int) -> None:
        """The rendered force of the running trial's records."""
        if self.stimulus is None:
            return
        mine = rows[rows["trial_index"] == trial_index]
        if len(mine):
            self._t.append(mine["t_ns"].astype(np.int64))
            self._f.append(np.hypot(np.hypot(mine["render_fx"], mine["render_fy"]), mine["render_fz"]))

    def _rendered(self, cue_ns: int) -> tuple[np.ndarray, np.ndarray]:
        if not self._t:
            return np.empty(0), np.empty(0)
        return (np.concatenate(self._t) - cue_ns) / 1e9, np.concatenate(self._f)

    def simulated_answer(self, spec: TrialSpec, cue_ns: int) -> str | None:
        """What the simulated participant answers (None: a person answers, or the task asks nothing)."""
        if self.answerer is None or self.stimulus is None:
            return None
        t_s, f = self._rendered(cue_ns)
        return self.answerer.answer(TrialQuestion(self.task.felt(t_s, f), self.task.answer_keys, spec.index))

    def finished(self, ev: TrialFinished, answered_at_s: float | None) -> TrialAnswer | None:
        """The trial ended: the sensor's force again; its answer and values (None: nothing to store)."""
        stim, self.stimulus = self.stimulus, None
        if stim is None:
            return None
        self.submit(CommandForce(None))
        if self.procedure is None or ev.outcome is Outcome.ABORTED:
            return None  # aborted: no answer stored (its re-run asks again)
        t_s, f = self._rendered(ev.cue_ns)
        values = self.procedure.answered(ev.spec, stim, ev.answer, t_s, f)
        return TrialAnswer(self.session_id, ev.spec.index, ev.answer,
                           answered_at_s if ev.answer is not None else None,
                           {k: float(v) if math.isfinite(float(v)) else math.nan for k, v in values.items()})
