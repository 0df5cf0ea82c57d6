"""A block encoded as one table (:mod:`protocol.recording.table_encode`) is byte for byte the column-by-column
encoding, on every codec's fall-backs: counts that are not counts, NaN, -0.0, marks an int32 cannot hold."""

from __future__ import annotations

import numpy as np
import pytest

import protocol.recording.codec as recording
from protocol.recording import COLUMNS, decode_block, encode_block, kept_records
from protocol.recording.open_block import _encode_raw
from protocol.recording.table_encode import column_words, record_words

SCALE = 1_000_000  # counts per unit (an int, as a recording's JSON may hold it: written to the header as it is)
SCALES = {f"raw_{a}": SCALE for a in ("fx", "fy", "fz", "tx", "ty", "tz")}


def _records(n: int, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    cols: dict[str, np.ndarray] = {}
    for c in COLUMNS:
        if c.codec in ("int", "small"):
            cols[c.name] = np.cumsum(rng.integers(0, 5, n)).astype(np.int64)
        elif c.codec == "counts":
            cols[c.name] = rng.integers(-(2**20), 2**20, n) / SCALE  # exactly counts
        else:
            cols[c.name] = np.cumsum(rng.normal(size=n))
    return cols


def _poses(m: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(m)
    return recording._pose_columns([(8 * i, tuple(rng.normal(size=9)), tuple(rng.normal(size=3)), 8_000_000 * i)
                                    for i in range(m)])


def _edges(cols: dict[str, np.ndarray]) -> None:
    """Every fall-back at once: each is a column the declared codec cannot keep."""
    cols["raw_fx"][3] = np.nan  # not counts: float64
    cols["raw_fy"][0] = -0.0  # -0.0 * scale is -0.0, rint keeps it, but the int 0 gives back +0.0: float64
    cols["raw_fz"][5] += 1e-9  # not a whole count: float64
    cols["raw_tx"][7] = 1e300  # counts beyond int64: float64
    cols["faults"][2] = 2**40  # beyond int32: differences of int64
    cols["trial_index"][1] = -(2**31)  # the least int32: still int32
    cols["stylus_x_m"][4] = np.inf
    cols["gain"][6] = -0.0


def _column_by_column(cols: dict[str, np.ndarray]) -> dict[str, list]:
    return {k: v.tolist() for k, v in cols.items()}  # (lists: never a table, each column encoded alone)


@pytest.mark.parametrize("n", [1, 2, 17, 1000])
@pytest.mark.parametrize("edges", [False, True])
def test_the_table_encoding_is_the_column_encoding_byte_for_byte(n: int, edges: bool) -> None:
    cols = _records(n, seed=n)
    if edges and n >= 8:
        _edges(cols)
    poses = _poses(n // 8 + 1)
    events = [(0, "device_limit", 4.0), (0, "refine", True)]
    rows = kept_records(cols)
    assert record_words(rows, [c.codec for c in COLUMNS]) is not None  # (the table path is the one taken)
    for scales in (SCALES, {}, {"raw_fx": float(SCALE)}):
        reference = encode_block(_column_by_column(cols), _column_by_column(poses), events, scales)
        assert encode_block(rows, poses, events, scales) == reference
        assert encode_block(cols, poses, events, scales) == reference
    got, _, _ = decode_block(encode_block(rows, poses, events, SCALES))
    for name, values in cols.items():
        np.testing.assert_array_equal(got[name].view(np.int64), values.view(np.int64))


def test_columns_not_of_the_codecs_own_types_go_column_by_column() -> None:
    cols = _records(10, seed=3)
    names, codecs = [c.name for c in COLUMNS], [c.codec for c in COLUMNS]
    assert column_words(cols, names, codecs) is not None
    floats = {**cols, "tick": cols["tick"].astype(np.float64)}  # an integer column as float64: values, not bits
    assert column_words(floats, names, codecs) is None
    assert encode_block(floats, _poses(2), []) == encode_block(_column_by_column(floats), _poses(2), [])
    assert record_words(kept_records(cols)[:0], [c.codec for c in COLUMNS]) is None


def test_blocks_of_constant_columns_reuse_no_other_inputs_deflated_bytes() -> None:
    # one value after the first: the deflated bytes are kept by (values, first value, the others' value); every
    # input here differs from the one before it in exactly one of them, or in how it is kept (int32, planes)
    seen = set()
    for n, first, rest in [(1000, 5, 7), (1000, 6, 7), (1000, 5, 8), (999, 5, 7), (1, 5, 5), (2, 5, 7)]:
        cols = _records(n, seed=0)
        for c in COLUMNS:
            values = np.full(n, rest, np.int64)
            values[0] = first
            cols[c.name] = values if c.codec in ("int", "small") else values.astype(np.float64) / 4
        blob = encode_block(kept_records(cols), _poses(3), [], SCALES)
        assert blob == encode_block(_column_by_column(cols), _column_by_column(_poses(3)), [], SCALES)
        seen.add(blob)
    assert len(seen) == 6


@pytest.mark.parametrize("n", [0, 1, 2, 100, 137])
def test_a_chunk_keeps_each_byte_plane_that_changes_and_one_byte_of_each_other(n: int) -> None:
    cols = _records(max(n, 1), seed=n)
    cols["gain"][:] = 1.0  # a column of one value: every plane one byte
    raw = np.ndarray((max(n, 1), 200), np.uint8, kept_records(cols))[:n]
    blob = _encode_raw(raw, kept_records(cols).dtype, [], [])
    planes = raw.T  # the definition: every record's byte b, for each b
    same = np.array([len(set(p.tolist())) <= 1 for p in planes], bool)
    tail = np.packbits(same).tobytes() + (planes[:, 0].tobytes() if n else bytes(200)) + planes[~same].tobytes()
    assert blob.endswith(tail)
    if n:
        got, _, _ = decode_block(blob)
        np.testing.assert_array_equal(got["gain"], cols["gain"][:n])
        assert same[8 * 16 : 8 * 17].all()  # gain is the 17th column


def test_records_whose_field_types_are_not_the_codecs_go_column_by_column() -> None:
    cols = _records(10, seed=4)
    codecs = [c.codec for c in COLUMNS]
    swapped = np.dtype([(c.name, "<f8" if c.codec in ("int", "small") else "<i8") for c in COLUMNS])
    rows = np.zeros(10, swapped)
    for c in COLUMNS:
        rows[c.name] = np.rint(cols[c.name]) if c.codec not in ("int", "small") else cols[c.name]
    assert record_words(rows, codecs) is None  # (read as they lie, the words would be the other type's bits)
    by_name = {c.name: rows[c.name] for c in COLUMNS}
    assert encode_block(rows, _poses(2), []) == encode_block(_column_by_column(by_name), _poses(2), [])
    got, _, _ = decode_block(encode_block(rows, _poses(2), []))
    np.testing.assert_array_equal(got["tick"], cols["tick"])
