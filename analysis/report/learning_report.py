"""The learning page of a study with a schedule of visits (:mod:`protocol.study.visits`): learning curves, the mixed
model of session number, retention.

Its numbers are each visit's own report's (:mod:`analysis.report.plan_report`: a report per visit and part, one
value per participant per mode, participants.csv): each primary metric per participant per visit per mode
(``learning.csv``).  The visits compared are those that hold the *learning task*: the task of the experiment part
the baseline, post and retention visits share (the roles' test), else of the first visit's first experiment part;
a visit with several experiment parts of that task is that task's mean over them, each part weighted by its trials
(the participant's trials pooled).  The statistics are :mod:`analysis.stats.visit_learning`'s.
"""

from __future__ import annotations

import html
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from scipy import stats as st

from analysis.plots.figures import MODE_COLORS
from analysis.report.learning_page import LEARNING_CODEBOOK, learning_page
from analysis.stats.aggregate import METRIC_LABELS, PRIMARY_METRICS
from analysis.stats.models import fixed_effects
from analysis.stats.visit_learning import PER_VISIT_KEYS, retention_table, retention_tests, visit_models
from protocol.study.visits import VisitPlace

__all__ = ["VisitPart", "learning_task", "per_visit_table", "write_learning"]

@dataclass(frozen=True, slots=True)
class VisitPart:
    """A stored session's place as the learning page needs it: its visit, its report's name (``VISIT-PART``), its
    session kind and task kind (:func:`analysis.report.plan_report.visit_parts`)."""

    visit: VisitPlace | None
    key: str
    session: str
    task: str


def learning_task(plan: Sequence[VisitPart]) -> str:
    """The learning task's kind (module docstring); "" when the plan has no experiment part in a visit."""
    measured = [e for e in plan if e.visit is not None and e.session == "experiment"]
    tests = [e for e in measured if e.visit is not None and e.visit.role in ("baseline", "post", "retention")]
    return (tests or measured)[0].task if measured else ""


def per_visit_table(plan: Sequence[VisitPart], overall: Mapping[str, pd.DataFrame | None]) -> pd.DataFrame:
    """learning.csv: one row per participant per visit per mode (``overall``: each visit-part report's
    per-participant table by its key, :func:`analysis.report.plan_report.entry_key`)."""
    kind = learning_task(plan)
    visits: dict[VisitPlace, set[str]] = {}
    for e in plan:
        if e.visit is not None and e.session == "experiment" and e.task == kind:
            visits.setdefault(e.visit, set()).add(e.key)
    frames = []
    metrics = list(PRIMARY_METRICS)
    for v, keys in sorted(visits.items(), key=lambda kv: kv[0].number):
        tables = [t for k in sorted(keys) if (t := overall.get(k)) is not None]
        if not tables:
            continue
        both = pd.concat(tables, ignore_index=True)
        have = [m for m in metrics if m in both.columns]
        # one part: its values as they are; several: pooled (each part's mean weighted by its trials)
        frame = (both[["participant_code", "haptic_mode", "n_trials", *have]].sort_values(
            ["participant_code", "haptic_mode"]).reset_index(drop=True) if len(tables) == 1 else _pooled(both, have))
        frame.insert(1, "visit", v.name)
        frame.insert(2, "visit_number", v.number)
        frame.insert(3, "day", v.day)
        frame.insert(4, "role", v.role)
        frames.append(frame)
    if not frames:
        return pd.DataFrame(columns=[*PER_VISIT_KEYS, "session", *metrics])
    table = pd.concat(frames, ignore_index=True)
    table.insert(len(PER_VISIT_KEYS), "session",
                 table.groupby("participant_code")["visit_number"].rank(method="dense").astype(int))
    return table


def _pooled(both: pd.DataFrame, metrics: Sequence[str]) -> pd.DataFrame:
    """Per participant and mode, each metric's mean over the rows (a visit's parts) weighted by the trials it is a
    mean of (``n_tct`` for TCT, the successful trials; ``n_trials`` otherwise): the participant's trials pooled."""
    keys = ["participant_code", "haptic_mode"]
    out = both.groupby(keys, sort=True)["n_trials"].sum().reset_index()
    for m in metrics:
        w = both["n_tct"] if m == "tct_s" and "n_tct" in both.columns else both["n_trials"]
        ok = np.isfinite(both[m].to_numpy(float))
        part = pd.DataFrame({"participant_code": both["participant_code"], "haptic_mode": both["haptic_mode"],
                             "wx": np.where(ok, both[m].to_numpy(float) * w, 0.0), "w": np.where(ok, w, 0)})
        sums = part.groupby(keys, sort=True)[["wx", "w"]].sum()
        out[m] = (sums["wx"] / sums["w"].replace(0, np.nan)).to_numpy()
    return out


def _mean_ci(v: np.ndarray, level: float = 0.95) -> tuple[float, float]:
    """The mean and the half-width of its t interval (NaN with fewer than 2 values)."""
    v = v[np.isfinite(v)]
    if v.size < 2:
        return (float(v.mean()) if v.size else math.nan), math.nan
    return float(v.mean()), float(st.t.ppf(0.5 + level / 2, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size))


def learning_figure(table: pd.DataFrame, metrics: Sequence[str]) -> Figure:
    """Each metric against the visit's day: a thin line per participant and mode, the mean with its 95 % t interval
    per mode."""
    fig = Figure(figsize=(10, 7), layout="constrained")
    axes = fig.subplots(2, math.ceil(len(metrics) / 2), squeeze=False).ravel()
    for ax, m in zip(axes, metrics, strict=False):
        for mode in ("off", "on"):
            rows = table[table["haptic_mode"] == mode]
            for _, g in rows.groupby("participant_code"):
                ax.plot(g["day"], g[m], color=MODE_COLORS[mode], alpha=0.25, linewidth=0.8)
            days = sorted(rows["day"].unique())
            stats = [_mean_ci(rows.loc[rows["day"] == d, m].to_numpy(float)) for d in days]
            ax.errorbar(days, [s[0] for s in stats], yerr=[s[1] for s in stats], color=MODE_COLORS[mode],
                        linewidth=2, marker="o", capsize=3, label=f"haptics {mode.upper()} (mean, 95 % CI)")
        ax.set_xlabel("day of the visit (days after the first)")
        ax.set_ylabel(METRIC_LABELS.get(m, m))
        ax.set_xticks(sorted(table["day"].unique()))
    for ax in axes[len(metrics):]:
        ax.set_visible(False)
    axes[0].legend(fontsize=8)
    n = table["participant_code"].nunique()
    fig.suptitle(f"Learning over the visits: {n} participants (thin lines: each participant)")
    return fig


def write_learning(folder: Path, plan: Sequence[VisitPart], overall: Mapping[str, pd.DataFrame | None],
                   confidence: float = 0.95) -> list[str]:
    """learning.html, learning.csv, retention.csv, learning_models.csv, retention_tests.csv, learning_codebook.csv
    and learning_curve.png into ``folder``; the lines to print ([] when no visit holds the learning task)."""
    table = per_visit_table(plan, overall)
    if table.empty:
        return []
    metrics = [m for m in PRIMARY_METRICS if m in table.columns]
    fits = visit_models(table, metrics, METRIC_LABELS, confidence)
    models = fixed_effects(fits)
    kept = retention_table(table, metrics)
    tests = retention_tests(kept)
    table.to_csv(folder / "learning.csv", index=False)
    kept.to_csv(folder / "retention.csv", index=False)
    models.to_csv(folder / "learning_models.csv", index=False)
    tests.to_csv(folder / "retention_tests.csv", index=False)
    pd.DataFrame({"column": list(LEARNING_CODEBOOK), "meaning": list(LEARNING_CODEBOOK.values())}).to_csv(
        folder / "learning_codebook.csv", index=False)
    learning_figure(table, metrics).savefig(folder / "learning_curve.png", format="png", dpi=110)
    (folder / "learning.html").write_text(learning_page(table, metrics, models, kept, tests, learning_task(plan)),
                                          encoding="utf-8")
    return [f"learning over visits: {table['participant_code'].nunique()} participants, "
            f"{table['visit'].nunique()} visits of {html.unescape(learning_task(plan)).replace('_', ' ')}"]
