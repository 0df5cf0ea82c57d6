"""The engine process: spawn, run a fixed number of ticks, stop on request, and stop by itself when detached.

The engine runs the loop on the virtual clock (as fast as the CPU allows), so
these tests wait only for process start-up and exit, with bounded timeouts.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import numpy as np
import pytest

from pipeline.devices import Fault
from pipeline.engine import EngineConfig, EngineProcess
from pipeline.loop import RECORD_FIELDS, SetHaptics
from pipeline.safety import SafetyConfig

START_TIMEOUT_S = 30.0
EXIT_TIMEOUT_S = 15.0
PERIOD_NS = 1_000_000
RAMP_TICKS = round(SafetyConfig().fault_ramp_s / (PERIOD_NS * 1e-9))  # 40


@pytest.fixture
def engines() -> Iterator[Callable[..., EngineProcess]]:
    """Make engine processes that are always cleaned up (killed if still running)."""
    made: list[EngineProcess] = []

    def make(config: EngineConfig, max_ticks: int | None = None) -> EngineProcess:
        p = EngineProcess(config, max_ticks=max_ticks)
        made.append(p)
        return p

    yield make
    for p in made:
        p.kill()
        assert not p.alive


def wait_for(pred: Callable[[], bool], timeout_s: float = 10.0) -> None:
    """Poll a condition on the shared ring (no sleeping: the engine fills it at CPU speed)."""
    end = time.monotonic() + timeout_s
    while not pred():
        if time.monotonic() > end:
            raise AssertionError("condition not reached within the timeout")


def latest(proc: EngineProcess) -> np.void:
    rows = proc.ring.latest(1)
    assert len(rows) == 1
    return rows[0]


def test_engine_runs_max_ticks_and_the_parent_reads_every_record(engines):
    proc = engines(EngineConfig(clock="virtual", driver="scripted"), max_ticks=3000)
    proc.start(timeout_s=START_TIMEOUT_S)
    assert proc.ring is not None
    assert proc.ring.fields == RECORD_FIELDS
    assert proc.calibration is not None and "force_bias_n" in str(proc.calibration)

    proc.wait(timeout_s=EXIT_TIMEOUT_S)
    assert not proc.alive
    assert proc.final_stats is not None
    # 3000 ticks of the run, then the ramp-down from full feedback (gain 1 → 0)
    assert proc.final_ticks == 3000 + RAMP_TICKS
    assert proc.final_stats["ticks"] == proc.final_ticks - 1  # periods between ticks
    assert proc.final_stats["period_p50_us"] == 1000.0
    assert proc.final_stats["period_p99_us"] == 1000.0
    assert proc.final_stats["period_max_us"] == 1000.0
    assert proc.final_stats["periods_over_2ms"] == 0.0
    assert proc.final_stats["missed_slots"] == 0.0
    assert proc.final_faults == 0

    ring = proc.ring
    assert ring.write_count == proc.final_ticks
    res = ring.read_since(0)
    assert res.lost == 0 and res.cursor == proc.final_ticks
    rows = res.rows
    assert rows.dtype.names == RECORD_FIELDS
    np.testing.assert_array_equal(rows["tick"], np.arange(proc.final_ticks, dtype=float))
    t_ns = np.round(rows["t_s"] * 1e9).astype(np.int64)
    assert np.all(np.diff(t_ns) == PERIOD_NS)  # t_s increases by exactly 1 ms
    assert np.all(rows["haptic_on"][:3000] == 1.0) and np.all(rows["haptic_on"][3000:] == 0.0)
    assert rows["gain"][2999] == 1.0 and rows["gain"][-1] == 0.0
    assert rows["render_fx"][-1] == 0.0 and rows["render_fy"][-1] == 0.0 and rows["render_fz"][-1] == 0.0
    assert np.all(rows["faults"] == 0.0)
    assert np.all(np.isfinite(rows["render_fy"]))


def test_engine_stops_on_request(engines):
    proc = engines(EngineConfig(clock="virtual"))
    proc.start(timeout_s=START_TIMEOUT_S)
    ring = proc.ring
    wait_for(lambda: ring.write_count >= 1000)
    assert latest(proc)["haptic_on"] == 1.0

    proc.send(SetHaptics(False))
    wait_for(lambda: latest(proc)["haptic_on"] == 0.0 and latest(proc)["gain"] == 0.0)
    seen = ring.write_count
    proc.stop(timeout_s=EXIT_TIMEOUT_S)

    assert not proc.alive
    assert proc.ring is None  # released by stop()
    assert proc.final_stats is not None
    assert proc.final_ticks >= seen
    assert proc.final_stats["ticks"] == proc.final_ticks - 1
    assert proc.final_stats["period_max_us"] == 1000.0
    assert proc.final_faults == 0
    assert proc.loop_events == []


@pytest.mark.parametrize("haptics_on", [True, False], ids=["feedback-on", "feedback-off"])
def test_engine_detached_latches_ramps_down_and_exits_by_itself(engines, haptics_on):
    proc = engines(EngineConfig(clock="virtual", haptics_on=haptics_on))
    proc.start(timeout_s=START_TIMEOUT_S)
    ring = proc.ring
    # running, and (with feedback on) fully faded in
    wait_for(lambda: ring.write_count >= 1000 and latest(proc)["gain"] == (1.0 if haptics_on else 0.0))

    proc.detach()  # as a crashed GUI would: the command pipe breaks
    proc.wait(timeout_s=EXIT_TIMEOUT_S)

    assert not proc.alive
    assert proc.final_stats is not None, "the engine must exit cleanly, reporting its stats"
    assert proc.final_faults is not None and proc.final_faults & Fault.ENGINE_DETACHED
    detached = [e for e in proc.loop_events if e.kind == "fault" and e.detail.startswith("ENGINE_DETACHED: ")]
    assert len(detached) == 1
    assert detached[0].faults & Fault.ENGINE_DETACHED

    last = latest(proc)
    assert ring.write_count == proc.final_ticks
    assert last["gain"] == 0.0
    assert last["render_fx"] == 0.0 and last["render_fy"] == 0.0 and last["render_fz"] == 0.0
    if haptics_on:  # the ramp-down ticks record the latched fault
        assert int(last["faults"]) & Fault.ENGINE_DETACHED
        assert last["haptic_on"] == 0.0


def test_real_clock_engine_explains_late_ticks_when_asked(engines):
    """The one real-clock engine test: 100 ticks (0.1 s) paced on the monotonic clock with the tracer on.

    Timing itself is not asserted (that is ``haptic-study bench pipeline``);
    the run must report its periods and the tracer's accounting of them.
    """
    proc = engines(EngineConfig(clock="real", driver="hold", trace_jitter=True), max_ticks=100)
    proc.start(timeout_s=START_TIMEOUT_S)
    proc.wait(timeout_s=EXIT_TIMEOUT_S)
    assert proc.final_stats is not None and proc.final_ticks is not None
    assert proc.final_stats["ticks"] == proc.final_ticks - 1
    late = proc.late_periods
    assert late is not None
    assert set(late) >= {"late_threshold_us", "ticks", "late_ticks", "causes", "over_2ms", "causes_over_2ms"}
    assert late["late_threshold_us"] == 100.0
    assert late["over_2ms"] <= proc.final_stats["periods_over_2ms"]
    assert sum(late["causes"].values()) == late["late_ticks"]


def test_engine_without_tracing_reports_no_explanation(engines):
    proc = engines(EngineConfig(clock="virtual", trace_jitter=True), max_ticks=10)
    proc.start(timeout_s=START_TIMEOUT_S)
    proc.wait(timeout_s=EXIT_TIMEOUT_S)
    assert proc.final_stats is not None
    assert proc.late_periods is None  # the tracer explains real-clock runs only


class _SteppedClock:
    """A clock that is not a VirtualClock, as the real one is to ``build_sim_engine``, without real time."""

    def __init__(self, t_ns: int) -> None:
        self.t_ns = t_ns

    def now_ns(self) -> int:
        return self.t_ns

    def sleep_until(self, t_ns: int) -> None:
        self.t_ns = max(self.t_ns, t_ns)


def test_a_real_clock_sim_engine_starts_in_the_working_pose_at_once():
    """The instant start-up calibration leaves the rig on the real clock's time, not 12 s ahead of it.

    (Before: the robot held the last calibration pose for the first 12 s of a
    real-clock run, and the stylus moved nothing.)
    """
    from pipeline.engine import build_sim_engine
    from pipeline.sim.robot import TOOL_DOWN

    clock = _SteppedClock(5_000_000_000_000)
    start = clock.now_ns()
    eng = build_sim_engine(EngineConfig(clock="real", driver="hold"), clock=clock)
    assert clock.now_ns() == start  # the calibration took no time on this clock
    eng.loop.run_ticks(10)
    pose = eng.rig.robot.read_pose()
    assert pose.rot_base_tip == TOOL_DOWN
    assert 0 <= clock.now_ns() - pose.t_ns < 8_000_000  # a fresh 125 Hz pose, not one from the future
    assert eng.loop.faults == 0
