"""A force-discrimination block run by simulated participants on the virtual clock (issue 43).

Per participant, the protocol's references (its ``[[targets]]``, at the hand) are interleaved trial by trial; each
trial's Δ is QUEST+'s (:class:`protocol.tasks.force_discrimination.NextDelta`, one per reference), its order the
seed's (:func:`protocol.tasks.force_discrimination.comparison_first`); the two-interval command is rendered at 1 kHz
through the pipeline's safety stage (:class:`pipeline.force.safety.SafetyGovernor`: bounded by ``f_max`` and the
device's peak, slew-limited, faded in), and the simulated observer
(:class:`pipeline.sim.discrimination_observer.DiscriminationObserver`) answers from the forces rendered over the two
plateaus.  Then each participant's answers at each reference are fitted (:mod:`analysis.stats.psychometric`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from analysis.stats.psychometric import PsychometricFit, fit_psychometric
from pipeline.force.safety import SafetyConfig, SafetyGovernor
from pipeline.sim.discrimination_observer import DiscriminationObserver
from protocol.study.config import ProtocolConfig
from protocol.tasks.force_discrimination import ForceDiscrimination, comparison_first, interval_means

__all__ = ["DiscriminationTrial", "ParticipantResult", "render", "run_block", "run_participants"]

#: The loop's period, s (1 kHz).
_DT_S = 0.001
#: The Touch's peak force, N (the device registry's ``touch``): the safety stage's device clamp.
_DEVICE_PEAK_N = 3.3


@dataclass(frozen=True, slots=True)
class DiscriminationTrial:
    """One answered trial: its reference, Δ, order, the felt forces and the answer."""

    participant: int
    target_label: str
    reference_n: float
    trial: int
    delta_n: float
    comparison_first: bool
    first_n: float
    second_n: float
    peak_n: float
    answer: int
    correct: bool


@dataclass(frozen=True, slots=True)
class ParticipantResult:
    """A simulated participant's true perception, its trials, and its fit per reference (by target label)."""

    observer: DiscriminationObserver
    trials: tuple[DiscriminationTrial, ...]
    fits: tuple[tuple[str, PsychometricFit], ...]


def render(task: ForceDiscrimination, first_n: float, second_n: float, safety: SafetyConfig,
           device_peak_n: float = _DEVICE_PEAK_N) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """A trial's command through the safety stage at 1 kHz, from the cue to the answer: times (s) and the rendered
    force (N), feedback enabled from the cue (so the lead-in covers the fade-in)."""
    t = np.arange(int(round(task.answer_at_s() / _DT_S)) + 1, dtype=np.float64) * _DT_S
    command = task.stimulus_n(first_n, second_n, t)
    gov = SafetyGovernor(safety, device_peak_n)
    out = np.empty_like(command)
    for i, f in enumerate(command.tolist()):
        out[i] = gov.step(0.0, 0.0, f, True, _DT_S)[2]
    return t, out


def run_block(task: ForceDiscrimination, protocol: ProtocolConfig, observer: DiscriminationObserver, seed: int,
              safety: SafetyConfig) -> tuple[DiscriminationTrial, ...]:
    """One participant's block: every reference's trials, interleaved."""
    refs = [(t.label, task.reference_n(t.force_n)) for t in protocol.targets]
    quests = [task.next_delta(ref) for _, ref in refs]
    rows: list[DiscriminationTrial] = []
    for k in range(task.trials):
        for r, ((label, ref), quest) in enumerate(zip(refs, quests, strict=True)):
            delta = quest.next_n()
            first = comparison_first(seed, observer.participant, r, k)
            t, felt = render(task, ref + delta if first else ref, ref if first else ref + delta, safety)
            f1, f2 = interval_means(t, felt, task.plateaus())
            answer = observer.answer(f1, f2, r, k)
            correct = (answer == 1) == first
            quest.answered(delta, correct)
            rows.append(DiscriminationTrial(observer.participant, label, ref, k, delta, first, f1, f2,
                                            float(np.max(felt)), answer, correct))
    return tuple(rows)


def run_participants(protocol: ProtocolConfig, n: int, seed: int,
                     safety: SafetyConfig | None = None) -> tuple[ParticipantResult, ...]:
    """``n`` simulated participants' blocks and fits (the protocol's task must be force discrimination)."""
    task = protocol.task
    if not isinstance(task, ForceDiscrimination):
        raise ValueError(f"task.kind = {task.kind!r}: a discrimination block needs 'force_discrimination'")
    safety = safety or SafetyConfig()
    out = []
    for p in range(1, n + 1):
        observer = DiscriminationObserver.drawn(seed, p)
        trials = run_block(task, protocol, observer, seed, safety)
        fits = tuple((t.label, fit_psychometric(task.reference_n(t.force_n),
                                                [x.delta_n for x in trials if x.target_label == t.label],
                                                [x.correct for x in trials if x.target_label == t.label]))
                     for t in protocol.targets)
        out.append(ParticipantResult(observer, trials, fits))
    return tuple(out)
