"""The ``report`` and ``plot-trial`` subcommands: analysis from the command line."""

from __future__ import annotations

import argparse
import sys

__all__ = ["add_analysis_options", "add_report_parsers", "cmd_plot_trial", "cmd_report"]


def _confidence(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--confidence = {text!r}: expected a number") from None
    if not 0.5 <= v < 1.0:
        raise argparse.ArgumentTypeError(f"--confidence = {text!r}: must be in [0.5, 1), e.g. 0.95")
    return v


def add_analysis_options(parser: argparse.ArgumentParser) -> None:
    """The aggregation and test choices a report is made with (``report`` and ``power`` share them)."""
    parser.add_argument("--error-window", choices=("cue", "first_contact"), default="cue",
                        help="RMSE / Max AE from the cue (default) or from first contact")
    parser.add_argument("--tct", choices=("successful", "censored"), default="successful",
                        help="TCT over successful trials only (default) or failures censored at the trial cap")
    parser.add_argument("--zero-method", choices=("wilcox", "pratt", "zsplit"), default="wilcox",
                        help="Wilcoxon handling of zero differences (default wilcox: dropped, as scipy and SPSS do)")


def add_report_parsers(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Register ``report`` and ``plot-trial``."""
    r = sub.add_parser(
        "report",
        help="analyse study databases: Wilcoxon tests, the paper's figures, report.html and tidy CSV tables",
    )
    r.add_argument("--db", action="append", required=True, metavar="PATH",
                   help="study database; repeat to merge several into one study")
    r.add_argument("--out", required=True, metavar="DIR", help="output folder (report.html, *.csv, figures/)")
    r.add_argument("--force", action="store_true", help="replace DIR if it exists and is not empty")
    add_analysis_options(r)
    r.add_argument("--confidence", type=_confidence, default=0.95,
                   help="confidence level of the Hodges–Lehmann interval (default 0.95)")
    r.add_argument("--power", action="store_true",
                   help="add 'what n would a study need': power against the number of participants, resampling "
                        "this study's participants (as haptic-study power with its defaults)")

    p = sub.add_parser("plot-trial", help="one trial's force through the pipeline: raw, compensated, rendered (paper Fig. 6)")
    p.add_argument("--db", required=True, metavar="PATH", help="study database")
    p.add_argument("--session", type=int, required=True, help="session_id")
    p.add_argument("--trial", type=int, required=True, help="trial_index within the session")
    p.add_argument("--out", required=True, metavar="FILE", help="image file: .png or .svg")


def cmd_report(args: argparse.Namespace) -> int:
    """Run ``haptic-study report``; errors raise :class:`study_app.cli.CliError`."""
    from analysis.load import AnalysisError
    from analysis.metrics import MetricOptions
    from analysis.report import build_report
    from study_app.cli import CliError
    from study_app.progress import ProgressBar

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
            power=args.power,
        )
    except AnalysisError as exc:
        raise CliError(str(exc)) from None
    finally:
        if bar is not None:
            bar.close()
    ex = summary.excluded
    print(f"Report {summary.out_dir / 'report.html'}: {summary.n_participants} participants, {summary.n_trials} trials, "
          f"{summary.n_samples:,} samples (excluded: {ex['training_trials']} training trials, "
          f"{ex['aborted_trials']} aborted trials)")
    cols = ["metric", "n", "median_off", "median_on", "p_value", "p_holm", "method"]
    print(summary.stats[cols].to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    print(f"Tables and figures in {summary.out_dir}/: " + ", ".join(f for f in summary.files if "/" not in f))
    return 0


def cmd_plot_trial(args: argparse.Namespace) -> int:
    """Run ``haptic-study plot-trial``."""
    from pathlib import Path

    from analysis.figures import pipeline_trace
    from analysis.load import AnalysisError, load_study, read_trial_samples
    from study_app.cli import CliError

    out = Path(args.out)
    if out.suffix.lower() not in (".png", ".svg"):
        raise CliError(f"--out = {args.out!r}: the file name must end in .png or .svg")
    if not out.resolve().parent.is_dir():
        raise CliError(f"--out = {args.out!r}: the folder {out.resolve().parent} does not exist")
    try:
        study = load_study([args.db])
        rows = study.trials[(study.trials["session_id"] == args.session) & (study.trials["trial_index"] == args.trial)]
        if rows.empty:
            raise CliError(f"--session {args.session} --trial {args.trial}: no such trial in {args.db}")
        row = rows.iloc[0]
        samples = read_trial_samples(args.db, args.session, args.trial)
    except AnalysisError as exc:
        raise CliError(str(exc)) from None
    title = (f"{row['participant_code']}, session {args.session}, trial {args.trial}: {row['target_label']} "
             f"{row['target_force_n']:g} N, haptics {str(row['haptic_mode']).upper()}, {row['outcome']}")
    fig = pipeline_trace(samples, target_force_n=float(row["target_force_n"]),
                         tolerance_fraction=float(row["tolerance_fraction"]), title=title)
    fig.savefig(out, dpi=150)
    print(f"wrote {out}", file=sys.stderr)
    return 0
