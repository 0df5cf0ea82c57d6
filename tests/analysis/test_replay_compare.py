"""analysis.stats.replay_compare: the delay estimate against a plain shift-by-shift reference, and on known delays."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis.stats.replay_compare import best_lag_ms, moving_average


def _reference_lag(ref: np.ndarray, dly: np.ndarray, max_lag: int) -> float:
    """The definition, one shift at a time: the shift of highest correlation coefficient, parabola-refined."""
    n = len(ref)
    core = ref[max_lag : n - max_lag]
    a = core - core.mean()
    na = math.sqrt(float(a @ a))
    lags = list(range(-max_lag, max_lag + 1))
    r = []
    for k in lags:
        b = dly[max_lag + k : n - max_lag + k]
        b = b - b.mean()
        nb = math.sqrt(float(b @ b))
        r.append(float(a @ b) / (na * nb) if na > 0 and nb > 0 else -1.0)
    i = int(np.argmax(r))
    if r[i] < 0.5:
        return math.nan
    if 0 < i < len(lags) - 1:
        y0, y1, y2 = r[i - 1], r[i], r[i + 1]
        den = y0 - 2 * y1 + y2
        return lags[i] + (0.5 * (y0 - y2) / den if den < 0 else 0.0)
    return float(lags[i])


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(30, 3000), max_lag=st.integers(1, 60),
       delay=st.integers(-20, 20), offset=st.sampled_from([0.0, 1.0, 1e6]), noise=st.floats(0.0, 2.0))
def test_the_delay_is_the_definition_computed_at_once(seed: int, n: int, max_lag: int, delay: int, offset: float,
                                                      noise: float) -> None:
    rng = np.random.default_rng(seed)
    base = moving_average(rng.standard_normal(n + 100), 15)
    ref = base[50 : 50 + n] + offset
    dly = base[50 - delay : 50 - delay + n] * 2.0 + offset + noise * 0.05 * rng.standard_normal(n)
    want = _reference_lag(ref, dly, max_lag) if n >= 3 * max_lag + 3 else math.nan
    got = best_lag_ms(ref, dly, max_lag)
    if math.isnan(want):
        assert math.isnan(got) or n >= 3 * max_lag + 3
    else:
        assert abs(got - want) < 1e-6


def test_a_known_delay_is_found_and_flat_or_short_signals_give_nan() -> None:
    rng = np.random.default_rng(1)
    x = moving_average(rng.standard_normal(5000), 25)
    assert abs(best_lag_ms(x[100:4100], x[93:4093], 40) - 7.0) < 0.01  # the second lags by 7 samples
    assert abs(best_lag_ms(x[100:4100], 3.0 * x[100:4100], 40)) < 0.01  # amplitude is not delay
    assert math.isnan(best_lag_ms(np.ones(500), x[:500], 40))
    assert math.isnan(best_lag_ms(x[:100], x[:100], 40))
