"""``haptic-study check``: verify a whole study database and say what was found.

SQLite's integrity check, every recorded block's checksum and decoding, every
trial against the recording, and every experiment session's trials against its
design (:mod:`protocol.storage.audit`).  Read only: the file is never changed.  Exit 0
when clean, 1 when problems were found, 2 when the input cannot be checked (no
such file, not a study database).
"""

from __future__ import annotations

import argparse
import json
import sys

from study_app.cli.argtypes import add_command
from study_app.cli.error import CliError

__all__ = ["add_check_parser", "cmd_check", "format_audit"]


def add_check_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``check``."""
    c = add_command(sub, "check", "verify a study database: SQLite's integrity check, every recorded block's "
                    "checksum and decoding, trials against the recording and the design",
                    "haptic-study check --db study.db\nhaptic-study check --db study.db --json",
                    "Verify a whole study database, read only, and say what was found: exit 0 when it is clean, "
                    "1 when problems were found, 2 when it cannot be checked")
    c.add_argument("--db", required=True, metavar="PATH", help="study database")
    c.add_argument("--json", action="store_true", help="print what was found as one JSON object")
    c.set_defaults(handler=cmd_check)


def format_audit(a: object) -> str:
    """The findings in words (an :class:`protocol.storage.audit.Audit`)."""
    from protocol.storage.audit import Audit
    from protocol.study.labels import plural

    assert isinstance(a, Audit)
    lines = [(f"{a.path}: schema version {a.schema_version}, {plural(a.sessions, 'session')} "
              f"({a.experiment_sessions} experiment), {plural(a.trials, 'trial')}")]
    lines.append("  SQLite integrity check: " + ("ok" if a.integrity == ["ok"] else "; ".join(a.integrity)))
    if a.schema_version >= 3 and a.integrity == ["ok"]:
        lines.append(f"  recorded blocks: {a.blocks_verified:,} verified by their checksum, "
                     f"{a.blocks_unverifiable:,} without one (written before version 4) decoded, "
                     f"{len(a.damage)} damaged stretch{'' if len(a.damage) == 1 else 'es'}")
        lines += [f"    damaged: {d.describe()}" for d in a.damage]
        lines.append(f"  trials against the recording: {a.trials_in_recording:,} in readable records, "
                     f"{len(a.trials_not_in_recording)} not")
        lines += [f"    {t}" for t in a.trials_not_in_recording]
    if a.integrity == ["ok"]:
        lines.append(f"  designed cells: full in {a.cells_complete} of {a.experiment_sessions} experiment sessions")
    other = [p for p in a.problems if not p.startswith(("recording damaged:", "SQLite integrity check:"))
             and p not in a.trials_not_in_recording]
    lines += [f"  problem: {p}" for p in other]
    lines += [f"  note: {n}" for n in a.notes]
    lines.append("No problem found." if not a.problems else f"{plural(len(a.problems), 'problem')} found.")
    return "\n".join(lines)


def cmd_check(args: argparse.Namespace) -> int:
    """Run ``haptic-study check``; errors raise :class:`CliError`."""
    from protocol.storage import StorageError, StudyDatabase
    from protocol.storage.audit import audit_database
    from protocol.study.labels import plural
    from study_app.cli.progress import ProgressBar

    try:
        db = StudyDatabase(args.db, readonly=True, check=False)  # the full integrity check is the first finding
    except StorageError as exc:
        raise CliError(str(exc)) from None
    bar: ProgressBar | None = None

    def progress(done: int, total: int) -> None:
        nonlocal bar
        if total < 500:
            return  # quick: no bar
        if bar is None:
            bar = ProgressBar(total, "check: decoding the recorded blocks", "blocks", decimals=0)
        bar.update(done)

    try:
        # which running sessions another process writes now: in progress, not interrupted (as `sessions` says)
        audit = audit_database(db.conn, args.db, progress, writers=db.sessions_being_written())
    finally:
        db.close()
        if bar is not None:
            bar.close()
    if args.json:
        print(json.dumps(audit.to_json()))
    else:
        print(format_audit(audit))
    if audit.problems and not args.json:
        print(f"haptic-study: check: {plural(len(audit.problems), 'problem')} found in {args.db}", file=sys.stderr)
    return 1 if audit.problems else 0
