"""TCT as the time-to-event it is: time to success per trial, a failure censored at the trial cap.

The paper's text defines TCT over successful trials (a time only a success has); its figure averages TCT over all
trials with a failure at the 12 s cap.  A trial capped at 12 s did not succeed *by* 12 s: its time to success is
censored there, and survival analysis is the statistics of such times.

* :func:`kaplan_meier` -- the Kaplan–Meier estimate of P(not yet succeeded by t) per haptic mode, over the trials of
  all participants (descriptive: trials of a participant are not independent, so its pointwise intervals are too
  narrow; the inference is the model's), computed by :func:`scipy.stats.ecdf` on censored data with its log-log
  pointwise interval;
* :func:`time_to_event_summary` -- per mode the trials, the successes, the Kaplan–Meier median time to success and
  the restricted mean (the mean of min(TCT, cap): the figure's reading of TCT, a mean over every trial);
* :func:`cox_model` -- a Cox proportional-hazards model of the time to success with haptics ON and the target as
  covariates, **stratified by participant** (each participant their own baseline hazard, so the effect is
  estimated within participants and a site, constant within a participant, is absorbed) and with standard errors
  clustered on the participant (the sandwich variance: the trials of one participant stay dependent), fitted by
  statsmodels' :class:`~statsmodels.duration.hazard_regression.PHReg` with Efron's handling of tied times.  Its
  hazard ratio for haptics ON is how many times sooner (> 1) a trial with feedback reaches success.

The tests recompute the estimate and its interval from trials.csv with a partial likelihood written out and with
statsmodels called from a formula (``tests/analysis/test_survival.py``).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pandas as pd

__all__ = ["COX_COLUMNS", "CoxFit", "cox_model", "kaplan_meier", "time_to_event", "time_to_event_summary"]

#: The columns of :meth:`CoxFit.table` (survival_model.csv).
COX_COLUMNS = ("term", "hazard_ratio", "ci_low", "ci_high", "coef", "std_error", "z", "p_value",
               "model_std_error", "n_trials", "n_events", "n_participants", "method", "note")


def time_to_event(trials: pd.DataFrame) -> pd.DataFrame:
    """Each analysed trial's time to success (s, the cap for a failure) and whether it succeeded (``event``); none
    in a study whose tasks have no TCT (force tracking: a trial runs its course, no success to wait for)."""
    if "tct_censored_s" not in trials.columns or "success" not in trials.columns:
        trials = pd.DataFrame({c: pd.Series(dtype=float) for c in ("participant_code", "haptic_mode", "target_label",
                                                                   "tct_censored_s", "success")})
    return pd.DataFrame({"participant_code": trials["participant_code"], "haptic_mode": trials["haptic_mode"],
                         "target_label": trials["target_label"],
                         "time_s": trials["tct_censored_s"].to_numpy(float),
                         "event": trials["success"].astype(bool).to_numpy()}, index=trials.index)


def _modes(trials: pd.DataFrame) -> Iterator[tuple[str, pd.DataFrame]]:
    """Each haptic mode that has trials (OFF, then ON) with its trials' times to event."""
    tte = time_to_event(trials)
    for mode in ("off", "on"):
        sel = tte[tte["haptic_mode"] == mode]
        if not sel.empty:
            yield mode, sel


def kaplan_meier(trials: pd.DataFrame, confidence: float = 0.95) -> pd.DataFrame:
    """The Kaplan–Meier curve of P(no success yet) per haptic mode.

    Returns
    -------
    pandas.DataFrame
        ``haptic_mode, time_s, n_at_risk, n_events, survival, ci_low, ci_high``: one row per distinct time of a
        success (the curve's steps), after a first row at time 0 with survival 1; the interval is SciPy's
        pointwise log-log (Greenwood) interval at ``confidence``.
    """
    from scipy.stats import CensoredData, ecdf

    rows = []
    for mode, sel in _modes(trials):
        t, e = sel["time_s"].to_numpy(float), sel["event"].to_numpy(bool)
        rows.append({"haptic_mode": mode, "time_s": 0.0, "n_at_risk": len(t), "n_events": 0, "survival": 1.0,
                     "ci_low": 1.0, "ci_high": 1.0})
        if not e.any():
            continue
        sf = ecdf(CensoredData(uncensored=t[e], right=t[~e])).sf
        with warnings.catch_warnings():  # a step at survival 0 has no log-log interval: NaN, said in the table
            warnings.simplefilter("ignore", RuntimeWarning)
            ci = sf.confidence_interval(confidence, method="log-log")
        times = sf.quantiles
        for k, time in enumerate(times):
            if not (t[e] == time).any():
                continue  # a censored time: no step
            rows.append({"haptic_mode": mode, "time_s": float(time), "n_at_risk": int((t >= time).sum()),
                         "n_events": int((t[e] == time).sum()), "survival": float(sf.probabilities[k]),
                         "ci_low": float(ci.low.probabilities[k]), "ci_high": float(ci.high.probabilities[k])})
    return pd.DataFrame(rows, columns=["haptic_mode", "time_s", "n_at_risk", "n_events", "survival", "ci_low",
                                       "ci_high"])


def time_to_event_summary(trials: pd.DataFrame, km: pd.DataFrame) -> pd.DataFrame:
    """Per mode: ``n_trials, n_successes, n_participants, km_median_s`` (the first time the Kaplan–Meier curve is at
    or below 0.5; empty when it stays above: fewer than half the trials succeeded), ``restricted_mean_s`` (the
    mean of min(TCT, cap) over every trial, the figure's reading) and ``successful_mean_s`` with ``n_successes``
    (the text's reading, successful trials only)."""
    rows = []
    for mode, sel in _modes(trials):
        curve = km[km["haptic_mode"] == mode]
        below = curve[curve["survival"] <= 0.5]
        ok = sel["event"].to_numpy(bool)
        rows.append({"haptic_mode": mode, "n_trials": len(sel), "n_successes": int(ok.sum()),
                     "n_participants": int(sel["participant_code"].nunique()),
                     "km_median_s": float(below["time_s"].iloc[0]) if len(below) else math.nan,
                     "restricted_mean_s": float(sel["time_s"].mean()),
                     "successful_mean_s": float(sel["time_s"][ok].mean()) if ok.any() else math.nan})
    return pd.DataFrame(rows, columns=["haptic_mode", "n_trials", "n_successes", "n_participants", "km_median_s",
                                       "restricted_mean_s", "successful_mean_s"])


@dataclass(frozen=True, slots=True)
class CoxFit:
    """The Cox model: its terms (hazard ratios with intervals) or why it was not fitted."""

    terms: pd.DataFrame
    n_trials: int
    n_events: int
    n_participants: int
    method: str
    note: str
    confidence: float = 0.95

    @property
    def fitted(self) -> bool:
        return len(self.terms) > 0

    def term(self, name: str) -> pd.Series | None:
        """One term's row (``haptics_on``), or None."""
        hit = self.terms[self.terms["term"] == name]
        return hit.iloc[0] if len(hit) else None

    def table(self) -> pd.DataFrame:
        """survival_model.csv: a row per term (:data:`COX_COLUMNS`); an unfitted model is one row with its note."""
        base = {"n_trials": self.n_trials, "n_events": self.n_events, "n_participants": self.n_participants,
                "method": self.method, "note": self.note}
        if not self.fitted:
            return pd.DataFrame([{**dict.fromkeys(COX_COLUMNS, math.nan), "term": "", **base}],
                                columns=list(COX_COLUMNS))
        return self.terms.assign(**base)[list(COX_COLUMNS)]


_METHOD = ("Cox proportional hazards (statsmodels PHReg, Efron ties), stratified by participant, sandwich standard "
           "errors clustered on the participant")


def cox_model(trials: pd.DataFrame, target_order: list[str], confidence: float = 0.95) -> CoxFit:
    """The hazard of success ~ haptics ON + target, stratified by participant, clustered SEs (module docstring)."""
    from scipy.special import ndtri
    from statsmodels.duration.hazard_regression import PHReg

    tte = time_to_event(trials)
    n, events, k = len(tte), int(tte["event"].sum()), int(tte["participant_code"].nunique())
    on = (tte["haptic_mode"] == "on").astype(float)
    cols = {"haptics_on": on.to_numpy()}
    for label in target_order[1:]:
        cols[f"target_{label}"] = (tte["target_label"] == label).astype(float).to_numpy()
    exog = pd.DataFrame(cols, index=tte.index)
    why = ""
    by_mode = tte.groupby("haptic_mode")["event"].sum()
    if set(by_mode.index) != {"off", "on"}:
        why = "not fitted: the trials are of one haptic mode"
    elif (by_mode == 0).any():
        none = ", ".join(m.upper() for m in by_mode.index[by_mode == 0])
        why = f"not fitted: no trial succeeded with haptics {none}, so the hazard ratio is not finite"
    elif k < 2:
        why = "not fitted: one participant; clustered standard errors need at least two"
    if why:
        return CoxFit(pd.DataFrame(columns=list(COX_COLUMNS)), n, events, k, _METHOD, why, confidence)
    exog = exog.loc[:, exog.std() > 0]  # a target of one label only: no term
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model = PHReg(tte["time_s"].to_numpy(float), exog, status=tte["event"].astype(float).to_numpy(),
                      strata=tte["participant_code"].astype(str).to_numpy(), ties="efron")
        plain = model.fit()
        robust = model.fit(groups=tte["participant_code"].astype(str).to_numpy())
    z_q = float(ndtri(0.5 + confidence / 2.0))
    coef, se = np.asarray(robust.params, float), np.asarray(robust.bse, float)
    z = coef / se
    from scipy.stats import norm

    terms = pd.DataFrame({"term": list(exog.columns), "hazard_ratio": np.exp(coef),
                          "ci_low": np.exp(coef - z_q * se), "ci_high": np.exp(coef + z_q * se), "coef": coef,
                          "std_error": se, "z": z, "p_value": 2.0 * norm.sf(np.abs(z)),
                          "model_std_error": np.asarray(plain.bse, float)})
    note = "; ".join(dict.fromkeys(str(w.message).splitlines()[0] for w in caught))
    return CoxFit(terms, n, events, k, _METHOD, note, confidence)
