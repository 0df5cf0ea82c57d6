"""``haptic-study discrimination``: a simulated force-discrimination study, its fits, tables and figures (issue 43).

The block runs headless (:mod:`study_app.headless.discrimination_run`: QUEST+, the command through the safety stage,
the simulated observer); per participant and reference the psychometric fit (:mod:`analysis.stats.psychometric`);
the outputs by the house's output policy (:func:`foundation.outdir.write_output_folder`).  A study database does not
hold a discrimination block yet (the session runner renders contact forces, not commanded ones, and takes no
answers): ``run`` refuses such a protocol in one line and names this command.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

from foundation.errors import InputRefused
from study_app.cli.argtypes import SEED, add_command, whole_number
from study_app.cli.error import CliError
from study_app.cli.part_choice import PART_HELP, one_part

__all__ = ["DISCRIMINATION_MARKER", "add_discrimination_parser", "cmd_discrimination"]

#: The marker of the command's output folder (:mod:`foundation.outdir`).
DISCRIMINATION_MARKER = ".haptic-study-discrimination"


def add_discrimination_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``discrimination``."""
    d = add_command(sub, "discrimination", "run a simulated force-discrimination study and fit each participant's JND",
                    "haptic-study discrimination --protocol docs/examples/discrimination.toml --participants 10 "
                    "--seed 0 --out disc")
    d.add_argument("--protocol", required=True, metavar="FILE", help="a protocol file whose [task] kind is "
                   "force_discrimination (docs/examples/discrimination.toml)")
    d.add_argument("--part", default=None, metavar="NAME", help=PART_HELP)
    d.add_argument("--participants", type=whole_number("--participants", 1, 999), default=10,
                   help="number of simulated participants (default 10)")
    d.add_argument("--seed", type=SEED, default=0, help="study seed: orders, observers and answers (default 0)")
    d.add_argument("--out", required=True, metavar="DIR", help="output folder (tables, codebook, figures)")
    d.add_argument("--force", action="store_true", help="replace this command's earlier outputs in --out")
    d.set_defaults(handler=cmd_discrimination)


def cmd_discrimination(args: argparse.Namespace) -> int:
    """Run ``haptic-study discrimination``; errors raise :class:`CliError`."""
    from foundation.outdir import check_output_folder, write_output_folder
    from protocol.study.config import load_protocol
    from protocol.tasks.force_discrimination import ForceDiscrimination

    folder = dict(command="discrimination", marker=DISCRIMINATION_MARKER, inputs=[], force=args.force)
    try:
        protocol = one_part(load_protocol(args.protocol), args.protocol, args.part, "discrimination")
        if not isinstance(protocol.task, ForceDiscrimination):
            which = f"--part = {args.part!r}" if args.part else f"--protocol = {args.protocol!r}"
            raise CliError(f"{which}: its task.kind is {protocol.task.kind!r}; discrimination "
                           "needs 'force_discrimination'")
        check_output_folder(args.out, **folder)  # before any work
    except (InputRefused, ValueError) as exc:
        raise CliError(str(exc)) from None

    from analysis.report.section_discrimination import BlockResult, write_discrimination
    from study_app.headless.discrimination_run import run_participants

    results = [BlockResult(r.observer.participant, [dataclasses.asdict(t) for t in r.trials], r.fits, r.observer.weber,
                           r.observer.lapse)
               for r in run_participants(protocol, args.participants, args.seed)]
    try:
        files = write_output_folder(args.out, lambda tmp: write_discrimination(results, tmp), **folder)
    except InputRefused as exc:
        raise CliError(str(exc), getattr(exc, "status", 2)) from None
    inside = sum(int(f.weber_lo <= (r.true_weber or 0.0) <= f.weber_hi) for r in results for _, f in r.fits)
    for r in results:
        print(f"P{r.participant:02d}  true W {r.true_weber:.3f}  " + "  ".join(
            f"{label} W {f.weber:.3f} [{f.weber_lo:.3f}, {f.weber_hi:.3f}]" for label, f in r.fits))
    total = sum(len(r.fits) for r in results)
    print(f"true Weber fraction within the fitted 95 % interval: {inside} of {total} fits", file=sys.stderr)
    print(f"Written in {args.out}/: {', '.join(f for f in files if '/' not in f)} and {len(results)} figures")
    return 0

