"""``power --groups``: plan a two-group study (the group × haptics interaction's power against participants per
group; :mod:`analysis.planning.group_power`).

The pool is a pilot database whose protocol declares ``[groups]`` (``--db``), or simulated participants of both
kinds (``--simulated``: the protocol of ``--protocol FILE``, which must declare ``[groups]``, or by default the
paper's protocol with a ``group`` covariate of novices and surgeons placed in turn, the surgeons simulated with the
experienced profile: :mod:`pipeline.sim.experience`).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from collections.abc import Callable
from typing import Any

from study_app.cli.error import CliError
from study_app.cli.part_choice import one_part

__all__ = ["GROUP_POWER_FILES", "check_group_request", "default_two_group_protocol", "run_group_power"]

#: The files ``power --groups`` writes.
GROUP_POWER_FILES = ("group_power.csv", "group_power.txt")
#: Studies × n per group from which a progress bar and the size up front are shown.
_BAR_DRAWS = 2_000_000


def check_group_request(args: argparse.Namespace) -> Any:
    """``--protocol`` checked (before any work): the protocol to simulate, or None (a pilot's own, or the
    default two-group one).  One line, exit 2, for a file without ``[groups]`` or ``--protocol`` without
    ``--simulated``."""
    if args.protocol is None:
        return None
    if not args.simulated:
        raise CliError(f"--protocol = {args.protocol!r}: only with --groups --simulated (a pilot's protocol is its "
                       "own)")
    from protocol.study.config import ProtocolError, load_protocol

    try:
        protocol = load_protocol(args.protocol)
    except ProtocolError as exc:
        raise CliError(str(exc)) from None
    protocol = one_part(protocol, args.protocol, args.part, "power")
    if protocol.groups is None:
        raise CliError(f"--protocol = {args.protocol!r}: declares no [groups]; a two-group plan needs the covariate "
                       "that divides the participants (docs/groups.md)")
    return protocol


def default_two_group_protocol() -> Any:
    """The paper's protocol with a required ``group`` covariate (novice, surgeon), placed in turn and the surgeons
    simulated experienced."""
    from protocol.study.config import default_protocol
    from protocol.study.covariates import Covariate
    from protocol.study.groups import GroupDesign

    group = Covariate("group", "category", ("novice", "surgeon"), required=True, label="Surgical experience")
    return dataclasses.replace(default_protocol(), name="Force regulation, novices and surgeons (power --groups)",
                               covariates=(group,),
                               groups=GroupDesign("group", group.levels, group.levels, ("surgeon",)))


def _say_the_size(n_values: tuple[int, ...], resamples: int) -> None:
    draws = 2 * resamples * sum(n_values)
    if draws >= _BAR_DRAWS:
        print(f"power: {resamples:,} resampled two-group studies for each of {len(n_values)} sizes per group "
              f"({draws:,} participants drawn); the bar says how long is left, Ctrl-C stops it with nothing written",
              file=sys.stderr)


def run_group_power(args: argparse.Namespace, req: Any, protocol: Any, folder: dict[str, Any], bars: Any,
                    simulated_source: Callable[..., tuple[list[str], Any, str]], client: Any = None) -> int:
    """Build the pool (simulate it by ``simulated_source``, ``power``'s own -- its participants on ``client``'s Dask
    cluster when one is given -- or read the pilot), estimate the power and write the files."""
    from analysis.planning.group_power import estimate_group_power, group_pool, group_power_text
    from analysis.reading.annotations import read_annotations
    from analysis.reading.load import load_study
    from analysis.reading.metrics import MetricOptions, compute_trials
    from foundation.outdir import write_output_folder

    options = MetricOptions(args.error_window, args.tct)
    databases, participants, source = list(args.db or []), None, None
    if args.simulated:
        databases, participants, source = simulated_source(args.out, req, bars,
                                                           protocol or default_two_group_protocol(), client=client)
    study = load_study(databases, part=args.part if args.db else None)
    if participants is not None:
        keep = set(participants)
        study = dataclasses.replace(study, trials=study.trials[study.trials["participant_code"].isin(keep)],
                                    sessions=study.sessions[study.sessions["participant_code"].isin(keep)])
    trials = compute_trials(study, options, progress=bars.reading).trials
    bars.close()
    ann = read_annotations(databases)
    pool = group_pool(trials, ann.covariates, ann.groups, options,
                      source=source or "the pilot study " + ", ".join(str(d) for d in databases)
                      + (f" (its part {args.part!r})" if args.part else ""))
    _say_the_size(req.n_values, req.resamples)
    t0 = time.perf_counter()
    big = 2 * req.resamples * sum(req.n_values) >= _BAR_DRAWS
    frame = estimate_group_power(pool, req.n_values, resamples=req.resamples, alpha=req.alpha, seed=req.seed,
                                 progress=bars.measures if big else None)
    bars.close()
    text = group_power_text(frame, pool, req.alpha)

    def fill(tmp: Any) -> list[str]:
        from analysis.reading import codebook

        # powers and their intervals to 4 decimals (as power.csv), the pool's median effects to 6
        shown = frame.round({c: 4 for c in ("power", "ci_low", "ci_high", "power_two_sided")}
                            | {"median_effect_reference": 6, "median_effect_group": 6})
        shown.assign(metric=shown["metric"].map(codebook.exported_name)).to_csv(tmp / "group_power.csv", index=False)
        (tmp / "group_power.txt").write_text(text + "\n", encoding="utf-8")
        return list(GROUP_POWER_FILES)

    files = write_output_folder(args.out, fill, **folder)
    print(f"power: {len(frame) * req.resamples:,} resampled Mann-Whitney tests in {time.perf_counter() - t0:.2f} s",
          file=sys.stderr)
    print(text)
    print(f"Written in {args.out}/: {', '.join(files)}")
    return 0
