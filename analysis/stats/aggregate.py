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
from analysis.stats.wilcoxon import WilcoxonResult, paired_wilcoxon, results_frame

__all__ = [
    "METRIC_LABELS",
    "PRIMARY_METRICS",
    "by_mode",
    "mean_sd",
    "mode_tests",
    "per_participant",
]

#: The paper's outcome measures, in report order; Holm's correction runs across them.
PRIMARY_METRICS: tuple[str, ...] = ("success_rate", "tct_s", "rmse_n", "max_ae_n")

#: Human labels with units, for tables and figures.
METRIC_LABELS: dict[str, str] = {
    "success_rate": "success rate",
    "tct_s": "TCT (s)",
    "rmse_n": "RMSE (N)",
    "max_ae_n": "Max AE (N)",
    "time_in_band_s": "time in band (s)",
    "peak_force_n": "peak force (N)",
}


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
        Columns ``participant_code, haptic_mode, [target_label,] n_trials,
        n_success, success_rate, tct_s, n_tct, rmse_n, max_ae_n,
        time_in_band_s, peak_force_n`` (``n_tct`` is the number of trials
        that entered the TCT mean).
    """
    keys = ["participant_code", "haptic_mode"] + (["target_label"] if by_target else [])
    t = trials.copy()
    t["_tct"] = t["tct_s"] if options.tct_policy == "successful" else t["tct_censored_s"]
    g = t.groupby(keys, sort=True, observed=True)
    out = pd.DataFrame(
        {
            "n_trials": g.size(),
            "n_success": g["success"].sum().astype(np.int64),
            "success_rate": g["success"].mean(),
            "tct_s": g["_tct"].mean(),  # NaN-skipping: failed trials are NaN under "successful"
            "n_tct": g["_tct"].count().astype(np.int64),
            "rmse_n": g["rmse_n"].mean(),
            "max_ae_n": g["max_ae_n"].mean(),
            "time_in_band_s": g["time_in_band_s"].mean(),
            "peak_force_n": g["peak_force_n"].mean(),
        }
    )
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
    metrics: Sequence[str] = PRIMARY_METRICS,
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
        Columns to test; Holm's correction runs across exactly these.
    zero_method, confidence
        Passed to :func:`analysis.stats.wilcoxon.paired_wilcoxon`.

    Returns
    -------
    results, frame
        The named results and their tidy table (one row per metric, with ``p_holm``).
    """
    results = []
    for m in metrics:
        wide = by_mode(per_part, m)
        off, on = wide["off"].to_numpy(dtype=float), wide["on"].to_numpy(dtype=float)
        results.append(paired_wilcoxon(off, on, metric=m, zero_method=zero_method, confidence=confidence))
    return results, results_frame(results)
