"""Tests of the moving-average filter: exactness, NaN/inf rejection, spike flushing, long runs.

The reference is the exact windowed mean ``math.fsum(last W accepted samples) / count``
(docs/science.md §7: drift, NaN poisoning and 1e17 spikes are the hazards).
"""

from __future__ import annotations

import math

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from pipeline.force.filters import MovingAverage, MovingAverage3, group_delay_s

U = 2.0**-53  # unit roundoff
TINY = 5e-324


def exact_mean(accepted: list[float], window: int) -> float:
    w = accepted[-window:]
    return math.fsum(w) / len(w)


def running_sum_tolerance(accepted: list[float], window: int) -> float:
    """Worst-case error of a running sum re-summed exactly every ``window`` samples.

    Everything the running sum has touched since its last exact re-sum lies in the
    last ``2·window - 1`` accepted samples; with ``A`` the sum of their magnitudes,
    fewer than ``window`` updates of two roundings each (plus the re-sum and the final
    division, here and in the reference) give at most ``(2·window + 3)·u·A / n``.
    """
    n = min(len(accepted), window)
    a = math.fsum(abs(x) for x in accepted[-(2 * window - 1):])
    return (2 * window + 3) * U * a / n * (1 + 1e-9) + TINY


windows = st.integers(1, 40)
mixed = st.one_of(
    st.floats(-1e300, 1e300),  # includes 0, subnormals and the extremes
    st.floats(-100.0, 100.0),
    st.sampled_from([1e17, -1e17, 50.0, -50.0, 1e-300, TINY, 0.1, 1e15 + 0.3]),
)
integral = st.integers(-(10**6), 10**6).map(float)  # every sum and difference is exact
non_finite = st.sampled_from([math.nan, math.inf, -math.inf])


# ---------------------------------------------------------------------------
# exactness


@given(windows, st.lists(integral, max_size=200))
@example(4, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
def test_integral_samples_give_the_exact_mean_at_every_step(window, xs):
    ma = MovingAverage(window)
    for i, x in enumerate(xs):
        out = ma.update(x)
        assert out == exact_mean(xs[: i + 1], window), (i, x)


def test_first_outputs_average_what_has_been_seen():
    ma = MovingAverage(4)
    assert [ma.update(x) for x in (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)] == [1.0, 1.5, 2.0, 2.5, 3.5, 4.5]
    ma2 = MovingAverage(2)  # the docstring example
    assert (ma2.update(1.0), ma2.update(3.0), ma2.update(5.0)) == (1.0, 2.0, 4.0)


@given(windows, st.lists(mixed, max_size=200))
@example(3, [1e17, 50.3, 50.7, 49.9, 50.1, 50.2, 49.8])
@example(2, [1e300, -1e300, 1.0, 1.0, 1.0])
@example(5, [TINY, TINY, 1e-300, -TINY, 0.0, 1e-300])
def test_outputs_track_the_exact_windowed_mean(window, xs):
    ma = MovingAverage(window)
    for i, x in enumerate(xs):
        out = ma.update(x)
        seen = xs[: i + 1]
        ref = exact_mean(seen, window)
        assert abs(out - ref) <= running_sum_tolerance(seen, window), (i, out, ref)
        if (i + 1) % window == 0:
            # the window has just been re-summed exactly: bit-for-bit the reference
            assert out == ref, (i, out, ref)


@given(st.lists(st.floats(allow_nan=False, allow_infinity=False), max_size=100))
def test_window_one_is_identity(xs):
    ma = MovingAverage(1)
    ma3 = MovingAverage3(1)
    for x in xs:
        assert ma.update(x) == x
        assert ma3.update(x, -x, 0.5 * x) == (x, -x, 0.5 * x)


@given(windows, st.lists(st.tuples(mixed, mixed, mixed), max_size=150))
def test_vector_filter_is_three_independent_scalar_filters(window, xs):
    ma3 = MovingAverage3(window)
    lanes = [MovingAverage(window) for _ in range(3)]
    for i, (x, y, z) in enumerate(xs):
        assert ma3.update(x, y, z) == tuple(m.update(c) for m, c in zip(lanes, (x, y, z), strict=True))
        assert ma3.count == min(i + 1, window)


def test_count_and_reset():
    ma3 = MovingAverage3(3)
    assert ma3.count == 0
    for i, expected in enumerate([1, 2, 3, 3, 3]):
        ma3.update(float(i), 0.0, 0.0)
        assert ma3.count == expected
    ma3.update(math.nan, 0.0, 0.0)
    ma3.reset()
    assert ma3.count == 0
    assert ma3.update(7.0, 8.0, 9.0) == (7.0, 8.0, 9.0)
    ma = MovingAverage(3)
    ma.update(100.0)
    ma.reset()
    assert ma.update(-2.0) == -2.0
    assert ma.window == 3


# ---------------------------------------------------------------------------
# non-finite samples


@given(windows, st.lists(st.one_of(integral, non_finite), max_size=200))
@example(3, [math.nan, 1.0, math.inf, 2.0, -math.inf, 3.0, 4.0, math.nan])
def test_non_finite_samples_are_rejected_and_do_not_poison(window, xs):
    ma = MovingAverage(window)
    accepted: list[float] = []
    previous = 0.0
    for x in xs:
        out = ma.update(x)
        if math.isfinite(x):
            accepted.append(x)
            assert out == exact_mean(accepted, window)
        else:
            assert out == previous  # unchanged
        assert math.isfinite(out)
        previous = out
    assert ma.rejected == sum(1 for x in xs if not math.isfinite(x))


@pytest.mark.parametrize("bad_lane", [0, 1, 2])
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_vector_sample_with_one_bad_component_is_rejected_whole(bad_lane, bad):
    ma3 = MovingAverage3(2)
    first = ma3.update(1.0, 2.0, 3.0)
    sample = [10.0, 20.0, 30.0]
    sample[bad_lane] = bad
    assert ma3.update(*sample) == first == (1.0, 2.0, 3.0)
    assert ma3.rejected == 1
    assert ma3.count == 1
    assert ma3.update(3.0, 4.0, 5.0) == (2.0, 3.0, 4.0)


def test_rejection_before_any_sample_returns_zero():
    ma3 = MovingAverage3(5)
    assert ma3.update(math.nan, 1.0, 1.0) == (0.0, 0.0, 0.0)
    assert ma3.count == 0 and ma3.rejected == 1
    ma = MovingAverage(5)
    assert ma.update(math.inf) == 0.0
    assert ma.rejected == 1


# ---------------------------------------------------------------------------
# spikes


@given(
    st.integers(1, 20),
    st.integers(0, 60),
    st.sampled_from([1e17, -1e17, 3.3e17, 1e200, -1e300]),
    st.lists(st.floats(-2.0, 2.0), min_size=1, max_size=7),
)
@example(10, 3, 1e17, [0.3, -0.7, 0.11])
def test_a_spike_is_flushed_within_two_windows(window, before, spike, wiggle):
    # 50 N plus a small non-integral variation, so the spike's rounding residue is real
    signal = [50.0 + wiggle[i % len(wiggle)] * 0.1 + 0.013 * i for i in range(before + 6 * window)]
    ma = MovingAverage(window)
    accepted: list[float] = []
    for x in signal[:before]:
        accepted.append(x)
        ma.update(x)
    accepted.append(spike)
    spike_count = len(accepted)
    out = ma.update(spike)
    assert abs(out) > 1e15  # the spike is in the window
    for x in signal[before:]:
        accepted.append(x)
        out = ma.update(x)
        c = len(accepted)
        ref = exact_mean(accepted, window)
        if c >= spike_count + 2 * window - 1:  # the 2W-th sample counting the spike itself
            assert abs(out - ref) <= 1e-12, (c - spike_count, out, ref)


def test_spike_residue_would_stay_without_the_resum():
    # Sanity check of the test above: the spike leaves a residue in the plain running sum,
    # so the flush assertion is not vacuous for this input.
    s = 0.0
    xs = [50.3, 1e17, 50.7, 49.9]
    for x in xs:
        s += x
    s -= 50.3
    s -= 1e17
    assert abs(s - (50.7 + 49.9)) > 1e-3


# ---------------------------------------------------------------------------
# huge finite samples


@pytest.mark.parametrize("window", [2, 3, 10])
def test_finite_samples_near_dbl_max_do_not_overflow(window):
    # Every sample is finite and so is every windowed mean (it is 1e308), so the filter
    # must neither raise nor return inf.
    ma = MovingAverage(window)
    outs = [ma.update(1e308) for _ in range(2 * window + 1)]
    assert outs == [1e308] * (2 * window + 1)


# ---------------------------------------------------------------------------
# configuration


@pytest.mark.parametrize("bad", [0, -1, 2.5, True, False, "10", None, 10.0, 1_000_001])
def test_invalid_windows_are_rejected(bad):
    with pytest.raises(ValueError, match="window"):
        MovingAverage(bad)
    with pytest.raises(ValueError, match="window"):
        MovingAverage3(bad)
    with pytest.raises(ValueError, match="window"):
        group_delay_s(bad)


def test_group_delay():
    # (n − 1)/2 ticks at the rate: equal to the printed seconds up to the division's rounding
    assert group_delay_s(10) == pytest.approx(0.0045, rel=1e-15)
    assert group_delay_s(20) == pytest.approx(0.0095, rel=1e-15)
    assert group_delay_s(1) == 0.0  # exactly: no delay at all
    assert group_delay_s(10, rate_hz=500.0) == pytest.approx(0.009, rel=1e-15)


def test_largest_window_is_accepted():
    assert MovingAverage(1_000_000).window == 1_000_000


# ---------------------------------------------------------------------------
# the long run: ten hours at 1 kHz


@pytest.mark.slow
def test_ten_hour_run_stays_exact():
    """A 10-hour run at 1 kHz (3.6e7 samples, ±50 N offsets) stays within 1e-9 N of the exact windowed mean.

    Three lanes of one MovingAverage3: +50 N with a small variation, -50 N with another, and a lane
    alternating between about +50 N and -50 N.  The inputs cycle through a 1009-sample table (prime).

    Why checking a short run proves the long one: the filter's complete state is what :meth:`state`
    returns (its slots are the window, the rejection count, the rings and the running sums with the ring
    index and count -- asserted below, so a hidden counter added later fails this test), and its next
    output and state are a function of that state and the next sample only.  The input's next sample is a
    function of its phase (sample number mod 1009).  So once the pair (filter state, input phase) at sample
    ``t2`` equals, bit for bit, the pair at an earlier sample ``t1``, the run from ``t2`` on repeats the run
    from ``t1`` on exactly, for ever: every output at any sample ``t >= t1`` equals the output at
    ``t1 + (t - t1) mod (t2 - t1)``.  The test runs until that repetition (it comes after a whole number of
    re-sum cycles, lcm(window, 1009) = 10090 samples here; a filter that drifted -- a running sum never
    re-summed, a re-sum period growing with the run -- would never repeat its state and fail), checking
    *every* output against ``math.fsum`` of its window on the way, then one more full period to check that
    the outputs do repeat.  It then puts the filter into the state it has at sample 3.6e7 - 20 (loaded from
    the equivalent sample of the first period) and checks every output across the 10-hour point, each
    equal to the exact mean and to the output of its equivalent early sample.  (The earlier version fed all
    3.6e7 samples and checked 10 of every 1e6: every one of those outputs is among the ones checked here.)
    """
    window = 10
    n_total = 36_000_000
    period = 1009
    xs = [50.0 + ((k * 7919) % 1000) * 1e-3 + 1e-7 * k for k in range(period)]
    ys = [-50.0 - ((k * 104729) % 997) * 1.3e-3 for k in range(period)]
    zs = [(50.0 if k % 2 else -50.0) + ((k * 31) % 101) * 1e-2 - 0.37 for k in range(period)]
    tables = (xs, ys, zs)
    # all of it (sums, index, count, rejected, rings) is in state()
    assert {n for c in MovingAverage3.__mro__ for n in getattr(c, "__slots__", ())} == {"window", "array"}

    def exact(done: int) -> list[float]:
        """The exact mean of the window ending with sample ``done`` (1-based count of samples fed)."""
        n = min(done, window)
        return [math.fsum(t[k % period] for k in range(done - n, done)) / n for t in tables]

    ma = MovingAverage3(window)
    seen: dict[tuple[int, str], int] = {}  # (input phase, state) -> samples fed when it was seen
    outputs: list[tuple[float, float, float]] = []  # outputs[t - 1]: the output after sample t
    worst = 0.0
    done = 0
    t1 = t2 = None
    while t2 is None:
        key = (done % period, repr(ma.state()))
        if key in seen:
            t1, t2 = seen[key], done
            break
        seen[key] = done
        k = done % period
        out = ma.update(xs[k], ys[k], zs[k])
        done += 1
        outputs.append(out)
        for lane, ref in enumerate(exact(done)):
            err = abs(out[lane] - ref)
            worst = max(worst, err)
            assert err <= 1e-9, (done, lane, out[lane], ref)
        assert done <= 50 * period * window, "the filter's state never repeats: it drifts"
    cycle_len = t2 - t1
    assert cycle_len % window == 0 and cycle_len % period == 0  # whole re-sum cycles and whole input cycles
    # one more full period, every output equal to that one period earlier (and exact)
    for _ in range(cycle_len):
        k = done % period
        out = ma.update(xs[k], ys[k], zs[k])
        done += 1
        assert out == outputs[done - 1 - cycle_len], done
        outputs.append(out)
    assert done >= 2 * cycle_len and done // window >= 2000  # thousands of full re-sum cycles, all checked

    def equivalent(t: int) -> int:
        """The sample of the checked run whose state (after it) equals the state after sample ``t``."""
        return t if t <= t2 else t1 + (t - t1) % cycle_len

    # across the 10-hour point: start from the state the filter has after sample 3.6e7 - 20
    start = n_total - 2 * window
    early = MovingAverage3(window)
    for t in range(equivalent(start)):
        k = t % period
        early.update(xs[k], ys[k], zs[k])
    late = MovingAverage3(window)
    late.load_state(early.state())
    for t in range(start + 1, n_total + 2 * window + 1):
        k = (t - 1) % period
        out = late.update(xs[k], ys[k], zs[k])
        assert out == outputs[equivalent(t) - 1], t
        for lane, ref in enumerate(exact(t)):
            err = abs(out[lane] - ref)
            worst = max(worst, err)
            assert err <= 1e-9, (t, lane, out[lane], ref)
    assert ma.rejected == late.rejected == 0
    assert worst <= 1e-9
