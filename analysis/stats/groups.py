"""Between-group questions: does the benefit of haptic feedback differ between groups of participants?

The protocol's ``[groups]`` names a category covariate (:mod:`protocol.study.groups`); its levels are the groups.
Three analyses, each with its method named and each group's n:

* **each group's haptic effect** (:func:`group_effects`): the report's own tests within the group's participants
  -- their per-participant ON and OFF values (:func:`analysis.stats.aggregate.per_participant`), the paired
  Wilcoxon signed-rank test with the Hodges–Lehmann shift, Holm across the primary measures
  (:func:`analysis.stats.aggregate.mode_tests`);
* **the group × haptics interaction** (:func:`interaction_models`): a trial-level model per tested measure,
  ``outcome ~ haptics_on × group + target (+ site) + (1 + haptics_on | participant)`` -- a linear mixed model
  (statsmodels MixedLM, REML, a random intercept and a random slope of haptic mode per participant) for the
  continuous measures, on the outcome as the report models it (TCT under the report's TCT policy), and for success,
  a yes/no outcome, the report's logistic GEE (exchangeable within a participant, Mancl–DeRouen standard errors)
  with the same terms; the ``haptics_on_x_group_<level>`` coefficient is how much larger the ON − OFF effect is in
  that group than in the reference group (the first declared level tested);
* **the per-participant effects compared between groups** (:func:`between_tests`): each participant's ON − OFF
  difference of their means, a group against the reference group by the two-sided Mann–Whitney U test
  (:func:`scipy.stats.mannwhitneyu`; exact where the effects have no ties and the groups hold at most
  :data:`EXACT_MAX` participants together, otherwise the normal approximation with the tie correction), with the
  rank-biserial correlation ``2U/(n₁n₂) − 1``.  With more than two groups each is compared with the reference,
  each with its own p.

A group with fewer than :data:`MIN_GROUP` participants is reported with its n and not tested, and is left out of
the model and of the comparisons.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np
import pandas as pd

from analysis.reading.metrics import MetricOptions
from analysis.stats.aggregate import TESTED_METRICS, by_mode, metrics_in, mode_tests
from analysis.stats.models import (
    FIXED_EFFECT_COLUMNS,
    ModelFit,
    design,
    fit_gee_logistic,
    fit_mixed,
    fixed_effects,
    site_terms,
)
from analysis.stats.trade import tct_column
from protocol.study.labels import plural

__all__ = ["BETWEEN_COLUMNS", "EXACT_MAX", "FORMULA", "FORMULA_GEE", "MIN_GROUP", "GroupAnalysis", "analyse_groups",
           "between_tests", "compare_effects", "group_effects", "group_terms", "groups_of", "interaction_models"]

#: Fewest participants for a group to be tested (a paired test of one participant is no test).
MIN_GROUP = 2
#: The exact Mann–Whitney distribution is used up to this many participants in the two groups together.
EXACT_MAX = 60
#: The interaction model's formula, in words (the CSV's ``formula`` column and the page).
FORMULA = "outcome ~ haptics_on × group + target (+ site) + (1 + haptics_on | participant)"
#: The columns of :func:`between_tests` (group_tests.csv).
BETWEEN_COLUMNS = ("metric", "group", "reference", "n_group", "n_reference", "median_effect_group",
                   "median_effect_reference", "u_statistic", "p_value", "rank_biserial", "test", "method", "computable",
                   "note")
FORMULA_GEE = "logit P(success) ~ haptics_on × group + target (+ site); exchangeable within participant"


@dataclass(frozen=True, slots=True)
class GroupAnalysis:
    """What :func:`analyse_groups` found: the groups with their n, each one's effects, the interaction models'
    fixed effects and the tests between groups."""

    by: str
    counts: pd.DataFrame
    effects: pd.DataFrame
    interaction: pd.DataFrame
    between: pd.DataFrame

    @property
    def tested(self) -> list[str]:
        """The groups tested, the reference first."""
        return list(self.counts.loc[self.counts["tested"], "group"])


def groups_of(covariates: pd.DataFrame, by: str, codes: Sequence[str]) -> pd.Series:
    """Each participant's group (``by``'s value), indexed by participant code, for ``codes`` (NaN: not given)."""
    values = covariates.set_index("participant_code")[by] if by in covariates.columns else pd.Series(dtype=object)
    return values.reindex(list(codes))


def _counts(group: pd.Series, levels: Sequence[str]) -> pd.DataFrame:
    rows = []
    for level in levels:
        n = int((group == level).sum())
        tested = n >= MIN_GROUP
        rows.append({"group": level, "n_participants": n, "tested": tested,
                     "note": "" if tested else f"not tested: {plural(n, 'participant')}; a group needs at least "
                                               f"{MIN_GROUP}"})
    missing = int(group.isna().sum())
    if missing:
        rows.append({"group": "", "n_participants": missing, "tested": False,
                     "note": f"no group recorded: {plural(missing, 'participant')} left out of the comparison"})
    return pd.DataFrame(rows, columns=["group", "n_participants", "tested", "note"])


def group_effects(overall: pd.DataFrame, group: pd.Series, counts: pd.DataFrame, *, zero_method: str = "wilcox",
                  confidence: float = 0.95) -> pd.DataFrame:
    """Each tested group's ON-vs-OFF tests (the report's, :func:`mode_tests`), with ``group`` and ``n_participants``
    first; an untested group has one row per measure with its note."""
    frames = []
    for r in counts.itertuples():
        if not r.group:
            continue
        if r.tested:
            mine = overall[overall["participant_code"].map(group) == r.group]
            _, frame = mode_tests(mine, zero_method=zero_method, confidence=confidence)
        else:
            frame = pd.DataFrame({"metric": [m for m in TESTED_METRICS if m in overall.columns],
                                  "computable": False, "note": r.note})
        frame.insert(0, "n_participants", r.n_participants)
        frame.insert(0, "group", r.group)
        frames.append(frame)
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def group_terms(trials: pd.DataFrame, group: pd.Series, tested: Sequence[str],
                target_order: Sequence[str]) -> dict[str, pd.Series | float]:
    """The interaction model's fixed effects: intercept, haptics ON, each group after the reference, their
    interactions with haptics ON, each target after the first, and a site term per site after the first."""
    on = (trials["haptic_mode"] == "on").astype(float)
    g = trials["participant_code"].map(group)
    terms: dict[str, pd.Series | float] = {"intercept": 1.0, "haptics_on": on}
    for level in tested[1:]:
        terms[f"group_{level}"] = (g == level).astype(float)
    for level in tested[1:]:
        terms[f"haptics_on_x_group_{level}"] = on * (g == level).astype(float)
    for label in target_order[1:]:
        terms[f"target_{label}"] = (trials["target_label"] == label).astype(float)
    terms.update(site_terms(trials))
    return terms


def interaction_models(trials: pd.DataFrame, group: pd.Series, tested: Sequence[str], target_order: Sequence[str],
                       options: MetricOptions = MetricOptions(), confidence: float = 0.95) -> list[ModelFit]:
    """One interaction model per tested measure, on the trials of the tested groups' participants (the module)."""
    mine = trials[trials["participant_code"].map(group).isin(list(tested))].reset_index(drop=True)
    exog = design(mine, group_terms(mine, group, tested, target_order))
    groups = mine["participant_code"]
    fits = []
    for m in (m for m in metrics_in(mine) if m.tested):
        if m.boolean:
            fits.append(fit_gee_logistic("group_interaction", m.name, mine[m.name].astype(float), exog, groups,
                                         confidence))
        else:
            y = mine[tct_column(options) if m.success_only else m.name].astype(float)
            fits.append(fit_mixed("group_interaction", m.label, m.unit, y, exog, groups, confidence,
                                  slope=(mine["haptic_mode"] == "on").astype(float)))
    return fits


def compare_effects(a: np.ndarray, b: np.ndarray, min_n: int, who: str, method: str = "exact-without-ties"
                    ) -> dict[str, object]:
    """Two sets of per-participant ON − OFF effects by the two-sided Mann–Whitney U test (U of ``a``), or why not.

    Not tested where a set has fewer than ``min_n`` (``who``: the sets in words, for the note) or every effect is
    the same.  ``method``: ``exact-without-ties`` (exact where nothing ties and there are at most :data:`EXACT_MAX`
    together, otherwise the normal approximation with the tie and continuity corrections: the between-group test)
    or SciPy's ``auto`` (the order check's, as it always was).

    Returns
    -------
    dict
        ``u_statistic, p_value, method, computable, note``.
    """
    from scipy.stats import mannwhitneyu

    out: dict[str, object] = {"u_statistic": math.nan, "p_value": math.nan, "method": "", "computable": False,
                              "note": ""}
    both = np.concatenate([a, b])
    if min(len(a), len(b)) < min_n:
        out["note"] = f"not tested: {len(a)} {who}; each group needs at least {min_n}"
    elif np.ptp(both) == 0:
        out["note"] = "not tested: every participant has the same ON − OFF difference"
    elif method == "auto":
        res = mannwhitneyu(a, b, alternative="two-sided")
        out.update(u_statistic=float(res.statistic), p_value=float(res.pvalue), computable=True)
    else:
        exact = len(np.unique(both)) == len(both) and len(both) <= EXACT_MAX
        res = mannwhitneyu(a, b, alternative="two-sided", method="exact" if exact else "asymptotic")
        out.update(u_statistic=float(res.statistic), p_value=float(res.pvalue), computable=True,
                   method="exact" if exact else "normal approximation, tie-corrected, continuity-corrected")
    return out


def between_tests(overall: pd.DataFrame, group: pd.Series, tested: Sequence[str]) -> pd.DataFrame:
    """Per tested measure, each tested group's per-participant ON − OFF effects against the reference group's
    (the first of ``tested``): Mann–Whitney U, two-sided (the module)."""
    rows = []
    for m in (name for name in TESTED_METRICS if name in overall.columns):
        wide = by_mode(overall, m)
        diff = (wide["on"] - wide["off"]).dropna()
        g = diff.index.map(group)
        ref = diff[g == tested[0]].to_numpy(float)
        for level in tested[1:]:
            x = diff[g == level].to_numpy(float)
            test = compare_effects(x, ref, MIN_GROUP, f"and {len(ref)} participants with an effect")
            row = {"metric": m, "group": level, "reference": tested[0], "n_group": len(x), "n_reference": len(ref),
                   "median_effect_group": float(np.median(x)) if len(x) else math.nan,
                   "median_effect_reference": float(np.median(ref)) if len(ref) else math.nan,
                   "u_statistic": test["u_statistic"], "p_value": test["p_value"],
                   "rank_biserial": (2.0 * cast(float, test["u_statistic"]) / (len(x) * len(ref)) - 1.0
                                     if test["computable"] else math.nan),
                   "test": "Mann–Whitney U, two-sided", "method": test["method"], "computable": test["computable"],
                   "note": test["note"]}
            rows.append(row)
    return pd.DataFrame(rows, columns=list(BETWEEN_COLUMNS))


def analyse_groups(trials: pd.DataFrame, overall: pd.DataFrame, covariates: pd.DataFrame, by: str,
                   levels: Sequence[str], target_order: Sequence[str], options: MetricOptions = MetricOptions(), *,
                   zero_method: str = "wilcox", confidence: float = 0.95) -> GroupAnalysis:
    """The three between-group analyses of the participants analysed (``overall``'s), grouped by ``by``."""
    codes = sorted(overall["participant_code"].unique())
    group = groups_of(covariates, by, codes)
    counts = _counts(group, levels)
    effects = group_effects(overall, group, counts, zero_method=zero_method, confidence=confidence)
    tested = list(counts.loc[counts["tested"], "group"])
    if len(tested) < 2:
        note = (f"not fitted: {plural(len(tested), 'group')} with at least {MIN_GROUP} participants; the interaction "
                "needs two")
        interaction = pd.DataFrame([{"model": "group_interaction", "note": note}],
                                   columns=[*FIXED_EFFECT_COLUMNS, "formula"])
        between = pd.DataFrame([{"note": note.replace("not fitted", "not tested"), "computable": False}],
                               columns=list(BETWEEN_COLUMNS))
    else:
        fits = interaction_models(trials, group, tested, target_order, options, confidence)
        interaction = fixed_effects(fits)
        interaction.insert(interaction.columns.get_loc("method") + 1, "formula",
                           [FORMULA_GEE if s == "log-odds" else FORMULA for s in interaction["scale"]])
        between = between_tests(overall, group, tested)
    return GroupAnalysis(by, counts, effects, interaction, between)
