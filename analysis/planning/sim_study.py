"""Simulated studies without a database: one row per trial, and a study's per-participant summary.

:mod:`study_app.headless.sim_trials` runs simulated participants through the
protocol's schedule on the simulated rig and returns :class:`TrialRow` s (their
metrics -- the ones the report tests -- come from the one definition in :mod:`protocol.metrics`, through
:class:`protocol.study.trial.TrialMachine`); :func:`summarise_study` aggregates them
like science.md §6 (success over a participant's trials, mean RMSE and Max AE
over trials, mean TCT over successful trials) and compares the modes.  The
calibration bench (``bench/participant_calibration.py``) and ``haptic-study
sweep`` (:mod:`analysis.planning.sweep`) share both.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from protocol.metrics import METRICS, TRADE_PHASES, Metric, MetricValue, get, select, split_unit, tested
from protocol.tasks.base import Task

__all__ = ["SIMULATED", "TrialRow", "censored_key", "measure_labels", "row_metrics", "sim_metrics", "summarise_study",
           "summary_keys", "trial_row_from_dict", "trial_row_to_dict"]


def sim_metrics(task: Task) -> tuple[Metric, ...]:
    """The metrics a simulated trial of ``task`` carries: the ones of the task's the report tests
    (:func:`protocol.metrics.tested`) and the speed–accuracy trade's phases it has
    (:data:`protocol.metrics.TRADE_PHASES`: the sweep's front), in the registry's order (the paper's task: success,
    TCT, RMSE, Max AE, ..., rise time, RMSE after reach)."""
    phases = [m.name for m in TRADE_PHASES if m.name in task.metric_names]
    return select([*(m.name for m in tested(task.metrics)), *phases])


#: What a simulated trial of any task may carry (:func:`sim_metrics`), in the registry's order: what a sweep may report.
SIMULATED: tuple[Metric, ...] = select([*(m.name for m in tested(METRICS)), *(m.name for m in TRADE_PHASES)])


def row_metrics(rows: Sequence[TrialRow]) -> tuple[Metric, ...]:
    """The metrics the rows carry (their task's :func:`sim_metrics`), in the registry's order."""
    return select(rows[0].values) if rows else ()


def censored_key(m: Metric) -> str:
    """A success-only metric with failures counted at the trial cap, as the summary names it (``tct_cens_s``)."""
    stem, units = split_unit(m.name)
    return "_".join((stem, "cens", *units))


def measure_labels(metrics: Sequence[Metric]) -> dict[str, str]:
    """The measures a sweep reports of these simulated ``metrics`` (:data:`analysis.planning.sweep.METRICS`, here so
    that the sweep's figures read them without importing the sweep): each with its label, a success-only one (TCT)
    also with failures at the cap."""
    return {k: v for m in metrics for k, v in (
        ((m.name, m.summary_label), (censored_key(m), f"{m.short}, every trial, failure at the cap ({m.unit})"))
        if m.success_only else ((m.name, m.summary_label),))}


def summary_keys(metrics: Sequence[Metric]) -> tuple[str, ...]:
    """What :func:`summarise_study` gives per key: ``off``, ``on``, ``change`` (ON/OFF − 1), ``p``, ``n_pairs``:
    each metric of ``metrics`` (the rows'), a success-only one also censored at the cap, and with a yes/no outcome
    the success rate per target of the paper's protocol."""
    return (*(m.name for m in metrics), *(censored_key(m) for m in metrics if m.success_only),
            *(("success_GENTLE", "success_FIRM") if any(m.boolean for m in metrics) else ()))


@dataclass(frozen=True, slots=True)
class TrialRow:
    """One simulated trial's outcome: its metrics by name (its task's :func:`sim_metrics`; ``tct_s`` None for a
    failure)."""

    study: int
    participant: int
    index: int
    target: str
    mode: str
    values: Mapping[str, MetricValue]

    @property
    def success(self) -> bool:
        """The trial succeeded: the task's verdict, its yes/no metric (a task without one: its trial ran its
        course)."""
        return all(bool(v) for k, v in self.values.items() if get(k).boolean)


def trial_row_to_dict(row: TrialRow) -> dict[str, Any]:
    """A row as plain JSON values: who and which trial, then each metric by name."""
    return {"study": row.study, "participant": row.participant, "index": row.index, "target": row.target,
            "mode": row.mode, **row.values}


def _number(v: MetricValue) -> float:
    return math.nan if v is None else float(v)


def _value(m: Metric, v: Any) -> MetricValue:
    return bool(v) if m.boolean else None if v is None else float(v)


def trial_row_from_dict(d: Mapping[str, Any], metrics: Sequence[Metric]) -> TrialRow:
    """The row :func:`trial_row_to_dict` wrote, of a task with these ``metrics`` (:func:`sim_metrics`;
    :class:`KeyError` when it lacks one: written before it existed)."""
    return TrialRow(int(d["study"]), int(d["participant"]), int(d["index"]), str(d["target"]), str(d["mode"]),
                    {m.name: _value(m, d[m.name]) for m in metrics})


def _wilcoxon_p(off: list[float], on: list[float]) -> float:
    """Two-sided Wilcoxon signed-rank p of the paired differences (NaN when undefined)."""
    from scipy.stats import wilcoxon

    d = [round(a - b, 12) for a, b in zip(off, on, strict=True) if not (math.isnan(a) or math.isnan(b))]
    if len(d) < 2 or all(x == 0 for x in d):
        return math.nan
    try:
        return float(wilcoxon(d).pvalue)
    except ValueError:
        return math.nan


def _participant_values(mine: Sequence[TrialRow], max_trial_s: float,
                        metrics: Sequence[Metric]) -> dict[str, float]:
    """One participant's values in one mode (science.md §6): a yes/no outcome's rate, a success-only metric's mean
    over successful trials (and with failures at the cap), every other metric's mean over the trials."""
    out: dict[str, float] = {}
    for m in metrics:
        if m.boolean:
            out[m.name] = sum(bool(r.values[m.name]) for r in mine) / len(mine)
        elif m.success_only:
            kept = [float(v) for r in mine if r.success and (v := r.values.get(m.name)) is not None]
            out[m.name] = statistics.fmean(kept) if kept else math.nan
            out[censored_key(m)] = statistics.fmean(
                float(v) if r.success and (v := r.values.get(m.name)) is not None else max_trial_s for r in mine)
        else:  # over the trials that have it (the trade's phases are undefined for a trial that never reached the band)
            have = [v for r in mine if math.isfinite(v := _number(r.values.get(m.name)))]
            out[m.name] = statistics.fmean(have) if have else math.nan
    for lab in ("GENTLE", "FIRM") if any(m.boolean for m in metrics) else ():
        sub = [r for r in mine if r.target == lab]
        out[f"success_{lab}"] = sum(r.success for r in sub) / len(sub) if sub else math.nan
    return out


def _nanmean(values: list[float]) -> float:
    return float(np.nanmean(values)) if not all(math.isnan(x) for x in values) else math.nan


def summarise_study(rows: Sequence[TrialRow], max_trial_s: float = 12.0,
                    keys: Sequence[str] | None = None) -> dict[str, Any]:
    """Per participant × mode aggregates (science.md §6), group means, changes and Wilcoxon p.

    Returns ``{"n_participants": n, key: {"off", "on", "change", "p", "n_pairs"} for key in keys}``
    (``keys``: some of :func:`summary_keys` of the rows' metrics, default all; a test with ties is an exact
    permutation test, ~0.1 s);
    ``change`` is ON/OFF − 1 (NaN when OFF is 0); a mode a participant has no trials of counts as NaN.
    """
    parts = sorted({r.participant for r in rows})
    metrics = row_metrics(rows)
    every = summary_keys(metrics)
    keys = every if keys is None else keys
    per: dict[str, dict[str, list[float]]] = {}
    for mode in ("off", "on"):
        per[mode] = {k: [] for k in every}
        for pid in parts:
            mine = [r for r in rows if r.participant == pid and r.mode == mode]
            vals = _participant_values(mine, max_trial_s, metrics) if mine else dict.fromkeys(every, math.nan)
            for k in every:
                per[mode][k].append(vals[k])
    out: dict[str, Any] = {"n_participants": len(parts)}
    for key in keys:
        off, on = per["off"][key], per["on"][key]
        m_off, m_on = _nanmean(off), _nanmean(on)
        out[key] = {
            "off": m_off,
            "on": m_on,
            "change": (m_on / m_off - 1.0) if m_off else math.nan,
            "p": _wilcoxon_p(off, on),
            "n_pairs": sum(1 for a, b in zip(off, on, strict=True) if not (math.isnan(a) or math.isnan(b))),
        }
    return out
