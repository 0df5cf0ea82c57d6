"""The experienced profile of the simulated participant: a surgeon who has learned to judge force by sight.

The calibrated participant (:mod:`pipeline.sim.participant_params`) is an *inexperienced* one: its OFF-mode
handicaps -- the force judged from the seen indentation through a poor stiffness belief, slow visual checks, a slow
approach because contact cannot be felt, a remembered target biased without a felt reference -- were set against
the paper's participants, who had no surgical training.

**Source.**  Bergholz, Ferle and Weber (2023, *Sci. Rep.* 13:19215; 56 studies of robot-assisted surgery with and
without haptic feedback) split the benefit of haptic feedback on the forces applied by the users' expertise: large
for inexperienced users (Hedges' g = 0.98, 23 observations), smaller for novices with some training (0.68) and not
significant for experienced surgeons (0.15, 95 % CI −0.18 to 0.47, 10 observations).  Their reading, and the
usual one, is that experienced surgeons have learned to substitute vision for touch (tissue deformation, instrument
bending), so restoring touch adds little for them.

**What is mapped, and how.**  The ratio of the two effects, ρ = 0.15 / 0.98 ≈ 0.153
(:data:`EXPERIENCED_RATIO`), is applied to each OFF-only handicap of the model, measured as the distance between
the OFF value and the value the same participant has with feedback (where touch carries the information): the
experienced participant keeps ρ of that distance.

===========================  =================  =============================  ==========================
parameter                    inexperienced      with feedback (the gap's end)  experienced (keeps ρ)
===========================  =================  =============================  ==========================
stiffness belief median      0.85               1 (felt force: no over-press)  1 − ρ·0.15 ≈ 0.977
stiffness belief σ_k         0.40               the participant's felt-force    σ_h,tot + ρ(0.40 − σ_h,tot)
                                                uncertainty σ_h,tot =           ≈ 0.21
                                                √(σ_h² + 0.13²) ≈ 0.18
OFF decision-interval ×      4.0                1                              1 + 3ρ ≈ 1.46
OFF approach ×               1.75               1                              1 + 0.75ρ ≈ 1.11
bias of the remembered       LogN(1, 0.15)      LogN(1, 0.05)                  LogN(1, 0.05 + 0.10ρ):
target OFF                                                                     the same draw, rescaled
===========================  =================  =============================  ==========================

Nothing else changes: the delays, the submovements, the motor noise, the haptic percept and everything ON are the
calibrated participant's (no source gives a surgeon's submovement noise in this task, and a change acting on both
modes alike would move the levels, not the benefit of feedback).  The mapping is linear in each handicap, an
assumption: a standardized effect need not scale so; it was chosen before any simulated two-group study was run
and is not fitted to one (docs/groups.md gives what a simulated study then showed).  The draws are the calibrated
participant's (the same seed gives the same person, only more practised), so a paired comparison of the profiles
is possible.
Model version 3's watch of the approach without feedback (:mod:`pipeline.sim.approach`) is not a handicap mapped
here: an experienced participant's OFF approach is watched and stopped by the same rule.
"""

from __future__ import annotations

import dataclasses
import math

from pipeline.sim.participant_params import BIAS_SIGMA_OFF, BIAS_SIGMA_ON, ParticipantParams

__all__ = ["EXPERIENCED_RATIO", "PROFILES", "experienced", "with_profile"]

#: Bergholz et al. (2023), Table 2 (applied forces): experienced users' g over inexperienced users' g.
EXPERIENCED_RATIO = 0.15 / 0.98
#: The simulated participant's profiles: the calibrated (inexperienced) one and the experienced one.
PROFILES = ("novice", "experienced")


def _keep(off: float, felt: float, ratio: float) -> float:
    """The OFF value moved towards the felt one, keeping ``ratio`` of their distance."""
    return felt + ratio * (off - felt)


def experienced(p: ParticipantParams, ratio: float = EXPERIENCED_RATIO) -> ParticipantParams:
    """``p`` as an experienced participant: each OFF-only handicap keeps ``ratio`` of its distance to the value with
    feedback (the table of this module)."""
    if not (math.isfinite(ratio) and 0.0 <= ratio <= 1.0):
        raise ValueError(f"ratio = {ratio!r}: must be a number from 0 to 1")
    felt_sigma = math.hypot(p.sigma_haptic, p.sigma_haptic_model)
    bias_sigma = _keep(BIAS_SIGMA_OFF, BIAS_SIGMA_ON, ratio)
    return dataclasses.replace(
        p,
        stiffness_belief_median=_keep(p.stiffness_belief_median, 1.0, ratio),
        stiffness_belief_sigma=_keep(p.stiffness_belief_sigma, felt_sigma, ratio),
        off_interval_factor=_keep(p.off_interval_factor, 1.0, ratio),
        off_approach_factor=_keep(p.off_approach_factor, 1.0, ratio),
        # the same standard-normal draw, on the narrower spread: log b' = log b · σ'/σ
        bias_off=math.exp(math.log(p.bias_off) * bias_sigma / BIAS_SIGMA_OFF),
    )


def with_profile(p: ParticipantParams, profile: str) -> ParticipantParams:
    """``p`` as the named profile (:data:`PROFILES`): ``novice`` is the calibrated participant itself."""
    if profile == "novice":
        return p
    if profile == "experienced":
        return experienced(p)
    raise ValueError(f"profile = {profile!r}: must be one of {', '.join(PROFILES)}")
