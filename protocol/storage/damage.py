"""Damage in a study database's recordings: every block's checksum and decoding checked, runs named in one line.

The checks of one block are the recording's own (:mod:`protocol.recording.integrity`); this module reads the
blocks through the one reader (:class:`protocol.storage.StudyReader`) and names the sessions, time ranges and
trials a run of damaged blocks touches.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import replace
from typing import Any

from protocol.recording.codec import BlockRow
from protocol.recording.integrity import BlockDamage, block_problem
from protocol.storage.reader import StudyReader

__all__ = ["block_rows", "describe_damage", "reader_of", "recording_damage"]


def reader_of(source: Any) -> StudyReader:
    """A :class:`protocol.storage.StudyReader` over ``source`` (a reader, a ``StudyDatabase`` or a connection)."""
    return StudyReader.over(source)


def block_rows(source: Any, session_id: int | None = None, segment: int | None = None,
               ticks: tuple[int, int] | None = None, arm: str = "") -> Iterator[BlockRow]:
    """``session_blocks`` rows (of a session, a segment, those overlapping ticks ``(first, last)``), by session,
    segment and block; ``source`` is a reader, a ``StudyDatabase`` or a connection (:func:`reader_of`).

    A version-3 file read as it is has no ``crc32`` (its blocks read as not verifiable); a column a table
    lacks reads as NULL (NaN times).  ``arm``: another arm's blocks than the task arm's.
    """
    return reader_of(source).blocks(session_id, segment, ticks, arm)  # (its rows go straight to the caller)


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
