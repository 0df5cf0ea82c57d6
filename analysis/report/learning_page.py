"""learning.html: the learning page of a study with visits (:mod:`analysis.report.learning_report`), every choice
stated beside its number."""

from __future__ import annotations

import html
import math
from collections.abc import Sequence

import pandas as pd

from analysis.stats.aggregate import METRIC_LABELS
from analysis.stats.visit_learning import RETENTION_COLUMNS

__all__ = ["LEARNING_CODEBOOK", "learning_page"]

#: What each file's columns hold (the page's codebook and learning_codebook.csv).
LEARNING_CODEBOOK: dict[str, str] = {
    "learning.csv participant_code": "the participant's pseudonymous code",
    "learning.csv visit / visit_number / day / role": "the visit, its place in the schedule, its planned day (days "
                                                      "after the first visit) and its role",
    "learning.csv haptic_mode": "on or off",
    "learning.csv n_trials": "the participant's analysed trials of the learning task in the visit and mode",
    "learning.csv session": "the participant's n-th measured visit (the models' session number)",
    "learning.csv <metric>": "the participant's value in the visit and mode, as that visit's participants.csv has "
                             "it (success_rate, tct_s, rmse_n, max_ae_n)",
    **{f"retention.csv {c}": w for c, w in zip(RETENTION_COLUMNS, (
        "the participant's code", "on or off", "the metric", "its value at the baseline visit",
        "its value at the post visit", "its value at the retention visit", "the retention visit",
        "post − baseline (the gain over the practice)", "retention − post (what was kept; 0: all of it)"),
        strict=True)},
    "learning_models.csv": "the mixed models' fixed effects (analysis.stats.models.FIXED_EFFECT_COLUMNS)",
    "retention_tests.csv": "the paired Wilcoxon tests: metric, mode, comparison, n_pairs, n_used, statistic, "
                           "p_value, method, median difference, note",
}


def _num(v: object, digits: int = 3) -> str:
    """A number for the page ("–" for NaN)."""
    x = float(v)  # type: ignore[arg-type]
    return "–" if not math.isfinite(x) else f"{x:.{digits}g}"


def _means(table: pd.DataFrame, metrics: Sequence[str]) -> str:
    """Mean (SD) per visit and mode, and n."""
    head = "".join(f"<th>{html.escape(METRIC_LABELS.get(m, m))} OFF</th><th>ON</th>" for m in metrics)
    rows = []
    for (number, visit, day, role), g in table.groupby(["visit_number", "visit", "day", "role"], sort=True):
        cells = []
        for m in metrics:
            for mode in ("off", "on"):
                v = g.loc[g["haptic_mode"] == mode, m].to_numpy(float)
                v = v[~pd.isna(v)]
                cells.append(f"<td>{_num(v.mean()) if v.size else '–'} ({_num(v.std(ddof=1)) if v.size > 1 else '–'})"
                             f"</td>")
        n = g["participant_code"].nunique()
        rows.append(f"<tr><td>{number}. {html.escape(str(visit))}</td><td>{day}</td><td>{html.escape(str(role))}"
                    f"</td><td>{n}</td>{''.join(cells)}</tr>")
    return (f"<table><tr><th>visit</th><th>day</th><th>role</th><th>n</th>{head}</tr>{''.join(rows)}</table>")


def _models(models: pd.DataFrame) -> str:
    """The fixed effects, with n, method and note."""
    rows = []
    for outcome, g in models.groupby("outcome", sort=False):
        first = g.iloc[0]
        label = html.escape(METRIC_LABELS.get(str(outcome), str(outcome)))
        if not str(first["term"]):
            rows.append(f"<tr><td>{label}</td><td colspan='5'>{html.escape(str(first['note']))}</td></tr>")
            continue
        for r in g.itertuples():
            rows.append(f"<tr><td>{label}</td><td>{html.escape(str(r.term))}</td><td>{_num(r.estimate)}</td>"
                        f"<td>{_num(r.ci_low)} to {_num(r.ci_high)}</td><td>{_num(r.p_value, 2)}</td>"
                        f"<td>{int(r.n_obs)} values, {int(r.n_participants)} participants</td></tr>")
        if str(first["note"]):
            rows.append(f"<tr><td></td><td colspan='5'><i>{html.escape(str(first['note']))}</i></td></tr>")
    method = html.escape(str(models["method"].iloc[0])) if len(models) else ""
    return (f"<p>Method: {method}; Wald 95 % intervals.</p><table><tr><th>metric</th><th>term</th><th>estimate</th>"
            f"<th>95 % CI</th><th>p</th><th>n</th></tr>{''.join(rows)}</table>")


def _tests(tests: pd.DataFrame) -> str:
    """The paired tests of the gain and of retention."""
    rows = "".join(
        f"<tr><td>{html.escape(METRIC_LABELS.get(str(r.metric), str(r.metric)))}</td><td>{str(r.haptic_mode).upper()}"
        f"</td><td>{html.escape(str(r.comparison))}</td><td>{_num(r.median_difference)}</td><td>{int(r.n_pairs)} "
        f"({int(r.n_used)} non-zero)</td><td>{_num(r.statistic)}</td><td>{_num(r.p_value, 2)}</td>"
        f"<td>{html.escape(str(r.method))}</td><td>{html.escape(str(r.note))}</td></tr>" for r in tests.itertuples())
    return ("<table><tr><th>metric</th><th>mode</th><th>comparison</th><th>median difference</th><th>pairs</th>"
            f"<th>W</th><th>p</th><th>method</th><th>note</th></tr>{rows}</table>")


def learning_page(table: pd.DataFrame, metrics: Sequence[str], models: pd.DataFrame, kept: pd.DataFrame,
                  tests: pd.DataFrame, task: str) -> str:
    """The page's HTML."""
    n = table["participant_code"].nunique()
    codebook = "".join(f"<tr><td>{html.escape(c)}</td><td>{html.escape(w)}</td></tr>"
                       for c, w in LEARNING_CODEBOOK.items())
    has_retention = bool((kept["retention_visit"] != "").any()) if len(kept) else False
    no_retention = "" if has_retention else " This schedule has no retention visit."
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>Learning over the visits</title>
<style>body{{font-family:sans-serif;max-width:70em;margin:2em auto}}td,th{{padding:2px 8px;text-align:left}}</style>
</head><body>
<p><a href="report.html">The plan and each visit's reports</a></p>
<h1>Learning over the visits</h1>
<p>{n} participants. The task followed over the visits: {html.escape(task.replace('_', ' '))} (the experiment part the
baseline, post and retention visits share). Each value is a participant's mean over the visit's analysed trials in
one haptic mode, as that visit's own report computes it (its participants.csv): one value per participant per visit
per mode (learning.csv). TCT is as the report's <code>--tct</code> makes it (by default a failed trial counts at
the trial's cap, the paper's figure).</p>
<h2>Learning curves</h2>
<img src="learning_curve.png" alt="learning curves" style="max-width:100%">
<p>Thin lines: each participant; thick: the mean per mode with its 95 % t interval (participants as the unit).
The x axis is each visit's planned day.</p>
{_means(table, metrics)}
<p>Mean (SD) across participants.</p>
<h2>A mixed model of session number</h2>
<p>Per metric: metric ~ log(session) × haptic ON + (1 | participant), over the practice visits (all but the
retention tests: the delay before those is forgetting, not practice). <i>session</i> is the participant's n-th
measured visit; log(session) because the power law of practice (Newell &amp; Rosenbloom 1981) makes the change fast
at first and ever slower, which is close to linear in log(session) over a few sessions: its coefficient is the
change per e-fold of practice with haptics OFF; haptic_on is ON − OFF at the first session; log_session:haptic_on
how much ON's slope differs. A random intercept per participant only (one value per participant × visit × mode
gives a random slope few observations).</p>
{_models(models)}
<h2>Gain and retention</h2>
<p>Per participant and mode: post − baseline (the gain over the practice) and retention − post (what was kept:
0 = all of it; for a rate, negative is forgotten; for an error or a time, positive is). Each is tested with the
paired Wilcoxon signed-rank test (two-sided, zero differences dropped, the report's rule for the exact, permutation
or normal p: the method is named in each row); no correction across the tests (they are descriptive of the
schedule, not the study's primary ON-vs-OFF family).{no_retention}</p>
{_tests(tests)}
<h2>Files</h2>
<p>learning.csv, retention.csv, learning_models.csv, retention_tests.csv, learning_curve.png; the columns:</p>
<table><tr><th>column</th><th>what it holds</th></tr>{codebook}</table>
</body></html>
"""
