"""When the study engine's driver works: simulated time held to a speed on the virtual clock, and the quiet moment
just after a loop tick on the real one."""

from __future__ import annotations

import time

from pipeline.runtime.loop_view import LoopView

__all__ = ["QUIET_OFFSET_NS", "LoopPacer"]

#: The driver thread wakes this long after a loop tick starts (a tick takes ~50 µs): see LoopPacer.quiet_wait_s.
QUIET_OFFSET_NS = 150_000


class LoopPacer:
    """Paces the study engine's driver against its loop (driver thread only).

    Parameters
    ----------
    loop
        The haptic loop the driver runs (virtual clock) or works beside (real clock).
    speed
        Virtual clock: simulated seconds per wall second (0 = as fast as the CPU allows).
    """

    def __init__(self, loop: LoopView, speed: float) -> None:
        self.loop = loop
        self.speed = speed
        self._anchor_wall = time.monotonic()
        self._anchor_ticks = 0
        self._ticks_run = 0

    def ran(self, ticks: int, *, throttle: bool) -> None:
        """The driver ran ``ticks`` of the virtual clock: wait so that simulated time keeps to :attr:`speed`."""
        self._ticks_run += ticks
        if throttle and self.speed > 0:
            self._throttle()

    def _throttle(self) -> None:
        # keep simulated time at `speed` × wall time; after a stall, re-anchor instead of bursting
        ahead = self._anchor_wall + (self._ticks_run - self._anchor_ticks) * 1e-3 / self.speed - time.monotonic()
        if ahead > 0:
            time.sleep(ahead)
        elif ahead < -0.2:
            self.reanchor()

    def reanchor(self) -> None:
        """Count simulated time from now (after a pause of the loop: a calibration step ran the rig)."""
        self._anchor_wall = time.monotonic()
        self._anchor_ticks = self._ticks_run

    def quiet_wait_s(self, interval_s: float, last_t_ns: int) -> float:
        """Seconds to wait to wake ``QUIET_OFFSET_NS`` after a loop tick, about ``interval_s`` from now.

        Real clock only.  The driver's work (runner, recorder hand-off, events)
        takes the GIL; if it asks for it while the loop thread spins to its
        deadline or runs a tick, the interpreter forces the loop out after a
        switch interval and the tick starts late.  Waking just after a tick
        leaves the driver (and the recorder it feeds) most of the loop's
        ~0.8 ms sleep to finish in.  The tick grid is read from the newest
        record the driver has seen (``last_t_ns``, its start on the loop's clock).
        """
        if not self.loop.tick_count:
            return interval_s
        now = time.perf_counter_ns()
        period = self.loop.period_ns
        last_tick = self.loop.t0_ns + last_t_ns
        target = now + int(interval_s * 1e9)
        target -= (target - last_tick - QUIET_OFFSET_NS) % period
        return max(0.0, (target - now) * 1e-9)
