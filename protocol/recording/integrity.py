"""Is a recorded block what was written?  Checksums verified on every read, damage named in one line.

Since schema version 4 every ``session_blocks`` row carries ``crc32``, the
CRC-32 (:func:`zlib.crc32`) of its ``data``.  SQLite checks its own pages'
structure (``PRAGMA quick_check``) but not their contents: one flipped bit in a
block passes it.  So every reader checks each block it decodes: a block whose
checksum does not match, or that does not decode (a block written before
version 4 has no checksum: it is *not verifiable*, which is not damage, but it
can still fail to decode), is **damaged**, and the reader raises
:class:`RecordingDamaged` -- or, asked to, reads around it -- with one line per run
of damaged blocks naming the session, the session-time range and the trials it
touches (:meth:`BlockDamage.describe`).

A checksum of the bytes alone cannot tell a block that is intact but in the wrong place -- swapped with another
session's block of the same ticks, one arm's copied over the other's.  So a block of a run recorded since the runs
count their blocks (``recordings.n_blocks`` not NULL) carries a checksum of its *place* and its bytes
(:func:`place_crc32`): the arm, session, run, block (and chunk) numbers, ticks and record count it was written
under, then its data.  Moved, it no longer matches where it is.

What a block's checksum and decoding say is here, pure; scanning a database for damage, which needs its
reader, is :mod:`protocol.storage.damage` (``haptic-study check``, the report, and a resume, which refuses to
append to a damaged session).
"""

from __future__ import annotations

import zlib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from protocol.recording.codec import COLUMNS, BlockRow, decode_block, decode_columns

__all__ = [
    "WHOLE_BLOCK",
    "BlockDamage",
    "BlockRow",
    "RecordingDamaged",
    "block_crc32",
    "block_problem",
    "columns_problem",
    "decode_failure",
    "place_crc32",
]

#: The chunk number of a whole block in its place (chunks are numbered from 0).
WHOLE_BLOCK = -1


def place_crc32(data: bytes, *, arm: str, session_id: int, segment: int, block: int, chunk: int, first_tick: int,
                last_tick: int, n_records: int) -> int:
    """The CRC-32 of a block's (or chunk's) place, then its bytes: moved to another place, it no longer matches."""
    place = (f"haptic-study block\x00{arm}\x00{session_id}\x00{segment}\x00{block}\x00{chunk}\x00{first_tick}\x00"
             f"{last_tick}\x00{n_records}\x00").encode()
    return zlib.crc32(data, zlib.crc32(place))


def block_crc32(row: BlockRow) -> int:
    """The checksum ``row`` must carry: of its place and bytes when it is bound, else of its bytes."""
    if not row.bound:
        return zlib.crc32(row.data)
    return place_crc32(row.data, arm=row.arm, session_id=row.session_id, segment=row.segment, block=row.block,
                       chunk=WHOLE_BLOCK, first_tick=row.first_tick, last_tick=row.last_tick, n_records=row.n_records)


@dataclass(frozen=True, slots=True)
class BlockDamage:
    """A run of consecutive damaged blocks of one recorded segment, and what it touches.

    ``trials`` are the 1-based numbers of the stored trials whose records (``first_tick`` …
    ``last_tick``) overlap it; ``why`` says what is wrong with its first block.
    """

    session_id: int
    segment: int
    first_block: int
    last_block: int
    first_tick: int
    last_tick: int
    t_first_s: float
    t_last_s: float
    why: str
    trials: tuple[int, ...] = ()

    def describe(self) -> str:
        """One line, e.g. ``session 4, recorded run 0, 12.000–13.999 s (blocks 12–13): checksum mismatch; touches
        trial 5``."""
        blocks = (f"block {self.first_block}" if self.first_block == self.last_block
                  else f"blocks {self.first_block}–{self.last_block}")
        touches = ("touches no trial" if not self.trials else
                   f"touches trial{'s' if len(self.trials) > 1 else ''} {', '.join(map(str, self.trials))}")
        return (f"session {self.session_id}, recorded run {self.segment}, {self.t_first_s:.3f}–{self.t_last_s:.3f} s "
                f"({blocks}): {self.why}; {touches}")


class RecordingDamaged(ValueError):
    """A recording's block is damaged; the message names where, in one line per run of damaged blocks.

    Attributes
    ----------
    damage
        What is damaged.
    """

    def __init__(self, damage: Sequence[BlockDamage]) -> None:
        self.damage = list(damage)
        super().__init__("; ".join(f"recording damaged: {d.describe()}" for d in self.damage))


def block_problem(row: BlockRow, columns: Iterable[str] | None = (), *, whole: bool = False) -> str:
    """What is wrong with a block ("" if nothing found).

    Parameters
    ----------
    row
        The block.
    columns
        For a block without a checksum: the columns to try to decode (``()``: none; None: the whole block).
    whole
        Decode every block in full, checksum or not, and check its records against the row (``haptic-study check``).
    """
    if row.crc32 is not None and block_crc32(row) != row.crc32:
        return ("checksum mismatch (the block's bytes changed since they were written)" if not row.bound else
                "checksum mismatch (the block's bytes, or the place it is stored at -- session, arm, run, block, "
                "ticks -- changed since it was written)")
    if not whole and (row.crc32 is not None or columns == ()):
        return ""
    names = [c.name for c in COLUMNS] if whole or columns is None else list(dict.fromkeys(["tick", *columns]))
    try:
        cols = decode_block(row.data)[0] if whole or columns is None else decode_columns(row.data, names)
    except Exception as exc:  # any failure to decode is damage: zlib, struct, json, numpy alike
        return decode_failure(exc)
    why = columns_problem(cols, names)
    if why:
        return why
    ticks = np.asarray(cols["tick"])
    if whole and (len(ticks) != row.n_records or (len(ticks) and (int(ticks[0]) != row.first_tick
                                                                 or int(ticks[-1]) != row.last_tick))):
        return (f"its records (ticks {int(ticks[0]) if len(ticks) else '-'}–{int(ticks[-1]) if len(ticks) else '-'}, "
                f"{len(ticks)} records) disagree with its row (ticks {row.first_tick}–{row.last_tick}, "
                f"{row.n_records} records)")
    return ""


def decode_failure(exc: BaseException) -> str:
    """What a failure to decode a block says (one line)."""
    return f"cannot be decoded ({type(exc).__name__}: {' '.join(str(exc).split())[:80]})"


def columns_problem(cols: Mapping[str, np.ndarray], names: Iterable[str]) -> str:
    """What is wrong with a block's decoded columns ("" if nothing): one missing, or lengths that differ.

    A block without a checksum whose header was changed can still decode, to the wrong columns.
    """
    names = list(names)
    missing = [n for n in names if n not in cols]
    if missing:
        return f"decodes without its column {missing[0]!r} (its header changed)"
    if len({len(cols[n]) for n in names}) > 1:
        return "decodes to columns of different lengths (its header changed)"
    return ""
