"""The simulated participant's learning across visits (pipeline/sim/learning.py): nothing at the first visit, a power
law of practice after, forgetting over a delay, never past the experienced participant."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.sim.experience import experienced
from pipeline.sim.learning import BOTH_MODES_GAIN, FORGETTING_EXPONENT, PRACTICE_EXPONENT, Practice, practised
from pipeline.sim.participant import SimulatedParticipant
from pipeline.sim.participant_params import ParticipantParams


def _params(seed: int = 7) -> ParticipantParams:
    return ParticipantParams.draw(np.random.default_rng(seed))


def test_the_first_visit_is_the_calibrated_participant() -> None:
    p = _params()
    assert practised(p, None) is p and practised(p, Practice(1, 0)) is p
    assert Practice(1, 0).learned() == 0.0 and Practice(1, 0).stream() == ()
    a, b = SimulatedParticipant(seed=5), SimulatedParticipant(seed=5, practice=Practice(1))
    assert a.params == b.params and b._stream == ()  # the same draws, the same trial streams: the paper's study


def test_learning_follows_the_power_law_and_forgetting() -> None:
    # L(n, g) = (1 − n^−α)(1 + max(0, g − 1))^−ψ, by hand
    assert Practice(4, 1).learned() == pytest.approx(1 - 4 ** -PRACTICE_EXPONENT, rel=1e-12)  # a daily rhythm: no loss
    assert Practice(6, 7).learned() == pytest.approx((1 - 6 ** -PRACTICE_EXPONENT) * 7 ** -FORGETTING_EXPONENT,
                                                     rel=1e-12)
    shares = [Practice(n, 1).learned() for n in range(1, 8)]
    steps = np.diff(shares)
    assert (steps > 0).all() and (np.diff(steps) < 0).all()  # ever more, ever more slowly
    assert Practice(6, 7).learned() < Practice(5, 1).learned()  # a week's delay costs more than a visit gains


def test_practice_moves_along_the_gap_and_no_further() -> None:
    p = _params()
    later = practised(p, Practice(5, 1))
    learned = Practice(5, 1).learned()
    expert = experienced(p)
    for name in ("off_interval_factor", "off_approach_factor", "stiffness_belief_sigma"):
        start, end, now = getattr(p, name), getattr(expert, name), getattr(later, name)
        assert min(start, end) <= now <= max(start, end)
        # the share of the way from the novice to the experienced value is the learned share (linear in each)
        assert (start - now) / (start - end) == pytest.approx(learned, rel=1e-9)
    assert later.approach_center_s == pytest.approx(p.approach_center_s * (1 - BOTH_MODES_GAIN * learned), rel=1e-12)
    assert later.motor_noise_rel == pytest.approx(p.motor_noise_rel * (1 - BOTH_MODES_GAIN * learned), rel=1e-12)
    assert later.tau_visual_s == p.tau_visual_s and later.bias_on == p.bias_on  # the rest is the participant's
    far = practised(p, Practice(30, 1))
    assert far.off_interval_factor >= expert.off_interval_factor and math.isfinite(far.off_interval_factor)


@pytest.mark.parametrize(("visit", "gap"), [(0, 0), (2, -1), (True, 0)])
def test_a_bad_practice_is_refused(visit, gap) -> None:
    with pytest.raises(ValueError, match="must be a whole number"):
        Practice(visit, gap)
