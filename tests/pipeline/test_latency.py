"""The end-to-end latency, stage by stage, measured on a twin of the simulated rig (virtual clock: exact)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.assembly.latency import STEP_N, Latency, Stage, live_stages, robot_stage, simulated_stages
from pipeline.core.tick_record import TICK_DTYPE
from pipeline.force.config import FrameworkConfig
from pipeline.force.pipeline_settings import framework_with


def _by_name(stages: tuple[Stage, ...]) -> dict[str, float]:
    return {s.name: s.ms for s in stages}


def test_the_paper_pipeline_on_the_simulated_rig_stage_by_stage() -> None:
    stages = simulated_stages()
    ms = _by_name(stages)
    # ticks are 1 ms apart on the virtual clock: every figure is a whole number of ticks (tolerance: float sums)
    assert ms["F/T sensor: sampling and transport"] == pytest.approx(0.0, abs=1e-9)  # sampled in the tick
    # a step through a 10-sample moving average reaches half its height 5 samples in: 4 ticks after the step's own
    assert ms["moving average (10 samples)"] == pytest.approx(4.0, abs=1e-9)
    # the rotations and scaling act within the tick, and the filtered 1 N step rises at 43 N/s at the stylus: below
    # the 50 N/s slew limit, which adds nothing
    assert ms["rotations, tanh scaling and the safety stage's slew limit (50 N/s)"] == pytest.approx(0.0, abs=1e-9)
    assert ms["haptic device: its servo renders the command"] == pytest.approx(1.0, abs=1e-9)  # the next servo tick
    (robot,) = [s for s in stages if s.path == "motion"]
    # an 8 ms zero-order hold and a 30 ms first-order lag: half a step after ~4 ms + 30 ms·ln 2 ≈ 25 ms (± a cycle)
    assert 20.0 <= robot.ms <= 34.0
    lat = Latency(stages)
    assert lat.force_ms == pytest.approx(5.0, abs=1e-9) and lat.total_ms == pytest.approx(5.0 + robot.ms, abs=1e-9)


def test_a_longer_window_and_a_bigger_step_show_in_their_stages() -> None:
    ms = _by_name(simulated_stages(framework_with({"filter_window": 50})))
    assert ms["moving average (50 samples)"] == pytest.approx(24.0, abs=1e-9)
    # a 10 N step renders 3·tanh(10/7) = 2.67 N; through 10 samples that rises at 267 N/s: the 50 N/s slew limit
    # stretches it, to half of it after ~1.34 N / 50 N/s = 27 ms from the step (less the filter's own 4 ms)
    big = _by_name(simulated_stages(FrameworkConfig(), step_n=10.0))
    assert 15.0 <= big["rotations, tanh scaling and the safety stage's slew limit (50 N/s)"] <= 30.0


def test_the_breakdown_as_data_and_in_words() -> None:
    lat = Latency((Stage("force", "a", 1.5, "x"), Stage("force", "b", math.nan, "y"), Stage("motion", "c", 20.0, "z")))
    assert lat.force_ms == 1.5 and lat.motion_ms == 20.0 and lat.total_ms == 21.5
    back = Latency.from_dict(lat.to_dict())
    assert back.stages[0] == lat.stages[0] and math.isnan(back.stages[1].ms) and back.step_n == STEP_N
    assert lat.to_dict()["stages"][1]["ms"] is None  # JSON has no NaN
    assert lat.summary() == "tip → hand 1.5 ms, hand → tip 20.0 ms, round trip 21.5 ms (a 1 N step of tip force)"
    assert lat.stages_text("force") == "a 1.5 ms, b –"
    assert Latency((Stage("force", "a", 2.0, "x"),)).summary().startswith("tip → hand 2.0 ms, hand → tip not measured")


def test_the_real_robot_share_comes_from_the_hardware_file() -> None:
    teleop = robot_stage("teleop", 0.03, 125.0)
    assert teleop.ms == pytest.approx(38.0) and "servoL look-ahead 0.03 s" in teleop.name
    observe = robot_stage("observe", None, 125.0)
    assert math.isnan(observe.ms) and "tap test" in observe.source


def test_the_loops_own_share_is_the_median_of_its_records() -> None:
    rows = np.zeros(5, dtype=TICK_DTYPE)
    rows["sensor_age_ns"] = [100_000, 200_000, 300_000, 400_000, 500_000]
    rows["latency_ns"] = rows["sensor_age_ns"] + [40_000, 50_000, 60_000, 70_000, 80_000]
    wait, compute = live_stages(rows)
    assert wait.ms == pytest.approx(0.3) and compute.ms == pytest.approx(0.06)
    assert live_stages(rows[:0]) == ()
