"""Trial-level models with participant as the unit of repetition, fitted by statsmodels.

Two kinds, each fitted once per outcome:

* a **linear mixed model** (:class:`statsmodels.regression.mixed_linear_model.MixedLM`, REML, a random
  intercept per participant and, where the design has one, a random slope of haptic mode -- each participant their
  own effect of feedback, so the fixed effect of mode is judged against how much that effect varies between people;
  optimisers :data:`MIXED_METHODS`) for continuous outcomes (TCT, RMSE, Max AE);
* **generalised estimating equations** (:class:`statsmodels.genmod.generalized_estimating_equations.GEE`,
  binomial, logit link, exchangeable working correlation within a participant) for success, a binary outcome --
  the population-averaged logistic model, which does not need the numerical integration a logistic mixed model
  does and is stable with few participants.  Its sandwich standard errors are Mancl and DeRouen's (2001)
  bias-reduced ones (statsmodels' ``cov_type="bias_reduced"``): the plain sandwich is too small with the 10-20
  clusters a study like this has.

A study pooled from several sites has a fixed effect per site after the first in every model
(:func:`site_terms`).

The design matrix is built here from named columns (:func:`design`), so each coefficient has a readable
term name and no formula parser is loaded; :func:`fixed_effects` turns a fit into one tidy table.  Below
:data:`MIN_PARTICIPANTS` participants no model is fitted and the table says so in a note: a participant
variance estimated from fewer people is little more than a guess.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from protocol.study.labels import plural

__all__ = ["FIXED_EFFECT_COLUMNS", "MIN_PARTICIPANTS", "MIXED_METHODS", "ModelFit", "design", "fit_gee_logistic",
           "fit_mixed", "fixed_effects", "site_terms"]

#: Fewest participants for which a model with a participant effect is fitted.
MIN_PARTICIPANTS = 6

#: The columns of :func:`fixed_effects`.
FIXED_EFFECT_COLUMNS = ("model", "outcome", "term", "estimate", "std_error", "ci_low", "ci_high", "z", "p_value",
                        "scale", "n_obs", "n_participants", "method", "converged", "note")


@dataclass(frozen=True, slots=True)
class ModelFit:
    """One fitted (or not fitted) model, ready for :func:`fixed_effects`.

    Attributes
    ----------
    model, outcome, scale, method
        What was modelled: the model's name, the outcome, the unit of its coefficients and how it was fitted.
    params, std_errors, z, p_values, ci_low, ci_high
        Fixed effects by term (empty when not fitted).
    n_obs, n_participants
        Observations and participants used.
    converged
        False when the optimiser did not converge or statsmodels warned (see ``note``).
    note
        Why the model was not fitted, or the warnings of the fit; empty otherwise.
    extra
        Other numbers a report may show (e.g. the participant variance ``participant_var`` and ``residual_var``).
    """

    model: str
    outcome: str
    scale: str
    method: str
    params: pd.Series
    std_errors: pd.Series
    z: pd.Series
    p_values: pd.Series
    ci_low: pd.Series
    ci_high: pd.Series
    n_obs: int
    n_participants: int
    converged: bool
    note: str
    extra: dict[str, float]

    @property
    def fitted(self) -> bool:
        """A fit was made (it may still carry warnings)."""
        return len(self.params) > 0


def design(frame: pd.DataFrame, columns: dict[str, pd.Series | np.ndarray | float]) -> pd.DataFrame:
    """A design matrix of named columns (a float ``1.0`` is a constant column), row for row with ``frame``."""
    out = pd.DataFrame(index=frame.index)
    for name, values in columns.items():
        out[name] = np.full(len(frame), values, dtype=float) if np.isscalar(values) else np.asarray(values, float)
    return out


def site_terms(frame: pd.DataFrame) -> dict[str, pd.Series | np.ndarray | float]:
    """A fixed effect per site after the first (``site_B``: 1 for site B's rows), where ``frame`` has a ``site``
    column naming more than one site; none otherwise."""
    if "site" not in frame.columns:
        return {}
    sites = sorted({str(s) for s in frame["site"] if isinstance(s, str) and s})
    return {f"site_{s}": (frame["site"] == s).astype(float) for s in sites[1:]}


def _unfitted(model: str, outcome: str, scale: str, method: str, n: int, k: int, note: str) -> ModelFit:
    empty = pd.Series(dtype=float)
    return ModelFit(model, outcome, scale, method, empty, empty, empty, empty, empty, empty, n, k, False, note, {})


def _too_few(groups: np.ndarray, n_terms: int) -> str:
    k = len(np.unique(groups))
    if k < MIN_PARTICIPANTS:
        return (f"not fitted: {plural(k, 'participant')}; a model with a participant effect needs at least "
                f"{MIN_PARTICIPANTS} for its participant variance to mean anything")
    if len(groups) <= n_terms + k:
        return (f"not fitted: {plural(len(groups), 'observation')} for {plural(n_terms, 'fixed effect')} and "
                f"{plural(k, 'participant')}")
    return ""


def _warned(caught: Sequence[warnings.WarningMessage]) -> list[str]:
    """The distinct warnings of a fit, first lines only."""
    return list(dict.fromkeys(str(w.message).splitlines()[0] for w in caught))


#: statsmodels' warnings that a variance may be zero (judged here: :data:`_AT_ZERO`).
_BOUNDARY = "on the boundary of the parameter space"
_SINGULAR = ("Random effects covariance is singular", "The random effects covariance matrix is singular")
#: A participant variance below this fraction of the residual variance is zero for the report.
_AT_ZERO = 1e-6
#: The optimisers MixedLM tries in turn: Powell's derivative-free method reaches a participant variance of 0
#: (common with few participants) where the gradient methods stall or fail on a singular matrix; L-BFGS if not.
MIXED_METHODS = ["powell", "lbfgs"]


def fit_mixed(model: str, outcome: str, scale: str, y: pd.Series, exog: pd.DataFrame, groups: pd.Series,
              confidence: float = 0.95, slope: pd.Series | None = None) -> ModelFit:
    """A linear mixed model ``y ~ exog + (1 [+ slope] | groups)``, REML, the optimisers of :data:`MIXED_METHODS`.

    Parameters
    ----------
    model, outcome, scale
        Names for the table: the model, the outcome and the unit of the coefficients.
    y, exog, groups
        Outcome, fixed-effects design (:func:`design`) and participant, row for row; rows with a NaN are
        left out.
    confidence
        Level of the Wald intervals.
    slope
        A random slope of this column per participant beside the random intercept (the haptic mode, 0/1), with
        their covariance; None: a random intercept only.  Where the slope's variance cannot be estimated (the fit
        fails) the model is fitted with the intercept alone and says so in its note.

    Returns
    -------
    ModelFit
    """
    method = "linear mixed model, REML (statsmodels MixedLM), random intercept per participant"
    keep = np.isfinite(y.to_numpy(float)) & np.isfinite(exog.to_numpy(float)).all(axis=1)
    y, exog, groups = y[keep], exog[keep], groups[keep]
    why = _too_few(groups.to_numpy(), exog.shape[1])
    if why:
        return _unfitted(model, outcome, scale, method, int(keep.sum()), int(groups.nunique()), why)
    fallback = ""
    if slope is not None:
        fit = _fit_mixed(y, exog, groups, method + " and random slope of haptic mode", confidence,
                         slope[keep].to_numpy(float))
        # a fit that warned (a Hessian not positive definite, an invalid value) or whose errors are not finite
        # is not trusted: the intercept alone, said in the note
        if not isinstance(fit, str) and fit[9] and np.isfinite(np.asarray(fit[2], float)).all():
            return ModelFit(model, outcome, scale, *fit)
        why = fit if isinstance(fit, str) else (fit[10] or "it did not converge")
        fallback = f"the random slope of haptic mode could not be fitted ({why}): random intercept only"
    fit = _fit_mixed(y, exog, groups, method, confidence, None)
    if isinstance(fit, str):
        return _unfitted(model, outcome, scale, method, int(keep.sum()), int(groups.nunique()), fit)
    plain = ModelFit(model, outcome, scale, *fit)
    return dataclasses.replace(plain, note="; ".join(filter(None, (fallback, plain.note))))


def _fit_mixed(y: pd.Series, exog: pd.DataFrame, groups: pd.Series, method: str, confidence: float,
               slope: np.ndarray | None) -> tuple[Any, ...] | str:
    """One MixedLM fit: the fields of :class:`ModelFit` after ``scale``, or why it failed."""
    from statsmodels.regression.mixed_linear_model import MixedLM

    exog_re = None if slope is None else np.column_stack([np.ones(len(slope)), slope])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            res = MixedLM(y.to_numpy(float), exog, groups=groups.to_numpy(), exog_re=exog_re).fit(
                reml=True, method=MIXED_METHODS)
        except (np.linalg.LinAlgError, ValueError, ZeroDivisionError) as exc:
            return f"the fit failed: {exc}"
    names = list(exog.columns)
    ci = res.conf_int(alpha=1.0 - confidence).loc[names]
    participant_var = float(np.asarray(res.cov_re)[0, 0])
    at_zero = participant_var <= _AT_ZERO * float(res.scale)
    # statsmodels warns of "the boundary" below an absolute 0.01 whatever the unit (0.01 N² is a real variance in
    # N); whether the participant variance is at zero is judged here against the residual variance instead
    notes = [w for w in _warned(caught) if _BOUNDARY not in w and not (at_zero and w.startswith(_SINGULAR))]
    converged = bool(res.converged) and not notes
    if at_zero:
        notes.append("the participant variance is estimated at zero (participants differ no more than their trials "
                     "do): the fixed effects are those of ordinary least squares")
    extra = {"participant_var": participant_var, "residual_var": float(res.scale)}
    if slope is not None:
        extra["mode_slope_var"] = float(np.asarray(res.cov_re)[1, 1])
    return (method, res.fe_params[names], res.bse_fe[names], res.tvalues[names], res.pvalues[names], ci[0], ci[1],
            int(res.nobs), int(groups.nunique()), converged, "; ".join(notes), extra)


def fit_gee_logistic(model: str, outcome: str, y: pd.Series, exog: pd.DataFrame, groups: pd.Series,
                     confidence: float = 0.95) -> ModelFit:
    """Logistic GEE ``logit P(y) ~ exog``, exchangeable correlation within ``groups``, robust SEs.

    Parameters are those of :func:`fit_mixed`; ``y`` is 0/1.  Coefficients are log-odds.
    """
    from statsmodels.genmod import families
    from statsmodels.genmod.cov_struct import Exchangeable
    from statsmodels.genmod.generalized_estimating_equations import GEE

    method = ("logistic GEE (statsmodels), exchangeable correlation within a participant, bias-reduced "
              "(Mancl–DeRouen) sandwich SEs")
    yv = y.to_numpy(float)
    keep = np.isfinite(yv) & np.isfinite(exog.to_numpy(float)).all(axis=1)
    y, exog, groups = y[keep], exog[keep], groups[keep]
    why = _too_few(groups.to_numpy(), exog.shape[1])
    if not why and y.nunique() < 2:
        why = f"not fitted: every trial has {outcome} = {int(y.iloc[0])}"
    if why:
        return _unfitted(model, outcome, "log-odds", method, int(keep.sum()), int(groups.nunique()), why)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            res = GEE(y.to_numpy(float), exog, groups=groups.to_numpy(), family=families.Binomial(),
                      cov_struct=Exchangeable()).fit(cov_type="bias_reduced")
        except (np.linalg.LinAlgError, ValueError, ZeroDivisionError) as exc:
            return _unfitted(model, outcome, "log-odds", method, int(keep.sum()), int(groups.nunique()),
                             f"the fit failed: {exc}")
    ci = res.conf_int(alpha=1.0 - confidence)
    note = "; ".join(_warned(caught))
    converged = bool(getattr(res, "converged", True)) and not note and bool(np.isfinite(res.bse).all())
    return ModelFit(model, outcome, "log-odds", method, res.params, res.bse, res.tvalues, res.pvalues, ci[0],
                    ci[1], int(res.nobs), int(groups.nunique()), converged, note, {})


def fixed_effects(fits: Sequence[ModelFit]) -> pd.DataFrame:
    """One row per fixed effect of every fit (:data:`FIXED_EFFECT_COLUMNS`); a model not fitted is one row
    with its note and no numbers."""
    rows = []
    for f in fits:
        base = {"model": f.model, "outcome": f.outcome, "scale": f.scale, "n_obs": f.n_obs,
                "n_participants": f.n_participants, "method": f.method, "converged": f.converged, "note": f.note}
        if not f.fitted:
            rows.append({**base, "term": "", **dict.fromkeys(("estimate", "std_error", "ci_low", "ci_high", "z",
                                                              "p_value"), math.nan)})
            continue
        for term in f.params.index:
            rows.append({**base, "term": term, "estimate": float(f.params[term]),
                         "std_error": float(f.std_errors[term]), "ci_low": float(f.ci_low[term]),
                         "ci_high": float(f.ci_high[term]), "z": float(f.z[term]), "p_value": float(f.p_values[term])})
    return pd.DataFrame(rows, columns=list(FIXED_EFFECT_COLUMNS))
