"""``haptic-study withdraw``: a participant withdraws, and every trace of their data leaves the study database.

What it does, in order (:mod:`protocol.storage.withdrawal` holds the storage half):

1. a read-only look decides every refusal first -- no such participant, one who already withdrew, a session of
   theirs (or any writer of the study) running -- so a refused command leaves the file byte-identical;
2. it says what will go and asks for the code to be typed again (``--yes CODE`` in a script);
3. under the study's one-writer lease it removes every row of theirs in one transaction, bytes overwritten, and
   stores the withdrawal record (code, time, reason, counts removed);
4. it rewrites the file (``VACUUM``) and empties its write-ahead log, so nothing of theirs can be read back from
   the database, and names what else on disk may still hold their data (upgrade backups beside the database,
   copies, reports and exports made earlier): files it did not make are never deleted.

If step 4 did not finish -- a program reading the study held it up, or the command was stopped (killed, a power
cut) after step 3's commit -- the same command run again finds the withdrawal record and a file still to rewrite
(a non-empty log, free pages) and finishes the rewrite.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from study_app.cli.argtypes import add_command
from study_app.cli.error import CliError

__all__ = ["add_withdraw_parser", "cmd_withdraw", "participant_code_arg"]

#: The longest reason stored (a sentence or two: the record is not the place for a case history).
REASON_MAX = 500


def participant_code_arg(text: str) -> str:
    """An argument type: a participant code (:func:`protocol.storage.validate_code`: NFKC, stripped)."""
    from protocol.storage import StorageError, validate_code

    try:
        return validate_code(text)
    except StorageError as exc:
        raise argparse.ArgumentTypeError(str(exc).replace("participant code = ", "")) from None


def _reason(text: str) -> str:
    text = text.strip()
    if not text:
        raise argparse.ArgumentTypeError("must not be empty: say why, in a few words (no personal data)")
    if len(text) > REASON_MAX:
        raise argparse.ArgumentTypeError(f"{len(text)} characters; at most {REASON_MAX} are stored")
    if not text.isprintable():
        raise argparse.ArgumentTypeError("must be one line of printable text")
    return text


def add_withdraw_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``withdraw``."""
    w = add_command(
        sub, "withdraw", "a participant withdraws: erase every trace of their data from the study database",
        'haptic-study withdraw --db study.db --participant P02 --reason "withdrew consent by e-mail"\n'
        'haptic-study withdraw --db study.db --participant P02 --reason "withdrew consent" --yes P02',
        "Remove everything stored about one participant -- their sessions, trials, events and whole-session "
        "recordings -- so that it cannot be recovered from the database file (the file is rewritten), after a "
        "confirmation that names what will go. A withdrawal record keeps only the code, the time, the reason and "
        "the counts removed; the report lists it. Refused while a session is being written",
    )
    w.add_argument("--db", required=True, metavar="PATH", help="study database")
    w.add_argument("--participant", required=True, type=participant_code_arg, metavar="CODE",
                   help="the participant's code")
    w.add_argument("--reason", required=True, type=_reason, metavar="TEXT",
                   help=f"why, in a few words, stored with the record (no personal data; at most {REASON_MAX} "
                        "characters)")
    w.add_argument("--yes", default=None, metavar="CODE",
                   help="confirm without asking, by typing the participant's code again (for scripts)")
    w.set_defaults(handler=cmd_withdraw)


def _refuse_live_writers(db: Any, path: str) -> None:
    """Withdraw rewrites the whole file: refused while any process writes to the study."""
    from protocol.storage import LeaseHeld

    study = [h for h in db.lease_holders() if h["alive"]]
    if study:
        h = study[0]
        raise LeaseHeld(f"{path}: {'the study in' if h['scope'] == 'study' else h['scope'] + ' of'} this database "
                        f"is being written by process {h['pid']} ({h['command']}); withdraw rewrites the whole "
                        "file, so it waits until nothing writes to it; nothing was changed")


def _look(path: str, code: str) -> Any:
    """The read-only look that decides every refusal: the participant's :class:`Footprint`.

    A participant who already withdrew is refused, unless that withdrawal's rewrite of the file did not finish
    (:func:`protocol.storage.withdrawal.rewrite_pending`: a program reading the study held it up, or the command
    was stopped between the removal and the rewrite): then their :class:`Withdrawal` is returned, and this command
    finishes it.
    """
    from protocol.storage import StorageError, StudyDatabase, StudyReader
    from protocol.storage.codes import stored_clash
    from protocol.storage.withdrawal import footprint, rewrite_pending, withdrawal_of

    if not Path(path).exists():
        raise CliError(f"--db {path}: no such database")
    try:
        db = StudyDatabase(path, readonly=True, check=True)
    except StorageError as exc:
        raise CliError(str(exc)) from None
    try:
        stored_clash(db.conn, code, path)  # p01 for a stored P01: refused, naming it (never a guess)
        done = withdrawal_of(db.conn, code)
        if done is not None and rewrite_pending(db, done):
            _refuse_live_writers(db, path)
            return done  # withdrawn, but the file's rewrite did not finish: this command finishes it
        if done is not None:
            raise CliError(f"--participant {code}: already withdrew from {path} on "
                           f"{done.withdrawn_at[:16].replace('T', ' ')} UTC ({done.counts()} removed then); "
                           "nothing to remove")
        fp = footprint(db.conn, code)
        if fp is None:
            codes = StudyReader.over(db).participant_codes(limit=11)
            listed = ", ".join(codes[:10]) + (", …" if len(codes) > 10 else "")
            raise CliError(f"--participant {code}: no such participant in {path} (participants: {listed or 'none'})")
        writing = db.sessions_being_written()
        for sid, _, _ in fp.sessions:
            if sid in writing:
                raise CliError(f"--participant {code}: session {sid} is running (being written by {writing[sid]}); "
                               "withdraw once it has ended; nothing was changed")
        _refuse_live_writers(db, path)
        return fp
    except StorageError as exc:
        raise CliError(str(exc)) from None
    finally:
        db.close()


def _confirm(args: argparse.Namespace, fp: Any) -> None:
    """The confirmation: ``--yes CODE``, or the code typed at the prompt; anything else changes nothing."""
    code = args.participant
    if args.yes is not None:
        if args.yes != code:
            raise CliError(f"--yes {args.yes!r}: must repeat the participant code {code} to confirm; nothing was "
                           "changed")
        return
    if not sys.stdin.isatty():
        raise CliError(f"withdraw erases data for good: confirm at a terminal, or give --yes {code} in a script; "
                       "nothing was changed")
    print(f"This erases from {args.db}, for good, {fp.describe()}.")
    print("It keeps only a withdrawal record: the code, the time, the reason and these counts.")
    try:
        typed = input(f"Type the participant code ({code}) to erase these data: ").strip()
    except EOFError:
        typed = ""
    if typed != code:
        raise CliError(f"not confirmed (the code typed was not {code}); nothing was changed")


def _other_copies(db_path: str, code: str, made: Path | None = None) -> list[str]:
    """What else on disk may hold the participant's data: lines for the user (files this command did not make)."""
    p = Path(db_path)
    try:
        backups = sorted(q.name for q in (p.parent if str(p.parent) else Path(".")).iterdir()
                         if q.name.startswith(f"{p.stem}.v") and "-backup-" in q.name and q.is_file()
                         and (made is None or q.name != made.name))
    except OSError:
        backups = []
    lines = []
    if backups:
        lines.append(f"  {', '.join(backups)} beside it: the cop{'y' if len(backups) == 1 else 'ies'} kept when the "
                     f"schema was upgraded, with {code}'s data as it was then; not touched (erase "
                     f"{'it' if len(backups) == 1 else 'them'} by hand if your approval requires)")
    lines.append("  copies, backups, reports and exports made earlier hold what they held; this command does not "
                 "touch files it did not make")
    lines.append("  the file system may keep freed blocks of the old file until it reuses them (on an SSD or a "
                 "copy-on-write file system, only an encrypted disk makes them unreadable)")
    return lines


def _reader_line(db_path: str, code: str, removed: bool) -> str:
    from protocol.storage.withdrawal import CHECKPOINT_WAIT_S

    what = (f"{code}'s rows are removed, but their bytes stay in {db_path} and {db_path}-wal until it closes; "
            f"once it has, run this command again to finish rewriting the file" if removed else "nothing was changed")
    return (f"{db_path}: another program is reading the study (a report, an export, a window): withdraw rewrites "
            f"the whole file and waited {CHECKPOINT_WAIT_S:g} s for it; close it and run withdraw again; {what}")


def _erase(db: Any, args: argparse.Namespace, finishing: Any) -> tuple[Any, bool]:
    """Under the study's lease: the participant's rows removed (unless ``finishing``), the file rewritten."""
    from protocol.storage import new_owner_token
    from protocol.storage.withdrawal import erase_participant, mark_rewritten, nobody_reading, rewrite_file

    owner = new_owner_token()
    db.acquire_lease("study", owner, command="haptic-study withdraw")  # no participant code in the lease
    try:
        if finishing is None:
            # the lease's row is in the log now, so a reader's older snapshot holds the log up: found before
            # anything is removed, not after (when it would keep the old pages in the file until it closes)
            if not nobody_reading(db):
                raise CliError(_reader_line(args.db, args.participant, removed=False))
            record = erase_participant(db, args.participant, args.reason)
        else:
            record = finishing
        clean = rewrite_file(db)
        if clean:  # the mark is a changed value in place: it frees no page and holds nothing of theirs
            mark_rewritten(db, record.code)
    finally:
        db.release_lease("study", owner)
    return record, clean and nobody_reading(db)  # the lease's release out of the log too


def cmd_withdraw(args: argparse.Namespace) -> int:
    """Run ``haptic-study withdraw``; errors raise :class:`CliError`."""
    from protocol.storage import StorageError, StudyDatabase
    from protocol.storage.withdrawal import Footprint

    code = args.participant
    found = _look(args.db, code)
    finishing = None if isinstance(found, Footprint) else found
    if finishing is None:
        _confirm(args, found)
    try:
        db = StudyDatabase(args.db)
    except StorageError as exc:
        raise CliError(str(exc)) from None
    notes = []
    if db.upgraded_from is not None:
        notes.append(f"  {db.backup_path}: written by this command before it upgraded the file from schema "
                     f"version {db.upgraded_from}; it holds {code}'s data: delete it once the upgraded file checks "
                     f"clean (haptic-study check --db {args.db})")
    try:
        record, clean = _erase(db, args, finishing)
    except StorageError as exc:
        raise CliError(str(exc)) from None
    finally:
        db.close()
    if not clean:
        raise CliError(_reader_line(args.db, code, removed=True), 1)
    if finishing is not None:
        print(f"{code} had withdrawn ({record.withdrawn_at[:16].replace('T', ' ')} UTC; their rows were removed "
              f"then), and {args.db} still held pages the withdrawal's rewrite drops (a reader held the rewrite up, "
              "or the command was stopped before it ended); the rewrite is finished now: none of their data can be "
              "read back from the database. The withdrawal's record keeps the reason given then.")
        return 0
    print(f"Withdrew {code} from {args.db}: removed {record.counts()}; the file was rewritten and its write-ahead "
          "log emptied, so none of it can be read back from the database.")
    print(f"Kept: the withdrawal record (code {code}, {record.withdrawn_at[:16].replace('T', ' ')} UTC, the reason, "
          "these counts); the report lists it. The other participants keep their numbers and schedules.")
    print("What else may still hold their data:")
    for line in notes + _other_copies(args.db, code, db.backup_path):
        print(line)
    return 0
