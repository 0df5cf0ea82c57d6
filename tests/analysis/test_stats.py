"""Tests of analysis.stats.wilcoxon against scipy.stats.wilcoxon (SciPy 1.17.1), brute force and hand-computed values.

Values are built from integers and halves so that ON − OFF is exact in floating
point and ties and zeros occur often; then "equal to SciPy" means bit-equal.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy import stats as sps

from analysis.stats.correlation import CorrelationResult, correlation
from analysis.stats.hodges_lehmann import _midpoint, _walsh_select, hodges_lehmann
from analysis.stats.holm import RESULT_COLUMNS, holm, results_frame
from analysis.stats.signed_rank import signed_rank_null_counts
from analysis.stats.wilcoxon import WilcoxonResult, methods_text, paired_wilcoxon

_SCIPY_METHOD = {"exact": "exact", "approx": "asymptotic"}
TEST_FIELDS = ("statistic", "p_value", "z", "rank_biserial", "r")


def _scipy(on, off, method, **kw):
    m = sps.PermutationMethod() if method == "permutation" else _SCIPY_METHOD.get(method, method)
    return sps.wilcoxon(on, off, method=m, **kw)


def _brute_walsh(d) -> np.ndarray:
    d = np.sort(np.asarray(d, dtype=np.float64))
    i, j = np.triu_indices(d.size)
    return np.sort(0.5 * d[i] + 0.5 * d[j])


def _brute_hl(d) -> float:
    return float(np.median(_brute_walsh(d)))


# Pairs of halves: OFF and the difference drawn separately so that ties and zeros are frequent.
halves = st.integers(-6, 6).map(lambda k: k * 0.5)


@st.composite
def pairs(draw, min_n: int = 2, max_n: int = 60):
    n = draw(st.integers(min_n, max_n))
    off = np.array(draw(st.lists(st.integers(0, 20), min_size=n, max_size=n)), dtype=np.float64) * 0.5
    d = np.array(draw(st.lists(halves, min_size=n, max_size=n)))
    return off, off + d


# -- the exact test: hand-computed n = 10 table ----------------------------------------------------
def test_exact_p_for_n10_t0_is_2_over_1024():
    # exact equality on purpose, in this and the other exact tests: an exact p is a count of sign patterns over 2^n
    # (2/1024 here), a dyadic fraction every float holds exactly; rank sums are whole or half numbers
    res = paired_wilcoxon(np.zeros(10), np.arange(1.0, 11.0), metric="rmse_n")
    assert res.method == "exact"
    assert res.statistic == 0.0
    assert res.p_value == 0.001953125
    assert res.p_value == sps.wilcoxon(np.arange(1.0, 11.0)).pvalue
    assert (res.n_pairs, res.n_used, res.n_zero, res.n_ties) == (10, 10, 0, 0)
    assert res.rank_biserial == 1.0
    assert res.computable and res.note == ""


@pytest.mark.parametrize(
    ("negative_ranks", "t", "count_le_t"),
    # #sign patterns with W ≤ T for n = 10, counted by hand: 1,2,3,5,7,10,14,19,25,33 for T = 0…9
    [((), 0, 1), ((1,), 1, 2), ((2,), 2, 3), ((3,), 3, 5), ((5,), 5, 10), ((8,), 8, 25), ((9,), 9, 33)],
)
def test_exact_two_sided_p_table_n10(negative_ranks, t, count_le_t):
    d = np.array([-k if k in negative_ranks else k for k in range(1, 11)], dtype=np.float64)
    res = paired_wilcoxon(np.zeros(10), d)
    assert res.method == "exact"
    assert res.statistic == t
    assert res.p_value == 2 * count_le_t / 1024
    # science.md §6: T ≤ 8 is significant at 0.05, T = 9 is not
    assert (res.p_value < 0.05) == (t <= 8)


def test_null_counts_are_the_binomial_sign_patterns():
    c = signed_rank_null_counts(10)
    assert c.sum() == 1024 and c.size == 56
    assert list(np.cumsum(c)[:10]) == [1, 2, 3, 5, 7, 10, 14, 19, 25, 33]
    assert np.array_equal(c, c[::-1])  # W⁺ and W⁻ are exchangeable
    with pytest.raises(ValueError, match="n = 63"):
        signed_rank_null_counts(63)


# -- parity with scipy.stats.wilcoxon --------------------------------------------------------------
# SciPy's permutation test enumerates sign flips in Python (about 0.06 s at n = 6, 3 s at n = 13 on CI),
# so the permutation branch is checked by property on n ≤ 7 and by name at n = 13; the exact and
# normal branches are checked on every size.
@st.composite
def distinct_pairs(draw, min_n: int = 2, max_n: int = 50):
    """No ties, no zeros: distinct magnitudes with random signs."""
    mags = draw(st.lists(st.integers(1, 400), min_size=min_n, max_size=max_n, unique=True))
    signs = draw(st.lists(st.sampled_from([-1.0, 1.0]), min_size=len(mags), max_size=len(mags)))
    off = np.array(draw(st.lists(st.integers(0, 20), min_size=len(mags), max_size=len(mags))), dtype=np.float64)
    return off, off + np.array(signs) * np.array(mags) * 0.5


zero_methods = st.sampled_from(["wilcox", "pratt", "zsplit"])
alternatives = st.sampled_from(["two-sided", "greater", "less"])


def _check_against_scipy(off, on, zero_method, alternative):
    res = paired_wilcoxon(off, on, zero_method=zero_method, alternative=alternative, decimals=None)
    if not res.computable:  # only the degenerate cases, which are tested by name below
        assert off.size == 1 or np.all(on == off)
        return res
    ref = sps.wilcoxon(on, off, zero_method=zero_method, alternative=alternative)
    assert res.statistic == ref.statistic
    assert res.p_value == ref.pvalue
    # the reported method is what SciPy's auto chose: the explicit call gives the identical p
    explicit = _scipy(on, off, res.method, zero_method=zero_method, alternative=alternative)
    assert explicit.pvalue == ref.pvalue
    # with the default rounding nothing changes for halves
    assert paired_wilcoxon(off, on, zero_method=zero_method, alternative=alternative) == res
    return res


@given(st.one_of(pairs(min_n=14, max_n=60), distinct_pairs()), zero_methods, alternatives)
def test_auto_equals_scipy_exact_and_normal(data, zero_method, alternative):
    off, on = data
    d = on - off
    if d.size > 13 and 0 < np.count_nonzero(d) <= 13:  # SciPy approximates; the report enumerates (see below)
        res = paired_wilcoxon(off, on, zero_method=zero_method, alternative=alternative, decimals=None)
        assert res.method == "permutation"
        assert res.p_value == pytest.approx(_enumerated_p(d, zero_method, alternative), rel=1e-9)
        return
    res = _check_against_scipy(off, on, zero_method, alternative)
    assert res.method in ("exact", "approx") or not res.computable


def _enumerated_p(d: np.ndarray, zero_method: str, alternative: str) -> float:
    """The exact sign-flip p-value of W⁺, every flip of the non-zero differences listed by numpy (the reference for
    an n that SciPy's permutation test would only sample: zeros counted in n, at most 13 non-zero)."""
    ranks = sps.rankdata(np.abs(d[d != 0] if zero_method == "wilcox" else d))
    half = ranks[d == 0].sum() / 2 if zero_method == "zsplit" else 0.0
    r = ranks if zero_method == "wilcox" else ranks[d != 0]
    flips = (np.arange(2 ** r.size)[:, None] >> np.arange(r.size)) & 1  # 1: positive
    w = flips @ r + half
    observed = float(np.sum(r[d[d != 0] > 0]) + half)
    eps = 1e-9 * max(1.0, observed)
    greater, less = np.mean(w >= observed - eps), np.mean(w <= observed + eps)
    return float({"greater": greater, "less": less}.get(alternative, min(1.0, 2 * min(greater, less))))


@settings(max_examples=40)
@given(pairs(min_n=1, max_n=7), zero_methods, alternatives)
def test_auto_equals_scipy_permutation_with_ties_and_zeros(data, zero_method, alternative):
    off, on = data
    _check_against_scipy(off, on, zero_method, alternative)


@settings(max_examples=60)  # six SciPy calls per example
@given(pairs(max_n=40), zero_methods, st.booleans())
def test_explicit_exact_and_approx_equal_scipy(data, zero_method, correction):
    off, on = data
    if np.all(on == off):
        return
    for method in ("exact", "approx"):
        for alternative in ("two-sided", "greater", "less"):
            res = paired_wilcoxon(off, on, zero_method=zero_method, alternative=alternative,
                                  method=method, correction=correction, decimals=None)
            if not res.computable:
                assert off.size == 1
                continue
            ref = _scipy(on, off, method, zero_method=zero_method, alternative=alternative, correction=correction)
            assert res.method == method
            assert res.statistic == ref.statistic
            assert res.p_value == ref.pvalue, (method, alternative)


@settings(max_examples=100)
@given(pairs(min_n=3, max_n=60), st.sampled_from(["wilcox", "pratt", "zsplit"]))
def test_z_equals_scipy_asymptotic_zstatistic(data, zero_method):
    off, on = data
    res = paired_wilcoxon(off, on, zero_method=zero_method, decimals=None)
    if not res.computable:
        return
    ref = sps.wilcoxon(on, off, zero_method=zero_method, method="asymptotic")
    assert -abs(res.z) == ref.zstatistic
    assert res.r == pytest.approx(res.z / math.sqrt(res.n_used), rel=1e-15)


@pytest.mark.parametrize(
    ("d", "method"),
    [
        ([1, 2, 3, 4, 5, 6, 7, 8, 9, -10], "exact"),  # n ≤ 50, no ties, no zeros
        ([0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, -12], "permutation"),  # a zero, 13 pairs
        ([0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14], "approx"),  # a zero, 15 pairs: 14 to flip
        ([1, 1, 2, 3, 4, -5], "permutation"),  # a tie
        ([1, -1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13], "approx"),  # |d| tie, 14 pairs
        (list(range(1, 51)), "exact"),
        (list(range(1, 52)), "approx"),
    ],
)
def test_auto_rule_boundaries(d, method):
    on = np.asarray(d, dtype=np.float64)
    res = paired_wilcoxon(np.zeros(on.size), on)
    assert res.method == method
    ref = sps.wilcoxon(on).pvalue
    assert res.p_value == ref
    if on.size < 13:  # at 13 SciPy's auto *is* PermutationMethod(); one 3 s enumeration is enough
        assert _scipy(on, np.zeros(on.size), method).pvalue == ref


@pytest.mark.parametrize("zero_method", ["wilcox", "pratt", "zsplit"])
def test_zeros_beyond_scipys_permutation_limit_are_enumerated(zero_method):
    # 14 pairs, one a zero: SciPy's auto approximates (it counts the zero in n), though only 13 signs can flip;
    # the report's test is the exact one (issue 41: the pooled success test, 0.0002 exact against 0.00142 normal)
    d = np.array([0.0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, -13])
    res = paired_wilcoxon(np.zeros(d.size), d, zero_method=zero_method)
    assert res.method == "permutation" and res.n_zero == 1
    assert res.p_value == pytest.approx(_enumerated_p(d, zero_method, "two-sided"), rel=1e-9)
    if zero_method == "wilcox":  # no ties among the 13: SciPy's exact distribution of the non-zero ones
        assert res.p_value == pytest.approx(sps.wilcoxon(d[d != 0], method="exact").pvalue, rel=1e-9)
    assert res.p_value < sps.wilcoxon(d, zero_method=zero_method).pvalue  # what the normal approximation gave


def test_pratt_zeros_count_towards_permutation_limit_and_n_used():
    d = np.array([0.0, 0.0, 1, 2, 3, 4, 5, 6, 7, 8])
    w = paired_wilcoxon(np.zeros(10), d)
    p = paired_wilcoxon(np.zeros(10), d, zero_method="pratt")
    z = paired_wilcoxon(np.zeros(10), d, zero_method="zsplit")
    assert (w.n_used, p.n_used, z.n_used) == (8, 10, 10)
    assert w.n_zero == p.n_zero == 2
    assert w.method == p.method == z.method == "permutation"
    # wilcox: ranks 1…8 all positive → W⁺ = 36, W⁻ = 0; zsplit: ranks 3…10 positive, zeros' 1.5+1.5 split
    assert (w.w_plus, w.w_minus) == (36.0, 0.0)
    assert (z.w_plus, z.w_minus) == (52.0 + 1.5, 1.5)
    assert z.rank_biserial == pytest.approx(52.0 / 55.0, rel=1e-15)
    assert w.p_value == 2 / 256  # all 8 non-zero differences positive


def test_success_rate_differences_tie_after_rounding():
    # 0.7 − 0.6 and 0.8 − 0.7 differ in the 17th digit; rounding makes them the tie they are
    off = np.array([0.6, 0.7, 0.5, 0.4, 0.9, 0.3, 0.5, 0.6, 0.2, 0.7])
    on = np.array([0.7, 0.8, 0.7, 0.6, 0.9, 0.6, 0.8, 0.9, 0.6, 1.0])
    raw = on - off
    assert len(set(np.abs(raw[raw != 0]).tolist())) > len(set(np.round(np.abs(raw[raw != 0]), 10).tolist()))
    res = paired_wilcoxon(off, on, metric="success_rate")
    assert res.n_zero == 1 and res.n_ties == 3  # |d| = 0.1 ×2, 0.2 ×2, 0.3 ×4 (0.4 once)
    assert res.method == "permutation"
    assert res.p_value == sps.wilcoxon(np.round(raw, 10)).pvalue == 2 / 512
    assert paired_wilcoxon(off, on, decimals=None).p_value == sps.wilcoxon(on, off).pvalue


# -- effect sizes and orientation ------------------------------------------------------------------
def test_orientation_is_on_minus_off():
    off = np.array([5.0, 6.0, 7.0, 8.0, 9.0, 10.0])
    on = off - np.array([1.0, 2.0, 3.0, 4.0, 5.0, -0.5])  # ON mostly smaller
    res = paired_wilcoxon(off, on, alternative="less")
    assert res.w_plus == 1.0 and res.w_minus == 20.0
    assert res.statistic == 1.0  # one-sided: W⁺
    assert res.rank_biserial == pytest.approx(-19.0 / 21.0, rel=1e-15)
    assert res.z < 0 and res.r < 0 and res.hl_estimate < 0
    assert (res.n_positive, res.n_negative) == (1, 5)
    assert res.p_value == sps.wilcoxon(on, off, alternative="less").pvalue == 2 / 64
    flipped = paired_wilcoxon(on, off, alternative="greater")
    assert flipped.p_value == res.p_value and flipped.rank_biserial == -res.rank_biserial


@given(pairs())
def test_computable_results_have_no_nan(data):
    off, on = data
    res = paired_wilcoxon(off, on, metric="m")
    if not res.computable:
        assert np.all(on == off) and res.note
        return
    for name in (*TEST_FIELDS, "median_off", "median_on", "hl_estimate", "hl_ci_low", "hl_ci_high", "ci_level"):
        assert math.isfinite(getattr(res, name)), name
    assert -1.0 <= res.rank_biserial <= 1.0
    assert 0.0 <= res.p_value <= 1.0
    assert res.hl_ci_low <= res.hl_estimate <= res.hl_ci_high
    assert res.n_used + (res.n_zero if res.zero_method == "wilcox" else 0) == res.n_pairs


# -- degenerate inputs ----------------------------------------------------------------------------
def _assert_test_fields_nan(res: WilcoxonResult) -> None:
    assert not res.computable and res.note
    assert res.method == ""
    for name in TEST_FIELDS:
        assert math.isnan(getattr(res, name)), name


def test_all_differences_zero():
    x = np.arange(10.0)
    res = paired_wilcoxon(x, x.copy(), metric="success_rate")
    _assert_test_fields_nan(res)
    assert "all 10 differences are zero" in res.note
    assert (res.n_pairs, res.n_zero, res.n_used) == (10, 10, 0)
    assert res.hl_estimate == 0.0 and res.hl_ci_low == 0.0 and res.hl_ci_high == 0.0
    assert res.median_off == res.median_on == 4.5
    pratt = paired_wilcoxon(x, x.copy(), zero_method="pratt")
    assert not pratt.computable and pratt.n_used == 10


def test_all_equal_nonzero_differences_are_a_valid_test():
    off = np.linspace(0.2, 0.8, 10)
    res = paired_wilcoxon(off, off + 0.1, metric="success_rate")
    assert res.computable
    assert res.method == "permutation"  # one tie group of 10
    assert res.p_value == 2 / 1024 == sps.wilcoxon(np.full(10, 0.1)).pvalue
    assert res.hl_estimate == pytest.approx(0.1, abs=1e-12)
    assert res.hl_ci_low == res.hl_ci_high == res.hl_estimate
    assert "all differences are equal" in res.note


def test_single_pair():
    res = paired_wilcoxon([3.0], [2.0], metric="tct_s")
    _assert_test_fields_nan(res)
    assert "single pair" in res.note
    assert res.n_pairs == 1 and res.hl_estimate == -1.0
    assert math.isnan(res.hl_ci_low) and math.isnan(res.ci_level)


def test_no_pairs():
    for off, on in (([], []), ([np.nan, 1.0], [2.0, np.nan])):
        res = paired_wilcoxon(off, on)
        _assert_test_fields_nan(res)
        assert "no complete pairs" in res.note
        assert math.isnan(res.median_off) and math.isnan(res.hl_estimate)


def test_nan_pairs_are_dropped_and_counted():
    off = np.array([1.0, 2.0, np.nan, 4.0, 5.0, 6.0, 7.0, 8.0])
    on = np.array([2.5, 4.0, 3.0, 7.0, np.nan, 10.5, 13.0, 15.0])
    res = paired_wilcoxon(off, on, metric="tct_s")
    keep = ~(np.isnan(off) | np.isnan(on))
    ref = paired_wilcoxon(off[keep], on[keep], metric="tct_s")
    assert res.n_dropped_nan == 2 and res.n_pairs == 6
    assert "2 of 8 pairs dropped" in res.note
    for name in (*TEST_FIELDS, "hl_estimate", "hl_ci_low", "hl_ci_high", "median_off", "median_on"):
        assert getattr(res, name) == getattr(ref, name)
    assert res.p_value == sps.wilcoxon(on, off, nan_policy="omit").pvalue


def test_infinite_values_are_refused_with_a_note():
    res = paired_wilcoxon([1.0, 2.0, np.inf, 4.0], [1.5, 2.5, 3.0, 4.5], metric="rmse_n")
    _assert_test_fields_nan(res)
    assert "off[2] is inf" in res.note
    res = paired_wilcoxon([1.0, 2.0, 3.0], [1.5, -np.inf, 3.5])
    assert not res.computable and "on[1] is -inf" in res.note
    huge = paired_wilcoxon([-1e308, -1e308, 0.0], [1e308, 1e308, 1.0])
    assert not huge.computable and "overflows" in huge.note


def test_few_pairs_note_and_small_n_interval():
    res = paired_wilcoxon(np.zeros(4), np.array([1.0, 2.0, 3.0, 4.0]))
    assert res.computable and res.p_value == 2 / 16
    assert "cannot be below 0.125" in res.note
    # 95 % is out of reach with 4 pairs: widest interval [min d, max d] at 1 − 2/16
    assert (res.hl_ci_low, res.hl_ci_high, res.ci_level) == (1.0, 4.0, 0.875)
    assert "4 differences are too few for a 95% Hodges–Lehmann interval" in res.note
    # with a zero among them, the note counts the differences the interval is made of, zeros named
    zero = paired_wilcoxon(np.zeros(4), np.array([0.0, 2.0, 3.0, 4.0]))
    assert zero.n_used == 3 and "4 differences (1 of them zero) are too few" in zero.note


def test_bad_arguments_raise_naming_the_value():
    with pytest.raises(ValueError, match="zero_method = 'zero'"):
        paired_wilcoxon([1, 2], [2, 3], zero_method="zero")
    with pytest.raises(ValueError, match="alternative = 'up'"):
        paired_wilcoxon([1, 2], [2, 3], alternative="up")
    with pytest.raises(ValueError, match="method = 'mc'"):
        paired_wilcoxon([1, 2], [2, 3], method="mc")
    with pytest.raises(ValueError, match="off has 2 values and on has 3"):
        paired_wilcoxon([1, 2], [2, 3, 4])
    with pytest.raises(ValueError, match=r"confidence = 1.5"):
        paired_wilcoxon([1, 2], [2, 3], confidence=1.5)
    with pytest.raises(ValueError, match="allowed up to 400"):
        paired_wilcoxon(np.zeros(401), np.arange(1.0, 402.0), method="exact")


# -- Hodges–Lehmann ---------------------------------------------------------------------------------
@given(st.lists(st.one_of(halves, st.floats(-1e3, 1e3, allow_nan=False)), min_size=1, max_size=40))
def test_walsh_selection_equals_brute_force(values):
    d = np.sort(np.array(values, dtype=np.float64))
    walsh = _brute_walsh(d)
    m = walsh.size
    for k in sorted({1, m, (m + 1) // 2, max(1, m // 3), max(1, 2 * m // 3)}):
        # enumerate_at=1 forces the pivot/counting path all the way down
        assert _walsh_select(d, k, enumerate_at=1) == walsh[k - 1]
        assert _walsh_select(d, k) == walsh[k - 1]


def _enumerated_counts(n: int) -> np.ndarray:
    """W⁺ counts by listing all 2ⁿ sign patterns."""
    signs = (np.arange(2**n)[:, None] >> np.arange(n)) & 1
    return np.bincount(signs @ np.arange(1, n + 1), minlength=n * (n + 1) // 2 + 1)


@pytest.mark.parametrize("n", range(0, 13))
def test_null_counts_equal_enumeration(n):
    assert np.array_equal(signed_rank_null_counts(n), _enumerated_counts(n))


@given(st.lists(st.floats(-1.7976931348623157e308, 1.7976931348623157e308, allow_nan=False, allow_infinity=False)
                | st.sampled_from([0.0, 5e-324, -5e-324, 1e308, -1e308]), min_size=1, max_size=30))
def test_walsh_selection_exact_at_float_extremes(values):
    d = np.sort(np.array(values, dtype=np.float64))
    walsh = _brute_walsh(d)
    for k in sorted({1, walsh.size, (walsh.size + 1) // 2}):
        assert _walsh_select(d, k, enumerate_at=1) == walsh[k - 1]


@example([0.0, 0.0, 0.0, 0.0, -0.5, -0.5, -2.225073858507203e-309])  # subnormal middle pair: one rounding
@given(st.lists(st.one_of(halves, st.floats(-50, 50, allow_nan=False)), min_size=2, max_size=60))
def test_hodges_lehmann_equals_brute_force(values):
    n = len(values)
    walsh = _brute_walsh(values)
    m = walsh.size
    est, lo, hi, level = hodges_lehmann(values)
    assert est == float(np.median(walsh))
    # critical rank: largest k with P(W⁺ ≤ k−1) ≤ 0.025 (exact, n ≤ 50), else the normal formula
    if n <= 50:
        cdf = np.cumsum(_enumerated_counts(n) if n <= 12 else signed_rank_null_counts(n))
        ok = [k for k in range(1, m + 1) if cdf[k - 1] <= 0.025 * 2**n]
        k = ok[-1] if ok else 1
        assert level == 1 - 2 * cdf[k - 1] / 2**n
        assert level >= 0.95 or n <= 5
    else:
        mean, sd = n * (n + 1) / 4, math.sqrt(n * (n + 1) * (2 * n + 1) / 24)
        k = math.floor(mean + 0.5 - 1.959963984540054 * sd)
    assert (lo, hi) == (walsh[k - 1], walsh[m - k])
    assert lo <= est <= hi


def test_hodges_lehmann_large_n_equals_brute_force_with_ties():
    rng = np.random.default_rng(7)
    d = np.round(rng.normal(0.3, 1.0, 1500), 1)  # heavy ties
    walsh = _brute_walsh(d)
    m = walsh.size
    est, lo, hi, level = hodges_lehmann(d)
    assert est == 0.5 * walsh[m // 2 - 1] + 0.5 * walsh[m // 2]  # m = 1 125 750 is even
    n = d.size
    mean, sd = n * (n + 1) / 4, math.sqrt(n * (n + 1) * (2 * n + 1) / 24)
    k = math.floor(mean + 0.5 - 1.959963984540054 * sd)
    assert (lo, hi) == (walsh[k - 1], walsh[m - k])
    assert level == pytest.approx(0.95, abs=1e-4) and level >= 0.95 - 1e-4


def test_hodges_lehmann_exact_critical_values_n10():
    # n = 10, 95 %: P(W ≤ 8) = 25/1024 ≤ 0.025 < P(W ≤ 9) = 33/1024 → 9th smallest and 9th largest
    d = np.array([1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0, 256.0, 512.0])
    walsh = _brute_walsh(d)
    est, lo, hi, level = hodges_lehmann(d)
    assert (lo, hi) == (walsh[8], walsh[55 - 9])
    assert level == 1 - 50 / 1024
    assert est == walsh[27]
    # 90 %: P(W ≤ 10) = 43/1024 ≤ 0.05 < P(W ≤ 11) = 54/1024 → k = 11
    assert hodges_lehmann(d, 0.9)[3] == 1 - 2 * 43 / 1024


def test_hodges_lehmann_extremes():
    big = np.array([1e308, 1e308, -1e308, 1.7e308])
    est, lo, hi, _ = hodges_lehmann(big)
    assert np.isfinite([est, lo, hi]).all()
    assert hodges_lehmann([2.5]) [0] == 2.5
    with pytest.raises(ValueError, match="empty"):
        hodges_lehmann([])
    with pytest.raises(ValueError, match=r"d\[1\] = nan"):
        hodges_lehmann([1.0, np.nan])


# -- Holm -----------------------------------------------------------------------------------------
def test_holm_hand_computed():
    # sorted 0.005·4 = 0.02, 0.01·3 = 0.03, 0.03·2 = 0.06, 0.04·1 → max(0.06, 0.04) = 0.06
    assert holm([0.01, 0.04, 0.03, 0.005]).tolist() == pytest.approx([0.03, 0.06, 0.06, 0.02], rel=1e-15)
    assert holm([0.3, 0.5, 0.6]).tolist() == [0.8999999999999999, 1.0, 1.0]  # capped at 1
    out = holm([0.01, np.nan, 0.04])  # NaN not counted: m = 2
    assert out[0] == 0.02 and math.isnan(out[1]) and out[2] == 0.04
    assert holm([]).size == 0
    assert np.isnan(holm([np.nan, np.nan])).all()
    with pytest.raises(ValueError, match=r"p_values\[1\] = 1.2"):
        holm([0.1, 1.2])


def _holm_reference(p: np.ndarray) -> np.ndarray:
    """statsmodels' multipletests(method='holm') written out as a loop."""
    m = p.size
    order = np.argsort(p)
    out = np.empty(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[i]))
        out[i] = running
    return out


@given(st.lists(st.one_of(st.floats(0, 1), st.sampled_from([0.01, 0.05, 0.2])), min_size=1, max_size=12))
def test_holm_matches_reference_and_is_monotone(ps):
    p = np.array(ps)
    adj = holm(p)
    assert np.allclose(adj, _holm_reference(p), rtol=1e-15, atol=0)
    assert np.all(adj >= p) and np.all(adj <= 1.0)
    order = np.argsort(p)
    assert np.all(np.diff(adj[order]) >= 0)


# -- correlation ----------------------------------------------------------------------------------
def test_spearman_equals_scipy_with_bonett_wright_interval():
    rng = np.random.default_rng(3)
    tct = rng.uniform(2, 12, 40)
    rmse = 0.5 - 0.02 * tct + rng.normal(0, 0.05, 40)
    res = correlation(tct, rmse)
    ref = sps.spearmanr(tct, rmse)
    assert isinstance(res, CorrelationResult)
    assert (res.r, res.p_value, res.n, res.method) == (ref.statistic, ref.pvalue, 40, "spearman")
    se = math.sqrt((1 + res.r**2 / 2) / 37)
    assert res.ci_low == pytest.approx(math.tanh(math.atanh(res.r) - 1.959963984540054 * se), rel=1e-12)
    assert res.ci_high == pytest.approx(math.tanh(math.atanh(res.r) + 1.959963984540054 * se), rel=1e-12)


def test_pearson_fisher_interval_hand_computed():
    x = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0])
    y = np.array([2.0, 1.0, 4.0, 3.0, 7.0, 5.0, 6.0])
    res = correlation(x, y, method="pearson")
    r = 23.0 / 28.0  # Sxy = 23, Sxx = Syy = 28
    assert res.r == pytest.approx(r, rel=1e-14)
    assert res.p_value == pytest.approx(sps.pearsonr(x, y).pvalue, rel=1e-14)
    assert res.ci_low == pytest.approx(math.tanh(math.atanh(r) - 1.959963984540054 / 2.0), rel=1e-12)


def test_correlation_degenerate():
    assert not correlation([1, 2], [3, 4]).computable
    c = correlation([1, 1, 1, 1], [1, 2, 3, 4])
    assert not c.computable and "x is constant" in c.note and math.isnan(c.r)
    c = correlation([1, 2, np.nan, 4, 5], [2, 1, 3, np.nan, 6])
    assert c.computable and c.n == 3 and c.n_dropped_nan == 2 and math.isnan(c.ci_low)
    c = correlation([1, 2, 3, 4], [1, 2, 3, 4])  # a perfect association: ±1 exactly on every CPU (UNIT_R_TOLERANCE)
    assert c.r == 1.0 and c.p_value == 0.0 and (c.ci_low, c.ci_high) == (1.0, 1.0)
    c = correlation([1, 2, 3, 4, 5], [-2.0, -4.0, -6.0, -8.0, -10.0], method="pearson")
    assert c.r == -1.0 and c.p_value == 0.0
    from analysis.stats.correlation import unit_snapped  # what the AVX-512 kernel gave for a perfect line

    assert unit_snapped(-0.9999999999999999) == -1.0 and unit_snapped(1.0000000000000002) == 1.0
    assert unit_snapped(0.9999) == 0.9999 and math.isnan(unit_snapped(math.nan))
    assert not correlation([1, 2, np.inf, 4], [1, 2, 3, 4]).computable
    with pytest.raises(ValueError, match="method = 'kendall'"):
        correlation([1, 2, 3], [1, 2, 3], method="kendall")


# -- tables and text ------------------------------------------------------------------------------
def test_results_frame_tidy_with_holm_over_computable_rows():
    rng = np.random.default_rng(5)
    off = rng.uniform(0.2, 0.6, 10)
    results = [
        paired_wilcoxon(off, off - np.arange(1.0, 11.0) / 100, metric="rmse_n"),
        paired_wilcoxon(off, off + np.array([3, -1, 2, 4, 5, -6, 7, 8, 9, 10.0]), metric="tct_s"),
        paired_wilcoxon(off, off.copy(), metric="success_rate"),  # not computable
    ]
    frame = results_frame(results)
    assert isinstance(frame, pd.DataFrame)
    assert tuple(frame.columns) == RESULT_COLUMNS
    assert all(c == c.lower() and " " not in c for c in frame.columns)
    assert frame["metric"].tolist() == ["rmse_n", "tct_s", "success_rate"]
    # rmse_n: all 10 differences negative → 2/1024; tct_s: W⁻ = 1 + 6 = 7 → 2·19/1024
    assert frame["p_value"].iloc[:2].tolist() == [2 / 1024, 38 / 1024]
    assert frame["p_holm"].iloc[:2].tolist() == [4 / 1024, 38 / 1024]
    assert math.isnan(frame["p_holm"].iloc[2]) and not frame["computable"].iloc[2]


def test_methods_text_states_the_choices():
    text = methods_text("pratt", 0.9)
    for phrase in ("d = ON − OFF", "Pratt", "90%", "Holm", "Hodges–Lehmann", "rank-biserial", "permutation",
                   "normal approximation", "exact"):
        assert phrase in text, phrase
    assert "discarded" in methods_text("wilcox") and "split equally" in methods_text("zsplit")
    assert "\n" not in text
    with pytest.raises(ValueError, match="zero_method = 'x'"):
        methods_text("x")


@given(st.floats(allow_nan=False, allow_infinity=False), st.floats(allow_nan=False, allow_infinity=False))
def test_midpoint_is_the_correctly_rounded_mean_of_any_two_doubles(a, b):
    from fractions import Fraction

    got = _midpoint(a, b)
    assert got == float((Fraction(a) + Fraction(b)) / 2)  # float(Fraction) rounds to nearest, ties to even


def test_scipy_pin_is_the_range_whose_auto_rule_was_read():
    import re
    import tomllib
    from pathlib import Path

    import scipy

    from analysis.stats.signed_rank import SCIPY_AUTO_RANGE

    deps = tomllib.loads((Path(__file__).parents[2] / "pyproject.toml").read_text())["project"]["dependencies"]
    (spec,) = [d for d in deps if d.startswith("scipy")]
    lo, hi = SCIPY_AUTO_RANGE
    major, minor = (int(x) for x in hi.split("."))
    assert spec == f"scipy>={lo},<{major}.{minor + 1}"
    installed = tuple(int(x) for x in re.findall(r"\d+", scipy.__version__)[:2])
    assert tuple(int(x) for x in lo.split(".")) <= installed <= (major, minor)
    assert f"SciPy {scipy.__version__}" in methods_text()
