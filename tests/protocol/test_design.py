"""Tests of the trial schedule: balance, seeding, ordering methods, a golden schedule, re-queueing, JSON."""

from __future__ import annotations

from collections import Counter
from dataclasses import replace

import numpy as np
import pytest

from protocol.study.config import ORDERINGS, ProtocolConfig, Target, default_protocol
from protocol.study.design import (
    HapticMode,
    TrialSpec,
    build_schedule,
    requeue_aborted,
    schedule_from_json,
    schedule_to_json,
)

FORCE = {"GENTLE": 0.6, "FIRM": 1.2}


def _protocol(ordering: str = "random", **changes) -> ProtocolConfig:
    return replace(default_protocol(), ordering=ordering, **changes)


def _pairs(schedule: list[TrialSpec]) -> list[tuple[str, str]]:
    return [(t.target_label, t.haptic_mode) for t in schedule]


def _is_well_formed(schedule: list[TrialSpec]) -> None:
    assert [t.index for t in schedule] == list(range(len(schedule)))
    for t in schedule:
        assert t.target_force_n == FORCE[t.target_label]


# -- golden value ---------------------------------------------------------------------------------
# Computed once from build_schedule(default_protocol(), seed=7, participant_number=1) and pasted:
# any change to the shuffling (RNG, seeding, cell order) changes every stored study and must be deliberate.
GOLDEN_SEED_7_P1 = [
    ("FIRM", "off"), ("GENTLE", "off"), ("FIRM", "off"), ("GENTLE", "off"), ("FIRM", "off"),
    ("GENTLE", "on"), ("FIRM", "on"), ("FIRM", "on"), ("GENTLE", "on"), ("FIRM", "on"),
    ("FIRM", "on"), ("GENTLE", "on"), ("GENTLE", "off"), ("FIRM", "off"), ("FIRM", "on"),
    ("GENTLE", "on"), ("GENTLE", "on"), ("FIRM", "off"), ("GENTLE", "off"), ("GENTLE", "off"),
]

GOLDEN_BLOCKED_SEED_7_P1 = [
    # the ON block
    ("FIRM", "on"), ("GENTLE", "on"), ("FIRM", "on"), ("FIRM", "on"), ("FIRM", "on"),
    ("GENTLE", "on"), ("GENTLE", "on"), ("GENTLE", "on"), ("GENTLE", "on"), ("FIRM", "on"),
    # then the OFF block
    ("GENTLE", "off"), ("FIRM", "off"), ("GENTLE", "off"), ("GENTLE", "off"), ("FIRM", "off"),
    ("GENTLE", "off"), ("GENTLE", "off"), ("FIRM", "off"), ("FIRM", "off"), ("FIRM", "off"),
]


def test_golden_schedule_of_the_default_protocol():
    schedule = build_schedule(default_protocol(), seed=7, participant_number=1)
    assert _pairs(schedule) == GOLDEN_SEED_7_P1
    assert schedule == [
        TrialSpec(i, label, FORCE[label], mode, None) for i, (label, mode) in enumerate(GOLDEN_SEED_7_P1)
    ]


def test_golden_schedule_blocked_by_mode():
    assert _pairs(build_schedule(_protocol("blocked_by_mode"), seed=7,
                                 participant_number=1)) == GOLDEN_BLOCKED_SEED_7_P1


def test_participant_number_defaults_to_one():
    assert build_schedule(default_protocol(), seed=7) == build_schedule(default_protocol(), seed=7,
                                                                        participant_number=1)


# -- balance --------------------------------------------------------------------------------------
@pytest.mark.parametrize("ordering", ORDERINGS)
def test_every_cell_occurs_exactly_trials_per_cell_times(ordering):
    protocol = _protocol(ordering)
    expected = Counter({(t, m): 5 for t in ("GENTLE", "FIRM") for m in ("on", "off")})
    for seed in range(60):
        for participant in (1, 2, 3, 10):
            schedule = build_schedule(protocol, seed=seed, participant_number=participant)
            assert len(schedule) == 20
            assert Counter(_pairs(schedule)) == expected
            _is_well_formed(schedule)


@pytest.mark.parametrize("ordering", ORDERINGS)
def test_balance_for_another_protocol_shape(ordering):
    protocol = _protocol(
        ordering, targets=(Target("A", 0.3), Target("B", 0.9), Target("C", 1.5)), modes=("off", "on"), trials_per_cell=2
    )
    for seed in range(30):
        schedule = build_schedule(protocol, seed=seed, participant_number=1 + seed % 4)
        assert Counter(_pairs(schedule)) == Counter({(t, m): 2 for t in "ABC" for m in ("on", "off")})
        assert [t.index for t in schedule] == list(range(12))


def test_single_mode_protocol_has_only_that_mode():
    protocol = _protocol("counterbalanced", modes=("off",))
    for participant in (1, 2):
        schedule = build_schedule(protocol, seed=3, participant_number=participant)
        assert Counter(_pairs(schedule)) == Counter({("GENTLE", "off"): 5, ("FIRM", "off"): 5})


# -- seeding --------------------------------------------------------------------------------------
@pytest.mark.parametrize("ordering", ORDERINGS)
def test_same_seed_and_participant_give_the_same_schedule(ordering):
    protocol = _protocol(ordering)
    for seed in (0, 7, 2**40):
        assert build_schedule(protocol, seed=seed, participant_number=4) == build_schedule(
            protocol, seed=seed, participant_number=4
        )


def test_different_seeds_give_different_random_schedules():
    protocol = _protocol("random")
    schedules = {tuple(_pairs(build_schedule(protocol, seed=seed, participant_number=1))) for seed in range(100)}
    assert len(schedules) == 100


def test_different_participants_with_one_seed_give_different_random_schedules():
    protocol = _protocol("random")
    schedules = {tuple(_pairs(build_schedule(protocol, seed=7, participant_number=n))) for n in range(1, 51)}
    assert len(schedules) == 50


def test_participant_number_below_one_is_refused():
    with pytest.raises(ValueError, match=r"participant_number = 0: must be ≥ 1"):
        build_schedule(default_protocol(), seed=7, participant_number=0)


# -- ordering methods -----------------------------------------------------------------------------
def test_blocked_by_mode_runs_all_of_one_mode_before_the_other():
    protocol = _protocol("blocked_by_mode")
    first_modes = Counter()
    for seed in range(40):
        modes = [t.haptic_mode for t in build_schedule(protocol, seed=seed, participant_number=1)]
        first = modes[0]
        other = "off" if first == "on" else "on"
        assert modes == [first] * 10 + [other] * 10
        first_modes[first] += 1
    # the mode order is drawn from the seed: both orders occur
    assert set(first_modes) == {"on", "off"}


def test_blocked_by_mode_shuffles_targets_within_blocks():
    protocol = _protocol("blocked_by_mode")
    blocks = {tuple(_pairs(build_schedule(protocol, seed=seed))[:10]) for seed in range(40)}
    assert len(blocks) > 2


@pytest.mark.parametrize(("participant", "first"), [(1, "on"), (2, "off"), (3, "on"), (4, "off"), (11, "on")])
def test_counterbalanced_alternates_the_starting_mode(participant, first):
    other = "off" if first == "on" else "on"
    for seed in (0, 7, 99):
        modes = [t.haptic_mode for t in build_schedule(_protocol("counterbalanced"), seed=seed,
                                                       participant_number=participant)]
        assert modes == [first] * 10 + [other] * 10


def test_counterbalanced_follows_the_protocols_mode_order():
    protocol = _protocol("counterbalanced", modes=("off", "on"))
    assert build_schedule(protocol, seed=1, participant_number=1)[0].haptic_mode == "off"
    assert build_schedule(protocol, seed=1, participant_number=2)[0].haptic_mode == "on"


def test_haptic_mode_values_serialise_unchanged():
    assert [str(m) for m in HapticMode] == ["on", "off"]
    assert HapticMode("on") == "on"


# -- re-queueing an aborted trial -----------------------------------------------------------------
def _schedule() -> list[TrialSpec]:
    return build_schedule(default_protocol(), seed=7, participant_number=1)


def test_append_puts_the_rerun_at_the_end():
    schedule = _schedule()
    aborted = schedule[3]
    new = requeue_aborted(schedule, aborted, 4, "append", np.random.default_rng(0))
    assert len(new) == 21
    assert new[:4] == schedule[:4]  # already run: unchanged, including the aborted one
    assert new[4:20] == schedule[4:]  # nothing inserted before them: same indices
    assert new[20] == TrialSpec(20, aborted.target_label, aborted.target_force_n, aborted.haptic_mode, repeat_of=3)
    assert [t.index for t in new] == list(range(21))
    assert schedule == _schedule()  # the input list is not modified


def test_append_does_not_use_the_rng():
    schedule = _schedule()
    rng = np.random.default_rng(5)
    requeue_aborted(schedule, schedule[0], 1, "append", rng)
    assert rng.integers(0, 2**32) == np.random.default_rng(5).integers(0, 2**32)


def test_reinsert_puts_the_rerun_among_the_trials_not_yet_run():
    schedule = _schedule()
    aborted = schedule[3]
    # default_rng(1).integers(0, 17) == 8: slot 8 of the 17 slots around the 16 remaining trials
    new = requeue_aborted(schedule, aborted, 4, "reinsert", np.random.default_rng(1))
    assert len(new) == 21
    assert new[:4] == schedule[:4]
    assert new[12] == TrialSpec(12, aborted.target_label, aborted.target_force_n, aborted.haptic_mode, repeat_of=3)
    rest = new[4:12] + new[13:]
    assert [t.index for t in new] == list(range(21))
    assert [(t.target_label, t.target_force_n, t.haptic_mode, t.repeat_of) for t in rest] == [
        (t.target_label, t.target_force_n, t.haptic_mode, t.repeat_of) for t in schedule[4:]
    ]


def test_reinsert_is_reproducible_and_spreads_over_the_remaining_slots():
    schedule = _schedule()
    aborted = schedule[3]
    positions = []
    for seed in range(200):
        a = requeue_aborted(schedule, aborted, 4, "reinsert", np.random.default_rng(seed))
        b = requeue_aborted(schedule, aborted, 4, "reinsert", np.random.default_rng(seed))
        assert a == b
        assert a[:4] == schedule[:4]
        reruns = [t.index for t in a if t.repeat_of == 3]
        assert len(reruns) == 1
        positions.append(reruns[0])
    assert set(positions) == set(range(4, 21))


def test_requeue_keeps_earlier_repeat_marks_and_reruns_a_rerun():
    schedule = _schedule()
    first = requeue_aborted(schedule, schedule[0], 1, "append", np.random.default_rng(0))
    assert first[20].repeat_of == 0
    # the re-run itself is aborted later: its re-run points to it, the old mark stays
    second = requeue_aborted(first, first[20], 21, "append", np.random.default_rng(0))
    assert second[:21] == first
    assert second[21] == TrialSpec(21, first[20].target_label, first[20].target_force_n, first[20].haptic_mode, 20)
    # re-queueing mid-schedule keeps a pending re-run's mark while renumbering it
    third = requeue_aborted(first, first[5], 6, "reinsert", np.random.default_rng(1))
    marks = sorted((t.repeat_of, t.index) for t in third if t.repeat_of is not None)
    assert [m[0] for m in marks] == [0, 5]
    assert [t.index for t in third] == list(range(22))


def test_completed_trials_stay_balanced_after_requeue():
    schedule = _schedule()
    new = requeue_aborted(schedule, schedule[3], 4, "reinsert", np.random.default_rng(2))
    counted = [t for t in new if t.index != 3]  # the aborted trial does not count
    assert Counter(_pairs(counted)) == Counter(_pairs(schedule))


# -- JSON -----------------------------------------------------------------------------------------
def test_schedule_json_round_trip():
    schedule = requeue_aborted(_schedule(), _schedule()[2], 3, "reinsert", np.random.default_rng(4))
    assert any(t.repeat_of == 2 for t in schedule)
    text = schedule_to_json(schedule)
    assert schedule_from_json(text) == schedule
    assert schedule_to_json(schedule_from_json(text)) == text


def test_schedule_json_format():
    text = schedule_to_json([TrialSpec(0, "GENTLE", 0.6, "on"), TrialSpec(1, "FIRM", 1.2, "off", repeat_of=0)])
    assert text == (
        '[{"index": 0, "target_label": "GENTLE", "target_force_n": 0.6, "haptic_mode": "on", "repeat_of": null}, '
        '{"index": 1, "target_label": "FIRM", "target_force_n": 1.2, "haptic_mode": "off", "repeat_of": 0}]'
    )
