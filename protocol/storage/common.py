"""What every part of the study database shares: its errors and its timestamps."""

from __future__ import annotations

import datetime as _dt

__all__ = ["EmptyDatabase", "LeaseHeld", "StorageError", "now_iso"]


class StorageError(Exception):
    """The database cannot be used as asked; the message says why and what to do."""


class LeaseHeld(StorageError):
    """Another live process writes to the study or session; the message names it."""


class EmptyDatabase(StorageError):
    """Opened for reading, the file holds no study yet (an empty or brand-new SQLite file)."""



def now_iso() -> str:
    """Wall-clock time now, UTC, ISO 8601 to the millisecond (the ``*_at`` TEXT columns)."""
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")
