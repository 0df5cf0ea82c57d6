"""The ``haptic-study`` command line.

Subcommands import their machinery lazily, so ``haptic-study --help`` and the
headless commands never load Qt.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence

from study_app.argtypes import (SQLITE_INTEGER_MAX, OneLineParser, add_command, host_name, one_line, real_number,
                                whole_number)
from study_app.cli_error import CliError

__all__ = ["CliError", "add_command", "main", "version_text"]


# Every number an option takes is bounded here, at parse time (study_app.argtypes): a bad value is one line
# naming the option, the value and what is allowed, before any file or database is touched.
#: Seeds are stored in the study database: at most SQLite's largest INTEGER.
_SEED = whole_number("--seed", 0, SQLITE_INTEGER_MAX, " (the largest integer SQLite stores)")


def _positive_float(name: str, hi: float = 86_400.0):  # type: ignore[no-untyped-def]
    """A finite number of seconds > 0 and ≤ ``hi`` (default one day)."""
    return real_number(name, 0.0, hi, lo_open=True)


def _nonneg_int(name: str, hi: int = SQLITE_INTEGER_MAX):  # type: ignore[no-untyped-def]
    """A whole number from 0 to ``hi`` (default: the largest integer the study database stores)."""
    return whole_number(name, 0, hi)


def _port_number(name: str):  # type: ignore[no-untyped-def]
    """A TCP/UDP port."""
    return whole_number(name, 1, 65535)


def _fault_plan(text: str):  # type: ignore[no-untyped-def]
    from protocol.rehearsal import parse_fault_plan

    try:
        return parse_fault_plan(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


class _VersionAction(argparse.Action):
    """``--version``: the installed version, and the commit when run from a git checkout (computed when asked)."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS, **_: object) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS,
                         help="print the version (and the git commit of a checkout) and exit")

    def __call__(self, parser, namespace, values, option_string=None):  # type: ignore[no-untyped-def]
        print(f"haptic-study {version_text()}")
        parser.exit()


def version_text() -> str:
    """``0.1.0``, or ``0.1.0 (commit 1a2b3c4d, with uncommitted changes)`` in a git checkout."""
    import subprocess
    from pathlib import Path

    from protocol.version import software_version

    text = software_version()
    root = Path(__file__).resolve().parent.parent
    if not (root / ".git").exists():  # an installed copy, not a checkout
        return text
    try:
        def git(*args: str) -> str:
            return subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=5,
                                  check=True).stdout.strip()

        commit = git("rev-parse", "--short=8", "HEAD")
        dirty = bool(git("status", "--porcelain", "--untracked-files=no"))
    except (OSError, subprocess.SubprocessError):
        return text
    return f"{text} (commit {commit}{', with uncommitted changes' if dirty else ''})"


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

    s = add_command(sub, "sim", "run the simulated rig with scripted presses and summarise what the pipeline saw",
                    "haptic-study sim --seconds 30 --seed 1")
    s.add_argument("--seconds", type=_positive_float("--seconds"), default=60.0, help="simulated time (default 60)")
    s.add_argument("--seed", type=_SEED, default=0, help="seed of every random process (default 0)")
    s.add_argument("--clock", choices=("virtual", "real"), default="virtual",
                   help="virtual: as fast as the CPU allows (default); real: paced at 1 kHz")
    s.add_argument("--haptics", choices=("on", "off"), default="on", help="haptic feedback (default on)")
    s.add_argument("--json", action="store_true", help="print the summary as one JSON object")

    r = add_command(sub, "run", "run a complete simulated study into a study database (headless)",
                    "haptic-study run --participants 10 --seed 0 --db study.db\n"
                    "haptic-study run --participants 10 --seed 0 --db study.db --continue   # after an interruption",
                    "Run a complete simulated study (training and experiment sessions of simulated participants on "
                    "the simulated rig) into a study database, headless, and print a summary")
    r.add_argument("--participants", type=whole_number("--participants", 1, 9999), default=10, help="number of simulated participants (default 10)")
    r.add_argument("--seed", type=_SEED, default=0, help="study seed: schedules, rigs and participants (default 0)")
    r.add_argument("--db", required=True, metavar="PATH", help="study database (SQLite); created if missing")
    r.add_argument("--protocol", default=None, metavar="FILE",
                   help="protocol file (default: the paper's study, protocol/default.toml)")
    r.add_argument("--clock", choices=("virtual", "real"), default="virtual",
                   help="virtual: as fast as the CPU allows (default); real: paced at 1 kHz")
    r.add_argument("--jobs", type=whole_number("--jobs", 1, 1024, " (omit it to use the usable cores)"), default=None,
                   help="participants run at once, each in its own process (default: the usable cores; 1: one after the other)")
    after = r.add_mutually_exclusive_group()
    after.add_argument("--resume", metavar="CODE", default=None,
                       help="continue this participant's interrupted session (training or experiment) "
                            "at its first unfinished trial")
    after.add_argument("--continue", dest="continue_study", action="store_true",
                       help="complete a study that stopped part-way in --db: resume interrupted sessions, run what "
                            "was not started (give the --participants, --seed and --protocol it was started with)")
    r.add_argument("--inject-fault", dest="inject_fault", action="append", default=[], type=_fault_plan,
                   metavar="KIND@CODE:TRIAL[+SECONDS]",
                   help="rehearse a fault on the simulated rig, SECONDS (default 3) after the cue of participant "
                        "CODE's TRIAL-th experiment trial; KIND: sensor-stall, nan-burst, bad-status, stale-pose, "
                        "device-error, kill (ends this command as kill -9 would); repeatable")

    from study_app.replay_cmds import add_replay_parsers
    from study_app.report_cmds import add_report_parsers

    add_report_parsers(sub)
    add_replay_parsers(sub)

    ss = add_command(sub, "sessions", "list the sessions of a study database: participant, kind, status, trials",
                     "haptic-study sessions --db study.db")
    ss.add_argument("--db", required=True, metavar="PATH", help="study database")
    ss.add_argument("--json", action="store_true", help="print one JSON array")

    from study_app.power_cmds import add_power_bench_parser, add_power_parser

    add_power_parser(sub)

    b = add_command(sub, "bench", "benchmarks (see README for recorded figures)",
                    "haptic-study bench pipeline --loop-seconds 15\nhaptic-study bench report --db study.db")
    bsub = b.add_subparsers(dest="bench", metavar="BENCH")
    bsub.required = True
    bp = add_command(bsub, "pipeline", "per-tick cost vs NumPy, 1 kHz loop timing, filter trade table",
                     "haptic-study bench pipeline --loop-seconds 15 --explain")
    bp.add_argument("--json", action="store_true", help="print one JSON object")
    bp.add_argument("--loop-seconds", type=real_number("--loop-seconds", 0.0, 3600.0, note=" (0 skips the loop)"), default=30.0,
                    help="real time to run the loop (default 30; 0 skips)")
    bp.add_argument("--explain", action="store_true",
                    help="name the cause of every loop tick over 100 µs late (costs the loop ~30 µs per tick)")
    bp.add_argument("--reference", action="store_true",
                    help="then run an empty loop as long: the machine's own floor for the loop figures")
    bp.add_argument("--ticks", type=whole_number("--ticks", 2000, 10_000_000), default=20_000, help="samples for the cost benchmark")
    bs = add_command(bsub, "study", "wall time of a complete simulated study on the virtual clock, and its storage as "
                     "blocks and as rows",
                     "haptic-study bench study --participants 4")
    bs.add_argument("--participants", type=whole_number("--participants", 1, 1000), default=10, help="participants (default 10)")
    bs.add_argument("--json", action="store_true", help="print one JSON object")
    br = add_command(bsub, "report", "report wall time on a 10-participant study, recorded and in the row format "
                     "of versions 1-2; statistics for 10 000 participants",
                     "haptic-study bench report --db study.db")
    br.add_argument("--db", default=None, metavar="PATH",
                    help="study database to report on (default: simulate a 10-participant study first)")
    br.add_argument("--stats-participants", type=whole_number("--stats-participants", 2, 1_000_000), default=10_000,
                    help="participants of the synthetic trial table (default 10000)")
    br.add_argument("--json", action="store_true", help="print one JSON object")
    add_power_bench_parser(bsub)
    bst = add_command(bsub, "stats", "analysis.stats on 10 000 pairs: Wilcoxon, Hodges–Lehmann, correlation, Holm",
                      "haptic-study bench stats --json")
    bst.add_argument("--json", action="store_true", help="print one JSON object")

    pr = add_command(sub, "probe", "read a real device once and report (no loop)",
                     "haptic-study probe netft --host 192.168.1.1 --samples 1000")
    prsub = pr.add_subparsers(dest="probe", metavar="DEVICE")
    prsub.required = True
    pn = add_command(prsub, "netft", "ATI Net F/T: mean wrench (N, N·m), packet rate, lost/reordered/faulted counts",
                     "haptic-study probe netft --host 192.168.1.1 --samples 1000")
    pn.add_argument("--host", required=True, type=host_name("--host", ipv6=False), help="the Net F/T box's IP address")
    pn.add_argument("--port", type=_port_number("--port"), default=49152, help="RDT UDP port (default 49152)")
    pn.add_argument("--http-port", type=_port_number("--http-port"), default=80, help="web server port for netftapi2.xml (default 80)")
    pn.add_argument("--samples", type=whole_number("--samples", 1, 1_000_000), default=1000, help="samples to average (default 1000)")
    pn.add_argument("--json", action="store_true", help="print one JSON object")

    ch = add_command(sub, "check-hardware", "connect to every device in the hardware file and print its state",
                     "haptic-study check-hardware --hardware hardware.toml")
    ch.add_argument("--hardware", default="hardware.toml", metavar="FILE",
                    help="hardware file (default ./hardware.toml; see hardware.example.toml)")

    bg = add_command(bsub, "gui", "1 kHz loop timing with and without the GUI attached; GUI stalls and start-up time",
                     "haptic-study bench gui --seconds 20")
    bg.add_argument("--json", action="store_true", help="print one JSON object")
    bg.add_argument("--seconds", type=_positive_float("--seconds", 3600.0), default=20.0,
                    help="real time per loop measurement (default 20)")
    bg.add_argument("--explain", action="store_true",
                    help="name the cause of every loop tick over 100 µs late (costs the loop ~25 µs per tick)")

    from study_app.calibrate_cmds import add_calibrate_command

    add_calibrate_command(sub, add_command, _SEED)

    g = add_command(sub, "gui", "the experimenter's window (simulated rig by default)",
                    "haptic-study gui --db study.db\n"
                    "haptic-study gui --rig real --hardware hardware.toml --db study.db\n"
                    "haptic-study gui --screenshot docs/screenshots   # regenerate the guide's screenshots",
                    "Open the experimenter's window: session setup, live force, trial table, device health, the "
                    "participant screen and the calibration wizard (simulated rig by default; see docs/gui.md)")
    g.add_argument("--db", default=None, metavar="PATH", help="study database (SQLite); default: the last one used")
    g.add_argument("--rig", choices=("sim", "real"), default="sim", help="simulated rig (default) or the real hardware")
    g.add_argument("--hardware", default=None, metavar="FILE", help="hardware.toml for --rig real")
    g.add_argument("--screenshot", default=None, metavar="DIR",
                   help="drive a short simulated session offscreen and save PNGs of every main view into DIR")
    g.add_argument("--sim-mount-error-deg", type=real_number("--sim-mount-error-deg", -180.0, 180.0), default=0.0,
                   metavar="DEG", help="simulated rig: mount the sensor turned about its own z axis by DEG without "
                                       "telling the pipeline (rehearse the wizard's frame check failing)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``haptic-study`` console script."""
    args = build_parser().parse_args(argv)
    try:
        if args.command == "sim":
            return _cmd_sim(args)
        if args.command == "run":
            return _cmd_run(args)
        if args.command == "sessions":
            return _cmd_sessions(args)
        if args.command in ("report", "plot-trial"):
            from study_app.report_cmds import cmd_plot_trial, cmd_report

            return cmd_report(args) if args.command == "report" else cmd_plot_trial(args)
        if args.command in ("replay", "plot-session", "export"):
            from study_app.replay_cmds import cmd_export, cmd_plot_session, cmd_replay

            return {"replay": cmd_replay, "plot-session": cmd_plot_session, "export": cmd_export}[args.command](args)
        if args.command == "power" or (args.command == "bench" and args.bench == "power"):
            from study_app.power_cmds import cmd_bench_power, cmd_power

            return cmd_power(args) if args.command == "power" else cmd_bench_power(args)
        if args.command == "bench" and args.bench == "pipeline":
            return _cmd_bench_pipeline(args)
        if args.command == "bench" and args.bench == "report":
            from bench.analysis_bench import format_report_bench, run_report_bench

            if args.db is not None and not os.path.isfile(args.db):
                raise CliError(f"--db = {args.db!r}: no such file")
            result = run_report_bench(args.db, stats_participants=args.stats_participants,
                                      log=lambda line: print(f"bench: {line}", file=sys.stderr, flush=True))
            print(json.dumps(result) if args.json else format_report_bench(result))
            return 0
        if args.command == "gui":
            return _cmd_gui(args)
        if args.command == "bench" and args.bench == "gui":
            from bench.gui_bench import format_gui_bench, run_gui_bench

            print("bench: measuring the loop without and with the GUI ...", file=sys.stderr, flush=True)
            result = run_gui_bench(seconds=args.seconds, explain=args.explain)
            print(json.dumps(result) if args.json else format_gui_bench(result))
            return 0
        if args.command == "bench" and args.bench == "stats":
            from bench.stats_bench import format_stats_bench, run_stats_bench

            result = run_stats_bench()
            print(json.dumps(result) if args.json else format_stats_bench(result))
            return 0
        if args.command == "bench" and args.bench == "study":
            from bench.study_bench import format_study_bench, run_study_bench

            result = run_study_bench(args.participants,
                                     log=lambda line: print(f"bench: {line}", file=sys.stderr, flush=True))
            print(json.dumps(result) if args.json else format_study_bench(result))
            return 0
        if args.command in ("probe", "check-hardware"):
            return _cmd_hardware(args)
        if args.command == "calibrate":
            from study_app.calibrate_cmds import cmd_calibrate

            return cmd_calibrate(args)
    except CliError as exc:
        print(f"haptic-study: error: {one_line(str(exc))}", file=sys.stderr)  # a path may hold a line break
        return 2
    except KeyboardInterrupt:
        print("haptic-study: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader went away (``| head``): not an error of ours; point stdout at nothing so that the
        # interpreter's final flush does not raise again
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    return 1  # pragma: no cover - argparse enforces a known command


def _cmd_sim(args: argparse.Namespace) -> int:
    from study_app.progress import ProgressBar
    from study_app.sim_summary import run_scripted_sim

    bar = None if args.json else ProgressBar(args.seconds, "simulating", "s")
    summary = run_scripted_sim(
        seconds=args.seconds, seed=args.seed, clock=args.clock, haptics_on=args.haptics == "on",
        progress=None if bar is None else bar.update,
    )
    if bar is not None:
        bar.close()
    if args.json:
        print(json.dumps(summary, indent=None))
    else:
        from study_app.sim_summary import format_summary

        print(format_summary(summary))
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    from protocol.config import ProtocolError, load_protocol
    from protocol.storage import StorageError
    from study_app.headless import SessionInterrupted, StudyWorkerError, resume_session, run_study
    from study_app.progress import ProgressBar
    from study_app.study_summary import format_study_summary

    if args.resume is not None:
        for f in args.inject_fault:
            if f.code != args.resume:
                raise CliError(f"--inject-fault = {f}: participant {f.code} is not the one resumed ({args.resume})")
    bar: ProgressBar | None = None
    try:
        if args.resume is None:
            protocol = load_protocol(args.protocol)

        def show(p):  # type: ignore[no-untyped-def]
            nonlocal bar
            if bar is None:
                bar = ProgressBar(p.study_trials_total, "study", "trials", decimals=0)
            bar.label = f"{p.code} {p.kind:<10} trial {p.trials_done:>2}/{p.trials_total:<2}"
            bar.update(p.study_trials_done)

        import time as _time

        t0 = _time.perf_counter()
        if args.resume is not None:
            progress = resume_session(args.db, args.resume, clock=args.clock, on_progress=show,
                                      faults=args.inject_fault)
        else:
            progress = run_study(
                args.db, participants=args.participants, seed=args.seed, protocol=protocol, clock=args.clock,
                on_progress=show, jobs=args.jobs, continue_study=args.continue_study, faults=args.inject_fault,
            )
        wall = _time.perf_counter() - t0
        if bar is not None:
            bar.close()
    except SessionInterrupted as exc:
        if bar is not None:
            bar.close()
        print(f"haptic-study: interrupted: {exc}; complete it with the same command and --continue "
              "(or --resume CODE)", file=sys.stderr)
        return 1
    except (ProtocolError, StorageError, StudyWorkerError, ValueError) as exc:
        if bar is not None:
            bar.close()
        raise CliError(str(exc)) from None
    for note in progress.notes:
        print(f"haptic-study: {note}", file=sys.stderr)
    if args.continue_study and progress.study_trials_total == 0:
        print(f"haptic-study: nothing to continue in {args.db}: every session of participants "
              f"1–{args.participants} has ended", file=sys.stderr)
    print(format_study_summary(args.db, progress.sessions, wall))
    for line in progress.rehearsals:
        print(f"Fault rehearsal {line}")
    return 0


def _cmd_sessions(args: argparse.Namespace) -> int:
    from protocol.storage import StorageError
    from study_app.session_list import format_sessions, list_sessions

    if not os.path.isfile(args.db):
        raise CliError(f"--db = {args.db!r}: no such file")
    try:
        sessions = list_sessions(args.db)
    except StorageError as exc:
        raise CliError(str(exc)) from None
    print(json.dumps(sessions) if args.json else format_sessions(args.db, sessions))
    return 0


def _cmd_hardware(args: argparse.Namespace) -> int:
    from study_app.hardware_cmds import HardwareCmdError, check_hardware, format_check, format_probe, probe_netft

    try:
        if args.command == "probe":
            result = probe_netft(args.host, args.port, args.http_port, args.samples)
            print(json.dumps(result) if args.json else format_probe(result))
            return 0
        rows, ok = check_hardware(args.hardware)
    except HardwareCmdError as exc:
        raise CliError(str(exc)) from None
    print(format_check(rows))
    return 0 if ok else 1


def _cmd_gui(args: argparse.Namespace) -> int:
    import os

    from study_app.engine_host import HostConfig

    if args.rig == "real" and args.hardware is None:
        raise CliError("--rig real needs --hardware FILE (the hardware.toml of the lab; see hardware.example.toml)")
    if args.hardware is not None and not os.path.isfile(args.hardware):
        raise CliError(f"--hardware = {args.hardware!r}: no such file")
    if args.rig == "real":
        # validated here, before any window opens: a bad field is one line and exit 2
        from pipeline.hardware import HardwareError, load_hardware

        try:
            load_hardware(args.hardware)
        except HardwareError as exc:
            raise CliError(str(exc)) from None
    if args.screenshot is not None and args.rig != "sim":
        raise CliError("--screenshot runs on the simulated rig only (omit --rig real)")
    if args.sim_mount_error_deg and args.rig != "sim":
        raise CliError("--sim-mount-error-deg applies to the simulated rig only (omit it with --rig real)")
    if args.screenshot is None and not any(os.environ.get(v) for v in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM")):
        # without this Qt aborts the process with a core dump and a page of plugin names
        raise CliError(
            "no display to open the window on (DISPLAY and WAYLAND_DISPLAY are unset): run it on the lab PC's "
            "desktop, or pass --screenshot DIR to drive it offscreen"
        )
    # Qt is imported here only: the other subcommands never load it
    from study_app.gui.app import run_gui

    if args.screenshot is not None:
        # a rehearsal on the virtual clock at 4x real time: a few trials in seconds
        host = HostConfig(rig="sim", clock="virtual", speed=4.0)
    else:
        host = HostConfig(rig=args.rig, hardware_path=args.hardware, clock="real",
                          sim_mount_error_deg=args.sim_mount_error_deg)
    try:
        return run_gui(host, db_path=args.db, screenshot_dir=args.screenshot)
    except RuntimeError as exc:
        raise CliError(str(exc)) from None


def _cmd_bench_pipeline(args: argparse.Namespace) -> int:
    from bench.pipeline_bench import format_pipeline_bench, run_pipeline_bench

    def say(msg: str) -> None:
        print(f"bench: {msg} ...", file=sys.stderr, flush=True)

    result = run_pipeline_bench(
        loop_seconds=args.loop_seconds, ticks=args.ticks, progress=say, explain=args.explain,
        reference=args.reference,
    )
    if args.json:
        print(json.dumps(result))
    else:
        print(format_pipeline_bench(result))
    return 0


if __name__ == "__main__":  # pragma: no cover
    # ``python -m study_app.cli``: CliError lives in study_app.cli_error, so this __main__ copy catches the one
    # the subcommand modules raise
    sys.exit(main())
