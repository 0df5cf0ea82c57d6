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

from protocol.metrics import TRADE_PHASES, Metric, MetricValue, split_unit, tested

__all__ = ["MEASURE_LABELS", "SIM_METRICS", "SUMMARY_KEYS", "TrialRow", "censored_key", "summarise_study",
           "trial_row_from_dict", "trial_row_to_dict"]

#: The metrics a simulated trial carries: the ones the report tests (:func:`protocol.metrics.tested`), in order, and the
#: speed–accuracy trade's phases (:data:`protocol.metrics.TRADE_PHASES`: the sweep's front).
SIM_METRICS: tuple[Metric, ...] = (*tested(), *TRADE_PHASES)
#: The yes/no outcome among them (the task's verdict): whose mean is a participant's success rate.
_VERDICT = next(m.name for m in SIM_METRICS if m.boolean)


def censored_key(m: Metric) -> str:
    """A success-only metric with failures counted at the trial cap, as the summary names it (``tct_cens_s``)."""
    stem, units = split_unit(m.name)
    return "_".join((stem, "cens", *units))


#: The measures a sweep reports (:data:`analysis.planning.sweep.METRICS`, here so that the sweep's figures read them
#: without importing the sweep): each simulated metric with its label, a success-only one (TCT) also with failures
#: at the cap.
MEASURE_LABELS: dict[str, str] = {k: v for m in SIM_METRICS for k, v in (
    ((m.name, m.summary_label), (censored_key(m), f"{m.short}, every trial, failure at the cap ({m.unit})"))
    if m.success_only else ((m.name, m.summary_label),))}

#: What :func:`summarise_study` gives per key: ``off``, ``on``, ``change`` (ON/OFF − 1), ``p``, ``n_pairs``: each
#: metric of :data:`SIM_METRICS`, a success-only one also censored at the cap, and the success rate per target.
SUMMARY_KEYS = (*(m.name for m in SIM_METRICS), *(censored_key(m) for m in SIM_METRICS if m.success_only),
                "success_GENTLE", "success_FIRM")


@dataclass(frozen=True, slots=True)
class TrialRow:
    """One simulated trial's outcome: its metrics by name (:data:`SIM_METRICS`; ``tct_s`` None for a failure)."""

    study: int
    participant: int
    index: int
    target: str
    mode: str
    values: Mapping[str, MetricValue]

    @property
    def success(self) -> bool:
        """The trial succeeded (the task's verdict)."""
        return bool(self.values[_VERDICT])


def trial_row_to_dict(row: TrialRow) -> dict[str, Any]:
    """A row as plain JSON values: who and which trial, then each metric by name."""
    return {"study": row.study, "participant": row.participant, "index": row.index, "target": row.target,
            "mode": row.mode, **{m.name: row.values.get(m.name) for m in SIM_METRICS}}


def _number(v: MetricValue) -> float:
    return math.nan if v is None else float(v)


def _value(m: Metric, v: Any) -> MetricValue:
    return bool(v) if m.boolean else None if v is None else float(v)


def trial_row_from_dict(d: Mapping[str, Any]) -> TrialRow:
    """The row :func:`trial_row_to_dict` wrote (:class:`KeyError` when it lacks a metric: written before it existed)."""
    return TrialRow(int(d["study"]), int(d["participant"]), int(d["index"]), str(d["target"]), str(d["mode"]),
                    {m.name: _value(m, d[m.name]) for m in SIM_METRICS})


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


def _participant_values(mine: Sequence[TrialRow], max_trial_s: float) -> dict[str, float]:
    """One participant's values in one mode (science.md §6): a yes/no outcome's rate, a success-only metric's mean
    over successful trials (and with failures at the cap), every other metric's mean over the trials."""
    out: dict[str, float] = {}
    for m in SIM_METRICS:
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
    for lab in ("GENTLE", "FIRM"):
        sub = [r for r in mine if r.target == lab]
        out[f"success_{lab}"] = sum(r.success for r in sub) / len(sub) if sub else math.nan
    return out


def _nanmean(values: list[float]) -> float:
    return float(np.nanmean(values)) if not all(math.isnan(x) for x in values) else math.nan


def summarise_study(rows: Sequence[TrialRow], max_trial_s: float = 12.0,
                    keys: Sequence[str] = SUMMARY_KEYS) -> dict[str, Any]:
    """Per participant × mode aggregates (science.md §6), group means, changes and Wilcoxon p.

    Returns ``{"n_participants": n, key: {"off", "on", "change", "p", "n_pairs"} for key in keys}``
    (``keys``: some of :data:`SUMMARY_KEYS`; a test with ties is an exact permutation test, ~0.1 s);
    ``change`` is ON/OFF − 1 (NaN when OFF is 0); a mode a participant has no trials of counts as NaN.
    """
    parts = sorted({r.participant for r in rows})
    per: dict[str, dict[str, list[float]]] = {}
    for mode in ("off", "on"):
        per[mode] = {k: [] for k in SUMMARY_KEYS}
        for pid in parts:
            mine = [r for r in rows if r.participant == pid and r.mode == mode]
            vals = _participant_values(mine, max_trial_s) if mine else dict.fromkeys(SUMMARY_KEYS, math.nan)
            for k in SUMMARY_KEYS:
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
