"""``haptic-study bench ...``: the benchmarks' subcommands, added to the product's command line from outside.

The product imports nothing from ``bench``: ``pyproject.toml`` names
:func:`register` in the entry-point group ``haptic_study.commands``, and
``study_app.cli.main`` calls what that group names while it builds its parser.
The dependency runs one way, bench → product, and an install without
``bench`` still has a working ``haptic-study`` (``bench`` then says so).

Each benchmark's machinery is imported when it runs: ``haptic-study --help``
loads none of it.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Callable

from study_app.cli.argtypes import add_command, positive_seconds, seconds_or_zero, whole_number
from study_app.cli.error import CliError
from study_app.cli.power_cmds import whole_option

__all__ = ["register"]


def _say(line: str) -> None:
    print(f"bench: {line}", file=sys.stderr, flush=True)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``bench`` and its benchmarks to the ``haptic-study`` subcommands (the entry point's target)."""
    b = add_command(sub, "bench", "benchmarks (see README for recorded figures)",
                    "haptic-study bench pipeline --loop-seconds 15\nhaptic-study bench report --db study.db")
    bsub = b.add_subparsers(dest="bench", metavar="BENCH")
    bsub.required = True
    for add in (_add_pipeline, _add_loop, _add_lsl, _add_study, _add_report, _add_power, _add_stats, _add_gui):
        add(bsub)


# -- bench pipeline --------------------------------------------------------------------------------------
def _add_pipeline(bsub: argparse._SubParsersAction) -> None:
    bp = add_command(bsub, "pipeline", "per-tick cost vs NumPy, 1 kHz loop timing, filter trade table",
                     "haptic-study bench pipeline --loop-seconds 15 --explain")
    bp.add_argument("--json", action="store_true", help="print one JSON object")
    bp.add_argument("--loop-seconds", type=seconds_or_zero("--loop-seconds", 3600.0, "skips the loop"),
                    default=None,
                    help="real time to run the loop (default 30, with --reference-tree 0; 0 skips)")
    bp.add_argument("--explain", action="store_true",
                    help="name the cause of every loop tick over 100 µs late (costs the loop ~30 µs per tick)")
    bp.add_argument("--reference", action="store_true",
                    help="then run an empty loop as long: the machine's own floor for the loop figures")
    bp.add_argument("--ticks", type=whole_number("--ticks", 2000, 10_000_000), default=20_000,
                    help="samples for the cost benchmark")
    bp.add_argument("--reference-tree", default=None, metavar="TREE",
                    help="a source tree of another version (e.g. a git worktree of main): its per-tick figures are "
                         "measured in turn with ours, in fresh processes, in the same run")
    bp.add_argument("--rounds", type=whole_number("--rounds", 1, 100), default=5,
                    help="with --reference-tree: rounds of ours and theirs in turn (default 5)")
    bp.set_defaults(handler=_cmd_pipeline)


def _cmd_pipeline(args: argparse.Namespace) -> int:
    from bench.pipeline_bench import format_pipeline_bench, run_pipeline_bench

    def say(msg: str) -> None:
        _say(f"{msg} ...")

    if args.reference_tree is not None:
        return _pipeline_against(args, say)
    result = run_pipeline_bench(
        loop_seconds=30.0 if args.loop_seconds is None else args.loop_seconds, ticks=args.ticks, progress=say,
        explain=args.explain, reference=args.reference,
    )
    if args.json:
        print(json.dumps(result))
    else:
        print(format_pipeline_bench(result))
    return 0


def _pipeline_against(args: argparse.Namespace, say: Callable[[str], None]) -> int:
    from bench.pipeline_reference import format_reference, run_reference

    tree = args.reference_tree
    if not os.path.isfile(os.path.join(tree, "bench", "pipeline_bench.py")):
        raise CliError(f"--reference-tree = {tree!r}: not a haptic-study source tree (no bench/pipeline_bench.py)")
    if args.explain or args.reference:
        raise CliError("--explain and --reference apply to a run without --reference-tree")
    result = run_reference(tree, rounds=args.rounds, loop_seconds=args.loop_seconds or 0.0, ticks=args.ticks,
                           progress=say)
    print(json.dumps(result) if args.json else format_reference(result))
    return 0


# -- bench loop -----------------------------------------------------------------------------------------
def _add_loop(bsub: argparse._SubParsersAction) -> None:
    bl = add_command(bsub, "loop", "the 1 kHz loop beside a load (busy processes, a report, a GUI plotting): period "
                     "distribution, missed slots, gap aborts; another version in the same run",
                     "haptic-study bench loop --load busy=2,report,gui --reference-tree ../ref-loop\n"
                     "haptic-study bench loop --load none --no-session --seconds 30")
    bl.add_argument("--load", default="busy=2,report,gui", metavar="SPEC",
                    help="the load beside the loop: busy=N (busy processes per CPU), report (a 10-participant "
                         "study's report over and over), gui (the live ring plotted at 30 Hz), or none "
                         "(default busy=2,report,gui)")
    bl.add_argument("--no-session", action="store_true",
                    help="measure --seconds of the loop alone (default: an experiment session of 20 trials)")
    bl.add_argument("--seconds", type=positive_seconds("--seconds", 3600.0), default=None,
                    help="with --no-session: how long each measurement (default 30); with a session: its cap "
                         "(default 900)")
    bl.add_argument("--reference-tree", default=None, metavar="TREE",
                    help="a source tree of another version (e.g. a git worktree of main): measured in turn with ours, "
                         "under the same load, in the same run")
    bl.add_argument("--rounds", type=whole_number("--rounds", 1, 20), default=1,
                    help="rounds of ours and the reference in turn (default 1)")
    bl.add_argument("--study-db", default=None, metavar="PATH",
                    help="the study the report load reports on (default: simulate a 10-participant study first)")
    bl.add_argument("--json", action="store_true", help="print one JSON object")
    bl.set_defaults(handler=_cmd_loop)


def _cmd_loop(args: argparse.Namespace) -> int:
    from bench.loop_bench import format_loop_bench, run_loop_bench
    from bench.loop_load import parse_load

    try:
        load = parse_load(args.load)
    except ValueError as exc:
        raise CliError(str(exc)) from None
    tree = args.reference_tree
    if tree is not None and not os.path.isfile(os.path.join(tree, "study_app", "engine", "client.py")):
        raise CliError(f"--reference-tree = {tree!r}: not a haptic-study source tree (no study_app/engine/client.py)")
    if args.study_db is not None and not os.path.isfile(args.study_db):
        raise CliError(f"--study-db = {args.study_db!r}: no such file")
    seconds = args.seconds if args.seconds is not None else (30.0 if args.no_session else 900.0)
    result = run_loop_bench(seconds=seconds, load=load, session=not args.no_session, reference_tree=tree,
                            rounds=args.rounds, study_db=args.study_db, progress=lambda line: _say(f"{line} ..."))
    print(json.dumps(result) if args.json else format_loop_bench(result))
    return 0


def _add_lsl(bsub: argparse._SubParsersAction) -> None:
    bl = add_command(bsub, "lsl", "a real-clock 20-trial session with the Lab Streaming Layer off and on, alternating "
                     "in the same run: loop p99, gap aborts and the markers' alignment", "haptic-study bench lsl "
                     "--rounds 2")
    bl.add_argument("--rounds", type=whole_number("--rounds", 1, 20), default=1,
                    help="rounds of LSL off and on (alternating which goes first; default 1)")
    bl.add_argument("--seconds", type=positive_seconds("--seconds", 3600.0), default=900.0,
                    help="each session's cap (default 900)")
    bl.add_argument("--json", action="store_true", help="print one JSON object")
    bl.set_defaults(handler=_cmd_lsl)


def _cmd_lsl(args: argparse.Namespace) -> int:
    from bench.lsl_bench import format_lsl_bench, run_lsl_bench
    from protocol.lsl.bus import LslUnavailable, pylsl

    try:
        pylsl()  # without pylsl: its one line saying how to install it, before any work
    except LslUnavailable as exc:
        raise CliError(str(exc)) from None
    result = run_lsl_bench(args.rounds, args.seconds, progress=lambda line: _say(f"{line} ..."))
    print(json.dumps(result) if args.json else format_lsl_bench(result))
    return 0


# -- bench study -----------------------------------------------------------------------------------------
def _add_study(bsub: argparse._SubParsersAction) -> None:
    bs = add_command(bsub, "study", "wall time of a complete simulated study on the virtual clock, and its storage as "
                     "blocks and as rows",
                     "haptic-study bench study --participants 4\n"
                     "haptic-study bench study --reference-tree ../base --rounds 3")
    bs.add_argument("--participants", type=whole_number("--participants", 1, 1000), default=10,
                    help="participants (default 10)")
    bs.add_argument("--reference-tree", default=None, metavar="TREE",
                    help="a source tree of another version: the same seeded study's wall time, ours and its in "
                         "turn, in fresh processes, in the same run (no storage comparison)")
    bs.add_argument("--rounds", type=whole_number("--rounds", 1, 100), default=3,
                    help="with --reference-tree: rounds of ours and theirs in turn (default 3)")
    bs.add_argument("--json", action="store_true", help="print one JSON object")
    bs.set_defaults(handler=_cmd_study)


def _cmd_study(args: argparse.Namespace) -> int:
    from bench.study_bench import format_study_bench, run_study_bench

    tree = args.reference_tree
    if tree is not None:
        if not os.path.isfile(os.path.join(tree, "study_app", "headless", "study.py")):
            raise CliError(f"--reference-tree = {tree!r}: not a haptic-study source tree "
                           "(no study_app/headless/study.py)")
        from bench.study_reference import format_study_reference, run_study_reference

        ref = run_study_reference(tree, participants=args.participants, rounds=args.rounds, log=_say)
        print(json.dumps(ref) if args.json else format_study_reference(ref))
        return 0
    result = run_study_bench(args.participants, log=_say)
    print(json.dumps(result) if args.json else format_study_bench(result))
    return 0


# -- bench report ----------------------------------------------------------------------------------------
def _add_report(bsub: argparse._SubParsersAction) -> None:
    br = add_command(bsub, "report", "report wall time on a 10-participant study, recorded and in the row format "
                     "of versions 1-2; statistics for 10 000 participants",
                     "haptic-study bench report --db study.db")
    br.add_argument("--db", default=None, metavar="PATH",
                    help="study database to report on (default: simulate a 10-participant study first)")
    br.add_argument("--stats-participants", type=whole_number("--stats-participants", 2, 1_000_000), default=10_000,
                    help="participants of the synthetic trial table (default 10000)")
    br.add_argument("--reference", default=None, metavar="TREE",
                    help="a source tree of another version (e.g. a git worktree of main): its report is timed in "
                         "turn with ours on the same database, in the same run")
    br.add_argument("--json", action="store_true", help="print one JSON object")
    br.set_defaults(handler=_cmd_report)


def _cmd_report(args: argparse.Namespace) -> int:
    from bench.analysis_bench import format_report_bench, run_report_bench

    if args.db is not None and not os.path.isfile(args.db):
        raise CliError(f"--db = {args.db!r}: no such file")
    # the command line is study_app/cli.py in trees from before the rooms were split, study_app/cli/ since
    if args.reference is not None and not any(os.path.isfile(os.path.join(args.reference, "study_app", *where))
                                              for where in (("cli.py",), ("cli", "__main__.py"))):
        raise CliError(f"--reference = {args.reference!r}: not a haptic-study source tree (no study_app/cli/)")
    result = run_report_bench(args.db, stats_participants=args.stats_participants, log=_say,
                              reference=args.reference)
    print(json.dumps(result) if args.json else format_report_bench(result))
    return 0


# -- bench power -----------------------------------------------------------------------------------------
def _add_power(bsub: argparse._SubParsersAction) -> None:
    # option values parsed by the command, as ``haptic-study power`` parses its own (study_app.cli.power_cmds)
    b = bsub.add_parser("power", help="power analysis: the vectorised engine against paired_wilcoxon per resample")
    b.add_argument("--db", default=None, metavar="PATH",
                   help="pilot study database (default: a synthetic 10-participant pilot)")
    b.add_argument("--resamples", default="2000", help="resampled studies per n (default 2000)")
    b.add_argument("--reference-resamples", default="100",
                   help="resamples per n for the paired_wilcoxon loop, scaled up (default 100)")
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.set_defaults(handler=_cmd_power)


def _cmd_power(args: argparse.Namespace) -> int:
    from bench.power_bench import format_power_bench, run_power_bench

    if args.db is not None and not os.path.isfile(args.db):
        raise CliError(f"--db = {args.db!r}: no such file")
    resamples = whole_option("--resamples", args.resamples, 1, 1_000_000)
    reference = whole_option("--reference-resamples", args.reference_resamples, 1, resamples)
    _say("timing the power analysis ...")
    result = run_power_bench(args.db, resamples=resamples, reference_resamples=reference)
    print(json.dumps(result) if args.json else format_power_bench(result))
    return 0


# -- bench stats -----------------------------------------------------------------------------------------
def _add_stats(bsub: argparse._SubParsersAction) -> None:
    bst = add_command(bsub, "stats", "analysis.stats on 10 000 pairs: Wilcoxon, Hodges–Lehmann, correlation, Holm",
                      "haptic-study bench stats --json")
    bst.add_argument("--json", action="store_true", help="print one JSON object")
    bst.set_defaults(handler=_cmd_stats)


def _cmd_stats(args: argparse.Namespace) -> int:
    from bench.stats_bench import format_stats_bench, run_stats_bench

    result = run_stats_bench()
    print(json.dumps(result) if args.json else format_stats_bench(result))
    return 0


# -- bench gui -------------------------------------------------------------------------------------------
def _add_gui(bsub: argparse._SubParsersAction) -> None:
    bg = add_command(bsub, "gui", "1 kHz loop timing with and without the GUI attached; GUI stalls and start-up time",
                     "haptic-study bench gui --seconds 20")
    bg.add_argument("--json", action="store_true", help="print one JSON object")
    bg.add_argument("--seconds", type=positive_seconds("--seconds", 3600.0), default=20.0,
                    help="real time per loop measurement (default 20)")
    bg.add_argument("--explain", action="store_true",
                    help="name the cause of every loop tick over 100 µs late (costs the loop ~25 µs per tick)")
    bg.set_defaults(handler=_cmd_gui)


def _cmd_gui(args: argparse.Namespace) -> int:
    from bench.gui_bench import format_gui_bench, run_gui_bench

    _say("measuring the loop without and with the GUI ...")
    result = run_gui_bench(seconds=args.seconds, explain=args.explain)
    print(json.dumps(result) if args.json else format_gui_bench(result))
    return 0
