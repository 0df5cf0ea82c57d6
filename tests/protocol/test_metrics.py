"""Tests of the one definition of success, TCT, RMSE and Max AE, on synthetic 1 kHz traces.

Sample k is at t_ns = k · 1_000_000 (1 ms) after the cue; expected values are computed by hand.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol.metrics import names
from protocol.tasks.force_regulation import (
    BAND_SLACK,
    ForceRegulation,
    HoldDetector,
    band_halfwidth_n,
    hold_completion_index,
    in_band,
    trial_metrics,
)
from protocol.tasks.window import CONTACT_THRESHOLD_N, TrialMetrics

MS = 1_000_000  # ns
S = 1_000_000_000  # ns
EXACT = dict(rel=1e-12, abs=1e-15)  # "equal up to float summation order"


def _t(n: int, start_ms: int = 0) -> np.ndarray:
    """Sample times of n samples at 1 kHz starting at start_ms, ns."""
    return (np.arange(n, dtype=np.int64) + start_ms) * MS


def _full_window(force_of_ms) -> tuple[np.ndarray, np.ndarray]:
    """Samples at 0, 1, …, 12000 ms with force_of_ms(k)."""
    t = _t(12001)
    return t, np.array([force_of_ms(k) for k in range(12001)], dtype=np.float64)


# -- the band -------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("force", "target", "inside"),
    [
        (0.54, 0.6, True), (0.66, 0.6, True), (0.6, 0.6, True),
        (0.5399999, 0.6, False), (0.6600001, 0.6, False),
        (1.08, 1.2, True), (1.32, 1.2, True), (1.2, 1.2, True),
        (1.0799999, 1.2, False), (1.3200001, 1.2, False),
        (0.0, 0.6, False), (-0.6, 0.6, False), (math.nan, 0.6, False), (math.inf, 0.6, False),
    ],
)
def test_band_edges_are_inclusive(force, target, inside):
    assert in_band(force, target, 0.10) is inside


def test_band_edges_computed_as_the_product_are_inclusive():
    # 1.1 * 0.6 == 0.6600000000000001 and 0.9 * 1.2 == 1.08 ± rounding: the slack makes them count
    for target in (0.6, 1.2, 0.3, 2.5):
        assert in_band(target * 1.1, target, 0.10)
        assert in_band(target * 0.9, target, 0.10)
        assert in_band(target + 0.1 * target, target, 0.10)
        assert in_band(target - 0.1 * target, target, 0.10)


def test_band_halfwidth():
    assert band_halfwidth_n(0.6, 0.10) == 0.10 * 0.6 * (1.0 + BAND_SLACK)
    assert band_halfwidth_n(0.6, 0.10) == pytest.approx(0.06, rel=2e-9)


def test_hold_detector_applies_the_band_edges():
    for force, done in ((0.54, True), (0.66, True), (0.5399999, False), (0.6600001, False)):
        det = HoldDetector(0.6, 0.10, 1 * S)
        results = [det.feed(k * MS, force) for k in range(1001)]
        assert results == [False] * 1000 + [done]


# -- HoldDetector ---------------------------------------------------------------------------------
def test_hold_completes_at_exactly_one_second_not_at_999_ms():
    det = HoldDetector(0.6, 0.10, 1 * S)
    for k in range(0, 2000):
        assert det.feed(k * MS, 0.2) is False
    assert det.hold_start_ns is None
    for k in range(2000, 3000):  # in band from 2000 ms: 999 ms of hold at 2999 ms
        assert det.feed(k * MS, 0.6) is False
    assert det.hold_start_ns == 2000 * MS
    assert det.completed_ns is None
    assert det.feed(3000 * MS, 0.6) is True  # 1000 ms after the first in-band sample
    assert det.completed_ns == 3000 * MS
    # reported once
    assert det.feed(3001 * MS, 0.6) is False
    assert det.completed_ns == 3000 * MS


def test_hold_of_999_ms_then_leaving_the_band_does_not_complete():
    det = HoldDetector(0.6, 0.10, 1 * S)
    fired = [det.feed(k * MS, 0.6 if 2000 <= k <= 2999 else 0.0) for k in range(4000)]
    assert not any(fired)
    assert det.completed_ns is None
    assert det.hold_start_ns is None


def test_one_out_of_band_sample_restarts_the_hold():
    det = HoldDetector(1.2, 0.10, 1 * S)
    starts = []
    fired_at = []
    for k in range(5000):
        if det.feed(k * MS, 1.2 if k >= 1000 and k != 1600 else 0.0):
            fired_at.append(k)
        if k in (1599, 1600, 1601):
            starts.append(det.hold_start_ns)
    # hold from 1000 ms, broken at 1600 ms, restarted at 1601 ms, completed at 2601 ms
    assert starts == [1000 * MS, None, 1601 * MS]
    assert fired_at == [2601]


def test_hold_uses_timestamps_not_sample_counts():
    # sparse, irregular samples: the hold completes at the first sample ≥ 1 s after its start
    det = HoldDetector(0.6, 0.10, 1 * S)
    times = [0, 250 * MS, 700 * MS, 999_999_999, 1_000_000_000 + 1, 2 * S]
    assert [det.feed(t, 0.6) for t in times] == [False, False, False, False, True, False]
    assert det.completed_ns == 1_000_000_001


def test_nan_breaks_a_hold():
    det = HoldDetector(0.6, 0.10, 1 * S)
    fired_at = [k for k in range(3000) if det.feed(k * MS, math.nan if k == 500 else 0.6)]
    assert fired_at == [1501]


# -- trial_metrics: success and TCT ---------------------------------------------------------------
def test_ramp_then_plateau_succeeds_one_second_after_the_plateau_starts():
    # 0, 0.001, …, 0.499 N over 0–499 ms (never in the 0.54–0.66 band), then 0.6 N from 500 ms
    t, f = _full_window(lambda k: k / 1000 if k < 500 else 0.6)
    m = trial_metrics(t, f, 0.6)
    assert m.success is True
    # times are tick counts × 1 ms: equal to the printed value up to that product's rounding
    assert m["tct_s"] == pytest.approx(1.5, **EXACT)
    assert m.end_s == pytest.approx(1.5, **EXACT)
    assert m.n_samples == 1501  # 0 … 1500 ms inclusive
    # errors: 0.6 − k/1000 for k < 500, i.e. j/1000 for j = 101 … 600; 0 on the plateau
    sum_sq = (600 * 601 * 1201 - 100 * 101 * 201) / 6 / 1e6  # Σ j² / 10⁶ = 71.84175
    assert m["rmse_n"] == pytest.approx(math.sqrt(sum_sq / 1501), **EXACT)
    assert m["max_ae_n"] == pytest.approx(0.6, **EXACT)
    assert m["time_in_band_s"] == pytest.approx(1.001, **EXACT)  # 1001 samples, 500 … 1500 ms
    assert m["peak_force_n"] == 0.6
    assert m.first_contact_s == pytest.approx(0.051, **EXACT)  # 0.050 N is not above the 0.05 N threshold; 0.051 N is
    assert CONTACT_THRESHOLD_N == 0.05


@pytest.mark.parametrize("plateau_ms", [9, 234, 1009, 5777, 10999, 11000])
def test_tct_is_exactly_plateau_start_plus_one_second(plateau_ms):
    t, f = _full_window(lambda k: 1.2 if k >= plateau_ms else 0.0)
    m = trial_metrics(t, f, 1.2)
    assert m.success is True
    assert m["tct_s"] == (plateau_ms + 1000) / 1000  # the double nearest to the exact decimal time
    assert m.end_s == m["tct_s"]
    assert m.n_samples == plateau_ms + 1001
    assert m.first_contact_s == plateau_ms / 1000


def test_plateau_too_late_for_a_full_hold_times_out():
    # in band from 11001 ms: at 12000 ms the hold is 999 ms long -- not a success
    t, f = _full_window(lambda k: 1.2 if k >= 11001 else 0.0)
    m = trial_metrics(t, f, 1.2)
    assert m.success is False
    assert m["tct_s"] is None
    assert m["time_in_band_s"] == pytest.approx(1.0, **EXACT)  # 11001 … 12000: 1000 samples


@pytest.mark.parametrize("force", [0.54, 0.66])
def test_plateau_on_a_band_edge_succeeds(force):
    t, f = _full_window(lambda k: force if k >= 300 else 0.0)
    m = trial_metrics(t, f, 0.6)
    assert (m.success, m["tct_s"]) == (True, 1.3)


@pytest.mark.parametrize("force", [0.5399999, 0.6600001])
def test_plateau_just_outside_the_band_times_out(force):
    t, f = _full_window(lambda k: force if k >= 300 else 0.0)
    m = trial_metrics(t, f, 0.6)
    assert (m.success, m["tct_s"], m["time_in_band_s"]) == (False, None, 0.0)


@pytest.mark.parametrize(("force", "success"), [(1.08, True), (1.32, True), (1.0799999, False), (1.3200001, False)])
def test_firm_band_edges_in_a_trace(force, success):
    t, f = _full_window(lambda k: force)
    assert trial_metrics(t, f, 1.2).success is success


def test_interrupted_hold_moves_the_tct():
    # in band from 1000 ms; one sample out of band at 1600 ms; in band again from 1601 ms
    t, f = _full_window(lambda k: 0.0 if k < 1000 else (0.7 if k == 1600 else 0.6))
    m = trial_metrics(t, f, 0.6)
    assert (m.success, m["tct_s"], m.n_samples) == (True, 2.601, 2602)
    assert m["time_in_band_s"] == pytest.approx(1.601, **EXACT)  # 1000 … 2601 minus the one sample at 1600
    assert m["peak_force_n"] == 0.7


def test_success_at_exactly_one_second_of_hold():
    # in band at 2000 … 3000 ms only: the sample 1000 ms after the first completes the hold
    t, f = _full_window(lambda k: 0.6 if 2000 <= k <= 3000 else 0.0)
    m = trial_metrics(t, f, 0.6)
    assert (m.success, m["tct_s"], m.n_samples) == (True, 3.0, 3001)


def test_hold_of_999_ms_is_not_a_success():
    t, f = _full_window(lambda k: 0.6 if 2000 <= k <= 2999 else 0.0)
    m = trial_metrics(t, f, 0.6)
    assert (m.success, m["tct_s"], m.end_s, m.n_samples) == (False, None, 12.0, 12001)
    assert m["time_in_band_s"] == pytest.approx(1.0, **EXACT)


def test_trial_metrics_and_hold_detector_agree_on_random_traces():
    rng = np.random.default_rng(11)
    for _ in range(30):
        f = np.clip(0.6 + rng.normal(0, 0.04, 12001).cumsum() * 0.05, 0, None)
        t = _t(12001)
        det = HoldDetector(0.6, 0.10, 1 * S)
        done = next((int(ti) for ti, fi in zip(t, f, strict=True) if det.feed(int(ti), float(fi))), None)
        m = trial_metrics(t, f, 0.6)
        assert m.success is (done is not None)
        assert m["tct_s"] == (None if done is None else done / 1e9)


_LEVELS = st.sampled_from([0.0, 0.54, 0.5399999999, 0.6, 0.66, 0.6600000001, 0.7, math.nan, math.inf])


@given(
    steps_ms=st.lists(st.integers(min_value=0, max_value=400), min_size=0, max_size=60),
    forces=st.lists(_LEVELS, min_size=60, max_size=60),
    hold_ms=st.integers(min_value=0, max_value=1500),
)
def test_vectorised_hold_equals_the_streaming_detector(steps_ms, forces, hold_ms):
    # irregular (and repeated) timestamps, band edges, NaN and inf: the offline
    # form must pick exactly the sample the live detector picks
    t = np.cumsum(np.asarray(steps_ms, dtype=np.int64) * MS)
    f = np.asarray(forces[: len(t)], dtype=np.float64)
    det = HoldDetector(0.6, 0.10, hold_ms * MS)
    expected = next((i for i, (ti, fi) in enumerate(zip(t.tolist(), f.tolist(), strict=True)) if det.feed(ti, fi)),
                    None)
    assert hold_completion_index(t, f, 0.6, 0.10, hold_ms * MS) == expected


# -- timeout and window ---------------------------------------------------------------------------
def test_never_holding_times_out_with_the_window_to_12_s_inclusive():
    t, f = _full_window(lambda k: 0.0)
    m = trial_metrics(t, f, 0.6)
    assert m == TrialMetrics(
        values={**m.values, **dict(success=False, tct_s=None, max_ae_n=0.6, time_in_band_s=0.0, peak_force_n=0.0)},
        success=False, n_samples=12001, end_s=12.0, first_contact_s=None,
    )
    assert m["rmse_n"] == pytest.approx(0.6, **EXACT)


def test_samples_outside_the_window_are_ignored():
    t = _t(14001, start_ms=-1000)  # −1000 … 13000 ms
    f = np.where(t < 0, 5.0, 0.0)  # a large force before the cue
    f[t > 12 * S] = 5.0  # and after the cap
    m = trial_metrics(t, f, 0.6)
    assert (m.n_samples, m["peak_force_n"], m["max_ae_n"]) == (12001, 0.0, 0.6)
    assert m["rmse_n"] == pytest.approx(0.6, **EXACT)


def test_samples_after_the_completing_sample_are_ignored():
    t, f = _full_window(lambda k: 0.6 if k < 1500 else 9.0)
    m = trial_metrics(t, f, 0.6)
    assert (m.success, m["tct_s"], m.n_samples, m["peak_force_n"], m["rmse_n"], m["max_ae_n"]) == (
        True, 1.0, 1001, 0.6, 0.0, 0.0)


def test_cap_and_hold_are_parameters():
    t, f = _full_window(lambda k: 0.6 if k >= 4000 else 0.0)
    short = trial_metrics(t, f, 0.6, max_trial_s=4.5, hold_s=1.0)
    assert (short.success, short.n_samples, short.end_s) == (False, 4501, 4.5)
    quick = trial_metrics(t, f, 0.6, hold_s=0.25)
    assert (quick.success, quick["tct_s"]) == (True, 4.25)
    wide = trial_metrics(t, np.full(12001, 0.7), 0.6, tolerance_fraction=0.2)
    assert (wide.success, wide["tct_s"]) == (True, 1.0)


# -- RMSE, Max AE, time in band, peak -------------------------------------------------------------
def test_two_level_trace_rmse_and_max_ae():
    # target 1.2 N: 0.9 N for 0 … 5999 ms (error −0.3), 2.0 N for 6000 … 12000 ms (error +0.8)
    t, f = _full_window(lambda k: 0.9 if k < 6000 else 2.0)
    m = trial_metrics(t, f, 1.2)
    assert m.success is False
    assert m["rmse_n"] == pytest.approx(math.sqrt((6000 * 0.09 + 6001 * 0.64) / 12001), **EXACT)
    assert m["rmse_n"] == pytest.approx(0.6041713, abs=5e-8)  # √(4380.64 / 12001)
    assert m["max_ae_n"] == pytest.approx(0.8, **EXACT)
    assert m["peak_force_n"] == 2.0
    assert m["time_in_band_s"] == 0.0
    assert m.first_contact_s == 0.0


def test_first_contact_window_excludes_the_approach():
    # no contact for 0 … 2999 ms, then 0.9 N (error −0.3 against 1.2 N) to the end
    t, f = _full_window(lambda k: 0.0 if k < 3000 else 0.9)
    cue = trial_metrics(t, f, 1.2, window="cue")
    contact = trial_metrics(t, f, 1.2, window="first_contact")
    assert cue["rmse_n"] == pytest.approx(math.sqrt((3000 * 1.44 + 9001 * 0.09) / 12001), **EXACT)
    assert cue["max_ae_n"] == pytest.approx(1.2, **EXACT)
    assert contact["rmse_n"] == pytest.approx(0.3, **EXACT)
    assert contact["max_ae_n"] == pytest.approx(0.3, **EXACT)
    # the window changes RMSE / Max AE only
    assert contact.first_contact_s == cue.first_contact_s == 3.0
    assert (contact.success, contact.n_samples, contact["time_in_band_s"], contact["peak_force_n"]) == (
        cue.success, cue.n_samples, cue["time_in_band_s"], cue["peak_force_n"]
    )


def test_first_contact_window_without_contact_gives_nan():
    t, f = _full_window(lambda k: CONTACT_THRESHOLD_N)  # at, not above, the threshold
    m = trial_metrics(t, f, 0.6, window="first_contact")
    assert m.first_contact_s is None
    assert math.isnan(m["rmse_n"]) and math.isnan(m["max_ae_n"])
    assert m.n_samples == 12001


def test_time_in_band_and_peak_force():
    # alternating 400 ms in band (0.62 N) and 600 ms out (0.3 N) from 0 ms: never a 1 s hold;
    # one spike of 3.5 N at 7777 ms (inside an out-of-band stretch)
    def force(k: int) -> float:
        if k == 7777:
            return 3.5
        return 0.62 if k % 1000 < 400 else 0.3

    t, f = _full_window(force)
    m = trial_metrics(t, f, 0.6)
    # 12 periods × 400 in-band samples, plus the sample at 12000 ms (12000 % 1000 = 0)
    assert m["time_in_band_s"] == pytest.approx(4.801, **EXACT)
    assert m["peak_force_n"] == 3.5
    assert m["max_ae_n"] == pytest.approx(2.9, **EXACT)
    assert m.success is False
    assert trial_metrics(t, f, 0.6, sample_period_s=0.002)["time_in_band_s"] == pytest.approx(9.602, **EXACT)


def test_nan_samples_are_out_of_band_and_excluded_from_errors():
    # constant 0 N with every 10th sample missing (NaN): errors are still exactly 0.6
    t, f = _full_window(lambda k: math.nan if k % 10 == 0 else 0.0)
    m = trial_metrics(t, f, 0.6)
    assert m["rmse_n"] == pytest.approx(0.6, **EXACT)
    assert m["max_ae_n"] == pytest.approx(0.6, **EXACT)
    assert m.n_samples == 12001  # NaN samples are still samples of the window
    assert m["peak_force_n"] == 0.0


def test_nan_inside_a_plateau_restarts_the_hold_and_is_not_in_band():
    t, f = _full_window(lambda k: math.nan if k == 500 else (0.6 if k >= 200 else 0.0))
    m = trial_metrics(t, f, 0.6)
    assert (m.success, m["tct_s"], m.n_samples) == (True, 1.501, 1502)
    assert m["time_in_band_s"] == pytest.approx(1.301, **EXACT)  # 200 … 1501 minus the NaN at 500
    # errors of the finite samples: 0.6 for 0 … 199 ms (200 samples), 0 afterwards (1301 samples)
    assert m["rmse_n"] == pytest.approx(math.sqrt(200 * 0.36 / 1501), **EXACT)
    assert m["max_ae_n"] == pytest.approx(0.6, **EXACT)
    assert m["peak_force_n"] == 0.6


def test_all_nan_trace():
    t, f = _full_window(lambda k: math.nan)
    m = trial_metrics(t, f, 0.6)
    assert (m.success, m.n_samples, m["time_in_band_s"], m.first_contact_s) == (False, 12001, 0.0, None)
    assert math.isnan(m["rmse_n"]) and math.isnan(m["max_ae_n"]) and math.isnan(m["peak_force_n"])


def test_no_samples():
    m = trial_metrics([], [], 0.6)
    assert (m.success, m["tct_s"], m.n_samples, m.end_s, m["time_in_band_s"], m.first_contact_s) == (
        False, None, 0, 12.0, 0.0, None
    )
    assert math.isnan(m["rmse_n"]) and math.isnan(m["max_ae_n"]) and math.isnan(m["peak_force_n"])


def test_values_are_every_registry_metric_by_name_in_order():
    t, f = _full_window(lambda k: 0.6)
    m = trial_metrics(t, f, 0.6)
    assert tuple(m.values) == names(ForceRegulation().metrics)
    assert {k: m[k] for k in ("success", "tct_s", "rmse_n", "max_ae_n", "time_in_band_s", "peak_force_n")} == {
        "success": True, "tct_s": 1.0, "rmse_n": 0.0, "max_ae_n": 0.0, "time_in_band_s": pytest.approx(1.001, **EXACT),
        "peak_force_n": 0.6}
    assert (m.success, m.n_samples, m.end_s, m.first_contact_s) == (True, 1001, 1.0, 0.0)


# -- argument checks ------------------------------------------------------------------------------
@pytest.mark.parametrize("window", ["contact", "", "CUE", None])
def test_invalid_window_is_refused(window):
    with pytest.raises(ValueError, match=r"window = .*: allowed values are 'cue' and 'first_contact'"):
        trial_metrics([0], [0.6], 0.6, window=window)


def test_mismatched_arrays_are_refused():
    with pytest.raises(ValueError, match=r"must be 1-D of equal length"):
        trial_metrics([0, 1], [0.6], 0.6)
    with pytest.raises(ValueError, match=r"must be 1-D of equal length"):
        trial_metrics([[0]], [[0.6]], 0.6)
