"""``haptic-study bench pipeline``'s two-arm figures measure what they say (no timing is asserted)."""

from __future__ import annotations

import math

from bench.pipeline_arms import arms_lines, measure_arms_cost, replay_loop
from bench.pipeline_cost import record_samples


def test_the_two_arm_tick_replays_the_same_inputs_into_each_arms_ring() -> None:
    data = record_samples(1200)
    r = measure_arms_cost(data, batch=400)
    assert r["arms_ticks_timed"] == 800  # the first batch warms up
    assert math.isfinite(r["arms_cost_ratio"]) and r["arms_tick_two_us"] > 0 and r["arms_tick_one_us"] > 0
    rep, loop = replay_loop(data, ("right", "left"))
    for i in range(600):
        rep.i = i
        loop.tick()
    right, left = (ch.ring.read_since(0).rows for ch in loop.arms)  # type: ignore[union-attr]
    assert len(right) == len(left) == 600 and (right["render_fz"] == left["render_fz"]).all()
    assert loop.arms[0].faults == loop.arms[1].faults == 0 and abs(right["render_fz"][-1]) > 0


def test_the_report_lines_say_the_target_and_the_loop_figures() -> None:
    r = {"arms_tick_one_us": 10.0, "arms_tick_two_us": 23.0, "arms_cost_ratio": 2.3, "arms_loop_one_ticks": 5000.0,
         "arms_loop_seconds_each": 5.0, "arms_loop_segments": 2, "arms_loop_one_abs_dev_p99_us": 100.0,
         "arms_loop_two_abs_dev_p99_us": 105.0, "arms_loop_one_over_2ms": 1.0, "arms_loop_two_over_2ms": 2.0,
         "arms_loop_one_segments_p99_us": [100.0, 98.0], "arms_loop_two_segments_p99_us": [105.0, 110.0]}
    text = "\n".join(arms_lines(r))
    assert "2.30x one arm (OVER the 2.2x target)" in text and "one arm 100 µs, two arms 105 µs (+5 %" in text
    assert "one arm 100 / 98 µs, two arms 105 / 110 µs" in text
