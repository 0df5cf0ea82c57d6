"""The study report: one self-contained HTML page, tidy CSV tables and the figures.

:func:`build_report` reads one or more study databases, recomputes every
trial's metrics from its samples, aggregates per participant and mode, tests
ON vs OFF, draws the paper's figures and writes::

    DIR/report.html            figures embedded, tables, methods paragraph
    DIR/trials.csv             one row per analysed trial
    DIR/participants.csv       per participant × haptic mode
    DIR/participants_by_target.csv
    DIR/stats.csv              one row per metric (paired Wilcoxon ON vs OFF, Holm across metrics)
    DIR/stats_by_target.csv    the same within each target
    DIR/speed_accuracy.csv     TCT–RMSE rank correlation per mode
    DIR/sessions.csv           every session read, with what was excluded
    DIR/figures/*.png, *.svg

The report is built in a temporary folder beside ``DIR`` and moved into place
at the end, so a failed run never leaves half a report or touches an old one.
"""

from __future__ import annotations

import base64
import datetime as dt
import html
import math
import os
import shutil
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from analysis import figures
from analysis.aggregate import METRIC_LABELS, PRIMARY_METRICS, mode_tests, per_participant, speed_accuracy
from analysis.load import AnalysisError, Progress, StudyData, load_study
from analysis.metrics import MetricOptions, TrialTable, compute_trials
from analysis.parallel import default_workers, run_tasks
from analysis.stats import WilcoxonResult, methods_text
from protocol.metrics import BAND_SLACK, CONTACT_THRESHOLD_N
from protocol.version import software_version

__all__ = ["ReportSummary", "TRIALS_CSV_COLUMNS", "STATS_CSV_COLUMNS", "build_report"]

#: trials.csv: the columns every consumer may rely on, in this order (more follow).
TRIALS_CSV_COLUMNS = ("participant_code", "session_id", "trial_index", "target_label", "target_force_n",
                      "haptic_mode", "outcome", "success", "tct_s", "rmse_n", "max_ae_n")
#: stats.csv: the columns every consumer may rely on, in this order (more follow).
STATS_CSV_COLUMNS = ("metric", "n", "median_off", "median_on", "statistic", "p_value", "method",
                     "zero_method", "rank_biserial", "p_holm")


@dataclass(frozen=True, slots=True)
class ReportSummary:
    """What :func:`build_report` wrote and found."""

    out_dir: Path
    n_participants: int
    n_trials: int
    n_samples: int
    excluded: dict[str, int]
    stats: pd.DataFrame
    files: list[str] = field(default_factory=list)


def _stats_table(frame: pd.DataFrame) -> pd.DataFrame:
    out = frame.copy()
    out.insert(1, "n", out["n_used"])
    rest = [c for c in out.columns if c not in STATS_CSV_COLUMNS]
    return out[list(STATS_CSV_COLUMNS) + rest]


def _fmt(v: object, digits: int = 3) -> str:
    if v is None:
        return ""
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        f = float(v)
        if math.isnan(f):
            return "–"
        if f != 0 and (abs(f) < 1e-3 or abs(f) >= 1e5):
            return f"{f:.{digits}g}"
        return f"{f:.{digits}f}"
    return html.escape(str(v))


def _html_table(frame: pd.DataFrame, columns: Sequence[str] | None = None) -> str:
    cols = list(columns) if columns else list(frame.columns)
    head = "".join(f"<th>{html.escape(c)}</th>" for c in cols)
    body = []
    for _, row in frame.iterrows():
        cells = "".join(f"<td>{_fmt(row[c])}</td>" for c in cols)
        body.append(f"<tr>{cells}</tr>")
    return f'<div class="scroll"><table><thead><tr>{head}</tr></thead><tbody>{"".join(body)}</tbody></table></div>'


def _stats_html(frame: pd.DataFrame, columns: Sequence[str], lead: Sequence[str] = ()) -> str:
    """A test table for the page: HL estimate and interval in one column, notes as numbered footnotes."""
    shown = frame.copy()
    shown["hl"] = [
        f"{_fmt(e)} [{_fmt(lo)}, {_fmt(hi)}]" if np.isfinite(e) else "–"
        for e, lo, hi in zip(shown["hl_estimate"], shown["hl_ci_low"], shown["hl_ci_high"])
    ]
    notes: list[str] = []
    labels = []
    for _, row in shown.iterrows():
        label = str(row["metric"])
        if isinstance(row.get("note"), str) and row["note"]:
            notes.append(row["note"])
            label += f" <sup>{len(notes)}</sup>"
        labels.append(label)
    cols = list(lead) + list(columns)
    head = "".join(f"<th>{html.escape('HL median difference [CI]' if c == 'hl' else c)}</th>" for c in cols)
    body = []
    for label, (_, row) in zip(labels, shown.iterrows()):
        cls = ' class="nc"' if not bool(row["computable"]) else ""
        cells = "".join(f"<td>{label if c == 'metric' else (row[c] if c == 'hl' else _fmt(row[c]))}</td>" for c in cols)
        body.append(f"<tr{cls}>{cells}</tr>")
    foot = "".join(f"<li>{html.escape(n)}</li>" for n in notes)
    return (f'<div class="scroll"><table><thead><tr>{head}</tr></thead><tbody>{"".join(body)}</tbody></table></div>'
            + (f'<ol class="notes">{foot}</ol>' if foot else ""))


def _img(png: bytes, alt: str) -> str:
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{base64.b64encode(png).decode("ascii")}">'


def _example_trials(trials: pd.DataFrame) -> list[pd.Series]:
    """One trial per mode for the pipeline figure: the first participant's first success (else first trial)."""
    first = sorted(trials["participant_code"].unique())[0]
    mine = trials[trials["participant_code"] == first]
    picks = []
    for mode in ("on", "off"):
        sel = mine[mine["haptic_mode"] == mode]
        if sel.empty:
            continue
        ok = sel[sel["success"]]
        picks.append((ok if not ok.empty else sel).iloc[0])
    return picks


def _marks(results: Sequence[WilcoxonResult], frame: pd.DataFrame) -> dict[str, str]:
    holm = dict(zip(frame["metric"], frame["p_holm"]))
    return {r.metric: figures.significance_mark(r, p_holm=holm.get(r.metric)) for r in results}


def _methods(study: StudyData, table: TrialTable, options: MetricOptions, zero_method: str, confidence: float,
             excluded: dict[str, int], n_participants: int, n_incomplete: int) -> str:
    trials = study.included
    tol = sorted(set(trials["tolerance_fraction"]))
    hold = sorted(set(trials["hold_s"]))
    cap = sorted(set(trials["max_trial_s"]))
    targets = (trials.drop_duplicates("target_label").sort_values("target_force_n")[["target_label", "target_force_n"]])
    target_txt = ", ".join(f"{lab} {f:g} N" for lab, f in zip(targets["target_label"], targets["target_force_n"]))

    def one(vals: list[float], unit: str) -> str:
        return " / ".join(f"{v:g}{unit}" for v in vals)

    window = ("from the cue to the trial end, the approach before contact included"
              if options.error_window == "cue" else
              f"from first contact (the first sample with task force above {CONTACT_THRESHOLD_N:g} N) to the trial end; "
              "a trial without contact has no RMSE or Max AE")
    tct = ("averaged over successful trials only, so it is undefined for a participant with no success in a mode "
           "(that participant's pair is left out of the TCT test and counted)"
           if options.tct_policy == "successful" else
           f"averaged over all trials, a failed trial counting as the trial cap ({one(cap, ' s')})")
    sessions = study.sessions
    exp = sessions[sessions["kind"] == "experiment"]
    versions = ", ".join(sorted(set(sessions["software_version"])))
    dbs = ", ".join(html.escape(os.path.basename(d)) for d in study.databases)
    check = (f"All {table.n_from_samples} analysed trials were recomputed from their stored 1 kHz samples"
             + (f" and agree with the values stored live" if table.n_disagree == 0 else
                f"; {table.n_disagree} disagree with the values stored live (the recomputed values are used)")
             + (f"; {table.n_stored_only} trials without samples use their stored values" if table.n_stored_only else "")
             + ".")
    return (
        f"<p><b>Data.</b> {n_participants} participants, {len(exp)} experiment sessions "
        f"({n_incomplete} not completed) from {len(study.databases)} database(s) ({dbs}), "
        f"{len(trials)} analysed trials. Excluded: {excluded['training_sessions']} training sessions "
        f"({excluded['training_trials']} trials) and {excluded['aborted_trials']} aborted trials "
        f"(each re-run later in its session). Recorded with haptic-study {html.escape(versions)}; "
        f"analysed with haptic-study {html.escape(software_version())}. {check}</p>"
        f"<p><b>Trial metrics.</b> Targets: {html.escape(target_txt)}. The task force is the magnitude of the "
        f"filtered, gravity- and bias-compensated contact force. A sample is in the band when |F − F*| ≤ "
        f"{one([100 * t for t in tol], ' %')} of F* (edges included, relative slack {BAND_SLACK:g}). A trial succeeds "
        f"when the force stays in the band continuously for {one(hold, ' s')} (leaving the band restarts the hold) "
        f"within {one(cap, ' s')} of the cue; TCT is the time from the cue to the end of that hold. RMSE and Max AE "
        f"of F against F* are taken {window}. Time in band is the number of in-band samples times 1 ms; peak force "
        f"is the largest task force in the window. These are the definitions of protocol.metrics, the same code "
        f"that judged the trials live.</p>"
        f"<p><b>Aggregation.</b> For each participant and haptic mode, the success rate is successes / trials and "
        f"RMSE, Max AE, time in band and peak force are means over trials; TCT is {tct}. Bars show the mean across "
        f"participants with ±1 SD (n − 1); dots are participants.</p>"
        f"<p><b>Tests.</b> {html.escape(methods_text(zero_method, confidence))} Holm's step-down correction is "
        f"applied across the {len(PRIMARY_METRICS)} outcome measures ({', '.join(PRIMARY_METRICS)}), and separately "
        f"within each target; significance marks in the figures use the Holm-adjusted p-values "
        f"(* p &lt; 0.05, ** p &lt; 0.01, *** p &lt; 0.001, n/c not computable). The speed–accuracy trade is the "
        f"Spearman rank correlation of TCT with RMSE over trials, per mode.</p>"
    )


_CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222;line-height:1.45}
h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:1px solid #ddd;padding-bottom:.2em;margin-top:1.8em}
.meta{color:#666;font-size:.9em}table{border-collapse:collapse;margin:.6em 0 1.2em;font-size:.85em}
th,td{border:1px solid #ddd;padding:3px 7px;text-align:right;white-space:nowrap}th{background:#f4f4f4}td:first-child,th:first-child{text-align:left}
tr.nc td{color:#999;font-style:italic}img{max-width:100%;height:auto;display:block;margin:.5em 0}
.key{display:grid;grid-template-columns:repeat(auto-fit,minmax(180px,1fr));gap:.6em;margin:1em 0}
.key div{background:#f7f9fc;border:1px solid #e3e8f0;border-radius:6px;padding:.6em .8em}
.key b{display:block;font-size:1.3em}.scroll{overflow-x:auto}.notes{font-size:.85em;color:#555}.warn{background:#fff4e5;border:1px solid #f0c36d;padding:.5em .8em;border-radius:6px}
"""


def build_report(
    databases: Sequence[str | os.PathLike[str]],
    out_dir: str | os.PathLike[str],
    *,
    options: MetricOptions = MetricOptions(),
    zero_method: str = "wilcox",
    confidence: float = 0.95,
    force: bool = False,
    progress: Progress | None = None,
    workers: int | None = None,
    power: bool = False,
) -> ReportSummary:
    """Analyse one study (one or more databases) and write its report.

    Parameters
    ----------
    databases
        Study databases; they merge into one study.
    out_dir
        Output folder.  It must not exist (or be empty) unless ``force``.
    options
        Error window and TCT policy.
    zero_method, confidence
        Wilcoxon zero handling and the Hodges–Lehmann confidence level.
    force
        Replace an existing, non-empty ``out_dir``.
    progress
        ``progress(samples read, samples expected)``.
    workers
        Processes for reading samples and drawing figures (default: the usable cores, at most 4; 1 = none).
    power
        Add "What n would a study need?": the power of the tests against the number of participants, by
        resampling this study's participants (:func:`analysis.power.report_section`; writes ``power.csv``).

    Returns
    -------
    ReportSummary

    Raises
    ------
    AnalysisError
        Unreadable input, nothing to analyse, or an existing output folder without ``force``.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise AnalysisError(f"--out {out}: exists and is not a folder")
    if out.exists() and any(out.iterdir()) and not force:
        raise AnalysisError(f"--out {out}: the folder exists and is not empty; pass --force to replace it")
    parent = out.resolve().parent
    if not parent.exists():
        raise AnalysisError(f"--out {out}: the folder {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise AnalysisError(f"--out {out}: cannot write in {parent}")

    study = load_study(databases)
    table = compute_trials(study, options, progress=progress, workers=workers)
    trials = table.trials
    overall = per_participant(trials, options)
    by_target = per_participant(trials, options, by_target=True)
    results, stats = mode_tests(overall, zero_method=zero_method, confidence=confidence)
    target_order = list(trials.drop_duplicates("target_label").sort_values("target_force_n")["target_label"])
    per_target: list[pd.DataFrame] = []
    target_results: dict[str, list[WilcoxonResult]] = {}
    for label in target_order:
        res, frame = mode_tests(by_target[by_target["target_label"] == label], zero_method=zero_method, confidence=confidence)
        frame.insert(0, "target_label", label)
        per_target.append(frame)
        target_results[label] = res
    stats_by_target = pd.concat(per_target, ignore_index=True)
    sa = speed_accuracy(trials, options)

    all_t = study.trials
    excluded = {
        "training_sessions": int((study.sessions["kind"] != "experiment").sum()),
        "training_trials": int((all_t["excluded"] == "training session").sum()),
        "aborted_trials": int((all_t["excluded"] == "aborted trial").sum()),
    }
    exp = study.sessions[study.sessions["kind"] == "experiment"]
    n_incomplete = int((exp["status"] != "completed").sum())
    n_participants = int(trials["participant_code"].nunique())

    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=parent))
    try:
        fig_dir = tmp / "figures"
        marks_overall = _marks(results, stats)
        marks: dict[tuple[str, str], str] = {(m, "overall"): s for m, s in marks_overall.items()}
        for label in target_order:
            frame = stats_by_target[stats_by_target["target_label"] == label]
            for m, s in _marks(target_results[label], frame).items():
                marks[(m, label)] = s
        tct_col = "tct_s" if options.tct_policy == "successful" else "tct_censored_s"
        rho_txt = {r.haptic_mode: (f"ρ = {r.rho:.2f}, p = {r.p_value:.3g}, n = {r.n}" if r.computable else "not computable")
                   for r in sa.itertuples()}
        bars = dict(target_order=target_order)
        tasks: list[tuple[str, tuple, dict, str, str]] = [
            ("mode_bars", (["success_rate"], overall, by_target, marks), bars, "success_rate", "success_rate"),
            ("mode_bars", (["tct_s"], overall, by_target, marks), bars, "tct", "tct"),
            ("mode_bars", (["rmse_n", "max_ae_n"], overall, by_target, marks), bars, "rmse_max_ae", "errors"),
            ("paired_lines", (overall, PRIMARY_METRICS, marks_overall), {}, "paired", "paired"),
            ("speed_accuracy_scatter", (trials, tct_col, rho_txt), {}, "speed_accuracy", "speed_accuracy"),
        ]
        titles = []
        for ex in _example_trials(trials):
            name = f"pipeline_{ex['participant_code']}_s{int(ex['session_id'])}_t{int(ex['trial_index'])}"
            title = (f"{ex['participant_code']}, trial {int(ex['trial_index'])}: {ex['target_label']} "
                     f"{ex['target_force_n']:g} N, haptics {str(ex['haptic_mode']).upper()}, {ex['outcome']}")
            tol = float(study.included.loc[(study.included["database"] == ex["database"]) &
                                           (study.included["session_id"] == ex["session_id"]), "tolerance_fraction"].iloc[0])
            tasks.append(("trial_trace", (str(ex["database"]), int(ex["session_id"]), int(ex["trial_index"])),
                          dict(target_force_n=float(ex["target_force_n"]), tolerance_fraction=tol, title=title),
                          name, name))
            titles.append((name, title))
        drawn = run_tasks(figures.render, [(b, a, k, str(fig_dir), f) for b, a, k, f, _ in tasks],
                          workers=default_workers() if workers is None else workers)
        pngs = {key: png for (_, _, _, _, key), png in zip(tasks, drawn)}
        examples = [(title, pngs[name]) for name, title in titles]

        trials_csv = trials[list(TRIALS_CSV_COLUMNS) + [c for c in trials.columns if c not in TRIALS_CSV_COLUMNS]].copy()
        trials_csv["database"] = trials_csv["database"].map(os.path.basename)
        trials_csv.to_csv(tmp / "trials.csv", index=False)
        overall.to_csv(tmp / "participants.csv", index=False)
        by_target.to_csv(tmp / "participants_by_target.csv", index=False)
        stats_out = _stats_table(stats)
        stats_out.to_csv(tmp / "stats.csv", index=False)
        tgt_out = _stats_table(stats_by_target.drop(columns="target_label"))
        tgt_out.insert(0, "target_label", stats_by_target["target_label"].to_numpy())
        tgt_out.to_csv(tmp / "stats_by_target.csv", index=False)
        sa.to_csv(tmp / "speed_accuracy.csv", index=False)
        sess = study.sessions.copy()
        sess["database"] = sess["database"].map(os.path.basename)
        sess.to_csv(tmp / "sessions.csv", index=False)

        power_html = ""
        if power:
            from analysis.power import report_section

            text, png = report_section(trials, options, zero_method, tmp)
            power_html = (f'<h2>What n would a study need?</h2><pre style="white-space:pre-wrap">{html.escape(text)}'
                          "</pre>" + (_img(png, "power of each test against the number of participants") if png else ""))

        # -- the page ----------------------------------------------------------------------
        by_metric = stats_out.set_index("metric")
        key = "".join(
            f"<div>{html.escape(METRIC_LABELS[m])}<b>{_fmt(by_metric.at[m, 'median_off'])} → "
            f"{_fmt(by_metric.at[m, 'median_on'])}</b>median OFF → ON (n = {_fmt(by_metric.at[m, 'n'])}), "
            f"{marks_overall.get(m, '')}</div>"
            for m in PRIMARY_METRICS
        )
        stat_cols = ["metric", "n", "n_zero", "n_ties", "median_off", "median_on", "hl", "statistic", "method",
                     "p_value", "p_holm", "rank_biserial", "r"]
        warn = ""
        if table.n_disagree:
            warn = (f'<p class="warn">{table.n_disagree} trials disagree between the metrics stored live and those '
                    "recomputed from samples; see the methods.</p>")
        nc = stats_out[~stats_out["computable"]] if "computable" in stats_out.columns else stats_out.iloc[:0]
        if len(nc):
            warn += ('<p class="warn">Not computable: '
                     + "; ".join(f"{html.escape(str(r.metric))}: {html.escape(str(r.note))}" for r in nc.itertuples())
                     + "</p>")
        now = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>haptic-study report</title><style>{_CSS}</style></head><body>
<h1>Haptic feedback study: report</h1>
<p class="meta">{n_participants} participants · {len(trials)} trials · generated {now} by haptic-study {html.escape(software_version())}
· error window: {options.error_window} · TCT: {options.tct_policy}</p>
{warn}
<div class="key">{key}</div>
<h2>Haptics ON vs OFF</h2>
<p>Paired Wilcoxon signed-rank tests across participants (differences ON − OFF); Holm-adjusted across the four measures.</p>
{_stats_html(stats_out, stat_cols)}
<h3>Within each target</h3>
{_stats_html(tgt_out, stat_cols, lead=["target_label"])}
<h2>Success rate</h2>{_img(pngs["success_rate"], "success rate per target and overall")}
<h2>Task completion time</h2>{_img(pngs["tct"], "TCT per target and overall")}
<h2>Force errors</h2>{_img(pngs["errors"], "RMSE and Max AE per target and overall")}
<h2>Per participant</h2>{_img(pngs["paired"], "paired per-participant changes")}
{_html_table(overall)}
<h2>Speed against accuracy</h2>
<p>Spearman rank correlation of TCT with RMSE over trials, per mode. A negative ρ means faster trials were less
accurate: participants traded accuracy for speed. A positive ρ means slow trials were also the inaccurate ones: no trade.</p>
{_html_table(sa)}
{_img(pngs["speed_accuracy"], "TCT against RMSE")}
<h2>Force through the pipeline</h2>
{"".join(f"<h3>{html.escape(t)}</h3>{_img(p, t)}" for t, p in examples)}
{power_html}
<h2>Methods</h2>
{_methods(study, table, options, zero_method, confidence, excluded, n_participants, n_incomplete)}
<h2>Sessions</h2>
{_html_table(sess[["database", "session_id", "participant_code", "kind", "status", "seed", "started_at", "ended_at",
                   "software_version", "rig"]])}
</body></html>
"""
        (tmp / "report.html").write_text(page, encoding="utf-8")
        files = sorted(str(p.relative_to(tmp)) for p in tmp.rglob("*") if p.is_file())
        if out.exists():
            shutil.rmtree(out)
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return ReportSummary(out, n_participants, len(trials), int(study.included["n_samples"].fillna(0).sum()),
                         excluded, stats_out, files)
