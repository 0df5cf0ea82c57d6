"""The approach to the tissue: its aim, and the watched (feedback OFF) approach's stop (model version 3)."""

from __future__ import annotations

import dataclasses
import math

import pytest
from test_participant import GAP_M, _scripted_run

from pipeline.core.aim import TrialAim
from pipeline.sim.approach import approach_end_y, seen_over_aim
from pipeline.sim.hand import HandObservation
from pipeline.sim.participant import SimulatedParticipant

K_TISSUE = 1.1e4  # the scripted surface's stiffness (N/m^1.5), as test_participant's


def test_the_stop_is_strictly_past_the_aim_times_one_plus_the_excess() -> None:
    aim, excess = 1.2, 1.0
    at_limit = ((1.0 + excess) * aim / K_TISSUE) ** (1 / 1.5)  # the indentation whose believed force is 2.4 N
    assert not seen_over_aim(at_limit * (1 - 1e-9), K_TISSUE, 1.5, aim, excess)
    assert seen_over_aim(at_limit * (1 + 1e-9), K_TISSUE, 1.5, aim, excess)
    # a stiffer belief reads more force into the same image: it stops sooner
    assert seen_over_aim(at_limit * 0.9, K_TISSUE * 1.5, 1.5, aim, excess)


@pytest.mark.parametrize("bad", [math.nan, -1e-3, 0.051, math.inf, -math.inf])
def test_no_usable_image_is_no_reason_to_stop(bad: float) -> None:
    assert not seen_over_aim(bad, K_TISSUE, 1.5, 0.6, 0.0)


def test_the_approach_aims_at_the_believed_surface_plus_the_believed_depth_and_the_push_back() -> None:
    # stylus at 0, 15 mm gap seen, believed 2 mm deeper, 3 mm of indentation wanted, 1 mm of push-back expected
    assert approach_end_y(0.0, 0.015, 0.0, 0.002, 0.003, 1.0, 0.001) == pytest.approx(-0.021, abs=1e-15)
    # motion scale 2: the robot moves twice the stylus, so half the stylus travel (the push-back is the hand's own)
    assert approach_end_y(0.0, 0.015, 0.0, 0.002, 0.003, 2.0, 0.001) == pytest.approx(-0.011, abs=1e-15)
    # a NaN gap is taken as the rig's start gap, a NaN indentation as none; out-of-range ones are clipped
    assert approach_end_y(0.0, math.nan, math.nan, 0.0, 0.0, 1.0, 0.0) == pytest.approx(-0.015, abs=1e-15)
    assert approach_end_y(0.0, 0.5, 0.5, 0.0, 0.0, 1.0, 0.0) == pytest.approx(-0.1 + 0.05, abs=1e-15)


def _deep_surface_seed() -> int:
    """The first participant seed whose first trial believes the surface > 2σ deeper than it is."""
    for seed in range(400):
        p = SimulatedParticipant(seed=seed)
        p.begin_trial(TrialAim.constant(1.2, False), 0.0)
        p.equilibrium_y(HandObservation(0.0, 0.0, 0.0, 0.0, GAP_M))
        if p._surface_err > 2.0 * p.params.surface_sigma_m:
            return seed
    raise AssertionError("no seed in 0-399 with a surface-depth error above 2 sigma")  # pragma: no cover


def _with_excess(seed: int, excess: float) -> SimulatedParticipant:
    drawn = SimulatedParticipant(seed=seed).params
    return SimulatedParticipant(seed=seed, params=dataclasses.replace(drawn, approach_stop_excess=excess))


def test_a_watched_approach_that_overshoots_is_stopped_short_of_where_it_was_going() -> None:
    seed = _deep_surface_seed()
    watched = _scripted_run(_with_excess(seed, 1.0), seconds=6.0, haptic=False)
    unwatched = _scripted_run(_with_excess(seed, math.inf), seconds=6.0, haptic=False)
    # the unwatched approach ends > 8.6 mm past the believed surface; the watched one is stopped before its end
    # (this seed: the deepest command -24.7 mm against -27.2 mm; deterministic, no BLAS, so a 2 mm margin is safe)
    assert min(watched) > min(unwatched) + 0.002
    # until the stop the two are the same command, tick for tick (the watch draws no random number)
    first = next(i for i, (a, b) in enumerate(zip(watched, unwatched, strict=True)) if a != b)
    assert first > 500


def test_with_feedback_the_approach_is_not_watched() -> None:
    seed = _deep_surface_seed()
    assert _scripted_run(_with_excess(seed, 1.0), haptic=True) == _scripted_run(_with_excess(seed, math.inf),
                                                                                 haptic=True)
