"""The speed–accuracy measure cannot manufacture a trade: a null model, simulated participants whose accuracy does not
depend on their speed.

Each simulated trial is a force trace from the cue: an approach through the air at 0 N (its length drawn per
trial), a rise from contact to the band's lower edge (its length, the participant's *speed*, drawn per trial), then
a trajectory about the target whose error -- its settling, its noise, a spell off target before the hold -- is drawn
independently of the rise (the participant's *accuracy*).  The metrics are computed by the one definition
(:func:`protocol.tasks.force_regulation.trial_metrics`), the correlation by the report's own :func:`speed_accuracy`.

* the default reading (rise time against RMSE after reach, phases apart) calls no trade more often than its
  nominal level: the rate of intervals below zero stays near the 2.5 % a 95 % interval gives by chance;
* the cue reading (TCT against RMSE from the cue, successful trials) on the very same trials finds a "trade" in most
  studies: the approach at 0 N is a larger share of a quick trial's window, so its RMSE is larger -- a correlation
  the window builds (the issue's 34 % share, r_rm = −0.64);
* a participant whose faster rises *do* overshoot more is found by the default reading (the measure is not blind).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from analysis.stats.trade import READINGS, speed_accuracy, trade_conclusion
from protocol.tasks.force_regulation import trial_metrics

_TARGET_N = 1.2
_TOL = 0.10
_CAP_S = 12.0
_DT_S = 0.001


def _trace(rng: np.random.Generator, overshoot_per_speed: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """One trial's samples: (t_ns from the cue, task force N).  ``overshoot_per_speed`` > 0 couples the error after
    reaching the band to the rise's speed (a real trade); 0 is the null."""
    approach = rng.uniform(1.0, 3.0)
    rise = rng.uniform(0.05, 1.5)
    tau = rng.uniform(0.05, 0.4)  # settling, drawn apart from the rise
    sigma = rng.uniform(0.01, 0.06) * _TARGET_N
    off_for = rng.uniform(0.0, 5.0) if rng.random() < 0.6 else 0.0  # a spell off target after reaching the band
    off_by = rng.choice([-1.0, 1.0]) * rng.uniform(0.15, 0.4) * _TARGET_N
    t = np.arange(0.0, _CAP_S + _DT_S / 2, _DT_S)
    start = _TARGET_N * (1 - _TOL + 0.01)  # the rise ends just inside the band: the band is reached on the rise
    f = np.zeros_like(t)
    on_rise = (t >= approach) & (t < approach + rise)
    f[on_rise] = start * (t[on_rise] - approach) / rise
    after = t >= approach + rise
    s = t[after] - (approach + rise)
    fade_in = 1 - np.exp(-s / 0.02)  # what follows starts where the rise ended
    noise = np.convolve(rng.normal(0.0, 1.0, s.size), np.ones(40) / np.sqrt(40), mode="same") * sigma * fade_in
    overshoot = overshoot_per_speed * (1.5 - rise) * _TARGET_N * np.exp(-s / 0.15) * fade_in
    spell = np.where((s > 0.05) & (s < 0.05 + off_for), off_by, 0.0) * fade_in
    f[after] = _TARGET_N - (_TARGET_N - start) * np.exp(-s / tau) + noise + overshoot + spell
    return np.round(t * 1e9).astype(np.int64), f


def _study(rng: np.random.Generator, n_participants: int = 8, n_trials: int = 12,
           overshoot_per_speed: float = 0.0) -> pd.DataFrame:
    rows = []
    for p in range(n_participants):
        for _ in range(n_trials):
            t, f = _trace(rng, overshoot_per_speed)
            m = trial_metrics(t, f, _TARGET_N, tolerance_fraction=_TOL, max_trial_s=_CAP_S)
            rows.append({"participant_code": f"P{p:02d}", "haptic_mode": "on", **m.values})
    return pd.DataFrame(rows)


def _rates(n_studies: int, seed: int, overshoot_per_speed: float = 0.0) -> dict[str, float]:
    """Per reading, the share of studies whose ON r_rm interval lies below zero (a 'trade' by that reading)."""
    rng = np.random.default_rng(seed)
    below = {r.key: 0 for r in READINGS[:2]}
    for _ in range(n_studies):
        trials = _study(rng, overshoot_per_speed=overshoot_per_speed)
        for reading in READINGS[:2]:  # the phases and the cue readings (these trials are in the cue window)
            row = speed_accuracy(trials, reading).set_index("haptic_mode").loc["on"]
            below[reading.key] += bool(row["computable"]) and float(row["ci_high"]) < 0
    return {k: v / n_studies for k, v in below.items()}


def test_a_participant_whose_accuracy_is_independent_of_speed_shows_no_trade_by_default() -> None:
    rates = _rates(60, seed=41)
    # 60 studies: under the null the count below zero is Binomial(60, 0.025), mean 1.5; P(≥ 6) < 0.5 %
    assert rates["phases"] <= 5 / 60, rates
    # the cue window's correlation is built by the window: most of the very same studies show a "trade"
    assert rates["cue"] >= 0.5, rates


def test_a_participant_who_overshoots_when_fast_is_found_by_the_default_reading() -> None:
    rates = _rates(15, seed=7, overshoot_per_speed=1.0)
    assert rates["phases"] >= 0.8, rates


def test_the_label_trade_needs_the_interval_below_zero_and_the_cue_reading_to_agree() -> None:
    def row(r: float, lo: float, hi: float, ok: bool = True) -> pd.Series:
        return pd.Series({"r_rm": r, "ci_low": lo, "ci_high": hi, "computable": ok})

    neg, cue_neg, cue_none = row(-0.4, -0.6, -0.2), row(-0.3, -0.5, -0.1), row(-0.1, -0.4, 0.2)
    assert trade_conclusion(neg, cue_neg) == "negative: faster trials less accurate (a trade)"
    # the cue reading only withholds the label, and the conclusion says what it showed
    assert trade_conclusion(neg, cue_none) == ("negative, but the cue-window reading holds 0 in its interval: "
                                               "not called a trade")
    assert trade_conclusion(neg, row(0.3, 0.1, 0.5)).startswith("negative, but the cue-window reading is positive")
    assert "cue-window reading is not computable" in trade_conclusion(neg, row(np.nan, np.nan, np.nan, ok=False))
    assert "cue-window reading is not computable" in trade_conclusion(neg, None)
    # one participant: r_rm -0.921 [-0.998, 0.348] is no trade (its interval holds zero)
    assert trade_conclusion(row(-0.921, -0.998, 0.348), cue_neg).startswith("no association shown")
    assert trade_conclusion(row(-0.9, np.nan, np.nan), cue_neg).startswith("not computable")
    assert "no trade" in trade_conclusion(row(0.4, 0.2, 0.6), cue_neg)


@pytest.mark.parametrize("seed", [0, 1])
def test_rise_time_and_reach_rmse_are_the_phases_of_the_trace(seed: int) -> None:
    """The two measures on one trace, by hand: contact and reaching the band from the samples, the RMSE over the
    1 s that follows."""
    t, f = _trace(np.random.default_rng(seed))
    m = trial_metrics(t, f, _TARGET_N, tolerance_fraction=_TOL, max_trial_s=_CAP_S)
    contact = t[np.flatnonzero(f > 0.05)[0]] / 1e9
    i = int(np.flatnonzero(f >= _TARGET_N - _TOL * _TARGET_N * (1 + 1e-9))[0])  # the band's edge with its slack
    assert m["rise_time_s"] == pytest.approx(t[i] / 1e9 - contact, abs=1e-12)
    end = m.end_s
    if t[i] / 1e9 + 1.0 <= end + 1e-12:
        part = (t >= t[i]) & (t <= t[i] + 1_000_000_000)
        assert m["reach_rmse_n"] == pytest.approx(float(np.sqrt(np.mean((f[part] - _TARGET_N) ** 2))), rel=1e-12)
    else:
        assert m["reach_rmse_n"] is None
