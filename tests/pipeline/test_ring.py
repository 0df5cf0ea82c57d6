"""Tests of the shared-memory ring buffer: cursor semantics, wrap-around, cross-process attach, lifetime."""

from __future__ import annotations

import multiprocessing as mp
import os
import struct

import numpy as np
import pytest

from pipeline.runtime.ring import RingBuffer

FIELDS = ("t_s", "a", "b")
TIMEOUT_S = 30.0


def _row(k: int) -> tuple[float, float, float]:
    return (float(k), 10.0 * k, -0.5 * k)


def _rows_as_tuples(rows: np.ndarray) -> list[tuple[float, ...]]:
    return [tuple(float(v) for v in r) for r in rows]


def _shm_path(name: str) -> str:
    return os.path.join("/dev/shm", name.lstrip("/"))


# -- a reader in another process (top level: picklable for the spawn context) ---------------------
def _read_ring_in_child(name: str, out: mp.Queue, close: bool) -> None:
    ring = RingBuffer.attach(name)
    res = ring.read_since(0)
    out.put((ring.fields, ring.capacity, ring.write_count, res.cursor, res.lost, res.rows.tobytes()))
    if close:
        ring.close()
    # else: exit with the segment still mapped, as a crashed GUI would


def _run_reader(name: str, close: bool) -> tuple:
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    p = ctx.Process(target=_read_ring_in_child, args=(name, q, close), daemon=True)
    p.start()
    try:
        msg = q.get(timeout=TIMEOUT_S)
        p.join(TIMEOUT_S)
        assert not p.is_alive()
        assert p.exitcode == 0
        return msg
    finally:
        if p.is_alive():
            p.kill()
            p.join(5.0)


@pytest.fixture
def created_segments(monkeypatch):
    """Names of the shared-memory segments this test creates (other processes may use /dev/shm too)."""
    from multiprocessing import shared_memory

    made: list[str] = []
    real = shared_memory.SharedMemory

    class Recording(real):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            if kwargs.get("create"):
                made.append(self.name)

    monkeypatch.setattr(shared_memory, "SharedMemory", Recording)
    return made


@pytest.fixture
def shared_ring():
    ring = RingBuffer.create(FIELDS, 5, shared=True)
    try:
        yield ring
    finally:
        if ring._buf is not None:  # not closed by the test
            ring.close()


# -- single process -------------------------------------------------------------------------------
@pytest.mark.parametrize("shared", [True, False])
def test_write_and_read_since_with_wraparound(shared):
    with RingBuffer.create(FIELDS, 5, shared=shared) as ring:
        assert ring.capacity == 5
        assert ring.write_count == 0
        empty = ring.read_since(0)
        assert len(empty.rows) == 0 and empty.cursor == 0 and empty.lost == 0

        for k in range(3):
            ring.write(_row(k))
        r = ring.read_since(0)
        assert _rows_as_tuples(r.rows) == [_row(k) for k in range(3)]
        assert r.cursor == 3 and r.lost == 0

        for k in range(3, 12):
            ring.write(_row(k))
        assert ring.write_count == 12

        # From the last cursor (3): records 3..6 were overwritten, and 7's slot is the one the
        # writer fills next (never read: it may be half-written); 8..11 remain.
        r2 = ring.read_since(r.cursor)
        assert _rows_as_tuples(r2.rows) == [_row(k) for k in range(8, 12)]
        assert r2.cursor == 12 and r2.lost == 5

        # From scratch: 8 lost.
        r0 = ring.read_since(0)
        assert _rows_as_tuples(r0.rows) == [_row(k) for k in range(8, 12)]
        assert r0.cursor == 12 and r0.lost == 8

        # A cursor inside the window: nothing lost; the copy wraps (12 % 5 = 2).
        r9 = ring.read_since(9)
        assert _rows_as_tuples(r9.rows) == [_row(9), _row(10), _row(11)]
        assert r9.cursor == 12 and r9.lost == 0

        # Up to date: nothing new.
        r12 = ring.read_since(12)
        assert len(r12.rows) == 0 and r12.cursor == 12 and r12.lost == 0

        # One more write is seen from the returned cursor.
        ring.write(_row(12))
        r13 = ring.read_since(r12.cursor)
        assert _rows_as_tuples(r13.rows) == [_row(12)]
        assert r13.cursor == 13 and r13.lost == 0


def test_latest():
    with RingBuffer.create(FIELDS, 5, shared=False) as ring:
        assert len(ring.latest(3)) == 0
        ring.write(_row(0))
        ring.write(_row(1))
        assert _rows_as_tuples(ring.latest(3)) == [_row(0), _row(1)]
        for k in range(2, 12):
            ring.write(_row(k))
        assert _rows_as_tuples(ring.latest(1)) == [_row(11)]
        assert _rows_as_tuples(ring.latest(3)) == [_row(9), _row(10), _row(11)]
        # more than the capacity: the whole ring but the slot the writer fills next
        assert _rows_as_tuples(ring.latest(100)) == [_row(k) for k in range(8, 12)]
        assert len(ring.latest(0)) == 0


class _RacingRing(RingBuffer):
    """A ring whose writer appends one record right after a reader's first look at the counter."""

    race_row: tuple[float, ...] | None = None

    @property
    def write_count(self) -> int:
        c = super().write_count
        row, self.race_row = self.race_row, None
        if row is not None:
            self.write(row)  # the 1 kHz writer in the other process got in between
        return c


def test_latest_returns_at_most_n_rows_when_the_writer_races():
    ring = _RacingRing.create(FIELDS, 8, shared=False)
    for k in range(3):
        ring.write(_row(k))
    ring.race_row = _row(3)
    assert _rows_as_tuples(ring.latest(1)) == [_row(2)]  # the newest when the call began, and only one
    ring.race_row = _row(4)
    assert _rows_as_tuples(ring.latest(2)) == [_row(2), _row(3)]
    ring.race_row = _row(5)
    assert len(ring.latest(0)) == 0


class _LappingRing(RingBuffer):
    """A ring whose writer goes round the whole ring once between a reader's two looks at the counter.

    ``laps_at`` lists which counter reads (1-based) the writer runs a lap right after: the reader
    was descheduled there for a whole ring.
    """

    laps_at: tuple[int, ...] = ()
    reads = 0
    next_k = 0

    @property
    def write_count(self) -> int:
        c = super().write_count
        self.reads += 1
        if self.reads in self.laps_at:
            for _ in range(self.capacity):
                self.write(_row(self.next_k))
                self.next_k += 1
        return c


@pytest.mark.parametrize("laps_at", [(1,), (2,), (1, 2), (2, 4), (1, 2, 3, 4)])
def test_latest_returns_n_rows_however_the_reader_is_scheduled(laps_at):
    ring = _LappingRing.create(FIELDS, 6, shared=False)
    for k in range(20):
        ring.write(_row(k))
    ring.next_k = 20
    ring.laps_at = laps_at
    rows = _rows_as_tuples(ring.latest(3))
    # three consecutive records, untorn, and as new as they were at some moment of the call
    assert len(rows) == 3
    first = int(rows[0][0])
    assert rows == [_row(k) for k in range(first, first + 3)]
    assert first >= 17
    # fewer written than asked: all of them
    small = _LappingRing.create(FIELDS, 6, shared=False)
    small.write(_row(0))
    small.next_k, small.laps_at = 1, laps_at
    got = _rows_as_tuples(small.latest(3))
    assert len(got) in (1, 3) and got == [_row(k) for k in range(int(got[0][0]), int(got[0][0]) + len(got))]


class _HalfWritingRing(RingBuffer):
    """A ring whose writer is half-way through its next record while a reader copies.

    Right after the reader's first look at the counter the writer stores the first field of the
    next record in that record's slot -- the oldest record's -- and has not published it yet.
    """

    armed = False

    @property
    def write_count(self) -> int:
        c = super().write_count
        if self.armed:
            self.armed = False
            slot = self._rows[c % self.capacity]
            slot[FIELDS[0]] = -1.0  # a torn row: first field new, the rest old
        return c


@pytest.mark.parametrize("cursor", [0, 6, 7])
def test_read_since_never_returns_the_slot_the_writer_is_filling(cursor):
    ring = _HalfWritingRing.create(FIELDS, 5, shared=False)
    for k in range(12):
        ring.write(_row(k))
    ring.armed = True
    res = ring.read_since(cursor)
    rows = _rows_as_tuples(res.rows)
    assert all(r == _row(int(r[0])) for r in rows), rows  # no torn row
    assert rows == [_row(k) for k in range(max(cursor, 8), 12)]
    assert res.lost == max(0, 8 - cursor) and res.cursor == 12


def test_latest_never_returns_the_slot_the_writer_is_filling():
    ring = _HalfWritingRing.create(FIELDS, 5, shared=False)
    for k in range(12):
        ring.write(_row(k))
    ring.armed = True
    assert _rows_as_tuples(ring.latest(10)) == [_row(k) for k in range(8, 12)]


def test_field_names_round_trip_and_columns():
    fields = ("t_s", "raw_fx", "render_fy", "x" * 40)
    with RingBuffer.create(fields, 4, shared=True) as ring:
        assert ring.fields == fields
        assert ring.dtype.names == fields
        ring.write((1.0, 2.0, 3.0, 4.0))
        reader = RingBuffer.attach(ring.name)
        try:
            assert reader.fields == fields
            assert reader.capacity == 4
            assert reader.name is None  # only the creator names (and frees) the segment
            rows = reader.latest(1)
            assert rows.dtype.names == fields
            np.testing.assert_array_equal(reader.column(rows, "render_fy"), [3.0])
            assert reader.column(rows, "render_fy").dtype == np.float64
        finally:
            reader.close()


def test_rows_are_copies_not_views():
    with RingBuffer.create(FIELDS, 3, shared=False) as ring:
        ring.write(_row(1))
        rows = ring.latest(1)
        for k in range(2, 8):
            ring.write(_row(k))
        assert _rows_as_tuples(rows) == [_row(1)]


def test_nan_and_inf_are_stored_verbatim():
    with RingBuffer.create(FIELDS, 3, shared=False) as ring:
        ring.write((float("nan"), float("inf"), -0.0))
        r = ring.latest(1)[0]
        assert np.isnan(r["t_s"]) and r["a"] == np.inf
        assert np.signbit(r["b"])


def test_private_ring_has_no_name_and_no_segment(created_segments):
    ring = RingBuffer.create(FIELDS, 4, shared=False)
    try:
        assert ring.name is None
        assert created_segments == []
        for k in range(6):
            ring.write(_row(k))
        r = ring.read_since(0)
        assert _rows_as_tuples(r.rows) == [_row(k) for k in range(3, 6)]  # 2's slot is the writer's next
        assert r.lost == 3 and r.cursor == 6
    finally:
        ring.close()


def test_write_with_wrong_number_of_values_raises():
    with RingBuffer.create(FIELDS, 3, shared=False) as ring:
        with pytest.raises(struct.error):
            ring.write((1.0, 2.0))
        assert ring.write_count == 0


# -- construction errors --------------------------------------------------------------------------
@pytest.mark.parametrize("capacity", [1, 0, -3])
def test_capacity_below_two_raises(capacity):
    with pytest.raises(ValueError, match="capacity"):
        RingBuffer.create(FIELDS, capacity)


@pytest.mark.parametrize(
    "fields",
    [
        ("a,b", "c"),  # a comma would split into two columns
        (),  # no fields
        ("a", ""),  # empty name
        ("a", "b", "a"),  # duplicate name
        tuple(f"field_{i:04d}" for i in range(400)),  # 4399 bytes of names > 4064
    ],
    ids=["comma", "empty-list", "empty-name", "duplicate", "too-long"],
)
def test_bad_field_names_raise_without_leaking_a_segment(fields, created_segments):
    with pytest.raises(ValueError):
        RingBuffer.create(fields, 4, shared=True)
    assert [n for n in created_segments if os.path.exists(_shm_path(n))] == []


def test_attach_unknown_name_raises():
    with pytest.raises(FileNotFoundError):
        RingBuffer.attach("nope")


def test_attach_rejects_a_segment_that_is_not_a_ring():
    from multiprocessing import shared_memory

    shm = shared_memory.SharedMemory(create=True, size=8192)
    try:
        with pytest.raises(ValueError, match="magic"):
            RingBuffer.attach(shm.name)
    finally:
        shm.close()
        shm.unlink()


# -- lifetime ---------------------------------------------------------------------------------------
def test_close_of_the_creator_removes_the_segment(created_segments):
    ring = RingBuffer.create(FIELDS, 4, shared=True)
    name = ring.name
    assert name is not None
    assert created_segments == [name]
    assert os.path.exists(_shm_path(name))
    ring.close()
    assert not os.path.exists(_shm_path(name))
    with pytest.raises(FileNotFoundError):
        RingBuffer.attach(name)


def test_same_process_reader_close_keeps_the_segment(shared_ring):
    name = shared_ring.name
    shared_ring.write(_row(0))
    reader = RingBuffer.attach(name)
    assert _rows_as_tuples(reader.latest(1)) == [_row(0)]
    reader.close()
    assert os.path.exists(_shm_path(name))
    shared_ring.write(_row(1))
    assert _rows_as_tuples(shared_ring.latest(2)) == [_row(0), _row(1)]


def test_reader_sees_writes_made_after_it_attached(shared_ring):
    reader = RingBuffer.attach(shared_ring.name)
    try:
        r = reader.read_since(0)
        assert len(r.rows) == 0 and r.cursor == 0
        for k in range(7):
            shared_ring.write(_row(k))
        r = reader.read_since(r.cursor)
        assert _rows_as_tuples(r.rows) == [_row(k) for k in range(3, 7)]  # 2's slot is the writer's next
        assert r.cursor == 7 and r.lost == 3
    finally:
        reader.close()


# -- another process --------------------------------------------------------------------------------
@pytest.mark.parametrize("reader_closes", [True, False], ids=["reader-closes", "reader-just-exits"])
def test_second_process_attaches_by_name_and_its_exit_keeps_the_segment(shared_ring, reader_closes):
    name = shared_ring.name
    for k in range(8):  # wraps: capacity 5
        shared_ring.write(_row(k))

    fields, capacity, count, cursor, lost, raw = _run_reader(name, reader_closes)

    assert fields == FIELDS
    assert capacity == 5
    assert count == 8 and cursor == 8 and lost == 4
    child_rows = np.frombuffer(raw, dtype=shared_ring.dtype)
    assert _rows_as_tuples(child_rows) == [_row(k) for k in range(4, 8)]  # 3's slot is the writer's next
    assert child_rows.tobytes() == shared_ring.latest(5).tobytes()

    # The reader's exit must not have unlinked the writer's segment.
    assert os.path.exists(_shm_path(name))
    shared_ring.write(_row(8))
    assert _rows_as_tuples(shared_ring.latest(2)) == [_row(7), _row(8)]
    # ... and a new reader can still attach by name.
    again = RingBuffer.attach(name)
    try:
        assert _rows_as_tuples(again.latest(1)) == [_row(8)]
    finally:
        again.close()

    shared_ring.close()
    assert not os.path.exists(_shm_path(name))


def _create_ring_and_die(conn) -> None:
    ring = RingBuffer.create(["t"], 4, shared=True)
    ring.write([1.0])
    conn.send(ring.name)  # a pipe write: it has left the process before the kill
    os.kill(os.getpid(), 9)  # as a crash would: the segment is never freed


def test_a_killed_writers_ring_is_freed_by_name_and_only_once():
    ctx = mp.get_context("spawn")
    here, there = ctx.Pipe()
    p = ctx.Process(target=_create_ring_and_die, args=(there,), daemon=True)
    p.start()
    assert here.poll(30)
    name = here.recv()
    p.join(30)
    assert p.exitcode == -9 and os.path.exists(_shm_path(name))  # left behind by the dead writer
    reader = RingBuffer.attach(name)
    assert reader.latest(1)["t"].tolist() == [1.0]
    reader.close()
    assert RingBuffer.free_orphaned(name) is True and not os.path.exists(_shm_path(name))
    assert RingBuffer.free_orphaned(name) is False and RingBuffer.free_orphaned("") is False


def _write_counts(name: str, n: int) -> None:
    """Writer process: ``n`` one-field records as fast as it can."""
    ring = RingBuffer.attach(name)  # mapped read-write: the stand-in for the engine's loop writing its ring
    for k in range(n):
        ring.write((float(k),))
    ring.close()


def test_a_reader_in_another_process_never_sees_the_write_counter_go_back():
    """The counter is one aligned word: read byte by byte (``struct``), it was seen half-written now and then --
    a count from the past, and old rows returned again as new (the GUI's plots got a trial's records twice)."""
    ring = RingBuffer.create(("k",), 4096, shared=True)
    try:
        writer = mp.get_context("spawn").Process(target=_write_counts, args=(ring.name, 1_500_000))
        writer.start()
        last, cursor, went_back, gaps = 0, 0, [], 0
        while writer.is_alive() or cursor < 1_500_000:
            c = ring.write_count
            if c < last:
                went_back.append((last, c))
            last = c
            res = ring.read_since(cursor)
            if len(res.rows) and res.rows["k"][0] != cursor + res.lost:
                gaps += 1
            cursor = res.cursor
            if not writer.is_alive() and cursor >= ring.write_count:
                break
        writer.join(30)
        assert writer.exitcode == 0
        assert went_back == [] and gaps == 0 and ring.write_count == 1_500_000
    finally:
        ring.close()
