"""Per-participant aggregation, the ON-vs-OFF tests and the speed–accuracy trade.

Statistics follow the paper's design: each participant contributes one value
per haptic mode (the mean of their trials, or their success rate), and the two
modes are compared by a paired Wilcoxon signed-rank test across participants
(:func:`analysis.stats.paired_wilcoxon`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from analysis.metrics import MetricOptions
from analysis.correlation import correlation
from analysis.stats import WilcoxonResult, paired_wilcoxon, results_frame

__all__ = [
    "METRIC_LABELS",
    "PRIMARY_METRICS",
    "by_mode",
    "mean_sd",
    "mode_tests",
    "per_participant",
    "speed_accuracy",
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
        :attr:`analysis.metrics.TrialTable.trials`.
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

    The SD is 0 for one value and both are NaN for none.
    """
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if len(v) == 0:
        return np.nan, np.nan, 0
    return float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else 0.0, len(v)


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


def _paired(per_part: pd.DataFrame, metric: str) -> tuple[np.ndarray, np.ndarray]:
    wide = by_mode(per_part, metric)
    return wide["off"].to_numpy(dtype=float), wide["on"].to_numpy(dtype=float)


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
        Passed to :func:`analysis.stats.paired_wilcoxon`.

    Returns
    -------
    results, frame
        The named results and their tidy table (one row per metric, with ``p_holm``).
    """
    results = []
    for m in metrics:
        off, on = _paired(per_part, m)
        results.append(paired_wilcoxon(off, on, metric=m, zero_method=zero_method, confidence=confidence))
    return results, results_frame(results)


def speed_accuracy(trials: pd.DataFrame, options: MetricOptions = MetricOptions()) -> pd.DataFrame:
    """How TCT and RMSE trade against each other, trial by trial, per haptic mode.

    A participant who hurries reaches the band sooner but overshoots more; the
    Spearman rank correlation of TCT with RMSE over the trials of each mode
    (and over all trials) measures that trade.  TCT follows
    ``options.tct_policy`` (successful trials only by default).

    Returns
    -------
    pandas.DataFrame
        One row per ``haptic_mode`` (``off``, ``on``, ``all``): ``n``,
        ``rho``, ``p_value``, ``ci_low``, ``ci_high``, ``method``,
        ``computable``, ``note``, and the medians ``median_tct_s``,
        ``median_rmse_n``.
    """
    tct_col = "tct_s" if options.tct_policy == "successful" else "tct_censored_s"
    rows = []
    for mode in ("off", "on", "all"):
        sel = trials if mode == "all" else trials[trials["haptic_mode"] == mode]
        x = sel[tct_col].to_numpy(dtype=float)
        y = sel["rmse_n"].to_numpy(dtype=float)
        # trials without a TCT (failures, under "successful") are not pairs: leave them out before testing
        keep = np.isfinite(x) & np.isfinite(y)
        x, y = x[keep], y[keep]
        c = correlation(x, y, method="spearman")
        rows.append(
            {
                "haptic_mode": mode,
                "n": c.n,
                "rho": c.r,
                "p_value": c.p_value,
                "ci_low": c.ci_low,
                "ci_high": c.ci_high,
                "method": c.method,
                "computable": c.computable,
                "note": c.note,
                "median_tct_s": float(np.median(x)) if len(x) else np.nan,
                "median_rmse_n": float(np.median(y)) if len(y) else np.nan,
            }
        )
    return pd.DataFrame(rows)
