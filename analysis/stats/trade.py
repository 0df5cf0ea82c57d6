"""The speed–accuracy trade, within participants: repeated-measures correlation, a mixed model, slopes.

Does a participant who is faster on a trial make larger errors on it?  Trials of one participant are not
independent, so the question is asked within participants (:func:`analysis.stats.rmcorr.rmcorr`), and speed and
accuracy are measured on parts of the trial that do not contain each other (docs/science.md §6.1):

* the default reading, ``phases``: speed is the **rise time** (first contact to the first sample at or above the
  band's lower edge) and accuracy the **RMSE after reach** (the fixed 1 s that follows), both metrics of the registry
  (:mod:`protocol.metrics`).  Neither window holds the other's samples, and the accuracy window has the same length
  for every trial, so a trial's speed cannot set its accuracy by construction; every trial that reached the band
  counts, failed or not (no conditioning on success);
* the sensitivity readings, ``cue`` and ``first_contact``: TCT of the successful trials against RMSE from the cue
  (the report's figure before this reading) or from first contact.  From the cue the approach at 0 N is in both
  TCT and RMSE: a trial whose hold came quickly has a larger share of approach in its RMSE, a negative correlation
  built by the window (the null model of ``tests/analysis/test_trade_null.py`` shows it).

:func:`speed_accuracy` gives r_rm per mode for one reading; :func:`trade_readings` every reading, with the
conclusion drawn only where the default's interval excludes zero **and** the cue reading agrees
(:func:`trade_conclusion`); :func:`trade_model` the mixed model ``speed ~ accuracy × mode (+ site) + (1 + mode |
participant)`` and :func:`participant_slopes` each participant's own line, for the figure.  No p-value here comes
from pooling trials as if independent.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from analysis.reading.codebook import p_text
from analysis.reading.metrics import MetricOptions, TrialTable
from analysis.stats.models import ModelFit, design, fit_mixed, site_terms
from analysis.stats.rmcorr import rmcorr
from protocol.metrics import TRADE_PHASES, get

__all__ = ["DEFAULT_READING", "READINGS", "TRADE_MODEL_TERMS", "TradeReading", "participant_slopes", "rm_caption",
           "speed_accuracy", "tct_column", "trade_conclusion", "trade_model", "trade_pairs", "trade_readings"]


@dataclass(frozen=True, slots=True)
class TradeReading:
    """One way of measuring speed and accuracy per trial.

    Attributes
    ----------
    key
        ``phases`` (the default), ``cue`` or ``first_contact``.
    speed, accuracy
        The trials table's columns (a time in s, an error in N).
    window
        The error window the accuracy is taken over (None: its own, the 1 s after reaching the band).
    words
        The reading in a few words, for tables.
    """

    key: str
    speed: str
    accuracy: str
    window: str | None
    words: str

    @property
    def speed_label(self) -> str:
        return "rise time (s)" if self.speed == "rise_time_s" else "TCT, successful trials (s)"

    @property
    def accuracy_label(self) -> str:
        if self.window is None:
            return get(self.accuracy).label
        return f"RMSE from {'the cue' if self.window == 'cue' else 'first contact'} (N)"


#: The readings: the default first.
READINGS = (
    TradeReading("phases", TRADE_PHASES[0].name, TRADE_PHASES[1].name, None,
                 "rise time against RMSE after reaching the band (phases apart)"),
    TradeReading("cue", "tct_s", "rmse_n", "cue", "TCT against RMSE from the cue (successful trials)"),
    TradeReading("first_contact", "tct_s", "rmse_n", "first_contact",
                 "TCT against RMSE from first contact (successful trials)"),
)
DEFAULT_READING = READINGS[0]
_BY_KEY = {r.key: r for r in READINGS}

#: The fixed effects of :func:`trade_model`, in order, and what each means (a site term per site after the first).
TRADE_MODEL_TERMS = {
    "intercept": "rise time at RMSE after reach = 0 N, haptics OFF (s)",
    "haptics_on": "ON − OFF difference of that intercept (s)",
    "accuracy": "slope of rise time on RMSE after reach, haptics OFF (s per N)",
    "accuracy_x_on": "ON − OFF difference of the slope (s per N)",
}


def tct_column(options: MetricOptions) -> str:
    """The trials' TCT column under ``options``' TCT policy."""
    return "tct_s" if options.tct_policy == "successful" else "tct_censored_s"


def trade_pairs(trials: pd.DataFrame, reading: TradeReading = DEFAULT_READING) -> pd.DataFrame:
    """Trials with both a speed and an accuracy under ``reading``, as columns ``speed`` (s) and ``accuracy`` (N)."""
    # (a study whose tasks lack either measure -- force tracking has no TCT, no rise time -- has no such trial)
    speed, accuracy = (trials[c].astype(float) if c in trials.columns else np.nan
                       for c in (reading.speed, reading.accuracy))
    t = trials.assign(speed=speed, accuracy=accuracy)
    return t[np.isfinite(t["speed"]) & np.isfinite(t["accuracy"])]


def speed_accuracy(trials: pd.DataFrame, reading: TradeReading = DEFAULT_READING, *,
                   confidence: float = 0.95) -> pd.DataFrame:
    """The repeated-measures correlation of speed with accuracy under ``reading``, per mode and over both.

    Parameters
    ----------
    trials
        :attr:`analysis.reading.metrics.TrialTable.trials`, in the reading's error window
        (:meth:`TrialTable.in_window`).
    reading
        Which speed and accuracy.
    confidence
        Level of the interval of r_rm.

    Returns
    -------
    pandas.DataFrame
        One row per ``haptic_mode`` (``off``, ``on``, ``all``: both modes, each participant × mode its own group,
        so the mode's effect on both measures does not pass for a trade): ``reading, speed, accuracy, n_trials,
        n_participants, r_rm, df, p_value, ci_low, ci_high, slope_s_per_n`` (the common within-participant slope of
        speed on accuracy), ``computable, note, median_speed_s, median_accuracy_n``.
    """
    pairs = trade_pairs(trials, reading)
    rows = []
    for mode in ("off", "on", "all"):
        sel = pairs if mode == "all" else pairs[pairs["haptic_mode"] == mode]
        who = (sel["participant_code"].astype(str) + "/" + sel["haptic_mode"].astype(str)).to_numpy()
        c = rmcorr(who, sel["accuracy"].to_numpy(), sel["speed"].to_numpy(), confidence=confidence)
        groups, sizes = np.unique(who, return_counts=True)  # a group with one trial contributes nothing
        contributing = sel["participant_code"][np.isin(who, groups[sizes >= 2])].nunique()
        rows.append({
            "reading": reading.key, "haptic_mode": mode, "speed": get(reading.speed).exported,
            "accuracy": get(reading.accuracy).exported,
            "n_trials": c.n_obs, "n_participants": int(contributing),
            "r_rm": c.r, "df": c.df, "p_value": c.p_value, "ci_low": c.ci_low, "ci_high": c.ci_high,
            "slope_s_per_n": c.slope, "computable": c.computable, "note": c.note,
            "median_speed_s": float(sel["speed"].median()) if len(sel) else np.nan,
            "median_accuracy_n": float(sel["accuracy"].median()) if len(sel) else np.nan,
        })
    return pd.DataFrame(rows)


def _direction(r: Any) -> str:
    """``negative`` / ``positive`` when the interval of r_rm excludes zero, ``none`` when it holds it, ``n/c``."""
    lo, hi = float(r.ci_low), float(r.ci_high)
    if not bool(r.computable) or not (math.isfinite(lo) and math.isfinite(hi)):
        return "n/c"
    return "negative" if hi < 0 else "positive" if lo > 0 else "none"


def trade_conclusion(row: Any, sensitivity: Any | None) -> str:
    """What a row of the default reading concludes, given the cue reading's row of the same mode (``sensitivity``).

    "a trade" only where the default's interval excludes zero on the negative side **and** the cue reading's does
    too; a reading that cannot say (no interval) or an interval that holds zero is no trade.  The cue reading can
    only withhold the label, never grant it (it is built to find a trade: docs/science.md §6.1), and where it does
    the conclusion says what it showed.
    """
    own = _direction(row)
    if own == "n/c":
        return "not computable (no interval)" if bool(row.computable) else "not computable"
    if own == "none":
        return "no association shown (the interval holds 0)"
    if own == "positive":
        return "positive: slower trials also less accurate (no trade)"
    cue = "n/c" if sensitivity is None else _direction(sensitivity)
    if cue == "negative":
        return "negative: faster trials less accurate (a trade)"
    shown = {"n/c": "is not computable", "none": "holds 0 in its interval", "positive": "is positive"}[cue]
    return f"negative, but the cue-window reading {shown}: not called a trade"


def _reading_conclusion(row: Any) -> str:
    """A sensitivity reading's own conclusion (no label of trade: that is the default's, :func:`trade_conclusion`)."""
    d = _direction(row)
    return {"n/c": "not computable", "none": "no association shown (the interval holds 0)",
            "negative": "negative: faster trials less accurate",
            "positive": "positive: slower trials also less accurate"}[d]


def trade_readings(table: TrialTable, *, confidence: float = 0.95) -> pd.DataFrame:
    """:func:`speed_accuracy` under every reading (:data:`READINGS`), each row with its ``conclusion``.

    The default reading's conclusion is :func:`trade_conclusion` against the cue reading of the same mode; the
    others say only the direction their interval shows.
    """
    frames = [speed_accuracy(table.in_window(r.window) if r.window else table.trials, r, confidence=confidence)
              for r in READINGS]
    out = pd.concat(frames, ignore_index=True)
    cue = out[out["reading"] == "cue"].set_index("haptic_mode")
    out["conclusion"] = [
        trade_conclusion(r, cue.loc[r.haptic_mode] if r.haptic_mode in cue.index else None)
        if r.reading == DEFAULT_READING.key else _reading_conclusion(r) for r in out.itertuples()]
    return out


def trade_model(trials: pd.DataFrame, *, confidence: float = 0.95) -> ModelFit:
    """``rise time ~ RMSE after reach × haptic mode (+ site) + (1 + mode | participant)``, REML.

    Accuracy is in newtons, speed in seconds; mode is coded 0 (OFF) / 1 (ON), so ``accuracy`` is the slope with
    haptics OFF and ``accuracy_x_on`` how much steeper (positive) or shallower it is ON.  A study of several sites
    has a fixed effect per site after the first (:func:`analysis.stats.models.site_terms`).
    """
    pairs = trade_pairs(trials)
    on = (pairs["haptic_mode"] == "on").astype(float)
    exog = design(pairs, {"intercept": 1.0, "haptics_on": on, "accuracy": pairs["accuracy"],
                          "accuracy_x_on": pairs["accuracy"] * on, **site_terms(pairs)})
    return fit_mixed("speed-accuracy", "rise time (s)", "s; s per N for the slopes", pairs["speed"], exog,
                     pairs["participant_code"], confidence, slope=on)


def participant_slopes(trials: pd.DataFrame) -> pd.DataFrame:
    """Each participant's least-squares line of speed on accuracy (the default reading), per haptic mode.

    Returns
    -------
    pandas.DataFrame
        ``participant_code, haptic_mode, n_trials, slope_s_per_n, intercept_s, accuracy_min_n, accuracy_max_n``;
        the slope and intercept are NaN for fewer than 2 trials or a constant accuracy.
    """
    pairs = trade_pairs(trials)
    rows = []
    for (code, mode), g in pairs.groupby(["participant_code", "haptic_mode"], sort=True):
        x, y = g["accuracy"].to_numpy(), g["speed"].to_numpy()
        slope = intercept = np.nan
        if len(x) >= 2 and np.ptp(x) > 0:
            slope, intercept = (float(v) for v in np.polyfit(x, y, 1))
        rows.append({"participant_code": code, "haptic_mode": mode, "n_trials": len(x), "slope_s_per_n": slope,
                     "intercept_s": intercept, "accuracy_min_n": float(x.min()), "accuracy_max_n": float(x.max())})
    return pd.DataFrame(rows, columns=["participant_code", "haptic_mode", "n_trials", "slope_s_per_n",
                                       "intercept_s", "accuracy_min_n", "accuracy_max_n"])


def rm_caption(row: Any) -> str:
    """``r_rm = −0.31 [−0.55, −0.03], df = 40, p = 0.03125`` for a row of :func:`speed_accuracy` (p as every
    table gives it)."""
    if not bool(row.computable):
        return "r_rm not computable"
    r, lo, hi = (float(getattr(row, k)) for k in ("r_rm", "ci_low", "ci_high"))
    ci = f" [{lo:.2f}, {hi:.2f}]" if np.isfinite(lo) else ""
    p = p_text(float(row.p_value))
    return f"r_rm = {r:.2f}{ci}, df = {int(row.df)}, p {p if p.startswith('<') else '= ' + p}"


def reading(key: str) -> TradeReading:
    """The reading of that key."""
    return _BY_KEY[key]
