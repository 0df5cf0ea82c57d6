"""Per-participant aggregation, ON-vs-OFF tests and the speed–accuracy trade."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
import scipy.stats
from studybuilder import SessionDef, build, success_trial, timeout_trial

from analysis.reading.load import load_study
from analysis.reading.metrics import MetricOptions, compute_trials
from analysis.stats.aggregate import PRIMARY_METRICS, TESTED_METRICS, mode_tests, per_participant
from analysis.stats.trade import READINGS, speed_accuracy

#: TCT over successful trials (the paper's text); the report's default counts a failure at the cap (the figure's)
SUCCESSFUL = MetricOptions(tct_policy="successful")


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    # P01: ON 2/2 successes (TCT 1.2, 1.4); OFF 1/2 (TCT 2.0) — and so on, by hand below
    def p(code, on_ms, off_ms, off_timeouts):
        trials = [success_trial("GENTLE", "on", on_ms[0]), success_trial("FIRM", "on", on_ms[1])]
        trials += [success_trial("GENTLE", "off", m) for m in off_ms]
        trials += [timeout_trial("FIRM", "off", 2.0) for _ in range(off_timeouts)]
        return SessionDef(code, trials, max_trial_s=4.0)  # 4 s cap: fewer samples to write

    sessions = [p("P01", (200, 400), [1000], 1), p("P02", (0, 100), [300], 1), p("P03", (500, 500), [], 2),
                p("P04", (100, 700), [200, 600], 0), p("P05", (300, 0), [900], 1), p("P06", (600, 200), [100], 1)]
    db = build(tmp_path_factory.mktemp("agg") / "agg.db", sessions)
    return compute_trials(load_study([db]), workers=1).trials


def test_per_participant_means_by_hand(study):
    pp = per_participant(study, SUCCESSFUL).set_index(["participant_code", "haptic_mode"])
    assert pp.loc[("P01", "on"), ["n_trials", "n_success", "success_rate"]].tolist() == [2, 2, 1.0]
    assert pp.at[("P01", "on"), "tct_s"] == pytest.approx((1.2 + 1.4) / 2, rel=1e-15)
    assert pp.at[("P01", "off"), "success_rate"] == 0.5
    assert pp.at[("P01", "off"), "tct_s"] == 2.0 and pp.at[("P01", "off"), "n_tct"] == 1
    # P03 never succeeded with haptics OFF: TCT over successful trials is undefined
    assert pp.at[("P03", "off"), "success_rate"] == 0.0 and math.isnan(pp.at[("P03", "off"), "tct_s"])
    assert pp.at[("P03", "off"), "n_tct"] == 0


def test_censored_tct_counts_failures_at_the_cap(study):
    pp = per_participant(study, MetricOptions(tct_policy="censored")).set_index(["participant_code", "haptic_mode"])
    assert pp.at[("P01", "off"), "tct_s"] == pytest.approx((2.0 + 4.0) / 2, rel=1e-15)
    assert pp.at[("P03", "off"), "tct_s"] == 4.0 and pp.at[("P03", "off"), "n_tct"] == 2


def test_by_target_split(study):
    pp = per_participant(study, SUCCESSFUL, by_target=True)
    pp = pp.set_index(["participant_code", "haptic_mode", "target_label"])
    assert pp.at[("P04", "off", "GENTLE"), "tct_s"] == pytest.approx((1.2 + 1.6) / 2, rel=1e-15)
    assert ("P04", "off", "FIRM") not in pp.index  # P04 had no FIRM trial with haptics OFF


def test_mode_tests_equal_scipy_on_the_participant_differences(study):
    pp = per_participant(study, SUCCESSFUL)
    results, frame = mode_tests(pp)
    # the measures the table has (the paper's task's: not force tracking's lag and gain) that the report tests
    paper = [m for m in TESTED_METRICS if m in pp.columns]
    assert list(frame["metric"]) == paper and paper[:4] == list(PRIMARY_METRICS)
    wide = pp.pivot(index="participant_code", columns="haptic_mode")
    for r in results:
        d = (wide[(r.metric, "on")] - wide[(r.metric, "off")]).to_numpy()
        d = d[np.isfinite(d)]
        ref = scipy.stats.wilcoxon(d, method=r.method) if r.method != "permutation" else None
        if ref is not None:
            assert (r.statistic, r.p_value) == (float(ref.statistic), float(ref.pvalue))
    tct = frame.set_index("metric").loc["tct_s"]
    assert (tct["n_pairs"], tct["n_dropped_nan"]) == (5, 1)  # P03's OFF TCT is undefined
    # Holm's p for every computable primary measure; none for a secondary one (its own p)
    primary = frame["metric"].isin(PRIMARY_METRICS)
    assert (frame["p_holm"].notna() == (frame["computable"] & primary)).all()


def test_a_single_participant_gives_not_computable_rows(tmp_path):
    db = build(tmp_path / "one.db", [SessionDef("P01", [success_trial("GENTLE", "on", 0),
                                                         timeout_trial("GENTLE", "off", 2.0)])])
    trials = compute_trials(load_study([db]), workers=1).trials
    results, frame = mode_tests(per_participant(trials))
    assert not frame["computable"].any()
    assert all(r.note for r in results)
    assert frame["p_holm"].isna().all()


def test_all_equal_differences_do_not_crash(tmp_path):
    # every participant improves success by exactly 0.5: all differences tie
    sessions = [SessionDef(f"P{i:02d}", [success_trial("GENTLE", "on", 0), success_trial("GENTLE", "on", 0),
                                         success_trial("GENTLE", "off", 0), timeout_trial("GENTLE", "off", 2.0)],
                           max_trial_s=4.0)
                for i in range(1, 8)]
    trials = compute_trials(load_study([build(tmp_path / "eq.db", sessions)]), workers=1).trials
    _, frame = mode_tests(per_participant(trials, SUCCESSFUL))
    row = frame.set_index("metric").loc["success_rate"]
    ref = scipy.stats.wilcoxon(np.full(7, 0.5))
    assert row["p_value"] == float(ref.pvalue) and row["statistic"] == float(ref.statistic)
    # TCT: every trial on target from the cue, 1.0 s everywhere → all differences zero, not computable
    tct = frame.set_index("metric").loc["tct_s"]
    assert (bool(tct["computable"]), tct["n_zero"]) == (False, 7)


def test_speed_accuracy_is_the_repeated_measures_correlation_per_mode(study):
    """Within participants: the correlation of participant-centred TCT and RMSE (the cue reading, a sensitivity
    reading of the trade), df = trials − participants − 1."""
    sa = speed_accuracy(study, READINGS[1]).set_index("haptic_mode")
    for mode in ("on", "off"):
        sel = study[(study["haptic_mode"] == mode) & study["tct_s"].notna()]
        sel = sel[sel.groupby("participant_code")["tct_s"].transform("size") >= 2]  # a lone trial says nothing
        x = sel["rmse_n"] - sel.groupby("participant_code")["rmse_n"].transform("mean")
        y = sel["tct_s"] - sel.groupby("participant_code")["tct_s"].transform("mean")
        df = len(sel) - sel["participant_code"].nunique() - 1
        assert (sa.at[mode, "n_trials"], sa.at[mode, "df"]) == (len(sel), df)
        if df < 1 or not (x != 0).any():
            assert not sa.at[mode, "computable"]
            continue
        r = float((x * y).sum() / math.sqrt((x * x).sum() * (y * y).sum()))
        assert sa.at[mode, "r_rm"] == pytest.approx(r, rel=1e-12)
        t = r * math.sqrt(df / (1 - r * r))
        assert sa.at[mode, "p_value"] == pytest.approx(2 * scipy.stats.t.sf(abs(t), df), rel=1e-9)
    assert "rho" not in sa.columns  # no correlation over pooled trials, and no p-value of one
    assert isinstance(sa, pd.DataFrame)
