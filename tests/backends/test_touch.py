"""3D Systems Touch backend: servo callback, clamping, HD errors and re-arming, and the missing-SDK error.

OpenHaptics is a C library (libHD) that is not installed on CI machines; the
backend is driven through its :class:`HDApi` seam by :class:`FakeHD`, which
runs servo ticks on demand the way OpenHaptics' scheduler thread would.
"""

from __future__ import annotations

import builtins
import math

import pytest

from pipeline.backends.hdapi import (
    HD_FORCE_OUTPUT,
    HD_MAX_FORCE_CLAMPING,
    HD_NOMINAL_MAX_CONTINUOUS_FORCE,
    HD_NOMINAL_MAX_FORCE,
    load_pyopenhaptics,
)
from pipeline.backends.touch import TouchHapticDevice
from pipeline.core.clock import VirtualClock
from pipeline.devices.interfaces import DeviceError, Fault, HapticDevice
from pipeline.devices.touch_output import HD_EXCEEDED_MAX_FORCE, HD_WARM_MOTORS
from pipeline.force.framework import FrameworkConfig, HapticFramework
from pipeline.runtime.loop import HapticLoop
from pipeline.runtime.loop_messages import ResetFaults, SetHaptics
from pipeline.sim.robot import TOOL_DOWN, SimRobot
from pipeline.sim.sensor import SimForceSensor


class FakeHD:
    """The HDAPI as OpenHaptics presents it for one Touch."""

    def __init__(self, peak: float = 3.3, cont: float = 0.88, init_error: int = 0) -> None:
        self.doubles = {HD_NOMINAL_MAX_FORCE: peak, HD_NOMINAL_MAX_CONTINUOUS_FORCE: cont}
        self.init_error = init_error
        self.enabled: list[int] = []
        self.callback = None
        self.running = False
        self.closed = False
        self.position = (10.0, -20.0, 30.0)
        self.button_mask = 0
        self.pending_error = 0
        self.forces: list[tuple[float, float, float]] = []

    def init_device(self, name: str) -> None:
        if self.init_error:
            raise DeviceError(f"OpenHaptics could not open the haptic device {name!r} (HD error "
                              f"0x{self.init_error:04x})")

    def error_code(self) -> int:
        e, self.pending_error = self.pending_error, 0
        return e

    def get_double(self, code: int) -> float:
        return self.doubles[code]

    def enable(self, code: int) -> None:
        self.enabled.append(code)

    def schedule(self, callback) -> None:
        self.callback = callback

    def start_scheduler(self) -> None:
        self.running = True

    def stop_scheduler(self) -> None:
        self.running = False

    def close_device(self) -> None:
        self.closed = True

    def position_mm(self) -> tuple[float, float, float]:
        return self.position

    def buttons(self) -> int:
        return self.button_mask

    def set_force(self, fx: float, fy: float, fz: float) -> None:
        self.forces.append((fx, fy, fz))

    def tick(self, n: int = 1) -> None:
        assert self.running and self.callback is not None
        for _ in range(n):
            self.callback()


def test_servo_copies_state_and_the_latest_force() -> None:
    hd = FakeHD()
    clock = VirtualClock(7_000)
    t = TouchHapticDevice(api=hd, clock=clock)
    assert isinstance(t, HapticDevice)
    assert hd.enabled == [HD_FORCE_OUTPUT, HD_MAX_FORCE_CLAMPING] and hd.running
    assert (t.peak_force_n, t.continuous_force_n) == (3.3, 0.88)
    t.command_force(0.5, -1.0, 0.25)
    hd.button_mask = 0b10
    hd.tick()
    assert hd.forces == [(0.5, -1.0, 0.25)]
    s = t.read_state()
    assert s.t_ns == 7_000 and s.position_m == pytest.approx((0.01, -0.02, 0.03), abs=1e-15)
    assert (s.buttons, s.error_code) == (2, 0)
    t.close()
    assert not hd.running and hd.closed


def test_force_is_clamped_to_the_reported_peak_and_non_finite_is_zero() -> None:
    hd = FakeHD(peak=2.0)
    t = TouchHapticDevice(api=hd, clock=VirtualClock())
    t.command_force(30.0, 40.0, 0.0)
    hd.tick()
    assert hd.forces[-1] == pytest.approx((1.2, 1.6, 0.0), abs=1e-15)
    assert math.hypot(*hd.forces[-1]) <= 2.0
    t.command_force(math.nan, 0.0, 0.0)
    hd.tick()
    assert hd.forces[-1] == (0.0, 0.0, 0.0)
    t.command_force(math.inf, 1.0, 0.0)
    hd.tick()
    assert hd.forces[-1] == (0.0, 0.0, 0.0)


def test_hd_error_disables_output_until_rearmed() -> None:
    hd = FakeHD()
    t = TouchHapticDevice(api=hd, clock=VirtualClock())
    t.command_force(1.0, 0.0, 0.0)
    hd.tick()
    hd.pending_error = HD_WARM_MOTORS
    hd.tick(3)
    assert hd.forces[-3:] == [(0.0, 0.0, 0.0)] * 3  # off at once, and stays off
    assert t.read_state().error_code == HD_WARM_MOTORS and t.errors == [HD_WARM_MOTORS]
    t.command_force(1.0, 0.0, 0.0)  # the loop keeps commanding: still nothing rendered
    hd.tick()
    assert hd.forces[-1] == (0.0, 0.0, 0.0)
    assert t.rearm() and t.read_state().error_code == 0
    hd.tick()
    assert hd.forces[-1] == (0.0, 0.0, 0.0)  # re-armed from zero, not from the stale command
    t.command_force(0.4, 0.0, 0.0)
    hd.tick()
    assert hd.forces[-1] == (0.4, 0.0, 0.0)


class _TouchRig:
    """Simulated sensor and robot, the real Touch backend."""

    def __init__(self, haptic: TouchHapticDevice) -> None:
        self.sensor = SimForceSensor()
        self.robot = SimRobot((0.3, 0.0, 0.1), TOOL_DOWN)
        self.haptic = haptic

    def advance(self, now_ns: int) -> None:
        self.robot.advance(now_ns, 0.001)
        self.sensor.sample(now_ns, TOOL_DOWN, (0.0, 0.0, 0.0), 0.001)

    def true_contact_force(self) -> None:
        return None

    def close(self) -> None:
        self.haptic.close()


def test_hd_error_latches_the_loops_fault_and_reset_rearms() -> None:
    clock = VirtualClock()
    hd = FakeHD()
    touch = TouchHapticDevice(api=hd, clock=clock)
    loop = HapticLoop(_TouchRig(touch), HapticFramework(FrameworkConfig(), device_peak_n=3.3), clock)
    loop.submit(SetHaptics(True))
    loop.run_ticks(2)
    hd.tick()
    assert loop.faults == 0
    hd.pending_error = HD_EXCEEDED_MAX_FORCE
    hd.tick()
    loop.run_ticks(1)
    assert loop.faults == Fault.HAPTIC_DEVICE
    hd.tick()
    loop.submit(ResetFaults())
    loop.run_ticks(1)
    assert loop.faults == 0 and touch.read_state().error_code == 0


def test_init_failure_and_bad_device_limits() -> None:
    with pytest.raises(DeviceError, match=r"could not open the haptic device 'Left Touch' \(HD error 0x0300\)"):
        TouchHapticDevice("Left Touch", api=FakeHD(init_error=0x0300))
    hd = FakeHD(peak=math.nan)
    with pytest.raises(DeviceError, match=r"reports nominal max force nan N"):
        TouchHapticDevice(api=hd)
    assert hd.closed


def test_missing_openhaptics_names_what_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    real_import = builtins.__import__

    def no_libhd(name, *args, **kw):
        if name.startswith("pyOpenHaptics"):
            raise OSError("libHD.so: cannot open shared object file: No such file or directory")
        return real_import(name, *args, **kw)

    monkeypatch.setattr(builtins, "__import__", no_libhd)
    with pytest.raises(DeviceError,
                       match=r"install the OpenHaptics SDK .* pip install 'haptic-study\[touch\]' .*\(OpenHaptics "
                             r"library not found: libHD\.so"):
        load_pyopenhaptics()
    monkeypatch.undo()
    try:
        import pyOpenHaptics  # noqa: F401
    except (ImportError, OSError):
        with pytest.raises(DeviceError, match=r"pip install 'haptic-study\[touch\]'"):
            TouchHapticDevice()


def test_a_command_that_stops_coming_renders_zero_once_it_is_10_ms_old() -> None:
    hd = FakeHD()
    clock = VirtualClock()
    t = TouchHapticDevice(api=hd, clock=clock)
    assert t.command_timeout_s == 0.010
    t.command_force(0.0, 0.83, 0.0)  # the stuck force
    out = []
    for _ in range(15):  # nobody commands any more; the servo runs on at 1 kHz
        clock.advance(1_000_000)
        hd.tick()
        out.append(hd.forces[-1])
    assert out[:9] == [(0.0, 0.83, 0.0)] * 9  # 1..9 ms old
    assert out[9:] == [(0.0, 0.0, 0.0)] * 6  # exactly zero from 10 ms on
    assert t.output.stale_ticks == 6
    t.command_force(0.0, 0.5, 0.0)  # a fresh command renders again
    hd.tick()
    assert hd.forces[-1] == (0.0, 0.5, 0.0)
    # a command computed at an earlier tick (a tick that froze half-way) is stale on arrival
    t.command_force(0.0, 0.5, 0.0, clock.now_ns() - 20_000_000)
    hd.tick()
    assert hd.forces[-1] == (0.0, 0.0, 0.0)


def test_the_real_touch_derates_with_the_same_heat_model_and_reports_its_limit() -> None:
    hd = FakeHD()
    clock = VirtualClock()
    t = TouchHapticDevice(api=hd, clock=clock, thermal_budget_n2s=1.0)
    hd.tick()
    for _ in range(3000):  # the loop commands 3 N every millisecond for 3 s
        limit = t.read_state().force_limit_n
        clock.advance(1_000_000)
        t.command_force(3.0, 0.0, 0.0)
        hd.tick()
        assert hd.forces[-1][0] <= limit * (1 + 1e-12)
    st = t.read_state()
    assert st.error_code == 0 and st.heat_fraction > 0.95 and 0.88 < st.force_limit_n < 1.0
    assert hd.forces[-1][0] == pytest.approx(st.force_limit_n, rel=1e-3)
