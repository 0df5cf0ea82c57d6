"""The loop's own checks on itself, on the virtual clock: late ticks, stalls, a ramp-down that fails, a dead loop and
the robot.

* a tick later than the Touch's command timeout (10 ms) finds the device's
  output dropped: the loop restarts it from zero (no kick back to the old
  force) and says so; one later than ``loop_stall_s`` (50 ms) latches
  ``LOOP_STALLED``;
* a deliberate pause (a ramp-down, then a calibration) is not a stall;
* the ramp-down's final zero command goes out whatever failed before it;
* a loop that dies with a teleoperated robot stops the robot: through its
  ramp-down (``stop_motion``) and, when its thread is found dead, through
  the fault hook of :meth:`HapticLoop.fail_safe`.
"""

from __future__ import annotations

import math

import pytest
from drivers import PressAndHold
from test_teleop_faults import Teleop

from pipeline.assembly.engine import Engine, EngineConfig, build_sim_engine
from pipeline.devices.interfaces import Fault
from pipeline.devices.teleop import TeleopState
from pipeline.runtime.loop_messages import ResetFaults

MS = 1_000_000


def pressing() -> Engine:
    eng = build_sim_engine(EngineConfig(clock="virtual", driver="hold"))
    eng.rig.set_driver(PressAndHold(-0.018))
    eng.loop.run_ticks(1500)  # ramped in, pressing steadily
    r = eng.loop.last_record
    assert r is not None and r["gain"] == 1.0 and math.hypot(r["render_fx"], r["render_fy"], r["render_fz"]) > 0.3
    return eng


def render(eng: Engine) -> float:
    r = eng.loop.last_record
    assert r is not None
    return math.hypot(r["render_fx"], r["render_fy"], r["render_fz"])


def test_a_tick_later_than_the_command_timeout_restarts_the_output_from_zero() -> None:
    eng = pressing()
    before = render(eng)
    eng.clock.advance(20 * MS)  # the loop stalled 20 ms: the Touch dropped its output after 10
    eng.loop.run_ticks(1)
    assert eng.rig.haptic.applied_force_n == (0.0, 0.0, 0.0)  # what the Touch rendered on the late tick
    # the output ramps in from zero: one ramp-in step (a late tick counts as at most 5 ms), not back to the old force
    assert eng.loop.last_record["gain"] == pytest.approx(0.005 / 0.5)
    assert render(eng) < 0.02 * before
    (ev,) = [e for e in eng.loop.events if e.kind == "output_restarted"]
    assert ev.detail.startswith("no loop tick for 21.0 ms: the haptic device's command watchdog (10 ms) had dropped")
    assert eng.loop.faults == 0
    eng.loop.run_ticks(600)  # ramps in again over 0.5 s, not in one step
    assert render(eng) == pytest.approx(before, rel=0.1)


def test_a_tick_later_than_the_stall_limit_latches_loop_stalled_until_reset() -> None:
    eng = pressing()
    eng.clock.advance(60 * MS)
    eng.loop.run_ticks(1)
    assert eng.loop.faults == Fault.LOOP_STALLED and render(eng) == 0.0
    (ev,) = [e for e in eng.loop.events if e.kind == "fault"]
    assert ev.detail.startswith("LOOP_STALLED: no loop tick for 61.0 ms (limit 50 ms); the haptic device's command "
                                "watchdog had dropped the force to zero after 10 ms")
    eng.loop.run_ticks(100)
    assert render(eng) == 0.0 and eng.loop.faults == Fault.LOOP_STALLED
    eng.loop.submit(ResetFaults())  # the condition (a late tick) is gone: the reset clears it
    eng.loop.run_ticks(1)
    assert eng.loop.faults == 0


def test_a_ramp_down_then_a_pause_is_not_a_stall() -> None:
    eng = pressing()
    eng.loop.ramp_down()
    eng.clock.advance(12_000 * MS)  # e.g. a calibration on the rig
    eng.loop.run_ticks(10)
    assert eng.loop.faults == 0 and not [e for e in eng.loop.events if e.kind in ("fault", "output_restarted")]


def test_the_ramp_down_commands_zero_even_when_its_ticks_fail() -> None:
    eng = pressing()
    eng.rig.sensor.read_wrench = lambda: (_ for _ in ()).throw(OSError("socket closed"))
    with pytest.raises(OSError):
        eng.loop.ramp_down()
    assert eng.rig.haptic.output.commanded == (0.0, 0.0, 0.0)


def test_a_loop_that_dies_stops_the_teleoperated_robot_through_its_ramp_down() -> None:
    t = Teleop()
    t.engage_and_move()
    stops = t.robot.servo_stops
    t.eng.rig.sensor.read_wrench = lambda: (_ for _ in ()).throw(OSError("socket closed"))
    with pytest.raises(OSError):
        t.loop.run(max_ticks=10)  # the thread's body: a tick raises, its finally ramps down
    assert t.robot.servo_stops == stops + 1 and t.ctl.state is TeleopState.FAULT
    assert t.ctl.stop_reason == "haptic loop stopped"


def test_a_dead_loop_thread_found_by_its_supervisor_stops_the_teleoperated_robot() -> None:
    t = Teleop()
    t.engage_and_move()
    stops = t.robot.servo_stops
    # the thread died without running its ramp-down (killed outright): the supervisor's fail-safe tells the rig
    ev = t.loop.fail_safe("the haptic loop thread died (SystemExit())", thread_dead=True)
    assert ev.kind == "fault" and ev.faults == Fault.LOOP_STALLED
    assert t.loop.faults == Fault.LOOP_STALLED
    assert t.robot.servo_stops == stops + 1 and t.ctl.state is TeleopState.FAULT
    assert "LOOP_STALLED" in t.ctl.stop_reason and t.driver.inhibit
    assert t.eng.rig.haptic.output.commanded == (0.0, 0.0, 0.0)
