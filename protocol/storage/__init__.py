"""The study database: SQLite in WAL mode, created from ``data/schema.sql``.

One writer owns the connection (:class:`StudyDatabase`); in a live session it
runs in a :class:`Recorder` thread fed through a queue, so neither the 1 kHz
loop nor the GUI ever waits on the disk.  Sample batches are committed at least
every 100 ms, each trial summary atomically when the trial ends, and nothing is
ever overwritten: a participant code with an experiment session already
stored is refused unless the caller resumes it.  WAL mode lets analysis read
while a session writes.

What protects the record:

* **one writer per session** -- a writer takes a lease (:meth:`StudyDatabase.acquire_lease`,
  the ``leases`` table) on the session, or on the whole study for a headless
  ``run``; a second process is refused with a message naming the holder, and a
  lease left by a killed process is taken over only once that process is gone;
* **no writing into a damaged file** -- ``PRAGMA quick_check`` runs before a
  writer touches the file (and when analysis asks for it); a damaged file is
  refused and left byte-identical;
* **archives stay readable** -- readers open read-only, and a database in a
  folder they cannot write opens immutable (:func:`connect_readonly`);
* **older files** -- a version-1 database is read as it is; a writer upgrades
  it in place only after writing a backup copy beside it;
* **privacy** -- new databases (and so their ``-wal``/``-shm`` files, which
  SQLite creates with the database's permissions) are readable by their owner only.
"""

from protocol.storage.codes import clash_of, code_key, near_duplicate, normalise_code
from protocol.storage.common import EmptyDatabase, LeaseHeld, StorageError
from protocol.storage.database import CODE_PATTERN, SessionInfo, StudyDatabase, validate_code
from protocol.storage.leases import LEASE_HEARTBEAT_S, LEASE_STALE_S, new_owner_token, process_identity, session_scope
from protocol.storage.reader import Rows, StudyReader
from protocol.storage.recorder import Recorder
from protocol.storage.schema import (
    ABORT_CAUSES,
    HEALTH_COLUMNS,
    SAMPLE_COLUMNS,
    SCHEMA_VERSION,
    connect_readonly,
    schema_path,
)
from protocol.study.records import trial_id_of

__all__ = [
    "ABORT_CAUSES",
    "CODE_PATTERN",
    "HEALTH_COLUMNS",
    "LEASE_HEARTBEAT_S",
    "LEASE_STALE_S",
    "SAMPLE_COLUMNS",
    "SCHEMA_VERSION",
    "EmptyDatabase",
    "LeaseHeld",
    "Recorder",
    "Rows",
    "SessionInfo",
    "StorageError",
    "StudyDatabase",
    "StudyReader",
    "clash_of",
    "code_key",
    "connect_readonly",
    "near_duplicate",
    "new_owner_token",
    "normalise_code",
    "process_identity",
    "schema_path",
    "session_scope",
    "trial_id_of",
    "validate_code",
]
