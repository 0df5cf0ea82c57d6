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

:func:`recording_damage` scans a whole database or session for damage without
reading the records (``haptic-study check``, the report, and a resume, which
refuses to append to a damaged session).
"""

from __future__ import annotations

import zlib
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from protocol.recording.codec import COLUMNS, BlockRow, decode_block, decode_columns

if TYPE_CHECKING:
    from protocol.storage.reader import StudyReader

__all__ = [
    "BlockDamage",
    "BlockRow",
    "RecordingDamaged",
    "block_problem",
    "block_rows",
    "describe_damage",
    "reader_of",
    "recording_damage",
]


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


def reader_of(source: Any) -> StudyReader:
    """A :class:`protocol.storage.StudyReader` over ``source`` (a reader, a ``StudyDatabase`` or a connection)."""
    from protocol.storage.reader import StudyReader  # (protocol.storage's recorder imports this package)

    return StudyReader.over(source)


def block_rows(source: Any, session_id: int | None = None, segment: int | None = None,
               ticks: tuple[int, int] | None = None, arm: str = "") -> Iterator[BlockRow]:
    """``session_blocks`` rows (of a session, a segment, those overlapping ticks ``(first, last)``), by session,
    segment and block; ``source`` is a reader, a ``StudyDatabase`` or a connection (:func:`reader_of`).

    A version-3 file read as it is has no ``crc32`` (its blocks read as not verifiable); a column a table
    lacks reads as NULL (NaN times).  ``arm``: another arm's blocks than the task arm's.
    """
    return reader_of(source).blocks(session_id, segment, ticks, arm)  # (its rows go straight to the caller)


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
    if row.crc32 is not None and zlib.crc32(row.data) != row.crc32:
        return "checksum mismatch (the block's bytes changed since they were written)"
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


def _trials_touched(source: Any, session_id: int, segment: int, first_tick: int, last_tick: int,
                   ) -> tuple[int, ...]:
    return tuple(i + 1 for i in reader_of(source).trials_touching(session_id, segment, first_tick, last_tick))


def describe_damage(conn: Any, bad: Sequence[tuple[BlockRow, str]]) -> list[BlockDamage]:
    """Damaged blocks (each with what is wrong), merged into runs of consecutive blocks, with the trials they touch."""
    runs: list[BlockDamage] = []
    for row, why in bad:
        last = runs[-1] if runs else None
        if (last is not None and (last.session_id, last.segment) == (row.session_id, row.segment)
                and last.last_block + 1 == row.block):
            runs[-1] = replace(last, last_block=row.block, last_tick=row.last_tick, t_last_s=row.t_last_s)
        else:
            runs.append(BlockDamage(row.session_id, row.segment, row.block, row.block, row.first_tick, row.last_tick,
                                    row.t_first_s, row.t_last_s, why))
    return [replace(d, trials=_trials_touched(conn, d.session_id, d.segment, d.first_tick, d.last_tick)) for d in runs]


def recording_damage(conn: Any, session_id: int | None = None, *, columns: Iterable[str] | None = (),
                     whole: bool = False) -> list[BlockDamage]:
    """The damaged blocks of a database's recordings (or one session's), merged into runs.

    Every block's checksum is verified; a block without one (written before version 4) is decoded as
    ``columns`` say (see :func:`block_problem`), and with ``whole`` every block is decoded in full.
    A database without recordings (version 1 or 2) has none.
    """
    reader = reader_of(conn)
    if not reader.has_recordings():
        return []
    cols = None if columns is None else tuple(columns)
    bad = [(r, why) for r in block_rows(reader, session_id) if (why := block_problem(r, cols, whole=whole))]
    return describe_damage(reader, bad)
