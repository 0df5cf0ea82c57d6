"""The whole-session recording: a lossless codec for any value, blocks built as records arrive, written by the
recorder within its deadline, read back by tick windows."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from old_chunks import old_chunk, old_open_block
from test_storage import FakeClock, _session_args

from pipeline.core.tick_record import TICK_DTYPE
from protocol.recording import (
    BLOCK_RECORDS,
    COLUMNS,
    POSE_COLUMNS,
    BlockBuilder,
    decode_block,
    decode_columns,
    encode_block,
    join_chunks,
    kept_records,
)
from protocol.recording.open_block import _encode_raw
from protocol.storage import Recorder, StudyDatabase
from protocol.storage.reader import StudyReader
from protocol.storage.recordings import read_segment, read_ticks
from protocol.storage.withdrawal import erase_participant, footprint

#: Every kind of float64 the loop could hand over, the awkward ones often.
ANY_FLOAT = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True),
    st.sampled_from([0.0, -0.0, np.nan, -np.nan, np.inf, -np.inf, 5e-324, -5e-324, 2.2250738585072014e-308,
                     1.7976931348623157e308, 1e-320, 0.1, 1 / 3]),
)
COUNTS_PER_UNIT = 1_000_000.0  # the Net F/T's counts per N


def bits(a: np.ndarray) -> np.ndarray:
    """Values compared bit for bit (NaN payloads, the sign of zero)."""
    a = np.ascontiguousarray(a)
    return a.view(np.int64) if a.dtype == np.float64 else a.astype(np.int64)


@st.composite
def blocks(draw: st.DrawFn) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], list]:
    n = draw(st.integers(0, 40))
    m = draw(st.integers(0, 6))
    cols: dict[str, np.ndarray] = {}
    for c in COLUMNS:
        if c.codec in ("int", "small"):
            lo, hi = (-(2**63), 2**63 - 1) if c.codec == "int" else (-(2**40), 2**40)
            cols[c.name] = draw(hnp.arrays(np.int64, n, elements=st.integers(lo, hi)))
        elif c.codec == "counts" and draw(st.booleans()):
            # what the sensor sends (integer counts over counts per unit), now and then something else
            counts = draw(hnp.arrays(np.int64, n, elements=st.integers(-(2**40), 2**40)))
            values = counts / COUNTS_PER_UNIT
            if n and draw(st.booleans()):
                values[draw(st.integers(0, n - 1))] = draw(ANY_FLOAT)
            cols[c.name] = values
        else:
            cols[c.name] = draw(hnp.arrays(np.float64, n, elements=ANY_FLOAT))
    poses = {c.name: (draw(hnp.arrays(np.int64, m, elements=st.integers(-(2**62), 2**62))) if c.codec == "int"
                      else draw(hnp.arrays(np.float64, m, elements=ANY_FLOAT))) for c in POSE_COLUMNS}
    events = [(draw(st.integers(0, 10**9)), "reset", None) for _ in range(draw(st.integers(0, 2)))]
    return cols, poses, events


@settings(max_examples=150, deadline=None)
@given(blocks())
def test_any_block_decodes_to_the_same_bits(block) -> None:
    cols, poses, events = block
    blob = encode_block(cols, poses, events,
                        {f"raw_{k}": COUNTS_PER_UNIT for k in ("fx", "fy", "fz", "tx", "ty", "tz")})
    back, back_poses, back_events = decode_block(blob)
    for name, values in cols.items():
        assert np.array_equal(bits(back[name]), bits(values)), name
    for name, values in poses.items():
        assert np.array_equal(bits(back_poses[name]), bits(values)), name
    assert back_events == events
    # reading some columns only gives the same values
    part = decode_columns(blob, ["t_ns", "force_n", "raw_fx"])
    assert all(np.array_equal(bits(part[k]), bits(cols[k])) for k in part)
    # so does an open block's chunk -- as the writer makes it, and as the writers before session_chunks did --
    # alone or joined after another
    kept = kept_records(cols)
    pose_list = [(int(poses["tick"][i]), tuple(float(poses[f"r{j}"][i]) for j in range(9)),
                  tuple(float(poses[f"{a}_m"][i]) for a in "xyz"), int(poses["pose_t_ns"][i]))
                 for i in range(len(poses["tick"]))]
    chunk = _encode_raw(np.ndarray((len(kept), kept.dtype.itemsize), np.uint8, kept), kept.dtype,
                                  pose_list, events)
    for blob, k in ((chunk, 1), (join_chunks([chunk, chunk]), 2), (old_chunk(cols, poses, events), 1),
                    (old_open_block([old_chunk(cols, poses, events)] * 2), 2)):
        back, back_poses, back_events = decode_block(blob)
        for name, values in cols.items():
            assert np.array_equal(bits(back[name]), bits(np.tile(values, k))), name
        for name, values in poses.items():
            assert np.array_equal(bits(back_poses[name]), bits(np.tile(values, k))), name
        assert back_events == events * k
        assert np.array_equal(bits(decode_columns(blob, ["force_n"])["force_n"]), bits(np.tile(cols["force_n"], k)))


def test_exact_counts_are_kept_as_counts_and_are_smaller() -> None:
    rng = np.random.default_rng(0)
    n = BLOCK_RECORDS
    counts = rng.integers(-20_000_000, 20_000_000, n)

    def block(raw: np.ndarray) -> bytes:
        cols = {c.name: np.zeros(n, dtype=np.int64 if c.codec in ("int", "small") else np.float64) for c in COLUMNS}
        cols["tick"] = np.arange(n)
        cols["raw_fx"] = raw
        poses = {c.name: np.empty(0) for c in POSE_COLUMNS}
        return encode_block(cols, poses, [], {"raw_fx": COUNTS_PER_UNIT})

    exact = block(counts / COUNTS_PER_UNIT)
    nudged = counts / COUNTS_PER_UNIT
    nudged[::7] = np.nextafter(nudged[::7], np.inf)  # not counts any more: stored as float64, still exactly
    kept = block(nudged)
    assert len(exact) < len(kept)
    assert np.array_equal(decode_block(kept)[0]["raw_fx"], nudged)
    assert np.array_equal(decode_block(exact)[0]["raw_fx"], counts / COUNTS_PER_UNIT)


def records(first_tick: int, n: int) -> dict[str, np.ndarray]:
    """The kept columns of loop records, values from the tick."""
    tick = np.arange(first_tick, first_tick + n, dtype=np.int64)
    cols: dict[str, np.ndarray] = {}
    for c in COLUMNS:
        cols[c.name] = tick.copy() if c.codec in ("int", "small") else np.sin(tick * 0.001) + tick * 1e-6
    cols["t_ns"] = tick * 1_000_000
    return cols


@pytest.mark.parametrize("chunk", [1, 37, 999, 1000, 1001, 2500])
def test_the_builder_cuts_full_blocks_and_keeps_the_rest_open(chunk: int) -> None:
    builder = BlockBuilder()
    written: dict[int, bytes] = {}
    chunks: dict[int, list[bytes]] = {}
    full: set[int] = set()
    total = 3210
    for start in range(0, total, chunk):
        n = min(chunk, total - start)
        builder.add(records(start, n), [(start, "pose", ((1.0,) * 9, (0.1, 0.2, 0.3), start * 1000))])
        for number, before, cols, blob in builder.take_full():
            # a full block is written once (over its partial writes)
            assert number not in full and before == number * BLOCK_RECORDS and len(cols["tick"]) == BLOCK_RECORDS
            written[number] = blob
            full.add(number)
        part = builder.partial()
        if part is not None:
            assert part.block not in full and part.number == len(chunks.get(part.block, []))
            assert len(part.records) == n or part.number == 0  # only what the block gained since the last commit
            chunks.setdefault(part.block, []).append(part.data)  # appended, as the recorder does at each commit
    assert builder.partial() is None  # nothing new since
    written.update({b: join_chunks(c) for b, c in chunks.items() if b not in full})  # as a reader joins them
    assert sorted(written) == [0, 1, 2, 3]
    cols = [decode_block(written[k]) for k in sorted(written)]
    ticks = np.concatenate([c[0]["tick"] for c in cols])
    assert np.array_equal(ticks, np.arange(total))
    pose_ticks = np.concatenate([c[1]["tick"] for c in cols])
    assert np.array_equal(pose_ticks, np.arange(0, total, chunk))  # each pose in the block of its tick


def _record_1540_ms(path: Path) -> tuple[StudyDatabase, int, Recorder]:
    """A recorder that was handed 1540 records, one per millisecond, in hand-overs of 10 ms as the runner makes them;
    not closed."""
    db = StudyDatabase(path)
    sid = db.create_session(**_session_args())
    clock = FakeClock()
    rec = Recorder(db, threaded=False, clock=clock)
    rec.segment(sid, 0, 0.0, 0, {"framework": {}}, {})
    for k in range(0, 1540, 10):
        clock.now = k / 1000
        rec.records(sid, 0, records(k, 10))
    return db, sid, rec


def test_the_recorder_writes_the_open_block_at_each_commit_and_a_crash_loses_only_the_uncommitted(
        tmp_path: Path) -> None:
    path = tmp_path / "rec.db"
    db, sid, _ = _record_1540_ms(path)
    # a crash now (no close, no flush): another connection sees what the commits wrote
    other = sqlite3.connect(path)
    try:
        seg = read_segment(other, sid, 0)
        stored = len(seg.columns["tick"])
        assert 1540 - 100 - 10 <= stored < 1540  # at most 100 ms (one commit deadline) of records lost
        assert np.array_equal(seg.columns["tick"], np.arange(stored))  # and what is there is whole and in order
        # one full block, and the open one in the chunks its commits appended (each only what it gained)
        assert other.execute("SELECT COUNT(*), MAX(n_records) FROM session_blocks").fetchone() == (1, BLOCK_RECORDS)
        chunk_rows = other.execute("SELECT block, chunk, n_records FROM session_chunks ORDER BY chunk").fetchall()
        assert [r[:2] for r in chunk_rows] == [(1, k) for k in range(len(chunk_rows))]
        assert sum(r[2] for r in chunk_rows) == stored - BLOCK_RECORDS
        window = read_ticks(other, sid, 0, 990, 1010, ["t_ns", "force_n"])  # across the blocks' seam
        assert np.array_equal(window["tick"], np.arange(990, 1011))
        assert np.array_equal(window["t_ns"], np.arange(990, 1011) * 1_000_000)
        fp = footprint(other, "P01")  # what a withdrawal would remove counts the open block and its records
        assert fp is not None and (fp.blocks, fp.records) == (2, stored)
        assert StudyReader.over(other).record_count([sid]) == stored
        assert db.last_session_time_s(sid) == pytest.approx((stored - 1) / 1000)  # a resume's clock goes on from it
    finally:
        other.close()
    db.conn.execute("ROLLBACK")  # the crash: what was not committed is gone
    erase_participant(db, "P01", "test")  # a withdrawal removes the open block's chunks with the rest
    assert db.conn.execute("SELECT (SELECT COUNT(*) FROM session_blocks) + (SELECT COUNT(*) FROM session_chunks)"
                           ).fetchone() == (0,)
    db.close()


@pytest.mark.parametrize("late_s", [0.0, 0.3])
def test_a_dated_recorder_counts_the_deadline_from_the_records_ticks(tmp_path: Path, late_s: float) -> None:
    """Issue 42, class 8: on a busy machine the driver hands records over late; counted from the writer's look, a crash
    lost that delay besides the deadline.  Dated by their ticks, records already past the deadline are committed as
    they come: a crash at the last hand-over loses at most the deadline of ticks, however late they came."""
    path = tmp_path / "rec.db"
    db = StudyDatabase(path)
    sid = db.create_session(**_session_args())
    clock = FakeClock()
    rec = Recorder(db, threaded=False, clock=clock, dated=True)
    rec.segment(sid, 0, 0.0, 0, {"framework": {}}, {})
    for k in range(0, 1540, 10):
        clock.now = (k + 10) / 1000 + late_s  # the hand-over of ticks k..k+9, late_s after the last of them
        rec.records(sid, 0, records(k, 10))
    other = sqlite3.connect(path)
    try:
        stored = len(read_segment(other, sid, 0).columns["tick"])
    finally:
        other.close()
    # a crash now, at the hand-over of tick 1539 (+ late_s): ticks up to 1539 - 100 are on the disk
    assert 1540 - 100 <= stored <= 1540
    if late_s >= 0.1:
        assert stored == 1540  # each hand-over already older than the deadline: committed as it came
    if db.conn.in_transaction:
        db.conn.execute("ROLLBACK")  # the crash
    db.close()


def test_a_commit_writes_a_chunk_for_each_segment_given_records_since_the_last_in_the_order_they_opened(
        tmp_path: Path) -> None:
    db = StudyDatabase(tmp_path / "rec.db")
    sids = [db.create_session(**_session_args(code=f"P0{i}")) for i in (1, 2, 3)]
    clock = FakeClock()
    rec = Recorder(db, threaded=False, clock=clock)
    for sid in sids:
        rec.segment(sid, 0, 0.0, 0, {"framework": {}}, {})
    for k in range(0, 300, 10):  # the third session's records first, then the first's; the second has none after 100
        clock.now = k / 1000
        for sid in (sids[2], sids[0], *((sids[1],) if k < 100 else ())):
            rec.records(sid, 0, records(k, 10))
    rows = db.conn.execute("SELECT session_id, chunk, n_records FROM session_chunks ORDER BY rowid").fetchall()
    assert [r[0] for r in rows] == [sids[0], sids[1], sids[2], sids[0], sids[2]]  # (2 commits; then 1 pending)
    assert [r[1] for r in rows] == [0, 0, 0, 1, 1]
    rec.close()
    for sid, n in zip(sids, (300, 100, 300), strict=True):
        assert np.array_equal(read_segment(db.conn, sid, 0).columns["tick"], np.arange(n))
    db.close()


def test_a_segment_that_ends_has_its_last_block_whole_in_place_of_its_chunks(tmp_path: Path) -> None:
    db, sid, rec = _record_1540_ms(tmp_path / "rec.db")
    assert db.conn.execute("SELECT COUNT(*) FROM session_chunks").fetchone()[0] > 0
    rec.close()
    assert db.conn.execute("SELECT COUNT(*) FROM session_chunks").fetchone() == (0,)
    assert db.conn.execute("SELECT block, n_records FROM session_blocks").fetchall() == [(0, 1000), (1, 540)]
    assert np.array_equal(read_segment(db.conn, sid, 0).columns["tick"], np.arange(1540))
    db.close()


def test_loop_records_are_encoded_from_their_layout_into_the_same_bytes() -> None:
    """The recorder takes the ring's rows as they lie (their kept prefix): the bytes are those of the columns."""
    n = 2345
    cols = records(0, n)
    rows = np.zeros(n, TICK_DTYPE)
    for name, values in cols.items():
        rows[name] = values
    rows["t_s"], rows["comp_fx"] = np.nan, 7.0  # fields the recording does not keep change nothing
    kept = kept_records(rows)
    assert kept.dtype.names == tuple(c.name for c in COLUMNS)
    assert all(np.array_equal(bits(kept[c.name]), bits(cols[c.name])) for c in COLUMNS)
    assert kept_records(kept) is kept
    # the builder fed loop records and the builder fed columns write the same blocks, full and open
    log = [(k, "pose", ((1.0,) * 9, (0.1, 0.2, 0.3), k * 1000)) for k in range(0, n, 8)]
    by_rows, by_cols = BlockBuilder(), BlockBuilder()
    for lo in range(0, n, 70):
        hi = min(lo + 70, n)
        part = [e for e in log if lo <= e[0] < hi]
        by_rows.add(rows[lo:hi], part)
        by_cols.add({k: v[lo:hi] for k, v in cols.items()}, part)
        assert [b[3] for b in by_rows.take_full()] == [b[3] for b in by_cols.take_full()]
        a, b = by_rows.partial(), by_cols.partial()
        assert (a is None and b is None) or (a is not None and b is not None and a.data == b.data)
    final_rows, final_cols = by_rows.final(), by_cols.final()
    assert final_rows is not None and final_cols is not None and final_rows[3] == final_cols[3]
    # an integer column handed over as floats is refused unless every value is an integer
    floats = {k: v.astype(np.float64) for k, v in cols.items()}
    assert kept_records(floats).tobytes() == kept.tobytes()
    floats["faults"][3] = 0.5
    with pytest.raises(ValueError, match="'faults'"):
        kept_records(floats)
