"""The ``report`` and ``plot-trial`` subcommands: analysis from the command line."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from foundation.errors import InputRefused
from pipeline.settings.tomlfields import SQLITE_INTEGER_MAX
from protocol.study.labels import plural
from study_app.cli.argtypes import add_command, arm_name, whole_number
from study_app.cli.error import CliError

if TYPE_CHECKING:
    from analysis.report.plan_report import PlanEntry
    from analysis.report.report import ReportSummary

__all__ = ["add_analysis_options", "add_report_parsers", "cmd_plot_trial", "cmd_report"]


def _confidence(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--confidence = {text!r}: expected a number") from None
    if not 0.5 <= v < 1.0:
        raise argparse.ArgumentTypeError(f"--confidence = {text!r}: must be in [0.5, 1), e.g. 0.95")
    return v


def site_name(text: str) -> str:
    """A site's name: letters, digits, ``-`` and ``_`` (it prefixes participant codes as ``NAME:CODE``)."""
    import re

    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_-]{0,31}", text):
        raise argparse.ArgumentTypeError(f"--site = {text!r}: allowed are 1-32 letters, digits, '-' and '_', "
                                         "beginning with a letter or digit (it prefixes codes as NAME:CODE)")
    return text


def add_analysis_options(parser: argparse.ArgumentParser) -> None:
    """The aggregation and test choices a report is made with (``report`` and ``power`` share them)."""
    parser.add_argument("--error-window", choices=("cue", "first_contact"), default="cue",
                        help="RMSE / Max AE from the cue (default) or from first contact")
    parser.add_argument("--tct", choices=("censored", "successful"), default="censored",
                        help="TCT with a failed trial at the trial cap (default: the paper's figure, every trial) or "
                             "over successful trials only (the paper's text); the report shows both, and TCT as a "
                             "time to event")
    parser.add_argument("--zero-method", choices=("wilcox", "pratt", "zsplit"), default="wilcox",
                        help="Wilcoxon handling of zero differences (default wilcox: dropped, as scipy and SPSS do)")


def add_report_parsers(sub: argparse._SubParsersAction) -> None:
    """Register ``report`` and ``plot-trial``."""
    r = add_command(
        sub, "report",
        "analyse study databases: Wilcoxon tests, the paper's figures, report.html and tidy CSV tables",
        "haptic-study report --db study.db --out report\n"
        "haptic-study report --db day1.db --db day2.db --out report --force   # two databases, one study\n"
        "haptic-study report --db a.db --site A --db b.db --site B --out pooled   # two sites: A:P01, B:P01",
        "Analyse one study (one or more databases): recompute every trial from its samples, test haptics ON "
        "against OFF per participant (paired Wilcoxon), draw the paper's figures, and write report.html, tidy "
        "CSV tables (trials, participants long and wide, tests) and codebook.csv describing every column",
    )
    r.add_argument("--db", action="append", required=True, metavar="PATH",
                   help="study database; repeat to merge several into one study")
    r.add_argument("--site", action="append", type=site_name, metavar="NAME",
                   help="the site of the --db before it (once after each --db): the sites are pooled, each "
                        "database's participant codes re-coded NAME:CODE on the fly (the files are not touched), "
                        "with a site term in the models, a table per site and each site's seed and protocol in "
                        "the methods")
    r.add_argument("--out", required=True, metavar="DIR", help="output folder (report.html, *.csv, figures/)")
    r.add_argument("--force", action="store_true",
                   help="replace the files an earlier report wrote in DIR, if unedited (the marker "
                        ".haptic-study-report lists them with their SHA-256); any other file, an edited one or an "
                        "input database in DIR is a refusal")
    add_analysis_options(r)
    r.add_argument("--confidence", type=_confidence, default=0.95,
                   help="confidence level of the Hodges–Lehmann interval (default 0.95)")
    r.add_argument("--power", action="store_true",
                   help="add 'what n would a study need': power against the number of participants, resampling "
                        "this study's participants (as haptic-study power with its defaults)")
    r.add_argument("--include-incomplete", action="store_true",
                   help="analyse the finished trials of experiment sessions that did not complete (aborted by the "
                        "experimenter, or interrupted and not resumed); by default they are left out, and listed "
                        "with the reason either way")
    r.set_defaults(handler=cmd_report)

    p = add_command(
        sub, "plot-trial", "one trial's force through the pipeline: task force against its band, rendered, raw",
        "haptic-study sessions --db study.db            # find the session\n"
        "haptic-study plot-trial --db study.db --session 4 --trial 7 --out trial7.pdf",
        "Draw one stored trial (the paper's Fig. 6): the task force the trial was judged on against its target "
        "band, the force rendered on the haptic device, and the raw sensor force on an axis of its own",
    )
    p.add_argument("--db", required=True, metavar="PATH", help="study database")
    p.add_argument("--session", type=whole_number("--session", 1, SQLITE_INTEGER_MAX), required=True, metavar="ID",
                   help="session id (haptic-study sessions --db PATH lists them)")
    p.add_argument("--trial", type=whole_number("--trial", 1, SQLITE_INTEGER_MAX, " (trials are numbered from 1)"),
                   required=True, metavar="N",
                   help="trial number within the session, from 1, as the GUI and trials.csv number them")
    p.add_argument("--out", required=True, metavar="FILE", help="figure file: .png (300 dpi), .pdf or .svg")
    p.add_argument("--arm", type=arm_name("--arm"), default=None, metavar="NAME",
                   help="a rig of several arms: draw this arm's records over the trial's window (default: the task "
                        "arm's, the trial's own)")
    p.set_defaults(handler=cmd_plot_trial)


def cmd_report(args: argparse.Namespace) -> int:
    """Run ``haptic-study report``; errors raise :class:`study_app.cli.error.CliError`."""
    from analysis.reading.inputs import check_databases
    from foundation.outdir import REPORT_MARKER, check_output_folder

    if args.site is not None and len(args.site) != len(args.db):
        raise CliError(f"--site: {len(args.site)} given for {len(args.db)} --db; give one --site after each --db "
                       "(report --db a.db --site A --db b.db --site B)")
    try:  # before the analysis is imported (seconds): a refused folder or database is said at once
        check_output_folder(args.out, command="report", marker=REPORT_MARKER, inputs=args.db, force=args.force)
        check_databases(args.db)
    except InputRefused as exc:
        raise CliError(str(exc)) from None
    from analysis.report.plan_report import study_plan

    plan = study_plan(args.db)
    if plan:  # a study of several parts: each experiment part's report, and the plan's page
        return _plan_report(args, plan)
    from analysis.reading.metrics import MetricOptions
    from analysis.report.report import build_report
    from study_app.cli.progress import ProgressBar

    bar: ProgressBar | None = None

    def show(done: float, total: float) -> None:
        nonlocal bar
        if bar is None:
            bar = ProgressBar(total, "reading samples", "samples", decimals=0)
        bar.update(done)

    try:
        summary = build_report(
            args.db, args.out, options=MetricOptions(args.error_window, args.tct),
            zero_method=args.zero_method, confidence=args.confidence, force=args.force, progress=show,
            power=args.power, include_incomplete=args.include_incomplete, sites=args.site,
        )
    except InputRefused as exc:
        raise CliError(str(exc), getattr(exc, "status", 2)) from None
    finally:
        if bar is not None:
            bar.close()
    ex = summary.excluded
    for line in summary.lines:  # the tasks' sections' own (a discrimination study's fits)
        print(line)
    for line in summary.damage:  # as every reader of the recording names it; the report lists the trials
        print(f"haptic-study: recording damaged: {line}: the trials it touches are left out of the analysis "
              f"(listed in {summary.out_dir / 'report.html'} under Trials that did not count)", file=sys.stderr)
    damaged = f", {plural(ex['damaged_trials'], 'trial')} with a damaged recording" if ex["damaged_trials"] else ""
    print(f"Report {summary.out_dir / 'report.html'}: {plural(summary.n_participants, 'participant')}, "
          f"{plural(summary.n_trials, 'trial')}, {plural(summary.n_samples, 'sample')} (excluded: "
          f"{plural(ex['training_trials'], 'training trial')}, {plural(ex['aborted_trials'], 'aborted trial')}"
          f"{damaged})")
    for line in summary.conditions:  # as the page opens with them
        print(f"haptic-study: warning: {line}", file=sys.stderr)
    if not summary.stats.empty:
        _print_tests(summary, args)
    print(f"Tables and figures in {summary.out_dir}/: " + ", ".join(f for f in summary.files if "/" not in f))
    return 0


def _print_tests(summary: ReportSummary, args: argparse.Namespace) -> None:
    """The tests ON vs OFF as stats.csv has them, with why a test's n is below the participants."""
    cols = ["metric", "n", "median_off", "median_on", "p_value", "p_holm", "method"]
    print("Paired Wilcoxon tests, haptics ON vs OFF (medians across participants; p_holm: Holm-adjusted; "
          f"error window: {args.error_window}, TCT: {args.tct}, zero differences: {args.zero_method}):")
    # stats.csv's values as it has them: rounded once there, never again here (2.4965 is not 2.497 here and
    # 2.496 on the page)
    print(summary.stats[cols].to_string(index=False, float_format=lambda v: "NaN" if v != v else repr(float(v))))
    for r in summary.stats.itertuples():  # why n is below the participants, as the page's footnotes say
        note = f": {r.note}" if isinstance(r.note, str) and r.note else ""
        if note or int(r.n) != summary.n_participants:
            print(f"  {r.metric}: {plural(int(r.n_pairs), 'complete pair')} of {summary.n_participants} "
                  f"participants, {plural(int(r.n_zero), 'zero difference')}{note}")


def _plan_report(args: argparse.Namespace, plan: Sequence[PlanEntry]) -> int:
    """A study of several parts: each experiment part's report in ``OUT/PART/`` and the plan's page, by the output
    policy (:mod:`analysis.report.plan_report`)."""
    from analysis.reading.metrics import MetricOptions
    from analysis.report.plan_report import write_plan_report
    from analysis.report.report import fill_report
    from foundation.outdir import REPORT_MARKER, write_output_folder

    if args.power or args.site:
        raise CliError("--power and --site are for a study of one task; this study has parts: report it without "
                       "them (each part's report is its own folder)")

    def fill_part(folder: Path, name: str, kind: str) -> tuple[list[str], Any]:
        # the part's sessions only: its task's core and section (analysis/report/section_KIND.py), one task
        s = fill_report(folder, args.db, part=name, options=MetricOptions(args.error_window, args.tct),
                        zero_method=args.zero_method, confidence=args.confidence,
                        include_incomplete=args.include_incomplete)
        return [f"{kind.replace('_', ' ')}: {plural(s.n_participants, 'participant')}, "
                f"{plural(s.n_trials, 'trial')}", *s.lines], s.overall

    lines: list[str] = []
    try:
        files = write_output_folder(args.out, lambda tmp: lines.extend(write_plan_report(tmp, args.db, plan,
                                                                                         fill_part)),
                                    command="report", marker=REPORT_MARKER, inputs=args.db, force=args.force)
    except InputRefused as exc:
        raise CliError(str(exc), getattr(exc, "status", 2)) from None
    for line in lines:
        print(line)
    if "learning.html" in files:
        print(f"Learning over visits: {args.out}/learning.html (learning.csv, retention.csv, learning_curve.png)")
    print(f"Report {args.out}/report.html (the plan) with a report per part: "
          + ", ".join(f for f in files if f.endswith("report.html")))
    return 0


def _trial_numbers(numbers: list[int]) -> str:
    """``1–20`` or ``1–5, 7, 9–12``: stored trial numbers, compactly."""
    runs: list[list[int]] = []
    for n in sorted(numbers):
        if runs and n == runs[-1][1] + 1:
            runs[-1][1] = n
        else:
            runs.append([n, n])
    return ", ".join(f"{a}" if a == b else f"{a}–{b}" for a, b in runs)


def cmd_plot_trial(args: argparse.Namespace) -> int:
    """Run ``haptic-study plot-trial`` (``--trial`` counts from 1)."""
    from pathlib import Path

    from foundation.outfile import check_output_file, write_output_file

    out = Path(args.out)
    if out.suffix.lower() not in (".png", ".pdf", ".svg"):
        raise CliError(f"--out = {args.out!r}: the file name must end in .png, .pdf or .svg")
    try:
        check_output_file(out, command="plot-trial")  # before the work: an existing file is never replaced
        from analysis.reading.load import load_study
        from analysis.reading.recorded import read_trial_samples

        study = load_study([args.db])
        trials = study.trials
        in_session = trials[trials["session_id"] == args.session]
        if in_session.empty:
            ids = ", ".join(str(int(i)) for i in sorted(trials["session_id"].unique()))
            raise CliError(f"--session {args.session}: no such session with trials in {args.db}; sessions with "
                           f"trials: {ids} (haptic-study sessions --db {args.db} lists them)")
        rows = in_session[in_session["trial_index"] == args.trial - 1]
        if rows.empty:
            numbers = [int(i) + 1 for i in in_session["trial_index"]]
            raise CliError(f"--trial {args.trial}: no such trial in session {args.session}; its stored trials are "
                           f"{_trial_numbers(numbers)}")
        row = rows.iloc[0]
        samples = read_trial_samples(args.db, args.session, args.trial - 1, args.arm)
    except InputRefused as exc:
        raise CliError(str(exc)) from None
    # matplotlib: once the trial is known to be there
    from analysis.plots.figures import save_one, stored_trial_figure

    task = study.task_of(row["database"], row["session_id"])  # the session's task draws its band
    fig = stored_trial_figure(args.db, row, samples, task)  # an aborted trial: its abort, time and cause marked
    try:
        write_output_file(out, lambda path: save_one(fig, path), command="plot-trial")
    except InputRefused as exc:
        raise CliError(str(exc), getattr(exc, "status", 2)) from None
    print(f"wrote {out}")
    return 0
