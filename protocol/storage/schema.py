"""The file and its schema: opening it safely, checking it, creating it, upgrading it.

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

from __future__ import annotations

import contextlib
import datetime as _dt
import os
import sqlite3
from collections.abc import Iterable
from dataclasses import fields
from pathlib import Path

from foundation.platform_support.files import may_write, owner_only
from protocol.metrics import get
from protocol.storage.common import EmptyDatabase, StorageError, has_table
from protocol.study.records import AbortCause, LoopHealth

__all__ = ["ABORT_CAUSES", "HEALTH_COLUMNS", "SAMPLE_COLUMNS", "SCHEMA_VERSION", "SchemaFile", "connect_readonly",
           "schema_path"]

SCHEMA_VERSION = 4
#: Why an aborted trial was aborted (``trials.abort_cause``, schema version 2).
ABORT_CAUSES = tuple(c.value for c in AbortCause)
#: Per-trial loop health columns (schema version 2), in table order (the fields of the record's health).
HEALTH_COLUMNS = tuple(f.name for f in fields(LoopHealth))
#: The causes a file of schema version 2 to 4 allowed before ``participant_screen`` was added (its CHECK's list).
_CAUSES_BEFORE = "('experimenter', 'fault', 'feedback', 'gap', 'interrupted')"
#: The causes allowed now, as the CHECK lists them (``data/schema.sql`` has the same list).
_CAUSES_NOW = "(" + ", ".join(f"'{c}'" for c in ABORT_CAUSES) + ")"
#: What upgrades a version-1 database to version 2 (the same tables as a new one; tested).
_UPGRADE_1_TO_2 = (
    f"ALTER TABLE trials ADD COLUMN abort_cause TEXT CHECK (abort_cause IS NULL OR abort_cause IN {_CAUSES_NOW})",
    *(f"ALTER TABLE trials ADD COLUMN {c} {'INTEGER' if c == 'periods_over_2ms' else 'REAL'}" for c in HEALTH_COLUMNS),
    "CREATE TABLE leases (scope TEXT PRIMARY KEY, owner TEXT NOT NULL, pid INTEGER NOT NULL, host TEXT NOT NULL, "
    "process_start TEXT NOT NULL, command TEXT NOT NULL, acquired_at TEXT NOT NULL, heartbeat_at TEXT NOT NULL)",
)
#: What upgrades a version-2 database to version 3: whole sessions recorded in blocks.
_UPGRADE_2_TO_3 = (
    "ALTER TABLE trials ADD COLUMN segment INTEGER",
    "ALTER TABLE trials ADD COLUMN first_tick INTEGER",
    "ALTER TABLE trials ADD COLUMN last_tick INTEGER",
    "CREATE TABLE recordings (session_id INTEGER NOT NULL REFERENCES sessions(session_id), segment INTEGER NOT NULL, "
    "started_at_s REAL NOT NULL, t0_ns INTEGER NOT NULL, snapshot_json TEXT NOT NULL, scales_json TEXT NOT NULL, "
    "PRIMARY KEY (session_id, segment))",
    "CREATE TABLE session_blocks (session_id INTEGER NOT NULL, segment INTEGER NOT NULL, block INTEGER NOT NULL, "
    "first_tick INTEGER NOT NULL, last_tick INTEGER NOT NULL, n_records INTEGER NOT NULL, t_first_s REAL NOT NULL, "
    "t_last_s REAL NOT NULL, data BLOB NOT NULL, PRIMARY KEY (session_id, segment, block), "
    "FOREIGN KEY (session_id, segment) REFERENCES recordings (session_id, segment))",
)
#: Version 4's record of the participants who withdrew (``haptic-study withdraw``; :mod:`protocol.storage.withdrawal`).
#: Added to version 4 after files of version 4 existed: a writer that opens a version-4 file without it adds it.
_WITHDRAWALS = (
    "CREATE TABLE IF NOT EXISTS withdrawals (code TEXT PRIMARY KEY, withdrawn_at TEXT NOT NULL, reason TEXT NOT NULL, "
    "removed_sessions INTEGER NOT NULL, removed_trials INTEGER NOT NULL, removed_events INTEGER NOT NULL, "
    "removed_blocks INTEGER NOT NULL, removed_records INTEGER NOT NULL, removed_samples INTEGER NOT NULL)"
)
#: Version 4's open blocks: what a segment being recorded gained at each commit (:mod:`protocol.recording`).  Added
#: to version 4 after files of version 4 existed: a writer that opens a version-4 file without it adds it.
_CHUNKS = (
    "CREATE TABLE IF NOT EXISTS session_chunks (session_id INTEGER NOT NULL, segment INTEGER NOT NULL, "
    "block INTEGER NOT NULL, chunk INTEGER NOT NULL, first_tick INTEGER NOT NULL, last_tick INTEGER NOT NULL, "
    "n_records INTEGER NOT NULL, t_first_s REAL NOT NULL, t_last_s REAL NOT NULL, data BLOB NOT NULL, "
    "crc32 INTEGER NOT NULL, PRIMARY KEY (session_id, segment, block, chunk), "
    "FOREIGN KEY (session_id, segment) REFERENCES recordings (session_id, segment))"
)
#: Version 4's other arms (a rig of several arms: the arms other than the task arm, :mod:`protocol.recording`): the
#: columns of ``recordings``, ``session_blocks`` and ``session_chunks`` with the arm's name.  Added to version 4 after
#: files of version 4 existed: a writer that opens a version-4 file without them adds them.
_ARMS = (
    "CREATE TABLE IF NOT EXISTS arm_recordings (session_id INTEGER NOT NULL REFERENCES sessions(session_id), "
    "arm TEXT NOT NULL, segment INTEGER NOT NULL, started_at_s REAL NOT NULL, t0_ns INTEGER NOT NULL, "
    "snapshot_json TEXT NOT NULL, scales_json TEXT NOT NULL, PRIMARY KEY (session_id, arm, segment))",
    "CREATE TABLE IF NOT EXISTS arm_blocks (session_id INTEGER NOT NULL, arm TEXT NOT NULL, segment INTEGER NOT NULL, "
    "block INTEGER NOT NULL, first_tick INTEGER NOT NULL, last_tick INTEGER NOT NULL, n_records INTEGER NOT NULL, "
    "t_first_s REAL NOT NULL, t_last_s REAL NOT NULL, data BLOB NOT NULL, crc32 INTEGER, "
    "PRIMARY KEY (session_id, arm, segment, block), "
    "FOREIGN KEY (session_id, arm, segment) REFERENCES arm_recordings (session_id, arm, segment))",
    "CREATE TABLE IF NOT EXISTS arm_chunks (session_id INTEGER NOT NULL, arm TEXT NOT NULL, segment INTEGER NOT NULL, "
    "block INTEGER NOT NULL, chunk INTEGER NOT NULL, first_tick INTEGER NOT NULL, last_tick INTEGER NOT NULL, "
    "n_records INTEGER NOT NULL, t_first_s REAL NOT NULL, t_last_s REAL NOT NULL, data BLOB NOT NULL, "
    "crc32 INTEGER NOT NULL, PRIMARY KEY (session_id, arm, segment, block, chunk), "
    "FOREIGN KEY (session_id, arm, segment) REFERENCES arm_recordings (session_id, arm, segment))",
)
#: What upgrades a version-3 database to version 4: a checksum per recorded block (NULL in blocks written before it,
#: which cannot be verified), and which code ran each session (the commit, and whether the checkout had uncommitted
#: changes; NULL where it is not known, e.g. an install from a wheel).
_UPGRADE_3_TO_4 = (
    "ALTER TABLE session_blocks ADD COLUMN crc32 INTEGER",
    "ALTER TABLE sessions ADD COLUMN software_commit TEXT",
    "ALTER TABLE sessions ADD COLUMN software_dirty INTEGER CHECK (software_dirty IS NULL OR software_dirty IN (0, 1))",
    _WITHDRAWALS,
    _CHUNKS,
    *_ARMS,
)


def metric_columns_missing(conn: sqlite3.Connection, names: Iterable[str]) -> list[str]:
    """Those of the metrics ``names`` (stored ones of the registry, :func:`protocol.metrics.stored`) the file's
    ``trials`` table has no column for."""
    has = {r[1] for r in conn.execute("PRAGMA table_info(trials)")}
    return [n for n in dict.fromkeys(names) if n not in has]


def add_metric_columns(conn: sqlite3.Connection, names: Iterable[str]) -> list[str]:
    """Give the ``trials`` table a column for each of the metrics ``names`` it lacks: a metric of a session's task
    that the file's earlier sessions did not produce (another task's, or one defined after the file was made).

    Only a writer calls this, on a file it is about to write a session's trials to (a file's metric columns are
    its sessions' tasks', :func:`protocol.tasks.base.metrics_of`: a force-regulation study's are the paper's): the
    column is added empty (NULL in every trial stored before: that metric was not computed for it), no row is
    changed, and the schema version stays (an older haptic-study reads and writes the file as before: it names the
    columns it knows).  Inside the caller's transaction, or in its own; either way the columns are checked again
    under the write lock, so two writers opening the file at once add each column once.  Returns the columns added.
    """
    wanted = list(names)
    for name in wanted:  # a name goes into SQL text: only the registry's stored metrics
        if not get(name).stored:
            raise ValueError(f"{name}: not a metric with a trials column")
    if not metric_columns_missing(conn, wanted):  # the common case: no lock taken
        return []
    own = not conn.in_transaction
    if own:
        conn.execute("BEGIN IMMEDIATE")
    try:
        missing = metric_columns_missing(conn, wanted)
        for name in missing:
            conn.execute(f"ALTER TABLE trials ADD COLUMN {name} REAL")
        if own:
            conn.execute("COMMIT")
    except BaseException:
        if own:
            conn.execute("ROLLBACK")
        raise
    return missing


#: Columns added to version 4 after files of version 4 existed, NULL in the rows stored before (table, column):
#: a run's count of its blocks (``n_blocks``: not NULL, its blocks' checksums bind their place; NULL, a run recorded
#: before, whose checksums cover their bytes alone), whether a withdrawal's rewrite of the file finished, and the LSL
#: rows a withdrawal removed (issue 46: NULL in a record made before them).
_LATER_COLUMNS = (("recordings", "n_blocks"), ("arm_recordings", "n_blocks"), ("withdrawals", "rewritten"),
                  ("withdrawals", "removed_lsl_streams"), ("withdrawals", "removed_lsl_chunks"))


def add_later_columns(conn: sqlite3.Connection) -> list[str]:
    """Give a file made before them the columns of :data:`_LATER_COLUMNS` (INTEGER, NULL in every row before).

    As :func:`add_metric_columns`: only a writer, in its own transaction, no row changed, the schema version kept
    (an older haptic-study writes rows without them -- NULL -- and never appends to a run it did not start).
    Returns the ``table.column`` added.
    """
    def missing() -> list[tuple[str, str]]:
        return [(t, col) for t, col in _LATER_COLUMNS if has_table(conn, t)
                and col not in {r[1] for r in conn.execute(f"PRAGMA table_info({t})")}]

    if not missing():
        return []
    conn.execute("BEGIN IMMEDIATE")
    try:
        added = missing()
        for table, column in added:
            conn.execute(f"ALTER TABLE {table} ADD COLUMN {column} INTEGER")
        conn.execute("COMMIT")
    except BaseException:
        conn.execute("ROLLBACK")
        raise
    return [f"{t}.{c}" for t, c in added]


#: Tables added to version 4 after files of version 4 existed (issue 44: who the participants are, the
#: experimenter's notes, the questionnaires' answers), defined once in ``data/schema.sql``: a writer that opens a
#: file without them adds them, empty.
LATER_TABLES = ("covariates", "notes", "questionnaire_answers")


def _later_table_sql(name: str) -> str:
    """The ``CREATE TABLE`` statement of ``name`` as ``data/schema.sql`` writes it (comments left out)."""
    text = "\n".join(line.split("--", 1)[0] for line in schema_path().read_text(encoding="utf-8").splitlines())
    for statement in text.split(";"):
        if statement.split()[:6] == ["CREATE", "TABLE", "IF", "NOT", "EXISTS", name]:
            return statement.strip()
    raise StorageError(f"{schema_path()}: no table {name}")  # (a broken install)


def add_later_tables(conn: sqlite3.Connection) -> list[str]:
    """Give a file made before them the tables of :data:`LATER_TABLES` (empty), as :func:`add_later_columns` adds
    columns: only a writer, in its own transaction, no row changed, the schema version kept.  Returns those added."""
    def missing() -> list[str]:
        return [t for t in LATER_TABLES if not has_table(conn, t)]

    if not missing():
        return []
    conn.execute("BEGIN IMMEDIATE")
    try:
        added = missing()
        for table in added:
            conn.execute(_later_table_sql(table))
        conn.execute("COMMIT")
    except BaseException:
        conn.execute("ROLLBACK")
        raise
    return added


SAMPLE_COLUMNS = (
    "trial_id", "t_s", "force_n",
    "raw_fx", "raw_fy", "raw_fz", "raw_tx", "raw_ty", "raw_tz",
    "comp_fx", "comp_fy", "comp_fz",
    "render_fx", "render_fy", "render_fz",
)


def schema_path() -> Path:
    """Location of the schema: ``data/schema.sql`` of a checkout, shipped in an installed wheel as
    ``protocol/storage/sql``.

    The installed copy is looked for first, so an install never reads a ``data/`` folder that is not its own.
    """
    here = Path(__file__).resolve().parent
    installed = here / "sql" / "schema.sql"
    return installed if installed.is_file() else here.parents[1] / "data" / "schema.sql"


_SQLITE_MAGIC = b"SQLite format 3\x00"


def _check_sqlite_header(p: Path) -> None:
    """Refuse a non-empty file that is not SQLite at all (before SQLite touches it)."""
    try:
        with open(p, "rb") as fh:
            head = fh.read(len(_SQLITE_MAGIC))
    except OSError as exc:
        raise StorageError(f"{p}: cannot read the database ({exc.strerror})") from None
    if head and head != _SQLITE_MAGIC:
        raise StorageError(f"{p}: not a haptic-study database (not an SQLite file)")


def _refuse_special(p: Path) -> None:
    """Refuse a path that is not a regular file, before SQLite opens it (and leaves a ``-journal`` beside it)."""
    if p.is_dir():
        raise StorageError(f"{p}: is a directory, not a database file")
    if p.exists() and not p.is_file():
        raise StorageError(f"{p}: is not a regular file (a device, a pipe or a socket); give the path of a study "
                           "database file; nothing was written")


def connect_readonly(path: str | os.PathLike[str], *, timeout_s: float = 5.0) -> sqlite3.Connection:
    """A read-only connection that never creates, migrates or locks the database for writing.

    An archived database -- a read-only file in a folder this user cannot
    write -- cannot be opened read-only in WAL mode (SQLite needs to create the
    ``-shm`` index beside it); it is opened *immutable* instead, which is
    exact as long as nobody writes to it, and nobody can.

    Raises
    ------
    StorageError
        No such file, or it cannot be opened.
    """
    p = Path(path)
    if not p.exists():
        raise StorageError(f"{p}: no such database")
    _refuse_special(p)
    uri = p.resolve().as_uri()
    folder = p.resolve().parent
    wal = p.with_name(p.name + "-wal")
    try:
        # a folder without a write bit is an archive to root too (may_write), whom SQLite lets make -shm in it
        archive = not may_write(folder)
        pending = wal.exists() and wal.stat().st_size > 0  # changes only a WAL reader sees
        if not archive or pending:
            conn = sqlite3.connect(f"{uri}?mode=ro", uri=True, check_same_thread=False, timeout=timeout_s)
            try:
                conn.execute("PRAGMA user_version").fetchone()
                return conn
            except sqlite3.OperationalError:
                conn.close()
                if not archive:
                    raise
                raise StorageError(
                    f"{p}: cannot be read where it is: its last changes are still in {wal.name}, which SQLite can "
                    f"read only with a writable folder and {folder} is read-only; copy the database and its "
                    f"{wal.name} into a writable folder and read the copy") from None
            except sqlite3.DatabaseError:
                conn.close()
                raise
        # an archive (nobody can write here): immutable needs no -shm and takes no lock
        conn = sqlite3.connect(f"{uri}?immutable=1", uri=True, check_same_thread=False, timeout=timeout_s)
        try:
            conn.execute("PRAGMA user_version").fetchone()
        except sqlite3.DatabaseError:
            conn.close()
            raise
        return conn
    except sqlite3.OperationalError as exc:
        raise StorageError(f"{p}: cannot open the database ({exc})") from None
    except sqlite3.DatabaseError as exc:
        raise StorageError(f"{p}: not a haptic-study database ({exc})") from None


class SchemaFile:
    """The opening half of :class:`protocol.storage.StudyDatabase`: the file, its checks, its schema and upgrades.

    Uses the database's ``path`` and ``conn``; sets ``upgraded_from`` and ``backup_path``.
    """

    path: Path
    conn: sqlite3.Connection
    upgraded_from: int | None
    backup_path: Path | None

    def _check_path(self, readonly: bool) -> bool:
        """Refuse what cannot be opened as asked; create a new file owner-only.  True if it was created."""
        p = self.path
        _refuse_special(p)
        if readonly:
            if not p.exists():
                raise StorageError(f"{p}: no such database")
            _check_sqlite_header(p)
            return False
        parent = p.parent if str(p.parent) else Path(".")
        if not parent.exists():
            raise StorageError(f"{p}: the folder {parent} does not exist")
        if p.exists():
            _check_sqlite_header(p)
            if not may_write(p):
                raise StorageError(f"{p}: the database is not writable (open it read-only, e.g. with report)")
            if not may_write(parent):
                raise StorageError(f"{p}: the folder {parent} is not writable (SQLite writes its journal beside "
                                   "the database)")
            return False
        if not may_write(parent):
            raise StorageError(f"{p}: cannot create the database here (folder {parent} is not writable)")
        try:
            # owner-only from the first byte: SQLite gives the -wal and -shm files the database's permissions
            os.close(os.open(p, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        except FileExistsError:  # another process created it meanwhile: open it as it is
            return False
        except OSError as exc:
            raise StorageError(f"{p}: cannot create the database ({exc.strerror})") from None
        return True

    def _quick_check(self) -> None:
        try:
            rows = self.conn.execute("PRAGMA quick_check(5)").fetchall()
        except sqlite3.DatabaseError as exc:
            raise StorageError(f"{self.path}: the database is damaged ({exc}); nothing was written to it "
                               "(restore it from a backup)") from None
        problems = [" ".join(str(r[0]).split()) for r in rows if r[0] != "ok"]  # SQLite's report spans lines
        if problems:
            raise StorageError(f"{self.path}: the database is damaged (integrity check: {problems[0]}); "
                               "nothing was written to it (restore it from a backup)")

    def quick_check(self) -> None:
        """``PRAGMA quick_check``; raises :class:`StorageError` with the first problem found."""
        self._quick_check()

    def _prepare(self, readonly: bool, upgrade: bool) -> None:
        c = self.conn
        # the version and the tables of one snapshot: read apart, a file being created between them looked like
        # version 0 with tables ("not a haptic-study database") to a reader such as a live check
        own = not c.in_transaction
        if own:
            c.execute("BEGIN")
        try:
            version = c.execute("PRAGMA user_version").fetchone()[0]
            tables = {r[0] for r in c.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        finally:
            if own:
                c.execute("ROLLBACK")
        if version > SCHEMA_VERSION:
            raise StorageError(
                f"{self.path}: database schema version {version} is newer than this software supports "
                f"({SCHEMA_VERSION}); update haptic-study to open it"
            )
        if version == 0:
            if tables:
                raise StorageError(f"{self.path}: not a haptic-study database (it has other tables: "
                                   f"{', '.join(sorted(tables))})")
            if readonly:
                raise EmptyDatabase(f"{self.path}: empty database (no study data)")
            script = schema_path().read_text(encoding="utf-8")
            c.execute("PRAGMA journal_mode = WAL")
            c.executescript("BEGIN IMMEDIATE;\n" + script + f"\nPRAGMA user_version = {SCHEMA_VERSION};\nCOMMIT;")
            self._owner_only()
        elif not {"participants", "sessions", "trials", "samples", "events"} <= tables:
            raise StorageError(f"{self.path}: not a haptic-study database (tables missing)")
        elif version < SCHEMA_VERSION and not readonly:
            if not upgrade:
                raise StorageError(f"{self.path}: database schema version {version} must be upgraded to "
                                   f"{SCHEMA_VERSION} before it is written to; nothing was changed")
            self._upgrade(version)
        elif not readonly and not {"withdrawals", "session_chunks", "arm_chunks"} <= tables:  # a v4 file before them
            for statement in (_WITHDRAWALS, _CHUNKS, *_ARMS):
                c.execute(statement)
        if not readonly and version:
            _widen_abort_causes(c)
        if not readonly:
            add_later_columns(c)
            add_later_tables(c)
            c.execute("PRAGMA journal_mode = WAL")
            # NORMAL in WAL mode: a committed transaction survives a process
            # crash (SIGKILL); only a power cut can lose the last commits.
            c.execute("PRAGMA synchronous = NORMAL")
            c.execute("PRAGMA foreign_keys = ON")
            # A writer deletes only its own scaffolding: the chunks of a block it just wrote whole (the same records,
            # in the same transaction) and its lease rows.  FAST zeroes deleted content on the pages it writes
            # anyway but not freed pages (Debian's SQLite zeroes those too by default: ~20 extra pages a block).
            # Erasing a participant's data is withdrawal's job, on its own connection with secure_delete ON
            # (protocol/storage/withdrawal.py), which then rewrites the whole file.
            c.execute("PRAGMA secure_delete = FAST")

    def _owner_only(self) -> None:
        """A study was just created in this file (new, or empty before): readable by its owner only."""
        try:
            owner_only(self.path)  # 0600 if ours (Windows: the folder's ACL holds; platform_support)
        except OSError:  # (not ours to change: leave it)
            pass

    @property
    def schema_version(self) -> int:
        """The file's ``PRAGMA user_version``."""
        return int(self.conn.execute("PRAGMA user_version").fetchone()[0])

    def _backup_to(self, target: Path) -> None:
        """A consistent copy of the whole database in ``target`` (SQLite's online backup)."""
        dst = sqlite3.connect(str(target))
        try:
            self.conn.backup(dst)
        finally:
            dst.close()

    def _upgrade(self, version: int) -> None:
        """Write a backup copy beside the file, then upgrade the schema in one transaction."""
        assert version in (1, 2, 3), version
        stamp = _dt.datetime.now().strftime("%Y%m%dT%H%M%S")
        backup = self.path.with_name(f"{self.path.stem}.v{version}-backup-{stamp}{self.path.suffix or '.db'}")
        n = 1
        while backup.exists():
            n += 1
            backup = self.path.with_name(f"{self.path.stem}.v{version}-backup-{stamp}-{n}{self.path.suffix or '.db'}")
        try:
            os.close(os.open(backup, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
            self._backup_to(backup)
        except (OSError, sqlite3.Error) as exc:
            with contextlib.suppress(OSError):
                backup.unlink()
            raise StorageError(f"{self.path}: schema version {version} must be upgraded to {SCHEMA_VERSION}, and the "
                               f"backup copy {backup.name} could not be written ({exc}); nothing was changed") from None
        c = self.conn
        c.execute("BEGIN IMMEDIATE")
        try:
            if c.execute("PRAGMA user_version").fetchone()[0] == version:  # not upgraded by another writer meanwhile
                if version == 1:
                    for stmt in _UPGRADE_1_TO_2:
                        c.execute(stmt)
                    try:
                        # v2 keeps one sample per time and trial; a v1 file that already holds duplicates keeps
                        # its index
                        c.execute("SAVEPOINT unique_samples")
                        c.execute("DROP INDEX IF EXISTS samples_by_trial")
                        c.execute("CREATE UNIQUE INDEX samples_by_trial ON samples (trial_id, t_s)")
                        c.execute("RELEASE unique_samples")
                    except sqlite3.IntegrityError:
                        c.execute("ROLLBACK TO unique_samples")
                        c.execute("RELEASE unique_samples")
                if version <= 2:
                    for stmt in _UPGRADE_2_TO_3:
                        c.execute(stmt)
                for stmt in _UPGRADE_3_TO_4:
                    c.execute(stmt)
                c.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
            c.execute("COMMIT")
        except BaseException:
            c.execute("ROLLBACK")
            raise
        self.upgraded_from, self.backup_path = version, backup


def _widen_abort_causes(conn: sqlite3.Connection) -> None:
    """A file made before an abort cause was added (``participant_screen``): its ``trials`` CHECK lists the causes
    of its time, and a trial aborted for the new cause would be refused at its insert.  A writer widens the list.

    SQLite keeps a CHECK only in the table's SQL text, so widening it changes no stored row and no page of data:
    the text is replaced in the schema table, as SQLite documents for changes that do not alter the stored content
    (``PRAGMA writable_schema``, the schema version bumped so every connection reads the new text), in one
    transaction; every row already stored satisfies the wider list.
    """
    row = conn.execute("SELECT sql FROM sqlite_master WHERE type = 'table' AND name = 'trials'").fetchone()
    if row is None or _CAUSES_BEFORE not in str(row[0]):
        return  # made or widened with the list of now
    conn.execute("BEGIN IMMEDIATE")
    try:
        row = conn.execute("SELECT sql FROM sqlite_master WHERE type = 'table' AND name = 'trials'").fetchone()
        if _CAUSES_BEFORE in str(row[0]):  # not widened by another writer meanwhile
            version = int(conn.execute("PRAGMA schema_version").fetchone()[0])
            conn.execute("PRAGMA writable_schema = ON")
            conn.execute("UPDATE sqlite_master SET sql = ? WHERE type = 'table' AND name = 'trials'",
                         (str(row[0]).replace(_CAUSES_BEFORE, _CAUSES_NOW),))
            conn.execute(f"PRAGMA schema_version = {version + 1}")
            conn.execute("PRAGMA writable_schema = OFF")
        conn.execute("COMMIT")
    except BaseException:
        conn.execute("ROLLBACK")
        raise
