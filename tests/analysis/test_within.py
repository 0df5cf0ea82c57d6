"""Within-participant statistics: the repeated-measures correlation and the report's models, checked independently.

* rmcorr against the rmcorr R package's own example (Bland & Altman 1995, ``bland1995``: the r, df and p its
  README prints; the interval is pingouin's, not the R package's wider one: see analysis/stats/rmcorr.py), against
  pingouin's ``rm_corr`` down to df = 2, against the ANCOVA fitted by statsmodels' OLS, and on synthetic data whose
  within-participant slope is known (and whose pooled correlation has the opposite sign);
* the trade's mixed model and the learning models against statsmodels called directly, from a formula.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis.stats.learning import learning_models, order_check
from analysis.stats.models import MIN_PARTICIPANTS, MIXED_METHODS
from analysis.stats.rmcorr import rmcorr
from analysis.stats.trade import speed_accuracy, trade_model

# Bland & Altman (1995), BMJ 310:446, Table 1: intramural pH and PaCO2 of eight subjects (the rmcorr package's
# bland1995).  rmcorr(Subject, PacO2, pH, bland1995) prints r = -0.5067697, df = 38, p = 0.0008471081,
# 95 % CI -0.7112297 -0.223255.
BLAND_SUBJECT = [1] * 4 + [2] * 4 + [3] * 9 + [4] * 5 + [5] * 8 + [6] * 6 + [7] * 3 + [8] * 8
BLAND_PH = [6.68, 6.53, 6.43, 6.33, 6.85, 7.06, 7.13, 7.17, 7.40, 7.42, 7.41, 7.37, 7.34, 7.35, 7.28, 7.30, 7.34,
            7.36, 7.33, 7.29, 7.30, 7.35, 7.35, 7.30, 7.30, 7.37, 7.27, 7.28, 7.32, 7.32, 7.38, 7.30, 7.29, 7.33,
            7.31, 7.33, 6.86, 6.94, 6.92, 7.19, 7.29, 7.21, 7.25, 7.20, 7.19, 6.77, 6.82]
BLAND_PACO2 = [3.97, 4.12, 4.09, 3.97, 5.27, 5.37, 5.41, 5.44, 5.67, 3.64, 4.32, 4.73, 4.96, 5.04, 5.22, 4.82,
               5.07, 5.67, 5.10, 5.53, 4.75, 5.51, 4.28, 4.44, 4.32, 3.23, 4.46, 4.72, 4.75, 4.99, 4.78, 4.73,
               5.12, 4.93, 5.03, 4.93, 6.85, 6.44, 6.52, 5.28, 4.56, 4.34, 4.32, 4.41, 3.69, 6.09, 5.58]


def test_rmcorr_reproduces_the_r_packages_published_example():
    res = rmcorr(BLAND_SUBJECT, BLAND_PACO2, BLAND_PH)
    assert res.computable and (res.n_obs, res.n_participants, res.df) == (47, 8, 38)
    # the R package's values as it prints them: to their last printed digit (rounding, not equality, at that digit)
    assert res.r == pytest.approx(-0.5067697, abs=5e-8)
    assert res.p_value == pytest.approx(0.0008471081, abs=5e-11)
    # the interval: pingouin's (rm_corr prints [-0.71, -0.23]; its compute_esci at n = df + 2 to 12 decimals), not
    # the R package's (-0.7112297, -0.223255), whose SE 1/sqrt(df - 3) takes df for the number of observations
    assert (res.ci_low, res.ci_high) == pytest.approx((-0.706714636386, -0.231863119757), abs=5e-13)


@pytest.mark.parametrize(("k", "m", "seed"), [(3, 2, 0), (3, 2, 1), (3, 3, 2), (4, 2, 3), (3, 4, 4), (5, 3, 5),
                                              (8, 6, 6), (10, 10, 7)])
@pytest.mark.filterwarnings("ignore:Sample size is too small to estimate power:UserWarning")  # its power column
def test_rmcorr_equals_pingouin_down_to_two_degrees_of_freedom(k: int, m: int, seed: int):
    """r, df, p and the interval of pingouin's rm_corr (at least 3 participants, as it requires), df from 2: the
    interval to pingouin's printed 2 decimals and, at full precision, to its Fisher interval at n = df + 2 (what
    rm_corr rounds)."""
    pg = pytest.importorskip("pingouin")
    rng = np.random.default_rng(seed)
    who = np.repeat(np.arange(k), m)
    x = rng.normal(0, 1, k * m) + 3 * who
    y = 0.6 * x + rng.normal(0, 1, k * m) - 2 * who
    res = rmcorr(who, x, y)
    ref = pg.rm_corr(pd.DataFrame({"s": who, "x": x, "y": y}), x="x", y="y", subject="s")
    assert res.df == int(ref["dof"].iloc[0]) == k * m - k - 1 >= 2
    assert res.r == pytest.approx(float(ref["r"].iloc[0]), rel=1e-9)  # summation order only
    assert res.p_value == pytest.approx(float(ref["pval"].iloc[0]), rel=1e-7)  # t against F: their tails' digits
    lo, hi = ref["CI95"].iloc[0]
    assert abs(res.ci_low - lo) <= 0.005 + 1e-12 and abs(res.ci_high - hi) <= 0.005 + 1e-12  # printed to 2 decimals
    full = pg.compute_esci(stat=res.r, nx=res.df + 2, eftype="pearson", decimals=14)
    assert (res.ci_low, res.ci_high) == pytest.approx((float(full[0]), float(full[1])), abs=1e-12)


def test_rmcorr_has_no_interval_below_two_degrees_of_freedom():
    """df = 1 (two participants with two trials, or one with three): r and p, but no interval to print."""
    res = rmcorr([1, 1, 1], [0.0, 1.0, 2.0], [0.1, 0.9, 2.3])
    assert res.computable and res.df == 1 and math.isnan(res.ci_low) and math.isnan(res.ci_high)
    assert "df = 1: no interval (needs df ≥ 2)" in res.note


def test_rmcorr_equals_the_ancova_fitted_by_statsmodels():
    """r_rm = sign(b)·√(SS_x / (SS_x + SS_res)) of lm(y ~ participant + x), with the slope's p-value."""
    from statsmodels.regression.linear_model import OLS

    who = np.asarray(BLAND_SUBJECT)
    dummies = (who[:, None] == np.unique(who)[None, :]).astype(float)
    x, y = np.asarray(BLAND_PACO2), np.asarray(BLAND_PH)
    full = OLS(y, np.column_stack([dummies, x])).fit()
    without_x = OLS(y, dummies).fit()
    ss_x = without_x.ssr - full.ssr
    expected = math.copysign(math.sqrt(ss_x / (ss_x + full.ssr)), full.params[-1])
    res = rmcorr(who, x, y)
    assert res.r == pytest.approx(expected, rel=1e-12)
    assert res.p_value == pytest.approx(float(full.pvalues[-1]), rel=1e-9)
    assert res.df == int(full.df_resid)
    assert (res.slope, res.slope_se) == pytest.approx((float(full.params[-1]), float(full.bse[-1])), rel=1e-9)


def test_rmcorr_finds_a_known_within_participant_slope_that_pooling_reverses():
    rng = np.random.default_rng(3)
    k, m, beta = 12, 15, -2.0
    who = np.repeat(np.arange(k), m)
    level = np.repeat(np.arange(k) * 3.0, m)  # people with higher x also have much higher y: pooled r > 0
    x = level + rng.normal(0, 1, k * m)
    y = 10 * level + beta * (x - level) + rng.normal(0, 0.5, k * m)
    assert np.corrcoef(x, y)[0, 1] > 0.9
    res = rmcorr(who, x, y)
    assert res.r < -0.9 and res.df == k * m - k - 1
    assert res.slope == pytest.approx(beta, abs=4 * res.slope_se)
    exact = rmcorr(who, x, 10 * level + beta * (x - level))  # no noise: the slope exactly, a perfect r_rm
    # a perfect line: r_rm is -1 up to the last bit of the BLAS dot products that form it (one ulp differs between
    # kernels, e.g. AVX-512 against Haswell); the product snaps it to exactly -1 with p 0 (UNIT_R_TOLERANCE) so it
    # reads the same on every CPU -- that rounding is what is asserted exactly here, the slope within 1e-12
    assert exact.slope == pytest.approx(beta, rel=1e-12) and exact.r == -1.0 and exact.p_value == 0.0
    assert (exact.ci_low, exact.ci_high) == (-1.0, -1.0)


def test_rmcorr_says_why_it_cannot_correlate():
    assert "degrees of freedom" in rmcorr([1, 2, 3], [1.0, 2.0, 3.0], [3.0, 1.0, 2.0]).note  # one trial each
    flat = rmcorr([1, 1, 2, 2], [0.1, 0.1, 0.3, 0.3], [1.0, 2.0, 3.0, 4.0])
    assert not flat.computable and "x does not vary within any participant" in flat.note
    some = rmcorr([1, 1, 1, 2, 2, 2, 3], [1, 2, 3, 1, 2, math.nan, 5], [2, 3, 5, 1, 1, 2, 4])
    assert some.computable and some.n_obs == 5 and "1 observations with a NaN" in some.note
    assert "1 participant with a single observation" in some.note


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 4), st.floats(-1e6, 1e6), st.floats(-1e6, 1e6)), min_size=0, max_size=40))
def test_rmcorr_is_bounded_and_never_crashes(rows):
    who = [r[0] for r in rows]
    res = rmcorr(who, [r[1] for r in rows], [r[2] for r in rows])
    if res.computable:
        assert -1.0 <= res.r <= 1.0 and 0.0 <= res.p_value <= 1.0 and res.df >= 1
    else:
        assert math.isnan(res.r) and res.note


def test_rmcorr_of_tiny_values_does_not_underflow():
    """Found by the property above: x near 1e-133 and y near 1e-38 have sums of squares whose product underflows
    to 0 (a division by zero) although each is a positive number."""
    res = rmcorr([0, 0, 0], [0.0, 0.0, 6.18408633407145e-133], [0.0, 7.101361545095521e-38, 0.0])
    assert res.computable and -1.0 <= res.r <= 1.0 and 0.0 <= res.p_value <= 1.0


def _trials(n_participants: int, seed: int = 0) -> pd.DataFrame:
    """A synthetic trial table: 2 modes × 2 targets × 5 trials per participant, a random intercept per person."""
    rng = np.random.default_rng(seed)
    rows = []
    for p in range(n_participants):
        person = rng.normal(0, 0.8)
        for i in range(20):
            mode, target = ("on", "off")[i % 2], ("GENTLE", "FIRM")[(i // 2) % 2]
            rmse = abs(rng.normal(0.8 if mode == "off" else 0.55, 0.2))
            tct = 7 + person - 1.5 * rmse - 0.05 * i + rng.normal(0, 0.7)
            success = rng.random() < (0.6 if mode == "on" else 0.3)
            reach = abs(rng.normal(0.15 if mode == "off" else 0.1, 0.05))  # the trade's phases: a real trade
            rise = 0.9 + 0.3 * person - 2.0 * reach + rng.normal(0, 0.1)
            rows.append({"participant_code": f"P{p:02d}", "trial_index": i, "haptic_mode": mode,
                         "target_label": target, "rmse_n": rmse, "max_ae_n": rmse * 2.2 + rng.normal(0, 0.1),
                         "tct_s": tct if success else math.nan, "tct_censored_s": tct if success else 12.0,
                         "success": success, "time_in_band_s": rng.uniform(0, 3), "peak_force_n": rmse + 1.0,
                         "rise_time_s": rise, "reach_rmse_n": reach})
    return pd.DataFrame(rows)


def test_the_trade_models_fixed_effects_equal_statsmodels_called_directly():
    import statsmodels.formula.api as smf

    trials = _trials(8)
    fit = trade_model(trials)  # rise time on RMSE after reach, a random intercept and slope of mode per participant
    data = trials.assign(on=(trials["haptic_mode"] == "on").astype(float))
    slope = "random slope of haptic mode" in fit.method
    direct = smf.mixedlm("rise_time_s ~ reach_rmse_n * on", data, groups=data["participant_code"],
                         re_formula="~on" if slope else None).fit(reml=True, method=MIXED_METHODS)
    names = {"intercept": "Intercept", "haptics_on": "on", "accuracy": "reach_rmse_n",
             "accuracy_x_on": "reach_rmse_n:on"}
    for ours, theirs in names.items():
        assert fit.params[ours] == pytest.approx(direct.fe_params[theirs], rel=1e-4, abs=1e-6)
        assert fit.std_errors[ours] == pytest.approx(direct.bse_fe[theirs], rel=1e-3)
    assert fit.n_obs == len(data) and fit.n_participants == 8


def test_the_learning_models_equal_statsmodels_called_directly():
    import statsmodels.formula.api as smf
    from statsmodels.genmod import families
    from statsmodels.genmod.cov_struct import Exchangeable

    trials = _trials(8, seed=1)
    fits = {f.outcome: f for f in learning_models(trials, ["GENTLE", "FIRM"])}
    data = trials.assign(on=(trials["haptic_mode"] == "on").astype(float),
                         firm=(trials["target_label"] == "FIRM").astype(float),
                         trial_number=trials["trial_index"] + 1.0, y=trials["success"].astype(float))
    slope = "random slope of haptic mode" in fits["RMSE (N)"].method  # else its note says why not
    rmse = smf.mixedlm("rmse_n ~ on * firm + trial_number", data, groups=data["participant_code"],
                       re_formula="~on" if slope else None).fit(reml=True, method=MIXED_METHODS)
    assert fits["RMSE (N)"].params["trial_number"] == pytest.approx(rmse.fe_params["trial_number"], rel=1e-6)
    assert fits["RMSE (N)"].params["haptics_on_x_target_FIRM"] == pytest.approx(rmse.fe_params["on:firm"], rel=1e-6)
    gee = smf.gee("y ~ on * firm + trial_number", "participant_code", data, family=families.Binomial(),
                  cov_struct=Exchangeable()).fit(cov_type="bias_reduced")  # Mancl–DeRouen
    assert fits["success"].params["trial_number"] == pytest.approx(gee.params["trial_number"], rel=1e-8)
    assert fits["success"].std_errors["haptics_on"] == pytest.approx(gee.bse["on"], rel=1e-8)


def test_the_trade_counts_only_the_participants_who_contribute():
    trials = _trials(8)
    p00_off = (trials["participant_code"] == "P00") & (trials["haptic_mode"] == "off")
    first = p00_off.idxmax()
    trials.loc[p00_off & (trials.index != first), "rise_time_s"] = math.nan  # P00: one OFF trial reached the band
    rows = speed_accuracy(trials).set_index("haptic_mode")
    assert rows.at["off", "n_participants"] == 7 and rows.at["on", "n_participants"] == 8
    assert rows.at["off", "df"] == rows.at["off", "n_trials"] - 7 - 1  # N − k − 1 over the 7 who contribute


def test_too_few_participants_is_a_plain_statement_not_a_fit():
    small = _trials(MIN_PARTICIPANTS - 1)
    fit = trade_model(small)
    assert not fit.fitted and f"{MIN_PARTICIPANTS - 1} participants" in fit.note
    assert all(not f.fitted for f in learning_models(small, ["GENTLE", "FIRM"]))
    assert speed_accuracy(small)["computable"].all()  # rmcorr needs no participant variance


def test_the_order_check_compares_on_first_with_off_first_participants():
    from analysis.stats.aggregate import per_participant

    per = per_participant(_trials(8, seed=2))
    first = pd.Series(["on", "off"] * 4, index=[f"P{p:02d}" for p in range(8)])
    order = order_check(per, first).set_index("metric")
    assert (order["n_on_first"] == 4).all() and order["computable"].all()
    lopsided = order_check(per, pd.Series(["on"] * 7 + ["off"], index=first.index))
    assert not lopsided["computable"].any() and "1 OFF-first" in lopsided["note"].iloc[0]
