"""The speed–accuracy trade, within participants: repeated-measures correlation, a mixed model, slopes.

Does a participant who is faster on a trial make larger errors on it?  Trials of one participant are not
independent, so the question is asked within participants:

* :func:`speed_accuracy` -- the repeated-measures correlation of TCT with RMSE (:func:`analysis.stats.rmcorr.rmcorr`)
  per haptic mode, and over both modes within each participant × mode cell;
* :func:`trade_model` -- a linear mixed model ``TCT ~ RMSE × mode + (1 | participant)``
  (:func:`analysis.stats.models.fit_mixed`): the slope of TCT on RMSE with haptics OFF, and how much it differs ON;
* :func:`participant_slopes` -- each participant's own least-squares slope per mode, for the figure.

No p-value here comes from pooling trials as if independent.  TCT follows the report's TCT policy (over
successful trials by default, so only successful trials enter).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from analysis.reading.codebook import p_text
from analysis.reading.metrics import MetricOptions
from analysis.stats.models import ModelFit, design, fit_mixed
from analysis.stats.rmcorr import rmcorr

__all__ = ["TRADE_MODEL_TERMS", "participant_slopes", "rm_caption", "speed_accuracy", "tct_column", "trade_model",
           "trade_pairs"]

#: The report's default metric options (TCT over successful trials, error window from the cue).
_DEFAULT_OPTIONS = MetricOptions()

#: The fixed effects of :func:`trade_model`, in order, and what each means.
TRADE_MODEL_TERMS = {
    "intercept": "TCT at RMSE = 0 N, haptics OFF (s)",
    "haptics_on": "ON − OFF difference of that intercept (s)",
    "rmse": "slope of TCT on RMSE, haptics OFF (s per N)",
    "rmse_x_on": "ON − OFF difference of the slope (s per N)",
}


def tct_column(options: MetricOptions) -> str:
    """The trials' TCT column under ``options``' TCT policy."""
    return "tct_s" if options.tct_policy == "successful" else "tct_censored_s"


def trade_pairs(trials: pd.DataFrame, options: MetricOptions) -> pd.DataFrame:
    """Trials with both a TCT (under the policy) and an RMSE, as columns ``tct`` (s) and ``rmse`` (N) too."""
    # (a study whose tasks have no TCT or RMSE -- force tracking has no TCT -- has no such trial)
    tct, rmse = (trials[c].astype(float) if c in trials.columns else np.nan for c in (tct_column(options), "rmse_n"))
    t = trials.assign(tct=tct, rmse=rmse)
    return t[np.isfinite(t["tct"]) & np.isfinite(t["rmse"])]


def speed_accuracy(trials: pd.DataFrame, options: MetricOptions = _DEFAULT_OPTIONS, *,
                   confidence: float = 0.95) -> pd.DataFrame:
    """The repeated-measures correlation of TCT with RMSE, per haptic mode and within participant × mode.

    Parameters
    ----------
    trials
        :attr:`analysis.reading.metrics.TrialTable.trials`.
    options
        TCT policy (which trials have a TCT).
    confidence
        Level of the interval of r_rm.

    Returns
    -------
    pandas.DataFrame
        One row per ``haptic_mode`` (``off``, ``on``, ``all``: both modes, each participant × mode its own
        group, so the mode's effect on both measures does not pass for a trade): ``n_trials``,
        ``n_participants``, ``r_rm``, ``df``, ``p_value``, ``ci_low``, ``ci_high``, ``slope_s_per_n`` (the
        common within-participant slope of TCT on RMSE), ``computable``, ``note``, and the medians
        ``median_tct_s``, ``median_rmse_n``.
    """
    pairs = trade_pairs(trials, options)
    rows = []
    for mode in ("off", "on", "all"):
        sel = pairs if mode == "all" else pairs[pairs["haptic_mode"] == mode]
        who = (sel["participant_code"].astype(str) + "/" + sel["haptic_mode"].astype(str)).to_numpy()
        c = rmcorr(who, sel["rmse"].to_numpy(), sel["tct"].to_numpy(), confidence=confidence)
        groups, sizes = np.unique(who, return_counts=True)  # a group with one trial contributes nothing
        contributing = sel["participant_code"][np.isin(who, groups[sizes >= 2])].nunique()
        rows.append({
            "haptic_mode": mode, "n_trials": c.n_obs, "n_participants": int(contributing),
            "r_rm": c.r, "df": c.df, "p_value": c.p_value, "ci_low": c.ci_low, "ci_high": c.ci_high,
            "slope_s_per_n": c.slope, "computable": c.computable, "note": c.note,
            "median_tct_s": float(sel["tct"].median()) if len(sel) else np.nan,
            "median_rmse_n": float(sel["rmse"].median()) if len(sel) else np.nan,
        })
    return pd.DataFrame(rows)


def trade_model(trials: pd.DataFrame, options: MetricOptions = _DEFAULT_OPTIONS, *,
                confidence: float = 0.95) -> ModelFit:
    """``TCT ~ RMSE × haptic mode + (1 | participant)``, REML, with the terms of :data:`TRADE_MODEL_TERMS`.

    RMSE is in newtons, TCT in seconds; mode is coded 0 (OFF) / 1 (ON), so ``rmse`` is the slope with haptics
    OFF and ``rmse_x_on`` how much steeper (positive) or shallower it is ON.
    """
    pairs = trade_pairs(trials, options)
    on = (pairs["haptic_mode"] == "on").astype(float)
    exog = design(pairs, {"intercept": 1.0, "haptics_on": on, "rmse": pairs["rmse"], "rmse_x_on": pairs["rmse"] * on})
    return fit_mixed("speed-accuracy", "TCT (s)", "s; s per N for the slopes", pairs["tct"], exog,
                     pairs["participant_code"], confidence)


def participant_slopes(trials: pd.DataFrame, options: MetricOptions = _DEFAULT_OPTIONS) -> pd.DataFrame:
    """Each participant's least-squares line of TCT on RMSE, per haptic mode (at least 2 distinct RMSEs).

    Returns
    -------
    pandas.DataFrame
        ``participant_code, haptic_mode, n_trials, slope_s_per_n, intercept_s, rmse_min_n, rmse_max_n``; the
        slope and intercept are NaN for fewer than 2 trials or a constant RMSE.
    """
    pairs = trade_pairs(trials, options)
    rows = []
    for (code, mode), g in pairs.groupby(["participant_code", "haptic_mode"], sort=True):
        x, y = g["rmse"].to_numpy(), g["tct"].to_numpy()
        slope = intercept = np.nan
        if len(x) >= 2 and np.ptp(x) > 0:
            slope, intercept = (float(v) for v in np.polyfit(x, y, 1))
        rows.append({"participant_code": code, "haptic_mode": mode, "n_trials": len(x), "slope_s_per_n": slope,
                     "intercept_s": intercept, "rmse_min_n": float(x.min()), "rmse_max_n": float(x.max())})
    return pd.DataFrame(rows, columns=["participant_code", "haptic_mode", "n_trials", "slope_s_per_n",
                                       "intercept_s", "rmse_min_n", "rmse_max_n"])


def rm_caption(row: Any) -> str:
    """``r_rm = −0.31 [−0.55, −0.03], df = 40, p = 0.03125`` for a row of :func:`speed_accuracy` (p as every
    table gives it)."""
    if not bool(row.computable):
        return "r_rm not computable"
    r, lo, hi = (float(getattr(row, k)) for k in ("r_rm", "ci_low", "ci_high"))
    ci = f" [{lo:.2f}, {hi:.2f}]" if np.isfinite(lo) else ""
    p = p_text(float(row.p_value))
    return f"r_rm = {r:.2f}{ci}, df = {int(row.df)}, p {p if p.startswith('<') else '= ' + p}"
