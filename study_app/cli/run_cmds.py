"""``haptic-study sim``, ``run`` and ``sessions``: the simulated rig and the headless study runner.

Each command's parser is registered beside the command; the machinery is
imported when the command runs, so ``haptic-study --help`` stays light.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sqlite3
import sys
from typing import TYPE_CHECKING, Any

from pipeline.devices.rig import SINGLE_ARM_NAME
from study_app.cli.argtypes import SEED, add_command, arm_names, positive_seconds, setting, whole_number
from study_app.cli.error import CliError
from study_app.cli.withdraw_cmds import participant_code_arg

if TYPE_CHECKING:
    from protocol.study.config import ProtocolConfig

__all__ = ["add_run_parser", "add_sessions_parser", "add_sim_parser", "cmd_run", "cmd_sessions", "cmd_sim"]


def _fault_plan(text: str):
    """An argument type: one ``--inject-fault`` plan (protocol.runner.rehearsal), or the parser's one-line error."""
    from protocol.runner.rehearsal import parse_fault_plan

    try:
        return parse_fault_plan(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_sim_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``sim``."""
    s = add_command(sub, "sim", "run the simulated rig with scripted presses and summarise what the pipeline saw",
                    "haptic-study sim --seconds 30 --seed 1")
    s.add_argument("--seconds", type=positive_seconds("--seconds"), default=60.0, help="simulated time (default 60)")
    s.add_argument("--seed", type=SEED, default=0, help="seed of every random process (default 0)")
    s.add_argument("--clock", choices=("virtual", "real"), default="virtual",
                   help="virtual: as fast as the CPU allows (default); real: paced at 1 kHz")
    s.add_argument("--haptics", choices=("on", "off"), default="on", help="haptic feedback (default on)")
    s.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    s.set_defaults(handler=cmd_sim)


def add_run_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``run``."""
    r = add_command(sub, "run", "run a complete simulated study into a study database (headless)",
                    "haptic-study run --participants 10 --seed 0 --db study.db\n"
                    "haptic-study run --participants 10 --seed 0 --db study.db --continue   # after an interruption",
                    "Run a complete simulated study (training and experiment sessions of simulated participants on "
                    "the simulated rig) into a study database, headless, and print a summary")
    r.add_argument("--participants", type=whole_number("--participants", 1, 9999), default=10,
                   help="number of simulated participants (default 10)")
    r.add_argument("--seed", type=SEED, default=0, help="study seed: schedules, rigs and participants (default 0)")
    r.add_argument("--db", required=True, metavar="PATH", help="study database (SQLite); created if missing")
    r.add_argument("--protocol", default=None, metavar="FILE",
                   help="protocol file (default: the paper's study, protocol/study/default.toml)")
    r.add_argument("--clock", choices=("virtual", "real"), default="virtual",
                   help="virtual: as fast as the CPU allows (default); real: paced at 1 kHz")
    r.add_argument("--jobs", type=whole_number("--jobs", 1, 1024, " (omit it to use the usable cores)"), default=None,
                   help="participants run at once, each in its own process (default: the usable cores; 1: one after "
                        "the other)")
    after = r.add_mutually_exclusive_group()
    after.add_argument("--resume", metavar="CODE", default=None, type=participant_code_arg,
                       help="continue this participant's interrupted session (training or experiment) "
                            "at its first unfinished trial")
    after.add_argument("--continue", dest="continue_study", action="store_true",
                       help="complete a study that stopped part-way in --db: resume interrupted sessions, run what "
                            "was not started (give the --participants, --seed and --protocol it was started with)")
    r.add_argument("--set", dest="settings", action="append", default=[], type=setting, metavar="NAME=VALUE",
                   help="a pipeline setting of every session, stored with it (default: the paper's): filter_window "
                        "(samples, 10), f_scale_n (f_scale, N, 7), f_max_n (f_max, N, 3), slew_n_per_s (slew, N/s, "
                        "50), ramp_in_s (ramp_in, s, 0.5); repeatable; --continue and --resume need the same")
    r.add_argument("--inject-fault", dest="inject_fault", action="append", default=[], type=_fault_plan,
                   metavar="KIND@CODE:TRIAL[+SECONDS]",
                   help="rehearse a fault on the simulated rig, SECONDS (default 3) after the cue of participant "
                        "CODE's TRIAL-th experiment trial; KIND: sensor-stall, nan-burst, bad-status, stale-pose, "
                        "device-error, kill (ends this command as kill -9 would); repeatable")
    r.add_argument("--sim-arms", dest="sim_arms", type=arm_names("--sim-arms"), default=(SINGLE_ARM_NAME,),
                   metavar="NAMES",
                   help=f"the simulated rig's arms, comma-separated (default: one arm, {SINGLE_ARM_NAME}); the "
                        "protocol's design.task_arm names the one that does the task, the others are rigged alike and "
                        "held still (e.g. --sim-arms left,right with task_arm = \"left\")")
    r.add_argument("--covariate", dest="covariates", action="append", default=[], type=_covariate,
                   metavar="NAME=VALUE",
                   help="a value every participant this run registers is given for one of the protocol's "
                        "[[covariates]] (e.g. group=surgeon; the others are drawn by the simulated participant's "
                        "rule); repeatable")
    r.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="run the participants on a Dask cluster, each merged into --db as it comes back "
                        "(`dask scheduler` prints its address; default: the HAPTIC_STUDY_SCHEDULER environment "
                        "variable, else this machine; docs/cluster.md)")
    r.add_argument("--lsl", action="store_true",
                   help="publish every session's force streams and trial markers on the Lab Streaming Layer (as the "
                        "protocol's [lsl] outlets = true; needs --clock real and pylsl: docs/lsl.md)")
    r.add_argument("--visit", default=None, metavar="NAME",
                   help="in a protocol with [[visits]]: run only this visit of each participant's schedule, "
                        "continuing the study in --db (a lab's participants come back one visit at a time); "
                        "default: every visit left, each on its planned day (docs/study-design.md)")
    r.add_argument("--day", type=whole_number("--day", 0, 1100), default=None, metavar="N",
                   help="with --visit: the study day the visit is held on (days after the participant's first "
                        "visit; default: today's, from the first visit's date)")
    r.add_argument("--deviation", default="", metavar="REASON",
                   help="with --visit: run a visit out of order or outside its window anyway, for this reason "
                        "(stored as a deviation of the visit, listed in the report)")
    r.set_defaults(handler=cmd_run)


def _visit_request(args: argparse.Namespace) -> Any:
    """``--visit``/``--day``/``--deviation`` as the headless run's request (None: the whole schedule)."""
    from study_app.headless.plan_visits import VisitRequest

    if args.visit is None:
        for given, name in ((args.day is not None, "--day"), (bool(args.deviation), "--deviation")):
            if given:
                raise CliError(f"{name} is given without --visit: it applies to one visit run at a time")
        return None
    if args.resume is not None or args.continue_study:
        raise CliError(f"--visit {args.visit} with {'--resume' if args.resume else '--continue'}: --visit runs "
                       "(and continues) that visit alone; give one of them")
    if args.inject_fault or args.scheduler:
        raise CliError(f"--visit {args.visit} with {'--inject-fault' if args.inject_fault else '--scheduler'}: "
                       "that is for a whole study's run; run the visit without it")
    return VisitRequest(args.visit, args.day, args.deviation)


def _covariate(text: str) -> tuple[str, str]:
    """An argument type: one ``--covariate NAME=VALUE`` (checked against the protocol when the run starts)."""
    from protocol.study.covariates import CovariateError, parse_assignment

    try:
        return parse_assignment(text)
    except CovariateError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_sessions_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``sessions``."""
    ss = add_command(sub, "sessions", "list the sessions of a study database: participant, kind, status, trials",
                     "haptic-study sessions --db study.db")
    ss.add_argument("--db", required=True, metavar="PATH", help="study database")
    ss.add_argument("--json", action="store_true", help="print one JSON array")
    ss.set_defaults(handler=cmd_sessions)


#: Memory ``sim`` keeps per simulated tick: 8 float64 columns read from the ring, and their concatenation, with a
#: margin.
_SIM_BYTES_PER_TICK = 160


def cmd_sim(args: argparse.Namespace) -> int:
    """Run ``haptic-study sim``."""
    from foundation.resources import memory_problem
    from study_app.cli.progress import ProgressBar
    from study_app.cli.sim_summary import run_scripted_sim

    problem = memory_problem(args.seconds * 1000 * _SIM_BYTES_PER_TICK, f"sim --seconds {args.seconds:g}",
                             "simulate fewer seconds (the summary keeps every tick)")
    if problem is not None:
        raise CliError(problem)
    bar = None if args.json else ProgressBar(args.seconds, "simulating", "s")
    summary = run_scripted_sim(
        seconds=args.seconds, seed=args.seed, clock=args.clock, haptics_on=args.haptics == "on",
        progress=None if bar is None else bar.update,
    )
    if bar is not None:
        bar.close()
    if args.json:
        # strict JSON: a measure with nothing to measure (no contact in a short run) is null, not NaN
        print(json.dumps({k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                          for k, v in summary.items()}, indent=None, allow_nan=False))
    else:
        from study_app.cli.sim_summary import format_summary

        print(format_summary(summary))
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    """Run ``haptic-study run``; errors raise :class:`CliError`."""
    from protocol.storage import StorageError
    from protocol.study.config import ProtocolError, load_protocol
    from study_app.cli.progress import ProgressBar
    from study_app.headless import SessionInterrupted, StudyWorkerError
    from study_app.headless.fanout import ClusterError

    _check_resume_options(args)
    visit = _visit_request(args)
    framework = framework_of(args.settings)
    address = _scheduler_of(args)
    _refuse_a_full_disk(args.db)
    bar: ProgressBar | None = None
    client = None
    try:
        if args.resume is None:
            protocol = load_protocol(args.protocol)
            _check_task_arm(protocol, args)
            protocol = _lsl_checked(protocol, args)
        elif args.lsl:
            raise CliError(f"--lsl with --resume {args.resume}: a resumed session publishes what its stored protocol "
                           "says ([lsl]); run it without --lsl")

        def show(p):
            nonlocal bar
            if bar is None:
                bar = ProgressBar(p.study_trials_total, "study", "trials", decimals=0)
            bar.label = f"{p.code} {p.kind:<10} trial {p.trials_done:>2}/{p.trials_total:<2}"
            bar.update(p.study_trials_done)

        import time as _time

        client = _connect(address)
        t0 = _time.perf_counter()
        progress = _run(args, protocol if args.resume is None else None, framework, show, client, visit)
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
    except ClusterError as exc:  # the participants merged so far are kept: --continue runs the others
        if bar is not None:
            bar.close()
        raise CliError(f"{exc} (with --continue)", 1) from None
    except (OSError, sqlite3.Error):  # the machine failed (a full disk): one line from the CLI's error path
        if bar is not None:
            bar.close()
        raise
    finally:
        if client is not None:
            client.close()
    for note in progress.notes:
        print(f"haptic-study: {note}", file=sys.stderr)
    if args.continue_study and progress.study_trials_total == 0:
        print(f"haptic-study: nothing to continue in {args.db}: every session of participants "
              f"1–{args.participants} has ended", file=sys.stderr)
    # imported only now: the summary's statistics (pandas, SciPy) cost a second that a refused run need not pay
    from study_app.cli.study_summary import format_study_summary

    print(format_study_summary(args.db, progress.sessions, wall))
    for line in progress.rehearsals:
        print(f"Fault rehearsal {line}")
    return 0


def _run(args: argparse.Namespace, protocol: Any, framework: Any, show: Any, client: Any, visit: Any) -> Any:
    """The run ``cmd_run`` asked for: a resume, one visit of a schedule, or a study (new or continued)."""
    from study_app.headless import resume_session, run_study
    from study_app.headless.study import run_visit

    if args.resume is not None:
        return resume_session(args.db, args.resume, clock=args.clock, on_progress=show, faults=args.inject_fault,
                              framework=framework)
    if visit is not None:
        return run_visit(args.db, visit, participants=args.participants, seed=args.seed, protocol=protocol,
                         clock=args.clock, on_progress=show, jobs=args.jobs, sim_arms=args.sim_arms,
                         framework=framework, covariates=dict(args.covariates))
    return run_study(args.db, participants=args.participants, seed=args.seed, protocol=protocol, clock=args.clock,
                     on_progress=show, jobs=args.jobs, continue_study=args.continue_study, faults=args.inject_fault,
                     sim_arms=args.sim_arms, framework=framework, covariates=dict(args.covariates), client=client)


def _check_resume_options(args: argparse.Namespace) -> None:
    """What a resume cannot be given: covariates (set at registration), faults of another participant."""
    if args.resume is not None and args.covariates:
        raise CliError(f"--covariate {args.covariates[0][0]}={args.covariates[0][1]}: a resumed participant was "
                       "registered with their first session, and their covariates are not changed")
    if args.resume is not None:
        for f in args.inject_fault:
            if f.code != args.resume:
                raise CliError(f"--inject-fault = {f}: participant {f.code} is not the one resumed ({args.resume})")


def _scheduler_of(args: argparse.Namespace) -> str | None:
    """The Dask scheduler's address (checked before any work), refused with the options it cannot go with."""
    from foundation.errors import InputRefused
    from study_app.headless.fanout import scheduler_address

    try:
        address = scheduler_address(args.scheduler)
    except InputRefused as exc:
        raise CliError(str(exc)) from None
    if address is None:
        return None
    for given, why in ((args.resume, "--resume"), (args.clock != "virtual", "--clock real"),
                       (args.inject_fault, "--inject-fault"), (args.jobs, "--jobs")):
        if given:
            raise CliError(f"--scheduler = {address}: {why} does not apply to a study on a Dask cluster (it runs on "
                           "the virtual clock, its workers' processes; no planned faults; a resume runs here); "
                           "leave out one or the other")
    return address


def _connect(address: str | None) -> Any:
    """A client of the cluster at ``address`` (its workers checked to run this software), or None."""
    if address is None:
        return None
    from foundation.errors import InputRefused
    from study_app.headless.fanout import connect

    try:
        return connect(address)
    except InputRefused as exc:
        raise CliError(str(exc), getattr(exc, "status", 2)) from None


def _lsl_checked(protocol: ProtocolConfig, args: argparse.Namespace) -> ProtocolConfig:
    """The protocol a run uses with ``--lsl`` (its outlets on), checked before anything is stored: LSL on needs the
    real clock (the virtual clock's times are on no clock another machine shares), one session at a time (each
    publishes its own streams), pylsl, and every stream the protocol records found (one line naming what is not)."""
    import dataclasses

    from protocol.runner.session_lsl import lsl_streams_of

    if args.lsl:
        protocol = dataclasses.replace(protocol, lsl=protocol.lsl.with_outlets())
    if not protocol.lsl.on:
        return protocol
    what = "--lsl" if args.lsl else f"{args.protocol}: [lsl]"
    if args.clock != "real":
        raise CliError(f"{what} needs --clock real: a virtual-clock run's times are on no clock LSL shares "
                       f"(--clock = {args.clock!r})")
    if args.jobs not in (None, 1):
        raise CliError(f"--jobs = {args.jobs} with {what}: sessions on LSL run one at a time (each publishes its "
                       "own streams); give --jobs 1 or leave it out")
    args.jobs = 1
    lsl_streams_of(protocol.lsl)  # (pylsl missing, or a named stream not found: one line, nothing stored)
    from protocol.lsl.bus import pylsl

    pylsl()
    return protocol


def _check_task_arm(protocol: ProtocolConfig, args: argparse.Namespace) -> None:
    """The protocol's task arm must be one of ``--sim-arms``: one line naming both."""
    from protocol.study.config import ProtocolError

    try:
        protocol.task_arm_of(args.sim_arms)
    except ProtocolError as exc:
        raise CliError(f"{args.protocol or 'protocol/study/default.toml'}: {exc}; the simulated rig's arms are "
                       f"--sim-arms {','.join(args.sim_arms)}") from None


def framework_of(settings: list[tuple[str, float]]):
    """The pipeline configuration of ``--set``'s settings (the paper's for the others); a setting given twice, or
    a combination the configuration refuses, is the one-line :class:`CliError`."""
    from pipeline.force.pipeline_settings import framework_with

    chosen: dict[str, float] = {}
    for name, value in settings:
        if name in chosen:
            raise CliError(f"--set {name}: given twice ({chosen[name]:g} and {value:g}); give each setting once")
        chosen[name] = value
    try:
        return framework_with(chosen)
    except ValueError as exc:
        raise CliError(f"--set: {exc}") from None


#: Free space below which ``run`` does not start: SQLite's journal and the first recorded blocks need about this.
_RUN_MIN_FREE_BYTES = 1 << 20


def _refuse_a_full_disk(db: str) -> None:
    """A database on a (nearly) full disk is refused before the study starts (a fuller one mid-run: cli's one line)."""
    from foundation.outfs import free_bytes, read_only

    folder = os.path.dirname(os.path.abspath(db))
    if not os.path.isdir(folder) or read_only(folder):
        return  # the database's own checks say what is wrong with the folder
    free = free_bytes(folder)
    if free is not None and free < _RUN_MIN_FREE_BYTES:
        raise CliError(f"--db {db}: no space left on the device ({free / 1e6:.2f} MB free, a study needs at least "
                       f"{_RUN_MIN_FREE_BYTES / 1e6:.0f} MB to start); free some space or use a database on another "
                       "disk (nothing was written)")


def cmd_sessions(args: argparse.Namespace) -> int:
    """Run ``haptic-study sessions``; errors raise :class:`CliError`."""
    from protocol.storage import StorageError
    from study_app.engine.session_list import format_sessions, list_sessions

    if not os.path.isfile(args.db):
        raise CliError(f"--db = {args.db!r}: " + ("is a folder, not a database file" if os.path.isdir(args.db)
                                                  else "no such file"))
    try:
        sessions = list_sessions(args.db)
    except StorageError as exc:
        raise CliError(str(exc)) from None
    print(json.dumps(sessions) if args.json else format_sessions(args.db, sessions))
    return 0
