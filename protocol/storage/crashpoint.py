"""A crash at a chosen storage call: the seam that proves every state change is one transaction.

Set ``HAPTIC_STUDY_CRASH_AT`` in a writer's environment and the process kills
itself with SIGKILL -- as ``kill -9`` or a power cut of the process would --
just before the chosen statement of its study database runs:

* ``commit:N`` -- before its N-th commit (a ``COMMIT``, or a write outside any
  transaction, which SQLite commits on its own).  What a reader of the file can
  see changes only at a commit, so killing before each commit in turn reaches
  every state a crash can leave the file in;
* ``statement:N`` -- before its N-th statement of any kind (the transaction it
  is in is rolled back: the same state as a kill before that transaction's commit);
* ``commit:0`` -- count, never kill (:func:`commits_seen` says how many so far).

The count is deterministic wherever the writer's commits are: a headless run on
the virtual clock commits on its own records' time (:class:`protocol.storage.Recorder`),
so a test can enumerate every crash point of a session (``tests/protocol/test_crash_points.py``).
Without the variable nothing is installed and the writer pays nothing.
"""

from __future__ import annotations

import os
import sqlite3

from foundation.platform_support.processes import kill_hard
from protocol.storage.common import StorageError

__all__ = ["CRASH_ENV", "commits_seen", "install", "planned", "statements_seen"]

#: The environment variable that plans the crash.
CRASH_ENV = "HAPTIC_STUDY_CRASH_AT"
_WRITES = ("INSERT", "UPDATE", "DELETE", "REPLACE", "CREATE", "DROP", "ALTER")
_seen = {"commit": 0, "statement": 0}


def commits_seen() -> int:
    """Commits this process's writers have started since it began (counted only while the variable is set)."""
    return _seen["commit"]


def statements_seen() -> int:
    """Statements this process's writers have started since it began (counted only while the variable is set)."""
    return _seen["statement"]


def planned() -> tuple[str, int] | None:
    """The planned crash, ("commit" or "statement", N), or None; a misspelt plan is a :class:`StorageError`."""
    text = os.environ.get(CRASH_ENV, "").strip()
    if not text:
        return None
    what, _, number = text.partition(":")
    if what not in _seen or not number.isdigit():
        raise StorageError(f"{CRASH_ENV} = {text!r}: expected commit:N or statement:N (N ≥ 0; 0 counts only)")
    return what, int(number)


def install(conn: sqlite3.Connection, plan: tuple[str, int] | None) -> None:
    """Count (and at the planned one, crash before) the statements of a writer's connection (:func:`planned`)."""
    if plan is None:
        return
    what, at = plan

    def trace(sql: str) -> None:
        # called by SQLite as a statement begins to run: killing here, the statement never runs
        words = sql.split(None, 1)
        first = words[0].rstrip(";").upper() if words else ""
        _seen["statement"] += 1
        if first in ("COMMIT", "END") or (first in _WRITES and not conn.in_transaction):
            _seen["commit"] += 1
        elif what == "commit":
            return
        if at and _seen[what] == at:
            kill_hard(os.getpid())

    conn.set_trace_callback(trace)
