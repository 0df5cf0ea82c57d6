"""The recorded columns: ``derate`` is kept exactly, and a block written before it existed still reads (as 1: no
cut)."""

from __future__ import annotations

import sqlite3

import numpy as np
import pytest
from old_chunks import old_chunk, old_open_block

import protocol.recording.codec as recording
from protocol.recording import COLUMNS, BlockBuilder, decode_block, decode_columns, encode_block, join_chunks
from protocol.storage.recordings import read_ticks


def block_columns(n: int, derate: np.ndarray | None = None) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(1)
    cols: dict[str, np.ndarray] = {}
    for c in COLUMNS:
        if c.codec in ("int", "small"):
            cols[c.name] = np.arange(n, dtype=np.int64)
        else:
            cols[c.name] = rng.normal(size=n)
    cols["derate"] = np.ones(n) if derate is None else derate
    return cols


def no_poses() -> dict[str, np.ndarray]:
    return recording._pose_columns([])


def test_the_derate_column_round_trips_exactly_and_costs_little_when_constant() -> None:
    n = 1000
    cut = np.ones(n)
    cut[400:700] = np.linspace(0.97, 0.41, 300)
    for derate in (np.ones(n), cut):
        cols, _, _ = decode_block(encode_block(block_columns(n, derate), no_poses(), []))
        np.testing.assert_array_equal(cols["derate"].view(np.int64), derate.view(np.int64))
    constant = recording._encode(np.ones(n), "float", None)[1]
    assert len(constant) < 40  # a second of 1.0 is a few bytes


def test_a_block_written_before_the_derate_column_reads_as_not_cut(monkeypatch: pytest.MonkeyPatch) -> None:
    n = 10
    old_columns = tuple(c for c in COLUMNS if c.name != "derate")
    with monkeypatch.context() as m:
        m.setattr(recording, "COLUMNS", old_columns)  # what version 3 wrote before derating
        blob = encode_block(block_columns(n), no_poses(), [(3, "refine", True)])
    cols, _, events = decode_block(blob)
    assert set(cols) == {c.name for c in COLUMNS} and events == [(3, "refine", True)]
    np.testing.assert_array_equal(cols["derate"], np.ones(n))
    part = decode_columns(blob, ["tick", "derate"])
    np.testing.assert_array_equal(part["derate"], np.ones(n))
    with pytest.raises(ValueError, match="no column 'nonesuch'"):
        decode_columns(blob, ["nonesuch"])
    # through the database, as analysis reads a trial's window
    c = sqlite3.connect(":memory:")
    c.execute("CREATE TABLE session_blocks (session_id, segment, block, first_tick, last_tick, n_records, data)")
    c.execute("INSERT INTO session_blocks VALUES (1, 0, 0, 0, ?, ?, ?)", (n - 1, n, blob))
    win = read_ticks(c, 1, 0, 2, 5, ["derate", "gain"])
    np.testing.assert_array_equal(win["tick"], [2, 3, 4, 5])
    np.testing.assert_array_equal(win["derate"], np.ones(4))


def test_device_limit_entries_are_kept_as_columns_and_read_back_among_the_events() -> None:
    n = 1000
    limits = 3.3 - np.cumsum(np.full(n, 2.4e-4))  # a Touch derating: a new limit every tick
    events: list[tuple[int, str, object]] = [(0, "refine", False), (0, "device_limit", 3.3), (5, "reset", None)]
    events += [(k, "device_limit", float(v)) for k, v in enumerate(limits.tolist()) if k > 0]
    events.insert(4, (2, "zero", "late_tick"))  # (tick 2: before that tick's device limit, as the loop logs them)
    blob = encode_block(block_columns(n), no_poses(), events)
    _, _, back = decode_block(blob)
    assert back == sorted(events, key=lambda e: e[0])  # every value exact, the others first within a tick
    assert [e for e in back if e[0] == 2] == [(2, "zero", "late_tick"), (2, "device_limit", float(limits[2]))]
    plain = encode_block(block_columns(n), no_poses(), [e for e in events if e[1] != "device_limit"])
    assert len(blob) - len(plain) < 8 * n  # not ~40 bytes of JSON a tick
    assert b'"limits"' not in plain  # a block without any is written as before


def test_an_open_block_written_in_chunks_before_the_derate_column_reads_as_not_cut(
        monkeypatch: pytest.MonkeyPatch) -> None:
    n = 30
    cols = block_columns(n)
    with monkeypatch.context() as m:
        m.setattr(recording, "COLUMNS", tuple(c for c in COLUMNS if c.name != "derate"))
        b = BlockBuilder()
        old = {k: v for k, v in cols.items() if k != "derate"}
        b.add({k: v[:10] for k, v in old.items()}, [(4, "refine", True)])
        first = b.partial()
        b.add({k: v[10:] for k, v in old.items()}, [(12, "device_limit", 3.1)])
        second = b.partial()
        assert first is not None and second is not None
        blob = join_chunks([first.data, second.data])  # (what a session killed mid-block leaves: its chunks)
    back, _, events = decode_block(blob)
    np.testing.assert_array_equal(back["derate"], np.ones(n))
    np.testing.assert_array_equal(back["gain"].view(np.int64), cols["gain"].view(np.int64))
    assert events == [(4, "refine", True), (12, "device_limit", 3.1)]
    np.testing.assert_array_equal(decode_columns(blob, ["derate"])["derate"], np.ones(n))
    # so does one the writers before session_chunks left (deflated chunks joined in a session_blocks row)
    poses = {c.name: np.empty(0, np.int64 if c.codec == "int" else np.float64) for c in recording.POSE_COLUMNS}
    blob = old_open_block([old_chunk({k: v[:10] for k, v in old.items()}, poses, [(4, "refine", True)], list(old)),
                           old_chunk({k: v[10:] for k, v in old.items()}, poses, [], list(old))])
    back, _, events = decode_block(blob)
    np.testing.assert_array_equal(back["derate"], np.ones(n))
    np.testing.assert_array_equal(back["gain"].view(np.int64), cols["gain"].view(np.int64))
    assert events == [(4, "refine", True)]
    # and one this code writes keeps the values
    b = BlockBuilder()
    cols["derate"][5] = 0.75
    b.add(cols)
    part = b.partial()
    assert part is not None
    back, _, _ = decode_block(part.data)
    assert back["derate"][5] == 0.75
