"""One writer per session: leases on a session, or on the whole study, held by a live process.

A writer takes a lease (:meth:`LeaseHolder.acquire_lease`, the ``leases``
table) on the session, or on the whole study for a headless ``run``; a second
process is refused with a message naming the holder, and a lease left by a
killed process is taken over only once that process is gone.
"""

from __future__ import annotations

import datetime as _dt
import os
import secrets
import socket
import sqlite3
import sys
import time
from collections.abc import Callable
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

from foundation.platform_support.processes import boot_id, process_exists, process_stat_fields
from protocol.storage.common import LeaseHeld, now_iso

__all__ = ["LEASE_HEARTBEAT_S", "LEASE_STALE_S", "LeaseHolder", "new_owner_token", "process_identity", "session_scope"]

#: A lease held from another host is stale after this long without a heartbeat.
LEASE_STALE_S = 30.0
#: Writers refresh their leases' heartbeat this often (with a commit).
LEASE_HEARTBEAT_S = 5.0


def session_scope(session_id: int) -> str:
    """The lease scope of one session."""
    return f"session {int(session_id)}"


def new_owner_token() -> str:
    """A fresh lease owner token (one per writing command; a study's workers share their command's)."""
    return secrets.token_hex(8)


def process_identity(pid: int) -> str:
    """Boot id and start time of a process: equal for the same process, different for a reused pid.

    Empty where ``/proc`` cannot tell (not Linux); the caller then falls back on heartbeats.
    """
    fields = process_stat_fields(pid)
    return "" if fields is None else f"{boot_id()}:{fields[19]}"


def _pid_alive(pid: int) -> bool:
    fields = process_stat_fields(pid)
    if fields is not None:
        # a zombie (killed, not yet reaped -- an orphan whose reaper is slow) writes nothing any more
        return fields[0] not in ("Z", "X")
    return process_exists(pid)  # (another user's counts; Windows asks OpenProcess: platform_support)


def _command_line() -> str:
    """This process's command, shortened (``haptic-study run --resume P01 ...``)."""
    args = [os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else "python", *sys.argv[1:]]
    text = " ".join(args)
    return text if len(text) <= 120 else text[:117] + "..."


class LeaseHolder:
    """The leases half of :class:`protocol.storage.StudyDatabase` (uses its ``conn``, ``path`` and ``transaction``)."""

    path: Path
    conn: sqlite3.Connection
    _owners: set[str]
    _last_heartbeat: float
    transaction: Callable[[], AbstractContextManager[None]]  # StudyDatabase's

    @property
    def schema_version(self) -> int:  # StudyDatabase's (protocol.storage.schema.SchemaFile), which comes first
        raise NotImplementedError

    def acquire_lease(self, scope: str, owner: str, *, command: str = "", study_owner: str | None = None) -> str:
        """Take the lease on ``scope`` (``"study"`` or :func:`session_scope`) for this process.

        Parameters
        ----------
        scope
            What to own.
        owner
            The caller's token (:func:`new_owner_token`).  A lease already held
            under this token by a live process of this command is shared, not refused.
        command
            What the caller is, for other processes' refusal messages.
        study_owner
            The token of the study lease the caller works under (a parallel
            ``run``'s workers), if any: a study lease under it is not a conflict.

        Returns
        -------
        str
            "" or, when a lease left by a process that is gone was taken over, a
            sentence saying so (worth storing as an event).

        Raises
        ------
        LeaseHeld
            Another live process holds the scope (or, for a session, the whole
            study; for the study, any session); the message names it.
        """
        with self.transaction():
            note = ""
            if scope == "study":
                for row in self._leases():
                    if row["owner"] != owner and self._alive(row):
                        what = "the study in" if row["scope"] == "study" else f"{row['scope']} of"
                        raise LeaseHeld(self._held_message(row, what))
            else:
                self._refuse_if_study_held(study_owner or owner)
            held = self._lease(scope)
            if held is not None and held["owner"] != owner:
                if self._alive(held):
                    raise LeaseHeld(self._held_message(held, f"{scope} of"))
                note = (f"took over the lease on {scope} left by process {held['pid']} on {held['host']} "
                        f"({held['command'] or 'unknown command'}), which is no longer running")
            for other in self._leases():  # leases of processes that are gone protect nothing: clear them
                if other["scope"] != scope and not self._alive(other):
                    self.conn.execute("DELETE FROM leases WHERE scope = ? AND owner = ?",
                                      (other["scope"], other["owner"]))
            self._write_lease(scope, owner, command)
        return note

    def release_lease(self, scope: str, owner: str) -> None:
        """Give a lease back (only the owner's own; a lease taken over meanwhile is left alone)."""
        with self.transaction():
            self.conn.execute("DELETE FROM leases WHERE scope = ? AND owner = ? AND pid = ?",
                              (scope, owner, os.getpid()))

    def heartbeat(self, *, force: bool = False) -> None:
        """Refresh this process's leases (at most every ``LEASE_HEARTBEAT_S``) in the open transaction, if any."""
        now = time.monotonic()
        if not self._owners or (not force and now - self._last_heartbeat < LEASE_HEARTBEAT_S):
            return
        self._last_heartbeat = now
        self.conn.execute("UPDATE leases SET heartbeat_at = ? WHERE pid = ? AND host = ?",
                          (now_iso(), os.getpid(), socket.gethostname()))

    def lease_holders(self) -> list[dict[str, Any]]:
        """Every stored lease with ``alive`` (for displays and tests)."""
        return [{**row, "alive": self._alive(row)} for row in self._leases()]

    def sessions_being_written(self) -> dict[int, str]:
        """Sessions a live process writes to right now: session id -> "process N (command)" ({} before version 2)."""
        if self.schema_version < 2:
            return {}
        out = {}
        for row in self.lease_holders():
            if row["alive"] and str(row["scope"]).startswith("session "):
                out[int(str(row["scope"]).split()[1])] = f"process {row['pid']} ({row['command']})"
        return out

    def _leases(self) -> list[dict[str, Any]]:
        cur = self.conn.execute(
            "SELECT scope, owner, pid, host, process_start, command, acquired_at, heartbeat_at FROM leases")
        names = [d[0] for d in cur.description]
        return [dict(zip(names, r, strict=True)) for r in cur]

    def _lease(self, scope: str) -> dict[str, Any] | None:
        return next((r for r in self._leases() if r["scope"] == scope), None)

    def _refuse_if_study_held(self, my_study_owner: str) -> None:
        row = self._lease("study")
        if row is not None and row["owner"] != my_study_owner and self._alive(row):
            raise LeaseHeld(self._held_message(row, "the study in"))

    def _write_lease(self, scope: str, owner: str, command: str) -> None:
        now = now_iso()
        pid = os.getpid()
        self.conn.execute(
            "INSERT OR REPLACE INTO leases (scope, owner, pid, host, process_start, command, acquired_at, "
            "heartbeat_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
            (scope, owner, pid, socket.gethostname(), process_identity(pid), command or _command_line(), now, now),
        )
        self._owners.add(owner)

    @staticmethod
    def _alive(row: dict[str, Any]) -> bool:
        """Is the lease's process still running? Same host: the pid runs the very process; else a fresh heartbeat."""
        if row["host"] == socket.gethostname():
            if not _pid_alive(row["pid"]):
                return False
            ident = process_identity(row["pid"])
            return not (ident and row["process_start"] and ident != row["process_start"])
        try:
            beat = _dt.datetime.fromisoformat(row["heartbeat_at"])
        except (TypeError, ValueError):
            return False
        return (_dt.datetime.now(_dt.UTC) - beat).total_seconds() < LEASE_STALE_S

    def _held_message(self, row: dict[str, Any], what: str) -> str:
        where = "" if row["host"] == socket.gethostname() else f" on {row['host']}"
        return (f"{self.path}: {what} this database is being written by process {row['pid']}{where} "
                f"({row['command']}, since {str(row['acquired_at'])[:19].replace('T', ' ')} UTC); nothing was changed "
                "(wait for it to finish, or stop it)")
