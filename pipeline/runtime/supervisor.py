"""Watching the haptic loop from outside: a dead loop (thread or process) or a tick counter that stops is a latched
fault.

The loop cannot report its own death: a thread killed by an exception (or a process killed by a signal) emits
nothing, and a frozen one nothing until it runs again.  Whoever drives it
(the study engine's driver thread, every ~10 ms) calls
:meth:`LoopSupervisor.check`; when the loop thread has died, or has not
ticked for longer than ``WatchdogConfig.loop_stall_s``, it latches
``LOOP_STALLED`` and reports it through the loop's own event path
(:meth:`pipeline.runtime.loop.HapticLoop.fail_safe`), so the study record stores it
like any other fault.  The force on the hand never depends on this check:
every arm's haptic device drops a command older than its own timeout (10 ms) in
its own servo thread (:mod:`pipeline.devices.touch_output`; two Touch devices in one
servo scheduler each keep their own), and a teleoperated robot's servo adapter
stops the arm when no target has come for 50 ms (:mod:`pipeline.backends.ur_control`).
"""

from __future__ import annotations

from pipeline.core.clock import Clock, MonotonicClock
from pipeline.runtime.loop_messages import LoopEvent
from pipeline.runtime.loop_view import LoopView

__all__ = ["LoopSupervisor"]


class LoopSupervisor:
    """Checks a loop that runs in its own thread (:meth:`pipeline.runtime.loop.HapticLoop.start`) or process
    (:class:`pipeline.assembly.loop_client.RemoteLoop`).

    Parameters
    ----------
    loop
        The loop (its ``runs_in`` names what died in the report: its thread or its process).
    clock
        Wall clock to time the tick counter by (the loop's own clock stops with it).
    """

    def __init__(self, loop: LoopView, clock: Clock | None = None) -> None:
        self.loop = loop
        self.clock: Clock = clock or MonotonicClock()
        self._stall_ns = int(loop.watchdog.loop_stall_s * 1e9)
        self._ticks = loop.tick_count
        self._seen_ns = self.clock.now_ns()
        self._stall_reported = False
        #: Why the loop thread died ("" while it has not).
        self.dead = ""

    def check(self) -> LoopEvent | None:
        """Look once; the event if the loop was found dead or newly stalled (reported once each)."""
        if self.dead:
            return None
        loop = self.loop
        now = self.clock.now_ns()
        ticks = loop.tick_count
        if ticks != self._ticks:
            self._ticks, self._seen_ns, self._stall_reported = ticks, now, False
        alive = loop.thread_alive
        if alive is None:  # not started, or stopped on purpose (a calibration): nothing to watch
            self._seen_ns = now
            return None
        if not alive:
            self.dead = loop.crash or f"the loop {loop.runs_in} ended"
            return loop.fail_safe(f"the haptic loop {loop.runs_in} died ({self.dead}); the haptic device's command "
                                  "watchdog dropped the force to zero", thread_dead=True)
        quiet = now - self._seen_ns
        if quiet > self._stall_ns and not self._stall_reported:
            self._stall_reported = True
            return loop.fail_safe(f"no loop tick for {quiet * 1e-6:.0f} ms (limit {self._stall_ns * 1e-6:g} ms): the "
                                  "haptic loop is frozen; the haptic device's command watchdog dropped the force to "
                                  "zero", thread_dead=False)
        return None
