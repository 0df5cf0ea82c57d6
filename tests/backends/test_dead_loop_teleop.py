"""A haptic loop that dies or freezes in teleoperation leaves no robot moving: the stops that reach ``servoStop``.

The bench of :mod:`test_dead_loop` -- the loop in its own thread on a
:class:`stepped_clock.SteppedClock`, the real Touch backend over the HD API
stand-in clocked by the test, the supervisor -- with the robot teleoperated:
a :class:`pipeline.devices.teleop.TeleopDriver` (deadman held) streams targets to the
real servo adapter :class:`pipeline.backends.ur_control.UrRtdeServo`, whose
control interface is the stand-in of :mod:`fake_ur_control`, aged on the same
stepped clock.  The targets come from the loop thread (``Rig.advance``), so a
loop that stops ticking stops them; then:

* frozen loop: nothing of ours runs, and the adapter's own watchdog stops the
  robot 50 ms (exactly: not at 50, at 51) after the last target; when the loop
  runs again it latches ``LOOP_STALLED`` and the robot stays stopped;
* killed loop: its ramp-down stops the robot at once (``Rig.stop_motion``);
  should that fail, the supervisor's latch does (``Rig.on_faults``); should
  every stop path of ours fail, the adapter's watchdog still does, at 51 ms.

The adapter's worker wakes on its own every control period (8 ms, wall
clock), so the test waits for its calls with bounded timeouts; the stepped
clock stands still meanwhile, so every age it judges is exact.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fake_ur_control import FakeControl
from stepped_clock import SteppedClock
from test_dead_loop import MS, Bench, Rig, stalled
from test_ur_control import QUIET_S, listener  # noqa: F401 - the fixture: a loopback port for the adapter's probe

from pipeline.backends.touch import TouchHapticDevice
from pipeline.backends.ur import RtdeLink
from pipeline.backends.ur_control import UrRtdeServo
from pipeline.devices.interfaces import Fault
from pipeline.devices.teleop import TeleopConfig, TeleopController, TeleopDriver, TeleopState

DEADMAN = 1
WATCHDOG_MS = 50  # UrRtdeServo's default target_timeout_s


class TeleopRig(Rig):
    """The dead-loop bench's rig with the robot driven from the stylus (as ``pipeline.assembly.real_rig.RealRig``
    does)."""

    def __init__(self, clock: SteppedClock, touch: TouchHapticDevice, servo: UrRtdeServo) -> None:
        super().__init__(clock, touch)
        self.controller = TeleopController(TeleopConfig((0.2, -0.1, 0.05), (0.4, 0.1, 0.2)))
        self.teleop = TeleopDriver(self.controller, touch, self.robot, servo)
        self.fail_stop_motion = False
        self.fail_on_faults = False

    def advance(self, now_ns: int) -> None:
        super().advance(now_ns)
        self.teleop.update(now_ns)

    def on_faults(self, faults: int) -> None:
        if self.fail_on_faults:
            raise OSError("on_faults failed")
        self.teleop.on_faults(faults)

    def stop_motion(self, reason: str) -> None:
        if self.fail_stop_motion:
            raise OSError("stop_motion failed")
        self.teleop.stop_motion(reason)


class TeleopBench(Bench):
    """The dead-loop bench with the robot teleoperated through the servo adapter on the same stepped clock."""

    def __init__(self, port: int) -> None:
        self.control = FakeControl()

        def make_rig(clock: SteppedClock, touch: TouchHapticDevice) -> TeleopRig:
            self.servo = UrRtdeServo(RtdeLink("127.0.0.1", clock=clock, port=port),
                                     control_factory=lambda h, f: self.control)
            return TeleopRig(clock, touch, self.servo)

        super().__init__(make_rig, buttons=DEADMAN)

    def teleoperating(self) -> None:
        for _ in range(200):
            seq, sent = self.servo._target_seq, self.control.count("servoL")
            self.ms()
            if self.servo._target_seq != seq:
                # the stepped clock waits for the adapter's worker to send it (the worker runs on the wall clock:
                # stepping on regardless would age the target past the adapter's limit before it is picked up);
                # the worker sends only the newest target, so one servoL may stand for two targets
                assert self.control.wait_count("servoL", sent + 1)
        assert self.rig.controller.state is TeleopState.ENGAGED, self.rig.controller.stop_reason
        assert self.control.wait_count("servoL", 5) and self.servo.servoing

    def since_last_target_ms(self) -> float:
        return (self.clock.now_ns() - self.servo._target_ns) / MS

    def stops(self) -> int:
        return self.control.names().count("servoStop")

    def close(self) -> None:
        super().close()
        self.servo.close()


@pytest.fixture
def bench(listener: int) -> Iterator[TeleopBench]:  # noqa: F811 - the imported fixture
    b = TeleopBench(listener)
    try:
        yield b
    finally:
        b.close()


def test_a_frozen_loop_stops_sending_targets_and_the_adapter_s_watchdog_stops_the_robot_at_51_ms(
        bench: TeleopBench) -> None:
    bench.teleoperating()
    bench.rig.sensor.freeze.set()
    bench.ms(done=bench.rig.sensor.frozen_in.is_set)  # the tick hangs in the sensor read: no target from now on
    while bench.since_last_target_ms() < WATCHDOG_MS:
        bench.ms(done=lambda: True)
    assert bench.since_last_target_ms() == WATCHDOG_MS
    assert not bench.control.wait_count("servoStop", 1, QUIET_S)  # exactly the limit: still servoing
    bench.ms(done=lambda: True)  # 51 ms without a target
    assert bench.control.wait_count("servoStop", 1)
    assert bench.servo.servo_error == "no teleoperation target for 51 ms: stopped the robot"
    assert bench.touch.output.rendered_n == (0.0, 0.0, 0.0)  # the Touch had dropped the force 40 ms earlier
    assert stalled(bench.events)  # and the supervisor reported the frozen loop

    # the loop runs again: its late tick latches LOOP_STALLED, and the robot is not driven again
    sent = bench.control.names().count("servoL")
    bench.rig.sensor.freeze.clear()
    bench.rig.sensor.thaw.set()
    for _ in range(100):
        bench.ms()
    assert bench.loop.faults & Fault.LOOP_STALLED
    assert bench.rig.controller.state is TeleopState.FAULT
    assert not bench.control.wait_count("servoL", sent + 1, QUIET_S)


@pytest.mark.parametrize("failing", ["", "stop_motion", "stop_motion and on_faults"])
def test_a_killed_loop_stops_the_robot_at_once_or_through_the_adapter_s_watchdog(bench: TeleopBench,
                                                                                 failing: str) -> None:
    bench.teleoperating()
    bench.rig.fail_stop_motion = "stop_motion" in failing
    bench.rig.fail_on_faults = "on_faults" in failing
    bench.rig.sensor.fail = True  # the tick raises; so do the ramp-down's ticks: the thread dies
    thread = bench.loop._thread
    assert thread is not None
    for _ in range(2):
        bench.ms(done=lambda: not thread.is_alive())
    assert not thread.is_alive() and bench.supervisor.dead  # found at the supervisor's first look
    if failing != "stop_motion and on_faults":
        # the ramp-down's stop (Rig.stop_motion), or else the supervisor's latch (Rig.on_faults): at once
        assert bench.control.wait_count("servoStop", 1)
        assert bench.since_last_target_ms() < WATCHDOG_MS and bench.servo.servo_error == ""
        assert bench.rig.controller.state is TeleopState.FAULT
        return
    # nothing of ours could stop it: the adapter's own watchdog does, 51 ms after the last target
    while bench.since_last_target_ms() < WATCHDOG_MS:
        bench.ms(done=lambda: True)
    assert not bench.control.wait_count("servoStop", 1, QUIET_S)
    bench.ms(done=lambda: True)
    assert bench.control.wait_count("servoStop", 1)
    assert bench.servo.servo_error == "no teleoperation target for 51 ms: stopped the robot"
    assert any("the rig could not act on the faults: OSError('on_faults failed')" in e.detail for e in bench.events)
