"""The trial state machine: pure logic, no threads, no clock, no I/O.

It is fed the loop's samples in blocks -- timestamp, task force and the trial
mark the loop stamped on each -- and returns what happened.  Every decision
uses sample timestamps, so the outcome is the same whether the caller keeps up
at 1 kHz or catches up a second late.

Phases (bluesky-style explicit table)::

    IDLE ──start──► CUED ──first sample marked with the trial──► ACTIVE
    ACTIVE ──hold complete / 12 s / abort──► PAUSE ──2 s──► IDLE
    ACTIVE ──rule complete, a task that asks an answer──► ANSWER ──answer / its window over / abort──► PAUSE

The cue (the target word) is shown when the trial starts, and only then.  The
trial's time origin is the first sample the loop marked with the trial's
index: the loop applies the runner's mark command and the haptic mode at the
same tick, so t = 0 is the first sample recorded under the trial's condition.

What ends a trial early as a success is its task's rule (:meth:`protocol.tasks.base.Task.rule`, fed every sample);
the finished trial is judged again by the task's offline form (:meth:`protocol.tasks.base.Task.judge`), which
computes its metrics, and the two verdicts must agree.

A task that asks the participant a question (:attr:`protocol.tasks.base.Task.answer_keys`: force discrimination's
"which was stronger, 1 or 2?") is asked when its rule completes: the machine waits in ANSWER for
:meth:`TrialMachine.answer` until the task's answer window closes (:meth:`protocol.tasks.base.Task.answer_by_s`);
the trial's samples and metrics are those up to the question, its end the answer (or the window's end, with no
answer).  A key outside the task's is refused in one line (``ValueError``).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from enum import StrEnum
from typing import Final

from protocol.study.config import TrialTiming
from protocol.study.design import TrialSpec
from protocol.study.records import Outcome
from protocol.tasks.base import Task, TrialRule
from protocol.tasks.force_regulation import ForceRegulation
from protocol.tasks.window import TrialMetrics

__all__ = ["RUNNING", "TRANSITIONS", "PhaseChanged", "TrialFinished", "TrialMachine", "TrialMachineError",
           "TrialPhase"]


class TrialPhase(StrEnum):
    """Where the trial machine is."""

    IDLE = "idle"
    CUED = "cued"
    ACTIVE = "active"
    PAUSE = "pause"
    #: The trial's stimulus is over and its question asked: waiting for the participant's answer.
    ANSWER = "answer"


TRANSITIONS: Final[dict[TrialPhase, frozenset[TrialPhase]]] = {
    TrialPhase.IDLE: frozenset({TrialPhase.CUED}),
    TrialPhase.CUED: frozenset({TrialPhase.ACTIVE, TrialPhase.PAUSE}),
    TrialPhase.ACTIVE: frozenset({TrialPhase.PAUSE, TrialPhase.ANSWER}),
    TrialPhase.ANSWER: frozenset({TrialPhase.PAUSE}),
    TrialPhase.PAUSE: frozenset({TrialPhase.IDLE}),
}

#: The phases in which a trial runs (it may be aborted, its records are its own).
RUNNING: Final[frozenset[TrialPhase]] = frozenset({TrialPhase.CUED, TrialPhase.ACTIVE, TrialPhase.ANSWER})

#: Integer phase codes stamped into the loop's samples (the ``phase`` column).
PHASE_CODES: Final[dict[TrialPhase, int]] = {
    TrialPhase.IDLE: 0, TrialPhase.CUED: 1, TrialPhase.ACTIVE: 2, TrialPhase.PAUSE: 3, TrialPhase.ANSWER: 4,
}


class TrialMachineError(RuntimeError):
    """An illegal transition was requested (a bug in the caller)."""


@dataclass(frozen=True, slots=True)
class PhaseChanged:
    """The machine changed phase at sample time ``t_ns``."""

    t_ns: int
    trial_index: int
    old: TrialPhase
    new: TrialPhase


@dataclass(frozen=True, slots=True)
class TrialFinished:
    """A trial ended (the trial machine's event); times in ns on the loop clock."""

    spec: TrialSpec
    outcome: Outcome
    cue_ns: int
    end_ns: int
    metrics: TrialMetrics
    reason: str = ""
    #: The participant's answer (a task that asks one; None: none asked, or none given within its window).
    answer: str | None = None


class TrialMachine:
    """Runs one trial at a time and the pause after it.

    Parameters
    ----------
    timing
        The trial's cap and the pause after it.
    task
        What each trial asks and how it is judged (default: the paper's force regulation).
    sample_period_s
        Nominal sample period (for time in band).
    """

    def __init__(self, timing: TrialTiming, task: Task | None = None, sample_period_s: float = 0.001) -> None:
        self.timing = timing
        self.task: Task = task if task is not None else ForceRegulation()
        self.sample_period_s = sample_period_s
        self.phase = TrialPhase.IDLE
        self.spec: TrialSpec | None = None
        self.cue_ns: int | None = None
        self.pause_until_ns: int | None = None
        self._rule: TrialRule | None = None
        self._t: list[int] = []
        self._f: list[float] = []
        self._cap_ns = int(round(timing.max_trial_s * 1e9))
        self._pause_ns = int(round(timing.pause_s * 1e9))
        self._asks = bool(self.task.answer_keys)
        self._answer_by_ns = int(round(self.task.answer_by_s(timing.max_trial_s) * 1e9))

    def _go(self, new: TrialPhase, t_ns: int) -> PhaseChanged:
        if new not in TRANSITIONS[self.phase]:
            raise TrialMachineError(f"illegal trial transition {self.phase} → {new}")
        ev = PhaseChanged(t_ns, self.spec.index if self.spec else -1, self.phase, new)
        self.phase = new
        return ev

    @property
    def elapsed_ns(self) -> int:
        """Time since the cue of the newest sample seen in this trial (0 before it starts)."""
        return self._t[-1] if self._t else 0

    def start(self, spec: TrialSpec, t_ns: int) -> list[PhaseChanged]:
        """Cue the next trial (from IDLE). Its clock starts at its first marked sample."""
        if TrialPhase.CUED not in TRANSITIONS[self.phase]:  # refuse before touching the running trial
            raise TrialMachineError(f"illegal trial transition {self.phase} → {TrialPhase.CUED}")
        self.spec = spec
        ev = self._go(TrialPhase.CUED, t_ns)
        self.cue_ns = None
        self._rule = self.task.rule(spec)
        self._t = []
        self._f = []
        return [ev]

    def feed(self, samples: Iterable[tuple[int, float, int]]) -> list[PhaseChanged | TrialFinished]:
        """Process samples ``(t_ns, force_n, trial_mark)`` in time order; return the events they caused."""
        events: list[PhaseChanged | TrialFinished] = []
        for t_ns, force, mark in samples:
            phase = self.phase
            if phase is TrialPhase.ANSWER:
                if t_ns - self.cue_ns > self._answer_by_ns:  # type: ignore[operator]  # set from CUE on
                    # no answer: the trial ends with none (stored so; its procedure skips it)
                    events.extend(self._finish(Outcome.SUCCESS, self.cue_ns + self._answer_by_ns))  # type: ignore[operator]  # as above
                continue
            if phase is TrialPhase.PAUSE:
                if t_ns >= self.pause_until_ns:  # type: ignore[operator]  # set in PAUSE (no assert on the per-tick path)
                    events.append(self._go(TrialPhase.IDLE, t_ns))
                    self.spec = None
                continue
            if phase is TrialPhase.CUED:
                if mark != self.spec.index:  # type: ignore[union-attr]  # set once started (no assert on the per-tick path)
                    continue  # the loop has not applied the trial's mark yet
                self.cue_ns = t_ns
                events.append(self._go(TrialPhase.ACTIVE, t_ns))
                phase = TrialPhase.ACTIVE
            if phase is TrialPhase.ACTIVE:
                rel = t_ns - self.cue_ns  # type: ignore[operator]  # set from CUE on (no assert on the per-tick path)
                if rel > self._cap_ns:
                    events.extend(self._finish(Outcome.TIMEOUT, self.cue_ns + self._cap_ns))  # type: ignore[operator]  # as above
                    # this sample already belongs to the pause
                    if t_ns >= self.pause_until_ns:  # type: ignore[operator]  # set in PAUSE (no assert on the per-tick path)
                        events.append(self._go(TrialPhase.IDLE, t_ns))
                        self.spec = None
                    continue
                self._t.append(rel)
                self._f.append(force)
                if self._rule.feed(rel, force):  # type: ignore[union-attr]  # set from CUE on (no assert on the per-tick path)
                    if self._asks:  # the question is asked: the trial ends with the answer
                        events.append(self._go(TrialPhase.ANSWER, t_ns))
                        continue
                    events.extend(self._finish(Outcome.SUCCESS, t_ns))
                elif rel == self._cap_ns:
                    events.extend(self._finish(Outcome.TIMEOUT, t_ns))
        return events

    def answer(self, t_ns: int, key: str) -> list[PhaseChanged | TrialFinished]:
        """The participant's answer to the trial's question (ANSWER only): the trial ends at ``t_ns`` with it.

        Raises ``ValueError`` (one line) for a key the task does not allow, :class:`TrialMachineError` when no
        question is open.
        """
        if key not in self.task.answer_keys:
            raise ValueError(f"answer = {key!r}: the {self.task.title} task's answers are "
                             f"{', '.join(self.task.answer_keys) or 'none (it asks no question)'}")
        if self.phase is not TrialPhase.ANSWER:
            raise TrialMachineError(f"no question is open in phase {self.phase}")
        return self._finish(Outcome.SUCCESS, t_ns, answer=key)

    def abort(self, t_ns: int, reason: str) -> list[PhaseChanged | TrialFinished]:
        """Abort the current trial (experimenter action); it is recorded as aborted."""
        if self.phase not in RUNNING:
            raise TrialMachineError(f"no trial to abort in phase {self.phase}")
        if self.cue_ns is None:
            self.cue_ns = t_ns
        return self._finish(Outcome.ABORTED, t_ns, reason)

    def _finish(self, outcome: Outcome, end_ns: int, reason: str = "",
                answer: str | None = None) -> list[PhaseChanged | TrialFinished]:
        spec = self.spec
        assert spec is not None and self.cue_ns is not None
        m = self.task.judge(self._t, self._f, spec, max_trial_s=self.timing.max_trial_s,
                            sample_period_s=self.sample_period_s)
        disagree = outcome is not Outcome.ABORTED and m.success != (outcome is Outcome.SUCCESS)
        if disagree:  # pragma: no cover - one definition
            raise TrialMachineError("the task's live rule disagrees with its offline judgement")
        done = TrialFinished(spec, outcome, self.cue_ns, end_ns, m, reason, answer)
        self.pause_until_ns = end_ns + self._pause_ns
        ev = self._go(TrialPhase.PAUSE, end_ns)
        return [done, ev]
