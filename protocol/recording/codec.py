"""The recording's codec: what a block keeps of each record, and how, losslessly; the open block as it grows.

Every decoding is checked bit for bit before a block is written, so a value
the codec cannot keep exactly is stored as plain float64 instead: nothing is
ever rounded.
"""

from __future__ import annotations

import functools
import json
import struct
import zlib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from pipeline.core.tick_record import KEPT_DTYPE, KEPT_FIELDS, TICK_DTYPE
from protocol.recording.table_encode import encode_table

__all__ = [
    "BLOCK_RECORDS", "COLUMNS", "LIMIT_COLUMNS", "POSE_COLUMNS", "BlockBuilder", "BlockRow", "Chunk", "Column",
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


@functools.lru_cache(maxsize=8)
def _fields_json(dtype: np.dtype) -> str:
    """A record type's fields as a chunk's header lists them (``[[name, type], ...]``; made once per type)."""
    return json.dumps([[name, dtype[name].str] for name in dtype.names or ()], separators=(",", ":"))


#: A pose's bytes in a chunk: :data:`POSE_COLUMNS`, 8 bytes each (kept as a table of the two integers, then one of
#: the twelve floats).
_POSE_DTYPE = np.dtype([(c.name, "<i8" if c.codec == "int" else "<f8") for c in POSE_COLUMNS])


def _encode_raw(raw: npt.NDArray[np.uint8], dtype: np.dtype,
                poses: Sequence[tuple[int, tuple[float, ...], tuple[float, ...], int]],
                events: Sequence[tuple[int, str, Any]]) -> bytes:
    """A chunk of an open block: the records (``raw``, one row a record of ``dtype``), the poses and the other log
    entries.

    A chunk lives until its block fills (about a second), then the block replaces it, so it is made for speed:
    the records' bytes are taken plane by plane (every record's first byte, then every second byte, …) and a
    plane whose bytes are all equal -- the high bytes of times and counters, the marks, an exponent that
    does not change -- is kept as one byte.  That keeps ~75 bytes of a record's 200 for ~0.4 µs, where deflate
    at its fastest level keeps ~67 for ~2 µs, and a commit's cost is mostly the bytes it writes.  The poses
    (~12 a chunk) are kept as they are (their integers, then their floats).  Lossless by construction.
    """
    n, size = raw.shape
    # which planes are one byte, found on the records as they lie; then only the other planes transposed (NumPy
    # moves bytes one at a time: a third of them, ~2.5x faster than the whole table and picking after)
    same = (raw == raw[0]).all(axis=0) if n else np.ones(size, bool)
    firsts = raw[0] if n else np.zeros(size, np.uint8)
    changing = np.ascontiguousarray(raw[:, ~same].T)  # (changing planes, n)
    # the poses as two tables (tick and time; rotation and position): NumPy makes plain arrays from tuples ~5x
    # faster than structured ones
    ints = np.array([(p[0], p[3]) for p in poses], np.int64)
    floats = np.array([(*p[1], *p[2]) for p in poses], np.float64)
    log = json.dumps([list(e) for e in events], separators=(",", ":")) if events else "[]"
    head = f'{{"n":{n},"m":{len(poses)},"fields":{_fields_json(dtype)},"events":{log}}}'.encode()
    return b"".join((_RAW, struct.pack("<I", len(head)), head, np.packbits(same).tobytes(), firsts.tobytes(),
                     changing.tobytes(), ints.tobytes(), floats.tobytes()))


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


# -- building blocks as records arrive --------------------------------------------------------------
class Chunk(NamedTuple):
    """What an open block gained since the last commit (:meth:`BlockBuilder.partial`): a ``session_chunks`` row."""

    block: int  # the open block's number
    number: int  # 0, 1, … within the block, in the order written
    records: np.ndarray  # its kept records (a view, valid until the builder's next add or cut)
    data: bytes  # :func:`_encode_raw`'s bytes


@dataclass(frozen=True, slots=True)
class BlockRow:
    """One ``session_blocks`` row as read (:meth:`protocol.storage.StudyReader.blocks`; ``crc32`` None: written
    before schema version 4, not verifiable)."""

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


@dataclass
class BlockBuilder:
    """The open block of one segment: records and log entries appended as they come, encoded on demand.

    ``take_full()`` returns the blocks that are complete (written once); ``partial()`` what the open block
    gained since it was last asked (a chunk, written beside the ones before it until the block fills).
    """

    scales: Mapping[str, float] = field(default_factory=dict)
    first_block: int = 0
    # the open block's kept records as bytes, one row a record (the first _n rows; room for more after them):
    # NumPy copies bytes ~5x faster than it assigns structured rows
    _raw: npt.NDArray[np.uint8] | None = None
    _dtype: np.dtype | None = None
    _n: int = 0
    _poses: list[tuple[int, tuple[float, ...], tuple[float, ...], int]] = field(default_factory=list)
    _events: list[tuple[int, str, Any]] = field(default_factory=list)
    block: int = 0  # number of the open block
    records_before: int = 0  # records in the blocks already full
    dirty: bool = False  # something the open block's last write lacks
    # the open block's chunks so far: how many, the records and the last tick they hold
    _chunk: int = 0
    _chunked_n: int = 0
    _chunked_tick: int = -(2**63)

    def __post_init__(self) -> None:
        self.block = self.first_block

    def add(self, records: np.ndarray | Mapping[str, np.ndarray], log: Iterable[tuple[int, str, Any]] = ()) -> None:
        """Append records (loop records or their kept part, :func:`kept_records`) and the log entries of their ticks."""
        dtype = self._dtype = self._dtype or _kept_dtype()
        raw = _record_bytes(records, dtype)
        n = len(raw)
        if n:
            have = self._n
            buf = self._raw
            if buf is None or have + n > len(buf):
                grown = np.empty((max(2 * (have + n), BLOCK_RECORDS + n), dtype.itemsize), np.uint8)
                if buf is not None:
                    grown[:have] = buf[:have]
                self._raw = buf = grown
            buf[have : have + n] = raw
            self._n = have + n
            self.dirty = True
        for tick, kind, payload in log:
            if kind == "pose":
                rot, pos, t_ns = payload
                self._poses.append((int(tick), tuple(rot), tuple(pos), int(t_ns)))
            else:
                self._events.append((int(tick), kind, payload))
            self.dirty = True

    def _merged(self) -> np.ndarray:
        """The open block's records (a view: valid until the next :meth:`add` or cut)."""
        if self._raw is None or self._dtype is None:
            return np.empty(0, _kept_dtype())
        return _as_records(self._raw[: self._n], self._dtype)

    def take_full(self) -> list[tuple[int, int, np.ndarray, bytes]]:
        """Complete blocks, cut off the open one: (block number, first record, kept records, encoded) each."""
        out = []
        while self._n >= BLOCK_RECORDS:
            raw, dtype, n = self._raw, self._dtype, BLOCK_RECORDS
            assert raw is not None and dtype is not None  # (n ≤ _n records were added)
            records = np.ndarray((n,), dtype, raw[:n].copy())  # (the bytes seen as records)
            rest = self._n - n
            if rest:
                raw[:rest] = raw[n : self._n].copy()  # (overlapping: through a copy)
            self._n = rest
            # the log entries of the block's ticks go with it, the later ones stay open
            last_tick = int(records["tick"][-1])
            poses = [p for p in self._poses if p[0] <= last_tick]
            self._poses = [p for p in self._poses if p[0] > last_tick]
            events = [e for e in self._events if e[0] <= last_tick]
            self._events = [e for e in self._events if e[0] > last_tick]
            self._chunk, self._chunked_n, self._chunked_tick = 0, 0, -(2**63)  # the next block starts unwritten
            out.append((self.block, self.records_before, records,
                        encode_block(records, _pose_columns(poses), events, self.scales)))
            self.block += 1
            self.records_before += BLOCK_RECORDS
        return out

    def final(self) -> tuple[int, int, np.ndarray, bytes] | None:
        """The open block, encoded whole as a full block is, when its segment ends (None when it is empty).

        Its chunks (:meth:`partial`) depend on when the commits fell; the final encoding does not, so a
        recording's bytes depend only on its records and log, however the writer's commits were timed.
        Log entries after the last record go with it.
        """
        if self._n == 0:
            return None
        cols = self._merged()
        block = (self.block, self.records_before, cols,
                 encode_block(cols, _pose_columns(self._poses), list(self._events), self.scales))
        self.dirty = False
        return block

    def partial(self) -> Chunk | None:
        """What the open block gained since the last call (None: nothing, or only log entries of later ticks,
        which go with the records of their ticks).

        Only those records are encoded, as they lie (:func:`_encode_raw`): a commit costs what it adds, not
        what the block holds.  The full block replaces the chunks, encoded column by column, once it fills
        (:meth:`take_full`) or its segment ends (:meth:`final`); until then the chunks are the block.
        """
        if self._n == 0 or not self.dirty:
            return None
        self.dirty = False
        if self._n == self._chunked_n or self._raw is None or self._dtype is None:
            return None
        raw = self._raw[self._chunked_n : self._n]
        new = _as_records(raw, self._dtype)
        lo, hi = self._chunked_tick, int(new["tick"][-1])
        poses = [p for p in self._poses if lo < p[0] <= hi]
        events = [e for e in self._events if lo < e[0] <= hi]
        chunk = Chunk(self.block, self._chunk, new, _encode_raw(raw, self._dtype, poses, events))
        self._chunk, self._chunked_n, self._chunked_tick = self._chunk + 1, self._n, hi
        return chunk


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
