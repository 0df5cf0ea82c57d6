"""The session runner's hand-off to the whole-session recording (:mod:`protocol.recording`).

A session's recording starts at the tick on which the loop took the snapshot of its framework that the runner
asked for (:class:`pipeline.runtime.loop_messages.StartRecording` with this hand-off's :attr:`SessionRecording.token`):
the records before that tick are the loop's, not the session's.  :class:`SessionRecording` finds that snapshot in
the loop's replay log, opens the session's segment with it, and hands each block of records to the recorder with
the replay-log entries of their ticks, so the session can be replayed through the pipeline
(:mod:`pipeline.force.replay`).
"""

from __future__ import annotations

import secrets
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from protocol.storage import Recorder
from protocol.study.clock import SessionClock

__all__ = ["OtherArms", "SessionRecording"]


class SessionRecording:
    """Which records are the session's, and their way to the recorder with the replay log of their ticks.

    Parameters
    ----------
    recorder
        The database writer.
    session_id
        The session's database id.
    segment
        The recording's segment this run writes (0, then one more per resume).
    scales
        Counts per unit of the raw wrench columns (the recording codec's hint; empty: store floats).
    arm, token
        Another arm's recording than the task arm's (""), and the snapshot token of the session's own recording
        (every arm takes its snapshot in the same tick).
    """

    def __init__(self, recorder: Recorder, session_id: int, segment: int, scales: dict[str, float] | None,
                 arm: str = "", token: int | None = None) -> None:
        self.recorder = recorder
        self.session_id = session_id
        self.segment = segment
        self.scales = dict(scales or {})
        self.arm = arm
        #: Names this run's snapshot among the loop's (sent with ``StartRecording``).
        self.token = secrets.randbits(31) if token is None else token
        self._log: list[tuple[int, str, object]] = []  # replay log entries not yet handed on
        #: The tick the recording (and the session clock) starts at; None until the loop took the snapshot.
        self.start_tick: int | None = None
        self._snapshot: dict[str, Any] = {}  # the loop's snapshot payload at that tick

    def session_rows(self, rows: npt.NDArray[np.void],
                     replay_log: Sequence[tuple[int, str, object]]) -> npt.NDArray[np.void] | None:
        """The session's part of a block of records (None: the loop has not taken the snapshot yet).

        ``replay_log`` is what the loop logged since the previous block, read after the records.  Once the start
        tick is known every record is the session's: :meth:`keep_log` is all a block then needs.
        """
        self._log.extend(replay_log)
        if self.start_tick is None:
            rows = self._from_snapshot(rows)
            if self.start_tick is None:
                return None
        return rows

    def keep_log(self, replay_log: Sequence[tuple[int, str, object]]) -> None:
        """Keep what the loop logged since the previous block for :meth:`record` (the recording has started)."""
        self._log.extend(replay_log)

    def _from_snapshot(self, rows: npt.NDArray[np.void]) -> npt.NDArray[np.void]:
        """Find this run's snapshot in the log; the records from its tick on (none before it is found)."""
        for i, (tick, kind, payload) in enumerate(self._log):
            if kind == "snapshot" and isinstance(payload, dict) and payload["token"] == self.token:
                self.start_tick = int(tick)
                self._snapshot = payload
                self._log = self._log[i + 1 :]
                return rows[rows["tick"] >= tick]
        self._log = [e for e in self._log if e[1] == "snapshot"]  # (another runner's: kept until ours shows)
        return rows[:0]

    def open_segment(self, started_at_s: float, t0_ns: int) -> None:
        """Open the run's segment at its first record (session time ``started_at_s``, loop time ``t0_ns``)."""
        self.recorder.segment(self.session_id, self.segment, started_at_s, t0_ns, self._snapshot, self.scales,
                              self.arm)

    def record(self, rows: npt.NDArray[np.void]) -> None:
        """Hand the records and the log entries of their ticks to the recorder (it keeps the kept fields)."""
        last = int(rows["tick"][-1])
        log = [e for e in self._log if e[0] <= last]
        self._log = [e for e in self._log if e[0] > last]
        self.recorder.records(self.session_id, self.segment, rows, log, self.arm)


class OtherArms:
    """The recordings of a rig's arms other than the task arm, on the session's clock.

    Each arm's records, from the same snapshot tick as the session's own, go to that arm's tables
    (:func:`protocol.storage.common.recording_tables`); its segment opens with the session's once the session's
    clock has started, and its records wait until then.

    Parameters
    ----------
    own
        The session's own recording (the task arm's): its recorder, session, segment, scales and snapshot token.
    """

    def __init__(self, own: SessionRecording) -> None:
        self._own = own
        self._arms: dict[str, SessionRecording] = {}
        self._waiting: dict[str, list[npt.NDArray[np.void]]] = {}
        self._open: set[str] = set()

    def record(self, arm: str, rows: npt.NDArray[np.void], replay_log: Sequence[tuple[int, str, object]],
               clock: SessionClock | None) -> None:
        """Hand one block of ``arm``'s records and its replay log on (``clock``: the session's; None: not started)."""
        rec = self._arms.get(arm)
        if rec is None:
            own = self._own
            rec = self._arms[arm] = SessionRecording(own.recorder, own.session_id, own.segment, own.scales, arm,
                                                     own.token)
        mine = rec.session_rows(rows, replay_log)
        if mine is None:
            return
        waiting = self._waiting.setdefault(arm, [])
        if len(mine):
            waiting.append(mine)
        if clock is None or not waiting:
            return
        if arm not in self._open:
            self._open.add(arm)
            rec.open_segment(clock.started_at_s, clock.t0_ns)
        rec.record(np.concatenate(waiting) if len(waiting) > 1 else waiting[0])
        waiting.clear()
