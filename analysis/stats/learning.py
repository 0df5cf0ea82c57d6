"""Learning and order: a secondary analysis of the trials, labelled as such in the report.

A within-subject design with a randomised or counterbalanced order raises two questions before any
reviewer reads the ON-vs-OFF tests: did participants improve over the session (learning), and does the
effect of feedback depend on which mode a participant met first (order, carry-over)?

* :func:`learning_models` -- per tested metric (:mod:`protocol.metrics`), one trial-level model
  ``metric ~ haptic mode × target + trial number (+ site) + (1 + mode | participant)``: a linear mixed model with a
  random slope of mode for TCT, RMSE and Max AE, a logistic GEE (exchangeable within a participant, Mancl–DeRouen
  standard errors) for success
  (:mod:`analysis.stats.models`).  The trial-number coefficient is the change per trial, at fixed mode and target.
* :func:`order_check` -- each participant's ON − OFF difference (their per-mode means) compared between
  participants whose stored schedule began with an ON trial and those whose began with an OFF trial
  (Mann–Whitney U, :func:`scipy.stats.mannwhitneyu`, two-sided).  With the paper's fully random order
  the first trial's mode is a weak notion of order; with ``blocked_by_mode`` or ``counterbalanced`` it is the
  block order.
* :func:`learning_curve` -- each metric over the trials of the session by mode (blocks of trials,
  participants' block means first), for the figure.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from analysis.stats.aggregate import TESTED_METRICS, by_mode, metrics_in
from analysis.stats.models import ModelFit, design, fit_gee_logistic, fit_mixed, site_terms
from protocol.metrics import Metric

__all__ = ["MIN_ORDER_GROUP", "first_modes", "learning_curve", "learning_models", "order_check", "trial_terms"]

#: Fewest participants in each order group for the order check to be tested.
MIN_ORDER_GROUP = 3



def _tested(trials: pd.DataFrame) -> tuple[Metric, ...]:
    """The metrics the report tests (:data:`analysis.stats.aggregate.TESTED_METRICS`) that ``trials`` has."""
    return tuple(m for m in metrics_in(trials) if m.tested)


def trial_terms(trials: pd.DataFrame, target_order: list[str]) -> dict[str, pd.Series | float]:
    """The fixed effects of the learning models: haptics ON, each target above the first, their
    interactions, and the trial number (trial_index + 1, as the report numbers trials)."""
    on = (trials["haptic_mode"] == "on").astype(float)
    terms: dict[str, pd.Series | float] = {"intercept": 1.0, "haptics_on": on}
    for label in target_order[1:]:
        is_t = (trials["target_label"] == label).astype(float)
        terms[f"target_{label}"] = is_t
        terms[f"haptics_on_x_target_{label}"] = on * is_t
    terms["trial_number"] = trials["trial_index"].astype(float) + 1.0
    terms.update(site_terms(trials))  # a study of several sites: a fixed effect per site after the first
    return terms


def learning_models(trials: pd.DataFrame, target_order: list[str], tct_column: str = "tct_s",
                    confidence: float = 0.95) -> list[ModelFit]:
    """The learning models, one per tested metric, in order: a yes/no outcome (success) by a logistic GEE, the
    others (TCT, RMSE, Max AE, ...) by linear mixed models.

    Parameters
    ----------
    trials
        The analysed trials.
    target_order
        Target labels, the first the reference level.
    tct_column
        The success-only metric's column: ``tct_s`` (successful trials only) or ``tct_censored_s``.
    confidence
        Level of the Wald intervals.
    """
    groups = trials["participant_code"]
    exog = design(trials, trial_terms(trials, target_order))
    fits = []
    for m in _tested(trials):
        if m.boolean:
            fits.append(fit_gee_logistic("learning", m.name, trials[m.name].astype(float), exog, groups, confidence))
        else:
            y = trials[tct_column if m.success_only else m.name].astype(float)
            fits.append(fit_mixed("learning", m.label, m.unit, y, exog, groups, confidence,
                                  slope=(trials["haptic_mode"] == "on").astype(float)))
    return fits


def order_check(per_part: pd.DataFrame, first_mode: pd.Series) -> pd.DataFrame:
    """ON − OFF per participant, ON-first against OFF-first participants, per metric (Mann–Whitney U).

    Parameters
    ----------
    per_part
        :func:`analysis.stats.aggregate.per_participant` (overall).
    first_mode
        Each participant's first scheduled mode (``on``/``off``), indexed by participant code.

    Returns
    -------
    pandas.DataFrame
        ``metric, n_on_first, n_off_first, median_diff_on_first, median_diff_off_first, u_statistic, p_value,
        computable, note`` (differences are ON − OFF in the metric's unit).
    """
    from analysis.stats.groups import compare_effects  # (groups builds on this floor's aggregation too)

    rows = []
    for m in (name for name in TESTED_METRICS if name in per_part.columns):
        wide = by_mode(per_part, m)
        diff = (wide["on"] - wide["off"]).dropna()
        order = first_mode.reindex(diff.index)
        a, b = diff[order == "on"].to_numpy(), diff[order == "off"].to_numpy()
        test = compare_effects(a, b, MIN_ORDER_GROUP, f"ON-first and {len(b)} OFF-first participants", "auto")
        rows.append({"metric": m, "n_on_first": len(a), "n_off_first": len(b),
                     "median_diff_on_first": float(np.median(a)) if len(a) else math.nan,
                     "median_diff_off_first": float(np.median(b)) if len(b) else math.nan,
                     **{k: test[k] for k in ("u_statistic", "p_value", "computable", "note")}})
    return pd.DataFrame(rows)


def learning_curve(trials: pd.DataFrame, tct_column: str = "tct_s", blocks: int = 4) -> pd.DataFrame:
    """Each tested metric over the session by mode: trials cut into ``blocks`` equal runs of trial numbers.

    Each participant's mean per block and mode comes first; the table gives their mean and standard error
    across participants, so every participant weighs the same.

    Returns
    -------
    pandas.DataFrame
        ``metric, haptic_mode, block, first_trial, last_trial, mean, se, n_participants``.
    """
    number = trials["trial_index"].astype(int) + 1
    top = int(number.max()) if len(number) else 1
    size = max(1, math.ceil(top / blocks))
    # each tested metric as a number per trial: a yes/no outcome as 0/1 (its mean a rate), TCT under the policy
    values = {f"_{m.participant}": (trials[m.name].astype(float) if m.boolean else
                                    trials[tct_column] if m.success_only else trials[m.name]) for m in _tested(trials)}
    t = trials.assign(block=(number - 1) // size, **values)
    rows = []
    for col in values:
        m = col[1:]
        cell = t.groupby(["haptic_mode", "block", "participant_code"], sort=True)[col].mean().dropna()
        for (mode, block), vals in cell.groupby(level=[0, 1]):
            v = vals.to_numpy(float)
            se = float(v.std(ddof=1) / math.sqrt(len(v))) if len(v) > 1 else math.nan
            rows.append({"metric": m, "haptic_mode": mode, "block": int(block), "first_trial": int(block) * size + 1,
                         "last_trial": min(top, (int(block) + 1) * size), "mean": float(v.mean()), "se": se,
                         "n_participants": len(v)})
    return pd.DataFrame(rows, columns=["metric", "haptic_mode", "block", "first_trial", "last_trial", "mean", "se",
                                       "n_participants"])


def first_modes(sessions: pd.DataFrame) -> pd.Series:
    """Each analysed participant's first scheduled haptic mode (from the stored schedule), by code."""
    analysed = sessions[sessions["analysed"].astype(bool)]
    return analysed.drop_duplicates("participant_code").set_index("participant_code")["first_mode"]
