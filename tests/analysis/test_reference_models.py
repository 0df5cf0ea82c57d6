"""The report's models and effect-size intervals refitted from its own CSVs with the reference libraries (issue 41, 5).

* the logistic GEE of success: statsmodels' formula GEE, exchangeable, Mancl–DeRouen's bias-reduced sandwich
  (``cov_type="bias_reduced"``), from trials.csv -- and its standard errors are larger than the plain sandwich's;
* the linear mixed model of RMSE with a random slope of haptic mode: statsmodels' formula MixedLM
  (``re_formula="~haptics_on"``, REML, the same optimisers), from trials.csv;
* the rank-biserial correlation's interval: :func:`scipy.stats.bootstrap` (BCa, the report's seed and resamples) of
  the differences participants_wide.csv gives, with r written out from ranks;
* participants_wide.csv's differences are the report's rounded ones: SciPy's Wilcoxon of them gives stats.csv's p.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats as sps
from studybuilder import SessionDef, TrialDef, build, success_trial, timeout_trial

from analysis.stats.effect_interval import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED
from study_app.cli.main import main

smf = pytest.importorskip("statsmodels.formula.api")


def _session(i: int) -> SessionDef:
    """Successes and failures in every cell of mode × target across participants (no separation for the GEE)."""
    cells = [("GENTLE", "on", 2, int(i % 3 == 0)), ("FIRM", "on", 2, i % 2), ("GENTLE", "off", 1 + i % 2, 1),
             ("FIRM", "off", int(i % 3 == 1), 2)]
    trials: list[TrialDef] = []
    for k, (label, mode, ok, failed) in enumerate(cells):
        trials += [success_trial(label, mode, 100 + 37 * i + 90 * j + (400 if mode == "off" else 0))
                   for j in range(ok)]
        trials += [timeout_trial(label, mode, 0.3 if label == "GENTLE" else 1.9 - 0.02 * k) for _ in range(failed)]
    return SessionDef(f"P{i:02d}", trials[::2] + trials[1::2], max_trial_s=4.0)  # modes and targets interleaved


@pytest.fixture(scope="module")
def out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("ref")
    db = build(d / "ref.db", [_session(i) for i in range(1, 9)])
    assert main(["report", "--db", str(db), "--out", str(d / "rep")]) == 0
    return d / "rep"


def _frame(out: Path) -> pd.DataFrame:
    t = pd.read_csv(out / "trials.csv")
    return t.assign(haptics_on=(t["haptic_mode"] == "on").astype(float),
                    target_FIRM=(t["target_label"] == "FIRM").astype(float), y=t["success"].astype(float))


def _model(out: Path, outcome: str) -> pd.DataFrame:
    m = pd.read_csv(out / "learning_models.csv")
    return m[m["outcome"] == outcome].set_index("term")


_FORMULA = "haptics_on + target_FIRM + haptics_on:target_FIRM + trial_number"
_TERMS = {"intercept": "Intercept", "haptics_on": "haptics_on", "target_FIRM": "target_FIRM",
          "haptics_on_x_target_FIRM": "haptics_on:target_FIRM", "trial_number": "trial_number"}


def test_gee_is_statsmodels_with_mancl_derouen_errors(out: Path) -> None:
    import statsmodels.api as sm

    t = _frame(out)
    model = smf.gee(f"y ~ {_FORMULA}", "participant_code", t, family=sm.families.Binomial(),
                    cov_struct=sm.cov_struct.Exchangeable())
    ref, plain = model.fit(cov_type="bias_reduced"), model.fit()
    mine = _model(out, "success")
    assert "Mancl" in str(mine["method"].iloc[0])
    for term, name in _TERMS.items():
        assert mine.loc[term, "estimate"] == pytest.approx(ref.params[name], rel=1e-4, abs=1e-6)
        assert mine.loc[term, "std_error"] == pytest.approx(ref.bse[name], rel=1e-4, abs=1e-6)
    assert (ref.bse > plain.bse).all()  # the small-sample correction grows every error


def test_mixed_model_has_statsmodels_random_slope_of_mode(out: Path) -> None:
    t = _frame(out)
    mine = _model(out, "RMSE (N)")
    note = str(mine["note"].iloc[0]) if mine["note"].notna().any() else ""
    slope = "random slope of haptic mode could not be fitted" not in note
    assert ("random slope of haptic mode" in str(mine["method"].iloc[0])) == slope
    ref = smf.mixedlm(f"rmse_N ~ {_FORMULA}", t, groups=t["participant_code"],
                      re_formula="~haptics_on" if slope else None).fit(reml=True, method=["powell", "lbfgs"])
    for term, name in _TERMS.items():
        assert mine.loc[term, "estimate"] == pytest.approx(ref.fe_params[name], rel=1e-3, abs=1e-5)


def _rank_biserial(d: np.ndarray, axis: int = -1) -> np.ndarray:
    """(W⁺ − W⁻)/(W⁺ + W⁻), zeros dropped (Wilcoxon's zero method), written out from SciPy's ranks."""
    d = np.moveaxis(d, axis, -1)
    ranks = sps.rankdata(np.where(d == 0, np.nan, np.abs(d)), axis=-1, nan_policy="omit")
    ranks = np.where(d == 0, 0.0, ranks)
    w_plus, w_minus = (ranks * (d > 0)).sum(-1), (ranks * (d < 0)).sum(-1)
    return (w_plus - w_minus) / (w_plus + w_minus)


def test_rank_biserial_interval_and_wide_differences_equal_scipy(out: Path) -> None:
    stats = pd.read_csv(out / "stats.csv").set_index("metric")
    wide = pd.read_csv(out / "participants_wide.csv")
    for metric, diff in (("success_rate", "success_rate_diff"), ("rmse_N", "rmse_diff_N")):
        d = wide[diff].dropna().to_numpy(float)
        row = stats.loc[metric]
        assert row["p_value"] == pytest.approx(sps.wilcoxon(d).pvalue, rel=5e-4)
        assert row["rank_biserial"] == pytest.approx(float(_rank_biserial(d)), abs=0.5e-3)
        if np.all(np.sign(d[d != 0]) == np.sign(d[d != 0][0])):
            continue  # every difference of one sign: r = ±1 on every resample, no BCa (the report says percentile)
        res = sps.bootstrap((d,), _rank_biserial, n_resamples=BOOTSTRAP_RESAMPLES, method="BCa",
                            rng=np.random.default_rng(BOOTSTRAP_SEED), vectorized=True)
        assert row["rank_biserial_ci_low"] == pytest.approx(res.confidence_interval.low, abs=0.5e-3)
        assert row["rank_biserial_ci_high"] == pytest.approx(res.confidence_interval.high, abs=0.5e-3)
