"""``haptic-study export participant``: everything stored about one participant, for a subject-access request.

Registered beside ``export samples`` (:mod:`study_app.cli.replay_cmds`); the export itself is
:mod:`analysis.export.participant_export`, written under the output policy of :mod:`foundation.outdir` (a new folder, or
one this command wrote before with ``--force``; nothing else in it replaced; owner-only files).
"""

from __future__ import annotations

import argparse
import sys

from foundation.errors import InputRefused
from protocol.study.labels import plural
from study_app.cli.argtypes import add_command
from study_app.cli.error import CliError

__all__ = ["add_export_participant_parser", "cmd_export_participant"]


def add_export_participant_parser(esub: argparse._SubParsersAction) -> None:
    """Register ``export participant`` under ``export``."""
    from study_app.cli.withdraw_cmds import participant_code_arg

    ep = add_command(
        esub, "participant", "everything stored about one participant, in open formats (a subject-access request)",
        "haptic-study export participant --db study.db --participant P02 --out P02-data\n"
        "haptic-study export participant --db study.db --participant P02 --format parquet --out P02-data",
        "Write everything the study database holds about one participant into a new folder: a table per kind of "
        "record (their participant row, sessions, trials as stored and as the report analyses them, events, every "
        "1 kHz record, the robot poses and the recording's log, recorded runs and blocks), a JSON of their "
        "sessions' protocol, schedule, configuration and calibration, and a codebook of every column",
    )
    ep.add_argument("--db", required=True, metavar="PATH", help="study database")
    ep.add_argument("--participant", required=True, type=participant_code_arg, metavar="CODE",
                    help="the participant's code")
    ep.add_argument("--format", choices=("csv", "parquet"), default="csv", help="table format (default csv)")
    ep.add_argument("--out", required=True, metavar="DIR", help="folder to write (new, or empty)")
    ep.add_argument("--force", action="store_true",
                    help="replace an earlier export in DIR (only the files it wrote there, unedited)")
    ep.set_defaults(handler=cmd_export_participant)


def cmd_export_participant(args: argparse.Namespace) -> int:
    """Run ``haptic-study export participant``; errors raise :class:`CliError`."""
    from analysis.export.participant_export import PARTICIPANT_MARKER, participant_export, write_participant_export
    from foundation.outdir import check_output_folder

    def policy(call):
        try:
            return call()
        except InputRefused as exc:
            raise CliError(str(exc), getattr(exc, "status", 2)) from None

    policy(lambda: check_output_folder(args.out, command="export participant", marker=PARTICIPANT_MARKER,
                                       inputs=[args.db], force=args.force))  # before the work
    if args.format == "parquet":
        try:
            import pyarrow  # noqa: F401
        except ImportError:
            raise CliError("--format parquet needs pyarrow (pip install pyarrow); or use --format csv") from None
    if sys.stderr.isatty():
        print(f"export: reading everything stored about {args.participant} ...", file=sys.stderr, flush=True)
    export = policy(lambda: participant_export(args.db, args.participant))
    files = policy(lambda: write_participant_export(export, args.out, fmt=args.format, inputs=(args.db,),
                                                    force=args.force))
    t = export.tables
    print(f"Wrote {args.out}/ for {args.participant}: {plural(len(t['sessions']), 'session')}, "
          f"{plural(len(t['stored_trials']), 'trial')}, {plural(len(t['events']), 'event')}, "
          f"{plural(len(t['samples']), 'record')} at 1 kHz; files: {', '.join(files)}")
    for line in export.damage:
        print(f"haptic-study: recording damaged: {line}: left out of {args.out}", file=sys.stderr)
    return 1 if export.damage else 0
