"""``build_real_rig`` with two arms: every arm's devices opened by name, one Touch servo scheduler for both, a
failing device closes what was opened and names its arm, and the loop drives both arms from their own devices.

Net F/T and RTDE are the real backends against two loopback fakes each (two boxes on 127.0.0.2 / 127.0.0.3, two
fake UR controllers); the Touch devices are the real backend in one :class:`pipeline.backends.touch.TouchScheduler`
over :class:`fake_multi_hd.FakeMultiHD` (libHD's current-device semantics), put in at the C library's seam
(``pipeline.backends.touch.PyOpenHapticsApi``): the Touch's backend is chosen by the registry as on a real rig.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from arm_fakes import arm_fakes
from fake_multi_hd import FakeMultiHD, FakeTouch
from fake_netft import FakeNetFT
from fake_rtde import FakeRtde
from waits import until

from pipeline.assembly.engine import build_hardware_engine
from pipeline.assembly.real_rig import RealRig, build_real_rig
from pipeline.backends.netft import NetFTForceSensor
from pipeline.backends.touch import TouchHapticDevice, TouchScheduler
from pipeline.backends.ur_process import UrPoseProcess
from pipeline.core.clock import VirtualClock
from pipeline.core.tick_record import RECORD_FIELDS
from pipeline.devices.interfaces import DeviceError, Fault
from pipeline.devices.touch_output import HD_EXCEEDED_MAX_FORCE
from pipeline.runtime.loop_messages import SetHaptics
from pipeline.runtime.watchdog import WatchdogConfig
from pipeline.settings.hardware import hardware_from_dict

ARMS = ("right", "left")


@pytest.fixture
def fakes() -> Iterator[dict[str, tuple[FakeNetFT, FakeRtde]]]:
    with arm_fakes() as out:
        yield out


@pytest.fixture
def touches(monkeypatch: pytest.MonkeyPatch) -> FakeMultiHD:
    hd = FakeMultiHD(FakeTouch("Right Touch", position=(10.0, 0.0, 0.0)),
                     FakeTouch("Left Touch", peak=2.0, position=(-10.0, 0.0, 0.0)))
    monkeypatch.setattr("pipeline.backends.touch.PyOpenHapticsApi", lambda dll_dir=None: hd)
    return hd


def _file(fakes: dict[str, tuple[FakeNetFT, FakeRtde]], policy: str = "both") -> Any:
    frames = {"rot_tip_sensor": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "rot_haptic_base": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}
    arms = [{"name": arm, "sensor": {"host": box.host, "port": box.udp_port, "http_port": box.http_port,
                                     "connect_timeout_s": 1.0},
             "robot": {"host": ur.host, "connect_timeout_s": 1.0},
             "haptic": {"device_name": f"{arm.title()} Touch"}, "frames": frames,
             "framework": {"f_max_n": 3.0, "f_scale_n": 7.0}} for arm, (box, ur) in fakes.items()]
    return hardware_from_dict({"arm": arms, "rig": {"fault_policy": policy}}, "two-arm test file")


def test_two_arms_open_by_name_into_one_scheduler_and_close(fakes: Any, touches: FakeMultiHD) -> None:
    opened: list[str] = []
    rig = build_real_rig(_file(fakes), VirtualClock(), on_open=opened.append)
    try:
        assert opened == [f"arm {a!r}: {d}" for a in ARMS for d in ("force sensor", "robot", "haptic device")] + [
            "haptic servo scheduler (arms right, left)"]
        assert isinstance(rig, RealRig) and [a.name for a in rig.arms] == list(ARMS)
        right, left = rig.real_arms
        assert rig.haptic is right.haptic and rig.sensor is right.sensor  # the one-arm fields: the first arm's
        for arm in rig.real_arms:
            assert isinstance(arm.sensor, NetFTForceSensor) and isinstance(arm.robot, UrPoseProcess)
            assert isinstance(arm.haptic, TouchHapticDevice)
        assert right.sensor.read_wrench()[3] == 1.0 and left.sensor.read_wrench()[3] == 2.0  # each its own box
        assert (right.haptic.device_name, left.haptic.device_name) == ("Right Touch", "Left Touch")
        assert (right.haptic.peak_force_n, left.haptic.peak_force_n) == (3.3, 2.0)
        assert touches.calls == ["start"]
        assert rig.arm("left") is left
        with pytest.raises(KeyError, match="right, left"):
            rig.arm("middle")
    finally:
        rig.close()
    assert touches.calls == ["start", "stop", "close Right Touch", "close Left Touch"]
    for box, ur in fakes.values():
        assert until(lambda b=box: [r[1] for r in b.requests] == [2, 0])
        assert ur.wait_for("DISCONNECTED")


def test_a_failing_device_of_the_second_arm_closes_the_first_arms_and_names_the_arm(fakes: Any,
                                                                                     touches: FakeMultiHD) -> None:
    del touches.plugged["Left Touch"]  # the left Touch is not plugged in (or Touch_Setup names it otherwise)
    opened: list[str] = []
    with pytest.raises(DeviceError) as err:
        build_real_rig(_file(fakes), VirtualClock(), on_open=opened.append)
    msg = str(err.value)
    assert msg.startswith("arm 'left': haptic device: OpenHaptics could not open the haptic device 'Left Touch'")
    assert "\n" not in msg and opened[-1] == "arm 'left': haptic device"
    assert touches.calls == ["close Right Touch"] and touches.plugged["Right Touch"].closed  # never started
    for box, ur in fakes.values():
        assert until(lambda b=box: [r[1] for r in b.requests] == [2, 0])
        assert ur.wait_for("DISCONNECTED")


@pytest.mark.parametrize("policy", ["both", "independent"])
def test_the_loop_renders_each_arms_force_on_its_own_touch(fakes: Any, touches: FakeMultiHD, policy: str) -> None:
    eng, _ = _steady(fakes, policy)
    try:
        assert eng.loop.fault_policy == policy and list(eng.frameworks) == list(ARMS)
        assert [ch.arm.haptic for ch in eng.loop.arms] == [a.haptic for a in eng.rig.real_arms]
        for _ in range(400):  # past the ramp-in
            eng.loop.run_ticks(1)
            touches.tick()
        assert [ch.faults for ch in eng.loop.arms] == [0, 0]
        # each Touch renders what its own arm's pipeline commanded, from its own box (1 N and 2 N pushes)
        for ch in eng.loop.arms:
            rec = dict(zip(RECORD_FIELDS, ch.last_record or (), strict=True))
            touch = touches.plugged[f"{ch.name.title()} Touch"]
            assert rec["raw_fz"] == {"right": 1.0, "left": 2.0}[ch.name]
            assert touch.forces[-1] == pytest.approx((rec["render_fx"], rec["render_fy"], rec["render_fz"]))
        fr, fl = (touches.plugged[n].forces[-1][2] for n in ("Right Touch", "Left Touch"))
        assert fl < fr < 0.0
    finally:
        eng.rig.close()


def _steady(fakes: Any, policy: str) -> tuple[Any, VirtualClock]:
    """The two-arm engine, feedback on.  The fakes sent one sample each at START and the virtual clock runs on: no
    staleness check here (the watchdog's per-arm faults are tests/pipeline/test_loop_arms.py's)."""
    clock = VirtualClock()
    eng = build_hardware_engine(_file(fakes, policy), clock=clock,
                                watchdog=WatchdogConfig(sensor_max_age_s=10.0, pose_max_age_s=10.0))
    eng.loop.submit(SetHaptics(True))
    return eng, clock


@pytest.mark.parametrize("policy", ["both", "independent"])
def test_an_hd_error_on_one_touch_faults_its_arm_and_the_policy_decides_the_other(
    fakes: Any, touches: FakeMultiHD, policy: str
) -> None:
    eng, _ = _steady(fakes, policy)
    try:
        for _ in range(400):
            eng.loop.run_ticks(1)
            touches.tick()
        left = eng.rig.arm("left").haptic
        touches.errors.append((HD_EXCEEDED_MAX_FORCE, left.handle))
        for _ in range(50):  # 50 ms
            touches.tick()
            eng.loop.run_ticks(1)
        right_ch, left_ch = eng.loop.arms
        assert left_ch.faults & Fault.HAPTIC_DEVICE and touches.plugged["Left Touch"].forces[-1] == (0.0, 0.0, 0.0)
        assert not right_ch.faults & Fault.HAPTIC_DEVICE
        if policy == "both":
            assert right_ch.faults == Fault.OTHER_ARM and touches.plugged["Right Touch"].forces[-1] == (0.0, 0.0, 0.0)
        else:
            assert right_ch.faults == 0 and touches.plugged["Right Touch"].forces[-1][2] < 0.0
    finally:
        eng.rig.close()


def test_a_dead_loop_leaves_no_force_on_either_touch(fakes: Any, touches: FakeMultiHD) -> None:
    eng, clock = _steady(fakes, "independent")
    try:
        for _ in range(400):
            eng.loop.run_ticks(1)
            touches.tick()
        right, left = touches.plugged["Right Touch"], touches.plugged["Left Touch"]
        assert right.forces[-1][2] < 0.0 and left.forces[-1][2] < 0.0
        for _ in range(12):  # the loop is gone; each Touch's servo runs on, 1 ms a tick
            clock.advance(1_000_000)
            touches.tick()
        for t in (right, left):  # each device's own command watchdog: zero once the command is 10 ms old
            assert t.forces[-3:] == [(0.0, 0.0, 0.0)] * 3 and t.forces[-12][2] < 0.0
    finally:
        eng.rig.close()


def test_a_given_haptic_opener_opens_each_arms_touch(fakes: Any) -> None:
    """The app's rig-construction seam (``open_haptic``, opening each arm's device in place of its model's backend)
    works for two arms too."""
    names: list[str] = []

    def stand_in(cfg: Any, clock: Any) -> Any:
        names.append(cfg.device_name)
        return TouchScheduler(FakeMultiHD(FakeTouch(cfg.device_name))).open(cfg.device_name, clock)

    opened: list[str] = []
    rig = build_real_rig(_file(fakes), VirtualClock(), on_open=opened.append, open_haptic=stand_in)
    rig.close()
    assert names == ["Right Touch", "Left Touch"] and not any("scheduler" in o for o in opened)


def test_each_teleoperated_arm_has_its_own_controller_clutch_and_deadman(fakes: Any, touches: FakeMultiHD) -> None:
    """``robot.mode = "teleop"`` on both arms: each arm's Touch drives its own robot's control interface through its
    own controller; the clutch on one stylus and the deadman released on the other change only that arm's state."""
    from fake_ur_control import FakeControl

    from pipeline.core.clock import MonotonicClock
    from pipeline.devices.teleop import TeleopState

    controls = {ur.host: FakeControl() for _, ur in fakes.values()}
    raw: dict[str, Any] = {"arm": [], "rig": {"fault_policy": "both"}}
    for arm, (box, ur) in fakes.items():  # the fake controllers' TCP is at (0.3, -0.1, 0.2) m
        raw["arm"].append({"name": arm, "sensor": {"host": box.host, "port": box.udp_port, "http_port": box.http_port,
                                                   "connect_timeout_s": 1.0},
                           "robot": {"host": ur.host, "connect_timeout_s": 1.0, "mode": "teleop"},
                           "haptic": {"device_name": f"{arm.title()} Touch"},
                           "frames": {"rot_tip_sensor": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
                                      "rot_haptic_base": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]},
                           "framework": {"f_max_n": 3.0, "f_scale_n": 7.0},
                           "teleop": {"workspace_min_m": [0.2, -0.2, 0.1], "workspace_max_m": [0.4, 0.0, 0.3],
                                      "control_timeout_s": 1.0}})
    clock = MonotonicClock()
    rig = build_real_rig(hardware_from_dict(raw, "two-arm teleop file"), clock,
                         control_factory=lambda host, hz: controls[host])
    try:
        right, left = rig.real_arms
        assert right.teleop is not None and left.teleop is not None
        assert right.teleop.controller is not left.teleop.controller
        assert (right.teleop.haptic, left.teleop.haptic) == (right.haptic, left.haptic)
        assert (right.teleop.robot, left.teleop.robot) == (right.robot, left.robot)

        def press(**masks: int) -> dict[str, TeleopState]:
            for name, mask in masks.items():
                touches.plugged[f"{name.title()} Touch"].button_mask = mask
            touches.tick()
            rig.advance(clock.now_ns())
            return {"right": right.teleop.controller.state, "left": left.teleop.controller.state}

        r_ctl, l_ctl = controls[fakes["right"][1].host], controls[fakes["left"][1].host]
        assert press(right=1, left=1) == {"right": TeleopState.ENGAGED, "left": TeleopState.ENGAGED}
        assert r_ctl.wait_count("servoL", 1) and l_ctl.wait_count("servoL", 1)  # each robot its own target
        assert press(left=1 | 2) == {"right": TeleopState.ENGAGED, "left": TeleopState.CLUTCHED}  # left clutch
        assert press(right=0) == {"right": TeleopState.IDLE, "left": TeleopState.CLUTCHED}  # right deadman off
        assert r_ctl.wait_count("servoStop", 1)  # the right robot stopped; the left one was never told to
        assert not any(n == "servoStop" for n, _ in l_ctl.calls)
    finally:
        rig.close()
