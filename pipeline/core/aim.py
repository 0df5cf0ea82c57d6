"""What a trial asks of the hand on the stylus: the hook a simulated participant is driven through.

The study (``protocol``, a floor above) decides what each trial asks -- its task says what to aim at, and when
(:meth:`protocol.tasks.base.Task.aim`); the simulated participant (:mod:`pipeline.sim.participant`, beside the rig)
decides how a hand would do it.  Neither may import the other's floor, so the pipeline owns the vocabulary between
them: a :class:`TrialAim` is plain data (it crosses a process boundary where the loop runs in a process of its own),
and a :class:`TrialParticipant` is what the session runner tells at each cue and each trial's end.

An aim's target is a function of trial time (s since the cue) given by knots, linear between them and held after
the last: the force-regulation task's is one knot, a constant force; a task whose target moves (a ramp, a sine
sampled finely enough) gives more.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from pipeline.core.force_program import check_knots, knot_value

__all__ = ["AnsweringParticipant", "TrialAim", "TrialParticipant", "TrialQuestion"]


@dataclass(frozen=True, slots=True)
class TrialAim:
    """What one trial asks of the participant, told at its cue.

    Attributes
    ----------
    knots
        ``(t_s, force_n)`` pairs: the target force (N) at trial time ``t_s`` (s since the cue), from 0 on in
        increasing time; linear between knots, the last one held.  One knot: a constant target.
    haptic_on
        Haptic feedback renders the contact force in this trial.
    gauge
        A live force gauge with the target band is in view (the training aid): the force is seen, not judged.
    practice
        A training trial (the participant draws its beliefs and noise from the training trials' own stream).
    """

    knots: tuple[tuple[float, float], ...]
    haptic_on: bool
    gauge: bool = False
    practice: bool = False

    def __post_init__(self) -> None:
        check_knots(self.knots, "TrialAim", "a trial's target")

    @classmethod
    def constant(cls, force_n: float, haptic_on: bool, *, gauge: bool = False, practice: bool = False) -> TrialAim:
        """A target that does not move (the force-regulation task's)."""
        return cls(((0.0, float(force_n)),), bool(haptic_on), bool(gauge), bool(practice))

    @property
    def steady_n(self) -> float | None:
        """The target when it does not move over the trial, N (None: it moves)."""
        first = self.knots[0][1]
        return first if all(f == first for _, f in self.knots) else None

    def force_n(self, t_s: float) -> float:
        """The target at trial time ``t_s`` (s since the cue; before 0: the first knot's)."""
        return knot_value(self.knots, t_s)


class TrialParticipant(Protocol):
    """Whom the session runner tells what a trial asks: a simulated participant (or a driver forwarding to one).

    Both calls only stage the news: it takes effect at the participant's next observation of the rig (the tick at
    which the loop applies the trial's mark), so ``t_s`` -- the participant's clock when told -- may lag it.
    """

    def begin_trial(self, aim: TrialAim, t_s: float) -> None:
        """The cue appeared: aim as ``aim`` says."""
        ...

    def end_trial(self, t_s: float) -> None:
        """The trial ended: rest until the next cue."""
        ...


@dataclass(frozen=True, slots=True)
class TrialQuestion:
    """A trial's question, as a simulated participant is asked it: the force the device rendered in each of the
    trial's intervals (N, what the hand felt), the answers allowed, and the trial's index in its block."""

    felt_n: tuple[float, ...]
    keys: tuple[str, ...]
    trial_index: int


@runtime_checkable
class AnsweringParticipant(Protocol):
    """A simulated participant that answers a trial's question (a task that asks one: force discrimination)."""

    def answer(self, question: TrialQuestion) -> str:
        """One of ``question.keys``."""
        ...
