"""A preallocated ring buffer of loop records that other processes read without blocking the writer.

One writer (the 1 kHz loop) appends fixed-size records of 8-byte fields (``int64`` or ``float64``; the
loop's are :data:`pipeline.core.tick_record.TICK_DTYPE`);
any number of readers, in this or another process, copy what is new.  No
lock is shared: the writer stores the record first and only then publishes
it by bumping the 64-bit write counter; a reader copies a range and then
re-reads the counter to discard any rows the writer overwrote meanwhile
(they are reported as lost, never returned torn).  The counter itself is
one aligned 8-byte word, stored and loaded in one instruction (a numpy
int64 cell): read byte by byte, as ``struct`` does, a reader in another
process could see it half-written -- a count from the past -- and return
old rows again as new.  On x86-64, stores are not reordered with stores nor
loads with loads, so a counter seen means its rows are complete.  The slot the writer fills
next -- the oldest record's -- is never read: the writer may be half-way
through it before the counter says so, so a ring of ``capacity`` slots
serves the newest ``capacity - 1`` records.

Layout of the shared block (little-endian)::

    0   8s  magic b"HSRING02"
    8   u32 number of fields      12  u32 reserved
    16  u64 capacity (records)    24  u64 write counter (records ever written)
    32  4064 bytes: the fields as ``name:i8`` or ``name:f8``, comma-separated, NUL-padded
    4096 ... capacity × n_fields 8-byte values (each record a row of the structured type)

The names and types travel with the data, so a reader that attaches by name
knows the columns and reads them with their own types.  The GUI runs in its
own process because a same-process Qt paint holds the GIL for milliseconds and
breaks the 1 kHz loop (science.md §7).
"""

from __future__ import annotations

import struct
import sys
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from foundation.platform_support.shared_memory import attach_segment, create_segment, free_orphaned_segment

if TYPE_CHECKING:
    from foundation.platform_support.shared_memory import SharedSegment

__all__ = ["RingBuffer", "RingReadResult"]

_MAGIC = b"HSRING02"
_CODES = {"i8": ("<i8", "q"), "f8": ("<f8", "d")}  # a field's type in the header: its NumPy type, its struct code
_HEADER = 4096
_NAMES_OFF = 32


class RingReadResult:
    """Rows copied out of the ring: ``rows`` (structured array), next ``cursor``, and ``lost`` rows."""

    __slots__ = ("cursor", "lost", "rows")

    def __init__(self, rows: npt.NDArray[np.void], cursor: int, lost: int) -> None:
        self.rows = rows
        self.cursor = cursor
        self.lost = lost


def _header_fields(fields: Sequence[str] | np.dtype) -> tuple[bytes, tuple[str, ...]]:
    """The header's field list for a ring of ``fields`` (a structured type, or names: all float64), and the names.

    Raises
    ------
    ValueError
        A type other than packed little-endian int64/float64 fields, or names empty, repeated, holding
        ``,`` or ``:``, or too long for the header.
    """
    if isinstance(fields, np.dtype):
        names = tuple(fields.names or ())
        types = [fields.fields[n][0].str for n in names]  # type: ignore[index]  # fields is None only for an unstructured dtype, which has no names
        if any(t not in ("<i8", "<f8") for t in types) or fields.itemsize != 8 * len(names):
            raise ValueError("ring fields must be packed int64 or float64 (little-endian)")
    else:
        names, types = tuple(fields), ["<f8"] * len(fields)
    header = ",".join(f"{n}:{t[1:]}" for n, t in zip(names, types, strict=True)).encode("ascii")
    if (not names or any(not n or "," in n or ":" in n for n in names) or len(set(names)) != len(names)
            or len(header) > _HEADER - _NAMES_OFF):
        raise ValueError("field names must be non-empty, unique, free of ',' and ':' and fit in 4064 bytes")
    return header, names


class RingBuffer:
    """Shared-memory (or private) ring of fixed-layout records (``int64`` and ``float64`` fields).

    Use :meth:`create` in the writing process and :meth:`attach` in readers.
    """

    def __init__(
        self,
        buf: memoryview,
        shm: SharedSegment | None,
        owner: bool,
    ) -> None:
        if bytes(buf[:8]) != _MAGIC:
            raise ValueError("not a haptic-study ring buffer (bad magic)")
        n_fields, _ = struct.unpack_from("<II", buf, 8)
        capacity, _ = struct.unpack_from("<QQ", buf, 16)
        fields = [f.rpartition(":") for f in bytes(buf[_NAMES_OFF:_HEADER]).rstrip(b"\0").decode("ascii").split(",")]
        if len(fields) != n_fields or any(t not in _CODES for _, _, t in fields):
            raise ValueError("corrupt ring header: the fields do not match their count or have no known type")
        names = [n for n, _, _ in fields]
        self._buf = buf
        self._shm = shm
        self._release: Callable[[], None] | None = None  # an attached segment's unmapping
        self._owner = owner
        self._attached_name: str | None = None
        self._cap: Callable[[], int] | None = None  # this reader's limit (see cap())
        self.fields: tuple[str, ...] = tuple(names)
        self.capacity: int = int(capacity)
        self._row_bytes = 8 * n_fields
        # one struct call packs a record: an int64 field takes an int (a float there raises, never truncates).
        # On a little-endian machine in its native order ("@"): the same bytes as "<" here (8-byte fields, no
        # padding: checked), through struct's native packers, and into a new bytes object copied into the slot --
        # 0.31 µs a 50-field record against 0.59 µs for "<" with pack_into (timeit, this VM)
        codes = "".join(_CODES[t][1] for _, _, t in fields)
        row = struct.Struct(("@" if sys.byteorder == "little" else "<") + codes)
        if row.size != 8 * n_fields:  # pragma: no cover - every platform the product runs on packs q and d in 8 bytes
            row = struct.Struct("<" + codes)
        self._pack_row = row.pack
        # the write counter as one aligned int64 word (offset 24): stored and loaded whole, never torn
        self._count_cell = np.ndarray((1,), dtype=np.int64, buffer=buf, offset=24)
        self._count = int(self._count_cell[0])
        # the next slot's byte offset, advanced by one row per write and wrapped at the end: no modulo and
        # product per record (measured with the loop's whole tick, see write)
        self._slot_off = _HEADER + (self._count % self.capacity) * self._row_bytes
        self._end_off = _HEADER + self.capacity * self._row_bytes
        self.dtype = np.dtype([(n, _CODES[t][0]) for n, _, t in fields])
        self._rows = np.ndarray((self.capacity,), dtype=self.dtype, buffer=buf, offset=_HEADER)

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def create(cls, fields: Sequence[str] | np.dtype, capacity: int, *, shared: bool = True) -> RingBuffer:
        """Allocate a ring for ``capacity`` records of ``fields``.

        ``fields``: a structured type of ``int64`` and ``float64`` fields (the loop's
        :data:`pipeline.core.tick_record.TICK_DTYPE`), or names (all ``float64``).
        ``shared=False`` keeps it in private memory (headless runs and tests
        that need no second process).
        """
        if capacity < 2:
            raise ValueError(f"capacity = {capacity}: must be at least 2 records")
        header, fields = _header_fields(fields)  # checked before the segment exists: a failure must not leak one
        size = _HEADER + 8 * len(fields) * capacity
        shm: SharedSegment | None
        if shared:
            shm = create_segment(size)
            assert shm.buf is not None  # None only once closed
            buf = shm.buf
        else:
            shm = None
            buf = memoryview(bytearray(size))
        buf[: len(_MAGIC)] = _MAGIC
        struct.pack_into("<IIQQ", buf, 8, len(fields), 0, capacity, 0)
        buf[_NAMES_OFF : _NAMES_OFF + len(header)] = header
        return cls(buf, shm, owner=True)

    @classmethod
    def attach(cls, name: str) -> RingBuffer:
        """Attach to a ring created by another process (read side)."""
        attached = attach_segment(name)  # mapped directly: see platform_support.attach_segment
        if attached is None:
            raise FileNotFoundError(f"no ring buffer named {name!r} (is the engine running?)")
        buf, release = attached
        ring = cls(buf, None, owner=False)
        ring._release = release
        ring._attached_name = name
        return ring

    @staticmethod
    def free_orphaned(name: str) -> bool:
        """Unlink the segment of a ring whose creator died without freeing it (killed by a signal); True if freed.

        A writer that exits normally unlinks its own segment (:meth:`close`).  One
        killed leaves it until the resource tracker of the process tree frees it at
        exit, with a warning; the reader that knows the writer is dead frees it at
        once and tells the tracker so.  Call it only for a ring whose writer is known
        to be dead: it removes nothing but the segment of that name.
        """
        return free_orphaned_segment(name)

    @property
    def name(self) -> str | None:
        """Shared-memory name for :meth:`attach` (None for a private ring, and for a reader: only the creator names,
        and frees, the segment)."""
        return self._shm.name if self._shm is not None and self._owner else None

    @property
    def segment(self) -> str:
        """The shared-memory segment's name, the creator's or the reader's ("" for a private ring): what another
        reader attaches by."""
        return self._attached_name or self.name or ""

    def cap(self, limit: Callable[[], int] | None) -> None:
        """:meth:`read_since` through this object returns no record at or after ``limit()`` (a write count); None: no
        limit.

        For a reader in another process than the writer that must not take a record before something the writer
        sends beside it (:mod:`pipeline.runtime.loop_link`: a tick's events and replay log).  :attr:`write_count`
        and :meth:`latest` are not capped (the newest record's state, a cursor moved past everything so far), nor
        are the writer and other readers.
        """
        self._cap = limit

    # -- writer ---------------------------------------------------------------------------------
    def write(self, values: Sequence[float]) -> None:
        """Append one record (exactly ``len(fields)`` numbers, an int for an ``int64`` field). Never blocks."""
        self.write_row(self._pack_row(*values))

    def write_row(self, row: bytes | memoryview) -> None:
        """Append one record given as its bytes (a record of this ring's fields, packed as they lie: :meth:`write`'s,
        or the row the loop's :func:`pipeline.runtime.arm_channel.record_kernel` writes). Never blocks."""
        off = self._slot_off
        end = off + self._row_bytes
        self._buf[off:end] = row
        self._slot_off = end if end < self._end_off else _HEADER
        c = self._count + 1
        self._count = c
        # publish after the row is complete
        self._count_cell[0] = c

    def write_rows(self, rows: npt.NDArray[np.float64]) -> None:
        """Append records given as the rows of a C-contiguous 2-D float64 array in this ring's layout (an int64
        field's bits in its float64 place: one row as :meth:`write_row` takes it), all published at once.

        For a private ring only (no reader in another process or thread): a reader copying the oldest records while
        they are overwritten could not tell, as it can for one record at a time.
        """
        if self._shm is not None:
            raise ValueError("write_rows: the ring is shared; write one record at a time (write_row)")
        rb = self._row_bytes
        if rows.ndim != 2 or rows.shape[1] * rows.itemsize != rb or not rows.flags.c_contiguous:
            raise ValueError(f"write_rows: a C-contiguous 2-D array of rows of {rb} bytes; given {rows.shape} "
                             f"of {rows.itemsize}-byte values")
        data = memoryview(rows.data).cast("B")
        off, start = self._slot_off, 0
        while start < len(data):
            m = min(len(data) - start, self._end_off - off)
            self._buf[off:off + m] = data[start:start + m]
            start += m
            off += m
            if off >= self._end_off:
                off = _HEADER
        self._slot_off = off
        c = self._count + len(data) // rb
        self._count = c
        self._count_cell[0] = c  # publish after the rows are complete

    # -- readers --------------------------------------------------------------------------------
    @property
    def write_count(self) -> int:
        """Records written since creation."""
        return int(self._count_cell[0])

    def read_since(self, cursor: int) -> RingReadResult:
        """Copy every record written at or after ``cursor`` that is still in the ring.

        Returns the rows, the cursor to pass next time, and how many records
        since ``cursor`` were overwritten before they could be read.  A record
        is returned only if the writer cannot have touched its slot during the
        copy (see the module docstring), so no row is ever torn.
        """
        c1 = self.write_count
        cap = self._cap
        end = c1 if cap is None else min(c1, cap())  # (a capped reader stops at its cap)
        start = max(cursor, self._oldest_readable(c1))
        rows = self._copy(start, end)
        c2 = self.write_count
        valid = max(start, self._oldest_readable(c2))  # rows below this may have been overwritten mid-copy
        if valid > start:
            rows = rows[min(valid, end) - start :]
        return RingReadResult(rows, max(end, cursor), max(0, min(valid, end) - cursor))

    def latest(self, n: int) -> npt.NDArray[np.void]:
        """Copy of the newest ``n`` records (all of them if fewer exist, at most ``capacity - 1``).

        However the reader is scheduled, the result holds exactly
        ``min(n, written, capacity - 1)`` rows for some moment during the
        call: a copy the writer lapped is taken again.
        """
        if n <= 0:
            return np.empty(0, dtype=self.dtype)
        while True:
            c1 = self.write_count
            start = max(0, c1 - n, self._oldest_readable(c1))
            rows = self._copy(start, c1)
            if self._oldest_readable(self.write_count) <= start:
                return rows
            # the writer lapped the copy (the reader was descheduled for a whole ring): copy again

    def _oldest_readable(self, count: int) -> int:
        """First record a reader may copy while ``count`` records are published (the next slot is the writer's)."""
        return max(0, count - self.capacity + 1)

    def _copy(self, start: int, stop: int) -> npt.NDArray[np.void]:
        """Records ``start`` to ``stop`` (write counts) copied out of the slots, oldest first.

        Copied as bytes and read as the record type: NumPy copies a structured array field by field (16.7 µs for
        the 50 records of a session runner's block, against 0.84 µs as bytes; timeit, this VM), the same bytes.
        """
        n = stop - start  # ≤ capacity by construction
        if n <= 0:
            return np.empty(0, dtype=self.dtype)
        cap = self.capacity
        rb = self._row_bytes
        buf = self._buf
        i = start % cap
        first = _HEADER + i * rb
        if i + n <= cap:
            raw = bytearray(buf[first : first + n * rb])
        else:  # the range wraps: the slots to the end, then from the first
            raw = bytearray(buf[first : self._end_off])
            raw += buf[_HEADER : _HEADER + (n - (cap - i)) * rb]
        return np.frombuffer(raw, dtype=self.dtype)

    def column(self, rows: npt.NDArray[np.void], name: str) -> npt.NDArray[np.float64]:
        """One field of copied rows as a float array."""
        return np.asarray(rows[name], dtype=np.float64)

    # -- lifetime -------------------------------------------------------------------------------
    def close(self) -> None:
        """Detach; the creator also frees the shared segment."""
        self._rows = None  # type: ignore[assignment]  # drop the numpy views before closing the buffer
        self._count_cell = None  # type: ignore[assignment]  # released: None only once closed
        buf, self._buf = self._buf, None  # type: ignore[assignment]  # as above
        if self._release is not None:
            buf.release()
            self._release()
            self._release = None
        elif self._shm is not None:
            del buf
            self._shm.close()
            if self._owner:
                try:
                    self._shm.unlink()
                except FileNotFoundError:
                    pass
            self._shm = None

    def __enter__(self) -> RingBuffer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
