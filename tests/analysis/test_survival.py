"""TCT as a time to event, recomputed with lifelines from the report's own CSVs (issue 41).

The report computes its Kaplan–Meier curves with :func:`scipy.stats.ecdf` and its Cox model with statsmodels'
PHReg (:mod:`analysis.stats.survival`); lifelines, the reference library a reviewer would reach for, refits both
from trials.csv here: every survival step and its log-log interval, and the hazard ratio ON : OFF of the model
stratified by participant with Efron's ties, its robust (clustered) standard error and interval.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from studybuilder import SessionDef, TrialDef, build, success_trial, timeout_trial

from study_app.cli.main import main

# Not in the test extra: lifelines 0.30 (the newest) declares pandas < 3, and pip would downgrade the product's
# pandas to install it.  Installed beside it by hand (pip install lifelines, then pandas again) it runs these
# refits under pandas 3; without it they are skipped.
lifelines = pytest.importorskip("lifelines")

#: The CSVs carry survival probabilities, hazard ratios and their bounds to 4 decimals and coefficients and standard
#: errors to 6 (codebook): each is compared within half a unit of its last written digit (and a hair for the two
#: optimisers' own tolerances), which is far finer than the 2-3 digits the page prints.
HALF_4, HALF_6 = 0.5e-4 + 1e-9, 0.5e-6 + 1e-9


def _session(i: int) -> SessionDef:
    """Each participant faster with feedback by a different amount, with failures in both modes (censored)."""
    trials: list[TrialDef] = []
    for k in range(3):
        trials += [success_trial("GENTLE", "on", 150 + 90 * k + 37 * i), success_trial("FIRM", "on", 400 + 70 * k),
                   success_trial("GENTLE", "off", 700 + 110 * k + 13 * i)]
    trials += [timeout_trial("FIRM", "off", 2.0), timeout_trial("GENTLE", "off", 0.2 + 0.01 * i),
               timeout_trial("FIRM", "on", 1.8) if i % 2 else success_trial("FIRM", "off", 1900 - 50 * i)]
    return SessionDef(f"P{i:02d}", trials, max_trial_s=4.0)


@pytest.fixture(scope="module")
def report_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("surv")
    db = build(d / "surv.db", [_session(i) for i in range(1, 7)])
    out = d / "rep"
    assert main(["report", "--db", str(db), "--out", str(out)]) == 0
    return out


def _trials(out: Path) -> pd.DataFrame:
    t = pd.read_csv(out / "trials.csv")
    return t.assign(on=(t["haptic_mode"] == "on").astype(float), event=t["success"].astype(bool))


def test_kaplan_meier_equals_lifelines(report_dir: Path) -> None:
    trials, km = _trials(report_dir), pd.read_csv(report_dir / "kaplan_meier.csv")
    for mode in ("off", "on"):
        sel = trials[trials["haptic_mode"] == mode]
        ref = lifelines.KaplanMeierFitter().fit(sel["tct_censored_s"], sel["event"], alpha=0.05)
        mine = km[(km["haptic_mode"] == mode) & (km["time_s"] > 0)]
        assert len(mine) == int(sel.loc[sel["event"], "tct_censored_s"].nunique())  # a step per time of a success
        at = ref.survival_function_at_times(mine["time_s"]).to_numpy()
        assert mine["survival"].to_numpy() == pytest.approx(at, abs=HALF_4)
        ci = ref.confidence_interval_survival_function_.loc[mine["time_s"]]
        finite = np.isfinite(mine["ci_low"].to_numpy())
        assert mine["ci_low"].to_numpy()[finite] == pytest.approx(ci.iloc[:, 0].to_numpy()[finite], abs=HALF_4)
        assert mine["ci_high"].to_numpy()[finite] == pytest.approx(ci.iloc[:, 1].to_numpy()[finite], abs=HALF_4)
        # the median time to success the page prints
        tte = pd.read_csv(report_dir / "time_to_event.csv").set_index("haptic_mode")
        assert tte.loc[mode, "km_median_s"] == pytest.approx(ref.median_survival_time_, abs=1e-9)
        assert tte.loc[mode, "restricted_mean_s"] == pytest.approx(sel["tct_censored_s"].mean(), abs=0.5e-3)
        assert tte.loc[mode, "n_successes"] == int(sel["event"].sum())


def test_cox_hazard_ratio_equals_lifelines_stratified_and_clustered(report_dir: Path) -> None:
    trials = _trials(report_dir)
    firm = (trials["target_label"] == "FIRM").astype(float)
    frame = pd.DataFrame({"time": trials["tct_censored_s"], "event": trials["event"].astype(int),
                          "haptics_on": trials["on"], "target_FIRM": firm,
                          "participant": trials["participant_code"], "cluster": trials["participant_code"]})
    ref = lifelines.CoxPHFitter().fit(frame, "time", "event", strata=["participant"], cluster_col="cluster",
                                      robust=True)
    cox = pd.read_csv(report_dir / "survival_model.csv").set_index("term")
    for term in ("haptics_on", "target_FIRM"):
        assert cox.loc[term, "coef"] == pytest.approx(ref.params_[term], abs=HALF_6)
        assert cox.loc[term, "hazard_ratio"] == pytest.approx(np.exp(ref.params_[term]), abs=HALF_4)
    # lifelines' sandwich is Lin & Wei's over the participant clusters; PHReg's the same score residuals:
    # equal up to the optimisers' tolerance
    se = ref.standard_errors_["haptics_on"]
    assert cox.loc["haptics_on", "std_error"] == pytest.approx(se, abs=HALF_6)
    lo, hi = np.exp(ref.confidence_intervals_.loc["haptics_on"].to_numpy())
    assert (cox.loc["haptics_on", "ci_low"], cox.loc["haptics_on", "ci_high"]) == pytest.approx((lo, hi), abs=HALF_4)
    assert cox.loc["haptics_on", "p_value"] == pytest.approx(ref.summary.loc["haptics_on", "p"], rel=5e-4)
    assert int(cox.loc["haptics_on", "n_events"]) == int(frame["event"].sum())
    # the model-based (not clustered) error too
    plain = lifelines.CoxPHFitter().fit(frame.drop(columns="cluster"), "time", "event", strata=["participant"])
    assert cox.loc["haptics_on", "model_std_error"] == pytest.approx(plain.standard_errors_["haptics_on"], abs=HALF_6)
    # what the page prints: the hazard ratio and its interval to 2 decimals
    page = (report_dir / "report.html").read_text(encoding="utf-8")
    hr = cox.loc["haptics_on"]
    shown = f"{hr['hazard_ratio']:.2f} [{hr['ci_low']:.2f}, {hr['ci_high']:.2f}]"
    assert f"Hazard ratio, haptics ON : OFF = {shown}" in page
