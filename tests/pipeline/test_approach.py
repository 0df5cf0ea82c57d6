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


def _approach_move_end_s(seed: int) -> float:
    """When the first trial's approach movement ends (the plan's end once the approach has started; the same for any
    observations: the reaction time and the approach's duration are drawn, not sensed)."""
    p = _with_excess(seed, math.inf)
    p.begin_trial(TrialAim.constant(1.2, False), 0.0)
    for i in range(2000):
        p.equilibrium_y(HandObservation(i * 1e-3, 0.0, 0.0, 0.0, GAP_M))
        if p._p_end > 0.5:  # before the approach the plan is a 1 ms hold
            return p._p_end
    raise AssertionError("no approach within 2 s")  # pragma: no cover


def _with_excess(seed: int, excess: float) -> SimulatedParticipant:
    drawn = SimulatedParticipant(seed=seed).params
    return SimulatedParticipant(seed=seed, params=dataclasses.replace(drawn, approach_stop_excess=excess))


def test_a_watched_approach_that_overshoots_is_stopped_short_of_where_it_was_going() -> None:
    seed = _deep_surface_seed()
    p_watched, p_unwatched = _with_excess(seed, 1.0), _with_excess(seed, math.inf)
    watched = _scripted_run(p_watched, seconds=6.0, haptic=False)
    unwatched = _scripted_run(p_unwatched, seconds=6.0, haptic=False)
    # the unwatched approach ends > 8.6 mm past the believed surface; the watched one is stopped before its end
    # (this seed: the deepest command -24.7 mm against -27.2 mm; deterministic, no BLAS, so a 2 mm margin is safe)
    assert min(watched) > min(unwatched) + 0.002
    # the watch draws no random number: the two are the same command until the stop, which comes while the
    # movement still runs, and then the equilibrium holds (only the slow postural drift moves it)
    first = next(i for i, (a, b) in enumerate(zip(watched, unwatched, strict=True)) if a != b)
    assert first * 1e-3 < _approach_move_end_s(seed)
    held = watched[first:first + 100]
    assert max(held) - min(held) < 1e-4 < abs(unwatched[first + 100] - unwatched[first])


def test_with_feedback_or_a_live_gauge_the_approach_is_not_watched() -> None:
    # a stop at the first sign of contact (excess 0) changes an OFF trial, and changes nothing with feedback.
    # Compared exactly: the same pure-Python arithmetic run twice in one process (no BLAS, no threads) is the same
    # bits; an unwatched trial must be the same trajectory, not a close one
    seed = _deep_surface_seed()
    assert _scripted_run(_with_excess(seed, 0.0), haptic=False) != _scripted_run(_with_excess(seed, math.inf),
                                                                                  haptic=False)
    assert _scripted_run(_with_excess(seed, 0.0), haptic=True) == _scripted_run(_with_excess(seed, math.inf),
                                                                                 haptic=True)
    for aim, watched in ((TrialAim.constant(1.2, False), True), (TrialAim.constant(1.2, True), False),
                         (TrialAim.constant(1.2, False, gauge=True, practice=True), False)):
        p = SimulatedParticipant(seed=seed)
        p.begin_trial(aim, 0.0)
        p.equilibrium_y(HandObservation(0.0, 0.0, 0.0, 0.0, GAP_M))
        assert p._watched is watched


def test_a_jump_of_the_time_base_moves_the_approachs_times_with_it() -> None:
    p = SimulatedParticipant(seed=1)
    p.begin_trial(TrialAim.constant(0.6, False), 0.0)
    for i in range(1200):  # past the reaction time: the approach has started
        p.equilibrium_y(HandObservation(i * 1e-3, 0.0, 0.0, 0.0, GAP_M))
    move_end_s, next_s = p._p_end, p._next
    assert next_s < move_end_s < move_end_s + p._interval < math.inf  # watching the movement
    jump_s = 101.2 - 1.199  # another time base, 100 s on from the last tick
    p.equilibrium_y(HandObservation(101.2, 0.0, 0.0, 0.0, GAP_M))
    # the movement's end (and with it the first decision's time) and the next look move with the time base
    assert p._p_end == pytest.approx(move_end_s + jump_s, abs=1e-9)  # abs: sums of s-sized floats
    assert p._next == pytest.approx(next_s + jump_s, abs=1e-9)


@pytest.mark.parametrize(("field", "bad"), [("approach_look_s", math.nan), ("approach_look_s", 0.0),
                                            ("approach_look_s", math.inf), ("approach_stop_excess", -0.5),
                                            ("approach_stop_excess", math.nan)])
def test_the_watchs_constants_are_checked(field: str, bad: float) -> None:
    drawn = SimulatedParticipant(seed=0).params
    with pytest.raises(ValueError, match=field):
        dataclasses.replace(drawn, **{field: bad})
