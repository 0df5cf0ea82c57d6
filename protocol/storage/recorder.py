"""The recorder: a queue-fed writer with a commit deadline, so neither the loop nor the GUI waits on the disk.

Sample batches are committed at least every 100 ms, each trial record
atomically when the trial ends.  **A state change is one transaction**: what
a producer queues inside :meth:`Recorder.atomic` -- a trial's row, the schedule
with its re-run, the events of its end, a session's end -- is applied and
committed together or not at all, however the commit deadline falls.
"""

from __future__ import annotations

import contextlib
import queue
import sqlite3
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from protocol.recording import BlockBuilder
from protocol.storage.common import StorageError
from protocol.storage.database import StudyDatabase
from protocol.study.clock import SessionClock
from protocol.study.records import TrialRecord

__all__ = ["Call", "Event", "Group", "Message", "Recorder", "Records", "Samples", "Segment", "Trial"]


# -- what the queue carries: one typed message per kind of write ------------------------------------------------
@dataclass(frozen=True, slots=True)
class Samples:
    """Rows of the ``samples`` table (schema versions 1 and 2)."""

    rows: Sequence[Sequence[float]] | np.ndarray


@dataclass(frozen=True, slots=True)
class Trial:
    """A finished trial's record (committed at once)."""

    record: TrialRecord


@dataclass(frozen=True, slots=True)
class Event:
    """A phase change or an experimenter action."""

    session_id: int
    t_s: float
    kind: str
    detail: str = ""


@dataclass(frozen=True, slots=True)
class Segment:
    """A segment of a session's recording opens (committed at once)."""

    session_id: int
    segment: int
    started_at_s: float
    t0_ns: int
    snapshot: dict[str, Any]
    scales: dict[str, float]
    arm: str = ""  # "": the task arm's (protocol.storage.common.recording_tables)


@dataclass(frozen=True, slots=True)
class Records:
    """Loop records of a segment and the replay log of their ticks."""

    session_id: int
    segment: int
    records: np.ndarray
    log: list[tuple[int, str, Any]]
    arm: str = ""


@dataclass(frozen=True, slots=True)
class Call:
    """A function run in the writer (committed at once)."""

    fn: Callable[[StudyDatabase], Any]


@dataclass(frozen=True, slots=True)
class Group:
    """Messages queued inside :meth:`Recorder.atomic`: applied and committed together."""

    items: list[Message]


#: What the recorder's queue carries.
Message = Samples | Trial | Event | Segment | Records | Call | Group


class Recorder:
    """Queue-fed writer with a commit deadline: samples reach the disk within ``max_latency_s``.

    ``threaded=True`` runs the writer in its own thread (live sessions: the
    producers never wait on the disk); ``threaded=False`` executes each call
    inline (headless runs on the virtual clock, where nothing else is
    waiting) with the same commit rules.  Trial summaries are committed at
    once, together with every sample before them, in one transaction.

    Parameters
    ----------
    db
        The database (the recorder becomes its only writer).
    max_latency_s
        Longest time a queued sample may stay uncommitted (wall clock).
    clock
        The commit deadline's clock, s: the wall clock for a live session; a
        run on the virtual clock passes its own time, so it commits every 100 ms
        of its records as a live session does (and a crash loses as much).
    short_transactions
        Keep queued writes in memory and execute them in one short
        transaction at each commit, instead of holding a transaction (and the
        database's write lock) open between commits.  For several writer
        processes on one database (parallel participants): a recorder holding
        the lock for ~100 ms at a time would starve the others.  The commit
        rules, and so the crash guarantees, are the same.
    dated
        The records' own times (``t_ns``) are on ``clock`` (x 1e-9 s): the deadline of records counts from their
        first tick, not from when the writer saw them.  A live session's records reach the writer some ms after
        their ticks (the driver reads the ring every 20 ms), and on a busy machine hundreds of ms after; counted
        from the writer's look, a crash then lost that delay besides the deadline (0.3 s under load, issue 42).
        Records already older than the deadline are committed at once.
    """

    def __init__(
        self, db: StudyDatabase, *, threaded: bool = True, max_latency_s: float = 0.1,
        clock: Callable[[], float] = time.monotonic, short_transactions: bool = False, dated: bool = False,
    ) -> None:
        self.db = db
        self.dated = dated
        self.short_transactions = short_transactions
        self._held: list[Message] = []
        self.max_latency_s = max_latency_s
        self._clock = clock
        self._first_pending: float | None = None
        self._q: queue.SimpleQueue[Message | None] = queue.SimpleQueue()
        #: The open block of every segment being recorded, and the segment's clock: (session, segment) -> both.
        self._blocks: dict[tuple[int, int, str], tuple[BlockBuilder, SessionClock]] = {}  # (session, segment, arm)
        #: The segments given records since the last commit, each with its place in ``_blocks`` (a commit writes
        #: their chunks in that order, and skips the segments of a study's other sessions, often dozens).
        self._fresh: dict[tuple[int, int, str], int] = {}
        self._rank: dict[tuple[int, int, str], int] = {}  # each segment's place in ``_blocks``
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None
        self._local = threading.local()  # per producer thread: the items queued inside atomic(), not yet handed on
        if threaded:
            self._thread = threading.Thread(target=self._run, name="recorder", daemon=True)
            self._thread.start()

    # producers ----------------------------------------------------------------------------------
    def samples(self, rows: Sequence[Sequence[float]] | np.ndarray) -> None:
        """Queue sample rows (a sequence of rows or a 2-D float array, not modified afterwards)."""
        self._put(Samples(rows))

    def trial(self, record: TrialRecord) -> None:
        """Queue a finished trial's record (committed at once with the samples before it)."""
        self._put(Trial(record))

    def event(self, session_id: int, t_s: float, kind: str, detail: str = "") -> None:
        """Queue an event."""
        self._put(Event(session_id, t_s, kind, detail))

    def segment(self, session_id: int, segment: int, started_at_s: float, t0_ns: int, snapshot: dict[str, Any],
                scales: dict[str, float], arm: str = "") -> None:
        """Open a segment of the session's recording (committed at once, before any of its blocks); ``arm``: of
        another arm than the task arm."""
        self._put(Segment(session_id, segment, started_at_s, t0_ns, snapshot, scales, arm))

    def records(self, session_id: int, segment: int, records: np.ndarray,
                log: Sequence[tuple[int, str, Any]] = (), arm: str = "") -> None:
        """Queue loop records of a segment (rows of :data:`pipeline.core.tick_record.TICK_DTYPE`, or their kept part,
        :func:`protocol.recording.kept_records`) and the replay log of their ticks.  The rows must not change
        after they are queued (the ring's copies do not).

        They are cut into blocks as they fill; what the open block gained is written at every commit (a chunk).
        """
        self._put(Records(session_id, segment, records, list(log), arm))

    def call(self, fn: Callable[[StudyDatabase], Any]) -> None:
        """Run ``fn(db)`` in the writer, committed at once (session start/end, schedule updates)."""
        self._put(Call(fn))

    @contextlib.contextmanager
    def atomic(self) -> Iterator[None]:
        """Everything queued inside the block is one transaction: applied and committed together, or not at all.

        Nestable (the outermost block commits).  The items the calling thread
        queues are handed to the writer as one when the block ends, so neither
        the commit deadline nor a crash can fall between them (other threads'
        items go on as usual).
        """
        local = self._local
        if getattr(local, "group", None) is not None:
            yield  # inside another block: its end commits
            return
        local.group = []
        try:
            yield
        except BaseException:
            local.group = None  # a state change that failed half-way is not stored at all
            raise
        group, local.group = local.group, None
        if group:
            self._put(Group(group))

    def _put(self, item: Message) -> None:
        if self.error is not None:
            raise StorageError(f"the recorder stopped after an error: {self.error}")
        group = getattr(self._local, "group", None)
        if group is not None and not isinstance(item, Group):
            group.append(item)
            return
        if self._thread is None:
            self._handle(item)
            self._maybe_commit()
        else:
            self._q.put(item)

    # writer -------------------------------------------------------------------------------------
    def _handle(self, item: Message) -> None:
        if self._first_pending is None:
            self._first_pending = self._clock()
        if self.dated and isinstance(item, Records) and len(item.records):
            self._first_pending = min(self._first_pending, int(item.records["t_ns"][0]) * 1e-9)
        if self.short_transactions:
            self._held.append(item)
            if _commits(item):
                self._commit()
            return
        self._apply(item)

    def _apply(self, item: Message, commit: bool = True) -> None:
        """Apply one message in the open transaction; a trial, a call, a segment or a group holding one commits
        (unless ``commit`` is False)."""
        db = self.db
        db.begin()
        if isinstance(item, Group):
            for sub in item.items:
                self._apply(sub, commit=False)
        elif isinstance(item, Records):
            key = (item.session_id, item.segment, item.arm)
            builder, _ = self._blocks[key]
            builder.add(item.records, item.log)
            if key not in self._fresh:
                self._fresh[key] = self._rank[key]
            for block in builder.take_full():
                self._write_block(key, block)
        elif isinstance(item, Samples):
            db.insert_samples(item.rows)
        elif isinstance(item, Event):
            db.insert_event(item.session_id, item.t_s, item.kind, item.detail)
        elif isinstance(item, Segment):
            db.insert_recording(item.session_id, item.segment, item.started_at_s, item.t0_ns, item.snapshot,
                                item.scales, item.arm)
            key = (item.session_id, item.segment, item.arm)
            self._blocks[key] = (BlockBuilder(scales=item.scales), SessionClock(item.started_at_s, item.t0_ns))
            self._rank.setdefault(key, len(self._rank))
        elif isinstance(item, Trial):
            db.insert_trial(item.record.to_row())
        else:
            item.fn(db)
        if commit and _commits(item):
            self._commit()

    def _write_block(self, key: tuple[int, int, str], block: tuple[int, int, np.ndarray, bytes]) -> None:
        _, clock = self._blocks[key]
        number, _, records, data = block
        session_id, segment, arm = key
        self.db.write_block(session_id, segment, number, *_span(records, clock), data, arm=arm)

    def _commit(self, final: bool = False) -> None:
        if self._held:
            held, self._held = self._held, []
            try:
                for item in held:
                    self._apply(item)  # a trial or call item commits everything before it, itself included
            except BaseException:
                if self.db.conn.in_transaction:
                    self.db.conn.execute("ROLLBACK")
                raise
        fresh = sorted(self._fresh, key=self._fresh.__getitem__) if len(self._fresh) > 1 else list(self._fresh)
        for key in self._blocks if final else fresh:
            builder, clock = self._blocks[key]
            # the records since the last commit reach the disk with it (a chunk); at the end, the open block whole
            if final:
                block = builder.final()
                if block is not None:
                    self.db.begin()
                    self._write_block(key, block)
            elif (chunk := builder.partial()) is not None:
                self.db.begin()
                sid, seg, arm = key
                self.db.write_chunk(sid, seg, chunk.block, chunk.number, *_span(chunk.records, clock), chunk.data,
                                    arm=arm)
        self._fresh.clear()  # (after the loop: a chunk that failed to write is looked at again next time)
        if self.db.conn.in_transaction:
            self.db.heartbeat()  # with data anyway: a live writer's leases stay fresh for other hosts
        self.db.commit()
        self._first_pending = None

    def _maybe_commit(self) -> None:
        if self._first_pending is not None and self._clock() - self._first_pending >= self.max_latency_s:
            self._commit()

    def _run(self) -> None:
        try:
            while True:
                timeout = None
                if self._first_pending is not None:
                    timeout = max(0.0, self.max_latency_s - (self._clock() - self._first_pending))
                try:
                    item = self._q.get(timeout=timeout)
                except queue.Empty:
                    self._commit()
                    continue
                if item is None:
                    break
                self._handle(item)
                self._maybe_commit()
            self._commit(final=True)
        except BaseException as exc:  # reported to the producer on its next call
            self.error = exc
            with contextlib.suppress(sqlite3.Error):
                if self.db.conn.in_transaction:
                    self.db.conn.execute("ROLLBACK")

    def flush(self) -> None:
        """Commit everything queued so far (blocks until the writer has)."""
        if getattr(self._local, "group", None) is not None:
            raise RuntimeError("Recorder.flush() inside atomic(): the block's items are not queued before it ends")
        if self._thread is None:
            self._commit()
            return
        done = threading.Event()

        def committed(db: StudyDatabase) -> None:
            db.commit()  # before waking the caller, who may read what it wrote from another connection
            done.set()

        self.call(committed)
        while not done.wait(0.05):
            if self.error is not None or not self._thread.is_alive():
                raise StorageError(f"the recorder stopped: {self.error}")

    def close(self) -> None:
        """Commit what is pending and stop the writer thread."""
        if self._thread is not None:
            self._q.put(None)
            self._thread.join()
            self._thread = None
        else:
            self._commit(final=True)
        if self.error is not None:
            raise StorageError(f"the recorder failed: {self.error}")


def _span(records: np.ndarray, clock: SessionClock) -> tuple[int, int, int, float, float]:
    """Where records lie, as a block's or a chunk's row says it: first and last tick, how many, and the session-clock
    times of the first and the last."""
    ticks, t_ns = records["tick"], records["t_ns"]
    return int(ticks[0]), int(ticks[-1]), len(ticks), clock.seconds(int(t_ns[0])), clock.seconds(int(t_ns[-1]))


def _commits(item: Message) -> bool:
    """Whether a message is committed at once: a trial, a call, a segment, or a group holding one (events and
    records wait for the deadline)."""
    if isinstance(item, Group):
        return any(_commits(sub) for sub in item.items)
    return isinstance(item, (Trial, Call, Segment))
