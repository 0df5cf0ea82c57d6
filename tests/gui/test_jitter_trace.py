"""Late-tick attribution, the driver's quiet window and the engine's own garbage-collector schedule.

No wall-clock sleeping: the tracer's classification rule is fed scheduler counters directly.
"""

from __future__ import annotations

import gc
import time

import pytest

from pipeline.core.clock import collect_garbage
from pipeline.runtime.jitter_trace import LateTickTracer, _Task
from study_app.engine import messages as m
from study_app.engine.host import QUIET_OFFSET_NS, StudyEngine
from study_app.engine.setup import HostConfig


@pytest.fixture
def tracer():
    t = LateTickTracer()
    t._loop_tid = 999
    t._tasks = [_Task(111, "recorder", None, -1), _Task(222, "MainThread", None, -1)]
    t._planned_sleep = 600_000  # the loop meant to sleep 0.6 ms of the period
    yield t
    t.close()
    assert t._on_gc not in gc.callbacks


def explain(t: LateTickTracer, period_ns: int, loop=(400_000, 0), recorder=(0, 0), main=(0, 0)) -> None:
    prev = {0: (0, 0), 111: (0, 0), 222: (0, 0)}
    t._explain(period_ns, period_ns - 1_000_000, 0, period_ns, prev, {0: loop, 111: recorder, 222: main})


def test_a_thread_using_the_cpu_while_the_loop_was_blocked_held_the_gil(tracer):
    # period 1.9 ms = 0.4 ms running + 0.6 ms planned sleep + 0.9 ms blocked; the recorder ran 0.85 ms meanwhile
    explain(tracer, 1_900_000, recorder=(850_000, 0), main=(20_000, 0))
    s = tracer.summary()
    assert s["causes"] == {"gil:recorder": 1} and s["late_ticks"] == 1 and s["over_2ms"] == 0
    assert s["culprits"] == {"recorder": 1}
    assert s["worst"][0]["loop_blocked_us"] == 900 and s["worst"][0]["others_cpu_us"] == {"recorder": 850}


def test_a_gil_holder_waiting_for_a_cpu_is_named_and_long_periods_are_counted_apart(tracer):
    explain(tracer, 2_500_000, recorder=(50_000, 1_300_000))
    s = tracer.summary()
    assert s["causes"] == {"gil-holder-preempted:recorder": 1}
    assert s["causes_over_2ms"] == {"gil-holder-preempted:recorder": 1}


def test_a_collector_pass_in_the_interval_is_the_cause(tracer):
    tracer._gc_log = [(200_000, 1_100_000, 999, 1)]  # 0.9 ms, generation 1, in the loop thread
    explain(tracer, 1_900_000, loop=(1_300_000, 0))
    s = tracer.summary()
    assert s["causes"] == {"gc": 1} and s["culprits"] == {"generation 1 in the loop thread": 1}


def test_the_loops_own_work_and_a_busy_cpu_and_nothing_at_all(tracer):
    explain(tracer, 1_900_000, loop=(1_200_000, 0))  # the tick itself ran 0.9 ms longer than usual (0.3 ms)
    explain(tracer, 1_900_000, loop=(400_000, 850_000))  # runnable, no CPU
    explain(tracer, 1_900_000)  # blocked, nobody in the process ran: the machine
    assert tracer.summary()["causes"] == {"loop-work": 1, "cpu-busy": 1, "machine": 1}
    tracer.reset()
    assert tracer.summary()["late_ticks"] == 0


def test_only_the_real_clock_is_traced_and_health_carries_the_breakdown():
    events: list[object] = []
    e = StudyEngine(HostConfig(clock="virtual", speed=0, trace_jitter=True), events.append, shared_ring=False)
    try:
        assert e.tracer is None and e.health().late_periods is None
    finally:
        e.close("test over")
        e.release_ring()


def test_the_driver_wakes_just_after_a_loop_tick_about_the_interval_from_now():
    events: list[object] = []
    e = StudyEngine(HostConfig(clock="virtual", speed=0), events.append, shared_ring=False)
    try:
        assert e.quiet_wait_s(0.01) == 0.01  # no tick yet: no grid to lock to
        e.start()
        e.step()
        assert isinstance(events[0], m.EngineReady) and e.loop.tick_count > 0
        # pretend the newest tick started 12.345678 ms ago on the loop's clock (perf_counter_ns)
        before = time.perf_counter_ns()
        e.loop.t0_ns, e.last_t_ns = before - 12_345_678 - 7_000_000, 7_000_000
        wait_s = e.quiet_wait_s(0.01)
        after = time.perf_counter_ns()
        assert 0.009 - 1e-6 <= wait_s <= 0.01 + (after - before) * 1e-9
        last_tick = before - 12_345_678
        # the wake-up lands QUIET_OFFSET_NS after a tick of the 1 ms grid (to within the call's own duration)
        phase = (before + round(wait_s * 1e9) - last_tick - QUIET_OFFSET_NS) % 1_000_000
        assert phase <= 1_000 or phase >= 1_000_000 - (after - before) - 1_000
    finally:
        e.close("test over")
        e.release_ring()


def test_collect_garbage_runs_the_pass_the_collector_would_have_run():
    enabled, threshold = gc.isenabled(), gc.get_threshold()
    gc.disable()
    try:
        gc.set_threshold(500, 3, 1000)
        gc.collect()
        assert collect_garbage() is None  # nothing allocated yet
        keep = []
        for _ in range(3):
            keep.extend([] for _ in range(700))
            assert collect_garbage() == 0
            assert gc.get_count()[0] < 500
        keep.extend([] for _ in range(700))
        assert collect_garbage() == 1  # three young passes since the last middle one
        assert gc.get_count()[1] == 0
    finally:
        gc.set_threshold(*threshold)
        if enabled:
            gc.enable()
