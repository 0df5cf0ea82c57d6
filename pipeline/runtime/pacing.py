"""Pacing the haptic loop on its clock: one tick per period, at absolute deadlines.

:class:`PacedTicks` is the part of :class:`pipeline.runtime.loop.HapticLoop` that decides *when* a tick runs
(the loop decides what a tick does).  Deadlines are absolute (``t0 + k·period``), so lateness never accumulates;
after a stall longer than one period the missed slots are counted (:attr:`LoopStats.missed_slots
<pipeline.runtime.loop_stats.LoopStats.missed_slots>`) and skipped rather than replayed in a burst.  On a
:class:`pipeline.core.clock.VirtualClock` the sleeps advance the clock, so the same code runs a deterministic
simulation as fast as it computes.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from pipeline.core.clock import Clock
from pipeline.runtime.loop_stats import LoopStats

__all__ = ["PacedTicks"]


class PacedTicks:
    """Runs :meth:`tick` at the loop rate (a base of :class:`pipeline.runtime.loop.HapticLoop`)."""

    clock: Clock
    period_ns: int
    stats: LoopStats
    _stop: threading.Event

    def tick(self) -> None:
        """Run one cycle at the clock's current time (the loop's)."""
        raise NotImplementedError

    def ramp_down(self, max_ticks: int = 200) -> None:
        """Bring the rendered force to zero (the loop's)."""
        raise NotImplementedError

    #: Runs ``n`` ticks in place of :meth:`run_ticks` when set: a simulated rig's compiled blocks on a virtual clock
    #: (:class:`pipeline.sim.block.SimBlocks`, the same ticks bit for bit).
    block_runner: Callable[[int], None] | None = None

    def run_ticks(self, n: int) -> None:
        """Run ``n`` ticks paced on the clock (instant on a virtual clock)."""
        if self.block_runner is not None:
            self.block_runner(n)
            return
        clock = self.clock
        deadline = clock.now_ns()
        period = self.period_ns
        for _ in range(n):
            self.tick()
            deadline += period
            clock.sleep_until(deadline)

    def run(
        self,
        stop: threading.Event | None = None,
        max_ticks: int | None = None,
        between_ticks: Callable[[], object] | None = None,
    ) -> None:
        """Tick at the loop rate until ``stop`` is set (or ``max_ticks`` ticks), then ramp down.

        Parameters
        ----------
        stop
            Set to stop (default: the loop's own, see :meth:`pipeline.runtime.loop.HapticLoop.stop`).
        max_ticks
            Stop after this many ticks.
        between_ticks
            Called right after each tick, when the rest of the period is
            free: housekeeping that must not land mid-tick, such as
            :func:`pipeline.core.clock.collect_garbage`.  Must be short (well under
            a period); its exceptions propagate.
        """
        stop = stop or self._stop
        clock = self.clock
        period = self.period_ns
        deadline = clock.now_ns()
        n = 0
        try:
            while not stop.is_set() and (max_ticks is None or n < max_ticks):
                self.tick()
                n += 1
                if between_ticks is not None:
                    between_ticks()
                deadline += period
                behind = clock.now_ns() - deadline
                if behind > period:
                    skipped = behind // period
                    self.stats.missed_slots += skipped
                    deadline += skipped * period
                clock.sleep_until(deadline)
        finally:
            self.ramp_down()
