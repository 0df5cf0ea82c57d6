"""``haptic-study sweep``: complete simulated studies per pipeline setting, their table and figures.

The grid is the cartesian product of the ``--set NAME=V1,V2,...`` lists; each setting runs ``--studies``
simulated studies of ``--participants`` participants (the same participants for every setting).  The cells run
in :mod:`study_app.headless.sweep_run`; the tables, figures and summary are :mod:`analysis.planning.sweep`'s.
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
import time
from pathlib import Path
from typing import Any

from foundation.errors import InputRefused
from study_app.cli.argtypes import SEED, add_command, setting_list, whole_number
from study_app.cli.error import CliError
from study_app.cli.part_choice import PART_HELP, compared_measures, one_part

__all__ = ["MAX_SETTINGS", "add_sweep_parser", "cmd_sweep", "grid_of"]

#: The most settings (grid points) one sweep runs.
MAX_SETTINGS = 50


def add_sweep_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``sweep``."""
    s = add_command(sub, "sweep", "predict the study's results per pipeline setting with simulated studies "
                    "(table and figures)",
                    "haptic-study sweep --set filter_window=1,10,50 --participants 10 --studies 3 --out sweep1\n"
                    "haptic-study sweep --set filter_window=5,10,20 --set f_scale=3,7,14 --studies 5 --out sweep2",
                    "Run complete simulated studies for every setting of a grid of the pipeline's settings (the "
                    "same simulated participants for every setting), on the virtual clock, and write a table and "
                    "figures of success, TCT, RMSE and Max AE against the setting; a model's prediction, not a "
                    "measurement")
    s.add_argument("--set", dest="grid", action="append", default=[], type=setting_list, metavar="NAME=V1,V2,...",
                   help="a swept pipeline setting and its values: filter_window (samples; paper 10), f_scale_n "
                        "(f_scale, N; 7), f_max_n (f_max, N; 3), slew_n_per_s (slew, N/s; 50), ramp_in_s (ramp_in, "
                        f"s; 0.5); repeatable (the grid is every combination, at most {MAX_SETTINGS})")
    s.add_argument("--participants", type=whole_number("--participants", 1, 200), default=10,
                   help="simulated participants per study (default 10)")
    s.add_argument("--studies", type=whole_number("--studies", 1, 50), default=5,
                   help="simulated studies per setting, for the intervals across studies (default 5)")
    s.add_argument("--seed", type=SEED, default=0, help="the seed the studies derive from (default 0)")
    s.add_argument("--out", default="sweep", metavar="DIR",
                   help="output folder (default ./sweep); it keeps the finished cells (cells.jsonl), so the same "
                        "command completes an interrupted sweep and a cell already run is not run again")
    s.add_argument("--protocol", default=None, metavar="FILE",
                   help="protocol file (default: the paper's study); its experiment schedule is run")
    s.add_argument("--part", default=None, metavar="NAME", help=PART_HELP)
    s.add_argument("--jobs", type=whole_number("--jobs", 1, 1024, " (omit it to use the usable cores)"), default=None,
                   help="participants run at once, each in its own process (default: the usable cores)")
    s.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="run the participants on a Dask cluster (`dask scheduler` prints its address; default: "
                        "the HAPTIC_STUDY_SCHEDULER environment variable, else this machine); the same table "
                        "whichever runs it (docs/cluster.md)")
    s.add_argument("--force", action="store_true", help="replace the outputs of an earlier sweep in --out")
    s.set_defaults(handler=cmd_sweep)


def grid_of(sets: list[tuple[str, tuple[float, ...]]]) -> tuple[list[str], list[dict[str, float]]]:
    """The swept names and the grid (every combination, each a full set of the pipeline's settings); one-line
    :class:`CliError` for no ``--set``, a name given twice, or too many settings."""
    from pipeline.force.pipeline_settings import framework_with, paper_settings, settings_of

    if not sets:
        raise CliError("--set: give at least one setting to sweep, e.g. --set filter_window=1,10,50")
    names = [n for n, _ in sets]
    for n in names:
        if names.count(n) > 1:
            raise CliError(f"--set {n}: given twice; give each setting once, with all its values")
    size = math.prod(len(v) for _, v in sets)
    if size > MAX_SETTINGS:
        raise CliError(f"--set: the grid has {size} settings ({' x '.join(str(len(v)) for _, v in sets)}); "
                       f"at most {MAX_SETTINGS} (give fewer values)")
    grid = []
    for combo in itertools.product(*(v for _, v in sets)):
        chosen = dict(zip(names, combo, strict=True))
        try:
            grid.append({**paper_settings(), **settings_of(framework_with(chosen))})
        except ValueError as exc:
            raise CliError(f"--set: {exc}") from None
    return names, grid


def cmd_sweep(args: argparse.Namespace) -> int:
    """Run ``haptic-study sweep``; errors raise :class:`CliError`."""
    from analysis.planning.sweep import CACHE_FILE, SWEEP_MARKER, is_cache_file
    from foundation.outdir import check_output_folder, ensure_output_folder, write_output_folder
    from study_app.headless.fanout import scheduler_address

    swept, grid = grid_of(args.grid)
    folder = dict(command="sweep", marker=SWEEP_MARKER, force=args.force, keep=is_cache_file)
    try:
        out = check_output_folder(args.out, **folder)  # before any work
        address = scheduler_address(args.scheduler)
    except InputRefused as exc:
        raise CliError(str(exc)) from None
    from pipeline.force.pipeline_settings import describe, framework_with, non_default_settings
    from protocol.study.config import ProtocolError, load_protocol

    try:
        protocol = one_part(load_protocol(args.protocol), args.protocol, args.part, "sweep")
        compared_measures(protocol.task, f"--part = {args.part!r}" if args.part else f"--protocol = {args.protocol!r}",
                          "sweep")
        for setting in grid:  # every setting's ramps fit the protocol's trials and pauses (else: one line)
            protocol.check_ramps(framework_with(setting).safety,
                                 f"protocol with --set {describe(non_default_settings(setting))}")
    except ProtocolError as exc:
        raise CliError(str(exc)) from None
    from analysis.planning.setting_labels import value_format
    from analysis.planning.sweep import FILTER_NOTE, caveat, summary_frame, summary_lines, sweep_frame, write_sweep
    from pipeline.force.pipeline_settings import paper_settings
    from study_app.headless.pool import default_jobs
    from study_app.headless.sim_trials import MODEL_FIT, MODEL_VERSION

    jobs = args.jobs or default_jobs(len(grid) * args.studies * args.participants)
    client = None
    try:
        if address is not None:
            from study_app.headless.fanout import connect

            client = connect(address)  # reached, with workers running this software, before the folder is made
        ensure_output_folder(out)
    except InputRefused as exc:
        if client is not None:
            client.close()
        raise CliError(str(exc), getattr(exc, "status", 2)) from None
    t0 = time.perf_counter()
    cells = _run_cells(args, grid, protocol, out / CACHE_FILE, jobs, client)
    wall = time.perf_counter() - t0
    paper = paper_settings()
    tidy = sweep_frame(cells, swept, protocol.trial.max_trial_s)
    summary = summary_frame(tidy, swept, paper)
    studies = f"{args.studies} stud{'y' if args.studies == 1 else 'ies'}"
    header = [f"Grid: {', '.join(swept)} = " + " x ".join(
        ",".join(map(value_format(vals), vals)) for _, vals in args.grid) + f" ({len(grid)} settings; the others the "
              f"paper's); {studies} per setting of {args.participants} simulated participants "
              f"(seed {args.seed}, the same participants for every setting); protocol {protocol.name!r}."]
    try:
        files = write_output_folder(out, lambda tmp: write_sweep(
            tmp, tidy=tidy, summary=summary, swept=swept, paper=paper, model_version=MODEL_VERSION,
            model_fit=MODEL_FIT, header=header), **folder)
    except InputRefused as exc:
        raise CliError(str(exc), getattr(exc, "status", 2)) from None
    print(caveat(MODEL_VERSION, MODEL_FIT))
    print(*header, sep="\n")
    print("Mean over studies [95 % t-interval over the study means, clipped to what the measure can be]; "
          "change = ON/OFF - 1.")
    if "filter_window" in swept:
        print(FILTER_NOTE)
    print("\n".join(summary_lines(summary, swept)))
    where = f"on the Dask cluster at {address}" if address else f"jobs {jobs}"
    print(f"Sweep: {len(cells)} cells ({len(grid)} settings x {studies}) in {wall:.1f} s wall "
          f"({where}). Written in {out}/: {', '.join(files)} (and {CACHE_FILE}, the cache)")
    return 0


def _run_cells(args: argparse.Namespace, grid: list[dict[str, float]], protocol: Any, cache: Path, jobs: int,
               client: Any) -> list[Any]:
    """The sweep's cells, from the cache or run (here or on ``client``'s cluster, closed after), with progress."""
    from study_app.cli.progress import ProgressBar
    from study_app.headless.fanout import ClusterError
    from study_app.headless.sweep_run import run_sweep

    bar: ProgressBar | None = None

    def show(p) -> None:
        nonlocal bar
        if bar is None:
            if p.cells_cached:
                print(f"sweep: {p.cells_cached} of {p.cells_total} cells from {cache}", file=sys.stderr)
            if not p.runs_total:
                return  # every cell cached: nothing to show progress of
            bar = ProgressBar(p.runs_total, "sweep", "participants", decimals=0)
        eta = "" if math.isnan(p.eta_s) else f", ETA {p.eta_s:.0f} s"
        bar.label = f"sweep: cells {p.cells_cached + p.cells_done}/{p.cells_total}{eta}"
        bar.update(p.runs_done)

    try:
        cells = run_sweep(grid, studies=args.studies, participants=args.participants, seed=args.seed,
                          cache=cache, jobs=jobs, protocol=protocol, on_progress=show, client=client)
    except ClusterError as exc:
        raise CliError(f"sweep: {exc}", 1) from None
    finally:
        if client is not None:
            client.close()
    if bar is not None:
        bar.close()
    return cells
