"""The experienced profile of the simulated participant (pipeline.sim.experience): the mapping as documented, the
same person's draws, and a participant who then does better without feedback and gains less from it."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pipeline.sim.experience import EXPERIENCED_RATIO, experienced, with_profile
from pipeline.sim.participant import SimulatedParticipant
from pipeline.sim.participant_params import BIAS_SIGMA_OFF, BIAS_SIGMA_ON, ParticipantParams


def _params(seed: int = 3) -> ParticipantParams:
    return ParticipantParams.draw(np.random.default_rng(seed))


def test_the_ratio_is_the_meta_analysis_one() -> None:
    # Bergholz et al. 2023, Table 2 (applied forces): experienced g = 0.15, inexperienced g = 0.98
    assert abs(EXPERIENCED_RATIO - 0.15 / 0.98) < 1e-15  # the same quotient: equal to one rounding


def test_each_off_handicap_keeps_the_ratio_of_its_gap() -> None:
    p = _params()
    e = experienced(p)
    r = EXPERIENCED_RATIO
    felt = math.hypot(p.sigma_haptic, p.sigma_haptic_model)
    # each value written out from the module's table (float arithmetic in another order: 1e-12)
    assert e.stiffness_belief_median == pytest.approx(1.0 - r * 0.15, rel=1e-12)
    assert e.stiffness_belief_sigma == pytest.approx(felt + r * (0.40 - felt), rel=1e-12)
    assert e.off_interval_factor == pytest.approx(1.0 + 3.0 * r, rel=1e-12)
    assert e.off_approach_factor == pytest.approx(1.0 + 0.75 * r, rel=1e-12)
    z = math.log(p.bias_off) / BIAS_SIGMA_OFF  # the same draw, on the narrower spread
    assert math.log(e.bias_off) == pytest.approx(z * (BIAS_SIGMA_ON + r * (BIAS_SIGMA_OFF - BIAS_SIGMA_ON)), rel=1e-12)
    changed = {f.name for f in dataclasses.fields(p) if getattr(p, f.name) != getattr(e, f.name)}
    assert changed == {"stiffness_belief_median", "stiffness_belief_sigma", "off_interval_factor",
                       "off_approach_factor", "bias_off"}  # nothing with feedback, no motor noise, no delays


def test_the_ends_of_the_ratio() -> None:
    p = _params()
    assert experienced(p, 1.0) == dataclasses.replace(p, bias_off=experienced(p, 1.0).bias_off)
    assert experienced(p, 1.0).bias_off == pytest.approx(p.bias_off, rel=1e-12)
    zero = experienced(p, 0.0)
    assert (zero.off_interval_factor, zero.off_approach_factor, zero.stiffness_belief_median) == (1.0, 1.0, 1.0)
    for bad in (-0.1, 1.5, math.nan):
        with pytest.raises(ValueError, match="ratio"):
            experienced(p, bad)


def test_profiles_of_the_participant() -> None:
    novice = SimulatedParticipant(seed=11)
    assert with_profile(novice.params, "novice") is novice.params
    surgeon = SimulatedParticipant(seed=11, profile="experienced")
    assert surgeon.params == experienced(novice.params)  # the same person, more practised
    assert surgeon.profile == "experienced"
    with pytest.raises(ValueError, match="profile = 'expert': must be one of novice, experienced"):
        SimulatedParticipant(seed=11, profile="expert")


def test_an_experienced_participant_gains_less_from_feedback() -> None:
    """Three simulated participants each way through the paper's schedule with 3 trials per cell instead of 5 (the
    suite's time; database-less runner): the experienced ones' RMSE without feedback is lower, and their ON − OFF
    gain smaller (the direction the mapping is for; its size is what docs/groups.md reports from a simulated study).
    The same seeds both ways (the same people, only more practised): seen 1.30 → 0.99 N OFF, gains 0.52 and 0.27 N."""
    import dataclasses

    from protocol.study.config import default_protocol
    from study_app.headless.sim_trials import run_participant

    shorter = dataclasses.replace(default_protocol(), trials_per_cell=3)

    def rmse(profile: str) -> tuple[float, float]:
        rows = [r for k in (1, 2, 3) for r in run_participant(7, k, shorter, profile=profile)]
        off = np.mean([r.values["rmse_n"] for r in rows if r.mode == "off"])
        on = np.mean([r.values["rmse_n"] for r in rows if r.mode == "on"])
        return float(off), float(on)

    n_off, n_on = rmse("novice")
    e_off, e_on = rmse("experienced")
    assert e_off < n_off
    assert abs(e_on - e_off) < abs(n_on - n_off)
