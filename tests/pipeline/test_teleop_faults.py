"""The haptic loop's faults stop a teleoperated robot: a real HapticLoop on the simulated rig, on the virtual clock.

The simulated hand sweeps the stylus up and down with the deadman held, so
the arm is moving when the fault strikes.  Each case checks, tick by tick:

* from the tick the loop latches the fault, the teleoperation driver sends
  no new target (the arm's commanded target stops changing at once);
* the simulated UR carries out ``servoStop`` at its next 125 Hz cycle (within
  one 8 ms control period) and the arm stays exactly where it stopped;
* the robot does not move while the fault is latched -- not even after the
  deadman is released and pressed again;
* after the experimenter resets the faults the robot still does not move
  until the deadman is released and pressed again; then it engages where the
  arm rests (no jump) and follows the stylus.
"""

from __future__ import annotations

import math

import pytest

from pipeline.assembly.engine import Engine, EngineConfig, build_sim_engine
from pipeline.devices.interfaces import Fault
from pipeline.devices.teleop import ServoTarget, TeleopConfig, TeleopController, TeleopDriver, TeleopState
from pipeline.runtime.loop_messages import ControllerDetached, OperatorStop, ResetFaults
from pipeline.sim.hand import HandObservation

DEADMAN = 1
PERIOD_TICKS = 8  # the simulated CB3's control period, in 1 ms loop ticks
LO, HI = (0.2, -0.1, 0.105), (0.4, 0.1, 0.2)  # the tool stays above the tissue (surface at z = 0.10 m)


class Sweep:
    """The hand moves the stylus 0..20 mm up and back (1 s period): the arm is always moving."""

    def equilibrium_y(self, obs: HandObservation) -> float:
        return 0.01 * (1.0 - math.cos(2.0 * math.pi * obs.t_s))


class Teleop:
    """A simulated engine whose arm is driven by a TeleopDriver from the simulated Touch."""

    def __init__(self) -> None:
        self.eng: Engine = build_sim_engine(EngineConfig(clock="virtual", calibrate=False, driver="hold"))
        rig = self.eng.rig
        rig.set_driver(Sweep())
        self.robot = rig.robot
        self.ctl = TeleopController(TeleopConfig(LO, HI, max_speed_m_s=0.1, rot_haptic_base=rig.config.rot_haptic_base))
        self.driver = TeleopDriver(self.ctl, rig.haptic, rig.robot, rig.robot)
        rig.attach_teleop(self.driver)
        self.loop = self.eng.loop

    def buttons(self, b: int) -> None:
        self.eng.rig.haptic.buttons = b

    def tick(self) -> tuple[int, int, tuple[float, ...], bool]:
        """One loop tick; (latched faults, servo targets sent so far, arm position, servoing) after it."""
        self.loop.run_ticks(1)
        r = self.robot
        return self.loop.faults, r.servo_commands, tuple(r.position_m), r.servoing

    def run(self, n: int) -> list[tuple[int, int, tuple[float, ...], bool]]:
        return [self.tick() for _ in range(n)]

    def engage_and_move(self) -> None:
        self.buttons(0)
        self.run(50)
        self.buttons(DEADMAN)
        self.run(300)
        assert self.ctl.state is TeleopState.ENGAGED
        assert self.robot.servo_commands > 30 and self.robot.servoing
        z = [s[2][2] for s in self.run(20)]
        assert z[-1] - z[0] > 1e-4  # moving up at several cm/s when the fault strikes


def assert_stops_at_the_latch(t: Teleop, after: list[tuple[int, int, tuple[float, ...], bool]], fault: Fault) -> int:
    """The latch tick's index; checks no target after it and the arm at rest within one control period."""
    k = next(i for i, s in enumerate(after) if s[0])
    assert Fault(after[k][0]) & fault
    sent = after[k][1]
    assert all(s[1] == sent for s in after[k:])  # no new target from the latching tick on
    rest = next(i for i, s in enumerate(after) if i >= k and not s[3])
    assert rest - k <= PERIOD_TICKS  # servoStop carried out at the UR's next cycle
    pos = after[rest][2]
    assert all(s[2] == pos for s in after[rest:])  # and the arm stays exactly there
    assert t.ctl.state is TeleopState.FAULT and fault.describe() in t.ctl.stop_reason
    return k


def assert_still(after: list[tuple[int, int, tuple[float, ...], bool]], sent: int, pos: tuple[float, ...]) -> None:
    assert all(s[1] == sent and s[2] == pos for s in after)


@pytest.mark.parametrize("kind", ["operator_stop", "sensor_stall", "nan_burst", "engine_detached"])
def test_a_latched_loop_fault_stops_the_robot_and_reengaging_needs_reset_then_deadman(kind: str) -> None:
    t = Teleop()
    t.engage_and_move()
    sensor = t.eng.rig.sensor
    if kind == "operator_stop":
        t.loop.submit(OperatorStop())
        fault = Fault.OPERATOR_STOP
    elif kind == "engine_detached":
        t.loop.submit(ControllerDetached())
        fault = Fault.ENGINE_DETACHED
    elif kind == "sensor_stall":
        sensor.stalled = True
        fault = Fault.SENSOR_STALE
    else:
        sensor.inject_nan = True
        fault = Fault.NON_FINITE
    after = t.run(300)
    k = assert_stops_at_the_latch(t, after, fault)
    # latched on the first tick (command or NaN), or once the last sample (from the tick before the stall)
    # is more than 5 ms old (stall: 6 ms at the sixth tick)
    assert k == (5 if kind == "sensor_stall" else 0)
    sent, pos = after[-1][1], after[-1][2]

    # the condition goes away; while the fault is latched even release-and-press does not move the robot
    sensor.stalled = sensor.inject_nan = False
    t.buttons(0)
    quiet = t.run(50)
    t.buttons(DEADMAN)
    quiet += t.run(200)
    assert_still(quiet, sent, pos)
    assert t.loop.faults and t.ctl.state is TeleopState.FAULT and t.driver.inhibit

    # the experimenter resets: the deadman is still held, so nothing moves
    t.loop.submit(ResetFaults())
    quiet = t.run(300)
    assert quiet[0][0] == 0 and t.driver.inhibit == ""
    assert_still(quiet, sent, pos)
    assert t.ctl.state is TeleopState.FAULT

    # release and press: engages where the arm rests, then follows the stylus again
    t.buttons(0)
    quiet = t.run(20)
    assert_still(quiet, sent, pos)
    assert t.ctl.state is TeleopState.IDLE
    t.buttons(DEADMAN)
    t.tick()
    assert t.ctl.state is TeleopState.ENGAGED
    first = t.driver.last_command
    assert isinstance(first, ServoTarget) and first.position_m == pos
    moving = t.run(300)
    assert moving[-1][1] > sent + 30 and moving[-1][2] != pos


def test_the_hook_runs_only_when_the_latched_set_changes() -> None:
    t = Teleop()
    calls: list[Fault] = []
    inner = t.driver.on_faults
    t.driver.on_faults = lambda f: (calls.append(f), inner(f))
    t.engage_and_move()
    t.run(500)
    assert calls == []  # fault-free steady state: never called
    t.loop.submit(OperatorStop())
    t.run(5)
    t.loop.submit(OperatorStop())  # already latched: no change, no call
    t.eng.rig.sensor.inject_nan = True
    t.run(1)
    t.run(5)  # NON_FINITE persists: no new call
    t.eng.rig.sensor.inject_nan = False
    t.loop.submit(ResetFaults())  # applied before this tick's watchdog: the NaN was still there last tick
    t.run(5)
    assert t.loop.faults == Fault.NON_FINITE and t.driver.inhibit  # a smaller set still holds the robot
    t.loop.submit(ResetFaults())
    t.run(5)
    t.loop.submit(ResetFaults())  # nothing latched: no change, no call
    t.run(5)
    assert calls == [Fault.OPERATOR_STOP, Fault.OPERATOR_STOP | Fault.NON_FINITE, Fault.NON_FINITE, Fault.NONE]
    assert t.driver.inhibit == ""


def test_ramp_down_stops_the_robot_and_a_restart_needs_the_deadman() -> None:
    t = Teleop()
    t.engage_and_move()
    sent = t.robot.servo_commands
    t.loop.ramp_down()
    assert t.robot.servo_commands == sent and t.loop.faults == 0
    assert t.ctl.state is TeleopState.FAULT and t.ctl.stop_reason == "haptic loop stopped"
    after = t.run(300)  # the loop runs again with the deadman still held
    assert not after[-1][3]
    assert_still(after[PERIOD_TICKS:], sent, after[PERIOD_TICKS][2])
    t.buttons(0)
    t.run(20)
    t.buttons(DEADMAN)
    moving = t.run(300)
    assert moving[-1][1] > sent + 30


def test_a_failing_hook_is_reported_and_the_force_still_ramps_down() -> None:
    t = Teleop()
    t.engage_and_move()

    def broken(faults: int) -> None:
        raise RuntimeError("servo adapter gone")

    t.driver.on_faults = broken
    t.loop.submit(OperatorStop())
    t.run(60)
    gone = "the rig could not act on the faults: RuntimeError('servo adapter gone')"
    assert any(gone in e.detail for e in t.loop.events)
    assert t.loop.faults == Fault.OPERATOR_STOP and t.eng.framework.safety.gain == 0.0
