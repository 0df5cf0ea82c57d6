"""The simulated participant in a force-discrimination (2AFC) trial: which of two felt forces was stronger.

A participant's perception of a force ``F`` is ``F + N(0, (W·F)²)``: Weber's law, the noise's SD a fixed fraction
``W`` of the force (the Weber fraction).  For force, ``W`` is about 0.07 over 2.5–10 N (Jones 2000, Pang, Tan &
Durlach 1991: 5–10 %, 7 % typical); each participant's own ``W`` is drawn uniformly from 0.07–0.10.  On a fraction
``λ`` of trials the participant lapses (inattention, a slip of the key) and answers at random; lapse rates of
2–4 % are typical of trained observers (Wichmann & Hill 2001, who show an unmodelled lapse biases the fitted slope),
so each participant's ``λ`` is drawn uniformly from 0.02–0.04.

Each interval's percept is of the force *rendered* over its plateau (the safety stage's output, what the hand
felt), so a clamp or a ramp that did not finish would show in the answers.  Everything is drawn from the study's
seed and the participant's number: the same study answers the same way, trial by trial.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["LAPSE_RANGE", "WEBER_RANGE", "DiscriminationObserver"]

#: The range each participant's Weber fraction is drawn from (Jones 2000; Pang, Tan & Durlach 1991).
WEBER_RANGE = (0.07, 0.10)
#: The range each participant's lapse rate is drawn from (Wichmann & Hill 2001).
LAPSE_RANGE = (0.02, 0.04)
#: A stream tag: the observer's draws are its own, apart from the regulation participant's.
_STREAM = 0x0B5E


@dataclass(frozen=True, slots=True)
class DiscriminationObserver:
    """One simulated participant's force perception: its Weber fraction and lapse rate (module docstring)."""

    weber: float
    lapse: float
    seed: int
    participant: int

    @classmethod
    def drawn(cls, seed: int, participant: int) -> DiscriminationObserver:
        """The participant's own Weber fraction and lapse rate, drawn from the study's seed."""
        rng = np.random.default_rng([seed, participant, _STREAM])
        return cls(float(rng.uniform(*WEBER_RANGE)), float(rng.uniform(*LAPSE_RANGE)), seed, participant)

    def answer(self, first_n: float, second_n: float, reference: int, trial: int) -> int:
        """Which interval felt stronger, 1 or 2, from the two felt forces (N): deterministic from the seed, the
        reference's index and the trial's.  A non-finite force is felt as none (0 N)."""
        rng = np.random.default_rng([self.seed, self.participant, _STREAM, reference, trial])
        lapse, guess, n1, n2 = rng.random(), rng.random(), rng.standard_normal(), rng.standard_normal()
        if lapse < self.lapse:
            return 1 if guess < 0.5 else 2
        f1 = first_n if math.isfinite(first_n) else 0.0
        f2 = second_n if math.isfinite(second_n) else 0.0
        p1 = f1 + self.weber * abs(f1) * n1
        p2 = f2 + self.weber * abs(f2) * n2
        return 1 if p1 > p2 else 2
