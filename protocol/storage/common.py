"""What every part of the study database shares: its errors and its timestamps."""

from __future__ import annotations

import datetime as _dt
import sqlite3

__all__ = ["EmptyDatabase", "LeaseHeld", "StorageError", "has_table", "now_iso", "recording_tables"]


class StorageError(Exception):
    """The database cannot be used as asked; the message says why and what to do."""


class LeaseHeld(StorageError):
    """Another live process writes to the study or session; the message names it."""


class EmptyDatabase(StorageError):
    """Opened for reading, the file holds no study yet (an empty or brand-new SQLite file)."""



def has_table(conn: sqlite3.Connection, name: str) -> bool:
    """Whether the file has the table ``name`` (a file of an older schema, or of version 4 before a table was added
    to it, lacks some)."""
    return conn.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (name,)).fetchone() is not None


def recording_tables(arm: str) -> tuple[str, str, str]:
    """The tables of an arm's recording -- its segments, its blocks, its open blocks' chunks: those of the task arm
    (every record of a one-arm rig) for ``""``, else those of the other arms, which have an ``arm`` column."""
    return ("arm_recordings", "arm_blocks", "arm_chunks") if arm else ("recordings", "session_blocks", "session_chunks")


def now_iso() -> str:
    """Wall-clock time now, UTC, ISO 8601 to the millisecond (the ``*_at`` TEXT columns)."""
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")
