"""Per-participant aggregation and the ON-vs-OFF tests (the speed–accuracy trade is :mod:`analysis.stats.trade`).

Statistics follow the paper's design: each participant contributes one value
per haptic mode (the mean of their trials, or their success rate), and the two
modes are compared by a paired Wilcoxon signed-rank test across participants
(:func:`analysis.stats.wilcoxon.paired_wilcoxon`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from analysis.reading.metrics import MetricOptions
from analysis.stats.effect_interval import rank_biserial_interval
from analysis.stats.holm import results_frame
from analysis.stats.wilcoxon import DEFAULT_DECIMALS, WilcoxonResult, paired_wilcoxon
from protocol.metrics import METRICS, Metric, primary, tested

__all__ = [
    "METRIC_LABELS",
    "PRIMARY_METRICS",
    "TESTED_METRICS",
    "by_mode",
    "mean_sd",
    "metrics_in",
    "mode_tests",
    "per_participant",
    "unbalanced_cells",
]

#: Every primary measure of the registry (per-participant columns), in report order: a study's are those of them its
#: tables have (its tasks' metrics: the paper's four for force regulation), and Holm's correction runs across them.
PRIMARY_METRICS: tuple[str, ...] = tuple(m.participant for m in primary(METRICS))
#: Every measure of the registry the report tests ON vs OFF: the primary ones, then the secondary ones (each with its
#: own p); a study tests those of them its tables have.
TESTED_METRICS: tuple[str, ...] = tuple(m.participant for m in tested(METRICS))

#: Human labels with units, for tables and figures, by per-participant column.
METRIC_LABELS: dict[str, str] = {m.participant: m.label for m in METRICS}


def metrics_in(trials: pd.DataFrame) -> tuple[Metric, ...]:
    """The registry's metrics a trials table has a column for, in order (the study's, in a table the analysis made:
    :attr:`analysis.reading.metrics.TrialTable.metrics`; a table of trials built by hand may lack one)."""
    return tuple(m for m in METRICS if m.name in trials.columns)


def per_participant(
    trials: pd.DataFrame, options: MetricOptions = MetricOptions(), *, by_target: bool = False
) -> pd.DataFrame:
    """Each participant's mean per haptic mode (and target).

    Parameters
    ----------
    trials
        :attr:`analysis.reading.metrics.TrialTable.trials`.
    options
        ``tct_policy`` decides whether TCT averages successful trials only
        (NaN when there is none) or censors failures at the trial cap.
    by_target
        Also split by ``target_label``.

    Returns
    -------
    pandas.DataFrame
        Columns ``participant_code, haptic_mode, [target_label,] n_trials``, then per metric of the registry
        that ``trials`` has (:func:`metrics_in`), in order: a yes/no outcome's count and rate (``n_success,
        success_rate``), a success-only metric's mean and the trials that entered it (``tct_s, n_tct``), every other
        metric's mean (``rmse_n, max_ae_n, time_in_band_s, peak_force_n``, ...).  Without the target split, a
        participant × mode whose trials are not spread equally over the targets (:func:`unbalanced_cells`: an
        incomplete session analysed) has each value the mean of its per-target values, so every target weighs the
        same as in the design; counts stay counts.
    """
    if not by_target and "target_label" in trials.columns:
        cells = unbalanced_cells(trials)
        if len(cells):
            return _balanced(trials, options, cells)
    keys = ["participant_code", "haptic_mode"] + (["target_label"] if by_target else [])
    metrics = metrics_in(trials)
    t = trials.copy()
    for m in metrics:  # a success-only metric (TCT) under the TCT policy: successful trials only, or censored
        if m.success_only:
            t[f"_{m.name}"] = t[m.name] if options.tct_policy == "successful" else t[str(m.censored)]
    g = t.groupby(keys, sort=True, observed=True)
    columns: dict[str, pd.Series] = {"n_trials": g.size()}
    for m in metrics:
        if m.boolean:  # a yes/no outcome: how many, and the rate
            columns[str(m.count)] = g[m.name].sum().astype(np.int64)
            columns[m.participant] = g[m.name].mean()
        elif m.success_only:
            columns[m.name] = g[f"_{m.name}"].mean()  # NaN-skipping: failed trials are NaN under "successful"
            columns[str(m.count)] = g[f"_{m.name}"].count().astype(np.int64)
        else:
            columns[m.name] = g[m.name].mean()
    return pd.DataFrame(columns).reset_index()


def unbalanced_cells(trials: pd.DataFrame) -> pd.DataFrame:
    """The participant × mode cells whose analysed trials are not spread equally over the study's targets.

    Returns
    -------
    pandas.DataFrame
        ``participant_code, haptic_mode, counts`` (``GENTLE 2, FIRM 3``, the targets in order of force): empty for a
        design whose sessions all completed.
    """
    targets = list(trials.drop_duplicates("target_label").sort_values("target_force_n")["target_label"]) \
        if "target_force_n" in trials.columns else sorted(trials["target_label"].unique())
    counts = trials.groupby(["participant_code", "haptic_mode", "target_label"], observed=True).size().unstack(
        "target_label").reindex(columns=targets).fillna(0).astype(np.int64)
    uneven = counts[counts.nunique(axis=1) > 1]
    return pd.DataFrame({"participant_code": [c for c, _ in uneven.index], "haptic_mode": [m for _, m in uneven.index],
                         "counts": [", ".join(f"{t} {int(n)}" for t, n in row.items())
                                    for _, row in uneven.iterrows()]},
                        columns=["participant_code", "haptic_mode", "counts"])


def _balanced(trials: pd.DataFrame, options: MetricOptions, cells: pd.DataFrame) -> pd.DataFrame:
    """:func:`per_participant` with each unbalanced cell's values the mean of its per-target values."""
    plain = per_participant(trials.drop(columns="target_label"), options)
    per_t = per_participant(trials, options, by_target=True)
    value_cols = [c for c in plain.columns if c not in ("participant_code", "haptic_mode", "n_trials")
                  and not c.startswith("n_")]
    means = per_t.groupby(["participant_code", "haptic_mode"], sort=True)[value_cols].mean()
    out = plain.set_index(["participant_code", "haptic_mode"])
    for key in zip(cells["participant_code"], cells["haptic_mode"], strict=True):
        out.loc[key, value_cols] = means.loc[key, value_cols].to_numpy(float)
    return out.reset_index()


def mean_sd(values: np.ndarray | pd.Series) -> tuple[float, float, int]:
    """Mean, SD (n − 1) and n of the finite values: what the report's bars and headline figures show.

    The SD is NaN for one value (there is no spread to show: not 0) and both are NaN for none.
    """
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if len(v) == 0:
        return np.nan, np.nan, 0
    return float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else np.nan, len(v)


def by_mode(per_part: pd.DataFrame, metric: str, codes: Sequence[str] | None = None) -> pd.DataFrame:
    """One metric of :func:`per_participant` side by side: a row per participant, columns ``off`` and ``on``.

    Parameters
    ----------
    per_part
        :func:`per_participant`'s table (one scope: overall or one target).
    metric
        The column to spread.
    codes
        Participant codes giving the rows and their order; default: every participant, sorted.

    Returns
    -------
    pandas.DataFrame
        Indexed by ``participant_code``; NaN where a participant lacks the mode (or the value).
    """
    wide = per_part.pivot(index="participant_code", columns="haptic_mode", values=metric)
    for mode in ("off", "on"):
        if mode not in wide.columns:
            wide[mode] = np.nan
    wide = wide[["off", "on"]]
    return wide if codes is None else wide.reindex(list(codes))


def mode_tests(
    per_part: pd.DataFrame,
    metrics: Sequence[str] | None = None,
    *,
    zero_method: str = "wilcox",
    confidence: float = 0.95,
) -> tuple[list[WilcoxonResult], pd.DataFrame]:
    """Paired Wilcoxon signed-rank test, haptics ON vs OFF, for every metric.

    Parameters
    ----------
    per_part
        :func:`per_participant` output without the target split (or one target's rows).
    metrics
        Columns to test (default: :data:`TESTED_METRICS` that ``per_part`` has); Holm's correction runs across
        those of them that are primary (:data:`PRIMARY_METRICS`), a secondary one keeps its own p (``p_holm`` NaN).
    zero_method, confidence
        Passed to :func:`analysis.stats.wilcoxon.paired_wilcoxon`.

    Returns
    -------
    results, frame
        The named results and their tidy table (one row per metric, with ``p_holm``).
    """
    if metrics is None:
        metrics = [m for m in TESTED_METRICS if m in per_part.columns]
    results, intervals = [], []
    for m in metrics:
        wide = by_mode(per_part, m)
        off, on = wide["off"].to_numpy(dtype=float), wide["on"].to_numpy(dtype=float)
        res = paired_wilcoxon(off, on, metric=m, zero_method=zero_method, confidence=confidence)
        results.append(res)
        # the effect size's interval, on the differences the test ranked (rounded as it rounds them)
        d = np.round(on - off, DEFAULT_DECIMALS)
        intervals.append(rank_biserial_interval(d, zero_method, confidence) if res.computable else
                         (np.nan, np.nan, ""))
    frame = results_frame(results, family=PRIMARY_METRICS)
    frame["rank_biserial_ci_low"] = [lo for lo, _, _ in intervals]
    frame["rank_biserial_ci_high"] = [hi for _, hi, _ in intervals]
    frame["rank_biserial_ci_method"] = [how for _, _, how in intervals]
    return results, frame
