"""Tests of the safety stage: bound, slew limit, ramp in, fault ramp out (docs/science.md §5).

Time is virtual: every test passes ``dt_s`` explicitly, nothing sleeps.
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from pipeline.force.safety import SafetyConfig, SafetyGovernor

NAN = math.nan
INF = math.inf
ZERO = (0.0, 0.0, 0.0)
FIELDS = ("f_max_n", "slew_n_per_s", "ramp_in_s", "fault_ramp_s", "max_dt_s")

# ---------------------------------------------------------------------------
# strategies

force_component = st.one_of(
    st.floats(),  # everything, including ±inf, NaN, subnormals and ±1.8e308
    st.floats(-5.0, 5.0),
    st.sampled_from([0.0, -0.0, 5e-324, 1e-300, 3.0, -3.0, 2.9999999999, 1e154, 1.7e308, -1.7e308, INF, -INF, NAN]),
)
dt_values = st.one_of(
    st.floats(),
    st.floats(0.0, 0.02),
    st.sampled_from([0.001, 0.0, -0.0, -0.001, 5e-324, 0.005, 0.0050001, 0.01, 1.0, 1e300, INF, -INF, NAN]),
)
ticks = st.tuples(force_component, force_component, force_component, st.booleans(), dt_values)


@st.composite
def configs(draw):
    cfg = SafetyConfig(
        f_max_n=draw(st.floats(0.1, 10.0)),
        slew_n_per_s=draw(st.one_of(st.floats(1.0, 1000.0), st.sampled_from([20.0, 50.0, 1e6]))),
        ramp_in_s=draw(st.floats(1e-3, 2.0)),
        fault_ramp_s=draw(st.floats(1e-3, 0.05)),
        max_dt_s=draw(st.floats(1e-4, 0.05)),
    )
    peak = draw(st.one_of(st.floats(0.1, 10.0), st.just(3.3)))
    return cfg, peak


def effective_dt(dt: float, cfg: SafetyConfig) -> float:
    if not dt > 0.0:
        return 0.0
    return min(dt, cfg.max_dt_s)


def diff_norm(a, b) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2])


def run_constant(gov, f, enabled, dt, n):
    return [gov.step(*f, enabled, dt) for _ in range(n)]


# ---------------------------------------------------------------------------
# properties over arbitrary input sequences


@given(configs(), st.lists(ticks, min_size=1, max_size=300))
@example(
    (SafetyConfig(), 3.3),
    [(3.0, 0.0, 0.0, True, 0.001)] * 600 + [(NAN, 0.0, 0.0, True, 0.001)] * 5 + [(0.0, 0.0, 0.0, False, 0.001)] * 45,
)
@example((SafetyConfig(), 2.0), [(1.7e308, -1.7e308, 1.7e308, True, 1e300)] * 200)
@example((SafetyConfig(slew_n_per_s=1e6, ramp_in_s=0.001), 3.3), [(1e154, 1e154, 0.0, True, 0.005)] * 5)
def test_output_always_finite_bounded_and_rate_limited(cfg_peak, seq):
    cfg, peak = cfg_peak
    gov = SafetyGovernor(cfg, peak)
    limit = min(cfg.f_max_n, peak)
    assert gov.limit_n == limit
    prev_out, prev_gain = ZERO, 0.0
    for fx, fy, fz, enabled, dt in seq:
        out = gov.step(fx, fy, fz, enabled, dt)
        gain = gov.gain
        assert isinstance(out, tuple) and len(out) == 3
        assert all(type(c) is float and math.isfinite(c) for c in out), out
        assert math.hypot(*out) <= limit, (out, limit)  # exactly, no tolerance
        assert 0.0 <= gain <= 1.0
        h = effective_dt(dt, cfg)
        # the gain ramps at its configured rates (the snap to 0 below 1e-12 aside)
        if enabled:
            assert prev_gain <= gain <= prev_gain + h / cfg.ramp_in_s * (1 + 1e-12) + 1e-15
        else:
            # the ramp-down runs on the true elapsed time (late ticks must not stretch it)
            true_dt = dt if dt > 0.0 else 0.0
            assert gain <= prev_gain
            assert prev_gain - gain <= true_dt / cfg.fault_ramp_s * (1 + 1e-12) + 1e-12
        # out = gain·s with |Δs| ≤ slew·dt and |s| ≤ limit, so
        # |Δout| ≤ gain·slew·dt + |Δgain|·limit (+ rounding)
        bound = gain * cfg.slew_n_per_s * h + abs(gain - prev_gain) * limit + 1e-12
        assert diff_norm(out, prev_out) <= bound, (prev_out, out, bound)
        if gain == 0.0:
            assert out == ZERO
        prev_out, prev_gain = out, gain


@given(configs(), st.lists(st.tuples(force_component, force_component, force_component, dt_values), max_size=200))
def test_steady_full_gain_output_moves_at_most_slew_times_dt(cfg_peak, seq):
    cfg, peak = cfg_peak
    cfg = dataclasses.replace(cfg, ramp_in_s=max(cfg.max_dt_s, 1e-3))  # full gain within a few ticks
    gov = SafetyGovernor(cfg, peak)
    for _ in range(int(cfg.ramp_in_s / cfg.max_dt_s) + 2):
        gov.step(0.0, 0.0, 0.0, True, cfg.max_dt_s)
    assert gov.gain == 1.0
    prev = gov.step(0.0, 0.0, 0.0, True, 0.0)
    for fx, fy, fz, dt in seq:
        out = gov.step(fx, fy, fz, True, dt)
        assert gov.gain == 1.0
        assert diff_norm(out, prev) <= cfg.slew_n_per_s * effective_dt(dt, cfg) + 1e-12
        prev = out


# ---------------------------------------------------------------------------
# clamping


def test_device_peak_below_f_max_clamps_at_device_peak():
    gov = SafetyGovernor(SafetyConfig(f_max_n=3.0), 2.0)
    assert gov.limit_n == 2.0
    outs = run_constant(gov, (10.0, 0.0, 0.0), True, 0.001, 1000)
    assert all(math.hypot(*o) <= 2.0 for o in outs)
    assert 2.0 * (1 - 1e-9) <= outs[-1][0] <= 2.0
    assert outs[-1][1:] == (0.0, 0.0)
    # the direction of an over-range request is kept: (0, 3, 4)·k
    outs = run_constant(gov, (0.0, -30.0, 40.0), True, 0.001, 1000)
    assert outs[-1][0] == 0.0
    assert outs[-1][1] == pytest.approx(-1.2, rel=1e-9)
    assert outs[-1][2] == pytest.approx(1.6, rel=1e-9)
    assert math.hypot(*outs[-1]) <= 2.0


def test_f_max_below_device_peak_clamps_at_f_max():
    gov = SafetyGovernor(SafetyConfig(), 3.3)
    assert gov.limit_n == 3.0
    out = run_constant(gov, (0.0, 0.0, -1e6), True, 0.001, 1000)[-1]
    assert -out[2] >= 3.0 * (1 - 1e-9) and math.hypot(*out) <= 3.0


@pytest.mark.parametrize("f", [(INF, 0.0, 0.0), (1.7e308, 1.7e308, 1.7e308)])
def test_overflowing_request_never_exceeds_the_limit(f):
    gov = SafetyGovernor(SafetyConfig(), 3.3)
    for o in run_constant(gov, f, True, 0.001, 700):
        assert math.isfinite(o[0]) and math.hypot(*o) <= 3.0


# ---------------------------------------------------------------------------
# ramp in


@pytest.mark.parametrize("target", [(1.0, -0.5, 0.25), (0.0, 2.9, 0.0), (-1.5, 1.5, -1.5)])
def test_enable_ramps_in_exactly(target):
    # dt = 2**-10 s (≈1 ms) and ramp_in = 0.5 s make every gain step exact (2**-9), so the
    # expected output is exactly min(1, k·dt/ramp_in)·target; the slew is large enough
    # that the command reaches the target on the first tick.
    dt = 2.0**-10
    cfg = SafetyConfig(slew_n_per_s=1e6, ramp_in_s=0.5)
    gov = SafetyGovernor(cfg, 3.3)
    for k in range(1, 601):
        out = gov.step(*target, True, dt)
        g = min(1.0, k * dt / cfg.ramp_in_s)
        assert out == tuple(c * g for c in target), k
    assert gov.gain == 1.0


def test_enable_ramps_in_at_one_millisecond():
    target = (0.3, -2.0, 1.1)
    gov = SafetyGovernor(SafetyConfig(slew_n_per_s=1e6), 3.3)  # ramp_in 0.5 s
    for k in range(1, 520):
        out = gov.step(*target, True, 0.001)
        g = min(1.0, k * 0.001 / 0.5)
        for o, c in zip(out, target, strict=True):
            assert o == pytest.approx(c * g, rel=1e-13, abs=1e-15), k
        if k >= 501:
            assert out == target
    assert gov.gain == 1.0


def test_slew_limit_at_full_gain():
    # ramp_in = 1 ms: full gain on the first tick; then the command moves 50 N/s·1 ms = 0.05 N per tick
    gov = SafetyGovernor(SafetyConfig(ramp_in_s=0.001), 3.3)
    outs = run_constant(gov, (2.0, 0.0, 0.0), True, 0.001, 60)
    for k, out in enumerate(outs, start=1):
        assert out[0] == pytest.approx(min(2.0, 0.05 * k), abs=1e-12)
        assert out[1:] == (0.0, 0.0)
    assert outs[-1] == (2.0, 0.0, 0.0)  # reaches the request exactly


def test_long_tick_counts_as_max_dt():
    gov = SafetyGovernor(SafetyConfig(), 3.3)  # max_dt 5 ms, slew 50 N/s, ramp_in 0.5 s
    out = gov.step(3.0, 0.0, 0.0, True, 10.0)
    assert gov.gain == pytest.approx(0.005 / 0.5, rel=1e-15)  # one 5 ms step of the 0.5 s ramp, up to rounding
    assert out[0] == pytest.approx(50.0 * 0.005 * 0.01, rel=1e-12)
    assert out[1:] == (0.0, 0.0)


@pytest.mark.parametrize("bad_dt", [0.0, -0.0, -0.001, -INF, NAN])
def test_zero_negative_or_nan_dt_changes_nothing(bad_dt):
    gov = SafetyGovernor(SafetyConfig(), 3.3)
    before = run_constant(gov, (1.0, 1.0, 0.0), True, 0.001, 100)[-1]
    gain = gov.gain
    for _ in range(5):
        assert gov.step(-3.0, 2.0, 1.0, True, bad_dt) == before
        assert gov.step(-3.0, 2.0, 1.0, False, bad_dt) == before
    assert gov.gain == gain


def test_starts_off():
    gov = SafetyGovernor(SafetyConfig(), 3.3)
    assert gov.gain == 0.0
    assert gov.step(1.0, 1.0, 1.0, False, 0.001) == ZERO


# ---------------------------------------------------------------------------
# ramp out (disable / fault)


def _full_force(cfg: SafetyConfig, peak=3.3, f=(3.0, 0.0, 0.0)):
    gov = SafetyGovernor(cfg, peak)
    run_constant(gov, f, True, 0.001, 1000)
    assert gov.gain == 1.0
    out = gov.step(*f, True, 0.001)
    assert math.hypot(*out) >= min(cfg.f_max_n, peak) * (1 - 1e-9)
    return gov, out


@pytest.mark.parametrize("fault_ramp_s", [0.01, 0.02, 0.04, 0.05])
@pytest.mark.parametrize("slew", [1.0, 50.0])
def test_disable_from_full_force_reaches_zero_within_fault_ramp(fault_ramp_s, slew):
    cfg = SafetyConfig(fault_ramp_s=fault_ramp_s, slew_n_per_s=slew)
    gov, start = _full_force(cfg, f=(0.0, 0.0, 3.0)) if slew == 50.0 else _full_force_slow(cfg)
    n_allowed = round(fault_ramp_s / 0.001)  # 40 ticks for the default 0.04 s; never more than 50
    outs = run_constant(gov, (0.0, 0.0, 3.0), False, 0.001, 60)
    first_zero = next(i for i, o in enumerate(outs, start=1) if o == ZERO)
    assert first_zero <= n_allowed <= 50
    assert all(o == ZERO for o in outs[first_zero - 1:])
    mags = [math.hypot(*start)] + [math.hypot(*o) for o in outs]
    assert all(b <= a for a, b in itertools.pairwise(mags))  # fades monotonically
    assert gov.gain == 0.0


def _full_force_slow(cfg):
    # with slew 1 N/s the command needs 3 s to reach 3 N
    gov = SafetyGovernor(cfg, 3.3)
    run_constant(gov, (0.0, 0.0, 3.0), True, 0.005, 700)
    out = gov.step(0.0, 0.0, 3.0, True, 0.001)
    assert gov.gain == 1.0 and out[2] >= 3.0 * (1 - 1e-9)
    return gov, out


def test_default_fault_ramp_takes_exactly_forty_ticks():
    gov, _ = _full_force(SafetyConfig())
    outs = run_constant(gov, (3.0, 0.0, 0.0), False, 0.001, 50)
    assert all(o != ZERO for o in outs[:39])
    assert outs[39:] == [ZERO] * 11
    # gain falls by dt/fault_ramp = 0.025 per tick
    assert outs[0][0] == pytest.approx(3.0 * 0.975, rel=1e-9)
    assert outs[19][0] == pytest.approx(3.0 * 0.5, rel=1e-9)


@pytest.mark.parametrize("dt", [0.002, 0.005, 0.0074, 0.01])
def test_fault_ramp_completes_within_fault_ramp_s_of_virtual_time_for_slow_ticks(dt):
    # A loop running late (docs/science.md §7: 4.8–7.4 ms periods with a same-process
    # GUI) must still reach zero within fault_ramp_s (≤ 50 ms, science.md §5) of elapsed
    # time; clipping dt to max_dt for the ramp-down stretches it instead.
    cfg = SafetyConfig()
    gov, _ = _full_force(cfg)
    elapsed = 0.0
    for _ in range(100):
        out = gov.step(3.0, 0.0, 0.0, False, dt)
        elapsed += dt
        if out == ZERO:
            break
    assert out == ZERO
    # the output changes only at ticks: zero by the first tick at or after fault_ramp_s
    assert elapsed < cfg.fault_ramp_s + dt, elapsed


def test_re_enable_after_off_ramps_from_rest():
    gov, _ = _full_force(SafetyConfig())
    run_constant(gov, (3.0, 0.0, 0.0), False, 0.001, 50)
    out = gov.step(3.0, 0.0, 0.0, True, 0.001)
    # gain 0.002, command one slew step (0.05 N) from rest: 1e-4 N, not a kick
    assert out[0] == pytest.approx(0.05 * 0.002, rel=1e-9)


def test_force_zero_drops_at_once_and_restarts_from_rest():
    gov, _ = _full_force(SafetyConfig())
    gov.force_zero()
    assert gov.gain == 0.0
    assert gov.step(3.0, 0.0, 0.0, False, 0.001) == ZERO
    out = gov.step(3.0, 0.0, 0.0, True, 0.001)
    assert out[0] == pytest.approx(0.05 * 0.002, rel=1e-9)


# ---------------------------------------------------------------------------
# bad requests while enabled


@pytest.mark.parametrize("bad", [(NAN, 0.0, 0.0), (0.0, NAN, NAN), (INF, 1.0, 1.0), (1.0, -INF, 0.0)])
def test_non_finite_request_while_enabled_moves_output_toward_zero(bad):
    gov = SafetyGovernor(SafetyConfig(), 3.3)
    run_constant(gov, (2.0, 0.0, 0.0), True, 0.001, 600)
    start = gov.step(2.0, 0.0, 0.0, True, 0.001)
    assert start == (2.0, 0.0, 0.0)
    outs = run_constant(gov, bad, True, 0.001, 45)
    mags = [math.hypot(*start)] + [math.hypot(*o) for o in outs]
    for o in outs:
        assert all(math.isfinite(c) for c in o)
    for a, b in itertools.pairwise(mags):
        assert b <= a and a - b <= 0.05 + 1e-12  # toward zero, at the slew rate
    # 2 N at 0.05 N per tick: 40 ticks, one more if rounding leaves a last ulp
    first_zero = next(i for i, o in enumerate(outs, start=1) if o == ZERO)
    assert 40 <= first_zero <= 41
    assert all(o == ZERO for o in outs[first_zero - 1:])
    assert gov.gain == 1.0  # a bad sample requests zero; it does not disable


# ---------------------------------------------------------------------------
# configuration


def test_defaults():
    cfg = SafetyConfig()
    assert (cfg.f_max_n, cfg.slew_n_per_s, cfg.ramp_in_s, cfg.fault_ramp_s, cfg.max_dt_s) == (
        3.0, 50.0, 0.5, 0.04, 0.005,
    )
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.f_max_n = 5.0


@pytest.mark.parametrize("field", FIELDS)
@pytest.mark.parametrize("bad", [0, 0.0, -0.0, -1.0, INF, -INF, NAN, "3", None])
def test_config_rejects_non_positive_or_non_finite(field, bad):
    with pytest.raises(ValueError, match=rf"safety\.{field}"):
        SafetyConfig(**{field: bad})


@pytest.mark.parametrize("value", [0.0500001, 0.06, 1.0])
def test_config_rejects_fault_ramp_above_50_ms(value):
    with pytest.raises(ValueError, match=r"safety\.fault_ramp_s.*0\.05"):
        SafetyConfig(fault_ramp_s=value)


def test_config_accepts_fault_ramp_of_exactly_50_ms():
    assert SafetyConfig(fault_ramp_s=0.05).fault_ramp_s == 0.05


@pytest.mark.parametrize("bad", [0.0, -1.0, INF, NAN])
def test_governor_rejects_bad_device_peak(bad):
    with pytest.raises(ValueError, match="device_peak_n"):
        SafetyGovernor(SafetyConfig(), bad)


@pytest.mark.parametrize(
    ("cfg_kwargs", "peak", "tick"),
    [
        ({"ramp_in_s": 5e-324}, 3.3, (1.0, 0.0, 0.0, True, 0.0)),  # 1/ramp_in = inf; inf·0 = NaN gain
        ({"fault_ramp_s": 5e-324}, 3.3, (1.0, 0.0, 0.0, False, 0.0)),
        ({"f_max_n": 1e300, "slew_n_per_s": 1e303}, 1e300, (1e305, 0.0, 0.0, True, 0.005)),  # limit² overflows
    ],
)
def test_every_accepted_config_keeps_output_finite_and_bounded(cfg_kwargs, peak, tick):
    # These configurations pass validation, so the stage's guarantee must hold for them
    # (or validation must reject them).
    try:
        gov = SafetyGovernor(SafetyConfig(**cfg_kwargs), peak)
    except ValueError:
        return
    for _ in range(3):
        out = gov.step(*tick)
        assert all(math.isfinite(c) for c in out), out
        assert math.hypot(*out) <= gov.limit_n, out
