"""``haptic-study note``: the experimenter's note on a stored session or one of its trials, added afterwards.

A note written during a session is the GUI's *Note* action (timestamped on the session clock); this command adds
one to a session that has ended or was interrupted -- what the experimenter remembered later, or a deviation
found when the data were looked at.  It appends one row (``t_s`` empty: written after the session) and alters
nothing stored.  Every refusal (no such session or trial, a session being written right now, a note without
text) is decided on a read-only look first and leaves the file byte-identical.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from study_app.cli.argtypes import add_command, whole_number
from study_app.cli.error import CliError

__all__ = ["NOTE_MAX", "add_note_parser", "cmd_note"]

#: The longest note, in characters.
NOTE_MAX = 2000


def _text(text: str) -> str:
    """An argument type: a note's text, one line, not empty, at most :data:`NOTE_MAX` characters."""
    stripped = " ".join(text.split())
    if not stripped or len(stripped) > NOTE_MAX:
        raise argparse.ArgumentTypeError(f"TEXT = {text[:40]!r}: must be the note's words, 1 to {NOTE_MAX} "
                                         "characters")
    return stripped


def add_note_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``note``."""
    n = add_command(
        sub, "note", "add the experimenter's note to a stored session or one of its trials (appended afterwards)",
        'haptic-study note --db study.db --session 4 --trial 7 "participant sneezed at the cue"\n'
        'haptic-study note --db study.db --session 4 --deviation "tool re-mounted between blocks"',
        "Add a note to a session that has ended or was interrupted, or to one of its trials (numbered from 1, as "
        "in the report). The note is appended (its session time is empty: written afterwards) and nothing stored "
        "is changed; --deviation lists it among the report's deviations from the protocol. A note during a "
        "session is the GUI's Note action",
    )
    n.add_argument("--db", required=True, metavar="PATH", help="study database")
    n.add_argument("--session", required=True, type=whole_number("--session", 1, 2**62), metavar="N",
                   help="the session's id (haptic-study sessions lists them)")
    n.add_argument("--trial", type=whole_number("--trial", 1, 10**6), default=None, metavar="K",
                   help="the trial it is about, numbered from 1 (default: the session)")
    n.add_argument("--deviation", action="store_true", help="a deviation from the protocol: the report lists it")
    n.add_argument("text", type=_text, metavar="TEXT", help=f"the note (at most {NOTE_MAX} characters)")
    n.set_defaults(handler=cmd_note)


def _look(args: argparse.Namespace) -> None:
    """Every refusal, on a read-only look."""
    from protocol.storage import StorageError, StudyDatabase, StudyReader

    if not Path(args.db).exists():
        raise CliError(f"--db {args.db}: no such database")
    try:
        db = StudyDatabase(args.db, readonly=True, check=True)
    except StorageError as exc:
        raise CliError(str(exc)) from None
    try:
        info = StudyReader.over(db).session(args.session)
        if info is None:
            ids = StudyReader.over(db).session_ids()
            raise CliError(f"--session {args.session}: no such session in {args.db} (sessions: "
                           f"{', '.join(map(str, ids[:12])) or 'none'}{', …' if len(ids) > 12 else ''})")
        writer = db.sessions_being_written().get(args.session)
        if writer is not None:
            raise CliError(f"--session {args.session}: is being run right now by {writer}; note it there (the "
                           "GUI's Note action) or once it has ended; nothing was changed")
        n = len(_schedule(info))
        if args.trial is not None and args.trial > n:
            raise CliError(f"--trial {args.trial}: session {args.session} has trials 1 to {n}; nothing was changed")
    finally:
        db.close()


def _schedule(info: Any) -> list[Any]:
    import json

    return list(json.loads(info.schedule_json))


def cmd_note(args: argparse.Namespace) -> int:
    """Run ``haptic-study note``; errors raise :class:`CliError`."""
    from protocol.storage import StorageError, StudyDatabase
    from protocol.storage.annotations import Note, insert_note

    _look(args)
    trial_index = None if args.trial is None else args.trial - 1
    try:
        db = StudyDatabase(args.db)
        try:
            with db.transaction():
                insert_note(db.conn, Note(args.session, None, trial_index, args.text, args.deviation, ""))
        finally:
            db.close()
    except StorageError as exc:
        raise CliError(str(exc)) from None
    about = "the session" if trial_index is None else f"trial {args.trial}"
    mark = " (a deviation: the report lists it)" if args.deviation else ""
    print(f"Noted on session {args.session}, {about}{mark}: {args.text}")
    return 0
