"""``build_real_rig`` with ``robot.mode = "teleop"``: open order, the attached driver, and close order.

Every device is the real backend against its loopback fake (Net F/T over UDP
and HTTP, ur_rtde's RTDEReceiveInterface against the fake RTDE server, the
Touch through the pure-Python pyOpenHaptics stand-in, the jaw over a pty),
except the UR's control interface, which cannot be faked at the protocol level
(see fake_ur_control.py) and is injected through ``control_factory``.
"""

from __future__ import annotations

import sys
import threading
import time
import tomllib
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
from fake_jaw import PtyJaw
from fake_netft import FakeNetFT
from fake_rtde import FakeRtde
from fake_ur_control import FakeControl
from test_hardware_config import write_rig_file

from pipeline.assembly.real_rig import RealRig, build_real_rig
from pipeline.backends.touch import TouchHapticDevice
from pipeline.backends.ur_control import UrRtdeServo
from pipeline.core.clock import MonotonicClock
from pipeline.devices.interfaces import DeviceError
from pipeline.devices.teleop import ServoTarget, TeleopDriver, TeleopState
from pipeline.settings.hardware import hardware_from_dict

FAKE_OPENHAPTICS = Path(__file__).resolve().parent / "fake_openhaptics"
OPEN_ORDER = ["force sensor", "robot", "haptic device", "jaw actuator", "robot control (teleoperation)"]


@pytest.fixture
def touch_hd(monkeypatch: pytest.MonkeyPatch) -> Iterator[ModuleType]:
    """The pyOpenHaptics stand-in on sys.path; forgotten afterwards so other tests see no OpenHaptics."""
    monkeypatch.syspath_prepend(str(FAKE_OPENHAPTICS))
    import pyOpenHaptics.hd as hd

    try:
        yield hd
    finally:
        hd.STATE["running"] = False
        for name in [m for m in sys.modules if m == "pyOpenHaptics" or m.startswith("pyOpenHaptics.")]:
            del sys.modules[name]


def until(pred: Callable[[], bool], timeout_s: float = 2.0) -> bool:
    """Poll a condition the devices' own threads make true (bounded; the backends run in real time)."""
    deadline = time.monotonic() + timeout_s
    tick = threading.Event()
    while not pred():
        if time.monotonic() > deadline:
            return False
        tick.wait(0.002)
    return True


def teleop_file(tmp_path: Path, netft: FakeNetFT, rtde: FakeRtde, jaw: PtyJaw, control_timeout_s: float = 1.0) -> Any:
    path = write_rig_file(tmp_path, netft, rtde, jaw)
    d = tomllib.loads(path.read_text(encoding="utf-8"))
    d["robot"]["mode"] = "teleop"
    # the fake controller's TCP is at (0.3, -0.1, 0.2) m
    d["teleop"] = {"workspace_min_m": [0.2, -0.2, 0.1], "workspace_max_m": [0.4, 0.0, 0.3],
                   "control_timeout_s": control_timeout_s}
    return hardware_from_dict(d, str(path))


def test_teleop_rig_opens_the_control_adapter_last_drives_it_and_stops_the_robot_before_closing_the_rest(
    tmp_path: Path, touch_hd: ModuleType
) -> None:
    log: list[str] = []
    fake = FakeControl()
    clock = MonotonicClock()
    with FakeNetFT(rate_hz=1000.0) as netft, FakeRtde() as rtde, PtyJaw() as jaw:
        hw = teleop_file(tmp_path, netft, rtde, jaw)

        def factory(host: str, frequency_hz: float) -> FakeControl:
            # by now every other device has answered: the sensor streams, the Touch's scheduler runs
            log.append(f"control interface for {host} at {frequency_hz:g} Hz")
            assert [r[1] for r in netft.requests] == [2] and touch_hd.STATE["running"]
            return fake

        rig = build_real_rig(hw, clock, on_open=log.append, control_factory=factory)
        try:
            assert log == [*OPEN_ORDER, f"control interface for {rtde.host} at 125 Hz"]
            assert isinstance(rig, RealRig) and isinstance(rig.teleop, TeleopDriver)
            drv = rig.teleop
            assert isinstance(drv.servo, UrRtdeServo) and drv.servo._ctrl is fake
            assert drv.haptic is rig.haptic and isinstance(rig.haptic, TouchHapticDevice) and drv.robot is rig.robot
            assert drv.controller.config.workspace_max_m == (0.4, 0.0, 0.3) and drv.controller.config.period_s == 0.008

            # the attached driver runs in advance(): deadman pressed on the Touch → a target at the measured TCP
            touch_hd.STATE["buttons"] = 1
            assert until(lambda: rig.haptic.read_state().buttons == 1)  # the Touch's next servo tick
            rig.advance(clock.now_ns())
            assert drv.controller.state is TeleopState.ENGAGED, drv.controller.stop_reason
            assert isinstance(drv.last_command, ServoTarget) and drv.last_command.position_m == (0.3, -0.1, 0.2)
            assert fake.wait_count("servoL", 1)
            assert fake.calls[0][1][0][:3] == [0.3, -0.1, 0.2]

            # a loop fault reaches the robot through the rig
            rig.on_faults(64)
            assert drv.controller.state is TeleopState.FAULT and "OPERATOR_STOP" in drv.controller.stop_reason
            assert fake.wait_count("servoStop", 1)
            rig.on_faults(0)

            # what every other device looks like when the robot is told to stop during close()
            seen: list[tuple[list[int], bool, str, bool]] = []
            marker = len(fake.calls)

            def snapshot(name: str) -> None:
                if name == "servoStop":
                    seen.append(([r[1] for r in netft.requests], touch_hd.STATE["running"], rig.robot.state,
                                 rig.jaw._ser is not None))

            fake.on_call = snapshot
        finally:
            rig.close()
        assert [n for n, _ in fake.calls[marker:]] == ["servoStop", "stopScript", "disconnect"]
        assert seen == [([2], True, "connected", True)]  # the robot stopped while everything else was still open
        assert until(lambda: [r[1] for r in netft.requests] == [2, 0]) and not touch_hd.STATE["running"]
        assert rig.robot.state == "closed" and rig.jaw._ser is None and not drv.servo._thread.is_alive()


def test_a_control_adapter_that_fails_closes_every_device_already_open(tmp_path: Path, touch_hd: ModuleType) -> None:
    release = threading.Event()

    def hangs(host: str, frequency_hz: float) -> FakeControl:
        release.wait(5.0)
        return FakeControl()

    with FakeNetFT(rate_hz=1000.0) as netft, FakeRtde() as rtde, PtyJaw() as jaw:
        hw = teleop_file(tmp_path, netft, rtde, jaw, control_timeout_s=0.3)
        opened: list[str] = []
        try:
            with pytest.raises(DeviceError, match=r"^robot control \(teleoperation\): the UR controller at .* did not "
                                                  r"start the ur_rtde control script within 0.3 s"):
                build_real_rig(hw, MonotonicClock(), on_open=opened.append, control_factory=hangs)
        finally:
            release.set()
        assert opened == OPEN_ORDER
        assert until(lambda: [r[1] for r in netft.requests] == [2, 0]) and not touch_hd.STATE["running"]
        assert rtde.wait_for("DISCONNECTED")
