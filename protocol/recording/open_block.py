"""The open block as it grows: records and log entries appended as they come, written at each commit as a chunk.

A segment's records are cut into blocks of :data:`protocol.recording.codec.BLOCK_RECORDS`; until its block fills,
the writer keeps what it gained since the last commit as a *chunk* (a ``session_chunks`` row: the records' own
bytes, made for speed, :func:`_encode_raw`), and once it fills, or its segment ends, encodes the whole block
(:func:`protocol.recording.codec.encode_block`), which replaces its chunks.  The chunks are read back by the codec
(:func:`protocol.recording.codec.decode_block`), with the block format they are part of.
"""

from __future__ import annotations

import functools
import json
import struct
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from protocol.recording.codec import (
    _RAW,
    BLOCK_RECORDS,
    _as_records,
    _kept_dtype,
    _pose_columns,
    _record_bytes,
    encode_block,
)

__all__ = ["BlockBuilder", "Chunk"]


@functools.lru_cache(maxsize=8)
def _fields_json(dtype: np.dtype) -> str:
    """A record type's fields as a chunk's header lists them (``[[name, type], ...]``; made once per type)."""
    return json.dumps([[name, dtype[name].str] for name in dtype.names or ()], separators=(",", ":"))


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


# -- building blocks as records arrive --------------------------------------------------------------
class Chunk(NamedTuple):
    """What an open block gained since the last commit (:meth:`BlockBuilder.partial`): a ``session_chunks`` row."""

    block: int  # the open block's number
    number: int  # 0, 1, … within the block, in the order written
    records: np.ndarray  # its kept records (a view, valid until the builder's next add or cut)
    data: bytes  # :func:`_encode_raw`'s bytes


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
