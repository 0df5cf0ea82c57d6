"""How the simulated participant learns across visits: a power law of practice, with forgetting over the delay.

The participant of a study done in one visit is the calibrated one (:mod:`pipeline.sim.participant_params`), as
ever: the rule acts only from a schedule's second visit on (:class:`Practice` with ``visit`` ≥ 2), so every study
of one visit -- the paper's -- is unchanged to the byte.

**Why nothing before the second visit.**  Within a session the model learns nothing (participant_params.py:
"Training does nothing to the simulated participant's experiment"; the paper's levels, which the model is fitted
to, are those of participants who had just trained), and motor skill is largely consolidated offline, between
practice days (Walker et al. 2002, *Neuron* 35:205; Schmidt & Lee, *Motor Control and Learning*, on the
distinction between performance during practice and learning shown at a later test).  So what a visit's practice
teaches shows from the next visit on.

**The rule.**  At visit *n* (1-based; *n* − 1 visits of practice before it) the participant has learned the share

    L(n, g) = (1 − n^(−α)) · (1 + max(0, g − 1))^(−ψ)

of what the task can teach, *g* the days since the previous visit:

* ``1 − n^(−α)`` is the power law of practice (Newell & Rosenbloom 1981, "Mechanisms of skill acquisition and the
  law of practice"): performance improves as a power of the amount of practice, fast at first, ever more slowly;
  α = :data:`PRACTICE_EXPONENT` = 0.4 is a choice (the law's form is sourced; its exponent varies by task, and no
  source gives it for this one);
* ``(1 + t)^(−ψ)`` is the power law of forgetting (Wixted & Ebbesen 1991, *Psychol. Sci.* 2:409): what is learned
  decays as a power of the time since practice; skill decays with the retention interval (Arthur et al. 1998,
  *Human Performance* 11:57, a meta-analysis of skill retention).  ψ = :data:`FORGETTING_EXPONENT` = 0.1 is a choice
  (motor skills are well retained: a small ψ).  *t* counts the days beyond the next day (a daily rhythm of practice
  loses nothing: the power law of practice above describes such practice), so a retention test a week after the
  post-test keeps 7^(−0.1) ≈ 82 % of what was learned.

**What practice changes.**  The learned share *L* moves the participant along the gap the experienced profile
(:mod:`pipeline.sim.experience`) maps: each OFF-only handicap (the stiffness belief, the slow visual checks, the
slow approach without felt contact, the spread of the remembered target) keeps ``1 − L·(1 − ρ)`` of its distance
to the value with feedback, ρ = Bergholz et al. (2023)'s ratio, so unlimited practice reaches the experienced
participant and no further.  And in both modes, practice lowers the approach duration and the relative motor
noise by the share ``L · c``, c = :data:`BOTH_MODES_GAIN` = 0.2 (a choice: practice makes movements faster and less
variable, Schmidt & Lee; how much for this task nothing pins down).  Everything else is the calibrated
participant's.

**Noise.**  A later visit's trials draw from their own streams (the trial's key with the visit's number added), so
two visits of the same test are not the same noise replayed; the participant's constants are the same draw.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from pipeline.sim.experience import EXPERIENCED_RATIO, experienced
from pipeline.sim.participant_params import ParticipantParams

__all__ = ["BOTH_MODES_GAIN", "FORGETTING_EXPONENT", "LEARNING_RULE", "PRACTICE_EXPONENT", "Practice", "practised"]

#: α of the power law of practice (a choice; module docstring).
PRACTICE_EXPONENT = 0.4
#: ψ of the power law of forgetting (a choice; module docstring).
FORGETTING_EXPONENT = 0.1
#: The share of the approach duration and of the relative motor noise unlimited practice removes (a choice).
BOTH_MODES_GAIN = 0.2
#: The rule's name in a report's methods (changes whenever a constant or the form changes).
LEARNING_RULE = (f"learning rule 1: power law of practice, alpha {PRACTICE_EXPONENT:g}; power law of forgetting, "
                 f"psi {FORGETTING_EXPONENT:g}; both modes x(1 - {BOTH_MODES_GAIN:g} L)")


@dataclass(frozen=True, slots=True)
class Practice:
    """Where in a schedule a simulated session is: the visit's number and the days since the previous visit."""

    visit: int
    gap_days: int = 0

    @classmethod
    def at(cls, visit: Any) -> Practice | None:
        """The practice of a session held in ``visit`` (a stored visit's place, with its ``number`` and
        ``gap_days``); None for a session outside a schedule of visits."""
        return None if visit is None else cls(visit.number, visit.gap_days)

    def __post_init__(self) -> None:
        if isinstance(self.visit, bool) or not isinstance(self.visit, int) or self.visit < 1:
            raise ValueError(f"visit = {self.visit!r}: must be a whole number ≥ 1")
        if isinstance(self.gap_days, bool) or not isinstance(self.gap_days, int) or self.gap_days < 0:
            raise ValueError(f"gap_days = {self.gap_days!r}: must be a whole number ≥ 0")

    def learned(self) -> float:
        """L(n, g) of the module docstring, in [0, 1): 0 at the first visit."""
        gained = 1.0 - math.pow(self.visit, -PRACTICE_EXPONENT)
        return gained * math.pow(1.0 + max(0, self.gap_days - 1), -FORGETTING_EXPONENT)

    def stream(self) -> tuple[int, ...]:
        """What a trial's random-stream key gets added: nothing at the first visit (the calibrated participant's
        streams, byte for byte), the visit's number after."""
        return () if self.visit == 1 else (self.visit,)


def practised(p: ParticipantParams, practice: Practice | None) -> ParticipantParams:
    """``p`` after the practice of the visits before ``practice``'s (``p`` itself at the first visit or without)."""
    if practice is None or practice.visit == 1:
        return p
    learned = practice.learned()
    q = experienced(p, ratio=1.0 - learned * (1.0 - EXPERIENCED_RATIO))
    both = 1.0 - BOTH_MODES_GAIN * learned
    if not (math.isfinite(both) and 0.0 < both <= 1.0):  # L is in [0, 1): unreachable, said for the reader
        raise ValueError(f"learned share {learned!r}: outside [0, 1)")
    return dataclasses.replace(q, approach_center_s=q.approach_center_s * both,
                               motor_noise_rel=q.motor_noise_rel * both)
