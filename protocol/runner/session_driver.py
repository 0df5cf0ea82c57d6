"""The session driver: from the loop's ring to the session runner, one definition for every process that runs one.

The study engine (:mod:`study_app.engine.host`, a person's session) and the headless study runner
(:mod:`study_app.headless.session_run`, simulated participants) both read the loop's shared-memory ring and feed
what they read to a :class:`protocol.runner.session.SessionRunner`.  :class:`SessionDriver` is that hand-off:

* :meth:`SessionDriver.take` copies the records written since the last call (:meth:`RingBuffer.read_since
  <pipeline.runtime.ring.RingBuffer.read_since>`) and, *after* them, the loop's pending events and replay log --
  so every entry of a tick whose record was read is in the block.  When no record came, the events and the log
  wait for the next block (a runner stores an event only on its records' time axis).
* :meth:`SessionDriver.feed` hands one block to a runner: records the ring lapped are reported first
  (:meth:`SessionRunner.records_lost`), then the records with the events and the log.  With a rehearsal
  trigger (:class:`protocol.runner.rehearsal.RehearsalTrigger`), a planned ``kill`` fires at its record exactly: the
  runner gets the records up to it, the trigger is polled there, then the rest.

The loop's events reach the driver through :meth:`SessionDriver.on_loop_event` (``HapticLoop.on_event``), which
may be called from the loop's thread: it only appends to a deque, which is atomic.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pipeline.runtime.loop_messages import LoopEvent
from pipeline.runtime.ring import RingBuffer
from protocol.runner.rehearsal import RehearsalTrigger
from protocol.runner.session import SessionRunner

__all__ = ["RingBlock", "SessionDriver"]

#: One entry of the loop's replay log: (tick, kind, payload) (:attr:`pipeline.runtime.loop.HapticLoop.replay_log`).
ReplayEntry = tuple[int, str, object]


@dataclass(frozen=True)
class RingBlock:
    """What one read of the ring gave: the records, how many were lost before them, and the loop's entries.

    Attributes
    ----------
    rows
        The records (rows of :data:`pipeline.core.tick_record.TICK_DTYPE`), oldest first; may be empty.
    lost
        Records written since the previous read that the ring overwrote before they could be read.
    loop_events
        The loop's events taken after the records (empty when no record came).
    replay_log
        The loop's replay-log entries taken after the records (empty when no record came).
    other_arms
        On a rig of several arms, per other arm: its name, its records read after the task arm's, its replay log.
    """

    rows: npt.NDArray[np.void]
    lost: int
    loop_events: list[LoopEvent]
    replay_log: list[ReplayEntry]
    other_arms: tuple[tuple[str, npt.NDArray[np.void], list[ReplayEntry]], ...] = ()


class SessionDriver:
    """Reads the loop's ring from where it was created and feeds the blocks to a session runner.

    Parameters
    ----------
    ring
        The ring the loop writes every tick's record to.
    replay_log
        The loop's replay log (:attr:`pipeline.runtime.loop.HapticLoop.replay_log`); the driver takes its entries.
    other_arms
        A rig of several arms: per arm other than the task arm (whose ``ring`` and log the two above are), its name,
        ring and replay log (:class:`pipeline.runtime.arm_channel.ArmChannel`), recorded beside the session's.
    """

    def __init__(self, ring: RingBuffer, replay_log: deque[ReplayEntry],
                 other_arms: tuple[tuple[str, RingBuffer, deque[ReplayEntry]], ...] = ()) -> None:
        self.ring = ring
        self.replay_log = replay_log
        self.other_arms = other_arms
        self._other_cursors = [r.write_count for _, r, _ in other_arms]
        #: The ring's write count of the next record to read (records before the driver was made are not read).
        self.cursor = ring.write_count
        #: The loop's events not yet handed on (appended on the loop's thread, taken on the driver's).
        self.loop_events: deque[LoopEvent] = deque()

    def on_loop_event(self, ev: LoopEvent) -> None:
        """Keep one of the loop's events for the next block (safe from the loop's thread)."""
        self.loop_events.append(ev)

    def take_events(self) -> list[LoopEvent]:
        """The loop's pending events, taken (oldest first)."""
        events = self.loop_events
        return [events.popleft() for _ in range(len(events))]

    def take(self) -> RingBlock:
        """The records written since the last call, then the loop's events and replay log (if any record came)."""
        res = self.ring.read_since(self.cursor)
        self.cursor = res.cursor
        if len(res.rows) == 0:
            return RingBlock(res.rows, res.lost, [], [])
        # the events and the replay log after the records: every entry of a tick whose record was read is in
        log = self.replay_log
        return RingBlock(res.rows, res.lost, self.take_events(), [log.popleft() for _ in range(len(log))],
                         self._take_other_arms())

    def _take_other_arms(self) -> tuple[tuple[str, npt.NDArray[np.void], list[ReplayEntry]], ...]:
        """The other arms' records since the last read, each with its replay log (an arm's lost records show as a
        gap in its own recording; the trial is the task arm's)."""
        out = []
        for i, (name, ring, log) in enumerate(self.other_arms):
            res = ring.read_since(self._other_cursors[i])
            self._other_cursors[i] = res.cursor
            out.append((name, res.rows, [log.popleft() for _ in range(len(log))]))
        return tuple(out)

    def feed(self, runner: SessionRunner, block: RingBlock | None = None,
             trigger: RehearsalTrigger | None = None) -> RingBlock:
        """Hand one block to ``runner`` (None: the records written since the last read, :meth:`take`); poll
        ``trigger`` (a planned ``kill`` fires at its record exactly).  Returns the block handed.

        A driver with nothing to do between reading and feeding (the headless runner) leaves the reading to this,
        so the records do not pass through its hands.
        """
        if block is None:
            block = self.take()
        if block.lost:
            runner.records_lost(block.lost)
        rows = block.rows
        n = len(rows)
        recording = not runner.done  # (the other arms' records of the block that ends the session are kept too)
        due = trigger.due_ns() if trigger is not None else None
        if trigger is not None and due is not None and n and int(rows["t_ns"][-1]) >= due:
            # a planned kill: the runner gets the records up to its moment, then the process dies there
            k = int(np.searchsorted(rows["t_ns"], due, side="right"))
            runner.process(rows[:k], block.loop_events, block.replay_log)
            if k:
                trigger.poll(int(rows["t_ns"][k - 1]))
            runner.process(rows[k:])
        else:
            runner.process(rows, block.loop_events, block.replay_log)
        if recording:
            for name, arm_rows, arm_log in block.other_arms:
                runner.other_arms.record(name, arm_rows, arm_log, runner.clock)
        if trigger is not None and n:
            trigger.poll(int(rows["t_ns"][-1]))
        return block

    def flush_events(self, runner: SessionRunner) -> None:
        """Hand the pending loop events to ``runner`` without records (the loop is frozen: it writes none)."""
        if self.loop_events:
            runner.process(np.empty(0), self.take_events())
