"""``UrRtdeServo`` (pipeline/backends/ur_control.py) with a fake control interface injected through its constructor.

ur_rtde's ``RTDEControlInterface`` uploads a URScript program and needs the
controller's primary/secondary interfaces and dashboard server, so a
protocol-level loopback fake (as for the Net F/T or the RTDE receive side) is
out of scope: :class:`fake_ur_control.FakeControl` stands in for the
interface object itself, through ``control_factory``.  The TCP probe that
precedes it is real (a listening socket on loopback).

The adapter's targets are aged on an injected :class:`VirtualClock`; its
worker thread wakes every control period (8 ms) on its own, so the tests wait
on the fake's calls with small bounded timeouts and never sleep.
"""

from __future__ import annotations

import math
import socket
import threading
import time
from collections.abc import Iterator

import pytest
from fake_ur_control import FakeControl

from pipeline.backends.ur import RtdeLink
from pipeline.backends.ur_control import UrRtdeServo
from pipeline.core.clock import VirtualClock
from pipeline.devices.interfaces import DeviceError, TcpServo
from pipeline.sim.robot import TOOL_DOWN

QUIET_S = 0.05  # how long "nothing happens" is watched (> 6 worker periods)


@pytest.fixture
def listener() -> Iterator[int]:
    """A loopback port that accepts TCP connections (the UR's RTDE port, for the probe)."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(8)
    try:
        yield s.getsockname()[1]
    finally:
        s.close()


def open_servo(port: int, fake: FakeControl, clock: VirtualClock, **kw: object) -> UrRtdeServo:
    made: list[tuple[str, float]] = []

    def factory(host: str, frequency_hz: float) -> FakeControl:
        made.append((host, frequency_hz))
        return fake

    servo = UrRtdeServo(RtdeLink("127.0.0.1", clock=clock, port=port), control_factory=factory, **kw)  # type: ignore[arg-type]
    assert made == [("127.0.0.1", 125.0)]
    return servo


def test_servol_gets_the_pose_as_position_and_rotation_vector(listener: int) -> None:
    fake, clock = FakeControl(), VirtualClock()
    servo = open_servo(listener, fake, clock, lookahead_s=0.05, gain=500.0)
    try:
        assert isinstance(servo, TcpServo)
        servo.stop_servo()  # nothing moving yet: not even a servoStop
        servo.servo_tcp((0.3, -0.1, 0.2), TOOL_DOWN)
        assert fake.wait_count("servoL", 1)
        pose, speed, acc, period, look, gain = fake.calls[0][1]
        assert pose[:3] == [0.3, -0.1, 0.2] and pose[3:] == pytest.approx([math.pi, 0.0, 0.0], abs=1e-12)
        assert (speed, acc, period, look, gain) == (0.0, 0.0, 0.008, 0.05, 500.0)
        assert fake.names() == ["servoL"] and servo.servo_error == ""
    finally:
        servo.close()


def test_a_control_interface_that_never_comes_up_is_a_clear_error_naming_the_host(listener: int) -> None:
    release = threading.Event()

    def hangs(host: str, frequency_hz: float) -> FakeControl:
        release.wait(5.0)  # the URScript never starts (pendant in local mode, brakes on)
        return FakeControl()

    t0 = time.monotonic()
    try:
        with pytest.raises(DeviceError, match=r"^the UR controller at 127\.0\.0\.1 did not start the ur_rtde control "
                                              r"script within 0\.2 s; is the robot in remote control mode"):
            UrRtdeServo(RtdeLink("127.0.0.1", port=listener), control_timeout_s=0.2, control_factory=hangs)
        assert time.monotonic() - t0 < 1.0  # bounded by the timeout: no hang
    finally:
        release.set()

    def refuses(host: str, frequency_hz: float) -> FakeControl:
        raise RuntimeError("RTDE control script not running")

    with pytest.raises(DeviceError, match=r"^ur_rtde could not take control of the UR controller at 127\.0\.0\.1: "
                                          r"RTDE control script not running$"):
        UrRtdeServo(RtdeLink("127.0.0.1", port=listener), control_factory=refuses)


def test_an_unreachable_controller_is_refused_before_the_control_interface_is_built() -> None:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # nothing listens there now
    built: list[str] = []
    with pytest.raises(DeviceError, match=rf"^cannot reach the UR controller at 127\.0\.0\.1:{port} for teleoperation "
                                          r"\(Connection refused\); check the IP address"):
        UrRtdeServo(RtdeLink("127.0.0.1", port=port, connect_timeout_s=0.3),
                    control_factory=lambda h, f: built.append(h))
    assert built == []
    with pytest.raises(ValueError, match=r"lookahead_s = 0\.5: servoL allows 0\.03 to 0\.2 s"):
        UrRtdeServo(RtdeLink("127.0.0.1", port=port), lookahead_s=0.5)
    with pytest.raises(ValueError, match=r"gain = 50: servoL allows 100 to 2000"):
        UrRtdeServo(RtdeLink("127.0.0.1", port=port), gain=50)


def clear_error_and_resume(servo: UrRtdeServo, fake: FakeControl) -> None:
    """While an error is latched, targets are not sent; a requested, accepted servoStop clears it."""
    n_servo, n_stop = fake.count("servoL"), fake.count("servoStop")
    servo.servo_tcp((0.31, -0.1, 0.2), TOOL_DOWN)
    assert not fake.wait_count("servoL", n_servo + 1, QUIET_S)  # ignored while the error is latched
    assert servo.servo_error
    servo.stop_servo()  # what the teleoperation controller sends while it is faulted
    assert fake.wait_count("servoStop", n_stop + 1)
    servo.servo_tcp((0.32, -0.1, 0.2), TOOL_DOWN)  # sent only once the error is gone
    assert fake.wait_count("servoL", n_servo + 1)
    assert fake.calls[-1][1][0][:3] == [0.32, -0.1, 0.2] and servo.servo_error == ""


def test_servol_refused_reports_a_latched_error_until_a_successful_servostop(listener: int) -> None:
    fake, clock = FakeControl(), VirtualClock()
    servo = open_servo(listener, fake, clock)
    try:
        fake.servo_ok = False  # protective stop: the controller refuses targets
        servo.servo_tcp((0.3, -0.1, 0.2), TOOL_DOWN)
        assert fake.wait_count("servoStop", 1)  # the worker stops the robot at once ...
        assert fake.names() == ["servoL", "servoStop"]
        # ... and the error stays for the controller to see (it latches a teleoperation fault)
        assert not fake.wait_count("servoStop", 2, QUIET_S)
        assert servo.servo_error == "servoL refused the target (protective stop, or the control script is not running)"
        assert not servo.servoing
        # a requested stop the controller refuses does not clear it either
        fake.stop_ok = False
        servo.stop_servo()
        assert fake.wait_count("servoStop", 2)
        assert not fake.wait_count("servoStop", 3, QUIET_S)
        assert servo.servo_error.endswith("; servoStop refused")
        fake.stop_ok = fake.servo_ok = True
        clear_error_and_resume(servo, fake)
    finally:
        servo.close()


def test_no_new_target_for_50_ms_stops_the_robot_by_itself(listener: int) -> None:
    fake, clock = FakeControl(), VirtualClock()
    servo = open_servo(listener, fake, clock)
    try:
        servo.servo_tcp((0.3, -0.1, 0.2), TOOL_DOWN)
        assert fake.wait_count("servoL", 1)
        clock.advance(50_000_000)  # exactly the limit: still fine
        assert not fake.wait_count("servoStop", 1, QUIET_S)
        assert servo.servo_error == ""
        clock.advance(1_000_000)  # the loop stalled: 51 ms without a target
        assert fake.wait_count("servoStop", 1)
        assert fake.names() == ["servoL", "servoStop"] and fake.calls[1][1] == (10.0,)
        assert servo.servo_error == "no teleoperation target for 51 ms: stopped the robot" and not servo.servoing
        clear_error_and_resume(servo, fake)
    finally:
        servo.close()


def test_a_target_picked_up_too_late_is_not_sent(listener: int) -> None:
    fake, clock = FakeControl(), VirtualClock()
    servo = open_servo(listener, fake, clock)
    try:
        # the worker runs on the loop's clock: a target already 60 ms old when seen must not move the robot
        with servo._cond:  # hold the worker off while the clock runs on
            servo.servo_tcp((0.3, -0.1, 0.2), TOOL_DOWN)
            clock.advance(60_000_000)
        assert not fake.wait_count("servoL", 1, QUIET_S)
        assert servo.servo_error == ""  # nothing was moving, nothing to stop
    finally:
        servo.close()


def test_close_stops_the_robot_first_then_ends_the_script_and_joins_the_worker(listener: int) -> None:
    fake, clock = FakeControl(), VirtualClock()
    servo = open_servo(listener, fake, clock)
    servo.servo_tcp((0.3, -0.1, 0.2), TOOL_DOWN)
    assert fake.wait_count("servoL", 1)
    worker = servo._thread
    alive_at_stop: list[bool] = []
    fake.on_call = lambda name: alive_at_stop.append(worker.is_alive()) if name == "servoStop" else None
    servo.close()
    assert fake.names() == ["servoL", "servoStop", "stopScript", "disconnect"]
    assert fake.calls[1][1] == (10.0,)
    assert alive_at_stop == [False] and not worker.is_alive()  # joined before the stop, so nothing races it
    servo.close()  # idempotent
    assert fake.names() == ["servoL", "servoStop", "stopScript", "disconnect"]


def test_close_releases_the_script_even_when_the_stop_fails(listener: int) -> None:
    fake, clock = FakeControl(), VirtualClock()
    servo = open_servo(listener, fake, clock)
    fake.stop_raises = RuntimeError("RTDE link lost")
    servo.close()
    assert fake.names() == ["servoStop", "stopScript", "disconnect"] and not servo._thread.is_alive()
