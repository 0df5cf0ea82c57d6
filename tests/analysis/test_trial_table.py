"""Loading study databases and recomputing per-trial metrics, against hand-computed values."""

from __future__ import annotations

import itertools
import math
import sqlite3

import pandas as pd
import pytest
from studybuilder import SessionDef, build, rmse_of_success, success_trial, timeout_trial

from analysis.reading.load import AnalysisError, load_study
from analysis.reading.metrics import MetricOptions, compute_trials

EXACT = dict(rel=1e-12, abs=1e-15)


@pytest.fixture
def one_session(tmp_path):
    return build(tmp_path / "one.db", [SessionDef("P01", [
        success_trial("GENTLE", "on", 200),     # success, TCT 1.2 s
        timeout_trial("FIRM", "off", 1.5),      # 0 N for 500 ms, then 1.5 N: never in band
        success_trial("FIRM", "off", 0),        # on target from the cue: TCT 1.0 s
        timeout_trial("GENTLE", "on", 0.5),     # 0.5 N is 0.1 N below 0.6 N: outside ±10 %
    ])])


def test_recomputed_metrics_equal_hand_values(one_session):
    table = compute_trials(load_study([one_session]), workers=1)
    t = table.trials.set_index("trial_index")
    assert (table.n_from_samples, table.n_stored_only, table.n_disagree) == (4, 0, 0)
    assert list(t["success"]) == [True, False, True, False]
    assert list(t["outcome"]) == ["success", "timeout", "success", "timeout"]
    # times are tick counts × 1 ms, equal to the hand values up to that product's rounding
    assert t.at[0, "tct_s"] == pytest.approx(1.2, **EXACT) and t.at[2, "tct_s"] == pytest.approx(1.0, **EXACT)
    assert math.isnan(t.at[1, "tct_s"]) and math.isnan(t.at[3, "tct_s"])
    assert list(t["tct_censored_s"]) == pytest.approx([1.2, 12.0, 1.0, 12.0], **EXACT)
    # success after 200 ms at 0 N: 200 samples off by 0.6 N out of 1201
    assert t.at[0, "rmse_n"] == pytest.approx(rmse_of_success(0.6, 200), **EXACT)
    assert t.at[0, "max_ae_n"] == pytest.approx(0.6, **EXACT)
    assert t.at[2, "rmse_n"] == 0.0 and t.at[2, "max_ae_n"] == 0.0  # exactly: every error is exactly 0
    # timeout: 500 samples at 0 N (error 1.2), 11 501 samples at 1.5 N (error 0.3), window 0…12 s
    assert t.at[1, "rmse_n"] == pytest.approx(math.sqrt((500 * 1.2**2 + 11501 * 0.3**2) / 12001), **EXACT)
    assert t.at[1, "max_ae_n"] == pytest.approx(1.2, **EXACT)
    assert t.at[1, "peak_force_n"] == 1.5
    assert t.at[3, "time_in_band_s"] == 0.0
    assert t.at[0, "time_in_band_s"] == pytest.approx(1.001, **EXACT)  # 1001 in-band samples
    assert t.at[0, "first_contact_s"] == pytest.approx(0.2, **EXACT) and t.at[2, "first_contact_s"] == 0.0


def test_first_contact_window_leaves_out_the_approach(one_session):
    table = compute_trials(load_study([one_session]), MetricOptions(error_window="first_contact"), workers=1)
    t = table.trials.set_index("trial_index")
    assert t.at[0, "rmse_n"] == 0.0 and t.at[0, "max_ae_n"] == 0.0
    assert t.at[1, "rmse_n"] == pytest.approx(0.3, **EXACT)
    assert table.n_disagree == 0  # the check always compares the live (cue-window) definition


def test_a_stored_value_that_disagrees_with_the_samples_is_counted(one_session):
    with sqlite3.connect(one_session) as c:
        c.execute("UPDATE trials SET rmse_n = rmse_n + 0.01 WHERE trial_index = 1")
    table = compute_trials(load_study([one_session]), workers=1)
    assert table.n_disagree == 1
    # the samples win
    assert table.trials.set_index("trial_index").at[1, "rmse_n"] == pytest.approx(
        math.sqrt((500 * 1.2**2 + 11501 * 0.3**2) / 12001), **EXACT)


def test_a_trial_without_samples_keeps_its_stored_metrics(tmp_path):
    t = success_trial("GENTLE", "on", 300)
    t.with_samples = False
    db = build(tmp_path / "s.db", [SessionDef("P01", [t, success_trial("FIRM", "on", 0)])])
    table = compute_trials(load_study([db]), workers=1)
    assert (table.n_from_samples, table.n_stored_only) == (1, 1)
    row = table.trials.set_index("trial_index").loc[0]
    assert (row["success"], row["tct_s"]) == (True, 1.3)
    assert row["rmse_n"] == pytest.approx(rmse_of_success(0.6, 300), **EXACT)


def test_worker_processes_give_the_same_table(tmp_path):
    sessions = [SessionDef(f"P{i:02d}", [success_trial("GENTLE", "on", 100 * i), timeout_trial("FIRM", "off", 2.0),
                                        success_trial("FIRM", "on", 50 * i), timeout_trial("GENTLE", "off", 0.3)],
                           max_trial_s=4.0)
                for i in range(1, 6)]
    db = build(tmp_path / "w.db", sessions)
    study = load_study([db])
    one = compute_trials(study, workers=1)
    two = compute_trials(study, workers=2)
    pd.testing.assert_frame_equal(one.trials, two.trials)
    assert (two.n_from_samples, two.n_disagree) == (20, 0)


def test_progress_reaches_the_total(one_session):
    seen = []
    compute_trials(load_study([one_session]), workers=1, progress=lambda d, t: seen.append((d, t)))
    assert seen[0][0] == 0.0 and seen[-1][0] == seen[-1][1] and len(seen) >= 2
    assert all(a[0] <= b[0] for a, b in itertools.pairwise(seen))


# -- what is excluded -----------------------------------------------------------------------------
def test_training_sessions_and_aborted_trials_are_excluded_and_labelled(tmp_path):
    aborted = success_trial("FIRM", "on", 0)
    aborted.outcome_override = "aborted"
    db = build(tmp_path / "x.db", [
        SessionDef("P01", [success_trial("GENTLE", "on", 0), success_trial("GENTLE", "off", 0)], kind="training"),
        SessionDef("P01", [success_trial("GENTLE", "on", 0), aborted, success_trial("FIRM", "on", 0)]),
    ])
    study = load_study([db])
    assert list(study.trials["excluded"]) == ["training session", "training session", "", "aborted trial", ""]
    table = compute_trials(study, workers=1)
    assert list(table.trials["trial_index"]) == [0, 2]


def test_several_databases_merge(tmp_path):
    a = build(tmp_path / "a.db", [SessionDef("P01", [success_trial("GENTLE", "on", 0)])])
    b = build(tmp_path / "b.db", [SessionDef("P02", [timeout_trial("GENTLE", "on", 2.0)])])
    table = compute_trials(load_study([a, b]), workers=1)
    assert list(table.trials["participant_code"]) == ["P01", "P02"]
    assert list(table.trials["session_id"]) == [1, 1]  # each database numbers its own sessions
    assert list(table.trials["success"]) == [True, False]


# -- bad input ------------------------------------------------------------------------------------
def test_a_text_file_is_not_a_study_database(tmp_path):
    p = tmp_path / "notes.db"
    p.write_text("hello")
    with pytest.raises(AnalysisError, match="not a haptic-study database"):
        load_study([p])


def test_another_sqlite_database_is_refused(tmp_path):
    p = tmp_path / "other.db"
    with sqlite3.connect(p) as c:
        c.execute("CREATE TABLE t (x)")
    with pytest.raises(AnalysisError, match=r"not a haptic-study database \(it has other tables: t\)"):
        load_study([p])


def test_missing_file(tmp_path):
    with pytest.raises(AnalysisError, match="no such database"):
        load_study([tmp_path / "nope.db"])


def test_empty_study_database(tmp_path):
    build(tmp_path / "e.db", [])
    with pytest.raises(AnalysisError, match=r"empty study database \(no sessions\)"):
        load_study([tmp_path / "e.db"])


def test_only_training_sessions(tmp_path):
    db = build(tmp_path / "t.db", [SessionDef("P01", [success_trial("GENTLE", "on", 0)], kind="training")])
    with pytest.raises(AnalysisError, match="only training sessions"):
        load_study([db])


def test_the_same_database_twice(tmp_path, one_session):
    with pytest.raises(AnalysisError, match="the same database is given twice"):
        load_study([one_session, str(one_session)])


def test_a_participant_code_in_two_databases_is_refused(tmp_path):
    a = build(tmp_path / "a.db", [SessionDef("P01", [success_trial("GENTLE", "on", 0)])])
    b = build(tmp_path / "b.db", [SessionDef("P01", [success_trial("GENTLE", "on", 0)])])
    with pytest.raises(AnalysisError, match="participant code 'P01' appears in"):
        load_study([a, b])


def test_a_newer_schema_is_refused(tmp_path, one_session):
    with sqlite3.connect(one_session) as c:
        c.execute("PRAGMA user_version = 99")
    with pytest.raises(AnalysisError, match="newer than this software supports"):
        load_study([one_session])


def test_reading_never_writes(one_session):
    before = one_session.read_bytes()
    compute_trials(load_study([one_session]), workers=1)
    assert one_session.read_bytes() == before
