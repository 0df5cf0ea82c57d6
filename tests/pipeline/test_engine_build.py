"""Assembling an engine in-process (:mod:`pipeline.assembly.engine`): the simulated rig's instant start-up
calibration."""

from __future__ import annotations

from pipeline.assembly.engine import EngineConfig


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
    from pipeline.assembly.engine import build_sim_engine
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
