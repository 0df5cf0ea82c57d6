"""Skill over days: learning across the visits of a schedule and its retention (:mod:`protocol.study.visits`).

The input is one value per participant per visit per haptic mode (:data:`PER_VISIT_KEYS` and each primary metric's
participant column, :mod:`analysis.stats.aggregate`), the participant's mean over the visit's analysed trials.

* :func:`visit_models` -- per metric, a linear mixed model of the practice visits (every visit but the retention
  tests: the delay before those is forgetting, not practice)
  ``metric ~ log(session) × haptic ON + (1 | participant)``, REML (statsmodels MixedLM through
  :func:`analysis.stats.models.fit_mixed`).  *session* is the participant's n-th measured visit (1, 2, …).
  **Why log(session)**: the power law of practice (Newell & Rosenbloom 1981) makes performance change fast at
  first and ever more slowly; a power law ``y = a + b·n^(−c)`` is close to linear in ``log n`` over a few sessions
  (exactly linear for ``c → 0``), so ``log_session`` is the change per e-fold of practice, one coefficient, where
  a term per session would spend the few participants' degrees of freedom and a linear term would call the slowing a
  misfit.  ``haptic_on`` is ON − OFF at the first session, ``log_session:haptic_on`` how much the ON curve's slope
  differs from OFF's.  A random intercept only: with one value per participant × visit × mode a random slope per
  participant has few observations to stand on.
* :func:`retention_table` -- per participant and mode: the baseline, post and retention values, ``post −
  baseline`` (the gain) and ``retention − post`` (what was kept: negative = forgotten for a rate, positive for an
  error or a time).
* :func:`retention_tests` -- for each metric and mode, the paired Wilcoxon signed-rank test
  (:func:`analysis.stats.wilcoxon.paired_wilcoxon`, two-sided, zero differences dropped -- Wilcoxon's method --
  the report's rule for exact/permutation/normal p) of retention against post and of post against baseline.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pandas as pd

from analysis.stats.models import ModelFit, design, fit_mixed
from analysis.stats.wilcoxon import paired_wilcoxon

__all__ = ["PER_VISIT_KEYS", "RETENTION_COLUMNS", "TEST_COLUMNS", "retention_table", "retention_tests",
           "session_numbers", "visit_models"]

#: The keys of a per-visit table (before the metric columns).
PER_VISIT_KEYS = ("participant_code", "visit", "visit_number", "day", "role", "haptic_mode", "n_trials")
#: retention.csv's columns.
RETENTION_COLUMNS = ("participant_code", "haptic_mode", "metric", "baseline", "post", "retention", "retention_visit",
                     "gain_post_minus_baseline", "kept_retention_minus_post")
#: The tests' columns (retention_tests.csv).
TEST_COLUMNS = ("metric", "haptic_mode", "comparison", "n_pairs", "n_used", "statistic", "p_value", "method",
                "median_difference", "note")


def session_numbers(per_visit: pd.DataFrame) -> pd.Series:
    """Each row's session number: the participant's n-th measured visit (by visit number), from 1."""
    ranks = per_visit.groupby("participant_code")["visit_number"].rank(method="dense")
    return ranks.astype(int)


def visit_models(per_visit: pd.DataFrame, metrics: Sequence[str], labels: dict[str, str],
                 confidence: float = 0.95) -> list[ModelFit]:
    """Per metric, the mixed model of the module docstring over the practice visits (not ``retention``)."""
    practice = per_visit[per_visit["role"] != "retention"]
    fits = []
    for m in metrics:
        frame = practice[np.isfinite(practice[m].to_numpy(float))]
        log_n = np.log(session_numbers(frame).to_numpy(float))
        on = (frame["haptic_mode"] == "on").to_numpy(float)
        exog = design(frame, {"const": 1.0, "log_session": log_n, "haptic_on": on, "log_session:haptic_on": log_n * on})
        fits.append(fit_mixed("learning over visits", m, labels.get(m, m), frame[m], exog, frame["participant_code"],
                              confidence))
    return fits


def _by_role(per_visit: pd.DataFrame, role: str) -> pd.DataFrame:
    """Each participant's value of the (first) visit of ``role``, per mode (empty when there is none)."""
    rows = per_visit[per_visit["role"] == role].sort_values("visit_number")
    return rows.drop_duplicates(["participant_code", "haptic_mode"]).set_index(["participant_code", "haptic_mode"])


def retention_table(per_visit: pd.DataFrame, metrics: Sequence[str]) -> pd.DataFrame:
    """:data:`RETENTION_COLUMNS`: a row per participant, mode, metric and retention visit (the baseline and post
    values with no retention visit: one row with the retention columns empty)."""
    base, post = _by_role(per_visit, "baseline"), _by_role(per_visit, "post")
    keeps = [(str(v), _by_role(per_visit[per_visit["visit"] == v], "retention"))
             for v in dict.fromkeys(per_visit.loc[per_visit["role"] == "retention", "visit"])] or [("", None)]
    keys = sorted(set(base.index) | set(post.index))
    rows = []
    for m in metrics:
        for key in keys:
            b = float(base[m].get(key, math.nan)) if m in base else math.nan
            p = float(post[m].get(key, math.nan)) if m in post else math.nan
            for visit, kept in keeps:
                r = float(kept[m].get(key, math.nan)) if kept is not None and m in kept else math.nan
                rows.append({"participant_code": key[0], "haptic_mode": key[1], "metric": m, "baseline": b,
                             "post": p, "retention": r, "retention_visit": visit, "gain_post_minus_baseline": p - b,
                             "kept_retention_minus_post": r - p})
    return pd.DataFrame(rows, columns=list(RETENTION_COLUMNS))


def retention_tests(table: pd.DataFrame) -> pd.DataFrame:
    """:data:`TEST_COLUMNS`: per metric, mode (and retention visit) the paired Wilcoxon tests of post against
    baseline and of retention against post (module docstring)."""
    rows = []
    for (metric, mode), g in table.groupby(["metric", "haptic_mode"], sort=False):
        first = g.drop_duplicates("participant_code")
        pairs = [("post − baseline", first["baseline"], first["post"])]
        for visit, kept in g.groupby("retention_visit", sort=False):
            if visit:
                pairs.append((f"{visit} − post", kept["post"], kept["retention"]))
        for comparison, before, after in pairs:
            res = paired_wilcoxon(before.to_numpy(float), after.to_numpy(float), metric=str(metric))
            rows.append({"metric": metric, "haptic_mode": mode, "comparison": comparison, "n_pairs": res.n_pairs,
                         "n_used": res.n_used, "statistic": res.statistic, "p_value": res.p_value,
                         "method": res.method, "median_difference": float(np.nanmedian(after - before))
                         if np.isfinite((after - before).to_numpy(float)).any() else math.nan, "note": res.note})
    return pd.DataFrame(rows, columns=list(TEST_COLUMNS))
