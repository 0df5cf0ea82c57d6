"""A haptic loop that dies or freezes leaves no force on the hand: the real Touch backend's own command watchdog.

The loop runs in its own thread (``HapticLoop.start``), as in the engine, on a
:class:`stepped_clock.SteppedClock` the test moves 1 ms at a time; the Touch
is the real backend (``TouchHapticDevice``) over :class:`test_touch.FakeHD`,
whose servo callback the test calls once per millisecond -- the HD API
stand-in clocked by the test.  The loop renders a steady force; then its
thread freezes (a sensor read that never returns) or dies (an exception,
with the final zero command failing too), and every servo tick after is
checked: the output is exactly zero once the last command is 10 ms old, the
supervisor latches ``LOOP_STALLED`` and reports it through the loop's event
path, and a frozen loop that runs again does not bring the old force back.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable

import pytest
from stepped_clock import SteppedClock
from test_touch import FakeHD

from pipeline.backends.touch import TouchHapticDevice
from pipeline.devices.interfaces import Fault, WrenchSample
from pipeline.force.framework import FrameworkConfig, HapticFramework
from pipeline.runtime.loop import HapticLoop
from pipeline.runtime.loop_messages import LoopEvent, SetHaptics
from pipeline.runtime.supervisor import LoopSupervisor
from pipeline.sim.robot import TOOL_DOWN, SimRobot
from pipeline.sim.sensor import GAMMA_RANGE

MS = 1_000_000
LIMIT_MS = 10  # the Touch's default command timeout


class PushSensor:
    """A fresh (0, 0, 2) N sample every read; it can be made to hang (``freeze``) or fail (``fail``)."""

    range_n = GAMMA_RANGE

    def __init__(self, clock: SteppedClock) -> None:
        self.clock = clock
        self.freeze = threading.Event()
        self.frozen_in = threading.Event()
        self.thaw = threading.Event()
        self.fail = False

    def read_wrench(self) -> WrenchSample:
        if self.fail:
            raise OSError("Net F/T socket closed")
        if self.freeze.is_set():
            self.frozen_in.set()
            self.thaw.wait(30.0)
        return WrenchSample(self.clock.now_ns(), 0.0, 0.0, 2.0, 0.0, 0.0, 0.0)

    def close(self) -> None:
        pass


class Rig:
    def __init__(self, clock: SteppedClock, touch: TouchHapticDevice) -> None:
        self.sensor = PushSensor(clock)
        self.robot = SimRobot((0.3, 0.0, 0.1), TOOL_DOWN)
        self.haptic = touch
        self.refuse_commands = False
        real = touch.command_force

        def command_force(fx: float, fy: float, fz: float, t_ns: int | None = None) -> None:
            if self.refuse_commands:
                raise OSError("HD_COMM_ERROR")
            real(fx, fy, fz, t_ns)

        self.command_force = command_force
        touch.command_force = command_force

    def advance(self, now_ns: int) -> None:
        self.robot.advance(now_ns, 0.001)

    def true_contact_force(self) -> None:
        return None

    def close(self) -> None:
        self.haptic.close()


class Bench:
    """Loop thread + Touch on FakeHD + supervisor, all on one stepped clock.

    ``make_rig(clock, touch)`` builds the rig (default :class:`Rig`); ``buttons`` are the stylus buttons held from
    the first tick on.
    """

    def __init__(self, make_rig: Callable[[SteppedClock, TouchHapticDevice], Rig] = Rig, buttons: int = 0) -> None:
        self.clock = SteppedClock()
        self.hd = FakeHD()
        self.hd.button_mask = buttons
        self.touch = TouchHapticDevice(api=self.hd, clock=self.clock)
        self.hd.tick()  # a stylus state before the loop's first tick
        self.rig = make_rig(self.clock, self.touch)
        self.events: list[LoopEvent] = []
        self.loop = HapticLoop(self.rig, HapticFramework(FrameworkConfig(), device_peak_n=3.3), self.clock)
        self.loop.on_event = self.events.append
        self.supervisor = LoopSupervisor(self.loop, self.clock)
        self.loop.submit(SetHaptics(True))
        self.loop.start()
        assert self.clock.wait_for_sleeper()

    def ms(self, done=None) -> float:
        """One millisecond: the loop's tick (if it can), the Touch's servo tick, the supervisor's look; |F| rendered."""
        self.clock.step(MS, done)
        self.hd.tick()
        self.supervisor.check()
        return math.hypot(*self.hd.forces[-1])

    def steady(self) -> float:
        for _ in range(700):  # past the 0.5 s ramp-in
            f = self.ms()
        assert f > 0.5
        return f

    def close(self) -> None:
        self.rig.sensor.thaw.set()
        self.clock.release()
        self.loop.stop(timeout_s=5.0)
        self.touch.close()


@pytest.fixture
def bench():
    b = Bench()
    try:
        yield b
    finally:
        b.close()


def stalled(events: list[LoopEvent]) -> list[LoopEvent]:
    return [e for e in events if e.kind == "fault" and "LOOP_STALLED" in e.detail]


def test_a_frozen_loop_thread_renders_zero_within_the_limit_and_is_latched_once_it_runs_again(bench: Bench) -> None:
    f = bench.steady()
    bench.rig.sensor.freeze.set()
    out = [bench.ms(done=bench.rig.sensor.frozen_in.is_set)]  # this tick hangs in the sensor read
    out += [bench.ms(done=lambda: True) for _ in range(60)]
    # the Touch kept rendering the last command for 9 ms, then exactly 0 -- 10 ms after that command
    zero_at = next(i for i, v in enumerate(out) if v == 0.0)
    assert out[:zero_at] == pytest.approx([f] * zero_at, rel=0.02) and all(v == 0.0 for v in out[zero_at:])
    assert zero_at + 1 == LIMIT_MS  # servo tick k is k + 1 ms after the last command (9 ms after the freeze)
    # the supervisor saw no tick for 50 ms: one LOOP_STALLED event, through the loop's own event path
    (ev,) = stalled(bench.events)
    assert ev.detail.startswith("LOOP_STALLED: no loop tick for 5") and "the haptic loop is frozen" in ev.detail
    assert ev.faults & Fault.LOOP_STALLED
    assert bench.loop.faults == 0  # the frozen loop latches it itself when it runs again

    bench.rig.sensor.freeze.clear()
    bench.rig.sensor.thaw.set()  # the hung read returns: the tick in flight completes, 60 ms late
    after = [bench.ms() for _ in range(50)]
    assert all(v == 0.0 for v in after)  # the late tick's command is stale on arrival; then the latch holds it at 0
    assert bench.loop.faults & Fault.LOOP_STALLED
    assert len(stalled(bench.events)) == 1  # latched without a second report


def test_a_killed_loop_thread_renders_zero_within_the_limit_even_when_its_zero_command_fails(bench: Bench) -> None:
    f = bench.steady()
    # the thread dies: its tick raises, the ramp-down's ticks raise, and the final zero command fails as well
    bench.rig.sensor.fail = True
    bench.rig.refuse_commands = True
    thread = bench.loop._thread
    assert thread is not None
    # the failing tick, then the ramp-down's first tick (it fails too, and so does the zero command): dead
    out = [bench.ms(done=lambda: not thread.is_alive()) for _ in range(2)]
    assert not thread.is_alive()
    out += [bench.ms(done=lambda: True) for _ in range(20)]
    zero_at = next(i for i, v in enumerate(out) if v == 0.0)
    assert out[:zero_at] == pytest.approx([f] * zero_at, rel=0.02) and all(v == 0.0 for v in out[zero_at:])
    assert zero_at + 1 == LIMIT_MS  # the device's own watchdog: 10 ms after the last command
    # the supervisor found the thread dead at its first look: latched, reported with the exception, robot told
    crash = "OSError('HD_COMM_ERROR') while handling OSError('Net F/T socket closed')"
    assert bench.loop.crash == crash
    (ev,) = stalled(bench.events)
    assert ev.detail == (f"LOOP_STALLED: the haptic loop thread died ({crash}); the haptic device's command watchdog "
                         "dropped the force to zero")
    assert bench.loop.faults & Fault.LOOP_STALLED and bench.supervisor.dead
    # (its own zero command failed too, and that is reported)
    assert any("refused the zero command" in e.detail for e in bench.events)


def test_a_killed_loop_thread_commands_zero_on_its_way_out(bench: Bench) -> None:
    bench.steady()
    bench.rig.sensor.fail = True  # the tick raises; ramp_down's ticks raise; its final zero command still goes out
    thread = bench.loop._thread
    assert thread is not None
    out = [bench.ms(done=lambda: not thread.is_alive()) for _ in range(2)]
    assert not thread.is_alive()
    assert out[0] > 0.5 and out[1] == 0.0  # zero at the ramp-down's first slot, 1 ms after the failed tick
    assert bench.loop.crash == "OSError('Net F/T socket closed')"
    (ev,) = stalled(bench.events)
    assert "the haptic loop thread died (OSError('Net F/T socket closed'))" in ev.detail
