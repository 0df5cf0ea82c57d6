"""The study engine reads its loop's records: the timing statistics, the commissioning chain's windows, the session.

:class:`RingReader` belongs to a :class:`study_app.engine.host.StudyEngine` and runs on its driver thread.  The
ring is read from one place, so every record reaches each of its readers once and in order.
"""

from __future__ import annotations

from pipeline.assembly.engine_view import EngineView
from protocol.runner.session_driver import SessionDriver
from study_app.engine.commissioning import Commissioning
from study_app.engine.period_stats import PeriodStats
from study_app.engine.sessions import EngineSessions

__all__ = ["RingReader"]


class RingReader:
    """Reads the loop's new records and hands them on (driver thread only).

    Parameters
    ----------
    eng
        The assembled rig: the task arm's ring is read, and the other arms' (a session records every arm).
    commissioning
        Fills its recording windows from the records.
    sessions
        Its running session is fed the records, the loop's events and its replay log.
    """

    def __init__(self, eng: EngineView, commissioning: Commissioning, sessions: EngineSessions) -> None:
        assert eng.ring is not None
        others = tuple((name, rg, eng.loop.arm(name).replay_log) for name, rg in eng.rings.items()
                       if rg is not None and rg is not eng.ring)
        #: Reads the ring from here on and feeds the running session (the loop's events and replay log with it).
        self.driver = SessionDriver(eng.ring, eng.loop.replay_log, others)
        self.commissioning = commissioning
        self.sessions = sessions
        #: The loop's timing since the last reset.
        self.stats = PeriodStats()
        #: Loop time of the newest record read, ns.
        self.last_t_ns = 0
        self._stats_from_tick = 0

    def drain(self) -> None:
        """Read the loop's new records: the timing statistics, the commissioning chain, the running session."""
        block = self.driver.take()
        rows = block.rows
        if len(rows):
            if self._stats_from_tick:
                # the first tick after a calibration carries the calibration's gap: not a loop overrun
                keep = rows["tick"] >= self._stats_from_tick
                self.stats.add(rows["period_ns"][keep] * 1e-9)
            else:
                self.stats.add(rows["period_ns"] * 1e-9)
            self.last_t_ns = int(rows["t_ns"][-1])
            self.commissioning.feed(rows)
        elif not block.lost:
            return
        runner = self.sessions.runner
        if runner is None:
            return
        self.driver.feed(runner, block, self.sessions.trigger)
        if runner.done:
            self.sessions.end(runner.status, runner.stop_reason)

    def flush_events(self) -> None:
        """Hand the pending loop events to the session runner without records (the loop writes none)."""
        runner = self.sessions.runner
        if runner is not None:
            self.driver.flush_events(runner)

    def restart_stats(self, from_tick: int) -> None:
        """Count the loop's timing afresh from tick ``from_tick`` on (the loop was paused for a calibration step)."""
        self.stats.reset()
        self._stats_from_tick = from_tick
