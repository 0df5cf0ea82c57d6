"""Learning over visits and retention (analysis/stats/visit_learning.py), recomputed independently: the mixed model
with statsmodels' formula interface, the paired tests with scipy, on a small synthetic table."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
import statsmodels.formula.api as smf
from scipy import stats

from analysis.stats.aggregate import METRIC_LABELS
from analysis.stats.models import fixed_effects
from analysis.stats.visit_learning import retention_table, retention_tests, session_numbers, visit_models

VISITS = [("baseline", 1, 0, "baseline"), ("t1", 2, 1, "training"), ("t2", 3, 2, "training"),
          ("post", 4, 3, "post"), ("keep", 5, 10, "retention")]


def _table(n: int = 8, seed: int = 1) -> pd.DataFrame:
    """RMSE falling as a power of the session, faster with haptics OFF, some forgetting at retention; noise."""
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(n):
        level = rng.normal(1.0, 0.15)
        for name, number, day, role in VISITS:
            for mode in ("off", "on"):
                base = level * (1.3 if mode == "off" else 0.7)
                k = number if role != "retention" else 3.4  # forgot some of the practice
                value = base * k ** (-0.25 if mode == "off" else -0.1) + rng.normal(0, 0.04)
                rows.append({"participant_code": f"P{i + 1:02d}", "visit": name, "visit_number": number, "day": day,
                             "role": role, "haptic_mode": mode, "n_trials": 12, "rmse_n": value})
    return pd.DataFrame(rows)


def test_the_mixed_model_is_statsmodels_own() -> None:
    table = _table()
    fit = visit_models(table, ["rmse_n"], METRIC_LABELS)[0]
    assert fit.fitted and fit.n_participants == 8 and fit.n_obs == 8 * 4 * 2  # retention left out
    practice = table[table["role"] != "retention"].copy()
    practice["log_session"] = np.log(practice["visit_number"].astype(float))  # every participant has every visit
    practice["on"] = (practice["haptic_mode"] == "on").astype(float)
    ref = smf.mixedlm("rmse_n ~ log_session * on", practice, groups=practice["participant_code"]).fit(
        reml=True, method=["powell", "lbfgs"])
    names = {"const": "Intercept", "log_session": "log_session", "haptic_on": "on",
             "log_session:haptic_on": "log_session:on"}
    for term, other in names.items():
        # two optimiser runs of the same likelihood agree to the optimiser's tolerance, not bit for bit
        assert fit.params[term] == pytest.approx(ref.fe_params[other], abs=1e-4)
        assert fit.std_errors[term] == pytest.approx(ref.bse_fe[other], rel=1e-3)
    assert fit.params["log_session"] < 0 < fit.params["log_session:haptic_on"]  # OFF learns faster, as built
    rows = fixed_effects([fit])
    assert "MixedLM" in rows["method"].iloc[0] and (rows["n_participants"] == 8).all()


def test_session_numbers_count_each_participants_measured_visits() -> None:
    table = _table(3)
    table = table[~((table["participant_code"] == "P02") & (table["visit"] == "t1"))]  # P02 missed a visit
    numbers = session_numbers(table)
    p2 = table.assign(s=numbers)[table["participant_code"] == "P02"].drop_duplicates("visit")
    assert p2["s"].tolist() == [1, 2, 3, 4]


def test_gain_and_retention_and_their_wilcoxon_tests_are_scipys() -> None:
    table = _table()
    kept = retention_table(table, ["rmse_n"])
    assert len(kept) == 8 * 2 and set(kept["retention_visit"]) == {"keep"}
    for mode in ("off", "on"):
        mine = kept[kept["haptic_mode"] == mode].sort_values("participant_code")
        wide = table[table["haptic_mode"] == mode].pivot(index="participant_code", columns="visit", values="rmse_n")
        np.testing.assert_allclose(mine["gain_post_minus_baseline"], (wide["post"] - wide["baseline"]).to_numpy(),
                                   rtol=0, atol=1e-12)  # a difference of two stored floats: exact but for rounding
        np.testing.assert_allclose(mine["kept_retention_minus_post"], (wide["keep"] - wide["post"]).to_numpy(),
                                   rtol=0, atol=1e-12)
        tests = retention_tests(kept)
        for comparison, d in (("post − baseline", wide["post"] - wide["baseline"]),
                              ("keep − post", wide["keep"] - wide["post"])):
            row = tests[(tests["haptic_mode"] == mode) & (tests["comparison"] == comparison)].iloc[0]
            ref = stats.wilcoxon(d.to_numpy())  # 8 distinct non-zero differences: scipy's exact test
            assert row["method"] == "exact" and int(row["n_pairs"]) == 8
            assert row["statistic"] == ref.statistic
            assert row["p_value"] == pytest.approx(ref.pvalue, rel=1e-12)
            assert row["median_difference"] == pytest.approx(float(np.median(d)), rel=1e-12)


def test_too_few_participants_are_said_not_fitted() -> None:
    fit = visit_models(_table(3), ["rmse_n"], METRIC_LABELS)[0]
    assert not fit.fitted and "not fitted: 3 participants" in fit.note
    no_keep = retention_table(_table(3)[lambda t: t["role"] != "retention"], ["rmse_n"])
    assert (no_keep["retention_visit"] == "").all() and no_keep["retention"].isna().all()
    assert math.isnan(float(no_keep["kept_retention_minus_post"].iloc[0]))
