"""The between-group analyses (analysis.stats.groups), recomputed independently with statsmodels and scipy.

A trials table is made here with a known structure (two groups whose haptic effects differ, a third group of one
participant, a fourth of none); each number of :func:`analyse_groups` is then computed again from that table by
another route: the interaction by statsmodels' *formula* interface (``smf.mixedlm`` / ``smf.gee``, its own design
matrix from a formula, not our named columns), the group effects by ``scipy.stats.wilcoxon`` on the participants'
means and the between-group test by ``scipy.stats.mannwhitneyu``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import statsmodels.formula.api as smf
from scipy import stats as sps
from statsmodels.genmod import families
from statsmodels.genmod.cov_struct import Exchangeable

from analysis.stats.groups import analyse_groups
from protocol.metrics import METRICS

LEVELS = ["novice", "resident", "surgeon", "fellow"]
TARGETS = ["GENTLE", "FIRM"]


def _trials(seed: int = 5) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Trials of 8 novices (ON lowers RMSE by 0.5 N), 7 surgeons (by 0.1 N) and 1 resident; and their covariates."""
    rng = np.random.default_rng(seed)
    rows, cov = [], []
    people = [("novice", 8, -0.5), ("surgeon", 7, -0.1), ("resident", 1, -0.3)]
    k = 0
    for group, n, effect in people:
        for _ in range(n):
            k += 1
            code = f"P{k:02d}"
            cov.append({"participant_code": code, "group": group})
            base, own = rng.normal(1.2, 0.15), rng.normal(0.0, 0.08)
            for i in range(16):
                mode = "on" if i % 2 else "off"
                target = TARGETS[(i // 2) % 2]
                on = mode == "on"
                rmse = base + (effect + own) * on + 0.1 * (target == "FIRM") + rng.normal(0, 0.12)
                p = 0.25 + (0.3 if group == "novice" else 0.1) * on
                rows.append({"participant_code": code, "haptic_mode": mode, "target_label": target,
                             "target_force_n": 0.6 if target == "GENTLE" else 1.2, "trial_index": i,
                             "rmse_n": rmse, "success": bool(rng.random() < p)})
    return pd.DataFrame(rows), pd.DataFrame(cov)


def _means(trials: pd.DataFrame, column: str) -> pd.DataFrame:
    return trials.groupby(["participant_code", "haptic_mode"])[column].mean().unstack()


@pytest.fixture(scope="module")
def analysed() -> tuple[pd.DataFrame, pd.DataFrame, object]:
    trials, cov = _trials()
    from analysis.stats.aggregate import per_participant

    overall = per_participant(trials)
    return trials, cov, analyse_groups(trials, overall, cov, "group", LEVELS, TARGETS)


def test_groups_counted_and_small_ones_not_tested(analysed) -> None:
    _, _, g = analysed
    counts = g.counts.set_index("group")
    assert counts["n_participants"].to_dict() == {"novice": 8, "resident": 1, "surgeon": 7, "fellow": 0}
    assert g.tested == ["novice", "surgeon"]  # the reference (first declared, tested) first
    assert "not tested: 1 participant" in counts.loc["resident", "note"]
    resident = g.effects[g.effects["group"] == "resident"]
    assert len(resident) and not resident["computable"].any() and resident["p_value"].isna().all()
    assert set(g.between["group"]) == {"surgeon"} and set(g.between["reference"]) == {"novice"}


def test_each_group_effect_is_scipy_wilcoxon_of_the_means(analysed) -> None:
    trials, cov, g = analysed
    group = cov.set_index("participant_code")["group"]
    for level in ("novice", "surgeon"):
        for column, metric in (("rmse_n", "rmse_n"), ("success", "success_rate")):
            means = _means(trials.assign(success=trials["success"].astype(float)), column)
            mine = means[means.index.map(group) == level]
            expected = sps.wilcoxon(mine["on"], mine["off"]).pvalue
            row = g.effects[(g.effects["group"] == level) & (g.effects["metric"] == metric)].iloc[0]
            assert row["n_participants"] == len(mine)
            # the same test on the same means: equal to float rounding (our differences are rounded to 1e-10)
            assert row["p_value"] == pytest.approx(expected, rel=1e-9)


def test_interaction_is_statsmodels_formula_mixedlm(analysed) -> None:
    trials, cov, g = analysed
    t = trials.merge(cov, on="participant_code")
    t = t[t["group"].isin(["novice", "surgeon"])].assign(on=lambda d: (d["haptic_mode"] == "on").astype(float))
    fit = smf.mixedlm("rmse_n ~ on * C(group, Treatment('novice')) + C(target_label, Treatment('GENTLE'))", t,
                      groups=t["participant_code"], re_formula="~on").fit(reml=True, method=["powell", "lbfgs"])
    term = "on:C(group, Treatment('novice'))[T.surgeon]"
    row = g.interaction[(g.interaction["outcome"] == "RMSE (N)")
                        & (g.interaction["term"] == "haptics_on_x_group_surgeon")].iloc[0]
    assert row["n_participants"] == 15 and row["n_obs"] == len(t)
    assert "MixedLM" in row["method"] and "haptics_on × group" in row["formula"]
    # the same REML problem by the same optimisers from another design matrix: equal to the optimiser's tolerance
    assert row["estimate"] == pytest.approx(fit.fe_params[term], abs=1e-4)
    assert row["std_error"] == pytest.approx(fit.bse_fe[term], rel=1e-2)
    assert row["estimate"] == pytest.approx(0.4, abs=0.15)  # the effect made: −0.1 − (−0.5)


def test_success_interaction_is_statsmodels_formula_gee(analysed) -> None:
    trials, cov, g = analysed
    t = trials.merge(cov, on="participant_code")
    t = t[t["group"].isin(["novice", "surgeon"])].assign(on=lambda d: (d["haptic_mode"] == "on").astype(float),
                                                         y=lambda d: d["success"].astype(float))
    fit = smf.gee("y ~ on * C(group, Treatment('novice')) + C(target_label, Treatment('GENTLE'))",
                  "participant_code", t, family=families.Binomial(), cov_struct=Exchangeable()
                  ).fit(cov_type="bias_reduced")
    term = "on:C(group, Treatment('novice'))[T.surgeon]"
    row = g.interaction[(g.interaction["outcome"] == "success")
                        & (g.interaction["term"] == "haptics_on_x_group_surgeon")].iloc[0]
    assert row["scale"] == "log-odds" and "GEE" in row["method"]
    # GEE's iterations from the same start: equal to its convergence tolerance
    assert row["estimate"] == pytest.approx(fit.params[term], abs=1e-5)
    assert row["p_value"] == pytest.approx(fit.pvalues[term], abs=1e-5)


def test_between_groups_is_scipy_mannwhitneyu(analysed) -> None:
    trials, cov, g = analysed
    group = cov.set_index("participant_code")["group"]
    means = _means(trials, "rmse_n")
    diff = means["on"] - means["off"]
    sur, nov = diff[diff.index.map(group) == "surgeon"], diff[diff.index.map(group) == "novice"]
    expected = sps.mannwhitneyu(sur, nov, alternative="two-sided", method="exact")
    row = g.between[g.between["metric"] == "rmse_n"].iloc[0]
    assert (row["n_group"], row["n_reference"]) == (7, 8) and row["method"] == "exact"
    assert row["u_statistic"] == expected.statistic
    assert row["p_value"] == pytest.approx(expected.pvalue, rel=1e-12)
    assert row["rank_biserial"] == pytest.approx(2 * expected.statistic / 56 - 1, rel=1e-12)
    assert row["median_effect_group"] == pytest.approx(float(np.median(sur)), rel=1e-12)


def test_one_group_only_fits_nothing() -> None:
    trials, cov = _trials()
    from analysis.stats.aggregate import per_participant

    cov = cov.assign(group="novice")
    g = analyse_groups(trials, per_participant(trials), cov, "group", LEVELS, TARGETS)
    assert g.tested == ["novice"]
    assert g.interaction["note"].iloc[0].startswith("not fitted: 1 group")
    assert not g.between["computable"].any() and g.between["note"].iloc[0].startswith("not tested")


def test_the_metrics_used_are_the_registry_ones() -> None:
    """(the synthetic table has two of the registry's measures: the analysis tests those it has)"""
    assert {"rmse_n", "success"} <= {m.name for m in METRICS}
