"""The ``haptic-study`` command line.

Each command group registers its own parser beside its command (``study_app/*_cmds.py``) and sets the
parser's ``handler``; this module assembles them in the order ``--help`` lists them and runs the handler.
Subcommands import their machinery lazily, so ``haptic-study --help`` and the headless commands never load Qt.

Commands from outside the product -- the benchmarks, ``haptic-study bench`` -- are found by name at run time
in the entry-point group :data:`COMMANDS_GROUP` (``pyproject.toml``): the product imports nothing from
``bench``, and an install without it says so in one line.
"""

from __future__ import annotations

import argparse
import os
import stat
import sys
from collections.abc import Sequence

from study_app.cli.argtypes import OneLineParser, one_line
from study_app.cli.calibrate_cmds import add_calibrate_command
from study_app.cli.check_cmds import add_check_parser
from study_app.cli.discrimination_cmds import add_discrimination_parser
from study_app.cli.error import CliError
from study_app.cli.gui_cmds import add_gui_parser
from study_app.cli.hardware_cmds import add_check_hardware_parser, add_probe_parser
from study_app.cli.note_cmds import add_note_parser
from study_app.cli.power_cmds import add_power_parser
from study_app.cli.qualify_cmds import add_qualify_parser
from study_app.cli.replay_cmds import add_replay_parsers
from study_app.cli.report_cmds import add_report_parsers
from study_app.cli.run_cmds import add_run_parser, add_sessions_parser, add_sim_parser
from study_app.cli.sweep_cmds import add_sweep_parser
from study_app.cli.terminal import safe_standard_streams
from study_app.cli.withdraw_cmds import add_withdraw_parser
from study_app.version_info import version_text

__all__ = [
    "COMMANDS_GROUP",
    "build_parser",
    "main",
    "version_text",
]

#: The entry-point group through which an installed package adds subcommands: each entry point names a
#: function ``register(sub)`` that adds its parsers to the ``haptic-study`` subparsers, every leaf with a
#: ``handler`` default (``bench = "bench.commands:register"``).
COMMANDS_GROUP = "haptic_study.commands"
#: Commands an install may leave out, with what they are: without their package, one line and exit 2.
_OPTIONAL_COMMANDS = {"bench": "benchmarks"}


class _VersionAction(argparse.Action):
    """``--version``: the installed version, and the commit when run from a git checkout (computed when asked)."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS, **_: object) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS,
                         help="print the version (and the git commit of a checkout) and exit")

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"haptic-study {version_text()}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    p = OneLineParser(
        prog="haptic-study",
        description="Force-feedback training study: haptic pipeline, simulated rig, protocol, analysis, GUI.",
        epilog="'haptic-study COMMAND --help' describes a command, with an example.",
    )
    p.add_argument("--version", action=_VersionAction)
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for add in (add_sim_parser, add_run_parser, add_report_parsers, add_replay_parsers, add_sessions_parser,
                add_check_parser, add_withdraw_parser, add_note_parser, add_power_parser, add_sweep_parser,
                add_discrimination_parser,
                _add_installed_commands, add_probe_parser, add_check_hardware_parser,
                add_qualify_parser, add_calibrate_command,
                add_gui_parser):
        add(sub)
    return p


def _add_installed_commands(sub: argparse._SubParsersAction) -> None:
    """The commands registered in :data:`COMMANDS_GROUP`, by name; an optional one that is absent says so."""
    from importlib.metadata import entry_points

    registered = set()
    for ep in sorted(entry_points(group=COMMANDS_GROUP), key=lambda e: e.name):
        if ep.name in registered:  # a name registered twice: the first (by sort order) is the command
            continue
        try:
            register = ep.load()
        except ModuleNotFoundError as exc:
            if exc.name is None or not (ep.module + ".").startswith(exc.name + "."):
                raise  # a module the command itself imports is missing: a broken install, shown as it is
            continue  # the package the entry point names is not installed: as if unregistered
        register(sub)
        registered.add(ep.name)
    for name, what in _OPTIONAL_COMMANDS.items():
        if name not in registered:
            _add_absent_command(sub, name, what)


def _add_absent_command(sub: argparse._SubParsersAction, name: str, what: str) -> None:
    """``name`` whose package is not installed: any use of it is one line naming what is missing, exit 2."""

    def absent(args: argparse.Namespace) -> int:
        raise CliError(f"{name}: the {what} are not part of this install (the '{name}' package and its entry "
                       f"point in '{COMMANDS_GROUP}'); install haptic-study from its source tree: pip install -e .")

    a = sub.add_parser(name, help=f"{what} (not installed)")
    a.add_argument("rest", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    a.set_defaults(handler=absent)


#: Options that name an input file, and what it must be: a FIFO, socket or device there is refused up front
#: (SQLite and the TOML reader would wait on a FIFO for ever).
_INPUT_FILES = {"db": "database", "protocol": "protocol", "hardware": "hardware"}


def _refuse_special_inputs(args: argparse.Namespace) -> None:
    """An input path that is a FIFO, a socket or a device, or a bad worker count or real-time switch in the
    environment: one line (a missing file is each command's to say)."""
    from foundation.oserrors import kind_of
    from foundation.parallel import workers_env_problem
    from pipeline.core.clock import loop_cpu_problem, realtime_env_problem

    for problem in (workers_env_problem(), realtime_env_problem(), loop_cpu_problem()):
        if problem is not None:
            raise CliError(problem)

    for option, what in _INPUT_FILES.items():
        value = getattr(args, option, None)
        for path in value if isinstance(value, list) else [value]:
            if not isinstance(path, str):
                continue
            try:
                mode = os.stat(path).st_mode
            except (OSError, ValueError):
                continue
            if stat.S_ISFIFO(mode) or stat.S_ISSOCK(mode) or stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
                raise CliError(f"--{option} {path}: is {kind_of(mode)}, not a {what} file; give the path of a "
                               "regular file")


def _machine_failure(args: argparse.Namespace, exc: BaseException) -> str | None:
    """One line for a failure of the machine under a command (a full disk, a failing device, memory), else None.

    The commands handle what they expect; this is the net under all of them.
    """
    import errno
    import sqlite3

    from foundation.oserrors import os_error_line

    db = getattr(args, "db", None)
    db = db[0] if isinstance(db, list) and len(db) == 1 else db
    again = (" then complete the study with the same command and --continue (what was committed is kept)"
             if getattr(args, "command", "") == "run" else " then run it again")
    if isinstance(exc, MemoryError):
        return f"{args.command}: out of memory; close other programs or ask for less, then run it again"
    if isinstance(exc, sqlite3.OperationalError):
        text = str(exc)
        known = {"database or disk is full": errno.ENOSPC, "disk I/O error": errno.EIO,
                 "attempt to write a readonly database": errno.EROFS, "unable to open database file": errno.EACCES}
        code = next((c for k, c in known.items() if k in text), None)
        if code is None:
            return None
        line = os_error_line(OSError(code, text), f"--db {db}" if isinstance(db, str) else "the database",
                             f"SQLite says '{text}'", written=True)
        return f"{line};{again}" if code != errno.EACCES else line
    if isinstance(exc, OSError):
        where = exc.filename if exc.filename is not None else (f"--db {db}" if isinstance(db, str) else args.command)
        return os_error_line(exc, where, "failed", written=True)
    return None


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``haptic-study`` console script."""
    import sqlite3

    safe_standard_streams()  # before anything is printed, --help included
    args = build_parser().parse_args(argv)
    try:
        _refuse_special_inputs(args)
        return args.handler(args)  # every leaf parser sets one; argparse enforces a known command
    except CliError as exc:
        print(f"haptic-study: error: {one_line(str(exc))}", file=sys.stderr)  # a path may hold a line break
        return exc.status
    except KeyboardInterrupt:
        print("haptic-study: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader went away (``| head``): not an error of ours; point stdout at nothing so that the
        # interpreter's final flush does not raise again
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except (OSError, MemoryError, sqlite3.OperationalError) as exc:
        line = _machine_failure(args, exc)
        if line is None:
            raise
        print(f"haptic-study: error: {one_line(line)}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    # ``python -m study_app.cli.main``: CliError lives in study_app.cli.error, so this __main__ copy of the module
    # catches the one the subcommand modules raise
    sys.exit(main())
