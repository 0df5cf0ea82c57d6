"""The ``power`` subcommand: planning the next study's sample size.

Option values are parsed here rather than by argparse so that a bad value is
one line on stderr naming the option, the value and what is allowed (exit 2).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from typing import Any

from foundation.errors import InputRefused
from study_app.cli.error import CliError
from study_app.cli.part_choice import PART_HELP, pilot_part

__all__ = ["add_power_parser", "cmd_power", "whole_option"]

_N_MAX = 10_000
#: analysis.planning.power.DEFAULT_N_VALUES, written out so that building the parser does not import the analysis
DEFAULT_N_TEXT = "6,8,10,12,16,20,30"
_POOL_DEFAULT = 100
#: Resampled participants (studies × n) from which on ``power`` shows a progress bar: ~10 s of work and more.
_BAR_DRAWS = 5_000_000
#: The marker of a power output folder (foundation.outdir): the files power wrote there, with their SHA-256.
POWER_MARKER = ".haptic-study-power"


def add_power_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``power``."""
    from study_app.cli.report_cmds import add_analysis_options

    p = sub.add_parser(
        "power",
        help="plan the next study: power of the report's tests to detect the effect in the pilot's direction "
             "against the number of participants, by resampling a pilot study or simulated participants",
    )
    p.add_argument("--db", action="append", metavar="PILOT.db",
                   help="pilot study database; repeat to merge several (the report's aggregation and tests)")
    p.add_argument("--simulated", action="store_true",
                   help="no pilot yet: simulate a pool of participants from the calibrated population, kept in DIR "
                        "as pool-N-seedS.db with a record of how it was made; a later call reuses it (or the first "
                        "N of a larger pool of the same seed) after checking its SHA-256, and completes an "
                        "interrupted simulation")
    p.add_argument("--pool", default=None, metavar="N",
                   help=f"participants in the simulated pool (default {_POOL_DEFAULT}; with --simulated)")
    p.add_argument("--n", default=None, metavar="LIST",
                   help=f"planned study sizes, comma-separated (default {DEFAULT_N_TEXT})")
    p.add_argument("--resamples", default="2000", help="resampled studies per n (default 2000)")
    p.add_argument("--alpha", default="0.05", help="significance level, p < alpha (default 0.05)")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="with --simulated (also --groups): run the pool's participants on a Dask cluster (`dask "
                        "scheduler` prints its address; default: the HAPTIC_STUDY_SCHEDULER environment variable, else "
                        "this machine)")
    p.add_argument("--seed", default="0", help="seed of the resampling and of the simulated pool (default 0)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="output folder: power.csv, power.txt, power.png/.pdf/.svg (and the simulated pool); it must "
                        "be new or empty, or hold only a simulated pool, unless --force")
    p.add_argument("--force", action="store_true",
                   help="replace the files an earlier power run wrote in DIR, if unedited (the marker "
                        ".haptic-study-power lists them with their SHA-256); any other file, or an edited one, is "
                        "a refusal; the simulated pool is never deleted")
    p.add_argument("--groups", action="store_true",
                   help="plan a two-group study: the power of the group x haptics interaction (the report's "
                        "Mann-Whitney U test of the per-participant ON - OFF effects between groups) against "
                        "participants per group (--n), from a pilot whose protocol declares [groups] or from "
                        "simulated novices and experienced surgeons (docs/groups.md)")
    p.add_argument("--protocol", default=None, metavar="FILE",
                   help="with --groups --simulated: the protocol to simulate (it must declare [groups]; default: the "
                        "paper's with a group covariate of novices and surgeons, half and half)")
    p.add_argument("--part", default=None, metavar="NAME", help=PART_HELP)
    add_analysis_options(p)
    p.set_defaults(handler=cmd_power)


def whole_option(option: str, text: str, low: int, high: int) -> int:
    """``text`` as a whole number from ``low`` to ``high``, or a :class:`CliError` naming ``option``."""
    try:
        v = int(text)
    except ValueError:
        v = None
    if v is None or not low <= v <= high:
        raise CliError(f"{option} = {text!r}: must be a whole number from {low} to {high}")
    return v


def _n_values(text: str) -> tuple[int, ...]:
    out = []
    for part in text.split(","):
        try:
            v = int(part.strip())
        except ValueError:
            v = None
        if v is None or not 2 <= v <= _N_MAX:
            raise CliError(f"--n = {text!r}: each n must be a whole number from 2 to {_N_MAX}, comma-separated "
                           "(e.g. 6,8,10,12)")
        if v in out:  # the table would show the size once: say so rather than drop it silently
            raise CliError(f"--n = {text!r}: {v} is given twice; give each n once")
        out.append(v)
    return tuple(out)


def _alpha(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = float("nan")
    if not 0.0 < v < 1.0:
        raise CliError(f"--alpha = {text!r}: must be a number with 0 < alpha < 1 (e.g. 0.05)")
    return v


@dataclass(frozen=True)
class _PowerRequest:
    """The ``power`` options, checked (before any work or import of the analysis)."""

    n_values: tuple[int, ...]
    resamples: int
    alpha: float
    seed: int
    pool_size: int
    scheduler: str | None = None  # a Dask scheduler's address: the simulated pool's participants run there


def _request(args: argparse.Namespace) -> _PowerRequest:
    """The options of ``power`` checked, each refusal one line naming the option and what is allowed."""
    if args.db and args.simulated:
        raise CliError("--db and --simulated: give one or the other (a pilot study, or simulated participants)")
    if not args.db and not args.simulated:
        raise CliError("power needs a source: --db PILOT.db (a pilot study) or --simulated (simulated participants)")
    if args.pool is not None and not args.simulated:
        raise CliError(f"--pool = {args.pool!r}: only with --simulated (a pilot's size is its own)")
    n_values = _n_values(DEFAULT_N_TEXT if args.n is None else args.n)
    resamples = whole_option("--resamples", args.resamples, 1, 1_000_000)
    alpha = _alpha(args.alpha)
    seed = whole_option("--seed", args.seed, 0, 2**32 - 1)
    pool_size = whole_option("--pool", args.pool, 4, _N_MAX) if args.pool is not None else _POOL_DEFAULT
    if args.out is None:
        raise CliError("--out: give the output folder (DIR) for power.csv, power.txt and the figure")
    if args.scheduler is not None and not args.simulated:
        raise CliError(f"--scheduler = {args.scheduler}: only with --simulated (a pilot study is read here)")
    from foundation.errors import InputRefused
    from study_app.headless.fanout import scheduler_address

    try:
        address = scheduler_address(args.scheduler) if args.simulated else None
    except InputRefused as exc:
        raise CliError(str(exc)) from None
    return _PowerRequest(n_values, resamples, alpha, seed, pool_size, address)


class _Bars:
    """The progress bars of a ``power`` run on stderr: the simulated pool, the samples read, the resampling."""

    def __init__(self) -> None:
        from study_app.cli.progress import ProgressBar

        self._bar = ProgressBar
        self.bars: list[ProgressBar] = []

    def reading(self, done: float, total: float) -> None:
        if not self.bars or self.bars[-1].unit != "samples":
            self.bars.append(self._bar(total, "reading samples", "samples", decimals=0))
        self.bars[-1].update(done)

    def resampling(self, done: int, total: int) -> None:
        if total < _BAR_DRAWS:  # a few seconds: no bar
            return
        if not self.bars or self.bars[-1].unit != "participants drawn":
            self.bars.append(self._bar(total, "resampling studies", "participants drawn", decimals=0))
        self.bars[-1].update(done)

    def simulating(self, p: Any) -> None:
        if not self.bars:
            self.bars.append(self._bar(p.study_trials_total, "simulating pool", "trials", decimals=0))
        self.bars[-1].label = f"simulating pool: {p.code} {p.kind:<10}"
        self.bars[-1].update(p.study_trials_done)

    def measures(self, done: int, total: int) -> None:
        if not self.bars or self.bars[-1].unit != "measures x sizes":
            self.bars.append(self._bar(total, "resampling two-group studies", "measures x sizes", decimals=0))
        self.bars[-1].update(done)

    def close(self) -> None:
        for bar in self.bars:
            bar.close()


def simulated_source(out: str, req: Any, bars: _Bars, protocol: Any = None, client: Any = None
                     ) -> tuple[list[str], Any, str]:
    """Simulate the pool of ``protocol`` (default: the paper's), or reuse or complete it: its database, its
    participants and how the report names it; with ``client``, its participants on that Dask cluster."""
    import functools

    from analysis.planning.power_pool import simulated_pool
    from study_app.headless import run_study
    from study_app.headless.sim_trials import MODEL_VERSION

    pool_size, seed = req.pool_size, req.seed
    t0 = time.perf_counter()
    simulate = run_study if client is None else functools.partial(run_study, client=client)
    pool_db = simulated_pool(out, pool_size, seed, simulate=simulate, participant_model=MODEL_VERSION,
                             protocol=protocol, on_progress=bars.simulating)
    bars.close()
    path = pool_db.path
    said = {"reused": f"reusing the simulated pool {path} (SHA-256 checked)",
            "reused-larger": f"reusing the first {pool_size} participants of the simulated pool {path} "
                             "(SHA-256 checked; participant k is the same in a pool of any size)",
            "resumed": f"completed the interrupted simulated pool {path} ({time.perf_counter() - t0:.0f} s)",
            "simulated": f"simulated pool written to {path} ({time.perf_counter() - t0:.0f} s); the next "
                         "call with the same --pool and --seed reuses it"}
    print(f"power: {said[pool_db.status]}", file=sys.stderr)
    first = f"the first {pool_size} of " if pool_db.status == "reused-larger" else ""
    source = (f"a simulated pool of {pool_size} participants of participant model v{MODEL_VERSION} (study seed "
              f"{seed}, {first}{path.name})")
    return [str(path)], pool_db.participants, source


def _say_the_size(req: _PowerRequest) -> None:
    """Before a long request's work: how much it is and the memory it may take (its bars then say the time left)."""
    from analysis.planning.power import memory_needed
    from foundation.resources import available_memory_bytes

    draws = req.resamples * sum(req.n_values)
    need = memory_needed(req.n_values, req.resamples, req.pool_size)
    have = available_memory_bytes()
    if draws < _BAR_DRAWS or (have is not None and need > have):
        return  # seconds of work; or a request the memory cannot hold, refused in one line later
    mib = need / 2**20
    print(f"power: {req.resamples:,} resampled studies for each of {len(req.n_values)} sizes ({draws:,} participants "
          f"drawn; at most {mib:,.0f} MiB at once): a long run; the bar says how long is left, Ctrl-C stops it with "
          "nothing written", file=sys.stderr)


def _client(req: _PowerRequest, args: argparse.Namespace) -> Any:
    """The Dask client the simulated pool's participants run on (``--scheduler``), or None: reached, its workers
    running this software, before the pool is made (a refusal is :class:`foundation.errors.InputRefused`)."""
    if req.scheduler is None or not args.simulated:
        return None
    from study_app.headless.fanout import connect

    return connect(req.scheduler)


def cmd_power(args: argparse.Namespace) -> int:
    """Run ``haptic-study power``; errors raise :class:`study_app.cli.error.CliError`."""
    req = _request(args)
    if args.protocol is not None and not args.groups:
        raise CliError(f"--protocol = {args.protocol!r}: only with --groups --simulated")
    if args.part is not None and args.simulated and args.protocol is None:
        raise CliError(f"--part = {args.part!r}: the simulated pool is the paper's study of one task; --part chooses "
                       "a part of a pilot (--db) or of --protocol FILE (with --groups --simulated)")
    from study_app.cli.group_power_cmds import check_group_request, run_group_power

    protocol = check_group_request(args) if args.groups else None

    from analysis.planning.power_pool import is_pool_file
    from analysis.reading.inputs import check_databases
    from foundation.outdir import check_output_folder, write_output_folder

    folder = dict(command="power", marker=POWER_MARKER, inputs=list(args.db or []), force=args.force,
                  keep=is_pool_file)
    try:
        check_output_folder(args.out, **folder)  # before any work (and before the analysis is imported)
        if args.db:
            check_databases(args.db)
    except InputRefused as exc:
        raise CliError(str(exc)) from None
    if args.db:
        pilot_part(args.db, args.part, "power")

    from analysis.planning.paired_pool import load_pool
    from analysis.planning.power import estimate_power, is_family_row
    from analysis.planning.power_outputs import write_power
    from analysis.planning.power_plan import summary_text
    from analysis.reading.metrics import MetricOptions

    options = MetricOptions(args.error_window, args.tct)
    bars = _Bars()
    client = None
    if args.groups:
        try:
            client = _client(req, args)
            return run_group_power(args, req, protocol, folder, bars, simulated_source, client=client)
        except InputRefused as exc:
            raise CliError(str(exc), getattr(exc, "status", 2)) from None
        finally:
            bars.close()
            if client is not None:
                client.close()
    _say_the_size(req)
    try:
        client = _client(req, args)
        participants = None
        source = None
        databases = list(args.db or [])
        if args.simulated:
            databases, participants, source = simulated_source(args.out, req, bars, client=client)
        pool = load_pool(databases, options, source=source, progress=bars.reading, participants=participants,
                         part=args.part if args.db else None)
        bars.close()
        t0 = time.perf_counter()
        result = estimate_power(pool, req.n_values, resamples=req.resamples, alpha=req.alpha, seed=req.seed,
                                zero_method=args.zero_method, progress=bars.resampling)
        if bars.bars and bars.bars[-1].unit == "participants drawn":
            bars.bars[-1].close()
        wall = time.perf_counter() - t0
        files = write_output_folder(args.out, lambda tmp: write_power(result, tmp), **folder)
    except InputRefused as exc:  # PowerError, PoolError, OutputError included
        raise CliError(str(exc), getattr(exc, "status", 2)) from None
    finally:
        if client is not None:
            client.close()
    tests = int((~result.frame["metric"].map(is_family_row)).sum()) * req.resamples
    print(f"power: {tests:,} resampled Wilcoxon tests (and Holm) in {wall:.2f} s", file=sys.stderr)
    print(summary_text(result))
    print(f"Written in {args.out}/: {', '.join(files)}")
    return 0
