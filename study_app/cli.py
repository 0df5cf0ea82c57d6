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

__all__ = ["main"]


class CliError(Exception):
    """A user-facing error: printed as one line, exit status 2."""


def _positive_float(name: str):  # type: ignore[no-untyped-def]
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} = {text!r}: expected a number") from None
        if not (v > 0 and v < float("inf")):
            raise argparse.ArgumentTypeError(f"{name} = {text!r}: must be a finite number > 0")
        return v

    return parse


def _loop_seconds(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--loop-seconds = {text!r}: expected a number") from None
    if not 0 <= v <= 3600:
        raise argparse.ArgumentTypeError(f"--loop-seconds = {text!r}: must be from 0 (skip the loop) to 3600")
    return v


def _nonneg_int(name: str):  # type: ignore[no-untyped-def]
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} = {text!r}: expected a whole number") from None
        if v < 0:
            raise argparse.ArgumentTypeError(f"{name} = {text!r}: must be ≥ 0")
        return v

    return parse


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    p = argparse.ArgumentParser(
        prog="haptic-study",
        description="Force-feedback training study: haptic pipeline, simulated rig, protocol, analysis, GUI.",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    s = sub.add_parser("sim", help="run the simulated rig with scripted presses and summarise what the pipeline saw")
    s.add_argument("--seconds", type=_positive_float("--seconds"), default=60.0, help="simulated time (default 60)")
    s.add_argument("--seed", type=_nonneg_int("--seed"), default=0, help="seed of every random process (default 0)")
    s.add_argument("--clock", choices=("virtual", "real"), default="virtual",
                   help="virtual: as fast as the CPU allows (default); real: paced at 1 kHz")
    s.add_argument("--haptics", choices=("on", "off"), default="on", help="haptic feedback (default on)")
    s.add_argument("--json", action="store_true", help="print the summary as one JSON object")

    r = sub.add_parser("run", help="run a complete simulated study into a study database (headless)")
    r.add_argument("--participants", type=_nonneg_int("--participants"), default=10, help="number of simulated participants (default 10)")
    r.add_argument("--seed", type=_nonneg_int("--seed"), default=0, help="study seed: schedules, rigs and participants (default 0)")
    r.add_argument("--db", required=True, help="study database (SQLite); created if missing")
    r.add_argument("--protocol", default=None, help="protocol file (default: the paper's study, protocol/default.toml)")
    r.add_argument("--clock", choices=("virtual", "real"), default="virtual",
                   help="virtual: as fast as the CPU allows (default); real: paced at 1 kHz")
    r.add_argument("--jobs", type=_nonneg_int("--jobs"), default=None,
                   help="participants run at once, each in its own process (default: the usable cores; 1: one after the other)")
    after = r.add_mutually_exclusive_group()
    after.add_argument("--resume", metavar="PARTICIPANT_CODE", default=None,
                       help="continue this participant's interrupted session (training or experiment) "
                            "at its first unfinished trial")
    after.add_argument("--continue", dest="continue_study", action="store_true",
                       help="complete a study that stopped part-way in --db: resume interrupted sessions, run what "
                            "was not started (give the --participants, --seed and --protocol it was started with)")

    from study_app.report_cmds import add_report_parsers

    add_report_parsers(sub)

    from study_app.power_cmds import add_power_bench_parser, add_power_parser

    add_power_parser(sub)

    b = sub.add_parser("bench", help="benchmarks (see README for recorded figures)")
    bsub = b.add_subparsers(dest="bench", metavar="BENCH")
    bsub.required = True
    bp = bsub.add_parser("pipeline", help="per-tick cost vs NumPy, 1 kHz loop timing, filter trade table")
    bp.add_argument("--json", action="store_true", help="print one JSON object")
    bp.add_argument("--loop-seconds", type=_loop_seconds, default=30.0,
                    help="real time to run the loop (default 30; 0 skips)")
    bp.add_argument("--explain", action="store_true",
                    help="name the cause of every loop tick over 100 µs late (costs the loop ~30 µs per tick)")
    bp.add_argument("--reference", action="store_true",
                    help="then run an empty loop as long: the machine's own floor for the loop figures")
    bp.add_argument("--ticks", type=_nonneg_int("--ticks"), default=20_000, help="samples for the cost benchmark")
    bs = bsub.add_parser("study", help="wall time of a complete simulated study on the virtual clock")
    bs.add_argument("--participants", type=_nonneg_int("--participants"), default=10, help="participants (default 10)")
    bs.add_argument("--json", action="store_true", help="print one JSON object")
    br = bsub.add_parser("report", help="report wall time on a 10-participant study; statistics for 10 000 participants")
    br.add_argument("--db", default=None, help="study database to report on (default: simulate a 10-participant study first)")
    br.add_argument("--stats-participants", type=_nonneg_int("--stats-participants"), default=10_000,
                    help="participants of the synthetic trial table (default 10000)")
    br.add_argument("--json", action="store_true", help="print one JSON object")
    add_power_bench_parser(bsub)
    bst = bsub.add_parser("stats", help="analysis.stats on 10 000 pairs: Wilcoxon, Hodges–Lehmann, correlation, Holm")
    bst.add_argument("--json", action="store_true", help="print one JSON object")

    pr = sub.add_parser("probe", help="read a real device once and report (no loop)")
    prsub = pr.add_subparsers(dest="probe", metavar="DEVICE")
    prsub.required = True
    pn = prsub.add_parser("netft", help="ATI Net F/T: mean wrench (N, N·m), packet rate, lost/reordered/faulted counts")
    pn.add_argument("--host", required=True, help="the Net F/T box's IP address")
    pn.add_argument("--port", type=_port_number("--port"), default=49152, help="RDT UDP port (default 49152)")
    pn.add_argument("--http-port", type=_port_number("--http-port"), default=80, help="web server port for netftapi2.xml (default 80)")
    pn.add_argument("--samples", type=_nonneg_int("--samples"), default=1000, help="samples to average (default 1000)")
    pn.add_argument("--json", action="store_true", help="print one JSON object")

    ch = sub.add_parser("check-hardware", help="connect to every device in the hardware file and print its state")
    ch.add_argument("--hardware", default="hardware.toml", help="hardware file (default ./hardware.toml; see hardware.example.toml)")

    bg = bsub.add_parser("gui", help="1 kHz loop timing with and without the GUI attached; GUI stalls and start-up time")
    bg.add_argument("--json", action="store_true", help="print one JSON object")
    bg.add_argument("--seconds", type=_positive_float("--seconds"), default=20.0,
                    help="real time per loop measurement (default 20)")
    bg.add_argument("--explain", action="store_true",
                    help="name the cause of every loop tick over 100 µs late (costs the loop ~25 µs per tick)")

    g = sub.add_parser("gui", help="the experimenter's window (simulated rig by default)")
    g.add_argument("--db", default=None, help="study database (SQLite); default: the last one used")
    g.add_argument("--rig", choices=("sim", "real"), default="sim", help="simulated rig (default) or the real hardware")
    g.add_argument("--hardware", default=None, metavar="FILE", help="hardware.toml for --rig real")
    g.add_argument("--screenshot", default=None, metavar="DIR",
                   help="drive a short simulated session offscreen and save PNGs of every main view into DIR")
    return p


def _port_number(name: str):  # type: ignore[no-untyped-def]
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} = {text!r}: expected a whole number") from None
        if not 1 <= v <= 65535:
            raise argparse.ArgumentTypeError(f"{name} = {text!r}: must be a port number from 1 to 65535")
        return v

    return parse


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``haptic-study`` console script."""
    args = build_parser().parse_args(argv)
    try:
        if args.command == "sim":
            return _cmd_sim(args)
        if args.command == "run":
            return _cmd_run(args)
        if args.command in ("report", "plot-trial"):
            from study_app.report_cmds import cmd_plot_trial, cmd_report

            return cmd_report(args) if args.command == "report" else cmd_plot_trial(args)
        if args.command == "power" or (args.command == "bench" and args.bench == "power"):
            from study_app.power_cmds import cmd_bench_power, cmd_power

            return cmd_power(args) if args.command == "power" else cmd_bench_power(args)
        if args.command == "bench" and args.bench == "pipeline":
            return _cmd_bench_pipeline(args)
        if args.command == "bench" and args.bench == "report":
            from bench.analysis_bench import format_report_bench, run_report_bench

            if args.db is not None and not os.path.isfile(args.db):
                raise CliError(f"--db = {args.db!r}: no such file")
            if args.stats_participants < 2:
                raise CliError(f"--stats-participants = {args.stats_participants}: must be ≥ 2")
            print("bench: timing the report ...", file=sys.stderr, flush=True)
            result = run_report_bench(args.db, stats_participants=args.stats_participants)
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

            if args.participants < 1:
                raise CliError(f"--participants = {args.participants}: must be ≥ 1")
            print("bench: running the simulated study ...", file=sys.stderr, flush=True)
            result = run_study_bench(args.participants)
            print(json.dumps(result) if args.json else format_study_bench(result))
            return 0
        if args.command in ("probe", "check-hardware"):
            return _cmd_hardware(args)
    except CliError as exc:
        print(f"haptic-study: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("haptic-study: interrupted", file=sys.stderr)
        return 130
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
    from protocol.study import StudyWorkerError, resume_session, run_study
    from study_app.progress import ProgressBar
    from study_app.study_summary import format_study_summary

    try:
        if args.resume is None:
            protocol = load_protocol(args.protocol)
            if args.participants < 1:
                raise CliError(f"--participants = {args.participants}: must be ≥ 1")
            if args.jobs is not None and args.jobs < 1:
                raise CliError(f"--jobs = {args.jobs}: must be ≥ 1 (omit it to use the usable cores)")
        bar: ProgressBar | None = None

        def show(p):  # type: ignore[no-untyped-def]
            nonlocal bar
            if bar is None:
                bar = ProgressBar(p.study_trials_total, "study", "trials", decimals=0)
            bar.label = f"{p.code} {p.kind:<10} trial {p.trials_done:>2}/{p.trials_total:<2}"
            bar.update(p.study_trials_done)

        import time as _time

        t0 = _time.perf_counter()
        if args.resume is not None:
            progress = resume_session(args.db, args.resume, clock=args.clock, on_progress=show)
        else:
            progress = run_study(
                args.db, participants=args.participants, seed=args.seed, protocol=protocol, clock=args.clock,
                on_progress=show, jobs=args.jobs, continue_study=args.continue_study,
            )
        wall = _time.perf_counter() - t0
        if bar is not None:
            bar.close()
    except (ProtocolError, StorageError, StudyWorkerError, ValueError) as exc:
        raise CliError(str(exc)) from None
    if args.continue_study and progress.study_trials_total == 0:
        print(f"haptic-study: nothing to continue in {args.db}: every session of participants "
              f"1–{args.participants} has ended", file=sys.stderr)
    print(format_study_summary(args.db, progress.sessions, wall))
    return 0


def _cmd_hardware(args: argparse.Namespace) -> int:
    from study_app.hardware_cmds import HardwareCmdError, check_hardware, format_check, format_probe, probe_netft

    try:
        if args.command == "probe":
            if args.samples < 1:
                raise CliError(f"--samples = {args.samples}: must be ≥ 1")
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
        host = HostConfig(rig=args.rig, hardware_path=args.hardware, clock="real")
    try:
        return run_gui(host, db_path=args.db, screenshot_dir=args.screenshot)
    except RuntimeError as exc:
        raise CliError(str(exc)) from None


def _cmd_bench_pipeline(args: argparse.Namespace) -> int:
    from bench.pipeline_bench import format_pipeline_bench, run_pipeline_bench

    def say(msg: str) -> None:
        print(f"bench: {msg} ...", file=sys.stderr, flush=True)

    result = run_pipeline_bench(
        loop_seconds=args.loop_seconds, ticks=max(2000, args.ticks), progress=say, explain=args.explain,
        reference=args.reference,
    )
    if args.json:
        print(json.dumps(result))
    else:
        print(format_pipeline_bench(result))
    return 0


if __name__ == "__main__":  # pragma: no cover
    # `python -m study_app.cli` runs this file as __main__, a second copy of the module: the subcommand modules
    # raise study_app.cli.CliError, which __main__'s except clause would not catch (a traceback, exit 1)
    from study_app.cli import main as _main

    sys.exit(_main())
