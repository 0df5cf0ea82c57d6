"""The error impulse ∫|F − F*| dt (``abs_impulse_n_s``): defined once in protocol.metrics, it is in the database, every
CSV, the codebook, the report and power -- and recomputed here independently, from the exported samples.

Its window is the error window of RMSE and Max AE (the same samples: from the cue to the trial end, approach
included, or from first contact); a secondary measure, tested outside Holm's family of the paper's four.
"""

from __future__ import annotations

import math
import sqlite3
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from cli_subprocess import tiny_protocol

from analysis.stats.holm import holm
from protocol.metrics import Role, get
from protocol.study.config import protocol_from_dict
from protocol.tasks.force_regulation import trial_metrics
from study_app.cli.main import main
from study_app.headless import run_study

MS = 1_000_000  # ns
#: Equal up to the order of a sum: the product's trapezoid and numpy's add the same terms in another order; over
#: ~3,000 terms of ~1e-3 N·s the rounding is ~n·ε relative (≈ 1e-12); 1e-9 leaves room and still catches a
#: sample too many or too few (one of ~3,000 samples moves the sum by ~1e-4 relative).
SUMMATION = 1e-9
#: The CSV files round N·s to 4 decimals: half a unit in the last place.
ROUNDED = 5e-5 + 1e-12
CAP_S = 3.0


def _impulse(t_ns, force_n, target, **kw) -> float:
    return float(trial_metrics(np.asarray(t_ns, dtype=np.int64), np.asarray(force_n, dtype=float), target,
                               **kw)["abs_impulse_n_s"])


# -- the definition, on traces computed by hand ----------------------------------------------------------------
def test_it_is_a_secondary_measure_taken_over_the_error_window() -> None:
    m = get("abs_impulse_n_s")
    assert (m.role, m.windowed, m.unit, m.exported, m.better) == (Role.SECONDARY, True, "N·s", "abs_impulse_N_s",
                                                                  "lower")


def test_the_approach_counts_from_the_cue_and_not_from_first_contact() -> None:
    # 0 N for 0…499 ms, then on target: the error is 0.6 N for 499 ms, one 1 ms interval from 0.6 to 0, then 0
    t = np.arange(12001) * MS
    f = np.where(np.arange(12001) < 500, 0.0, 0.6)
    assert _impulse(t, f, 0.6) == pytest.approx(0.6 * 0.499 + 0.3 * 0.001, rel=1e-12)  # trapezoid: 0.2997 N·s
    assert _impulse(t, f, 0.6, window="first_contact") == 0.0  # from 500 ms on there is no error


def test_a_timeout_integrates_the_whole_window_and_no_contact_has_no_first_contact_window() -> None:
    t = np.arange(12001) * MS
    assert _impulse(t, np.zeros(12001), 0.6) == pytest.approx(0.6 * 12.0, rel=1e-12)  # 0 … 12 s inclusive
    assert math.isnan(_impulse(t, np.zeros(12001), 0.6, window="first_contact"))


def test_it_uses_the_samples_own_times_and_bridges_a_missing_sample() -> None:
    # irregular samples (a late loop): errors 0.1, 0.3, 0.2, 0.4 N at 0, 1, 3, 6 ms
    t = np.array([0, 1, 3, 6]) * MS
    f = 0.6 - np.array([0.1, 0.3, 0.2, 0.4])
    expected = (0.1 + 0.3) / 2 * 0.001 + (0.3 + 0.2) / 2 * 0.002 + (0.2 + 0.4) / 2 * 0.003
    assert _impulse(t, f, 0.6) == pytest.approx(expected, rel=1e-12)
    # a NaN force is left out, as it is of RMSE: the integral runs straight across it
    flat = np.full(1001, 0.4)
    flat[100] = math.nan
    assert _impulse(np.arange(1001) * MS, flat, 0.6) == pytest.approx(0.2 * 1.0, rel=1e-12)


def test_an_empty_window_has_none_and_one_sample_has_no_duration() -> None:
    assert math.isnan(_impulse([], [], 0.6))
    assert _impulse([0], [0.0], 0.6) == 0.0


# -- end to end: a simulated study, its database, its report, its power ---------------------------------------
@pytest.fixture(scope="module")
def study(tmp_path_factory) -> tuple[Path, Path, Path]:
    """Four simulated participants (power needs four), 3 s trials; the report with power, and the exported samples."""
    d = tmp_path_factory.mktemp("impulse")
    db = d / "study.db"
    protocol = protocol_from_dict(tomllib.loads(tiny_protocol("impulse", max_trial_s=CAP_S, hold_s=0.3)))
    run_study(str(db), participants=4, seed=3, protocol=protocol, jobs=1)
    assert main(["report", "--db", str(db), "--out", str(d / "rep"), "--power"]) == 0
    assert main(["export", "samples", "--db", str(db), "--out", str(d / "samples.csv")]) == 0
    return db, d / "rep", d / "samples.csv"


def _stored(db: Path) -> pd.DataFrame:
    with sqlite3.connect(db) as c:
        frame = pd.read_sql_query(
            "SELECT p.code AS participant_code, t.session_id, t.trial_index, t.target_force_n, t.outcome, t.tct_s, "
            "t.abs_impulse_n_s FROM trials t JOIN sessions s USING (session_id) JOIN participants p "
            "USING (participant_id) ORDER BY t.session_id, t.trial_index", c)
    c.close()
    return frame


def test_the_database_holds_what_numpy_recomputes_from_the_exported_samples(study) -> None:
    db, _, samples_csv = study
    stored = _stored(db)
    samples = pd.read_csv(samples_csv)
    assert len(stored) == 16 and stored["abs_impulse_n_s"].notna().all()
    for r in stored.itertuples():
        end_s = r.tct_s if r.outcome == "success" else CAP_S  # the trial window: cue … end, both included
        mine = samples[(samples["session_id"] == r.session_id) & (samples["trial_number"] == r.trial_index + 1)
                       & (samples["t_since_cue_s"] >= 0) & (samples["t_since_cue_s"] <= end_s + 1e-9)]
        err = np.abs(mine["force_N"].to_numpy() - r.target_force_n)
        ok = np.isfinite(err)
        again = float(np.trapezoid(err[ok], mine["t_since_cue_s"].to_numpy()[ok]))
        assert mine["t_since_cue_s"].iloc[0] == 0.0 and len(mine) > 100
        assert r.abs_impulse_n_s == pytest.approx(again, rel=SUMMATION), (r.session_id, r.trial_index)


def test_every_csv_and_the_codebook_carry_it(study) -> None:
    db, rep, _ = study
    stored = _stored(db).set_index(["session_id", "trial_index"])["abs_impulse_n_s"]
    trials = pd.read_csv(rep / "trials.csv")
    got = trials.set_index(["session_id", trials["trial_number"] - 1])["abs_impulse_N_s"]
    assert np.allclose(got.to_numpy(), stored.reindex(got.index).to_numpy(), rtol=0, atol=ROUNDED)
    per = pd.read_csv(rep / "participants.csv")
    means = trials.groupby(["participant_code", "haptic_mode"])["abs_impulse_N_s"].mean()
    assert np.allclose(per.set_index(["participant_code", "haptic_mode"])["abs_impulse_N_s"].reindex(means.index),
                       means, rtol=0, atol=2 * ROUNDED)  # the mean of the rounded values against the rounded mean
    wide = pd.read_csv(rep / "participants_wide.csv")
    assert {"abs_impulse_off_N_s", "abs_impulse_on_N_s"} <= set(wide.columns)
    assert "abs_impulse_N_s" in pd.read_csv(rep / "participants_by_target.csv").columns
    book = pd.read_csv(rep / "codebook.csv")
    rows = book[book["column"].str.startswith("abs_impulse")]
    assert set(rows["file"]) >= {"trials.csv", "participants.csv", "participants_wide.csv",
                                 "participants_by_target.csv"}
    assert (rows["unit"] == "N·s").all() and rows["description"].str.len().min() > 20


def test_it_is_tested_outside_the_primary_family_whose_correction_does_not_move(study) -> None:
    _, rep, _ = study
    stats = pd.read_csv(rep / "stats.csv").set_index("metric")
    assert list(stats.index) == ["success_rate", "tct_s", "rmse_N", "max_ae_N", "abs_impulse_N_s"]
    assert math.isnan(stats.at["abs_impulse_N_s", "p_holm"])  # its own p, not adjusted
    primary = stats.loc[["success_rate", "tct_s", "rmse_N", "max_ae_N"]]
    # Holm across the four alone, as before the impulse existed (4 significant digits, as the file rounds)
    assert np.allclose(primary["p_holm"], holm(primary["p_value"].to_numpy()), rtol=1e-3, equal_nan=True)
    learning = pd.read_csv(rep / "learning_models.csv")
    assert "error impulse (N·s)" in set(learning["outcome"])
    page = (rep / "report.html").read_text(encoding="utf-8")
    assert "error impulse (N·s)" in page and "is a secondary measure" in page


def test_power_estimates_it_without_holm(study) -> None:
    _, rep, _ = study
    power = pd.read_csv(rep / "power.csv")
    mine = power[power["metric"] == "abs_impulse_N_s"]
    assert len(mine) == len(power[power["metric"] == "rmse_N"]) > 0
    assert mine["power"].notna().all() and mine["rejections_holm"].isna().all() and mine["power_holm"].isna().all()
    assert power[power["metric"] == "rmse_N"]["rejections_holm"].notna().all()
