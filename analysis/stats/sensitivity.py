"""Does a choice of the analysis change the answer?  The headline results under every reading, side by side.

Three choices a reviewer asks about, each a block of :func:`sensitivity` (one row per reading of a measure):

* the **error window** (:data:`analysis.reading.metrics.ERROR_WINDOWS`) of RMSE and Max AE: from the cue (the paper's
  "during the trial", the default) or from first contact.  From the cue, the approach from 0 N is part of the error,
  and Max AE is often exactly the target (the error at the cue, before contact) rather than a peak excursion; the
  ON-vs-OFF tests of the primary measures (Holm across them in each window, as the report);
* the **TCT reading**: the figure's (every trial, a failure at the trial cap: the report's default), the text's
  (successful trials only, conditioned on success: a participant with few successes in a mode has a TCT of one or
  two trials, or none) and TCT as a time to event (the Cox model's hazard ratio, :mod:`analysis.stats.survival`);
* the **speed–accuracy reading** (:data:`analysis.stats.trade.READINGS`): the phases apart (the default), TCT against
  RMSE from the cue and from first contact.

``differs`` flags a measure whose conclusion is not the same under every reading; :func:`max_ae_from_approach`
counts the trials whose Max AE is the approach.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from analysis.reading.metrics import ERROR_WINDOWS, MetricOptions, TrialTable
from analysis.stats.aggregate import PRIMARY_METRICS, mode_tests, per_participant
from analysis.stats.survival import CoxFit

__all__ = ["ALPHA", "SENSITIVITY_COLUMNS", "max_ae_from_approach", "sensitivity"]

#: The level at which a conclusion is drawn.
ALPHA = 0.05

#: The columns of :func:`sensitivity`.
SENSITIVITY_COLUMNS = ("analysis", "measure", "reading", "default", "n", "estimate", "ci_low", "ci_high", "p_value",
                       "p_holm", "conclusion", "differs")

_TCT = "tct_s"


def _test_conclusion(p_holm: float, rank_biserial: float, computable: bool) -> str:
    if not computable or not math.isfinite(p_holm):
        return "not computable"
    if p_holm >= ALPHA:
        return "no significant difference"
    return "ON higher than OFF" if rank_biserial > 0 else "ON lower than OFF"


def _test_rows(table: TrialTable, options: MetricOptions, window: str, tct_policy: str, zero_method: str,
               confidence: float) -> list[Any]:
    """The primary measures' ON-vs-OFF tests with this window and TCT policy (Holm across them)."""
    per = per_participant(table.in_window(window), MetricOptions(window, tct_policy))
    family = [m for m in PRIMARY_METRICS if m in per.columns]  # the study's primary measures
    _, frame = mode_tests(per, family, zero_method=zero_method, confidence=confidence)
    return list(frame.itertuples())


def _test_row(analysis: str, r: Any, reading: str, default: bool) -> dict[str, Any]:
    return {"analysis": analysis, "measure": r.metric, "reading": reading, "default": default, "n": r.n_used,
            "estimate": r.hl_estimate, "ci_low": r.hl_ci_low, "ci_high": r.hl_ci_high, "p_value": r.p_value,
            "p_holm": r.p_holm, "conclusion": _test_conclusion(r.p_holm, r.rank_biserial, bool(r.computable))}


def _cox_row(cox: CoxFit, default: bool = False) -> dict[str, Any]:
    on = cox.term("haptics_on")
    if on is None:
        return {"analysis": "TCT reading", "measure": _TCT, "reading": "time_to_event", "default": default,
                "n": cox.n_trials, "estimate": math.nan, "ci_low": math.nan, "ci_high": math.nan,
                "p_value": math.nan, "p_holm": math.nan, "conclusion": "not computable"}
    p = float(on["p_value"])
    if p >= ALPHA:
        conclusion = "no significant difference"
    else:  # a hazard of success above 1: ON reaches success sooner, a lower time
        conclusion = "ON lower than OFF" if float(on["hazard_ratio"]) > 1 else "ON higher than OFF"
    return {"analysis": "TCT reading", "measure": _TCT, "reading": "time_to_event", "default": default,
            "n": cox.n_trials, "estimate": float(on["hazard_ratio"]), "ci_low": float(on["ci_low"]),
            "ci_high": float(on["ci_high"]), "p_value": p, "p_holm": math.nan, "conclusion": conclusion}


def sensitivity(table: TrialTable, options: MetricOptions, trade: pd.DataFrame, cox: CoxFit, *,
                zero_method: str = "wilcox", confidence: float = 0.95) -> pd.DataFrame:
    """The three blocks of the module docstring, long format (:data:`SENSITIVITY_COLUMNS`).

    Parameters
    ----------
    table
        The analysed trials with their metrics in every window (:attr:`TrialTable.by_window`).
    options
        The report's window and TCT policy (``default`` marks its readings).
    trade
        :func:`analysis.stats.trade.trade_readings`' rows (each with its conclusion).
    cox
        :func:`analysis.stats.survival.cox_model`.
    zero_method, confidence
        As the report's tests.

    Returns
    -------
    pandas.DataFrame
        ``estimate`` is the Hodges–Lehmann shift ON − OFF with its interval (tests), the hazard ratio ON : OFF of
        success (time to event) or r_rm (speed–accuracy); ``p_holm`` Holm's p within the reading's family of the
        primary measures (tests only); ``conclusion`` at p < 0.05 (Holm's p for the tests; the interval for r_rm);
        ``differs`` true on every row of a measure whose conclusion is not the same under every reading.
    """
    rows = []
    for window in ERROR_WINDOWS:
        for r in _test_rows(table, options, window, options.tct_policy, zero_method, confidence):
            if r.metric != _TCT:
                rows.append(_test_row("error window", r, window, window == options.error_window))
    for policy in ("censored", "successful"):
        for r in _test_rows(table, options, options.error_window, policy, zero_method, confidence):
            if r.metric == _TCT:
                rows.append(_test_row("TCT reading", r, policy, policy == options.tct_policy))
    if _TCT in table.trials.columns:  # a study whose tasks have a TCT (force tracking has none)
        rows.append(_cox_row(cox))
    for r in trade.itertuples():
        rows.append({"analysis": "speed-accuracy", "measure": f"r_rm {r.haptic_mode}", "reading": r.reading,
                     "default": r.reading == "phases", "n": r.n_trials, "estimate": r.r_rm, "ci_low": r.ci_low,
                     "ci_high": r.ci_high, "p_value": r.p_value, "p_holm": math.nan, "conclusion": r.conclusion})
    out = pd.DataFrame(rows)
    # a conclusion compared by its direction: the trade's default names a trade where the others name a direction
    kind = out["conclusion"].str.split(r"[:,(]").str[0].str.strip()
    out["differs"] = kind.groupby([out["analysis"], out["measure"]]).transform("nunique") > 1
    return out[list(SENSITIVITY_COLUMNS)]


def max_ae_from_approach(table: TrialTable) -> tuple[int, int]:
    """(trials whose Max AE from the cue comes before first contact, trials with a Max AE from the cue).

    Such a trial's largest error is the approach (the error at the cue's 0 N is the target force itself), not a
    peak force excursion: its Max AE from the cue exceeds its Max AE from first contact, or it never touched.
    """
    if "max_ae_n" not in table.trials.columns:  # a study whose tasks have no Max AE
        return 0, 0
    cue = table.in_window("cue")["max_ae_n"].to_numpy(float)
    contact = table.in_window("first_contact")["max_ae_n"].to_numpy(float)
    has = np.isfinite(cue)
    approach = has & (~np.isfinite(contact) | (cue > contact))
    return int(approach.sum()), int(has.sum())
