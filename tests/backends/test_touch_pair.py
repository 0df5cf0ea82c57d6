"""Two Touch devices in one OpenHaptics servo scheduler (both arms of the rig), by their device names.

:class:`fake_multi_hd.FakeMultiHD` keeps libHD's current-device semantics: each device's force, clamp, watchdog and
HD errors must land on that device and no other.
"""

from __future__ import annotations

import pytest
from fake_multi_hd import FakeMultiHD, FakeTouch

from pipeline.backends.hdapi import HD_FORCE_OUTPUT, HD_MAX_FORCE_CLAMPING
from pipeline.backends.touch import TouchScheduler
from pipeline.core.clock import VirtualClock
from pipeline.devices.interfaces import DeviceError, HapticDevice
from pipeline.devices.touch_output import HD_EXCEEDED_MAX_FORCE, HD_WARM_MOTORS

MS = 1_000_000


def _pair(clock: VirtualClock) -> tuple[FakeMultiHD, FakeTouch, FakeTouch, TouchScheduler]:
    right = FakeTouch("Right Touch", peak=3.3, position=(10.0, 0.0, 0.0), button_mask=1)
    left = FakeTouch("Left Touch", peak=2.0, position=(-10.0, 5.0, 0.0), button_mask=2)
    hd = FakeMultiHD(right, left)
    return hd, right, left, TouchScheduler(hd)


def test_each_device_reads_its_stylus_and_renders_its_own_command() -> None:
    clock = VirtualClock(5 * MS)
    hd, right, left, sched = _pair(clock)
    r = sched.open("Right Touch", clock)
    lt = sched.open("Left Touch", clock)
    assert isinstance(r, HapticDevice) and isinstance(lt, HapticDevice)
    assert right.enabled == left.enabled == [HD_FORCE_OUTPUT, HD_MAX_FORCE_CLAMPING]  # each enabled while current
    assert (r.peak_force_n, lt.peak_force_n) == (3.3, 2.0)
    assert not hd.running and hd.callback is None  # nothing served before start
    sched.start()
    assert hd.calls == ["start"]
    r.command_force(0.5, 0.0, 0.0)
    lt.command_force(0.0, -0.25, 0.0)
    hd.tick()
    assert right.forces == [(0.5, 0.0, 0.0)] and left.forces == [(0.0, -0.25, 0.0)]
    sr, sl = r.read_state(), lt.read_state()
    assert sr.position_m == pytest.approx((0.01, 0.0, 0.0)) and sr.buttons == 1
    assert sl.position_m == pytest.approx((-0.01, 0.005, 0.0)) and sl.buttons == 2
    r.command_force(30.0, 40.0, 0.0)  # each clamps to its own reported peak
    lt.command_force(30.0, 40.0, 0.0)
    hd.tick()
    assert right.forces[-1] == pytest.approx((1.98, 2.64, 0.0)) and left.forces[-1] == pytest.approx((1.2, 1.6, 0.0))


def test_an_hd_error_disables_only_the_device_it_names() -> None:
    clock = VirtualClock()
    hd, right, left, sched = _pair(clock)
    r, lt = sched.open("Right Touch", clock), sched.open("Left Touch", clock)
    sched.start()
    r.command_force(0.4, 0.0, 0.0)
    lt.command_force(0.3, 0.0, 0.0)
    hd.errors.append((HD_EXCEEDED_MAX_FORCE, lt.handle))  # the left Touch's error, popped during any device's frame
    hd.tick(2)
    assert left.forces == [(0.0, 0.0, 0.0)] * 2 and lt.read_state().error_code == HD_EXCEEDED_MAX_FORCE
    assert right.forces == [(0.4, 0.0, 0.0)] * 2 and r.read_state().error_code == 0 and r.errors == []
    assert lt.rearm()
    lt.command_force(0.3, 0.0, 0.0)
    hd.tick()
    assert left.forces[-1] == (0.3, 0.0, 0.0)
    hd.errors.append((HD_WARM_MOTORS, 999))  # an error naming no device of ours: charged to both
    hd.tick()
    assert right.forces[-1] == left.forces[-1] == (0.0, 0.0, 0.0)
    assert r.errors == [HD_WARM_MOTORS] and lt.errors == [HD_EXCEEDED_MAX_FORCE, HD_WARM_MOTORS]


def test_each_device_has_its_own_command_watchdog() -> None:
    clock = VirtualClock()
    hd, right, left, sched = _pair(clock)
    r, lt = sched.open("Right Touch", clock), sched.open("Left Touch", clock)
    sched.start()
    r.command_force(0.0, 0.8, 0.0)  # the right arm's commands stop coming
    for _ in range(12):
        clock.advance(MS)
        lt.command_force(0.0, 0.5, 0.0)  # the left arm's keep coming
        hd.tick()
    assert right.forces[:9] == [(0.0, 0.8, 0.0)] * 9 and right.forces[9:] == [(0.0, 0.0, 0.0)] * 3
    assert left.forces == [(0.0, 0.5, 0.0)] * 12
    assert (r.output.stale_ticks, lt.output.stale_ticks) == (3, 0)


def test_closing_one_leaves_the_other_served_and_the_last_stops_the_scheduler() -> None:
    clock = VirtualClock()
    hd, right, left, sched = _pair(clock)
    r, lt = sched.open("Right Touch", clock), sched.open("Left Touch", clock)
    sched.start()
    r.command_force(0.2, 0.0, 0.0)
    lt.command_force(0.1, 0.0, 0.0)
    lt.close()
    hd.tick()
    assert hd.running and not left.closed
    assert left.forces[-1] == (0.0, 0.0, 0.0) and right.forces[-1] == (0.2, 0.0, 0.0)
    r.close()
    assert hd.calls == ["start", "stop", "close Right Touch", "close Left Touch"]
    assert right.closed and left.closed


def test_open_refusals_name_the_device() -> None:
    clock = VirtualClock()
    hd, right, _left, sched = _pair(clock)
    with pytest.raises(DeviceError, match=r"could not open the haptic device 'Middle Touch'"):
        sched.open("Middle Touch", clock)
    sched.open("Right Touch", clock)
    with pytest.raises(DeviceError, match=r"'Right Touch' is opened already; each arm needs its own Touch"):
        sched.open("Right Touch", clock)
    bad = FakeTouch("Bad Touch", peak=1.0, cont=2.0)
    hd.plugged["Bad Touch"] = bad
    with pytest.raises(DeviceError, match=r"'Bad Touch' reports nominal max force 1.0 N / continuous 2.0 N"):
        sched.open("Bad Touch", clock)
    assert bad.closed and not right.closed and len(sched.devices) == 1
    sched.start()
    with pytest.raises(DeviceError, match=r"open every Touch before the servo scheduler starts"):
        sched.open("Left Touch", clock)
    with pytest.raises(DeviceError, match="nothing for the servo scheduler to serve"):
        TouchScheduler(FakeMultiHD()).start()


def test_the_pyopenhaptics_adapter_serves_two_devices_by_handle(monkeypatch: pytest.MonkeyPatch) -> None:
    """The real adapter (:class:`PyOpenHapticsApi`: ctypes callback, hdMakeCurrentDevice, frames by handle) over the
    pure-Python pyOpenHaptics stand-in; the servo callback is called by hand, not by the stand-in's thread."""
    import sys
    from pathlib import Path

    from pipeline.backends.hdapi import PyOpenHapticsApi

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parent / "fake_openhaptics"))
    try:
        from pyOpenHaptics import hd, hd_callback

        clock = VirtualClock()
        sched = TouchScheduler(PyOpenHapticsApi())
        r, lt = sched.open("Right Touch", clock), sched.open("Left Touch", clock)
        assert (r.handle, lt.handle) == (1, 2) and hd.STATE["names"] == {1: "Right Touch", 2: "Left Touch"}
        sched.api.schedule_frames(sched._tick)  # what start() does, without the stand-in's scheduler thread
        r.command_force(0.5, 0.0, 0.0)
        lt.command_force(0.0, 0.25, 0.0)
        hd_callback.CALLBACK(None)
        assert hd.STATE["forces"] == {1: [0.5, 0.0, 0.0], 2: [0.0, 0.25, 0.0]}
        assert hd.STATE["frames"] == [("begin", 1, 1), ("end", 1, 1), ("begin", 2, 2), ("end", 2, 2)]
        r.close()
        lt.close()
    finally:
        for name in [m for m in sys.modules if m == "pyOpenHaptics" or m.startswith("pyOpenHaptics.")]:
            del sys.modules[name]
