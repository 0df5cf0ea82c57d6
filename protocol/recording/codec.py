"""The recording's codec: what a block keeps of each record, and how, losslessly; a block, or an open block's
chunks, read back (the open block as it grows is :mod:`protocol.recording.open_block`).

Every decoding is checked bit for bit before a block is written, so a value
the codec cannot keep exactly is stored as plain float64 instead: nothing is
ever rounded.
"""

from __future__ import annotations

import json
import struct
import zlib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pipeline.core.tick_record import KEPT_DTYPE, KEPT_FIELDS, TICK_DTYPE
from protocol.recording.table_encode import encode_table

__all__ = [
    "BLOCK_RECORDS", "COLUMNS", "LIMIT_COLUMNS", "POSE_COLUMNS", "BlockRow", "Column",
    "decode_block",
    "decode_columns", "encode_block", "join_blocks", "join_chunks", "join_decoded", "kept_records",
]

#: Records per block (one second at 1 kHz).
BLOCK_RECORDS = 1000
_MAGIC = b"HSB1"  # a block: each column with its own codec
_RAW = b"HSR1"  # a chunk of an open block (a ``session_chunks`` row): the records' and poses' own bytes
_CHUNKED = b"HSBC"  # an open block as read back: its chunks, each length-prefixed
_FAST = b"HSF1"  # a chunk as the writers before ``session_chunks`` deflated it (still read)
_LEVEL = 6  # zlib: level 6 is within 10 % of 9's size at three times its speed on these arrays


@dataclass(frozen=True, slots=True)
class Column:
    """One recorded column: its name, where it comes from in a loop record, and how it is kept.

    ``codec``: ``"int"`` (differences of int64), ``"small"`` (int32, plain), ``"float"`` (float64,
    byte-shuffled), ``"smooth"`` (float64, differences of the bit patterns), ``"counts"`` (raw
    sensor values: integer counts when exact, else ``"float"``).  ``missing``: the value of every
    record in a block written before the column was added (None: every block has it).
    """

    name: str
    source: str
    codec: str
    missing: float | None = None


#: What a block keeps of each record, in order: the kept fields of the tick's record
#: (:data:`pipeline.core.tick_record.KEPT_FIELDS`, where a field's codec and ``missing`` value are defined).  A
#: column
#: added later goes at the end, with its ``missing`` value: a block or chunk written before it then reads as the
#: columns before it plus that value.
COLUMNS: tuple[Column, ...] = tuple(Column(f.name, f.name, f.keep or "", f.missing) for f in KEPT_FIELDS)
_KEPT_COLUMNS = COLUMNS
#: Columns a block may lack (written before they were added), with the value each of its records had.
_MISSING = {c.name: c.missing for c in COLUMNS if c.missing is not None}
#: The pose log's columns (one row per pose the framework took, at the robot's 125 Hz).
POSE_COLUMNS: tuple[Column, ...] = (
    Column("tick", "", "int"), Column("pose_t_ns", "", "int"),
    *(Column(f"r{i}", "", "smooth") for i in range(9)),
    Column("x_m", "", "smooth"), Column("y_m", "", "smooth"), Column("z_m", "", "smooth"),
)
#: The device-limit log's columns (one row per change of the haptic device's force limit: while it derates,
#: every tick), kept like the poses rather than as events (a few bytes a change instead of ~40).
LIMIT_COLUMNS: tuple[Column, ...] = (Column("tick", "", "int"), Column("limit_n", "", "smooth"))
_INT_CODECS = ("int", "small")


def kept_records(records: np.ndarray | Mapping[str, np.ndarray]) -> np.ndarray:
    """The kept part of loop records: a structured array of :data:`COLUMNS`' fields, each with the record's type.

    ``records``: rows of :data:`pipeline.core.tick_record.TICK_DTYPE` (the ring's), whose kept fields are one prefix
    of each row's bytes, taken in one copy; rows of the kept type itself, returned as they are; or anything
    else with the columns by name (a structured array, a mapping of columns), copied field by field.

    Raises
    ------
    ValueError
        A column of an integer field holds a value that is not an integer.
    """
    dtype = _kept_dtype()
    if isinstance(records, np.ndarray) and records.dtype == dtype:
        return records
    if isinstance(records, np.ndarray) and records.dtype == TICK_DTYPE and dtype is KEPT_DTYPE:
        return _as_records(np.ascontiguousarray(_record_bytes(np.ascontiguousarray(records), dtype)), dtype)
    n = len(records["tick"])
    out = np.empty(n, dtype)
    for c in COLUMNS:
        values = np.asarray(records[c.name])
        out[c.name] = values
        if c.codec in _INT_CODECS and values.dtype.kind == "f" and not np.array_equal(out[c.name], values):
            raise ValueError(f"recorded column {c.name!r}: holds a value that is not an integer")
    return out


def _kept_dtype() -> np.dtype:
    """The structured type of :data:`COLUMNS` (int64 for the integer codecs, else float64)."""
    if COLUMNS is _KEPT_COLUMNS:
        return KEPT_DTYPE
    # (only where a test stands for a writer from before a column was added)
    return np.dtype([(c.name, "<i8" if c.codec in _INT_CODECS else "<f8") for c in COLUMNS])


def _record_bytes(records: np.ndarray | Mapping[str, np.ndarray], dtype: np.dtype) -> npt.NDArray[np.uint8]:
    """The kept part of records as bytes, one row a record (``dtype.itemsize`` bytes): a view where it can be.

    Loop records (:data:`pipeline.core.tick_record.TICK_DTYPE`) and kept records lay their kept fields out as
    ``dtype`` does, so their bytes are viewed, not converted (NumPy's structured copies cost ~2 µs a record);
    anything else goes through :func:`kept_records`.
    """
    if isinstance(records, np.ndarray) and records.flags.c_contiguous:
        rec = records.dtype
        if rec is dtype or rec == dtype:
            return np.ndarray((len(records), dtype.itemsize), np.uint8, records)
        if dtype is KEPT_DTYPE and (rec is TICK_DTYPE or rec == TICK_DTYPE):
            return np.ndarray((len(records), rec.itemsize), np.uint8, records)[:, : dtype.itemsize]
    recs = kept_records(records)
    return np.ndarray((len(recs), dtype.itemsize), np.uint8, recs)


def _as_records(raw: npt.NDArray[np.uint8], dtype: np.dtype) -> np.ndarray:
    """Contiguous record bytes (one row a record) seen as records of ``dtype``."""
    return np.ndarray((len(raw),), dtype, raw)


# -- codecs ----------------------------------------------------------------------------------------
def _shuffle(a: np.ndarray) -> bytes:
    """Byte planes: all first bytes, then all second bytes, ... (what deflate finds repetitive)."""
    b = np.ascontiguousarray(a).view(np.uint8).reshape(-1, a.dtype.itemsize)
    return np.ascontiguousarray(b.T).tobytes()


def _unshuffle(data: bytes, dtype: np.dtype, n: int) -> np.ndarray:
    size = np.dtype(dtype).itemsize
    return np.ascontiguousarray(np.frombuffer(data, np.uint8).reshape(size, n).T).view(dtype).reshape(n)


def _delta(a: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
    d = np.empty_like(a)
    if len(a):
        d[0] = a[0]
        np.subtract(a[1:], a[:-1], out=d[1:])  # wraps like the int64 arithmetic that undoes it
    return d


def _encode(values: np.ndarray, codec: str, scale: float | None) -> tuple[dict[str, Any], bytes]:
    """One column: (its header entry, its compressed bytes); lossless by construction or by check."""
    n = len(values)
    if codec == "counts" and scale is not None:
        with np.errstate(invalid="ignore", over="ignore"):
            counts = np.rint(values * scale)
        if np.all(np.isfinite(counts)) and np.all(np.abs(counts) < 2.0**62):
            ints = counts.astype(np.int64)
            back = ints / scale
            if np.array_equal(back.view(np.int64), np.asarray(values, dtype=np.float64).view(np.int64)):
                return {"codec": "counts", "scale": scale}, zlib.compress(_shuffle(ints), _LEVEL)
        codec = "float"  # not exactly counts (NaN, -0.0, another unit): keep the float64 as it is
    if codec == "counts":
        codec = "float"
    if codec == "int":
        return {"codec": "int"}, zlib.compress(_shuffle(_delta(values.astype(np.int64))), _LEVEL)
    if codec == "small":
        v = values.astype(np.int64)
        if n and (v.min() < -(2**31) or v.max() >= 2**31):
            return {"codec": "int"}, zlib.compress(_shuffle(_delta(v)), _LEVEL)
        return {"codec": "small"}, zlib.compress(v.astype(np.int32).tobytes(), _LEVEL)
    f = np.ascontiguousarray(values, dtype=np.float64)
    if codec == "smooth":
        return {"codec": "smooth"}, zlib.compress(_shuffle(_delta(f.view(np.int64))), _LEVEL)
    return {"codec": "float"}, zlib.compress(_shuffle(f), _LEVEL)


def _decode(entry: Mapping[str, Any], data: bytes, n: int) -> np.ndarray:
    raw = zlib.decompress(data)
    codec = entry["codec"]
    if codec == "small":
        return np.frombuffer(raw, np.int32).astype(np.int64)
    if codec == "int":
        return np.cumsum(_unshuffle(raw, np.dtype(np.int64), n), dtype=np.int64)
    if codec == "smooth":
        return np.cumsum(_unshuffle(raw, np.dtype(np.int64), n), dtype=np.int64).view(np.float64)
    if codec == "counts":
        return _unshuffle(raw, np.dtype(np.int64), n) / float(entry["scale"])
    return _unshuffle(raw, np.dtype(np.float64), n).copy()


def encode_block(
    columns: np.ndarray | Mapping[str, np.ndarray], poses: Mapping[str, np.ndarray],
    events: Sequence[tuple[int, str, Any]], scales: Mapping[str, float] | None = None,
) -> bytes:
    """A block: the records' columns (:data:`COLUMNS`), the poses taken meanwhile, the other log entries.

    ``columns``: the kept records (:func:`kept_records`; each column is read from them where it lies) or the
    columns by name.

    ``scales``: counts per unit of the raw wrench columns (``raw_fx`` … ``raw_tz``), when known.
    The log's ``"device_limit"`` entries are kept as columns (:data:`LIMIT_COLUMNS`, only in a block
    that has any); :func:`decode_block` returns them among the events again.
    """
    n = len(columns["tick"])
    m = len(poses["tick"]) if poses else 0
    limits = [e for e in events if e[1] == "device_limit"]
    if limits:
        events = [e for e in events if e[1] != "device_limit"]
    header: dict[str, Any] = {"n": n, "m": m, "columns": [], "poses": [], "events": [list(e) for e in events]}
    sections = [(COLUMNS, columns, "columns", n), (POSE_COLUMNS, poses, "poses", m)]
    if limits:
        header["k"] = len(limits)
        header["limits"] = []
        sections.append((LIMIT_COLUMNS, {"tick": np.array([e[0] for e in limits], dtype=np.int64),
                                         "limit_n": np.array([e[2] for e in limits], dtype=np.float64)},
                         "limits", len(limits)))
    parts: list[bytes] = []
    scales = scales or {}
    for specs, data, key, count in sections:
        # kept records and columns of the codecs' own types go as one table (~4x fewer NumPy calls); anything else
        # column by column: the same bytes either way
        coded = encode_table(data, [c.name for c in specs], [c.codec for c in specs], scales, _LEVEL) if count else None
        if coded is None:
            coded = [_encode(np.asarray(data[c.name]) if count else np.empty(0), c.codec, scales.get(c.name))
                     for c in specs]
        for c, (entry, payload) in zip(specs, coded, strict=True):
            entry.update(name=c.name, bytes=len(payload))
            header[key].append(entry)
            parts.append(payload)
    head = json.dumps(header, separators=(",", ":")).encode()
    return _MAGIC + struct.pack("<I", len(head)) + head + b"".join(parts)


def decode_block(blob: bytes) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], list[tuple[int, str, Any]]]:
    """The inverse of :func:`encode_block`: (columns, poses, events).

    Raises
    ------
    ValueError
        Not a block this code wrote.
    """
    if blob[:4] == _CHUNKED:
        return join_blocks(_chunks(blob))
    if blob[:4] == _RAW:
        return _decode_raw(blob, None)
    if blob[:4] == _FAST:
        return _decode_fast(blob, None)
    if blob[:4] != _MAGIC:
        raise ValueError("not a recorded block (bad magic)")
    (hlen,) = struct.unpack_from("<I", blob, 4)
    header = json.loads(blob[8 : 8 + hlen])
    pos = 8 + hlen
    out: list[dict[str, np.ndarray]] = [{}, {}, {}]
    for key, count, target in (("columns", header["n"], out[0]), ("poses", header["m"], out[1]),
                               ("limits", header.get("k", 0), out[2])):
        for entry in header.get(key, ()):
            size = entry["bytes"]
            target[entry["name"]] = _decode(entry, blob[pos : pos + size], count)
            pos += size
    _fill_missing(out[0], _MISSING.keys(), header["n"])
    events = [(int(t), str(k), p) for t, k, p in header["events"]]
    if out[2]:
        # back among the events, after a tick's others (a stable sort; the device limit commutes with them)
        events += [(t, "device_limit", v)
                   for t, v in zip(out[2]["tick"].tolist(), out[2]["limit_n"].tolist(), strict=True)]
        events.sort(key=lambda e: e[0])
    return out[0], out[1], events


#: A pose's bytes in a chunk: :data:`POSE_COLUMNS`, 8 bytes each (kept as a table of the two integers, then one of
#: the twelve floats).
_POSE_DTYPE = np.dtype([(c.name, "<i8" if c.codec == "int" else "<f8") for c in POSE_COLUMNS])


def _decode_raw(blob: bytes, names: Iterable[str] | None,
                ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], list[tuple[int, str, Any]]]:
    """The inverse of :func:`_encode_raw` (with ``names``: only those columns of the records)."""
    (hlen,) = struct.unpack_from("<I", blob, 4)
    header = json.loads(blob[8 : 8 + hlen])
    n, m = int(header["n"]), int(header["m"])
    dtype = np.dtype([(str(name), str(t)) for name, t in header["fields"]])
    size = dtype.itemsize
    data = np.frombuffer(blob, np.uint8, offset=8 + hlen)
    flags = (size + 7) // 8
    same = np.unpackbits(data[:flags])[:size].astype(bool)
    changing = int(size - same.sum())
    if len(data) != flags + size + changing * n + m * _POSE_DTYPE.itemsize:
        raise ValueError(f"a chunk of {len(blob)} bytes where its header says {n} records and {m} poses")
    planes = np.empty((size, n), np.uint8)
    planes[:] = data[flags : flags + size, None]
    planes[~same] = data[flags + size : flags + size + changing * n].reshape(changing, n)
    recs = np.ascontiguousarray(planes.T).view(dtype).reshape(n)
    at = len(blob) - m * _POSE_DTYPE.itemsize
    ints = np.frombuffer(blob, np.int64, 2 * m, at).reshape(m, 2)
    floats = np.frombuffer(blob, np.float64, 12 * m, at + 16 * m).reshape(m, 12)
    known = [c.name for c in COLUMNS if c.name in (dtype.names or ())]  # (a newer writer's extra fields: not ours)
    cols = {name: recs[name].copy() for name in (known if names is None else [k for k in names if k in known])}
    _fill_missing(cols, [k for k in (_MISSING.keys() if names is None else names) if k in _MISSING], n)
    poses = {"tick": ints[:, 0].copy(), "pose_t_ns": ints[:, 1].copy(),
             **{c.name: floats[:, i].copy() for i, c in enumerate(POSE_COLUMNS[2:])}}
    return cols, poses, [(int(t), str(k), p) for t, k, p in header["events"]]


def _unstack8(raw: bytes, dtypes: Sequence[str], n: int) -> list[np.ndarray]:
    if n == 0:
        return [np.empty(0, np.dtype(d)) for d in dtypes]
    table = np.ascontiguousarray(np.frombuffer(raw, np.uint8).reshape(-1, n).T).view(np.int64)
    return [np.ascontiguousarray(table[:, j]).view(np.dtype(d)) for j, d in enumerate(dtypes)]


def _decode_fast(blob: bytes, names: Iterable[str] | None,
                 ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], list[tuple[int, str, Any]]]:
    """A chunk as the writers before ``session_chunks`` kept it (every column's bytes shuffled into one deflate
    stream): databases of that time hold one for every session killed mid-block."""
    (hlen,) = struct.unpack_from("<I", blob, 4)
    header = json.loads(blob[8 : 8 + hlen])
    raw = zlib.decompress(blob[8 + hlen :])
    n, m, dtypes = header["n"], header["m"], header["dtypes"]
    k = len(dtypes) - len(POSE_COLUMNS)  # the columns of the code that wrote it: a prefix of ours (appended since)
    split = n * 8 * k
    cols = dict(zip((c.name for c in COLUMNS[:k]), _unstack8(raw[:split], dtypes[:k], n), strict=True))
    poses = dict(zip((c.name for c in POSE_COLUMNS), _unstack8(raw[split:], dtypes[k:], m), strict=True))
    _fill_missing(cols, _MISSING.keys(), n)
    if names is not None:
        cols = {k: v for k, v in cols.items() if k in set(names)}
    return cols, poses, [(int(t), str(k), p) for t, k, p in header["events"]]


def join_chunks(chunks: Iterable[bytes]) -> bytes:
    """An open block's chunks as one blob (read as the block so far: :func:`decode_block`, :func:`decode_columns`)."""
    return _CHUNKED + b"".join(struct.pack("<I", len(c)) + c for c in chunks)


def _chunks(blob: bytes) -> list[bytes]:
    """The chunks of an open block's blob, in order."""
    out, pos = [], 4
    while pos < len(blob):
        (size,) = struct.unpack_from("<I", blob, pos)
        out.append(blob[pos + 4 : pos + 4 + size])
        pos += 4 + size
    return out


@dataclass(frozen=True, slots=True)
class BlockRow:
    """One ``session_blocks`` row as read (:meth:`protocol.storage.StudyReader.blocks`; ``crc32`` None: written
    before schema version 4, not verifiable).  ``bound``: its checksum covers its place too (``arm`` -- "" for the
    task arm --, session, run, block, ticks, records: :func:`protocol.recording.integrity.place_crc32`), as every
    block of a run recorded since the runs count their blocks."""

    session_id: int
    segment: int
    block: int
    first_tick: int
    last_tick: int
    n_records: int
    t_first_s: float
    t_last_s: float
    data: bytes
    crc32: int | None
    arm: str = ""
    bound: bool = False


def _pose_columns(poses: Sequence[tuple[int, tuple[float, ...], tuple[float, ...], int]]) -> dict[str, np.ndarray]:
    """The poses as :data:`POSE_COLUMNS` (two arrays, one of ints and one of floats, seen column by column)."""
    ints = np.array([(p[0], p[3]) for p in poses], dtype=np.int64).reshape(-1, 2)
    floats = np.array([(*p[1], *p[2]) for p in poses], dtype=np.float64).reshape(-1, 12)
    out: dict[str, np.ndarray] = {"tick": ints[:, 0], "pose_t_ns": ints[:, 1]}
    for i in range(9):
        out[f"r{i}"] = floats[:, i]
    for i, axis in enumerate("xyz"):
        out[f"{axis}_m"] = floats[:, 9 + i]
    return out


def join_blocks(
    blobs: Iterable[bytes],
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], list[tuple[int, str, Any]]]:
    """Decode and concatenate a segment's blocks, in order."""
    return join_decoded(decode_block(blob) for blob in blobs)


def join_decoded(decoded: Iterable[tuple[dict[str, np.ndarray], dict[str, np.ndarray], list[tuple[int, str, Any]]]],
                 ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], list[tuple[int, str, Any]]]:
    """Concatenate decoded blocks (:func:`decode_block`'s output), in order."""
    cols: list[dict[str, np.ndarray]] = []
    poses: list[dict[str, np.ndarray]] = []
    events: list[tuple[int, str, Any]] = []
    for c, p, e in decoded:
        cols.append(c)
        poses.append(p)
        events.extend(e)
    if not cols:
        empty = _kept_dtype()
        return ({c.name: np.empty(0, empty[c.name]) for c in COLUMNS}, _pose_columns([]), [])
    return ({k: np.concatenate([c[k] for c in cols]) for k in cols[0]},
            {k: np.concatenate([p[k] for p in poses]) for k in poses[0]}, events)


# -- reading ------------------------------------------------------------------------------------------
def _fill_missing(columns: dict[str, np.ndarray], names: Iterable[str], n: int) -> None:
    """Columns a block written before they were added lacks: every record's value then (:attr:`Column.missing`)."""
    for name in names:
        if name not in columns:
            columns[name] = np.full(n, _MISSING[name], dtype=np.float64)


def decode_columns(blob: bytes, names: Iterable[str]) -> dict[str, np.ndarray]:
    """Only some columns of a block (the others are skipped, not decompressed)."""
    names = list(names)
    if blob[:4] == _CHUNKED:
        parts = [decode_columns(c, names) for c in _chunks(blob)]
        return {k: np.concatenate([p[k] for p in parts]) for k in names}
    if blob[:4] in (_RAW, _FAST):
        got = (_decode_raw if blob[:4] == _RAW else _decode_fast)(blob, names)[0]
        if set(names) - got.keys():
            raise ValueError(f"the block has no column {sorted(set(names) - got.keys())[0]!r}")
        return got
    if blob[:4] != _MAGIC:
        raise ValueError("not a recorded block (bad magic)")
    (hlen,) = struct.unpack_from("<I", blob, 4)
    header = json.loads(blob[8 : 8 + hlen])
    wanted = set(names)
    pos = 8 + hlen
    out: dict[str, np.ndarray] = {}
    for entry in header["columns"]:
        size = entry["bytes"]
        if entry["name"] in wanted:
            out[entry["name"]] = _decode(entry, blob[pos : pos + size], header["n"])
        pos += size
    _fill_missing(out, wanted & _MISSING.keys(), header["n"])
    missing = wanted - out.keys()
    if missing:
        raise ValueError(f"the block has no column {sorted(missing)[0]!r}")
    return out
