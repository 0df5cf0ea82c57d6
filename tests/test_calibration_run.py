"""The calibration bench on run's code path (issue 48): a study run as `run` runs it, read as `report` reads it."""

from __future__ import annotations

import math
import statistics
import tomllib

import numpy as np
import pytest
from cli_subprocess import tiny_protocol

from bench.calibration_run import format_effect_sizes, hedges_g_av, run_and_read
from protocol.study.config import protocol_from_dict


def test_hedges_g_av_is_the_average_sd_standardised_difference_with_the_small_sample_correction() -> None:
    off = np.array([2.1, 2.6, 1.9, 3.0, 2.4, 2.2])
    on = np.array([1.5, 2.0, 1.7, 2.1, 1.6, 1.9])
    n = len(off)
    # Lakens 2013, eq. 5 and 4 (d_av, Hedges' correction), with the statistics module rather than NumPy
    d_av = (statistics.fmean(on) - statistics.fmean(off)) / math.sqrt(
        (statistics.variance(off) + statistics.variance(on)) / 2)
    expected = -d_av * (1 - 3 / (4 * (n - 1) - 1))  # lower is better: an improvement is positive
    assert hedges_g_av(off, on, lower_is_better=True) == pytest.approx(expected, rel=1e-12)  # summation order only
    assert hedges_g_av(on, off, lower_is_better=False) == pytest.approx(expected, rel=1e-12)
    assert math.isnan(hedges_g_av(off[:2], on[:2], lower_is_better=True))  # too few pairs
    assert math.isnan(hedges_g_av(np.ones(4), np.ones(4), lower_is_better=True))  # no spread
    assert hedges_g_av(np.array([1.0, np.nan, 2.0, 3.0]), np.array([0.5, 1.0, np.nan, 2.0]), True) != 0.0


def test_a_study_run_as_run_runs_it_is_read_as_the_report_reads_it(tmp_path) -> None:
    protocol = protocol_from_dict(tomllib.loads(tiny_protocol("calibration")), "calibration protocol")
    s = run_and_read(3, 4, protocol=protocol, jobs=1, keep=tmp_path)
    assert (tmp_path / "study-3.db").exists() and s["n_participants"] == 4
    for key in ("success", "rmse_n", "max_ae_n", "tct_s", "tct_cens_s", "success_GENTLE"):
        assert set(s[key]) == {"off", "on", "change", "p", "n_pairs", "g"}
    assert 0.0 < s["rmse_n"]["off"] < 5.0 and s["rmse_n"]["n_pairs"] == 4
    assert "Bergholz" in format_effect_sizes([s]) and "RMSE" in format_effect_sizes([s])


def test_the_schedule_path_meets_the_participants_run_meets(tmp_path) -> None:
    """Participant j of the schedule path's study k is participant j of `run --seed k` (issue 48: the two paths
    drew different people and disagreed by a third in Max AE off haptics), the training block before changing
    nothing of the experiment: the same trials in the same order, and the same forces."""
    import dataclasses
    import sqlite3

    from protocol.study.config import default_protocol
    from study_app.headless import run_study
    from study_app.headless.sim_trials import run_participant

    protocol = dataclasses.replace(default_protocol(), trials_per_cell=1)  # 4 trials, the training block kept
    db = tmp_path / "run.db"
    run_study(str(db), participants=2, seed=11, protocol=protocol, jobs=1)
    with sqlite3.connect(db) as conn:
        stored = conn.execute(
            "SELECT t.trial_index, t.target_label, t.haptic_mode, t.max_ae_n FROM trials t JOIN sessions s "
            "USING (session_id) JOIN participants p USING (participant_id) WHERE s.kind = 'experiment' "
            "AND p.code = 'P02' ORDER BY t.trial_index").fetchall()
    rows = run_participant(11, 2, protocol)
    assert [(r.index, r.target, r.mode) for r in rows] == [s[:3] for s in stored]
    # The two runners start a trial on ticks up to one 20-tick read apart (the schedule path marks a trial at its
    # block's end), so a trial's largest error can differ by what the force changes in 20 ms: ≤ 0.05 N here; a
    # different participant differs by ~1 N.
    for r, s in zip(rows, stored, strict=True):
        assert float(r.values["max_ae_n"]) == pytest.approx(s[3], abs=0.05)
